"""Plane masks of the wire field build (wire paper sections 5, 7.1): planes
normal to the modified wire, β under their pixels, the 2.5D seed fill, and the mask test
of a voxel."""

from __future__ import annotations

import math
import warnings
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from scipy import ndimage

from voxwarp.deform.warp import WarpError
from voxwarp.deform.wires.constants import (
    LUT_SIZE,
    MASK_BLOCK_PIXELS,
    MASK_THREADS,
    MAX_MASK_PIXELS,
)
from voxwarp.deform.wires.geometry import _refine_u, side_tables
from voxwarp.deform.wires.tables import WireTables, _lerp_table
from voxwarp.deform.wires.wire import Wire


class PlaneMasks:
    """The plane-mask stages of :class:`~voxwarp.deform.wires.build.WireDeformer` (which
    sets these attributes)."""

    data: np.ndarray
    spacing: np.ndarray
    origin: np.ndarray
    _direction: np.ndarray
    wires: list[Wire]
    field_scale: int
    masks: bool
    mask_resolution: float
    dilation: int

    def _plane_masks(self, wire: Wire, tab: WireTables) -> tuple[np.ndarray, int, int]:
        """Masks (planes, K, K) of one wire, K and how many planes were dropped (no
        object)."""
        px = self.mask_resolution
        n_planes = max(2, math.ceil(tab.length_modified / px) + 1)
        smax = float(wire.scale[:, 1].max())
        half = math.ceil(wire.reach_at(smax) / px)
        k = 2 * half + 1
        if n_planes * k * k > MAX_MASK_PIXELS:
            raise WarpError(
                f"wire {wire.name or self.wires.index(wire)}: its masks would need"
                f" {n_planes:,} planes of {k}x{k} pixels, over the limit of"
                f" {MAX_MASK_PIXELS:,}; give a smaller radius or scale, a shorter modified"
                " wire, or a coarser mask_resolution"
            )
        ax = (np.arange(k) - half) * px
        x, y = np.meshgrid(ax, ax, indexing="ij")
        disc = x**2 + y**2 <= wire.reach_at(smax) ** 2
        # the radius is the region of influence on the base side: a scaled cross-section
        # covers s * radius on the modified side
        tt = np.linspace(0.0, LUT_SIZE - 1.0, n_planes)
        s_at = wire.scale_at(tt / (LUT_SIZE - 1))
        in_disc = (x[None] ** 2 + y[None] ** 2) <= wire.reach_at(s_at[:, None, None]) ** 2
        if wire.smooth_sides:  # no masks: everything within the reach moves
            return in_disc & disc[None], k, 0
        obj = self._object_pixels(wire, tab, tt, x[disc], y[disc], in_disc[:, disc])
        obj_full = np.zeros((n_planes, k, k), dtype=bool)
        obj_full[:, disc] = obj
        obj = obj_full
        # the object is chosen within the radius (as the rigid sweep does); a smooth
        # wire's fade beyond it takes the parts of the same objects that lie there
        core = (x[None] ** 2 + y[None] ** 2) <= (wire.radius * s_at[:, None, None]) ** 2
        mask, has = self._seed_fill(obj & core, x, y)
        # cavities (a vessel's lumen, a swim bladder) move with their object
        mask = _fill_holes_in_planes(mask)
        structure = np.zeros((3, 3, 3), dtype=bool)
        structure[1] = ndimage.generate_binary_structure(2, 1)
        if self.dilation:
            mask = ndimage.binary_dilation(mask, structure=structure, iterations=self.dilation)
            mask &= in_disc & disc[None]
        if wire.smooth:
            mask |= self._fade_pixels(obj, core, mask, structure) & in_disc
        mask[~has] = False
        return mask, k, int((~has).sum())

    def _seed_fill(
        self, obj: np.ndarray, x: np.ndarray, y: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The object pixels of the planes' masks (before holes and dilation) and which
        planes hold any: with ``masks``, the 2.5D seed fill; else every β pixel."""
        n_planes = obj.shape[0]
        if not self.masks:
            return obj.copy(), obj.reshape(n_planes, -1).any(axis=1)
        # seed: the object pixel nearest the wire on each plane ("searching outward
        # from the wire"); the fill is 2.5D: a plane's pixel joins when it connects,
        # in its plane or through the masks of the neighbouring planes, to a seed, so
        # an object that splits along the wire (a forked tail fin) stays whole,
        # while an object that never touches the seeded one (a neighbouring vessel)
        # stays out
        r2 = np.where(obj, (x**2 + y**2)[None], np.inf)
        flat = r2.reshape(n_planes, -1)
        seed = flat.argmin(axis=1)
        has = np.isfinite(flat[np.arange(n_planes), seed])
        labels, _ = ndimage.label(obj, structure=ndimage.generate_binary_structure(3, 1))
        seed_labels = np.unique(labels.reshape(n_planes, -1)[np.arange(n_planes), seed][has])
        keep = np.zeros(int(labels.max()) + 1, dtype=bool)
        keep[seed_labels[seed_labels > 0]] = True
        mask = keep[labels]
        return mask, mask.reshape(n_planes, -1).any(axis=1)

    def _fade_pixels(
        self, obj: np.ndarray, core: np.ndarray, mask: np.ndarray, structure: np.ndarray
    ) -> np.ndarray:
        """A smooth wire's mask pixels beyond its radius (``core``): the β pixels there
        that connect (2.5D) to the mask within it, or all of them without ``masks``;
        dilated as the mask is."""
        if self.masks:
            labels, _ = ndimage.label(obj, structure=ndimage.generate_binary_structure(3, 1))
            keep = np.zeros(int(labels.max()) + 1, dtype=bool)
            keep[labels[mask & obj]] = True
            keep[0] = False
            extra = keep[labels] & ~core
        else:
            extra = obj & ~core
        if self.dilation:
            extra = ndimage.binary_dilation(extra, structure=structure, iterations=self.dilation)
        return extra

    def _object_pixels(
        self,
        wire: Wire,
        tab: WireTables,
        tt: np.ndarray,
        x: np.ndarray,
        y: np.ndarray,
        in_disc: np.ndarray,
    ) -> np.ndarray:
        """β of the volume under the pixels (x, y) (mm, in the modified frame) of the
        planes at table coordinates ``tt``, (planes, pixels) bool; False outside the
        volume and outside ``in_disc``. Planes go in blocks (their temporaries stay in
        the cache; a few threads sample blocks at once, numpy and scipy release the GIL)
        and only pixels in the disc and the volume are sampled."""
        a, b = tab.lookup(tt)
        m = _lerp_table(tab.modified_points, tt)
        fm = _lerp_table(tab.modified_frames, tt)
        centre = np.einsum("pij,pj->pi", a, m) + b
        vlo = np.zeros(3) - 0.5
        vhi = np.asarray(self.data.shape) - 1.0 + 0.5
        # an identity rotation changes no bit of the product: skip it
        rotated = not np.array_equal(self._direction, np.eye(3))

        def sample(sl: slice) -> tuple[slice, np.ndarray, np.ndarray]:
            # deformed points p = M + x N_m + y B_m -> base points q = C + A (p - M)
            local = x[None, :, None] * fm[sl, None, :, 0] + y[None, :, None] * fm[sl, None, :, 1]
            q = centre[sl, None, :] + np.einsum("pij,pnj->pni", a[sl], local)
            ijk = ((q - self.origin) @ self._direction) if rotated else q - self.origin
            ijk /= self.spacing
            use = np.all((ijk >= vlo) & (ijk <= vhi), axis=-1) & in_disc[sl]
            return sl, use, _sample(self.data, ijk[use].T)

        out = np.zeros((len(tt), len(x)), dtype=bool)
        step = max(1, MASK_BLOCK_PIXELS // max(len(x), 1))
        blocks = [slice(p0, p0 + step) for p0 in range(0, len(tt), step)]
        with ThreadPoolExecutor(MASK_THREADS) as pool:
            for sl, use, vals in pool.map(sample, blocks):
                block = out[sl]
                block[use] = wire.classify(vals)  # β in this thread: it may be any callable
        return out

    def _mask_bits(
        self,
        wire: Wire,
        tab: WireTables,
        mask_geom: tuple[np.ndarray, int, float],
        u: np.ndarray,
        p: np.ndarray,
        side: str,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Refined closest-point fractions u of points p near ``wire`` (on ``side``) and
        whether the plane mask at u covers them.

        On the modified side the mask pixel is p's position in the modified frame; on
        the base side p's base-frame position is turned and scaled as the sweep does
        (``s R(θ)``) into the modified plane's pixels.
        """
        mask, k, half = mask_geom
        n_planes = mask.shape[0]
        px = self.mask_resolution
        points, frames, length = side_tables(tab, side)
        u = _refine_u(points, frames[:, :, 2], length, u, p)
        # the nearest table entry: its spacing (length / 255) is far below a mask pixel
        i = np.rint(u * (LUT_SIZE - 1)).astype(np.int64)
        f = frames.astype(np.float32)[i]
        d = (p - points[i]).astype(np.float32)
        x = np.einsum("ni,ni->n", d, f[:, :, 0])
        y = np.einsum("ni,ni->n", d, f[:, :, 1])
        z = np.einsum("ni,ni->n", d, f[:, :, 2])
        if side == "base":
            theta = wire.twist_at(u)
            s = wire.scale_at(u)
            c, si = np.cos(theta), np.sin(theta)
            x, y = s * (c * x - si * y), s * (si * x + c * y)
        plane = np.clip(np.rint(u * (n_planes - 1)).astype(np.int64), 0, n_planes - 1)
        a = np.rint(x / px + half).astype(np.int64)
        b = np.rint(y / px + half).astype(np.int64)
        ok = (a >= 0) & (a < k) & (b >= 0) & (b < k)
        # beyond the end planes nothing is swept (the along-wire offset stays within a
        # field voxel of the plane)
        cap = self._end_cap() + wire.end_reach(side)
        ends = (u <= 0.0) | (u >= 1.0)
        ok &= ~ends | (np.abs(z) <= cap)
        out = np.zeros(len(u), dtype=bool)
        out[ok] = mask[plane[ok], a[ok], b[ok]]
        return u, out

    def _warn_ends_inside(
        self, tables: list[WireTables], masks: list[tuple[np.ndarray, int, float]]
    ) -> None:
        """Warn (one line per end) where a rigid wire ends inside the object it sweeps
        and moves it there: the object under its end plane's mask goes on beyond the
        end, its cross-section moves (by more than half a voxel), and the rigid sweep
        cuts it there. An end at rest inside the object cuts nothing visible."""
        px = self.mask_resolution
        for wi, (w, tab, (mask, _, half)) in enumerate(zip(self.wires, tables, masks, strict=True)):
            if w.smooth:
                continue
            for end, plane, sign in (("start", 0, -1.0), ("end", -1, 1.0)):
                a, b = np.nonzero(mask[plane])
                if len(a) < 4:
                    continue
                i = 0 if plane == 0 else LUT_SIZE - 1
                fm = tab.modified_frames[i]
                step = sign * 3.0 * px * tab.length_modified / tab.length_base
                p = (
                    tab.modified_points[i]
                    + np.outer((a - half) * px, fm[:, 0])
                    + np.outer((b - half) * px, fm[:, 1])
                    + step * fm[:, 2]
                )
                q = p @ tab.matrices[i].T + tab.offsets[i]
                moves = np.linalg.norm(q - p, axis=1).max() > 0.5 * float(self.spacing.min())
                inside = self._beta_at(w, q)
                if moves and inside.sum() > max(4, 0.1 * len(a)):
                    label = f"{w.name!r}" if w.name else str(wi)
                    warnings.warn(
                        f"wire {label}: its {end} lies inside the object it sweeps"
                        f" ({100 * inside.mean():.0f}% of the end's cross-section goes on"
                        " past it), and the rigid sweep cuts the object there; use"
                        " ends='smooth' or extend the wire past the object",
                        stacklevel=3,
                    )

    def _beta_at(self, wire: Wire, q: np.ndarray) -> np.ndarray:
        """β of the volume at world points q (False outside the volume)."""
        rotated = not np.array_equal(self._direction, np.eye(3))
        ijk = ((q - self.origin) @ self._direction) if rotated else q - self.origin
        ijk = ijk / self.spacing
        use = np.all((ijk >= -0.5) & (ijk <= np.asarray(self.data.shape) - 0.5), axis=1)
        out = np.zeros(len(q), dtype=bool)
        if use.any():
            out[use] = wire.classify(_sample(self.data, ijk[use].T))
        return out


def _sample(data: np.ndarray, coords: np.ndarray) -> np.ndarray:
    """The volume's trilinear samples at index coordinates (3, n), as scipy's
    ``map_coordinates(order=1, mode="nearest", prefilter=False)`` gives them: compiled
    (:mod:`voxwarp.deform.wires.linear_sample`, the same bits) where the dtype allows."""
    from voxwarp.deform.wires import linear_sample  # numba: on the first build

    if linear_sample.supported(data):
        return linear_sample.sample_linear(data, coords)
    return ndimage.map_coordinates(data, coords, order=1, mode="nearest", prefilter=False)


def _fill_holes_in_planes(mask: np.ndarray) -> np.ndarray:
    """``mask`` (planes, K, K) with the holes of each plane filled: background pixels
    not 4-connected within their plane to the plane's edge (what
    ``ndimage.binary_fill_holes`` does with an in-plane structure, by one labelling)."""
    in_plane = np.zeros((3, 3, 3), dtype=bool)
    in_plane[1] = ndimage.generate_binary_structure(2, 1)
    labels, n = ndimage.label(~mask, structure=in_plane)
    outside = np.zeros(n + 1, dtype=bool)
    for edge in (labels[:, 0, :], labels[:, -1, :], labels[:, :, 0], labels[:, :, -1]):
        outside[edge] = True
    outside[0] = True  # the mask itself
    return mask | ~outside[labels]
