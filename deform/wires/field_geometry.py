"""The field's box stage of :class:`~voxwarp.deform.wires.build.WireDeformer`: the
whole reach of the wires, the content box inside it
(:mod:`voxwarp.deform.wires.field_box`) and the check that a built field's box cut no
content."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from voxwarp.deform.warp import WarpError
from voxwarp.deform.wires.constants import MAX_FIELD_VOXELS
from voxwarp.deform.wires.field_box import Probes, content_box, escapes, wire_probes
from voxwarp.deform.wires.geometry import _curve_box, _region_centres
from voxwarp.deform.wires.sides import SidePasses, _SideResult
from voxwarp.deform.wires.tables import WireTables


class FieldGeometry(SidePasses):
    """Where :class:`~voxwarp.deform.wires.build.WireDeformer`'s field lies (it sets
    ``volume_bounds``)."""

    volume_bounds: tuple[np.ndarray, np.ndarray]

    def _field_geometry(
        self, tables: Sequence[WireTables], masks: Sequence[tuple[np.ndarray, int, float]] | None
    ) -> tuple[np.ndarray, np.ndarray, tuple[int, int, int], np.ndarray]:
        """Field box lo, voxel spacing and shape: the volume box grown (in whole field
        voxels) to hold the wires' curves and the places their masks can bring the
        volume's content (:func:`~voxwarp.deform.wires.field_box.content_box`; beyond
        them every sample is empty); with ``masks`` None, grown by the wires' whole
        reach. Also which faces (2, 3: lower, upper) lie inside the whole reach."""
        h = self.spacing * self.field_scale
        vlo, vhi = self.volume_bounds
        loose_lo, loose_hi = vlo.copy(), vhi.copy()
        out = []  # the wires whose reach leaves the volume box
        for wi, w in enumerate(self.wires):
            clo, chi = _curve_box(w.modified)
            grow = max(w.reach_at(float(w.scale[:, 1].max())), w.end_reach())
            loose_lo = np.minimum(loose_lo, clo - grow)
            loose_hi = np.maximum(loose_hi, chi + grow)
            if np.any(clo - grow < vlo) or np.any(chi + grow > vhi):
                out.append(wi)
        lo, hi = loose_lo, loose_hi
        if masks is not None:
            probes = [pr for wi in out for pr in self._probes(tables, masks, wi, h)]
            c_lo, c_hi = content_box(
                probes,
                self._content_bounds(),
                (loose_lo, loose_hi),
                int(np.prod(np.ceil((loose_hi - loose_lo) / h))),
            )
            k_lo, k_hi = self._curves_box(2.0 * h)
            # a field voxel more: a sample that can show content then interpolates
            # between the same voxels as in the whole reach's field; never beyond it
            lo = np.maximum(np.minimum(k_lo, c_lo - h), loose_lo)
            hi = np.minimum(np.maximum(k_hi, c_hi + h), loose_hi)
        grow_lo = np.ceil((vlo - lo) / h - 1e-9)
        lo = vlo - grow_lo * h
        count = np.maximum(np.ceil((hi - lo) / h - 1e-9), 1)
        if float(np.prod(count)) > MAX_FIELD_VOXELS:
            dims = "x".join(f"{v:.0f}" for v in count)
            raise WarpError(
                f"the attribute field would be {dims} voxels, over the limit of"
                f" {MAX_FIELD_VOXELS:,}: the modified wires reach far outside the volume;"
                " keep them near the object or use a larger field_scale"
            )
        shape = count.astype(int)
        inner = np.stack([lo > loose_lo + 1e-9, lo + count * h < loose_hi - 1e-9])
        return lo, h, (int(shape[0]), int(shape[1]), int(shape[2])), inner

    def _content_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The volume box grown by a volume voxel: trilinear sampling reaches half a
        voxel beyond its faces (the longest voxel side on every axis: an oblique
        volume's voxels may lie across the world axes)."""
        vlo, vhi = self.volume_bounds
        border = float(np.max(self.spacing))
        return vlo - border, vhi + border

    def _probes(
        self,
        tables: Sequence[WireTables],
        masks: Sequence[tuple[np.ndarray, int, float]],
        wi: int,
        h: np.ndarray,
    ) -> list[Probes]:
        """Wire ``wi``'s probes (:func:`~voxwarp.deform.wires.field_box.wire_probes`):
        each plane's widest mask pixel, grown as the build grows the masks (half a field
        voxel) and by a pixel's rounding; along the wire, a swept voxel stays within a
        field voxel and a mask pixel (twice over) and two table steps of its entry."""
        mask, _, half = masks[wi]
        px = self.mask_resolution
        # per plane and row, the farther of the row's first and last pixel
        k = mask.shape[2]
        first, last = mask.argmax(axis=2), k - 1 - mask[:, :, ::-1].argmax(axis=2)
        across = np.maximum(np.abs(first - half), np.abs(last - half)) * px
        along = np.abs(np.arange(mask.shape[1]) - half) * px
        widest = np.where(mask.any(axis=2), np.hypot(along, across), 0.0).max(axis=1)
        grow = math.ceil(0.5 * float(h.max()) / px) + 0.5
        radii = widest + grow * px * math.sqrt(2.0)
        tab = tables[wi]
        slack = 2.0 * (float(np.linalg.norm(h)) + px) + 2.0 * tab.length_modified / (tab.size - 1)
        caps = self._end_cap() + self.wires[wi].end_reach("modified")
        return wire_probes(tab, radii, slack, caps)

    def _cuts_content(
        self,
        tables: Sequence[WireTables],
        swept_side: _SideResult,
        lo: np.ndarray,
        h: np.ndarray,
        shape: tuple[int, int, int],
        inner: np.ndarray,
    ) -> bool:
        """Whether a swept voxel on a face of the field inside the wires' whole reach
        can be mapped into the volume (:func:`~voxwarp.deform.wires.field_box.escapes`):
        the box then cut content, and the build runs again on the whole reach."""
        region_lo, rshape, r_wire, r_u, swept, _ = swept_side
        for end, d in zip(*np.nonzero(inner), strict=True):
            k = (0 if end == 0 else shape[d] - 1) - int(region_lo[d])
            if not 0 <= k < rshape[d]:
                continue
            face = [slice(None)] * 3
            face[d] = slice(k, k + 1)
            at = np.nonzero(swept[tuple(face)])
            if len(at[0]) == 0:
                continue
            idx = np.stack(at, -1) + np.eye(3, dtype=int)[d] * k
            flat = np.ravel_multi_index(tuple(idx.T), rshape)
            pts = _region_centres(lo, h, region_lo, rshape, flat)
            wire, u = r_wire.ravel()[flat], r_u.ravel()[flat]
            if escapes(tables, pts, wire, u, self._content_bounds()):
                return True
        return False

    def _curves_box(self, pad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The volume box and every wire's base and modified curve (grown by ``pad``,
        so that each seed voxel around a curve lies in the field)."""
        lo, hi = self.volume_bounds
        for w in self.wires:
            for curve in (w.base, w.modified):
                clo, chi = _curve_box(curve)
                lo, hi = np.minimum(lo, clo - pad), np.maximum(hi, chi + pad)
        return lo, hi
