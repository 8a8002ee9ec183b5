"""The numpy builders of the skip maps, for volumes below
:data:`voxwarp.render.skipping.maps.COMPILED_MIN_SIZE` (the maths and the public functions are
:mod:`voxwarp.render.skipping.maps`, which picks these or the compiled kernels of
:mod:`voxwarp.render.skipping.kernels`; both give the same arrays). A small volume's first
render then needs neither numba nor its start-up; these make full-size temporaries
(int16 and padded copies), which only a small volume can afford.
"""

from __future__ import annotations

from typing import Any

import numpy as np

Octant = tuple[int, int, int]


def block_min_max(data: np.ndarray, block: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-block (min, max) with a one-voxel apron, float32 (one axis at a time)."""
    lo = np.asarray(data)
    hi = lo
    for axis in range(3):
        lo = _reduce_axis(lo, axis, block, np.minimum)
        hi = _reduce_axis(hi, axis, block, np.maximum)
    return lo.astype(np.float32), hi.astype(np.float32)


def _reduce_axis(a: np.ndarray, axis: int, block: int, op: Any) -> np.ndarray:
    n = a.shape[axis]
    nb = -(-n // block)
    pad = nb * block - n
    a = np.moveaxis(a, axis, 0)
    if pad:
        a = np.concatenate([a, np.repeat(a[-1:], pad, axis=0)], axis=0)
    r = op.reduce(a.reshape(nb, block, *a.shape[1:]), axis=1)
    if nb > 1:
        prev_last = a[block - 1 : (nb - 1) * block : block]
        next_first = a[block : nb * block : block]
        r[1:] = op(r[1:], prev_last)
        r[:-1] = op(r[:-1], next_first)
    return np.moveaxis(r, 0, axis)


def cell_min_max(data: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per trilinear cell (min, max) of its 8 corner voxels (n + 1 per axis), data dtype."""
    p = np.pad(np.asarray(data), 1, mode="edge")
    lo = hi = None
    for i in (0, 1):
        for j in (0, 1):
            for k in (0, 1):
                v = p[i : i + p.shape[0] - 1, j : j + p.shape[1] - 1, k : k + p.shape[2] - 1]
                lo = v if lo is None else np.minimum(lo, v)
                hi = v if hi is None else np.maximum(hi, v)
    return lo, hi  # type: ignore[return-value]


def _flip(signs: Octant) -> tuple[slice, ...]:
    return tuple(slice(None, None, -1) if s < 0 else slice(None) for s in signs)


def _forward_chessboard(g: np.ndarray, cap: int) -> np.ndarray:
    """``min over 0 <= k < cap of max(k, g[c + k])`` along x, y and z in turn (uint8)."""
    src = np.ascontiguousarray(g, dtype=np.uint8).copy()
    out = src.copy()
    tmp = np.empty_like(src)
    for axis in range(3):
        n = src.shape[axis]
        for k in range(1, min(cap, n)):
            head = [slice(None)] * 3
            tail = [slice(None)] * 3
            head[axis] = slice(0, n - k)
            tail[axis] = slice(k, n)
            t = tmp[tuple(head)]
            np.maximum(src[tuple(tail)], np.uint8(k), out=t)
            np.minimum(out[tuple(head)], t, out=out[tuple(head)])
        src[...] = out
    return out


def octant_skip_distances(
    visible: np.ndarray, signs: Octant, cell_cap: int, block: int
) -> np.ndarray:
    """Octant skip distances (see :func:`voxwarp.render.skipping.maps.octant_skip_distances`),
    in the frame flipped towards ``signs``."""
    visible = np.asarray(visible, dtype=bool)
    flip = _flip(signs)
    v = np.ascontiguousarray(visible[flip])
    cap = int(min(max(cell_cap, 1), 255))
    near = _forward_chessboard(np.where(v, 0, cap).astype(np.uint8), cap)
    shape = v.shape
    nb = tuple(-(-n // block) for n in shape)
    padded = np.zeros(tuple(b * block for b in nb), dtype=bool)
    padded[: shape[0], : shape[1], : shape[2]] = v
    bvis = padded.reshape(nb[0], block, nb[1], block, nb[2], block).any(axis=(1, 3, 5))
    far_cap = min(-(-(255 + block - 1) // block), 255)
    far = _forward_chessboard(np.where(bvis, 0, far_cap).astype(np.uint8), far_cap)
    r = far.astype(np.int16) * block
    r = r.repeat(block, 0).repeat(block, 1).repeat(block, 2)[: shape[0], : shape[1], : shape[2]]
    offs = [np.arange(n, dtype=np.int16) % block for n in shape]
    inner = np.maximum(
        np.maximum(offs[0][:, None, None], offs[1][None, :, None]), offs[2][None, None, :]
    )
    r -= inner
    bound = np.clip(r, 0, 255).astype(np.uint8)
    out = np.maximum(near, bound)
    return np.ascontiguousarray(out[flip])


def _grow(mask: np.ndarray) -> np.ndarray:
    """``mask`` dilated by its 26 neighbours (one step of the chessboard metric)."""
    out = mask
    for axis in range(mask.ndim):
        grown = out.copy()
        lead = [slice(None)] * mask.ndim
        lag = [slice(None)] * mask.ndim
        lead[axis], lag[axis] = slice(1, None), slice(None, -1)
        grown[tuple(lead)] |= out[tuple(lag)]
        grown[tuple(lag)] |= out[tuple(lead)]
        out = grown
    return out


def block_skip_distances(visible: np.ndarray) -> np.ndarray:
    """Chessboard distance to the nearest visible block, capped at 255, by growing the
    visible set one chessboard step at a time (exact; no scipy import on the path of a
    small volume's first render)."""
    d = np.full(visible.shape, 255, dtype=np.uint8)
    reach = np.asarray(visible, dtype=bool)
    d[reach] = 0
    for r in range(1, 255):
        grown = _grow(reach)
        new = grown & ~reach
        if not new.any():
            break
        d[new] = r
        reach = grown
    return d
