"""Attachments: geometry that follows a deforming base mesh through anchors.

About this technique (Knuth, Kohlhammer, Kuijper, "Embedding hierarchical deformation
within a realtime scene graph", GRAPP 2010, section 5)
---------------------------------------------------------------------------------------
An *anchor* sits on one triangle of a base mesh: barycentric coordinates give its
position P and a second point Q of the same triangle (the tangent point). Its frame is
rebuilt from the triangle wherever the base mesh moves: origin P, x along Q - P (made
orthogonal to the normal), z the triangle's normal, y = z × x. Because P and Q are
barycentric, they follow the triangle exactly, whatever deforms or animates the mesh.

An array of anchors builds the deformation grid of an attached object *on the fly*,
each frame: a 1D array (along a strap, a belt, a spine) or a 2D array (over a patch of
skin) gives the nodes of a :class:`voxwarp.deform.lattice.trilinear.TrilinearGrid` by stepping from
each
anchor along its frame. The attached geometry lives in the unit cube of its own box
(the scene-graph convention, :mod:`voxwarp.deform.lattice.scene_graph`); the grid maps it onto the
base
mesh, bending with it:

* 1D array of n anchors: nodes ``(n, 2, 2)``: node (i, j, k) = P_i + (j - 1/2) width y_i
  + (offset + k thickness) z_i: the attached object's x runs along the anchors, y across
  (centred), z away from the surface.
* 2D array of m x n anchors: nodes ``(m, n, 2)``: node (i, j, k) = P_ij + (offset + k
  thickness) z_ij: x and y run over the patch, z away from it.

With anchors on the base mesh's own vertices the attached object touches the surface
exactly at the anchor points (tested): it stays in contact as the base deforms.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from voxwarp.deform.lattice.trilinear import TrilinearGrid
from voxwarp.deform.warp import WarpError


def _barycentric(b: Any, what: str) -> np.ndarray:
    try:
        a = np.asarray(b, dtype=np.float64).reshape(3)
    except (TypeError, ValueError) as exc:
        raise WarpError(f"anchor {what} must be 3 barycentric coordinates; got {b!r:.60}") from exc
    if not np.all(np.isfinite(a)):
        raise WarpError(f"anchor {what} has NaN/Inf; give 3 finite barycentric coordinates")
    if abs(a.sum() - 1.0) > 1e-6:
        raise WarpError(f"anchor {what} must sum to 1 (barycentric); got sum {a.sum():.6g}")
    return a


@dataclass(frozen=True)
class Anchor:
    """A point and a tangent point on one triangle of a base mesh (barycentric).

    Parameters
    ----------
    triangle
        Index of the triangle in the base mesh's faces.
    position
        Barycentric coordinates (3, summing to 1) of the anchor point P.
    tangent
        Barycentric coordinates of the tangent point Q (P != Q): the frame's x axis
        points from P towards Q.
    """

    triangle: int
    position: tuple[float, float, float]
    tangent: tuple[float, float, float]

    def __post_init__(self) -> None:
        t = self.triangle
        integral = isinstance(t, int | np.integer) or (isinstance(t, float) and t.is_integer())
        if isinstance(t, bool) or not integral or not 0 <= t < 2**62:
            raise WarpError(f"anchor triangle must be a face index >= 0; got {self.triangle!r}")
        p = _barycentric(self.position, "position")
        q = _barycentric(self.tangent, "tangent point")
        if np.allclose(p, q):
            raise WarpError(
                "an anchor's tangent point must differ from its position (it sets the frame's"
                " x axis)"
            )
        object.__setattr__(self, "triangle", int(self.triangle))
        object.__setattr__(self, "position", tuple(float(v) for v in p))
        object.__setattr__(self, "tangent", tuple(float(v) for v in q))

    def to_dict(self) -> dict[str, Any]:
        """JSON form."""
        return {
            "triangle": self.triangle,
            "position": list(self.position),
            "tangent": list(self.tangent),
        }

    @classmethod
    def from_dict(cls, d: Any) -> Anchor:
        """Inverse of :meth:`to_dict`."""
        if not isinstance(d, dict) or not {"triangle", "position", "tangent"} <= set(d):
            raise WarpError("an anchor needs 'triangle', 'position' and 'tangent'")
        return cls(d["triangle"], d["position"], d["tangent"])


def _check_mesh(vertices: Any, faces: Any) -> tuple[np.ndarray, np.ndarray]:
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
        raise WarpError(f"base mesh vertices must be (N, 3); got shape {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0 or not np.issubdtype(f.dtype, np.integer):
        raise WarpError(f"base mesh faces must be (M, 3) vertex indices; got shape {f.shape}")
    if not np.all(np.isfinite(v)):
        raise WarpError("base mesh vertices contain NaN/Inf")
    if f.min() < 0 or f.max() >= len(v):
        raise WarpError("base mesh faces index vertices that do not exist")
    return v, f


def anchor_frames(
    anchors: Sequence[Anchor], vertices: Any, faces: Any
) -> tuple[np.ndarray, np.ndarray]:
    """Origins (K, 3) and frames (K, 3, 3) (columns x, y, z) of anchors on a base mesh.

    Raises :class:`WarpError` for a triangle index out of range or a degenerate
    (zero-area) anchor triangle.
    """
    v, f = _check_mesh(vertices, faces)
    tri = np.array([a.triangle for a in anchors], dtype=np.int64)
    if len(tri) and tri.max() >= len(f):
        raise WarpError(
            f"anchor triangle {int(tri.max())} does not exist: the base mesh has {len(f)} faces"
        )
    corners = v[f[tri]]  # (K, 3 corners, 3)
    bp = np.array([a.position for a in anchors])
    bq = np.array([a.tangent for a in anchors])
    p = np.einsum("kc,kci->ki", bp, corners)
    q = np.einsum("kc,kci->ki", bq, corners)
    n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    nn = np.linalg.norm(n, axis=1)
    if np.any(nn <= 1e-12 * max(1.0, float(np.abs(v).max()))):
        bad = int(tri[np.argmin(nn)])
        raise WarpError(f"anchor triangle {bad} is degenerate (zero area): anchor elsewhere")
    z = n / nn[:, None]
    x = q - p
    x -= np.einsum("ki,ki->k", x, z)[:, None] * z
    xn = np.linalg.norm(x, axis=1)
    if np.any(xn <= 1e-12):
        raise WarpError("an anchor's tangent point lies on its normal: choose another one")
    x /= xn[:, None]
    y = np.cross(z, x)
    return p, np.stack([x, y, z], axis=-1)


def anchors_at(
    vertices: Any, faces: Any, points: Any, directions: Any, step: float = 0.25
) -> list[Anchor]:
    """Anchors at the triangles closest to ``points`` (K, 3), their tangent points a
    fraction ``step`` of the triangle's size along ``directions`` (K, 3) (projected onto
    the triangle, clamped into it)."""
    v, f = _check_mesh(vertices, faces)
    pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
    dirs = np.atleast_2d(np.asarray(directions, dtype=np.float64))
    if pts.shape != dirs.shape or pts.shape[1] != 3:
        raise WarpError("points and directions must both be (K, 3)")
    tri = v[f]  # (M, 3, 3)
    centroid = tri.mean(axis=1)
    out = []
    for p, d in zip(pts, dirs, strict=True):
        k = int(np.argmin(np.linalg.norm(centroid - p, axis=1)))
        a, b, c = tri[k]
        bp = _bary(p, a, b, c)
        size = max(float(np.linalg.norm(b - a)), float(np.linalg.norm(c - a)))
        bq = _bary(p + step * size * d / max(float(np.linalg.norm(d)), 1e-12), a, b, c)
        if np.allclose(bq, bp):
            bq = _bary(0.5 * (a + b), a, b, c)
        out.append(Anchor(k, tuple(bp), tuple(bq)))
    return out


def _bary(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Barycentric coordinates of p projected onto triangle abc, clamped into it."""
    e0, e1, d = b - a, c - a, p - a
    m = np.array([[e0 @ e0, e0 @ e1], [e0 @ e1, e1 @ e1]])
    s, t = np.linalg.solve(m, [d @ e0, d @ e1])
    w = np.clip(np.array([1.0 - s - t, s, t]), 0.0, None)
    return w / w.sum()


class AnchorStrip:
    """A 1D (n) or 2D (m x n) array of anchors that builds an attached object's grid.

    Parameters
    ----------
    anchors
        A sequence of n :class:`Anchor` (1D) or m sequences of n (2D), n >= 2 (m >= 2).
    thickness
        Extent of the attached object away from the surface (mm, along the normals).
    width
        1D only: extent across the strip (mm, along the frames' y), centred on the anchors.
    offset
        Distance of the object's bottom face from the surface (mm; 0 = touching).
    """

    def __init__(
        self,
        anchors: Any,
        thickness: float,
        width: float | None = None,
        offset: float = 0.0,
    ) -> None:
        rows = list(anchors)
        two_d = len(rows) > 0 and not isinstance(rows[0], Anchor)
        grid = [list(r) for r in rows] if two_d else [rows]
        if any(len(r) != len(grid[0]) for r in grid) or len(grid[0]) < 2:
            raise WarpError("an anchor array needs >= 2 anchors per row, the same in every row")
        if two_d and len(grid) < 2:
            raise WarpError("a 2D anchor array needs >= 2 rows (or give a 1D list)")
        for r in grid:
            for a in r:
                if not isinstance(a, Anchor):
                    raise WarpError(f"anchor arrays hold Anchor objects; got {type(a).__name__}")
        self.two_d = two_d
        self.anchors = grid
        if not np.isfinite(thickness) or thickness <= 0:
            raise WarpError(f"thickness must be a length in mm > 0; got {thickness!r}")
        if not two_d and (width is None or not np.isfinite(width) or width <= 0):
            raise WarpError("a 1D anchor array needs width > 0 (mm across the strip)")
        self.thickness = float(thickness)
        self.width = None if width is None else float(width)
        if not np.isfinite(offset):
            raise WarpError(f"offset must be a finite length in mm; got {offset!r}")
        self.offset = float(offset)

    def nodes(self, vertices: Any, faces: Any) -> np.ndarray:
        """Grid nodes on the base mesh as it is now: ``(n, 2, 2, 3)`` for 1D, ``(m, n, 2, 3)``
        for 2D (see the module docstring)."""
        flat = [a for r in self.anchors for a in r]
        p, fr = anchor_frames(flat, vertices, faces)
        z = fr[:, :, 2]
        lift = np.array([self.offset, self.offset + self.thickness])  # k = 0, 1
        if self.two_d:
            m, n = len(self.anchors), len(self.anchors[0])
            nodes = p[:, None, :] + lift[None, :, None] * z[:, None, :]
            return nodes.reshape(m, n, 2, 3)
        assert self.width is not None
        y = fr[:, :, 1]
        across = np.array([-0.5, 0.5]) * self.width  # j = 0, 1
        nodes = (
            p[:, None, None, :]
            + across[None, :, None, None] * y[:, None, None, :]
            + lift[None, None, :, None] * z[:, None, None, :]
        )
        return nodes  # (n, 2, 2, 3)

    def to_dict(self) -> dict[str, Any]:
        """JSON form: the anchors (a list, or a list of rows), thickness, width, offset."""
        anchors: list[Any] = [[a.to_dict() for a in r] for r in self.anchors]
        d: dict[str, Any] = {
            "anchors": anchors if self.two_d else anchors[0],
            "thickness": self.thickness,
            "offset": self.offset,
        }
        if self.width is not None:
            d["width"] = self.width
        return d

    @classmethod
    def from_dict(cls, d: Any) -> AnchorStrip:
        """Inverse of :meth:`to_dict` (raises :class:`WarpError`)."""
        if not isinstance(d, dict) or not {"anchors", "thickness"} <= set(d):
            raise WarpError("an anchor array needs 'anchors' and 'thickness' (mm)")
        unknown = set(d) - {"anchors", "thickness", "width", "offset"}
        if unknown:
            raise WarpError(
                f"unknown anchor array keys {sorted(unknown)}; allowed: anchors, thickness,"
                " width, offset"
            )
        rows = d["anchors"]
        if not isinstance(rows, list) or not rows:
            raise WarpError("an anchor array's 'anchors' must be a list of anchors (or of rows)")
        if isinstance(rows[0], list):
            anchors: Any = [[Anchor.from_dict(a) for a in _row(r)] for r in rows]
        else:
            anchors = [Anchor.from_dict(a) for a in rows]
        return cls(
            anchors,
            _length(d["thickness"], "thickness"),
            None if d.get("width") is None else _length(d["width"], "width"),
            _length(d.get("offset", 0.0), "offset"),
        )

    def grid(self, vertices: Any, faces: Any) -> Any:
        """The attached object's :class:`voxwarp.deform.lattice.trilinear.TrilinearGrid` for the
        base
        mesh's current vertices (call every frame the base moves)."""
        return TrilinearGrid(self.nodes(vertices, faces))


def _row(r: Any) -> list[Any]:
    if not isinstance(r, list):
        raise WarpError("a 2D anchor array's rows must be lists of anchors")
    return r


def _length(x: Any, what: str) -> float:
    if isinstance(x, bool) or not isinstance(x, int | float):
        raise WarpError(f"anchor array {what} must be a number (mm); got {x!r:.60}")
    return float(x)
