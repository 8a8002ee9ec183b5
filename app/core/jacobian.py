"""The Jacobian determinant ``det J`` of a warp chain or of a displacement field.

voxwarp's warp chain maps a deformed point ``x`` to the original point
``q = chain(x)``; an exported field holds the pull-back ``u(x) = q - x``, so
``det J = det(d chain / dx) = det(I + grad u)``, what ITK's
``DisplacementFieldJacobianDeterminantFilter`` computes from ``u``. The value is the
same in RAS and LPS (``diag(-1, -1, 1) (I + grad u) diag(-1, -1, 1)`` has the same
determinant). ``det J > 1``: the deformed picture shows that neighbourhood shrunk
(the map pulls from a larger region); ``< 1``: enlarged; ``<= 0``: folded.

* :func:`point_determinant` evaluates it at any deformed points (the slice overlay);
  :func:`chain_determinant` evaluates it from the warps' analytic Jacobians
  (:func:`voxwarp.deform.warp.chain_jacobian`) at the nodes of a grid; nodes the chain
  does not carry are NaN.
* :func:`field_determinant` computes it from a field's nodes by central differences
  (one-sided halves at the border, ITK's zero-flux Neumann boundary) along the grid's
  axes, converted to world derivatives through the grid's affine. Note that ITK's
  filter itself differentiates along the index axes and ignores the image direction,
  so it agrees with this only on fields whose direction is the identity (rotate the
  vectors into the index frame first; ``tests/core/test_jacobian.py`` does).
* :class:`JacobianStats` summarises a map in one line (folded, compressed, expanded).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from voxwarp.deform.warp import Warp, chain_apply_carried, chain_jacobian

#: det J below this counts as compressed in :class:`JacobianStats` (volume halved).
COMPRESSED_BELOW = 0.5
#: det J above this counts as expanded in :class:`JacobianStats` (volume doubled).
EXPANDED_ABOVE = 2.0


def _nodes(affine: np.ndarray, shape: Sequence[int], k: int) -> np.ndarray:
    nx, ny = int(shape[0]), int(shape[1])
    ii, jj = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    idx = np.stack([ii.ravel(), jj.ravel(), np.full(ii.size, k)], axis=1).astype(float)
    return idx @ affine[:3, :3].T + affine[:3, 3]


def point_determinant(warps: Sequence[Warp], points: np.ndarray) -> np.ndarray:
    """``det J`` of ``warps`` at deformed points ``(N, 3)`` (world mm): float64 ``(N,)``,
    NaN where the chain does not carry the point (the slice overlay's per-pixel value)."""
    p = np.atleast_2d(np.asarray(points, dtype=np.float64))
    chain = list(warps)
    _, ok = chain_apply_carried(chain, p)
    with np.errstate(invalid="ignore", over="ignore"):
        det = np.linalg.det(chain_jacobian(chain, p))
    return np.where(ok, det, np.nan)


def chain_determinant(
    warps: Sequence[Warp], affine: np.ndarray, shape: Sequence[int]
) -> np.ndarray:
    """``det J`` of ``warps`` at the nodes of the grid ``(affine, shape)``: float32
    ``(nx, ny, nz)``, NaN where the chain does not carry the node."""
    a = np.asarray(affine, dtype=np.float64)
    nx, ny, nz = (int(v) for v in shape)
    out = np.empty((nx, ny, nz), dtype=np.float32)
    for k in range(nz):
        out[:, :, k] = point_determinant(warps, _nodes(a, shape, k)).reshape(nx, ny)
    return out


def field_determinant(u: np.ndarray, affine: np.ndarray) -> np.ndarray:
    """``det(I + grad u)`` of node vectors ``u`` ``(nx, ny, nz, 3)`` (world mm, the
    same frame as ``affine``'s world) by central differences on the node grid; float32
    ``(nx, ny, nz)``. ``affine``: the grid's 4x4 index -> world matrix."""
    u = np.asarray(u, dtype=np.float64)
    if u.ndim != 4 or u.shape[3] != 3 or min(u.shape[:3]) < 2:
        raise ValueError(f"u must be (nx, ny, nz, 3) with nx, ny, nz >= 2; got {u.shape}")
    inv = np.linalg.inv(np.asarray(affine, dtype=np.float64)[:3, :3])
    per_index = np.empty((*u.shape, 3))  # [..., component, index axis]
    for ax in range(3):
        pad = [(1, 1) if a == ax else (0, 0) for a in range(3)] + [(0, 0)]
        p = np.pad(u, pad, mode="edge")
        hi = np.take(p, np.arange(2, u.shape[ax] + 2), axis=ax)
        lo = np.take(p, np.arange(0, u.shape[ax]), axis=ax)
        per_index[..., ax] = (hi - lo) / 2.0
    jac = per_index @ inv + np.eye(3)
    return np.linalg.det(jac).astype(np.float32)


@dataclass(frozen=True)
class JacobianStats:
    """What a ``det J`` map holds (:meth:`of`); NaN nodes are left out.

    Attributes: ``min``, ``max`` (NaN when no node is finite), ``nodes`` (finite
    nodes), ``folded`` (``det J <= 0``), ``compressed`` (``< COMPRESSED_BELOW``),
    ``expanded`` (``> EXPANDED_ABOVE``) and ``voxel_mm3`` (one node's cell volume).
    """

    min: float
    max: float
    nodes: int
    folded: int
    compressed: int
    expanded: int
    voxel_mm3: float

    @classmethod
    def of(cls, det: np.ndarray, affine: np.ndarray) -> JacobianStats:
        """The stats of ``det`` on the grid whose index -> world matrix is ``affine``."""
        d = np.asarray(det, dtype=np.float64)
        d = d[np.isfinite(d)]
        empty = d.size == 0
        return cls(
            min=float("nan") if empty else float(d.min()),
            max=float("nan") if empty else float(d.max()),
            nodes=int(d.size),
            folded=int(np.count_nonzero(d <= 0)),
            compressed=int(np.count_nonzero(d < COMPRESSED_BELOW)),
            expanded=int(np.count_nonzero(d > EXPANDED_ABOVE)),
            voxel_mm3=float(abs(np.linalg.det(np.asarray(affine, float)[:3, :3]))),
        )

    def line(self) -> str:
        """One line: min/max, folded, compressed and expanded counts and volumes."""

        def part(n: int, what: str) -> str:
            return f"{n} {what} ({n * self.voxel_mm3:.4g} mm^3)"

        return (
            f"det J: min {self.min:.4g}, max {self.max:.4g} over {self.nodes} node(s);"
            f" {part(self.folded, 'folded (det J <= 0)')},"
            f" {part(self.compressed, f'compressed (< {COMPRESSED_BELOW:g})')},"
            f" {part(self.expanded, f'expanded (> {EXPANDED_ABOVE:g})')}"
        )


@dataclass(frozen=True)
class JacobianMap:
    """``det J`` on a grid (:meth:`voxwarp.scene.Scene.jacobian_determinant`).

    Attributes: ``det`` (float32 ``(nx, ny, nz)``, NaN at nodes the chain does not
    carry) and ``affine`` (4x4 index -> world RAS mm, the field export's grid).
    """

    det: np.ndarray
    affine: np.ndarray

    @property
    def stats(self) -> JacobianStats:
        """Min/max and the folded, compressed and expanded nodes."""
        return JacobianStats.of(self.det, self.affine)
