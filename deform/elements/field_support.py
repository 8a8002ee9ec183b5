"""Where an offset field's warp moves points: its support in deformed space, per box.

The warp (shaders/warp_offset_field.glsl) ends every evaluation with the step
``q = p - u(q')``, ``q'`` the previous iterate (or the baked seed), which lies within
``max |u|`` of ``p`` per axis. So ``warp(p) - p = -u(q')`` exceeds ``tol`` only where
``q'`` lies in a trilinear cell with a node ``|u| > tol``: the deformed support is that
rest-space region dilated by ``max |u|``. The region is widened by one cell for the
Jacobian's central differences (half a node spacing either side of ``q``), so shading
outside the support is the undeformed one too. numpy on the node grid: a prefix sum of
the moved cells answers each box in O(1).
"""

from __future__ import annotations

import numpy as np

#: half-float rounding of the displacement texture (2^-11 relative), with room to spare
HALF_SLACK = 2.0**-9


def moved_cells(u: np.ndarray, tol: float) -> np.ndarray:
    """(cx, cy, cz) bool: trilinear cells with a node moved more than ``tol`` mm on some
    axis (after half-float rounding), dilated by one cell."""
    node = np.any(np.abs(u) > tol * (1.0 - HALF_SLACK), axis=-1)
    cell = np.zeros(np.maximum(np.asarray(node.shape) - 1, 1), dtype=bool)
    n = cell.shape
    for o in range(8):
        i, j, k = o & 1, (o >> 1) & 1, (o >> 2) & 1
        cell |= node[i : i + n[0], j : j + n[1], k : k + n[2]]
    grown = cell.copy()
    for axis in range(3):  # one-cell dilation, axis by axis (a 3x3x3 cube)
        src = grown.copy()
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[axis], hi[axis] = slice(1, None), slice(None, -1)
        grown[tuple(lo)] |= src[tuple(hi)]
        grown[tuple(hi)] |= src[tuple(lo)]
    return grown


def boxes_touching(
    cells: np.ndarray, grid_lo: np.ndarray, spacing: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> np.ndarray:
    """(N,) bool: which boxes ``[lo_i, hi_i]`` (mm) touch a True cell of ``cells``, whose
    cell ``c`` spans ``grid_lo + c * spacing`` .. ``grid_lo + (c + 1) * spacing``."""
    n = np.asarray(cells.shape)
    a = np.floor((lo - grid_lo) / spacing)
    b = np.floor((hi - grid_lo) / spacing)
    outside = np.any((b < 0) | (a > n - 1), axis=1)
    a = np.clip(a, 0, n - 1).astype(np.int64)
    b = np.clip(b, 0, n - 1).astype(np.int64) + 1
    s = np.zeros(tuple(n + 1), dtype=np.int64)  # s[i, j, k] = cells below (i, j, k)
    s[1:, 1:, 1:] = cells.astype(np.int64).cumsum(0).cumsum(1).cumsum(2)
    total = np.zeros(len(lo), dtype=np.int64)
    for o in range(8):
        pick = [(o >> axis) & 1 for axis in range(3)]
        idx = [b[:, axis] if pick[axis] else a[:, axis] for axis in range(3)]
        sign = (-1) ** (3 - sum(pick))
        total += sign * s[idx[0], idx[1], idx[2]]
    return (total > 0) & ~outside


def field_support(
    u: np.ndarray,
    grid_lo: np.ndarray,
    spacing: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    tol: float,
) -> np.ndarray:
    """(N,) bool: the deformed-space boxes ``[lo_i, hi_i]`` in which the warp of the node
    field ``u`` ((nx, ny, nz, 3) mm, nodes at ``grid_lo + index * spacing``) may move a
    point by more than ``tol`` mm (see the module docstring)."""
    lo, hi = np.atleast_2d(lo).astype(float), np.atleast_2d(hi).astype(float)
    cells = moved_cells(u, tol)
    if not cells.any():
        return np.zeros(len(lo), dtype=bool)
    reach = np.abs(u).reshape(-1, 3).max(axis=0) * (1.0 + HALF_SLACK) + 1e-9
    return boxes_touching(cells, np.asarray(grid_lo, float), spacing, lo - reach, hi + reach)
