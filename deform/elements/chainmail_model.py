"""The 3D ChainMail model's data and constraints, shared by its CPU and GPU solvers.

About this technique (Gibson 1997, "3D ChainMail"; Schill et al. 1998, "Enhanced
ChainMail"; Knoche 2008, 2.4.2.2, 3.5.3)
------------------------------------------------------------------------------------
The elements of an :class:`~voxwarp.deform.elements.grid.ElementGrid` are linked to their 6
neighbours like the rings of a chain mail: a link has slack, so an element can move a
little without disturbing its neighbours, and pulls or pushes them once the slack is
used up. For the link from element ``a`` to ``b = a + e_i`` (the next element along
axis i) with ``d = x_b - x_a`` (world mm), the constraint is (Gibson)::

    min_i <= d_i <= max_i        (stretch and compression along the link's axis)
    |d_j| <= shear_i  for j != i (shear across it)

Limits are given per element and axis (anisotropic, heterogeneous materials); a link
uses the mean of its two elements' limits (:meth:`ChainMailModel.link_limits`). A link
can be removed (:attr:`ChainMailModel.links`: cuts, and past the grid's faces), and
fixed elements never move. Every solver (``voxwarp.deform.elements.chainmail``'s CPU variants and
the
GPU backend of ``voxwarp.deform.elements.chainmail_gpu``) moves elements only to satisfy these
constraints, and :meth:`ChainMailModel.violation` is the common check.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from voxwarp.errors import VoxwarpError

#: Constraint violations below this many mm (float round-off) do not count.
VIOLATION_TOL_MM = 1e-6

#: A box of elements ``((i0, j0, k0), (i1, j1, k1))``, half-open.
Box = tuple[tuple[int, int, int], tuple[int, int, int]]


class ChainMailError(VoxwarpError, ValueError):
    """Invalid ChainMail parameters (limits, indices, cuts)."""


@dataclass
class ChainMailModel:
    """Grid, limits, links and fixed elements (see the module docstring).

    Arrays are indexed ``[i, j, k]`` along x, y, z; positions in world mm.
    """

    #: (nx, ny, nz, 3) rest positions
    rest: np.ndarray
    #: (3,) rest distance between neighbouring elements per axis (mm)
    spacing: np.ndarray
    #: (nx, ny, nz, 3) per element and axis i: least ``d_i`` of its links along i (mm)
    min_dist: np.ndarray
    #: (nx, ny, nz, 3) per element and axis i: largest ``d_i`` of its links along i (mm)
    max_dist: np.ndarray
    #: (nx, ny, nz, 3) per element and axis i: largest ``|d_j|``, j != i (mm)
    max_shear: np.ndarray
    #: (nx, ny, nz, 3) bool: element a is linked to a + e_i (False on the last layer
    #: along i, and where a cut removed the link)
    links: np.ndarray
    #: (nx, ny, nz) bool: fixed elements never move
    fixed: np.ndarray

    def __post_init__(self) -> None:
        self.rest = np.asarray(self.rest, dtype=np.float64)
        shape = self.rest.shape[:3]
        self.spacing = np.asarray(self.spacing, dtype=np.float64).reshape(3)
        for name in ("min_dist", "max_dist", "max_shear"):
            a = np.asarray(getattr(self, name), dtype=np.float64)
            if a.shape != (*shape, 3):
                a = np.broadcast_to(a, (*shape, 3)).copy()
            setattr(self, name, a)
        self.links = np.asarray(self.links, dtype=bool).copy()
        self.fixed = np.asarray(self.fixed, dtype=bool).copy()
        for a in range(3):  # no link past the last layer
            idx = [slice(None)] * 3
            idx[a] = -1
            self.links[(*idx, a)] = False
        check_limits(self.min_dist, self.max_dist, self.max_shear)

    @property
    def shape(self) -> tuple[int, int, int]:
        """Elements per axis ``(nx, ny, nz)``."""
        return tuple(int(n) for n in self.rest.shape[:3])  # type: ignore[return-value]

    def link_limits(self, axis: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(min, max, shear, linked)`` of the links along ``axis``.

        Each of shape ``shape`` with ``axis`` shortened by one: entry ``a`` is the link
        from ``a`` to ``a + e_axis``, its limits the mean of both elements' limits.
        """
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[axis] = slice(0, -1)
        hi[axis] = slice(1, None)
        lo_t, hi_t = tuple(lo), tuple(hi)

        def mean(a: np.ndarray) -> np.ndarray:
            return 0.5 * (a[lo_t][..., axis] + a[hi_t][..., axis])

        return (
            mean(self.min_dist),
            mean(self.max_dist),
            mean(self.max_shear),
            self.links[lo_t][..., axis],
        )

    def violation(self, positions: np.ndarray) -> float:
        """Largest constraint violation (mm) of any present link at ``positions``.

        0 when every link satisfies its limits. ``positions``: (nx, ny, nz, 3).
        """
        x = np.asarray(positions, dtype=np.float64)
        worst = 0.0
        for axis in range(3):
            if self.shape[axis] < 2:
                continue
            mn, mx, sh, linked = self.link_limits(axis)
            d = np.diff(x, axis=axis)
            v = np.maximum(mn - d[..., axis], d[..., axis] - mx)
            for j in range(3):
                if j != axis:
                    v = np.maximum(v, np.abs(d[..., j]) - sh)
            v = np.where(linked, v, 0.0)
            if v.size:
                worst = max(worst, float(v.max()))
        return max(worst, 0.0)

    def link_excess(self, positions: np.ndarray, links: np.ndarray) -> np.ndarray:
        """(m,) how far (mm) links ``[i, j, k, axis]`` (present or removed, e.g. ones to
        join) are beyond their limits at ``positions`` (<= 0: within them)."""
        x = np.asarray(positions, dtype=np.float64)
        idx = np.asarray(links, dtype=np.int64).reshape(-1, 4)
        r, axis = np.arange(len(idx)), idx[:, 3]
        a = tuple(idx[:, :3].T)
        hi = idx[:, :3].copy()
        hi[r, axis] += 1
        b = tuple(hi.T)

        def mean(lim: np.ndarray) -> np.ndarray:
            return 0.5 * (lim[a][r, axis] + lim[b][r, axis])

        d = x[b] - x[a]
        along = d[r, axis]
        v = np.maximum(mean(self.min_dist) - along, along - mean(self.max_dist))
        across = np.abs(d)
        across[r, axis] = -np.inf
        return np.maximum(v, across.max(axis=1, initial=-np.inf) - mean(self.max_shear))

    def satisfied(self, positions: np.ndarray, tol: float = VIOLATION_TOL_MM) -> bool:
        """True when no link is violated by more than ``tol`` mm."""
        return self.violation(positions) <= tol


def check_limits(min_dist: np.ndarray, max_dist: np.ndarray, max_shear: np.ndarray) -> None:
    """Raise :class:`ChainMailError` for impossible limits (naming the fix)."""
    for name, a in (("min_dist", min_dist), ("max_dist", max_dist), ("max_shear", max_shear)):
        if not np.all(np.isfinite(a)):
            raise ChainMailError(f"{name} has NaN/Inf entries; give finite distances in mm")
        if np.any(a < 0):
            raise ChainMailError(
                f"{name} must be >= 0 mm (got {float(np.min(a)):g}); ChainMail limits are"
                " distances between neighbouring elements"
            )
    if np.any(min_dist > max_dist):
        bad = np.argwhere(min_dist > max_dist)[0]
        raise ChainMailError(
            f"min_dist > max_dist at element {tuple(int(v) for v in bad[:3])}, axis"
            f" {int(bad[3])} ({float(min_dist[tuple(bad)]):g} > {float(max_dist[tuple(bad)]):g}"
            " mm): the link could never be satisfied; use min_dist <= max_dist"
        )


def union_box(a: Box | None, b: Box | None) -> Box | None:
    """The smallest box holding both (None: no box)."""
    if a is None:
        return b
    if b is None:
        return a
    return (
        tuple(min(p, q) for p, q in zip(a[0], b[0], strict=True)),  # type: ignore[return-value]
        tuple(max(p, q) for p, q in zip(a[1], b[1], strict=True)),
    )


def grow_box(box: Box | None, shape: tuple[int, int, int]) -> Box | None:
    """The box grown by one element on every face, clipped to the grid (None stays)."""
    if box is None:
        return None
    lo = tuple(max(v - 1, 0) for v in box[0])
    hi = tuple(min(v + 1, n) for v, n in zip(box[1], shape, strict=True))
    return (lo, hi)  # type: ignore[return-value]


def relax_boxes(box: Box | None, steps: int, shape: tuple[int, int, int]) -> list[Box]:
    """The boxes of the ``2 * steps`` half-sweeps (colour 0, 1, 0, ...) of a relaxation
    that starts with every element off the rule's fixed point inside ``box``.

    An element can change in a half-sweep only if it or a linked neighbour changed
    before (else its update gives its position again), so each half-sweep covers the
    previous one's box grown by one element, the first ``box`` grown by one: the
    result is that of half-sweeps over the whole grid. Empty for ``box`` None.
    Both backends relax over these boxes.
    """
    out: list[Box] = []
    for _ in range(2 * steps):
        box = grow_box(box, shape)
        if box is None:
            break
        out.append(box)
    return out
