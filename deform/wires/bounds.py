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


class _MinMaxPyramid:
    """Min/max of per-voxel (n, 3) intervals over index boxes, by a mip pyramid: a box
    spanning e voxels is covered by at most 2 cells per axis at level ceil(log2 e)."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray) -> None:
        self.levels = [(lo, hi)]
        while max(lo.shape[:3]) > 1:
            lo = _halve(lo, np.minimum, np.inf)
            hi = _halve(hi, np.maximum, -np.inf)
            self.levels.append((lo, hi))

    def __call__(self, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ext = np.max(b - a + 1, axis=1)
        lev = np.ceil(np.log2(np.maximum(ext, 1))).astype(np.int64)
        lev = np.minimum(lev, len(self.levels) - 1)
        out_lo = np.full((len(a), 3), np.inf)
        out_hi = np.full((len(a), 3), -np.inf)
        for level in np.unique(lev):
            sel = lev == level
            lo_l, hi_l = self.levels[level]
            top = np.asarray(lo_l.shape[:3]) - 1
            ia, ib = np.minimum(a[sel] >> level, top), np.minimum(b[sel] >> level, top)
            r_lo = np.full((int(sel.sum()), 3), np.inf)
            r_hi = np.full((int(sel.sum()), 3), -np.inf)
            for c in _CORNERS:
                ix = np.where(c == 1, ib, ia)
                r_lo = np.minimum(r_lo, lo_l[ix[:, 0], ix[:, 1], ix[:, 2]])
                r_hi = np.maximum(r_hi, hi_l[ix[:, 0], ix[:, 1], ix[:, 2]])
            out_lo[sel], out_hi[sel] = r_lo, r_hi
        return out_lo, out_hi


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


class _AnyPyramid:
    """Whether any voxel of a 3D bool array is set within index boxes, by an OR pyramid
    (as :class:`_MinMaxPyramid`: a box spanning e voxels is covered by at most 2 cells
    per axis at level ceil(log2 e); conservative by those cells)."""

    def __init__(self, bits: np.ndarray) -> None:
        self.levels = [bits]
        while max(bits.shape) > 1:
            bits = _halve(bits, np.logical_or, False)
            self.levels.append(bits)

    def __call__(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Per box (first and last voxel index, (n, 3) each, within the array): any set."""
        ext = np.max(b - a + 1, axis=1)
        lev = np.ceil(np.log2(np.maximum(ext, 1))).astype(np.int64)
        lev = np.minimum(lev, len(self.levels) - 1)
        out = np.zeros(len(a), dtype=bool)
        for level in np.unique(lev):
            sel = lev == level
            bits = self.levels[level]
            top = np.asarray(bits.shape) - 1
            ia, ib = np.minimum(a[sel] >> level, top), np.minimum(b[sel] >> level, top)
            hit = np.zeros(int(sel.sum()), dtype=bool)
            for c in _CORNERS:
                ix = np.where(c == 1, ib, ia)
                hit |= bits[ix[:, 0], ix[:, 1], ix[:, 2]]
            out[sel] = hit
        return out
