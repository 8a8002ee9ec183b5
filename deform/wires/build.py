"""The :class:`WireDeformer`: builds the attribute field of a set of wires on a
volume (wire paper sections 5, 7; see :mod:`voxwarp.deform.wires`)."""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy import ndimage

from voxwarp.deform.warp import WarpError, warp_class
from voxwarp.deform.wires import propagation as prop
from voxwarp.deform.wires.classify import classify_available
from voxwarp.deform.wires.constants import (
    FIELD_BOXES,
    FIELD_SCALES,
    LAYOUTS,
    LUT_SIZE,
    MAX_REACH_DIAGONALS,
    MAX_WIRES,
    PAPER_MAX_SEGMENTS,
    PAPER_MAX_WIRES,
    PROPAGATE_MODES,
)
from voxwarp.deform.wires.field_geometry import FieldGeometry
from voxwarp.deform.wires.geometry import _box_overlap, _curve_box
from voxwarp.deform.wires.layouts import WireField, WireFieldStats, store_field
from voxwarp.deform.wires.propagation import last_backend
from voxwarp.deform.wires.sides import _SideJob, _SideResult
from voxwarp.deform.wires.tables import WireTables
from voxwarp.deform.wires.wire import Wire

if TYPE_CHECKING:
    from voxwarp.deform.wires.warp import WireFieldWarp


def _volume_parts(volume: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    try:
        data = volume.data
        spacing = np.asarray(volume.spacing, dtype=np.float64).reshape(3)
        origin = np.asarray(volume.origin, dtype=np.float64).reshape(3)
    except (AttributeError, ValueError, TypeError) as exc:
        raise WarpError(
            "WireDeformer needs a volume with data, spacing and origin (app.load_volume or"
            f" a sample); got {type(volume).__name__}"
        ) from exc
    if np.ndim(data) != 3:
        raise WarpError(f"WireDeformer needs a 3D volume; got data of shape {np.shape(data)}")
    return data, spacing, origin


def _checked_wires(wires: Sequence[Wire]) -> list[Wire]:
    """``wires`` as a list of 1 to :data:`MAX_WIRES` :class:`Wire` objects (a one-line
    WarpError otherwise)."""
    wires = list(wires)
    if not wires:
        raise WarpError("WireDeformer needs at least one Wire")
    if len(wires) > MAX_WIRES:
        raise WarpError(
            f"at most {MAX_WIRES} wires fit one attribute field (7-bit wire id); got"
            f" {len(wires)}: split them over several WireDeformers"
        )
    for i, w in enumerate(wires):
        if not isinstance(w, Wire):
            raise WarpError(f"wires[{i}] is a {type(w).__name__}, not a voxwarp.deform.Wire")
    return wires


class WireDeformer(FieldGeometry):
    """Builds the attribute field of a set of wires on a volume (paper sections 5, 7).

    Parameters
    ----------
    volume
        The original volume (``data`` indexed x, y, z; ``spacing``; ``origin``): β
        classifies its values.
    wires
        Up to :data:`MAX_WIRES` :class:`Wire` objects.
    field_scale
        Per-axis reduction of the field against the volume: 1, 2, 4, 8 or 16
        (1:1 ... 1:4096 in voxels).
    ctx
        Optional moderngl context: :meth:`warp` then uploads its textures at once.
    layout
        ``"float"``, ``"packed"`` (2 bytes per voxel) or ``"paper"`` (2 bytes per voxel,
        the paper's wire / segment / t split), see :mod:`voxwarp.deform.wires`.
    masks
        Sweep only the seed-filled cross-section of the object the wire runs through
        (True, the paper's plane masks), or every β voxel in the region (False).
    mask_resolution
        Pixel size of the plane masks and spacing of the planes (mm); default the
        volume's smallest voxel spacing for a 1:1 field, twice that for coarser fields
        (whose voxels sample the masks no finer).
    dilation
        Pixels of morphological dilation of each mask.
    backend
        Propagation backend of :func:`voxwarp.deform.wires.propagation.nearest_seed`.
    precision
        Arc-length precision p (eq. 4) and closest-point precision (in t).
    propagate
        ``"region"``: nearest-seed propagation over the whole box of the wires' reach,
        then the mask test; ``"flagged"``: the paper's order (sections 5.1, 7.1): the
        voxels the plane masks touch are flagged first and only they (and their
        neighbours, which swept samples interpolate) get a nearest seed.
    box
        The field's box: ``"content"`` (default) grows the volume box only where the
        wires can bring the volume's content
        (:func:`~voxwarp.deform.wires.field_box.content_box`: every other sample is
        empty anyway); ``"reach"`` by the wires' whole reach, as before. A content
        box is a block of the reach box's field with the same bits; where a swept
        voxel on its faces could still show content it is dropped for the reach box
        (:attr:`box_used` says which box the last build used).
    """

    def __init__(
        self,
        volume: Any,
        wires: Sequence[Wire],
        field_scale: int = 2,
        ctx: Any = None,
        *,
        layout: str = "float",
        masks: bool = True,
        mask_resolution: float | None = None,
        dilation: int = 1,
        backend: str = "auto",
        precision: float = 1e-4,
        propagate: str = "region",
        box: str = "content",
    ) -> None:
        self.data, self.spacing, self.origin = _volume_parts(volume)
        # oblique scans: world <-> index through the volume's rotation
        direction = getattr(volume, "direction", None)
        self._direction = np.eye(3) if direction is None else np.asarray(direction, float)
        self.wires = _checked_wires(wires)
        if field_scale not in FIELD_SCALES:
            raise WarpError(
                f"field_scale must be one of {FIELD_SCALES} (per-axis reduction);"
                f" got {field_scale!r}"
            )
        self.field_scale = int(field_scale)
        if layout not in LAYOUTS:
            raise WarpError(f"layout must be one of {LAYOUTS}; got {layout!r}")
        self.layout = layout
        self._check_layout_limits()
        if propagate not in PROPAGATE_MODES:
            raise WarpError(f"propagate must be one of {PROPAGATE_MODES}; got {propagate!r}")
        self.propagate = propagate
        if box not in FIELD_BOXES:
            raise WarpError(f"box must be one of {FIELD_BOXES}; got {box!r}")
        self.box = box
        self.masks = bool(masks)
        if mask_resolution is None:
            # the volume's voxel for a 1:1 field; two of them for coarser fields, whose
            # voxels sample the masks at most that finely (8x fewer mask pixels)
            px = float(self.spacing.min()) * min(int(field_scale), 2)
        else:
            px = float(mask_resolution)
        if not math.isfinite(px) or px <= 0:
            raise WarpError(f"mask_resolution must be a length in mm > 0; got {mask_resolution}")
        self.mask_resolution = px
        if int(dilation) != dilation or dilation < 0:
            raise WarpError(f"dilation must be a whole number of pixels >= 0; got {dilation}")
        self.dilation = int(dilation)
        self.backend = backend
        self.precision = float(precision)
        self.ctx = ctx
        self.field: WireField | None = None
        self.stats: WireFieldStats | None = None
        self.propagation_input: tuple[np.ndarray, tuple[float, ...]] | None = None
        self._warp: WireFieldWarp | None = None
        #: the box of the last build's field: "content" or "reach" (see ``box``)
        self.box_used: str | None = None
        vlo = self.origin - 0.5 * self.spacing
        vhi = self.origin + (np.asarray(self.data.shape) - 0.5) * self.spacing
        if hasattr(volume, "bounds"):  # the axis-aligned box of a (possibly oblique) volume
            vlo, vhi = (np.asarray(b, dtype=np.float64) for b in volume.bounds)
        self.volume_bounds = (vlo, vhi)
        self._check_wires_in_box()

    def _check_wires_in_box(self) -> None:
        """Each wire's reach within the volume's diagonal, its base curve touching the
        volume box (a one-line WarpError naming the wire)."""
        vlo, vhi = self.volume_bounds
        diagonal = float(np.linalg.norm(vhi - vlo))
        for i, w in enumerate(self.wires):
            reach = w.radius * float(w.scale[:, 1].max())
            if reach > MAX_REACH_DIAGONALS * diagonal:
                raise WarpError(
                    f"wire {i}: radius x largest scale = {reach:.4g} mm, over the volume's"
                    f" diagonal ({diagonal:.4g} mm, the limit): give a radius in mm that"
                    " covers the object, not more"
                )
        for i, w in enumerate(self.wires):
            blo, bhi = _curve_box(w.base)
            if np.any(bhi < vlo) or np.any(blo > vhi):
                raise WarpError(
                    f"wire {i}'s base curve lies entirely outside the volume box"
                    f" {vlo.round(2).tolist()}..{vhi.round(2).tolist()} mm: lay it through"
                    " the object (control points are world mm, not voxel indices)"
                )

    def _check_layout_limits(self) -> None:
        """The paper layout's 4-bit wire id and segment index (a one-line WarpError)."""
        if self.layout != "paper":
            return
        if len(self.wires) > PAPER_MAX_WIRES:
            raise WarpError(
                f"layout='paper' holds at most {PAPER_MAX_WIRES} wires (4-bit wire id); got"
                f" {len(self.wires)}: use layout='packed' (up to {MAX_WIRES} wires)"
            )
        for i, w in enumerate(self.wires):
            if w.modified.n_segments > PAPER_MAX_SEGMENTS:
                raise WarpError(
                    f"layout='paper' holds at most {PAPER_MAX_SEGMENTS} segments per wire"
                    f" (4-bit segment index); wire {i}'s modified curve has"
                    f" {w.modified.n_segments}: use fewer control points or layout='packed'"
                )

    # ------------------------------------------------------------------ build
    def build(self) -> WireFieldStats:
        """Build the attribute field (planes, masks, seeds, propagation, flags, storage).

        Returns
        -------
        WireFieldStats
            Field size, planes kept/dropped, seeds, swept/vacated/ignored voxel counts and
            the time of each stage.
        """
        t_all = time.perf_counter()
        timings: dict[str, float] = {}
        self._check_layout_limits()  # the wires may have been edited since __init__
        t0 = time.perf_counter()
        tables = [w.tables(LUT_SIZE, self.precision) for w in self.wires]
        timings["tables"] = time.perf_counter() - t0

        # the whole reach within the field limit (a one-line WarpError naming the wires,
        # before masks as wide as that reach are allocated)
        self._field_geometry(tables, None)

        # 1-2. planes and their masks (per wire)
        t0 = time.perf_counter()
        masks, dropped, planes_total, mask_bytes = self._all_masks(tables)
        timings["masks"] = time.perf_counter() - t0
        self._warn_ends_inside(tables, masks)
        for w in self.wires:
            fold = w.side_fold_warning()
            if fold is not None:
                warnings.warn(fold, stacklevel=2)

        # the field's box: where the masks can bring the volume's content
        t0 = time.perf_counter()
        content = self.box == "content"
        lo, h, shape, inner = self._field_geometry(tables, masks if content else None)
        timings["box"] = time.perf_counter() - t0
        swept_side, vacated_side = self._sides_in(tables, masks, (lo, h, shape), timings)
        self.box_used = self.box
        if inner.any() and self._cuts_content(tables, swept_side, lo, h, shape, inner):
            self.box_used = "reach"
            lo, h, shape, _ = self._field_geometry(tables, None)
            swept_side, vacated_side = self._sides_in(tables, masks, (lo, h, shape), timings)
        region_lo, rshape, r_wire, r_u, swept, seed_count = swept_side
        b_lo, b_shape, vacated = vacated_side

        # 6. storage
        t0 = time.perf_counter()
        fld = store_field(
            self.layout, self.wires, tables, (lo, h, shape), swept_side, (b_lo, b_shape, vacated)
        )
        fld.weight, seam_faded = self._weights(
            tables, lo, h, shape, region_lo, rshape, r_wire, r_u, swept
        )
        timings["store"] = time.perf_counter() - t0
        timings["total"] = time.perf_counter() - t_all

        n_swept = int(swept.sum())
        n_vac = int(vacated.sum())
        self.field = fld
        self.stats = WireFieldStats(
            field_shape=shape,
            field_scale=self.field_scale,
            layout=self.layout,
            backend=last_backend(),
            planes=planes_total,
            planes_dropped=dropped,
            seeds=seed_count,
            region_voxels=int(np.prod(rshape)),
            swept=n_swept,
            vacated=n_vac,
            ignored=int(np.prod(shape)) - n_swept - n_vac,
            timings=timings,
            mask_bytes=tuple(mask_bytes),
            propagate=self.propagate,
            seam_faded=seam_faded,
        )
        if self._warp is not None:
            self._warp._set_field(fld)
        return self.stats

    def _sides_in(
        self,
        tables: list[WireTables],
        masks: list[tuple[np.ndarray, int, float]],
        box: tuple[np.ndarray, np.ndarray, tuple[int, int, int]],
        timings: dict[str, float],
    ) -> tuple[_SideResult, tuple[np.ndarray, tuple[int, int, int], np.ndarray]]:
        """Steps 3-5 in the field box ``box`` (lo, spacing, shape): seeds (the 8 voxels
        of every field cell a wire enters; the modified wires for the swept voxels, the
        base wires for the place the object leaves), then propagation and flags of both
        sides (:meth:`_both_sides`)."""
        lo, h, shape = box
        t0 = time.perf_counter()
        seeds_m = self._seeds(tables, lo, h, shape, "modified")
        seeds_b = self._seeds(tables, lo, h, shape, "base")
        timings["seeds"] = timings.get("seeds", 0.0) + time.perf_counter() - t0
        return self._both_sides(seeds_m, seeds_b, tables, masks, lo, h, shape, timings)

    def _all_masks(
        self, tables: list[WireTables]
    ) -> tuple[list[tuple[np.ndarray, int, float]], int, int, list[int]]:
        """Every wire's plane masks as (masks, K, half), the planes dropped, the planes
        in all, and each wire's mask memory in bytes."""
        masks: list[tuple[np.ndarray, int, float]] = []  # (planes, K, K) masks, K, half
        dropped = 0
        planes_total = 0
        mask_bytes = []
        for w, tab in zip(self.wires, tables, strict=True):
            mask, k_side, n_dropped = self._plane_masks(w, tab)
            masks.append((mask, k_side, (k_side - 1) / 2.0))
            dropped += n_dropped
            planes_total += mask.shape[0]
            # section 7.1: one bit per pixel of every kept plane
            mask_bytes.append(math.ceil((mask.shape[0] - n_dropped) * k_side * k_side / 8))
        return masks, dropped, planes_total, mask_bytes

    def _both_sides(
        self,
        seeds_m: tuple[np.ndarray, np.ndarray, np.ndarray],
        seeds_b: tuple[np.ndarray, np.ndarray, np.ndarray],
        tables: list[WireTables],
        masks: list[tuple[np.ndarray, int, float]],
        lo: np.ndarray,
        h: np.ndarray,
        shape: tuple[int, int, int],
        timings: dict[str, float],
    ) -> tuple[_SideResult, tuple[np.ndarray, tuple[int, int, int], np.ndarray]]:
        """Propagation of (wire, u) from the seeds over each side's region, then the
        flags: the mask bit under each voxel's projection on its plane. The swept side's
        result, and the vacated place (the base side's first voxel, shape and bits, less
        the swept voxels): the swept object's original place, the same masks seen from
        the base wires (not propagated at all when no wire vacates anything).

        A field voxel counts when its footprint touches a mask, not only its centre: the
        masks grow by half a field voxel (else the object's edges would be cut at coarse
        field scales, and thin parts of it, such as a fin's edge, would stay behind as a
        ghost); what this adds is the background around the object.
        """
        t0 = time.perf_counter()
        grow = math.ceil(0.5 * float(h.max()) / self.mask_resolution)
        # (a box dilated `grow` times is one box of side 2 grow + 1: separable maxima)
        grown = [
            (ndimage.maximum_filter(m, size=2 * grow + 1, mode="constant"), k, half)
            for m, k, half in masks
        ]
        timings["flags"] = time.perf_counter() - t0
        timings["propagate"] = 0.0
        swept_side = self._side(_SideJob(seeds_m, tables, grown, lo, h, shape, "modified", timings))
        region_lo, rshape, _, _, swept, _ = swept_side
        if not any(w.vacates for w in self.wires):  # smooth sides or vacated="rest"
            return swept_side, (region_lo, rshape, np.zeros(rshape, dtype=bool))
        b_lo, b_shape, _, _, gone, _ = self._side(
            _SideJob(seeds_b, tables, grown, lo, h, shape, "base", timings)
        )
        t0 = time.perf_counter()
        # vacated: the base side's bits, less the swept voxels (within the base box)
        vacated = gone
        both = _box_overlap(b_lo, b_shape, region_lo, rshape)
        if both is not None:
            vacated[both[0]] &= ~swept[both[1]]
        timings["flags"] += time.perf_counter() - t0
        return swept_side, (b_lo, b_shape, vacated)

    def classify_on_device(self) -> bool:
        """Whether :meth:`build` propagates and flags in one OpenCL pass (an OpenCL
        device with double precision), rather than with numpy."""

        return prop.opencl_available() and classify_available(prop._opencl_state())

    def warp(self) -> WireFieldWarp:
        """The warp that renders this deformer's field (built on first call if needed).

        The same object follows later :meth:`build` calls (its revision changes).
        """
        if self.field is None:
            self.build()
        if self._warp is None:
            # the warp module imports this one: its class comes from the warp registry
            self._warp = warp_class({"type": "wires"})(self)  # type: ignore[call-arg]
            if self.ctx is not None:
                self._warp.textures(self.ctx)
        return self._warp
