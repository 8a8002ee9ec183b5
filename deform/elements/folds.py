"""Folds of an offset field: where ``det(I + grad u) <= 0``.

The map ``X -> X + u(X)`` of a trilinear node field (:class:`OffsetFieldWarp`) folds
where its Jacobian ``I + grad u`` has a determinant <= 0: material turns inside out,
the raycaster's fixed-point inverse has no unique answer and meshes carried through
it self-intersect. Inside a cell the gradient at each corner is made of the cell's edge
differences, so the determinant is checked at the 8 corners of every cell (exact at the
corners, the usual discrete test of a trilinear map's invertibility).

Use :func:`fold_summary` for one line naming how many cells fold and where, or
:func:`folded_cells` for the mask.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def corner_dets(u: np.ndarray, spacing: np.ndarray) -> np.ndarray:
    """``det(I + grad u)`` at the 8 corners of every cell of a node field.

    Parameters
    ----------
    u
        (nx, ny, nz, 3) node displacements (mm), at least 2 nodes per axis.
    spacing
        (3,) node spacing (mm).

    Returns
    -------
    numpy.ndarray
        (8, nx - 1, ny - 1, nz - 1) determinants.
    """
    u = np.asarray(u, dtype=np.float64)
    h = np.asarray(spacing, dtype=np.float64)
    nx, ny, nz = u.shape[:3]
    dx = (u[1:] - u[:-1]) / h[0]
    dy = (u[:, 1:] - u[:, :-1]) / h[1]
    dz = (u[:, :, 1:] - u[:, :, :-1]) / h[2]
    out = np.empty((8, nx - 1, ny - 1, nz - 1))
    for c in range(8):
        ox, oy, oz = c & 1, (c >> 1) & 1, (c >> 2) & 1
        j = np.empty((nx - 1, ny - 1, nz - 1, 3, 3))
        j[..., :, 0] = dx[:, oy : oy + ny - 1, oz : oz + nz - 1]
        j[..., :, 1] = dy[ox : ox + nx - 1, :, oz : oz + nz - 1]
        j[..., :, 2] = dz[ox : ox + nx - 1, oy : oy + ny - 1, :]
        j += np.eye(3)
        out[c] = np.linalg.det(j)
    return out


def folded_cells(u: np.ndarray, spacing: np.ndarray) -> np.ndarray:
    """(nx - 1, ny - 1, nz - 1) bool: cells with ``det(I + grad u) <= 0`` at a corner."""
    return np.any(corner_dets(u, spacing) <= 0.0, axis=0)


def fold_summary(u: np.ndarray, lo: Any, spacing: Any) -> str | None:
    """One line saying how many cells of a node field over a grid from ``lo`` (mm) fold
    and where (the centre of the worst one, world mm), or None when none folds."""
    spacing = np.asarray(spacing, dtype=np.float64)
    dets = corner_dets(u, spacing).min(axis=0)
    bad = dets <= 0.0
    if not np.any(bad):
        return None
    worst = np.unravel_index(int(np.argmin(dets)), dets.shape)
    centre = np.asarray(lo, dtype=np.float64) + (np.asarray(worst) + 0.5) * spacing
    return (
        f"the offset field folds (det J <= 0) in {int(bad.sum())} of {bad.size} cells, worst"
        f" det {float(dets[worst]):.3g} around {np.round(centre, 1).tolist()} mm: the"
        " material turns inside out there, so the volume's inverse is ambiguous and meshes"
        " self-intersect; drag less or use more (or stiffer) elements"
    )
