"""Displacement bounds of a wire field per box (the raycaster's empty-space
skipping through the deformed volume)."""

from __future__ import annotations

from typing import Any

import numpy as np

from voxwarp.deform.wires.constants import FLOAT32_MARGIN, LUT_SIZE, MAX_T_STEPS
from voxwarp.deform.wires.geometry import _CORNERS
from voxwarp.deform.wires.tables import WireTables

#: boxes per chunk of :func:`_box_mapping_range`
MAPPING_CHUNK = 1 << 16


def _grow(bound: np.ndarray, sign: float) -> np.ndarray:
    """A displacement bound moved outwards (``sign``) by :data:`FLOAT32_MARGIN`, except
    where it is 0 up to float64 noise: an identity mapping is exact in float32 too (its
    table holds exact ones and zeros), and a margin there would widen the skip maps'
    windows by a whole cell."""
    exact = np.abs(bound) < 1e-9
    return np.where(exact, 0.0, bound + sign * FLOAT32_MARGIN)


def _box_mapping_range(
    tables: list[WireTables],
    wire: np.ndarray,
    t_lo: np.ndarray,
    t_hi: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Per box, the range of ``A(t) p + b(t) - p`` over p in [lo, hi] and t in
    [t_lo, t_hi] of one wire.

    For a fixed t the displacement is linear in p, so over the box it is its value at
    the centre plus or minus ``|A - I|`` times the half extent; between table entries it
    is linear in t, so its extremes lie at the table entries from floor(t_lo) to
    ceil(t_hi) (which also hold what the GPU's filtered, 8-bit-weighted lookups of t and
    of the table can return). Ranges over more than :data:`MAX_T_STEPS` entries take the
    whole table.
    """
    out_lo = np.full((len(lo), 3), np.inf)
    out_hi = np.full((len(lo), 3), -np.inf)
    centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    top = LUT_SIZE - 1.0
    first = np.floor(t_lo)
    last = np.minimum(np.ceil(t_hi), top)
    wide = last - first > MAX_T_STEPS
    first, last = np.where(wide, 0.0, first), np.where(wide, top, last)
    for wi in np.unique(wire):
        tab = tables[int(wi)]
        # the table at whole entries (what its lookup gives there, bit for bit)
        mats, offs = tab.matrices, tab.offsets
        spread = np.abs(mats - np.eye(3))
        for narrow in (True, False):
            sel = np.nonzero((wire == wi) & (wide != narrow))[0]
            # in chunks: a few MB of temporaries per step, not the whole box list's
            for at in range(0, len(sel), MAPPING_CHUNK):
                part = sel[at : at + MAPPING_CHUNK]
                c, h = centre[part], half[part]
                f, g = first[part].astype(np.int64), last[part].astype(np.int64)
                p_lo, p_hi = out_lo[part], out_hi[part]
                for k in range(int((g - f).max()) + 1):
                    i = np.minimum(f + k, g)
                    d = np.einsum("nij,nj->ni", mats[i], c) + offs[i] - c
                    e = np.einsum("nij,nj->ni", spread[i], h)
                    np.minimum(p_lo, d - e, out=p_lo)
                    np.maximum(p_hi, d + e, out=p_hi)
                out_lo[part], out_hi[part] = p_lo, p_hi
    return out_lo, out_hi


class _ReducePyramid:
    """Reductions of 3D arrays (a trailing channel axis allowed) over index boxes, by a
    mip pyramid per array: a box spanning e voxels is covered by at most 2 cells per axis
    at level ceil(log2 e), so an answer is conservative by those cells. ``channels``:
    (array, reduction, its identity), e.g. (lo, np.minimum, np.inf)."""

    def __init__(self, *channels: tuple[np.ndarray, Any, Any]) -> None:
        self.ops = [(op, fill) for _, op, fill in channels]
        arrays = [x for x, _, _ in channels]
        self.levels = [arrays]
        while max(arrays[0].shape[:3]) > 1:
            arrays = [_halve(x, op, fill) for x, (op, fill) in zip(arrays, self.ops, strict=True)]
            self.levels.append(arrays)

    def __call__(self, a: np.ndarray, b: np.ndarray) -> list[np.ndarray]:
        """Per channel, the reduction over each box (first and last voxel index, (n, 3)
        each, within the arrays); float channels come back as float64."""
        ext = np.max(b - a + 1, axis=1)
        lev = np.ceil(np.log2(np.maximum(ext, 1))).astype(np.int64)
        lev = np.minimum(lev, len(self.levels) - 1)
        outs = [
            np.full((len(a), *x.shape[3:]), fill, dtype=bool if x.dtype == bool else np.float64)
            for x, (_, fill) in zip(self.levels[0], self.ops, strict=True)
        ]
        for level in np.unique(lev):
            sel = lev == level
            arrays = self.levels[level]
            top = np.asarray(arrays[0].shape[:3]) - 1
            ia, ib = np.minimum(a[sel] >> level, top), np.minimum(b[sel] >> level, top)
            corners = [tuple(np.where(c == 1, ib, ia).T) for c in _CORNERS]
            for out, x, (op, _) in zip(outs, arrays, self.ops, strict=True):
                r = out[sel]
                for ix in corners:
                    r = op(r, x[ix])
                out[sel] = r
        return outs


class _MinMaxPyramid:
    """Min/max of per-voxel (n, 3) intervals over index boxes (:class:`_ReducePyramid`)."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray) -> None:
        self._pyramid = _ReducePyramid((lo, np.minimum, np.inf), (hi, np.maximum, -np.inf))

    def __call__(self, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = self._pyramid(a, b)
        return lo, hi


class _AnyPyramid:
    """Whether any voxel of a 3D bool array is set within index boxes
    (:class:`_ReducePyramid` of logical or)."""

    def __init__(self, bits: np.ndarray) -> None:
        self._pyramid = _ReducePyramid((bits, np.logical_or, False))

    def __call__(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Per box (first and last voxel index, (n, 3) each, within the array): any set."""
        return self._pyramid(a, b)[0]


def _halve(a: np.ndarray, op: Any, fill: float) -> np.ndarray:
    for axis in range(3):
        n = a.shape[axis]
        if n == 1:
            continue
        if n % 2:
            pad = [(0, 0)] * a.ndim
            pad[axis] = (0, 1)
            a = np.pad(a, pad, constant_values=fill)
        sl0 = [slice(None)] * a.ndim
        sl1 = [slice(None)] * a.ndim
        sl0[axis] = slice(0, None, 2)
        sl1[axis] = slice(1, None, 2)
        a = op(a[tuple(sl0)], a[tuple(sl1)])
    return a
