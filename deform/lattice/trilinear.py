"""Trilinear transformations and uniform grids of trilinear cells (free-form lattices).

About this technique (Knuth, Kohlhammer, Kuijper, "Embedding hierarchical deformation
within a realtime scene graph", GRAPP 2010, sections 3-6)
------------------------------------------------------------------------------------
A *trilinear transformation* ``T`` maps the unit cube ``[0,1]^3`` onto the hexahedron
spanned by eight world points, the *corners*. Corner ``p_i`` is the image of the cube
corner whose coordinates are the bits of ``i`` (``i = x + 2 y + 4 z``: ``p0 = T(0,0,0)``,
``p1 = T(1,0,0)``, ``p2 = T(0,1,0)``, ... ``p7 = T(1,1,1)``). In *corner form* (the
paper's eq. 1)

.. math::

    T(x, y, z) = \\sum_i p_i \\, b_{i_x}(x) \\, b_{i_y}(y) \\, b_{i_z}(z), \\qquad
    b_0(s) = 1 - s, \\; b_1(s) = s.

Multiplying out gives the *coefficient form* (eqs. 2-4): ``T(u) = C v(u)`` with the
monomial vector ``v = (xyz, yz, xz, xy, z, y, x, 1)`` and a ``3 x 8`` coefficient matrix
``C``. The column of a monomial over the variable set ``S`` is the alternating sum
``sum_{bits(i) subset of S} (-1)^{|S| - |bits(i)|} p_i``; e.g. the ``x`` column is
``p1 - p0``, the ``xy`` column ``p3 - p2 - p1 + p0`` and the constant column ``p0``.
Here ``C`` is computed exactly this way, as ``corners.T @ M`` with a fixed integer
matrix ``M``.

*Linear detection* (section 3): the four left columns of ``C`` (``xyz, yz, xz, xy``)
vanish exactly when every pair of opposite edges is parallel and of equal length, i.e.
the corners form a parallelepiped. Then ``T`` is the affine map ``u -> A u + t`` with
``A = [C_x C_y C_z]`` and ``t = C_1``, a 4x4 matrix, and evaluation, Jacobian and
inverse take the cheap matrix path. Scene-graph chains of such transforms stay
matrices (section 4).

*Inverse* (left open by the paper): for a world point ``q`` we solve ``T(u) = q`` by
Newton's method, ``u <- u - J(u)^{-1} (T(u) - q)``, with the exact Jacobian
``J = dT/du`` of the coefficient form. The seed is the inverse of the *linear part*,
the least-squares affine fit of the eight corners (its columns are the mean of the four
parallel edges, its centre the mean of the corners); for a parallelepiped the seed is
already the answer. Newton converges quadratically where ``J`` is regular. A point is
reported *folded* when ``det J`` has the wrong sign (relative to the transform's
orientation, the sign of its signed volume) or vanishes at the solution or at any
iterate: there the map is not locally invertible (a fold) and a solution, if found, is
only one of several preimages. Points where Newton does not converge within
``max_iter`` iterations (or hits a singular Jacobian) are marked not converged and come
back as NaN. A flat transform (zero volume everywhere: ``det J == 0`` on a 3x3x3 sample,
which for this degree-2-per-variable polynomial means everywhere) has no inverse and
raises :class:`~voxwarp.deform.warp.WarpError`.

*Grids of trilinear cells* (sections 5-6: hierarchical lattices): a
:class:`TrilinearGrid` holds ``(nx+1, ny+1, nz+1)`` world nodes; node ``(i, j, k)`` is
the image of the unit-cube point ``(i/nx, j/ny, k/nz)`` and each cell is a trilinear
transformation of its eight nodes. The map is continuous across cells. Outside
``[0,1]^3`` the grid *extrapolates*: a point is evaluated with the polynomial of the
nearest border cell (its cell index is clamped, its local coordinates are not), so the
map extends linearly along the border cells' edges. The grid's inverse finds candidate
cells whose node bounding box (padded) contains the world point through a uniform
bucket grid over the world bounds, runs Newton in every candidate (vectorised over all
point/cell pairs) and keeps a solution that converged inside its cell (tolerance
``1e-6`` in cell coordinates), preferring unfolded ones; a point with two distinct
accepted preimages is reported folded. Points outside the lattice come back NaN and not
converged (``outside="nan"``, the default) or, with ``outside="extrapolate"``, are
inverted through the extrapolated border cells (then ``u`` lies outside ``[0,1]^3``).

*Composition* (section 4.1, the scene graph's ``G o L``): ``outer.compose(inner)``
evaluates the outer grid at the inner grid's nodes after resampling the inner grid to
the higher resolution of the two (per axis). Within each fine cell the result is the
trilinear interpolation of the exact composition at its nodes, so the error shrinks
like ``h^2`` with the cell size ``h``; two linear grids compose exactly (the matrix
product).

On the GPU the node grid is an RGBA32F 3D texture (:meth:`TrilinearGrid.texture_data`)
whose hardware trilinear filtering, at node-centred texture coordinates
``(u * n + 0.5) / (n + 1)``, *is* the lattice map.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from voxwarp.deform.warp import WarpError

__all__ = [
    "MONOMIALS",
    "UNIT_CORNERS",
    "TrilinearGrid",
    "TrilinearTransform",
    "carry_normals",
    "cofactor_matrix",
    "corner_to_coefficient_matrix",
]

#: Names of the monomials of ``v(u)``, the column order of the coefficient matrix.
MONOMIALS: tuple[str, ...] = ("xyz", "yz", "xz", "xy", "z", "y", "x", "1")
#: Bit set (x = 1, y = 2, z = 4) of each monomial in :data:`MONOMIALS`.
_MONOMIAL_BITS: tuple[int, ...] = (7, 6, 5, 3, 4, 2, 1, 0)
#: Unit-cube coordinates of the eight corners (index = x + 2 y + 4 z).
UNIT_CORNERS: np.ndarray = np.array(
    [[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=np.float64
)
UNIT_CORNERS.setflags(write=False)
#: Relative size of the non-linear columns of ``C`` below which a transform is linear.
LINEAR_RTOL = 1e-10
#: Relative size of ``det J`` (to the product of its column norms) treated as zero.
SINGULAR_RTOL = 1e-12
#: How far (in cell coordinates) a grid inverse may land outside its cell and count.
INSIDE_TOL = 1e-6
#: Length of the direct normal ``J n`` (relative to ``|n|`` times J's largest column)
#: below which :func:`carry_normals` falls back to the tangent-space normal.
DIRECT_NORMAL_RTOL = 1e-6
#: Normal methods of :func:`carry_normals` (GRAPP 2010, section 4.2).
NORMAL_METHODS: tuple[str, ...] = ("normal", "tangent")
#: Points per batch of the grid inverse (bounds the memory of its (point, cell) pairs).
INVERSE_CHUNK = 65536
#: Two accepted preimages further apart than this (unit-cube coordinates): a fold.
DISTINCT_TOL = 1e-6

_EPS = np.finfo(np.float64).eps
_GAUSS = 0.5 + np.array([-0.5, 0.5]) / np.sqrt(3.0)  # 2-point Gauss-Legendre on [0, 1]


def corner_to_coefficient_matrix() -> np.ndarray:
    """The integer matrix ``M`` (8, 8) with ``C = corners.T @ M``.

    Returns
    -------
    numpy.ndarray
        ``M[i, m]`` is the weight of corner ``i`` in the coefficient of monomial ``m``
        (order :data:`MONOMIALS`): ``(-1)^(|S| - |bits(i)|)`` when the bits of ``i`` are
        a subset of the monomial's variable set ``S``, else 0.
    """
    m = np.zeros((8, 8), dtype=np.float64)
    for col, s in enumerate(_MONOMIAL_BITS):
        for i in range(8):
            if i & ~s == 0:
                m[i, col] = (-1.0) ** (bin(s).count("1") - bin(i).count("1"))
    return m


_M = corner_to_coefficient_matrix()
_M.setflags(write=False)


# ------------------------------------------------------------------ input checks
def _points(u: Any, what: str = "points") -> tuple[np.ndarray, tuple[int, ...]]:
    """(N, 3) float64 view of ``u`` (any (..., 3)) and the leading shape."""
    try:
        a = np.asarray(u, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise WarpError(f"{what} must be numbers of shape (N, 3); got {u!r:.60}") from exc
    if a.ndim == 0 or a.shape[-1] != 3:
        raise WarpError(f"{what} must have shape (N, 3) or (3,); got shape {a.shape}")
    if not np.isfinite(a).all():
        raise WarpError(f"{what} contain NaN or infinite values; drop or mask them first")
    return a.reshape(-1, 3), a.shape[:-1]


def _matrix4(m4: Any, what: str = "matrix") -> np.ndarray:
    """A finite affine 4x4 matrix (last row 0 0 0 1)."""
    try:
        m = np.asarray(m4, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise WarpError(f"{what} must be a 4x4 array of numbers") from exc
    if m.shape != (4, 4) or not np.isfinite(m).all():
        raise WarpError(f"{what} must be a finite 4x4 affine matrix; got shape {m.shape}")
    if not np.allclose(m[3], (0.0, 0.0, 0.0, 1.0), atol=1e-12):
        raise WarpError(f"{what} must be affine: make its last row (0, 0, 0, 1), got {m[3]}")
    return m


def _cells3(cells: Any) -> tuple[int, int, int]:
    """Cells per axis from an int or a 3-sequence, each >= 1."""
    c = np.broadcast_to(np.asarray(cells), (3,)) if np.ndim(cells) == 0 else np.asarray(cells)
    if c.shape != (3,) or not all(float(v).is_integer() and v >= 1 for v in c.tolist()):
        raise WarpError(f"cells must be an int or 3 ints >= 1 (cells per axis); got {cells!r}")
    return (int(c[0]), int(c[1]), int(c[2]))


def _unit_nodes(cells: tuple[int, int, int]) -> np.ndarray:
    """(nx+1, ny+1, nz+1, 3) unit-cube coordinates of the nodes of a grid."""
    axes = [np.linspace(0.0, 1.0, n + 1) for n in cells]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)


# ------------------------------------------------------------- shared kernels
def _corner_weights(t: np.ndarray) -> np.ndarray:
    """(N, 8) corner weights of eq. 1 at local coordinates ``t`` (N, 3)."""
    x, y, z = t[:, 0:1], t[:, 1:2], t[:, 2:3]
    bx = np.concatenate([1.0 - x, x], axis=1)  # (N, 2)
    by = np.concatenate([1.0 - y, y], axis=1)
    bz = np.concatenate([1.0 - z, z], axis=1)
    # index = x + 2 y + 4 z: z slowest -> (N, z, y, x)
    w = bz[:, :, None, None] * by[:, None, :, None] * bx[:, None, None, :]
    return w.reshape(-1, 8)


def _monomials(t: np.ndarray) -> np.ndarray:
    """(N, 8) monomial vectors ``v = (xyz, yz, xz, xy, z, y, x, 1)``."""
    x, y, z = t[:, 0], t[:, 1], t[:, 2]
    yz, xz, xy = y * z, x * z, x * y
    return np.stack([xy * z, yz, xz, xy, z, y, x, np.ones_like(x)], axis=1)


def _eval_coef(c: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``C v(t)``; ``c`` is (3, 8) or per point (N, 3, 8)."""
    v = _monomials(t)
    if c.ndim == 2:
        return v @ c.T
    return np.einsum("nij,nj->ni", c, v)


def _jac_columns(c: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Columns ``dT/dx, dT/dy, dT/dz`` (each (N, 3)) of the coefficient form."""
    x, y, z = t[:, 0:1], t[:, 1:2], t[:, 2:3]
    col = (lambda k: c[:, k]) if c.ndim == 2 else (lambda k: c[:, :, k])
    c0, c1, c2, c3 = col(0), col(1), col(2), col(3)
    dx = col(6) + y * c3 + z * c2 + (y * z) * c0
    dy = col(5) + x * c3 + z * c1 + (x * z) * c0
    dz = col(4) + x * c2 + y * c1 + (x * y) * c0
    return dx, dy, dz


def _det_columns(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``det [a b c]`` and the product of the column norms (its natural scale)."""
    det = np.einsum("ni,ni->n", a, np.cross(b, c))
    scale = np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1) * np.linalg.norm(c, axis=1)
    return det, scale


def _newton(
    coef: np.ndarray,
    x: np.ndarray,
    u0: np.ndarray,
    tol: float,
    max_iter: int,
    orient: float,
    lower: np.ndarray | None = None,
    upper: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vectorised Newton solve of ``C v(u) = x``.

    ``coef`` is (3, 8) or per point (P, 3, 8). ``lower``/``upper`` (P, 3), if given,
    bound where a solution is of use: an iterate more than 4 cell units beyond them is
    abandoned. Returns ``(u, converged, folded)``; ``u`` is the last iterate.
    """
    p = len(x)
    u = np.array(u0, dtype=np.float64, copy=True)
    conv = np.zeros(p, dtype=bool)
    fold = np.zeros(p, dtype=bool)
    per_point = coef.ndim == 3
    cmag = np.abs(coef).max(axis=(-2, -1))  # (P,) or ()
    noise = 64.0 * _EPS * (8.0 * cmag + np.abs(x).max(axis=1))
    active = np.arange(p)
    for _ in range(max_iter):
        if active.size == 0:
            break
        ca = coef[active] if per_point else coef
        ua, xa = u[active], x[active]
        r = _eval_coef(ca, ua) - xa
        a, b, c = _jac_columns(ca, ua)
        bc, ca_, ab = np.cross(b, c), np.cross(c, a), np.cross(a, b)
        det = np.einsum("ni,ni->n", a, bc)
        scale = np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1) * np.linalg.norm(c, axis=1)
        singular = ~(np.abs(det) > SINGULAR_RTOL * scale)
        fold[active] |= ~(det * orient > SINGULAR_RTOL * scale)
        res_ok = np.abs(r).max(axis=1) <= noise[active]
        safe = np.where(singular, 1.0, det)
        step = (
            np.stack(
                [
                    np.einsum("ni,ni->n", bc, r),
                    np.einsum("ni,ni->n", ca_, r),
                    np.einsum("ni,ni->n", ab, r),
                ],
                axis=1,
            )
            / safe[:, None]
        )
        move = ~singular & ~res_ok
        ua = ua - np.where(move[:, None], step, 0.0)
        u[active] = ua
        step_ok = move & (np.abs(step).max(axis=1) <= tol)
        done = res_ok | step_ok
        conv[active[done]] = True
        stop = done | singular | ~np.isfinite(ua).all(axis=1)
        if lower is not None and upper is not None:
            out = np.maximum(lower[active] - ua, ua - upper[active]).max(axis=1)
            stop |= out > 4.0
        active = active[~stop]
    # the sign of det J at the solutions found
    idx = np.flatnonzero(conv)
    if idx.size:
        cs = coef[idx] if per_point else coef
        a, b, c = _jac_columns(cs, u[idx])
        det, scale = _det_columns(a, b, c)
        fold[idx] |= ~(det * orient > SINGULAR_RTOL * scale)
    return u, conv, fold


def _affine_fit(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares affine fit ``u -> A u + t`` of eight corners (the linear part).

    On the symmetric unit-cube corners the columns of ``A`` are the means of the four
    parallel edges and ``A (0.5, 0.5, 0.5) + t`` is the mean of the corners.
    """
    a = np.stack(
        [
            corners[1::2].mean(axis=0) - corners[0::2].mean(axis=0),
            corners[[2, 3, 6, 7]].mean(axis=0) - corners[[0, 1, 4, 5]].mean(axis=0),
            corners[4:].mean(axis=0) - corners[:4].mean(axis=0),
        ],
        axis=1,
    )
    t = corners.mean(axis=0) - a @ np.full(3, 0.5)
    return a, t


def _affine_inverse(a: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """``(A^-1, t)`` or None when ``A`` is (numerically) singular."""
    det = np.linalg.det(a)
    scale = float(np.prod(np.linalg.norm(a, axis=0)))
    if not abs(det) > SINGULAR_RTOL * scale:
        return None
    return np.linalg.inv(a), t


def cofactor_matrix(a: np.ndarray) -> np.ndarray:
    """Cofactor matrices of (..., 3, 3) matrices: ``cof(A) = det(A) A^-T`` where A is
    invertible, still defined where it is singular. ``cof(A) (x cross y) = A x cross A y``."""
    c0, c1, c2 = a[..., :, 0], a[..., :, 1], a[..., :, 2]
    return np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=-1)


def carry_normals(jac: Any, normals: Any, method: str = "normal") -> np.ndarray:
    """Unit normals carried by Jacobians ``J = d world / d local`` (GRAPP 2010, section 4.2).

    The paper lists two methods and numbers them differently in Figure 5's caption
    (method 1: direct) and in section 4.2's text (first: tangent space), so they are
    named by what they do. The vertex shader ``shaders/mesh.vert.glsl`` does the same.

    Parameters
    ----------
    jac : array_like, shape (N, 3, 3)
        Jacobians at the vertices.
    normals : array_like, shape (N, 3)
        Local vertex normals.
    method : str
        ``"normal"``, the direct transform ``J n``: smooth across cell faces (J's
        columns along a shared face agree on both sides), not always orthogonal to the
        deformed surface. ``"tangent"``: two tangents ``t1 x t2 = n`` through J, crossed,
        ``= cof(J) n``: orthogonal to the deformed surface, but it jumps across cell
        faces. Where ``J n`` nearly vanishes (``n`` in J's null space, a flattened
        lattice) ``"normal"`` falls back to ``"tangent"``.

    Returns
    -------
    numpy.ndarray
        (N, 3) float64 unit normals.
    """
    if method not in NORMAL_METHODS:
        raise WarpError(f"normal method must be one of {', '.join(NORMAL_METHODS)}; got {method!r}")
    j = np.asarray(jac, dtype=np.float64).reshape(-1, 3, 3)
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    out = np.einsum("nij,nj->ni", cofactor_matrix(j), n)
    if method == "normal":
        direct = np.einsum("nij,nj->ni", j, n)
        scale = np.linalg.norm(j, axis=1).max(axis=1) * np.linalg.norm(n, axis=1)
        ok = np.linalg.norm(direct, axis=1) > DIRECT_NORMAL_RTOL * scale
        out[ok] = direct[ok]
    length = np.linalg.norm(out, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return out / length


# ========================================================== TrilinearTransform
class TrilinearTransform:
    """A trilinear transformation of the unit cube, given by its eight corners.

    Parameters
    ----------
    corners : array_like, shape (8, 3)
        World images of the unit-cube corners in the order ``index = x + 2 y + 4 z``:
        ``p0 = T(0,0,0)``, ``p1 = T(1,0,0)``, ``p2 = T(0,1,0)``, ``p3 = T(1,1,0)``,
        ``p4 = T(0,0,1)``, ``p5 = T(1,0,1)``, ``p6 = T(0,1,1)``, ``p7 = T(1,1,1)``.

    Attributes
    ----------
    corners : numpy.ndarray
        (8, 3) float64, read-only.
    coefficients : numpy.ndarray
        ``C`` (3, 8), read-only: ``T(u) = C v(u)``, ``v = (xyz, yz, xz, xy, z, y, x, 1)``.
    is_linear : bool
        True when the ``xyz, yz, xz, xy`` columns of ``C`` vanish (relative to the edge
        lengths, :data:`LINEAR_RTOL`): the corners form a parallelepiped and ``T`` is
        affine (:meth:`matrix`).

    Raises
    ------
    WarpError
        When ``corners`` is not a finite (8, 3) array.

    Notes
    -----
    ``T`` is a polynomial and is defined on all of R^3; :meth:`__call__` evaluates it
    outside the unit cube too (trilinear extrapolation).
    """

    def __init__(self, corners: Any) -> None:
        try:
            p = np.array(corners, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise WarpError("corners must be an (8, 3) array of numbers") from exc
        if p.shape != (8, 3):
            raise WarpError(
                f"corners must have shape (8, 3) (order x + 2y + 4z); got shape {p.shape}"
            )
        if not np.isfinite(p).all():
            raise WarpError("corners contain NaN or infinite values; give 8 finite points")
        p.setflags(write=False)
        self.corners: np.ndarray = p
        c = p.T @ _M
        c.setflags(write=False)
        self.coefficients: np.ndarray = c
        edge = float(np.abs(c[:, 4:7]).max())
        self.is_linear: bool = bool(np.abs(c[:, :4]).max() <= LINEAR_RTOL * edge)
        self._cache: dict[str, Any] = {}

    # ------------------------------------------------------------ constructors
    @classmethod
    def identity(cls) -> TrilinearTransform:
        """The identity of the unit cube.

        Returns
        -------
        TrilinearTransform
            Corners equal to the unit-cube corners.
        """
        return cls(UNIT_CORNERS)

    @classmethod
    def from_matrix(cls, m4: Any) -> TrilinearTransform:
        """The affine map of a 4x4 matrix restricted to the unit cube.

        Parameters
        ----------
        m4 : array_like, shape (4, 4)
            Affine matrix (last row ``0 0 0 1``) acting on column vectors ``(u, 1)``.

        Returns
        -------
        TrilinearTransform
            A linear transform whose :meth:`matrix` is ``m4``.

        Raises
        ------
        WarpError
            When ``m4`` is not a finite affine 4x4 matrix.
        """
        m = _matrix4(m4)
        return cls(UNIT_CORNERS @ m[:3, :3].T + m[:3, 3])

    @classmethod
    def from_box(cls, lo: Any, hi: Any) -> TrilinearTransform:
        """The axis-aligned box ``[lo, hi]`` (unit cube -> box).

        Parameters
        ----------
        lo, hi : array_like, shape (3,)
            Opposite box corners, ``lo < hi`` on every axis.

        Returns
        -------
        TrilinearTransform
            ``T(u) = lo + u * (hi - lo)``.

        Raises
        ------
        WarpError
            When the box is not finite or has ``hi <= lo`` on some axis.
        """
        lo_, hi_ = _box(lo, hi)
        return cls(lo_ + UNIT_CORNERS * (hi_ - lo_))

    # -------------------------------------------------------------- evaluation
    def matrix(self) -> np.ndarray:
        """The 4x4 affine matrix of a linear transform (unit cube -> world).

        Returns
        -------
        numpy.ndarray
            ``[[C_x C_y C_z C_1], [0 0 0 1]]`` (4, 4).

        Raises
        ------
        WarpError
            When the transform is not linear (the corners are no parallelepiped).
        """
        if not self.is_linear:
            raise WarpError(
                "this trilinear transform is not linear (its corners are no parallelepiped);"
                " use __call__/inverse instead of matrix(), or check is_linear first"
            )
        return self._matrix()

    def _matrix(self) -> np.ndarray:
        c = self.coefficients
        m = np.eye(4)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = c[:, 6], c[:, 5], c[:, 4], c[:, 7]
        return m

    def __call__(self, u: Any) -> np.ndarray:
        """Map unit-cube coordinates to world points.

        Parameters
        ----------
        u : array_like, shape (N, 3) or (3,)
            Unit-cube coordinates (points outside ``[0,1]^3`` are extrapolated).

        Returns
        -------
        numpy.ndarray
            World points, same shape as ``u``. A linear transform uses its matrix; any
            other the corner form (eq. 1, :meth:`evaluate_corners`).

        Raises
        ------
        WarpError
            When ``u`` has the wrong shape or contains NaN.
        """
        t, lead = _points(u)
        if self.is_linear:
            m = self._matrix()
            out = t @ m[:3, :3].T + m[:3, 3]
        else:
            out = _corner_weights(t) @ self.corners
        return out.reshape(*lead, 3)

    def evaluate_corners(self, u: Any) -> np.ndarray:
        """Corner form (eq. 1): ``sum_i p_i b(x) b(y) b(z)``; same contract as ``__call__``.

        Parameters
        ----------
        u : array_like, shape (N, 3) or (3,)
            Unit-cube coordinates.

        Returns
        -------
        numpy.ndarray
            World points, same shape as ``u``.
        """
        t, lead = _points(u)
        return (_corner_weights(t) @ self.corners).reshape(*lead, 3)

    def evaluate_coefficients(self, u: Any) -> np.ndarray:
        """Coefficient form (eqs. 2-4): ``C v(u)``; same contract as ``__call__``.

        Parameters
        ----------
        u : array_like, shape (N, 3) or (3,)
            Unit-cube coordinates.

        Returns
        -------
        numpy.ndarray
            World points, same shape as ``u``.
        """
        t, lead = _points(u)
        return _eval_coef(self.coefficients, t).reshape(*lead, 3)

    def jacobian(self, u: Any) -> np.ndarray:
        """The Jacobian ``dT/du``.

        Parameters
        ----------
        u : array_like, shape (N, 3) or (3,)
            Unit-cube coordinates.

        Returns
        -------
        numpy.ndarray
            Shape (N, 3, 3) (or (3, 3)); ``J[n, i, j] = d T_i / d u_j``.
        """
        t, lead = _points(u)
        dx, dy, dz = _jac_columns(self.coefficients, t)
        return np.stack([dx, dy, dz], axis=-1).reshape(*lead, 3, 3)

    # ------------------------------------------------------------ properties
    @property
    def volume(self) -> float:
        """Signed volume ``integral of det J over [0,1]^3`` (exact, 2x2x2 Gauss points).

        Returns
        -------
        float
            Negative for an orientation-reversing (mirrored) transform.
        """
        if "volume" not in self._cache:
            g = np.stack(np.meshgrid(_GAUSS, _GAUSS, _GAUSS, indexing="ij"), -1).reshape(-1, 3)
            a, b, c = _jac_columns(self.coefficients, g)
            det, _ = _det_columns(a, b, c)
            self._cache["volume"] = float(det.mean())
        return self._cache["volume"]

    def _size(self) -> float:
        """Largest corner distance from ``p0`` (the transform's scale)."""
        return float(np.abs(self.corners - self.corners[0]).max())

    def _dets(self, n: int) -> tuple[np.ndarray, float]:
        """``det J`` on an ``n^3`` sample of the cube and the zero threshold."""
        s = np.linspace(0.0, 1.0, n)
        g = np.stack(np.meshgrid(s, s, s, indexing="ij"), -1).reshape(-1, 3)
        a, b, c = _jac_columns(self.coefficients, g)
        det, _ = _det_columns(a, b, c)
        return det, SINGULAR_RTOL * self._size() ** 3

    def is_flat(self) -> bool:
        """True when ``det J == 0`` throughout the cube (zero volume everywhere).

        Returns
        -------
        bool
            ``det J`` is a polynomial of degree <= 2 in each variable, so vanishing on a
            3x3x3 sample means vanishing everywhere.
        """
        det, thr = self._dets(3)
        return bool(np.abs(det).max() <= thr)

    def folds(self) -> bool:
        """Whether ``det J`` changes sign or vanishes inside the unit cube (sampled).

        Returns
        -------
        bool
            True when ``det J`` on a 9x9x9 sample takes both signs or is ~0 somewhere.
            A mirrored (orientation-reversing) but regular transform does not fold.
        """
        det, thr = self._dets(9)
        return bool(not (det.min() > thr or det.max() < -thr))

    def _orientation(self) -> float:
        v = self.volume
        return -1.0 if v < 0 else 1.0

    # --------------------------------------------------------------- inverse
    def inverse(
        self,
        x: Any,
        tol: float = 1e-10,
        max_iter: int = 30,
        return_info: bool = False,
    ) -> np.ndarray | tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World points -> unit-cube coordinates (Newton's method).

        Parameters
        ----------
        x : array_like, shape (N, 3) or (3,)
            World points.
        tol : float
            Convergence: the last Newton step is at most ``tol`` (unit-cube units), or
            the residual is at floating-point noise level.
        max_iter : int
            Most Newton iterations per point.
        return_info : bool
            Also return ``(converged, folded)``.

        Returns
        -------
        u : numpy.ndarray
            Same shape as ``x``. Solutions may lie outside ``[0,1]^3`` (the polynomial
            extension) - check the range if only the cube is wanted. Points that did not
            converge are NaN.
        converged, folded : numpy.ndarray of bool, shape (N,)
            Only with ``return_info``. ``folded``: ``det J`` has the wrong sign (against
            the sign of :attr:`volume`) or vanishes at the solution or at an iterate.

        Raises
        ------
        WarpError
            When ``x`` is malformed or the transform is flat (zero volume).
        """
        xs, lead = _points(x)
        if max_iter < 1 or not tol > 0:
            raise WarpError("inverse needs tol > 0 and max_iter >= 1")
        if self.is_flat():
            raise WarpError(
                "this trilinear transform is flat (zero volume), it has no inverse; move the"
                " corners so that they span a volume"
            )
        if self.is_linear:
            m = self._matrix()
            u = np.linalg.solve(m[:3, :3], (xs - m[:3, 3]).T).T
            conv = np.ones(len(xs), dtype=bool)
            fold = np.zeros(len(xs), dtype=bool)
        else:
            a, t = _affine_fit(self.corners)
            inv = _affine_inverse(a, t)
            u0 = (xs - t) @ inv[0].T if inv is not None else np.full_like(xs, 0.5)
            u, conv, fold = _newton(
                self.coefficients, xs, u0, float(tol), int(max_iter), self._orientation()
            )
            u[~conv] = np.nan
        u = u.reshape(*lead, 3)
        if return_info:
            return u, conv.reshape(lead), fold.reshape(lead)
        return u

    # -------------------------------------------------------------------- io
    def to_dict(self) -> dict[str, Any]:
        """JSON form.

        Returns
        -------
        dict
            ``{"corners": 8 x 3 nested lists}``.
        """
        return {"corners": self.corners.tolist()}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TrilinearTransform:
        """Rebuild from :meth:`to_dict`'s form.

        Parameters
        ----------
        d : Mapping
            Must hold ``"corners"``.

        Returns
        -------
        TrilinearTransform

        Raises
        ------
        WarpError
            When the key is missing or the corners are malformed.
        """
        if not isinstance(d, Mapping) or "corners" not in d:
            raise WarpError("a trilinear transform entry needs 'corners' (8 x 3 numbers)")
        return cls(d["corners"])

    def __repr__(self) -> str:
        kind = "linear" if self.is_linear else "trilinear"
        return f"TrilinearTransform({kind}, corners={self.corners.tolist()})"


def _box(lo: Any, hi: Any) -> tuple[np.ndarray, np.ndarray]:
    try:
        lo_ = np.asarray(lo, dtype=np.float64).reshape(3)
        hi_ = np.asarray(hi, dtype=np.float64).reshape(3)
    except (TypeError, ValueError) as exc:
        raise WarpError("a box needs lo and hi of 3 numbers each") from exc
    if not (np.isfinite(lo_).all() and np.isfinite(hi_).all()) or not (hi_ > lo_).all():
        raise WarpError(f"a box needs finite lo < hi on every axis; got lo={lo_}, hi={hi_}")
    return lo_, hi_


# =============================================================== TrilinearGrid
class TrilinearGrid:
    """A uniform grid of trilinear cells mapping the unit cube to world.

    Node ``(i, j, k)`` is the image of the unit-cube point ``(i/nx, j/ny, k/nz)``; each
    cell is a :class:`TrilinearTransform` of its eight nodes. Outside ``[0,1]^3`` the map
    is extrapolated with the polynomial of the nearest border cell (see the module
    docstring).

    Parameters
    ----------
    nodes : array_like, shape (nx+1, ny+1, nz+1, 3)
        World node points, at least 2 per axis (one cell).

    Attributes
    ----------
    nodes : numpy.ndarray
        (nx+1, ny+1, nz+1, 3) float64, read-only (build a new grid to change it).
    shape : tuple of int
        Cells per axis ``(nx, ny, nz)``.

    Raises
    ------
    WarpError
        When ``nodes`` is not a finite (a, b, c, 3) array with a, b, c >= 2.
    """

    def __init__(self, nodes: Any) -> None:
        try:
            n = np.array(nodes, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise WarpError("grid nodes must be an (nx+1, ny+1, nz+1, 3) array of numbers") from exc
        if n.ndim != 4 or n.shape[3] != 3 or min(n.shape[:3]) < 2:
            raise WarpError(
                "grid nodes must have shape (nx+1, ny+1, nz+1, 3) with at least 2 nodes"
                f" (1 cell) per axis; got shape {n.shape}"
            )
        if not np.isfinite(n).all():
            raise WarpError("grid nodes contain NaN or infinite values; give finite points")
        n.setflags(write=False)
        self.nodes: np.ndarray = n
        self.shape: tuple[int, int, int] = (n.shape[0] - 1, n.shape[1] - 1, n.shape[2] - 1)
        self._cache: dict[str, Any] = {}

    # ------------------------------------------------------------ constructors
    @classmethod
    def identity(cls, cells: Any = (1, 1, 1)) -> TrilinearGrid:
        """The identity of the unit cube sampled on ``cells`` cells.

        Parameters
        ----------
        cells : int or sequence of 3 ints
            Cells per axis.

        Returns
        -------
        TrilinearGrid
        """
        return cls(_unit_nodes(_cells3(cells)))

    @classmethod
    def from_transform(cls, transform: TrilinearTransform, cells: Any = (1, 1, 1)) -> TrilinearGrid:
        """Sample a :class:`TrilinearTransform` (exact: a refined trilinear map).

        Parameters
        ----------
        transform : TrilinearTransform
        cells : int or sequence of 3 ints
            Cells per axis.

        Returns
        -------
        TrilinearGrid
        """
        return cls(transform(_unit_nodes(_cells3(cells))))

    @classmethod
    def from_function(
        cls, f: Callable[[np.ndarray], np.ndarray], cells: Any = (1, 1, 1)
    ) -> TrilinearGrid:
        """Sample any map of the unit cube at the nodes.

        Parameters
        ----------
        f : callable
            ``f((N, 3) unit-cube points) -> (N, 3) world points``.
        cells : int or sequence of 3 ints
            Cells per axis.

        Returns
        -------
        TrilinearGrid

        Raises
        ------
        WarpError
            When ``f`` returns the wrong shape or non-finite points.
        """
        c = _cells3(cells)
        u = _unit_nodes(c).reshape(-1, 3)
        out = np.asarray(f(u), dtype=np.float64)
        if out.shape != u.shape:
            raise WarpError(f"f must map (N, 3) points to (N, 3); got shape {out.shape}")
        return cls(out.reshape(c[0] + 1, c[1] + 1, c[2] + 1, 3))

    @classmethod
    def from_matrix(cls, m4: Any, cells: Any = (1, 1, 1)) -> TrilinearGrid:
        """An affine 4x4 map (unit cube -> world) as a grid.

        Parameters
        ----------
        m4 : array_like, shape (4, 4)
            Affine matrix on column vectors ``(u, 1)``.
        cells : int or sequence of 3 ints
            Cells per axis.

        Returns
        -------
        TrilinearGrid
            A linear grid whose :meth:`matrix` is ``m4``.
        """
        m = _matrix4(m4)
        return cls(_unit_nodes(_cells3(cells)) @ m[:3, :3].T + m[:3, 3])

    @classmethod
    def from_box(cls, lo: Any, hi: Any, cells: Any = (1, 1, 1)) -> TrilinearGrid:
        """The undeformed lattice of the box ``[lo, hi]``.

        Parameters
        ----------
        lo, hi : array_like, shape (3,)
            Box corners, ``lo < hi``.
        cells : int or sequence of 3 ints
            Cells per axis.

        Returns
        -------
        TrilinearGrid
            ``u -> lo + u * (hi - lo)``.
        """
        lo_, hi_ = _box(lo, hi)
        return cls(lo_ + _unit_nodes(_cells3(cells)) * (hi_ - lo_))

    def with_box(self, lo: Any, hi: Any) -> TrilinearGrid:
        """Read the nodes as unit-cube coordinates of a box and return them in world.

        Parameters
        ----------
        lo, hi : array_like, shape (3,)
            Box corners, ``lo < hi``.

        Returns
        -------
        TrilinearGrid
            Nodes ``lo + nodes * (hi - lo)``: a lattice edited in normalised coordinates
            (the identity being :meth:`identity`) placed on the box.
        """
        lo_, hi_ = _box(lo, hi)
        return TrilinearGrid(lo_ + self.nodes * (hi_ - lo_))

    # ------------------------------------------------------------ cell data
    @property
    def n_cells(self) -> int:
        """Total number of cells ``nx * ny * nz``."""
        return self.shape[0] * self.shape[1] * self.shape[2]

    def _cell_corners(self) -> np.ndarray:
        """(cells, 8, 3) corners of every cell, cells in C order (i slowest)."""
        if "corners" not in self._cache:
            nx, ny, nz = self.shape
            n = self.nodes
            cs = [
                n[(i & 1) : (i & 1) + nx, ((i >> 1) & 1) : ((i >> 1) & 1) + ny,
                  ((i >> 2) & 1) : ((i >> 2) & 1) + nz]
                for i in range(8)
            ]  # fmt: skip
            self._cache["corners"] = np.stack(cs, axis=3).reshape(-1, 8, 3)
        return self._cache["corners"]

    def _coefficients(self) -> np.ndarray:
        """(cells, 3, 8) coefficient matrices of every cell."""
        if "coef" not in self._cache:
            self._cache["coef"] = np.einsum("cki,km->cim", self._cell_corners(), _M)
        return self._cache["coef"]

    def cell(self, i: int, j: int, k: int) -> TrilinearTransform:
        """Cell ``(i, j, k)`` as a transformation of its own unit cube.

        Parameters
        ----------
        i, j, k : int
            Cell indices, ``0 <= i < nx`` etc.

        Returns
        -------
        TrilinearTransform
            Local coordinate ``t`` of the cell is global ``((i, j, k) + t) / shape``.

        Raises
        ------
        WarpError
            When an index is out of range.
        """
        idx = (i, j, k)
        if not all(
            isinstance(v, int | np.integer) and 0 <= v < s
            for v, s in zip(idx, self.shape, strict=True)
        ):
            raise WarpError(f"cell index {idx} out of range; cells per axis are {self.shape}")
        return TrilinearTransform(
            self.nodes[i : i + 2, j : j + 2, k : k + 2].transpose(2, 1, 0, 3).reshape(8, 3)
        )

    def _locate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Flat cell index (N,) and local coordinates (N, 3) of unit points (clamped cells)."""
        n = np.asarray(self.shape, dtype=np.float64)
        s = t * n
        ijk = np.clip(np.floor(s), 0, n - 1).astype(np.intp)
        local = s - ijk
        flat = (ijk[:, 0] * self.shape[1] + ijk[:, 1]) * self.shape[2] + ijk[:, 2]
        return flat, local

    # ------------------------------------------------------------- linearity
    def _fit(self) -> tuple[np.ndarray, np.ndarray, float]:
        """Least-squares affine fit ``u -> A u + t`` of all nodes and its max residual."""
        if "fit" not in self._cache:
            u = _unit_nodes(self.shape).reshape(-1, 3)
            x = self.nodes.reshape(-1, 3)
            um = u.mean(axis=0)
            xm = x.mean(axis=0)
            sol, *_ = np.linalg.lstsq(u - um, x - xm, rcond=None)
            a = sol.T
            t = xm - a @ um
            res = float(np.abs(u @ a.T + t - x).max())
            self._cache["fit"] = (a, t, res)
        return self._cache["fit"]

    def _extent(self) -> float:
        n = self.nodes.reshape(-1, 3)
        return float((n.max(axis=0) - n.min(axis=0)).max())

    @property
    def is_linear(self) -> bool:
        """True when the whole grid is one affine map (nodes on an affine image of the cube).

        Returns
        -------
        bool
            The max node deviation from the least-squares affine fit is at most
            :data:`LINEAR_RTOL` times the grid's extent.
        """
        if "linear" not in self._cache:
            # cheap rejections first (animated scenes ask this of every new composed
            # grid): the affine map through four corners misses the nodes of a grid within
            # tol of an affine map by at most 6 tol; the 8 corners alone first (an affine
            # grid's extent is its corners' extent)
            if self._far_corner_residual() > 8 * LINEAR_RTOL * self._corner_extent():
                self._cache["linear"] = False
            else:
                tol = LINEAR_RTOL * self._extent()
                linear = self._corner_residual() <= 8 * tol and self._fit()[2] <= tol
                self._cache["linear"] = bool(linear)
        return self._cache["linear"]

    def _corners(self) -> np.ndarray:
        """The 8 corner nodes, (2, 2, 2, 3) (a view)."""
        n = self.nodes
        return n[:: n.shape[0] - 1, :: n.shape[1] - 1, :: n.shape[2] - 1]

    def _corner_extent(self) -> float:
        c = self._corners().reshape(8, 3)
        return float((c.max(axis=0) - c.min(axis=0)).max())

    def _far_corner_residual(self) -> float:
        """Distance of the corner (1,1,1) from the affine map through the corners
        (0,0,0), (1,0,0), (0,1,0), (0,0,1): O(1), rejects most bent grids at once."""
        c = self._corners()
        far = c[1, 1, 1] - c[1, 0, 0] - c[0, 1, 0] - c[0, 0, 1] + 2.0 * c[0, 0, 0]
        return float(np.abs(far).max())

    def _corner_residual(self) -> float:
        """Max node distance from the affine map through the corners (0,0,0), (1,0,0),
        (0,1,0) and (0,0,1)."""
        n = self.nodes
        o = n[0, 0, 0]
        f = [np.arange(c + 1) / c for c in self.shape]
        pred = (
            o
            + f[0][:, None, None, None] * (n[-1, 0, 0] - o)
            + f[1][None, :, None, None] * (n[0, -1, 0] - o)
            + f[2][None, None, :, None] * (n[0, 0, -1] - o)
        )
        return float(np.abs(pred - n).max())

    def matrix(self) -> np.ndarray:
        """The 4x4 affine matrix of a linear grid (unit cube -> world).

        Returns
        -------
        numpy.ndarray
            (4, 4), last row ``0 0 0 1``.

        Raises
        ------
        WarpError
            When the grid is not one affine map.
        """
        if not self.is_linear:
            raise WarpError(
                "this lattice is not one affine map; use __call__/inverse instead of matrix(),"
                " or check is_linear first"
            )
        a, t, _ = self._fit()
        m = np.eye(4)
        m[:3, :3], m[:3, 3] = a, t
        return m

    # -------------------------------------------------------------- evaluation
    def __call__(self, u: Any) -> np.ndarray:
        """Map unit-cube coordinates to world (trilinear in each cell).

        Parameters
        ----------
        u : array_like, shape (N, 3) or (3,)
            Unit-cube coordinates; outside ``[0,1]^3`` the border cells extrapolate.

        Returns
        -------
        numpy.ndarray
            World points, same shape as ``u``.

        Raises
        ------
        WarpError
            When ``u`` has the wrong shape or contains NaN.
        """
        t, lead = _points(u)
        if self.is_linear:
            a, tr, _ = self._fit()
            out = t @ a.T + tr
        else:
            from voxwarp.deform.lattice.kernel import eval_grid  # numba: on first use

            out = np.empty_like(t)
            eval_grid(self._contiguous_nodes(), np.ascontiguousarray(t), out)
        return out.reshape(*lead, 3)

    def _contiguous_nodes(self) -> np.ndarray:
        if "c_nodes" not in self._cache:
            self._cache["c_nodes"] = np.ascontiguousarray(self.nodes, dtype=np.float64)
        return self._cache["c_nodes"]

    def jacobian(self, u: Any) -> np.ndarray:
        """The Jacobian ``d grid / du`` (unit-cube coordinates).

        Parameters
        ----------
        u : array_like, shape (N, 3) or (3,)
            Unit-cube coordinates. On a cell face the cell of the clamped floor index
            (the upper one, except at the border) is used.

        Returns
        -------
        numpy.ndarray
            (N, 3, 3) (or (3, 3)), ``J[n, i, j] = d x_i / d u_j``.
        """
        t, lead = _points(u)
        if self.is_linear:
            a, _, _ = self._fit()
            return np.broadcast_to(a, (*lead, 3, 3)).copy()
        flat, local = self._locate(t)
        dx, dy, dz = _jac_columns(self._coefficients()[flat], local)
        j = np.stack([dx, dy, dz], axis=-1) * np.asarray(self.shape, dtype=np.float64)
        return j.reshape(*lead, 3, 3)

    def _cell_dets(self, pts: np.ndarray) -> np.ndarray:
        """(cells, len(pts)) ``det J`` (cell-local) at local points ``pts``."""
        coef = self._coefficients()
        out = np.empty((coef.shape[0], len(pts)))
        for m, p in enumerate(pts):
            a, b, d = _jac_columns(coef, np.broadcast_to(p, (coef.shape[0], 3)))
            out[:, m], _ = _det_columns(a, b, d)
        return out

    def _orientation_and_flat(self) -> tuple[float, bool]:
        """Sign of the signed volume and whether ``det J ~ 0`` at all Gauss points."""
        if "orient" not in self._cache:
            g = np.stack(np.meshgrid(_GAUSS, _GAUSS, _GAUSS, indexing="ij"), -1).reshape(-1, 3)
            det = self._cell_dets(g)
            thr = SINGULAR_RTOL * self._extent() ** 3 / max(self.n_cells, 1)
            flat = bool(np.abs(det).max() <= thr)
            self._cache["orient"] = (-1.0 if det.sum() < 0 else 1.0, flat)
        return self._cache["orient"]

    @property
    def volume(self) -> float:
        """Signed volume of the lattice (exact: 2x2x2 Gauss points per cell).

        Returns
        -------
        float
        """
        g = np.stack(np.meshgrid(_GAUSS, _GAUSS, _GAUSS, indexing="ij"), -1).reshape(-1, 3)
        return float(self._cell_dets(g).mean(axis=1).sum())

    def folds(self) -> bool:
        """Whether ``det J`` vanishes or takes the wrong sign anywhere (sampled).

        Returns
        -------
        bool
            ``det J`` sampled at 3x3x3 points per cell, against the sign of the lattice's
            signed volume.
        """
        s = np.linspace(0.0, 1.0, 3)
        g = np.stack(np.meshgrid(s, s, s, indexing="ij"), -1).reshape(-1, 3)
        det = self._cell_dets(g)
        orient, _ = self._orientation_and_flat()
        thr = SINGULAR_RTOL * self._extent() ** 3 / max(self.n_cells, 1)
        return bool((det * orient <= thr).any())

    def folded_cells(self) -> np.ndarray:
        """The cells where :meth:`folds` finds ``det J`` vanishing or of the wrong sign.

        Returns
        -------
        numpy.ndarray
            ``(K, 3)`` cell indices ``(i, j, k)`` in C order (empty when nothing folds).
        """
        s = np.linspace(0.0, 1.0, 3)
        g = np.stack(np.meshgrid(s, s, s, indexing="ij"), -1).reshape(-1, 3)
        det = self._cell_dets(g)
        orient, _ = self._orientation_and_flat()
        thr = SINGULAR_RTOL * self._extent() ** 3 / max(self.n_cells, 1)
        bad = np.flatnonzero((det * orient <= thr).any(axis=1))
        return np.stack(np.unravel_index(bad, tuple(self.shape)), axis=1)

    # --------------------------------------------------------------- inverse
    def _buckets(self) -> dict[str, Any]:
        """Uniform bucket grid over the world bounds listing the cells whose padded node
        bounding box overlaps each bucket (CSR: ``start``, ``count``, ``cells``)."""
        if "buckets" in self._cache:
            return self._cache["buckets"]
        corners = self._cell_corners()
        lo_c, hi_c = corners.min(axis=1), corners.max(axis=1)
        pad = 2.0 * INSIDE_TOL * (hi_c - lo_c).max(axis=1, keepdims=True)
        pad = pad + 1e-12 * max(self._extent(), 1e-300)
        lo_c, hi_c = lo_c - pad, hi_c + pad
        lo, hi = lo_c.min(axis=0), hi_c.max(axis=0)
        nb = np.clip(np.asarray(self.shape), 1, 128)
        size = np.maximum((hi - lo) / nb, 1e-300)
        b0 = np.clip(np.floor((lo_c - lo) / size), 0, nb - 1).astype(np.intp)
        b1 = np.clip(np.floor((hi_c - lo) / size), 0, nb - 1).astype(np.intp)
        r = b1 - b0 + 1
        cnt = r.prod(axis=1)
        cell = np.repeat(np.arange(len(cnt)), cnt)
        m = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        rx, ry = r[cell, 0], r[cell, 1]
        bx = b0[cell, 0] + m % rx
        by = b0[cell, 1] + (m // rx) % ry
        bz = b0[cell, 2] + m // (rx * ry)
        bucket = (bx * nb[1] + by) * nb[2] + bz
        order = np.argsort(bucket, kind="stable")
        count = np.bincount(bucket, minlength=int(nb.prod()))
        b = {
            "lo": lo,
            "size": size,
            "nb": nb,
            "start": np.cumsum(count) - count,
            "count": count,
            "cells": cell[order],
            "lo_c": lo_c,
            "hi_c": hi_c,
        }
        self._cache["buckets"] = b
        return b

    def _candidates(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(point, cell) pairs whose padded cell bounding box contains the point."""
        b = self._buckets()
        s = np.floor((x - b["lo"]) / b["size"])
        ok = ((s >= 0) & (s < b["nb"])).all(axis=1)
        pts = np.flatnonzero(ok)
        si = s[pts].astype(np.intp)
        bucket = (si[:, 0] * b["nb"][1] + si[:, 1]) * b["nb"][2] + si[:, 2]
        cnt = b["count"][bucket]
        pi = np.repeat(pts, cnt)
        off = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        ci = b["cells"][np.repeat(b["start"][bucket], cnt) + off]
        xp = x[pi]
        inside = ((xp >= b["lo_c"][ci]) & (xp <= b["hi_c"][ci])).all(axis=1)
        return pi[inside], ci[inside]

    def _ijk(self, ci: np.ndarray) -> np.ndarray:
        """(N, 3) cell indices of flat cell ids (C order)."""
        _, ny, nz = self.shape
        return np.stack([ci // (ny * nz), (ci // nz) % ny, ci % nz], axis=1)

    def _cell_bounds(self, ci: np.ndarray, extrapolate: bool) -> tuple[np.ndarray, np.ndarray]:
        """Accepted local-coordinate range of each cell (open beyond the border when
        extrapolating)."""
        ijk = self._ijk(ci)
        lower = np.zeros((len(ci), 3))
        upper = np.ones((len(ci), 3))
        if extrapolate:
            n = np.asarray(self.shape)
            lower[ijk == 0] = -np.inf
            upper[ijk == n - 1] = np.inf
        return lower, upper

    def _solve_pairs(
        self,
        x: np.ndarray,
        pi: np.ndarray,
        ci: np.ndarray,
        tol: float,
        max_iter: int,
        extrapolate: bool,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Newton per (point, cell) pair; returns (pair u global, accepted, folded, outdist)."""
        corners = self._cell_corners()
        coef = self._coefficients()[ci]
        if "seeds" not in self._cache:
            ainv = np.zeros((self.n_cells, 3, 3))
            tr = np.zeros((self.n_cells, 3))
            ok = np.zeros(self.n_cells, dtype=bool)
            a_all = np.stack(
                [
                    corners[:, 1::2].mean(1) - corners[:, 0::2].mean(1),
                    corners[:, [2, 3, 6, 7]].mean(1) - corners[:, [0, 1, 4, 5]].mean(1),
                    corners[:, 4:].mean(1) - corners[:, :4].mean(1),
                ],
                axis=2,
            )
            det = np.linalg.det(a_all)
            sc = np.prod(np.linalg.norm(a_all, axis=1), axis=1)
            ok = np.abs(det) > SINGULAR_RTOL * sc
            ainv[ok] = np.linalg.inv(a_all[ok])
            tr[:] = corners.mean(axis=1) - np.einsum("cij,j->ci", a_all, np.full(3, 0.5))
            self._cache["seeds"] = (ainv, tr, ok)
        ainv, tr, ok = self._cache["seeds"]
        xp = x[pi]
        u0 = np.where(ok[ci][:, None], np.einsum("nij,nj->ni", ainv[ci], xp - tr[ci]), 0.5)
        lower, upper = self._cell_bounds(ci, extrapolate)
        orient, _ = self._orientation_and_flat()
        t, conv, fold = _newton(coef, xp, u0, tol, max_iter, orient, lower, upper)
        outd = np.maximum(lower - t, t - upper).max(axis=1).clip(min=0.0)
        accepted = conv & (outd <= INSIDE_TOL)
        ug = (self._ijk(ci) + t) / np.asarray(self.shape, dtype=np.float64)
        return ug, accepted, fold, outd

    def inverse(
        self,
        x: Any,
        tol: float = 1e-9,
        max_iter: int = 40,
        return_info: bool = False,
        outside: str = "nan",
    ) -> np.ndarray | tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World points -> unit-cube coordinates (cell search + Newton per candidate).

        Parameters
        ----------
        x : array_like, shape (N, 3) or (3,)
            World points.
        tol : float
            Newton convergence: last step at most ``tol`` in cell coordinates (or the
            residual at floating-point noise).
        max_iter : int
            Most Newton iterations per (point, candidate cell) pair.
        return_info : bool
            Also return ``(converged, folded)``.
        outside : {"nan", "extrapolate"}
            Points not inside the lattice: ``"nan"`` (default) returns NaN and
            ``converged = False``; ``"extrapolate"`` inverts the extrapolated map of the
            border cells (the inverse of :meth:`__call__` outside ``[0,1]^3``), so ``u``
            lies outside the unit cube.

        Returns
        -------
        u : numpy.ndarray
            Same shape as ``x``; NaN where no cell holds the point (see ``outside``).
            An accepted solution may lie up to ``1e-6`` cell units outside its cell.
        converged, folded : numpy.ndarray of bool, shape (N,)
            Only with ``return_info``. ``folded``: ``det J`` of the accepted cell has the
            wrong sign (against the lattice's signed volume) or vanishes at the solution
            or along the iteration, or the point has two distinct preimages.

        Raises
        ------
        WarpError
            When ``x`` is malformed, ``outside`` unknown, or the lattice is flat.

        Notes
        -----
        Candidate cells are those whose padded node bounding box holds the point, found
        through a uniform bucket grid over the lattice bounds (one bucket per cell, at
        most 128 per axis). Newton runs on all pairs at once; a point keeps the converged
        solution inside its cell, preferring unfolded ones. For
        ``outside="extrapolate"`` unresolved points also try the 3x3x3 cells around the
        cell the lattice's affine fit points to and around their nearest node. Far outside
        the lattice the extrapolated map need not be injective (nor regular): there
        ``u`` is one preimage, and a point may stay unresolved.
        """
        xs, lead = _points(x)
        if outside not in ("nan", "extrapolate"):
            raise WarpError(f"outside must be 'nan' or 'extrapolate'; got {outside!r}")
        if max_iter < 1 or not tol > 0:
            raise WarpError("inverse needs tol > 0 and max_iter >= 1")
        extrapolate = outside == "extrapolate"
        _, flat = self._orientation_and_flat()
        if flat or (self.is_linear and abs(np.linalg.det(self._fit()[0])) == 0):
            raise WarpError(
                "this lattice is flat (zero volume), it has no inverse; move its nodes so"
                " that the cells span a volume"
            )
        n = len(xs)
        if self.is_linear:
            a, t, _ = self._fit()
            u = np.linalg.solve(a, (xs - t).T).T
            conv = np.ones(n, dtype=bool)
            if not extrapolate:
                conv = ((u >= -INSIDE_TOL) & (u <= 1.0 + INSIDE_TOL)).all(axis=1)
                u[~conv] = np.nan
            fold = np.zeros(n, dtype=bool)
        else:
            u = np.full((n, 3), np.nan)
            conv = np.zeros(n, dtype=bool)
            fold = np.zeros(n, dtype=bool)
            for s in range(0, n, INVERSE_CHUNK):  # bounds the (point, cell) pair arrays
                xc = xs[s : s + INVERSE_CHUNK]
                uc, cc, fc = (
                    u[s : s + INVERSE_CHUNK],
                    conv[s : s + INVERSE_CHUNK],
                    fold[s : s + INVERSE_CHUNK],
                )
                pi, ci = self._candidates(xc)
                self._resolve(xc, pi, ci, tol, max_iter, extrapolate, uc, cc, fc)
                if extrapolate and not cc.all():
                    pi, ci = self._neighbourhood(xc, np.flatnonzero(~cc))
                    self._resolve(xc, pi, ci, tol, max_iter, extrapolate, uc, cc, fc)
        u = u.reshape(*lead, 3)
        if return_info:
            return u, conv.reshape(lead), fold.reshape(lead)
        return u

    def _resolve(
        self,
        xs: np.ndarray,
        pi: np.ndarray,
        ci: np.ndarray,
        tol: float,
        max_iter: int,
        extrapolate: bool,
        u: np.ndarray,
        conv: np.ndarray,
        fold: np.ndarray,
    ) -> None:
        """Run the candidate pairs and write the chosen solutions into u/conv/fold."""
        if pi.size == 0:
            return
        ug, acc, pfold, outd = self._solve_pairs(xs, pi, ci, float(tol), int(max_iter), extrapolate)
        pi, ug, pfold, outd = pi[acc], ug[acc], pfold[acc], outd[acc]
        if pi.size == 0:
            return
        order = np.lexsort((outd, pfold, pi))
        pi, ug, pfold = pi[order], ug[order], pfold[order]
        first = np.ones(len(pi), dtype=bool)
        first[1:] = pi[1:] != pi[:-1]
        best = pi[first]
        u[best] = ug[first]
        conv[best] = True
        fold[best] = pfold[first]
        # a second, distinct preimage: the map is not injective here
        rep = np.cumsum(first) - 1
        dist = np.abs(ug - ug[first][rep]).max(axis=1)
        multi = pi[dist > DISTINCT_TOL]
        fold[multi] = True

    def _neighbourhood(self, xs: np.ndarray, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(point, cell) pairs: the 3x3x3 cells around the affine-fit guess of each point and
        around its nearest node."""
        from scipy.spatial import cKDTree

        a, t, _ = self._fit()
        n = np.asarray(self.shape)
        guesses = []
        if abs(np.linalg.det(a)) > 0:
            guess = np.linalg.solve(a, (xs[rest] - t).T).T
            guesses.append(np.clip(np.floor(guess * n), 0, n - 1).astype(np.intp))
        if "kdtree" not in self._cache:
            self._cache["kdtree"] = cKDTree(self.nodes.reshape(-1, 3))
        _, node = self._cache["kdtree"].query(xs[rest])
        nn = np.stack(np.unravel_index(node, self.nodes.shape[:3]), axis=1)
        guesses.append(np.clip(nn, 0, n - 1))
        offs = np.stack(np.meshgrid(*([np.arange(-1, 2)] * 3), indexing="ij"), -1).reshape(-1, 3)
        keys = []
        for ijk in guesses:
            cand = np.clip(ijk[:, None, :] + offs[None], 0, n - 1)  # (M, 27, 3)
            ci = (cand[..., 0] * n[1] + cand[..., 1]) * n[2] + cand[..., 2]
            keys.append((rest[:, None].astype(np.int64) * self.n_cells + ci).ravel())
        key = np.unique(np.concatenate(keys))
        return (key // self.n_cells).astype(np.intp), (key % self.n_cells).astype(np.intp)

    # ----------------------------------------------------------- composition
    def resample(self, cells: Any) -> TrilinearGrid:
        """The same map sampled on another node grid.

        Parameters
        ----------
        cells : int or sequence of 3 ints
            Cells per axis of the result.

        Returns
        -------
        TrilinearGrid
            Nodes = this grid evaluated at the new nodes' unit coordinates (exact when
            the new cell counts are multiples of the old ones).
        """
        c = _cells3(cells)
        if c == self.shape:
            return self
        return TrilinearGrid(self(_unit_nodes(c)))

    def compose(self, inner: TrilinearGrid | np.ndarray, cells: Any = None) -> TrilinearGrid:
        """``self o inner``: ``inner`` maps the unit cube into this grid's unit cube.

        Parameters
        ----------
        inner : TrilinearGrid, TrilinearTransform or array_like (4, 4)
            The inner map; its "world" is this grid's unit-cube coordinates. A 4x4 is an
            affine matrix; it and a transform are sampled at ``self.shape`` unless
            ``cells`` is given.
        cells : int or sequence of 3 ints, optional
            Cells per axis of the result; default the per-axis maximum of the two grids.

        Returns
        -------
        TrilinearGrid
            Nodes ``self(inner'.nodes)`` where ``inner'`` is ``inner`` resampled at the
            result's resolution. Exact for two linear grids; otherwise the trilinear
            interpolant of the exact composition (error ~ ``h^2``).

        Raises
        ------
        WarpError
            When ``inner`` is neither a grid, a transform nor an affine 4x4 matrix.
        """
        if isinstance(inner, TrilinearGrid):
            c = (
                _cells3(cells)
                if cells is not None
                else tuple(max(a, b) for a, b in zip(self.shape, inner.shape, strict=True))
            )
            inner_g = inner.resample(c)
        elif isinstance(inner, TrilinearTransform):
            c = _cells3(cells) if cells is not None else self.shape
            inner_g = TrilinearGrid.from_transform(inner, c)
        else:
            c = _cells3(cells) if cells is not None else self.shape
            inner_g = TrilinearGrid.from_matrix(_matrix4(inner, "inner"), c)
        return TrilinearGrid(self(inner_g.nodes))

    # -------------------------------------------------------------------- io
    def texture_data(self) -> np.ndarray:
        """The nodes as an RGBA32F 3D texture.

        Returns
        -------
        numpy.ndarray
            float32 (nz+1, ny+1, nx+1, 4): xyz = node, w = 1; x varies fastest in memory
            (C order), as ``glTexImage3D`` expects. Sampling at node-centred coordinates
            ``(u * n + 0.5) / (n + 1)`` with linear filtering gives the lattice map.
        """
        n = self.nodes.transpose(2, 1, 0, 3)
        out = np.ones((*n.shape[:3], 4), dtype=np.float32)
        out[..., :3] = n
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON form.

        Returns
        -------
        dict
            ``{"nodes": (nx+1) x (ny+1) x (nz+1) x 3 nested lists}``.
        """
        return {"nodes": self.nodes.tolist()}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TrilinearGrid:
        """Rebuild from :meth:`to_dict`'s form.

        Parameters
        ----------
        d : Mapping
            Must hold ``"nodes"``.

        Returns
        -------
        TrilinearGrid

        Raises
        ------
        WarpError
            When ``"nodes"`` is missing or malformed.
        """
        if not isinstance(d, Mapping) or "nodes" not in d:
            raise WarpError("a trilinear grid entry needs 'nodes' ((nx+1) x (ny+1) x (nz+1) x 3)")
        return cls(d["nodes"])

    def __repr__(self) -> str:
        kind = "linear" if self.is_linear else "trilinear"
        return f"TrilinearGrid({kind}, cells={self.shape})"
