"""Oracles shared by the ChainMail tests: what a model's links allow each element."""

from __future__ import annotations

import numpy as np

from voxwarp.deform.elements.chainmail_model import ChainMailModel


def link_bounds(model: ChainMailModel, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per element and coordinate, the intersection of its links' intervals."""
    lo = np.full(x.shape, -np.inf)
    hi = np.full(x.shape, np.inf)
    for axis in range(3):
        if model.shape[axis] < 2:
            continue
        mn, mx, sh, linked = model.link_limits(axis)
        low = np.stack([mn if c == axis else -sh for c in range(3)], axis=-1)
        high = np.stack([mx if c == axis else sh for c in range(3)], axis=-1)
        a_t, b_t = link_ends(axis)
        on = linked[..., None]
        xa, xb = x[a_t], x[b_t]
        lo[b_t] = np.where(on, np.maximum(lo[b_t], xa + low), lo[b_t])
        hi[b_t] = np.where(on, np.minimum(hi[b_t], xa + high), hi[b_t])
        lo[a_t] = np.where(on, np.maximum(lo[a_t], xb - high), lo[a_t])
        hi[a_t] = np.where(on, np.minimum(hi[a_t], xb - low), hi[a_t])
    return lo, hi


def link_ends(axis: int) -> tuple[tuple[slice, ...], tuple[slice, ...]]:
    """Index tuples of the lower and the upper element of every link along ``axis``."""
    a = [slice(None)] * 3
    b = [slice(None)] * 3
    a[axis] = slice(0, -1)
    b[axis] = slice(1, None)
    return tuple(a), tuple(b)
