"""Compiled (numba) kernels behind the skip maps of :mod:`voxwarp.render.skipping.maps`.

A module of its own so that importing the raycaster does not import numba: it loads
on the first skip map a renderer builds. Every kernel works in *texture order*: a
C-contiguous ``(nz, ny, nx)`` array, x fastest (a :class:`voxwarp.core.volume.Volume`'s
``data.T``, no copy), and writes its result in that order, so the maps go to the GPU
without a transposed copy. No kernel makes a full-volume float copy; the octant map is
built in place in its own output array.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from voxwarp.deform.parallel import threadsafe


@threadsafe
@njit(parallel=True, cache=True, nogil=True)
def block_range(
    t: np.ndarray, block: int, lo: np.ndarray, hi: np.ndarray
) -> None:  # pragma: no cover
    """Per-block (min, max) of ``t`` (nz, ny, nx) with a one-voxel apron into ``lo``/``hi``
    (nbz, nby, nbx): block ``b`` covers voxels ``[b*block - 1, (b+1)*block]`` (clamped)
    per axis. Per block slab, whole rows are reduced along z, then y, then x."""
    nz, ny, nx = t.shape
    nbz, nby, nbx = lo.shape
    for i in prange(nbz):
        bz = np.int64(i)  # prange indices may be unsigned: bz * block - 1 must stay an int
        z0 = max(bz * block - 1, 0)
        z1 = min((bz + 1) * block + 1, nz)
        zlo = t[z0].copy()
        zhi = t[z0].copy()
        for z in range(z0 + 1, z1):
            src = t[z]
            for y in range(ny):
                for x in range(nx):
                    zlo[y, x] = min(zlo[y, x], src[y, x])
                    zhi[y, x] = max(zhi[y, x], src[y, x])
        ylo = np.empty(nx, dtype=t.dtype)
        yhi = np.empty(nx, dtype=t.dtype)
        for by in range(nby):
            y0 = max(by * block - 1, 0)
            y1 = min((by + 1) * block + 1, ny)
            ylo[:] = zlo[y0]
            yhi[:] = zhi[y0]
            for y in range(y0 + 1, y1):
                for x in range(nx):
                    ylo[x] = min(ylo[x], zlo[y, x])
                    yhi[x] = max(yhi[x], zhi[y, x])
            for bx in range(nbx):
                x0 = max(bx * block - 1, 0)
                x1 = min((bx + 1) * block + 1, nx)
                a = ylo[x0]
                b = yhi[x0]
                for x in range(x0 + 1, x1):
                    a = min(a, ylo[x])
                    b = max(b, yhi[x])
                lo[bz, by, bx] = a
                hi[bz, by, bx] = b


@njit(cache=True, nogil=True)
def _cell_rows(
    t: np.ndarray, cz: int, zlo: np.ndarray, zhi: np.ndarray, rlo: np.ndarray, rhi: np.ndarray
) -> None:  # pragma: no cover
    """Into ``rlo``/``rhi`` (ny + 1, nx + 1): the (min, max) of the 8 voxels of the cells
    of z index ``cz`` (cell ``c`` reads voxels ``c - 1`` and ``c`` per axis, clamped);
    ``zlo``/``zhi`` (ny, nx) are scratch."""
    nz, ny, nx = t.shape
    za = t[max(cz - 1, 0)]
    zb = t[min(cz, nz - 1)]
    for y in range(ny):
        for x in range(nx):
            zlo[y, x] = min(za[y, x], zb[y, x])
            zhi[y, x] = max(za[y, x], zb[y, x])
    for cy in range(ny + 1):
        ya = max(cy - 1, 0)
        yb = min(cy, ny - 1)
        lo = rlo[cy]
        hi = rhi[cy]
        lo[0] = min(zlo[ya, 0], zlo[yb, 0])
        hi[0] = max(zhi[ya, 0], zhi[yb, 0])
        for x in range(1, nx):
            lo[x] = min(min(zlo[ya, x - 1], zlo[yb, x - 1]), min(zlo[ya, x], zlo[yb, x]))
            hi[x] = max(max(zhi[ya, x - 1], zhi[yb, x - 1]), max(zhi[ya, x], zhi[yb, x]))
        lo[nx] = min(zlo[ya, nx - 1], zlo[yb, nx - 1])
        hi[nx] = max(zhi[ya, nx - 1], zhi[yb, nx - 1])


@threadsafe
@njit(parallel=True, cache=True, nogil=True)
def cell_range(t: np.ndarray, z0: int, lo: np.ndarray, hi: np.ndarray) -> None:  # pragma: no cover
    """(min, max) of the 8 voxels of trilinear cells ``z0 .. z0 + len(lo)`` (z) and every
    y and x cell into ``lo``/``hi`` (cz, ny + 1, nx + 1); cell ``c`` reads voxels
    ``c - 1`` and ``c`` per axis (clamped)."""
    _, ny, nx = t.shape
    for i in prange(lo.shape[0]):
        zlo = np.empty((ny, nx), dtype=t.dtype)
        zhi = np.empty((ny, nx), dtype=t.dtype)
        _cell_rows(t, z0 + np.int64(i), zlo, zhi, lo[i], hi[i])


@threadsafe
@njit(parallel=True, cache=True, nogil=True)
def cell_visibility_table(
    t: np.ndarray, vmin: int, first_hi: np.ndarray, out: np.ndarray
) -> None:  # pragma: no cover
    """Visibility of every trilinear cell of integer data ``t`` into ``out``
    (nz + 1, ny + 1, nx + 1): a cell with value range [lo, hi] is visible when
    ``hi >= first_hi[lo - vmin]`` (the lowest visible upper end for that lower end)."""
    nz, ny, nx = t.shape
    for i in prange(nz + 1):
        zlo = np.empty((ny, nx), dtype=t.dtype)
        zhi = np.empty((ny, nx), dtype=t.dtype)
        rlo = np.empty((ny + 1, nx + 1), dtype=t.dtype)
        rhi = np.empty((ny + 1, nx + 1), dtype=t.dtype)
        _cell_rows(t, np.int64(i), zlo, zhi, rlo, rhi)
        plane = out[i]
        for cy in range(ny + 1):
            for cx in range(nx + 1):
                plane[cy, cx] = np.int64(rhi[cy, cx]) >= first_hi[np.int64(rlo[cy, cx]) - vmin]


@threadsafe
@njit(parallel=True, cache=True, nogil=True)
def flipped_blocks(
    vis: np.ndarray, bz: np.ndarray, by: np.ndarray, bx: np.ndarray, out: np.ndarray
) -> None:  # pragma: no cover
    """``out[B] = any vis`` over the cells whose (flipped-frame) block is ``B``:
    ``bz[z]``, ``by[y]``, ``bx[x]`` map a cell index to its block index."""
    nz, ny, nx = vis.shape
    for j in prange(out.shape[0]):
        acc = np.zeros((ny, nx), dtype=np.uint8)
        for z in range(nz):
            if bz[z] != j:
                continue
            src = vis[z]
            for y in range(ny):
                for x in range(nx):
                    acc[y, x] |= src[y, x]
        rows = np.zeros((out.shape[1], nx), dtype=np.uint8)
        for y in range(ny):
            row = rows[by[y]]
            for x in range(nx):
                row[x] |= acc[y, x]
        for b in range(out.shape[1]):
            for x in range(nx):
                out[j, b, bx[x]] |= rows[b, x]


@threadsafe
@njit(parallel=True, cache=True, nogil=True)
def scan_z(vis: np.ndarray, sign: int, cap: int, out: np.ndarray) -> None:  # pragma: no cover
    """First 1D pass (z): ``out = min(cap, steps to the nearest visible cell at
    z + sign * k, k >= 0)`` (``vis`` nonzero = visible), whole rows at a time."""
    nz, ny, nx = vis.shape
    for y in prange(ny):
        d = np.full(nx, cap, dtype=np.uint8)
        top = np.uint8(cap)
        one = np.uint8(1)
        zero = np.uint8(0)
        for i in range(nz):
            z = nz - 1 - i if sign > 0 else i
            src = vis[z, y]
            row = out[z, y]
            for x in range(nx):  # uint8 selects only: vectorised
                e = d[x]
                e = e + one if e < top else top
                e = zero if src[x] else e
                d[x] = e
                row[x] = e


@njit(cache=True, nogil=True, inline="always")
def _min_max_row(dst: np.ndarray, src: np.ndarray, k: np.uint8) -> None:  # pragma: no cover
    """``dst = min(dst, max(k, src))`` elementwise on uint8 rows (selects: vectorised)."""
    for x in range(dst.shape[0]):
        v = src[x]
        v = v if v > k else k
        w = dst[x]
        dst[x] = w if w < v else v


@threadsafe
@njit(parallel=True, cache=True, nogil=True)
def pass_y(a: np.ndarray, sign: int, cap: int) -> None:  # pragma: no cover
    """1D pass along y in place: ``a[c] = min over 0 <= k < cap of max(k, a[c + sign k e_y])``
    (shifts leaving the array ignored). Rows go in the direction that reads only rows
    not yet rewritten."""
    nz, ny, nx = a.shape
    for z in prange(nz):
        tmp = np.empty(nx, dtype=np.uint8)
        for i in range(ny):
            y = i if sign > 0 else ny - 1 - i
            tmp[:] = a[z, y]
            for k in range(1, cap):
                yy = y + sign * k
                if yy < 0 or yy >= ny:
                    break
                _min_max_row(tmp, a[z, yy], np.uint8(k))
            a[z, y] = tmp


@threadsafe
@njit(parallel=True, cache=True, nogil=True)
def pass_x(a: np.ndarray, sign: int, cap: int) -> None:  # pragma: no cover
    """1D pass along x in place (as :func:`pass_y`), each row from a copy of itself."""
    nz, ny, nx = a.shape
    for z in prange(nz):
        src = np.empty(nx, dtype=np.uint8)
        for y in range(ny):
            dst = a[z, y]
            src[:] = dst
            for k in range(1, min(cap, nx)):
                if sign > 0:
                    _min_max_row(dst[: nx - k], src[k:], np.uint8(k))
                else:
                    _min_max_row(dst[k:], src[: nx - k], np.uint8(k))


@threadsafe
@njit(parallel=True, cache=True, nogil=True)
def raise_to_block_bound(
    a: np.ndarray,
    far: np.ndarray,
    bz: np.ndarray,
    by: np.ndarray,
    bx: np.ndarray,
    oz: np.ndarray,
    oy: np.ndarray,
    ox: np.ndarray,
    block: int,
) -> None:  # pragma: no cover
    """``a = max(a, clip(far[block of c] * block - max_i(offset_i of c), 0, 255))``: the
    cell bound of the block-level map (``bz``.. map cells to blocks, ``oz``.. give the
    cell's offset in its block, all in the flipped frame)."""
    nz, ny, nx = a.shape
    for z in prange(nz):
        fx = np.empty(nx, dtype=np.int32)
        for y in range(ny):
            frow = far[bz[z], by[y]]
            base = max(oz[z], oy[y])
            for x in range(nx):
                fx[x] = np.int32(frow[bx[x]]) * block - max(base, ox[x])
            row = a[z, y]
            for x in range(nx):
                row[x] = min(max(fx[x], np.int32(row[x])), 255)


@njit(cache=True, nogil=True)
def chessboard_distance(vis: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    """Chessboard distance from every element of ``vis`` (nonzero = visible) to the
    nearest visible one into ``out`` (int32, large where none is visible): the exact
    two-pass chamfer transform with the 26-neighbourhood and unit steps (as
    ``scipy.ndimage.distance_transform_cdt(metric="chessboard")``)."""
    nz, ny, nx = vis.shape
    big = np.int32(nz + ny + nx + 1)
    for z in range(nz):
        for y in range(ny):
            for x in range(nx):
                out[z, y, x] = 0 if vis[z, y, x] else big
    for z in range(nz):  # forward: the 13 neighbours already visited
        for y in range(ny):
            for x in range(nx):
                d = out[z, y, x]
                if d == 0:
                    continue
                for dz in range(-1, 1):
                    for dy in range(-1, 2):
                        for dx in range(-1, 2):
                            if dz == 0 and (dy > 0 or (dy == 0 and dx >= 0)):
                                continue
                            zz, yy, xx = z + dz, y + dy, x + dx
                            if 0 <= zz and 0 <= yy < ny and 0 <= xx < nx:
                                d = min(d, out[zz, yy, xx] + 1)
                out[z, y, x] = d
    for z in range(nz - 1, -1, -1):  # backward: the other 13
        for y in range(ny - 1, -1, -1):
            for x in range(nx - 1, -1, -1):
                d = out[z, y, x]
                if d == 0:
                    continue
                for dz in range(0, 2):
                    for dy in range(-1, 2):
                        for dx in range(-1, 2):
                            if dz == 0 and (dy < 0 or (dy == 0 and dx <= 0)):
                                continue
                            zz, yy, xx = z + dz, y + dy, x + dx
                            if zz < nz and 0 <= yy < ny and 0 <= xx < nx:
                                d = min(d, out[zz, yy, xx] + 1)
                out[z, y, x] = d


@njit(cache=True, nogil=True, inline="always")
def _clipped_window(c: int, lo: int, hi: int, q0: int, q1: int) -> tuple:  # pragma: no cover
    """One axis of cell c's window [c + lo, c + hi + 1), clipped to [q0, q1] and made
    relative to q0 (never ending before it starts)."""
    a = min(max(c + lo, q0), q1) - q0
    return a, max(min(max(c + hi + 1, q0), q1) - q0, a)


@njit(cache=True, nogil=True)
def window_cells(
    out: np.ndarray,
    sat: np.ndarray,
    q0: np.ndarray,
    q1: np.ndarray,
    blocks: np.ndarray,
    lo_off: np.ndarray,
    hi_off: np.ndarray,
    block: int,
) -> None:  # pragma: no cover
    """Each cell c of the ``block``³ blocks (block indices (n, 3), in ``out``'s index
    order) is set to whether the window [c + lo_off, c + hi_off + 1) of its block holds
    a visible cell, from the summed-area table ``sat`` over [q0, q1] (windows clipped to
    it, as :func:`voxwarp.render.skipping.maps.warped_cell_visibility`'s numpy count).

    Serial: a version threaded over the blocks made the second frame after a wire edit
    no faster (``docs/benchmarks.md``, "A new CPU, its OpenCL driver and the wire
    build")."""
    nx, ny, nz = out.shape
    for n in range(blocks.shape[0]):
        for i in range(block):
            cx = blocks[n, 0] * block + i
            if cx >= nx:
                continue
            ax, bx = _clipped_window(cx, lo_off[n, 0], hi_off[n, 0], q0[0], q1[0])
            for j in range(block):
                cy = blocks[n, 1] * block + j
                if cy >= ny:
                    continue
                ay, by = _clipped_window(cy, lo_off[n, 1], hi_off[n, 1], q0[1], q1[1])
                for k in range(block):
                    cz = blocks[n, 2] * block + k
                    if cz >= nz:
                        continue
                    az, bz = _clipped_window(cz, lo_off[n, 2], hi_off[n, 2], q0[2], q1[2])
                    count = (
                        sat[bx, by, bz]
                        - sat[ax, by, bz]
                        - sat[bx, ay, bz]
                        - sat[bx, by, az]
                        + sat[ax, ay, bz]
                        + sat[ax, by, az]
                        + sat[bx, ay, az]
                        - sat[ax, ay, az]
                    )
                    out[cx, cy, cz] = count > 0
