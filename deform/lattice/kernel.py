"""The compiled (numba) trilinear grid evaluation behind
:meth:`voxwarp.deform.lattice.trilinear.TrilinearGrid.forward`.

A module of its own so that ``import voxwarp.deform.lattice.trilinear`` (and with it the
raycaster and the mesh module) does not import numba: it loads on the first
evaluation of a non-linear grid. :func:`eval_grid` picks the threaded kernel for many
points and the serial one for few: a scene graph evaluates hundreds of small node
grids per frame, where starting the threads costs more than the work (and far more on
a loaded machine).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from voxwarp.deform.parallel import threadsafe

#: points from which the threaded kernel runs
PARALLEL_MIN_POINTS = 16384


@njit(cache=True, inline="always")
def _eval_point(
    nodes: np.ndarray, t: np.ndarray, p: int, out: np.ndarray
) -> None:  # pragma: no cover
    """Point ``p``: the cell of the clamped floor index, local coordinates unclamped
    (border cells extrapolate), the corner form of eq. 1."""
    nx = nodes.shape[0] - 1
    ny = nodes.shape[1] - 1
    nz = nodes.shape[2] - 1
    sx = t[p, 0] * nx
    sy = t[p, 1] * ny
    sz = t[p, 2] * nz
    i = min(max(int(np.floor(sx)), 0), nx - 1)
    j = min(max(int(np.floor(sy)), 0), ny - 1)
    k = min(max(int(np.floor(sz)), 0), nz - 1)
    x = sx - i
    y = sy - j
    z = sz - k
    for c in range(3):
        c00 = nodes[i, j, k, c] * (1.0 - x) + nodes[i + 1, j, k, c] * x
        c10 = nodes[i, j + 1, k, c] * (1.0 - x) + nodes[i + 1, j + 1, k, c] * x
        c01 = nodes[i, j, k + 1, c] * (1.0 - x) + nodes[i + 1, j, k + 1, c] * x
        c11 = nodes[i, j + 1, k + 1, c] * (1.0 - x) + nodes[i + 1, j + 1, k + 1, c] * x
        out[p, c] = (c00 * (1.0 - y) + c10 * y) * (1.0 - z) + (c01 * (1.0 - y) + c11 * y) * z


@threadsafe
@njit(parallel=True, cache=True)
def eval_grid_kernel(nodes: np.ndarray, t: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    """Trilinear evaluation of a node grid (nx+1, ny+1, nz+1, 3) at unit points t (N, 3)
    into out (N, 3), threaded over the points."""
    for p in prange(t.shape[0]):
        _eval_point(nodes, t, p, out)


@njit(cache=True)
def eval_grid_serial(nodes: np.ndarray, t: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    """:func:`eval_grid_kernel` on one thread."""
    for p in range(t.shape[0]):
        _eval_point(nodes, t, p, out)


def eval_grid(nodes: np.ndarray, t: np.ndarray, out: np.ndarray) -> None:
    """Evaluate ``nodes`` at ``t`` into ``out`` (C-contiguous float64 arrays), threaded
    from :data:`PARALLEL_MIN_POINTS` points on."""
    if len(t) >= PARALLEL_MIN_POINTS:
        eval_grid_kernel(nodes, t, out)
    else:
        eval_grid_serial(nodes, t, out)
