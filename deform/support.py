"""Where a warp chain moves anything: its *support*, as a coarse brick map.

About this technique
--------------------
A backward-mapped raycaster samples the original volume at ``chain(p)`` for each
deformed-space sample ``p``. Wherever ``|chain(p) - p|`` stays below a tolerance the
straight ray samples the same point, so the renderer may march straight there and pay
for the chain only inside the support. The support is kept per *brick* of a coarse grid
over the deformed ray box: a brick is in the support unless every point of it is moved
by at most ``tol`` mm along each axis. Each warp says which bricks it moves
(:meth:`voxwarp.deform.warp.Warp.support_bricks`, by default from its
:meth:`~voxwarp.deform.warp.Warp.displacement_range` intervals, which every family
derives from its own data: an offset field's nodes, a lattice's cells, a wire's
influence region); a chain adds the intervals of its warps as
:func:`voxwarp.deform.warp.chain_displacement_range` does, each warp seeing the boxes
moved by those before it, so the union is mapped conservatively.

Use :func:`chain_support` (numpy on the bricks, not on the volume; rebuild only when a
warp's revision changes).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from voxwarp.deform.warp import Warp

#: bricks per axis at most (a 32³ map is rebuilt for every frame of a drag: tens of
#: milliseconds of numpy)
MAX_BRICKS = 32


@dataclass(frozen=True)
class SupportMap:
    """A brick map over the deformed box ``[lo, hi]`` (mm).

    ``moved`` is an (nx, ny, nz) bool array: brick ``(i, j, k)`` spans
    ``lo + (i, j, k) * size`` to ``lo + (i + 1, j + 1, k + 1) * size`` and is True when
    some point in it may be moved by more than the tolerance. Points outside every True
    brick are moved by at most the tolerance (per axis).
    """

    lo: np.ndarray
    hi: np.ndarray
    moved: np.ndarray

    @property
    def size(self) -> np.ndarray:
        """Edge lengths (mm) of one brick."""
        return (self.hi - self.lo) / np.asarray(self.moved.shape)

    @property
    def fraction(self) -> float:
        """Share of the bricks in the support (0: nothing moves, 1: everything may)."""
        return float(self.moved.mean()) if self.moved.size else 0.0

    def world_to_brick(self) -> np.ndarray:
        """4x4 matrix: deformed world (mm) -> brick coordinates (brick i spans [i, i+1])."""
        m = np.eye(4)
        scale = 1.0 / self.size
        m[:3, :3] = np.diag(scale)
        m[:3, 3] = -self.lo * scale
        return m

    def moved_box(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The box (lo, hi) around every support brick, or None when there is none."""
        idx = np.argwhere(self.moved)
        if len(idx) == 0:
            return None
        size = self.size
        return self.lo + idx.min(axis=0) * size, self.lo + (idx.max(axis=0) + 1) * size

    def boundary_triangles(self, grow: float = 0.0) -> np.ndarray:
        """(T, 3, 3) float32 triangles (deformed world, mm) of the support's surface: the
        brick faces between a support brick and one outside it (or the map's edge), runs
        of them along a row merged into one rectangle, two triangles each. A straight ray
        meets a support brick only between the first and last of these it crosses (the
        renderer rasterises them for each ray's range).

        ``grow``: each rectangle widened in its plane by this fraction of a brick on
        every side. Merged rows meet their neighbours in T-junctions (an edge of one
        rectangle ends in the middle of another's), where a rasteriser, snapping each
        edge's ends on its own, can leave pixels that neither rectangle covers; widened
        rectangles overlap there (a ray then counts a face it passes near: a range a
        little longer, never a shorter one)."""
        q = np.concatenate([self._faces(axis, grow) for axis in range(3)])
        return np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]]).astype(np.float32)

    def _faces(self, axis: int, grow: float = 0.0) -> np.ndarray:
        """(F, 4, 3) corners of the surface's rectangles normal to ``axis``: in each
        brick plane, runs of faces along the last of the other two axes, widened in
        their plane by ``grow`` bricks."""
        pad = [(0, 0)] * 3
        pad[axis] = (1, 1)
        m = np.moveaxis(np.pad(self.moved, pad), axis, 0)
        change = m[1:] != m[:-1]  # face (f, i, j) lies at brick plane f along axis
        c = np.pad(change, ((0, 0), (0, 0), (1, 1)))
        starts = np.argwhere(c[..., 1:-1] & ~c[..., :-2])  # same order as their ends
        ends = np.argwhere(c[..., 1:-1] & ~c[..., 2:])
        others = [a for a in range(3) if a != axis]
        corners = np.zeros((len(starts), 4, 3))
        for k, (di, end) in enumerate(((0, False), (1, False), (1, True), (0, True))):
            corners[:, k, axis] = starts[:, 0]
            corners[:, k, others[0]] = starts[:, 1] + di + (2 * di - 1) * grow
            corners[:, k, others[1]] = ends[:, 2] + 1 + grow if end else starts[:, 2] - grow
        return self.lo + corners * self.size

    def contains(self, points: np.ndarray) -> np.ndarray:
        """(N,) bool: which (N, 3) deformed points lie in a support brick (points outside
        the box count as in the brick they are clamped to, as the shaders do)."""
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        n = np.asarray(self.moved.shape)
        c = np.clip(np.floor((p - self.lo) / self.size), 0, n - 1).astype(np.intp)
        return self.moved[c[:, 0], c[:, 1], c[:, 2]]


def brick_shape(lo: np.ndarray, hi: np.ndarray, brick_mm: float) -> tuple[int, int, int]:
    """Bricks per axis over ``[lo, hi]`` for bricks of about ``brick_mm`` (at least one,
    at most :data:`MAX_BRICKS`)."""
    extent = np.maximum(np.asarray(hi, float) - np.asarray(lo, float), 0.0)
    n = np.clip(np.ceil(extent / max(float(brick_mm), 1e-9)), 1, MAX_BRICKS).astype(int)
    return (int(n[0]), int(n[1]), int(n[2]))


def brick_boxes(
    lo: np.ndarray, hi: np.ndarray, shape: Sequence[int]
) -> tuple[np.ndarray, np.ndarray]:
    """Corners (N, 3) of the bricks of ``shape`` over ``[lo, hi]``, in C order of
    ``shape`` (brick ``(i, j, k)`` is row ``(i * ny + j) * nz + k``)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    n = np.asarray(shape)
    size = (hi - lo) / n
    idx = np.stack(np.meshgrid(*(np.arange(v) for v in n), indexing="ij"), -1).reshape(-1, 3)
    return lo + idx * size, lo + (idx + 1) * size


def chain_support(
    warps: Sequence[Warp], lo: np.ndarray, hi: np.ndarray, brick_mm: float, tol: float
) -> SupportMap:
    """The support of a chain over the deformed box ``[lo, hi]`` in bricks of about
    ``brick_mm``: bricks where the chain may move a point by more than ``tol`` mm.

    Warp ``i`` is asked (:meth:`Warp.support_bricks`, with ``tol / len(warps)`` so that
    the chain's moves add up to at most ``tol`` outside) about the bricks moved by the
    displacement intervals of warps ``0 .. i-1``; a brick any warp moves is in the
    support. When a warp before the last cannot bound its displacement, every brick is.
    """
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    shape = brick_shape(lo, hi, brick_mm)
    blo, bhi = brick_boxes(lo, hi, shape)
    moved = np.zeros(len(blo), dtype=bool)
    each = float(tol) / max(len(warps), 1)
    a, b = np.zeros(blo.shape), np.zeros(blo.shape)
    for i, w in enumerate(warps):
        moved |= np.asarray(w.support_bricks(blo + a, bhi + b, each), dtype=bool)
        if i + 1 == len(warps) or moved.all():
            break
        r = w.displacement_range(blo + a, bhi + b)
        if r is None:
            moved[:] = True
            break
        a, b = a + np.asarray(r[0], float), b + np.asarray(r[1], float)
    return SupportMap(lo, hi, moved.reshape(shape))
