"""Helpers for displacements stored on a regular node grid, shared by every dense warp
(the offset field, lattices, imported displacement fields): the half-float range check
and per-cell / sliding-window reductions (bounds for empty-space skipping)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from voxwarp.deform.warp import WarpError

#: Largest displacement a half-float texture holds (mm).
MAX_DISPLACEMENT_MM = 6.0e4


def check_vectors(u: np.ndarray, units_hint: str) -> None:
    """Raise :class:`WarpError` for NaN/Inf displacements or ones beyond
    :data:`MAX_DISPLACEMENT_MM` (the half-float texture); ``units_hint`` ends the latter."""
    bad = int(np.count_nonzero(~np.isfinite(u)))
    if bad:
        first = np.argwhere(~np.isfinite(u))[0][:3].tolist()
        raise WarpError(
            f"the displacements have {bad} NaN/Inf entries (the first at node {first});"
            " fix the field"
        )
    if np.max(np.abs(u), initial=0.0) > MAX_DISPLACEMENT_MM:
        raise WarpError(
            f"displacements above {MAX_DISPLACEMENT_MM:g} mm do not fit the half-float"
            f" texture; {units_hint}"
        )


def cell_reduce(node: np.ndarray, op: Any) -> np.ndarray:
    """Per grid cell, ``op`` over its (up to) 8 corner nodes; (cells..., 3)."""
    cell = node
    for axis in range(3):
        if cell.shape[axis] > 1:
            a = np.moveaxis(cell, axis, 0)
            cell = np.moveaxis(op(a[:-1], a[1:]), 0, axis)
    return cell


def _part(ndim: int, axis: int, start: int, stop: int | None) -> tuple[slice, ...]:
    """Index of ``start:stop`` along ``axis`` of an ``ndim``-array."""
    sl = [slice(None)] * ndim
    sl[axis] = slice(start, stop)
    return tuple(sl)


def window_reduce(
    cell: np.ndarray,
    width: Sequence[int],
    op: Any,
    cache: dict[tuple, np.ndarray] | None = None,
) -> np.ndarray:
    """Forward window reduction: ``out[i] = op(cell[i : i + width])`` per axis (clamped
    at the end). Power-of-two widths take log2 doubling steps per axis, in place on
    slices (no transposed copies); ``cache`` keeps the passes of width prefixes (x,
    then x and y) for the next call."""
    m = cell
    for axis in range(3):
        key = tuple(width[: axis + 1])
        if cache is not None and key in cache:
            m = cache[key]
            continue
        w = int(width[axis])
        if w > 1:
            src = m
            m = m.copy()
            nd = m.ndim
            if w & (w - 1) == 0:  # doubling: spans 1, 2, 4, ... reach w
                span = 1
                while span < w and span < m.shape[axis]:
                    head, tail = _part(nd, axis, 0, -span), _part(nd, axis, span, None)
                    op(m[head], m[tail], out=m[head])
                    span *= 2
            else:
                for k in range(1, min(w, m.shape[axis])):
                    head, tail = _part(nd, axis, 0, -k), _part(nd, axis, k, None)
                    op(m[head], src[tail], out=m[head])
        if cache is not None:
            cache[key] = m
    return m
