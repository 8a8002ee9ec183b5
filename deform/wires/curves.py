"""Parametric cubic curves for wire deformation: evaluation, arc length, closest points, frames.

About this technique
--------------------
**Parametrisation.** A :class:`Curve` is a chain of ``n_segments`` cubic segments with one
*global* parameter ``t`` in ``[0, 1]``: segment ``s = min(floor(t * n), n - 1)`` and local
parameter ``u = t * n - s`` in ``[0, 1]``. Each segment is stored in the power basis,
``alpha_s(u) = c0 + c1 u + c2 u^2 + c3 u^3``, with ``[c0, c1, c2, c3]^T = M G``: ``M`` is the
4x4 basis matrix of the curve kind and ``G`` the segment's four control points (rows). So
``d alpha / dt = n * d alpha_s / du`` and ``d^2 alpha / dt^2 = n^2 * d^2 alpha_s / du^2``.
Parameters outside ``[0, 1]`` extrapolate the end segments' polynomials.

**Bézier** (``kind="bezier"``): ``N = 3k + 1`` control points, segment ``s`` uses
``P[3s .. 3s+3]`` (consecutive segments share end points), ::

        M_bezier = [[ 1,  0,  0, 0],
                    [-3,  3,  0, 0],
                    [ 3, -6,  3, 0],
                    [-1,  3, -3, 1]]

It interpolates only ``P[3s]``; the inner points are handles. The curve is C0 at the
joins, C1 where ``P[3s-1], P[3s], P[3s+1]`` are collinear with equal spacing (G1 when only
collinear), and it lies in the convex hull of each segment's control points.

**Uniform Catmull-Rom** (``kind="catmull-rom"``, tension 1/2, the default): passes through
every control point, ``N - 1`` segments; segment ``s`` runs from ``P[s]`` to ``P[s+1]``
using ``G = (P[s-1], P[s], P[s+1], P[s+2])``, with phantom end points
``P[-1] = 2 P[0] - P[1]`` and ``P[N] = 2 P[N-1] - P[N-2]``, ::

        M_catmull_rom = 1/2 [[ 0,  2,  0,  0],
                             [-1,  0,  1,  0],
                             [ 2, -5,  4, -1],
                             [-1,  3, -3,  1]]

It is C1 everywhere (tangent at ``P[i]`` is ``(P[i+1] - P[i-1]) / 2`` per unit ``u``) and
reproduces straight lines with uniform speed when the points are equally spaced. Its
basis functions go negative, so it has *no* convex-hull property with respect to its own
control points; :meth:`Curve.bounds` converts each segment to its Bézier form (handles
``P[s] + (P[s+1] - P[s-1]) / 6`` and ``P[s+1] - (P[s+2] - P[s]) / 6``) whose hull does
bound it.

**Arc length** (eq. 4 of the wire deformation paper in the Journal of WSCG, 2006): the
length is the sum of chord lengths of an inscribed polyline,
``L_k = sum_i |alpha(t_{i+1}) - alpha(t_i)|`` with every segment (or the part of it inside
``[t0, t1]``) split into ``k`` equal parameter steps, and the subdivision is doubled
(``k = 8, 16, 32, ...``) until the relative change ``|L_2k - L_k| / L_2k`` is below the
precision ``p``. An inscribed polyline never exceeds the arc, refining never shortens it,
and its error falls like ``1/k^2``, so the returned ``L_2k`` underestimates the true length
by about ``p / 3`` (relative). No Richardson extrapolation is applied: the estimate is the
paper's, a lower bound.

**Closest point by subdivision**: every segment is sampled coarsely (64 parameters per
segment); a k-d tree gives each query point its nearest sample; then the parameter bracket
of +-1 coarse step around it is refined repeatedly, 9 samples across the bracket, keeping
the best sample and shrinking the bracket to +-1 sample step around it (4x per round),
until the bracket is narrower than ``precision`` (in ``t``). All query points are refined
together (numpy), in chunks to bound memory. Near the curve's medial axis (points about
equidistant from two distant parts of the curve) the coarse stage may pick the slightly
farther part; the distance is then over by at most half a coarse chord and typically by
far less (second order).

**Rotation-minimising frames** (:meth:`Curve.frames`): a wire's *twist* (rotation about its
own tangent) must be something the user does, not an artefact of the frame, so the frame
along the curve must have no twist of its own. Frenet frames do not qualify: their normal
follows the curvature vector, so it flips at inflection points, spins with the torsion, and
is undefined where the curve is straight. A rotation-minimising frame (RMF) has zero
angular velocity about the tangent. It is computed by the *double reflection method*
(W. Wang, B. Jüttler, D. Zheng, Y. Liu, "Computation of rotation minimizing frames",
ACM Transactions on Graphics 27(1), article 2, 2008): at ``samples`` parameters
equally spaced in arc length (:meth:`Curve.arc_length_table`), the frame at sample ``i`` is
reflected in the bisecting plane of the chord ``x_{i+1} - x_i`` and then in the plane that
maps the reflected tangent onto ``T_{i+1}``; the error is ``O(h^4)`` per step (``O(h^3)``
over the curve). The products of the per-step reflections are accumulated with a
log-depth prefix scan, so no Python loop runs over the samples. For an arbitrary ``t``
the normals of the two neighbouring samples are each carried to the exact tangent
``T(t)`` by the minimal rotation from their own tangent (:func:`minimal_rotation`), then
interpolated linearly in ``t`` and re-normalised; ``B = T x N`` (interpolating the raw
sample normals and re-orthonormalising against ``T(t)`` would be only second order
between samples). Accuracy needs the samples to resolve the turns: a turn of radius
below a few sample spacings (``length / samples``) is followed less accurately; pass
more ``samples`` for such curves.

Measurements (speed of evaluation, closest points and frames; frame accuracy):
docs/benchmarks.md, section 'voxwarp.deform.wires.curves: speed and frame accuracy'.

**Tangent.** ``T = alpha'(t) / |alpha'(t)|``. Where the derivative vanishes (coincident
Bézier handles, e.g. ``P[1] == P[0]``; a cusp) it falls back to a finite-difference chord
``alpha(t + h) - alpha(t - h)`` with ``h = 1e-4 / n_segments`` (clipped to ``[0, 1]``,
so one-sided at the ends, where it gives the limit direction), then ``h = 1 / n_segments``,
then the curve's end-to-end chord, then the x axis.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from functools import cached_property
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from voxwarp.deform.warp import WarpError

#: Curve kinds: Bézier (3k+1 points, handles) and uniform Catmull-Rom (interpolating).
KINDS: tuple[str, ...] = ("bezier", "catmull-rom")

#: Power-basis coefficients ``[c0, c1, c2, c3]`` of a cubic Bézier segment from its 4 points.
BEZIER_BASIS = np.array(
    [[1.0, 0.0, 0.0, 0.0], [-3.0, 3.0, 0.0, 0.0], [3.0, -6.0, 3.0, 0.0], [-1.0, 3.0, -3.0, 1.0]]
)
#: Power-basis coefficients of a uniform Catmull-Rom segment (tension 1/2) from its 4 points.
CATMULL_ROM_BASIS = 0.5 * np.array(
    [[0.0, 2.0, 0.0, 0.0], [-1.0, 0.0, 1.0, 0.0], [2.0, -5.0, 4.0, -1.0], [-1.0, 3.0, -3.0, 1.0]]
)
_POWER_TO_BEZIER = np.linalg.inv(BEZIER_BASIS)

#: Default precision of :meth:`Curve.arc_length` (relative change of the chord sum).
DEFAULT_LENGTH_PRECISION = 1e-4
#: Default precision (in ``t``) of :meth:`Curve.closest_point`.
DEFAULT_CLOSEST_PRECISION = 1e-3
#: Default number of rotation-minimising-frame samples of :meth:`Curve.frames`.
DEFAULT_FRAME_SAMPLES = 1024

_FIRST_SUBDIVISION = 8  # chords per segment of the first arc-length estimate
_MAX_POLYLINE_POINTS = 1 << 22  # stop doubling the arc-length subdivision beyond this
_COARSE_PER_SEGMENT = 64  # closest point: coarse samples per segment
_REFINE_STEPS = 8  # closest point: sample intervals across a bracket per round
_CHUNK = 1 << 16  # closest point: query points refined at once
_MAX_FRAME_SAMPLES = 1 << 20
_RMF_CACHE_SIZE = 8  # (initial_normal, samples) combinations whose RMF a curve keeps


# ------------------------------------------------------------------------------ helpers
def _as_params(t: Any) -> np.ndarray:
    """``t`` as a float64 array of finite numbers (any shape), or WarpError."""
    try:
        arr = np.asarray(t, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise WarpError(f"curve parameters t must be numbers in [0, 1]; got {t!r:.60}") from exc
    if not np.all(np.isfinite(arr)):
        raise WarpError("curve parameters t must be finite numbers in [0, 1]; got NaN or inf")
    return arr


def _as_vector(v: Any, name: str) -> np.ndarray:
    """A finite 3-vector (or (M, 3) stack of them) as float64, or WarpError."""
    try:
        arr = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise WarpError(f"{name} must be a 3-vector of numbers; got {v!r:.60}") from exc
    if arr.ndim not in (1, 2) or arr.shape[-1] != 3:
        raise WarpError(f"{name} must be a 3-vector (or an (M, 3) array); got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise WarpError(f"{name} must be finite; got NaN or inf")
    return arr


def _normalise_rows(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows of ``v`` (M, 3) divided by their lengths (zero rows stay zero), and the lengths."""
    n = np.sqrt(np.einsum("ij,ij->i", v, v))
    safe = np.where(n > 0.0, n, 1.0)
    return v / safe[:, None], n


def _perpendicular(a: np.ndarray) -> np.ndarray:
    """Unit vectors (M, 3) perpendicular to the unit rows of ``a``."""
    axis = np.zeros_like(a)
    axis[np.arange(len(a)), np.argmin(np.abs(a), axis=1)] = 1.0
    p = axis - np.einsum("ij,ij->i", axis, a)[:, None] * a
    return _normalise_rows(p)[0]


def _rotations(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(M, 3, 3) minimal rotations taking the unit rows of ``a`` to those of ``b``."""
    v = np.cross(a, b)
    s = np.sqrt(np.einsum("ij,ij->i", v, v))
    c = np.einsum("ij,ij->i", a, b)
    angle = np.arctan2(s, c)
    k = np.where((s > 1e-15)[:, None], v / np.where(s > 1e-15, s, 1.0)[:, None], 0.0)
    tiny = s <= 1e-15
    if tiny.any():  # parallel (angle 0: any axis) or antiparallel (angle pi: any perpendicular)
        k[tiny] = _perpendicular(a[tiny])
    kx = np.zeros((len(a), 3, 3))
    kx[:, 0, 1], kx[:, 0, 2] = -k[:, 2], k[:, 1]
    kx[:, 1, 0], kx[:, 1, 2] = k[:, 2], -k[:, 0]
    kx[:, 2, 0], kx[:, 2, 1] = -k[:, 1], k[:, 0]
    eye = np.broadcast_to(np.eye(3), kx.shape)
    return (
        eye + np.sin(angle)[:, None, None] * kx + (1.0 - np.cos(angle))[:, None, None] * (kx @ kx)
    )


def _rotate_minimal(a: np.ndarray, b: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rows of ``v`` turned by the minimal rotations taking unit rows ``a`` to unit rows ``b``."""
    w = np.cross(a, b)
    s = np.sqrt(np.einsum("ij,ij->i", w, w))
    c = np.einsum("ij,ij->i", a, b)
    ok = s > 1e-15
    k = w / np.where(ok, s, 1.0)[:, None]
    if not ok.all():
        k[~ok] = _perpendicular(a[~ok])
    sin, cos = s[:, None], c[:, None]  # sin, cos of the angle (|a| = |b| = 1)
    kv = np.einsum("ij,ij->i", k, v)[:, None]
    out = v * cos + np.cross(k, v) * sin + k * (kv * (1.0 - cos))
    return out


def minimal_rotation(a: Any, b: Any) -> np.ndarray:
    """The rotation of least angle taking direction ``a`` to direction ``b``.

    It turns about ``a x b`` by the angle between them (Rodrigues' formula with the angle
    from ``atan2(|a x b|, a . b)``, accurate also for nearly (anti)parallel vectors). Equal
    directions give the identity; opposite ones a half turn about an axis perpendicular
    to ``a``.

    Parameters
    ----------
    a, b : array_like
        Directions, shape (3,), or (M, 3) for M rotations at once. Normalised here, so they
        need not be unit vectors, but must be finite and non-zero.

    Returns
    -------
    numpy.ndarray
        (3, 3) rotation matrix ``R`` with ``R @ a_hat == b_hat`` (det 1, orthogonal), or
        (M, 3, 3) for stacked input.

    Raises
    ------
    WarpError
        If ``a`` or ``b`` is not a finite, non-zero 3-vector (or the shapes differ).
    """
    av, bv = _as_vector(a, "a"), _as_vector(b, "b")
    if av.shape != bv.shape:
        raise WarpError(f"a and b must have the same shape; got {av.shape} and {bv.shape}")
    single = av.ndim == 1
    a2, na = _normalise_rows(np.atleast_2d(av))
    b2, nb = _normalise_rows(np.atleast_2d(bv))
    if np.any(na == 0.0) or np.any(nb == 0.0):
        raise WarpError("minimal_rotation needs non-zero vectors a and b; got a zero vector")
    r = _rotations(a2, b2)
    return r[0] if single else r


def _validate_points(control_points: Any) -> np.ndarray:
    try:
        raw = np.asarray(control_points)
    except (TypeError, ValueError) as exc:
        raise WarpError(
            "control points must be an (N, 3) array of x, y, z numbers (mm); could not read "
            f"them as an array ({exc})"
        ) from exc
    if raw.dtype.kind not in "biuf":
        raise WarpError(
            "control points must be an (N, 3) array of x, y, z numbers (mm); got elements of "
            f"type {raw.dtype}"
        )
    pts = raw.astype(np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise WarpError(
            f"control points must be an (N, 3) array of x, y, z (mm); got shape {pts.shape}"
        )
    bad = ~np.all(np.isfinite(pts), axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise WarpError(
            f"control points must be finite; point {i} is {tuple(pts[i].tolist())}: replace "
            "NaN/inf coordinates"
        )
    return pts


# -------------------------------------------------------------------------------- Curve
class Curve:
    """A chain of cubic segments (Bézier or uniform Catmull-Rom), global parameter t in [0, 1].

    See the module docstring for the parametrisation, the basis matrices, the arc-length
    estimate, the closest-point search and the rotation-minimising frames. A curve is
    immutable (its control points are a read-only array), so lengths, sample tables and
    frames are cached.

    Parameters
    ----------
    control_points : array_like
        (N, 3) control points, world mm. Catmull-Rom needs ``N >= 2``; Bézier needs
        ``N = 3k + 1 >= 4``.
    kind : {"catmull-rom", "bezier"}
        The curve kind.

    Attributes
    ----------
    kind : str
        ``"bezier"`` or ``"catmull-rom"``.
    control_points : numpy.ndarray
        (N, 3) float64, read-only.
    n_segments : int
        Number of cubic segments: ``N - 1`` (Catmull-Rom) or ``(N - 1) / 3`` (Bézier).

    Raises
    ------
    WarpError
        Unknown kind; control points not an (N, 3) array of finite numbers; too few (or,
        for Bézier, not 3k+1) points; a curve of zero length.

    Notes
    -----
    Evaluation is vectorised over parameters and points; timings are in
    docs/benchmarks.md, section 'voxwarp.deform.wires.curves: speed and frame accuracy'.
    """

    def __init__(self, control_points: Any, kind: str = "catmull-rom") -> None:
        if not isinstance(kind, str) or kind not in KINDS:
            raise WarpError(
                f"unknown curve kind {kind!r}; use one of {', '.join(repr(k) for k in KINDS)}"
            )
        pts = _validate_points(control_points)
        n = len(pts)
        if kind == "catmull-rom":
            if n < 2:
                raise WarpError(f"a Catmull-Rom curve needs at least 2 control points; got {n}")
            padded = np.concatenate([[2.0 * pts[0] - pts[1]], pts, [2.0 * pts[-1] - pts[-2]]])
            geometry = np.stack([padded[s : s + 4] for s in range(n - 1)])
            basis = CATMULL_ROM_BASIS
        else:
            if n < 4 or (n - 1) % 3 != 0:
                raise WarpError(
                    "a Bézier curve needs 3k+1 control points (4, 7, 10, ...), consecutive "
                    f"segments sharing end points; got {n}: add or remove points"
                )
            geometry = np.stack([pts[3 * s : 3 * s + 4] for s in range((n - 1) // 3)])
            basis = BEZIER_BASIS
        self.kind: str = kind
        self.control_points: np.ndarray = pts
        self.control_points.setflags(write=False)
        self.n_segments: int = len(geometry)
        coeffs = np.einsum("ij,sjk->sik", basis, geometry)  # (n, 4, 3): c0..c3 per segment
        self._coeffs = coeffs
        self._c = [np.ascontiguousarray(coeffs[:, i, :]) for i in range(4)]
        polygon = float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())
        scale = float(np.abs(pts).max())
        coarse = self._chord_sum(*self._pieces(0.0, 1.0), _FIRST_SUBDIVISION)[2]
        if coarse <= 1e-9 * scale:  # also exactly 0 when all points coincide at the origin
            raise WarpError(
                f"the curve has zero length (its control points coincide at "
                f"{tuple(np.round(pts[0], 6).tolist())}); move at least one control point"
            )
        # |alpha'(t)| below this counts as a vanishing derivative (see _unit_tangent)
        self._deriv_eps = 1e-9 * polygon
        # coordinates and chords below ~1e-13 of this are rounding noise
        self._scale = scale + polygon
        self._rmf_cache: dict[tuple[Any, ...], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._tree: tuple[np.ndarray, cKDTree, np.ndarray] | None = None

    # ---------------------------------------------------------------- evaluation
    def segment_of(self, t: Any) -> tuple[np.ndarray, np.ndarray]:
        """Segment index and local parameter of global parameters ``t``.

        Parameters
        ----------
        t : array_like
            Global parameters (any shape; a scalar gives 0-d arrays).

        Returns
        -------
        segment : numpy.ndarray
            ``min(max(floor(t * n), 0), n - 1)`` as integers (``t = 1`` is in the last
            segment, ``t = s / n`` starts segment ``s``).
        u : numpy.ndarray
            ``t * n - segment`` (in ``[0, 1]`` for ``t`` in ``[0, 1]``).
        """
        x = _as_params(t) * self.n_segments
        s = np.clip(np.floor(x), 0, self.n_segments - 1)
        return np.asarray(s, dtype=np.intp), np.asarray(x - s)

    def _poly(self, t: Any, order: int) -> np.ndarray:
        """``order``-th derivative w.r.t. global t at parameters ``t``: shape ``t.shape + (3,)``."""
        tt = _as_params(t)
        shape = tt.shape
        s, u = self.segment_of(tt.ravel())
        u = u[:, None]
        c0, c1, c2, c3 = (np.take(c, s, axis=0) for c in self._c)
        n = float(self.n_segments)
        if order == 0:
            out = c3 * u
            out += c2
            out *= u
            out += c1
            out *= u
            out += c0
        elif order == 1:
            out = c3 * (3.0 * u)
            out += 2.0 * c2
            out *= u
            out += c1
            out *= n
        else:
            out = c3 * (6.0 * u)
            out += 2.0 * c2
            out *= n * n
        return out.reshape(*shape, 3)

    def evaluate(self, t: Any) -> np.ndarray:
        """Points ``alpha(t)`` of the curve.

        Parameters
        ----------
        t : array_like
            Global parameters in ``[0, 1]``: a scalar or an array of any shape.

        Returns
        -------
        numpy.ndarray
            ``t.shape + (3,)`` points (mm): (3,) for a scalar, (M, 3) for (M,).
        """
        return self._poly(t, 0)

    def derivative(self, t: Any) -> np.ndarray:
        """First derivative ``d alpha / dt`` with respect to the global parameter.

        At a segment join ``t = s / n`` the derivative of segment ``s`` (the right-hand
        one) is returned.

        Parameters
        ----------
        t : array_like
            Global parameters, scalar or any shape.

        Returns
        -------
        numpy.ndarray
            ``t.shape + (3,)`` (mm per unit t).
        """
        return self._poly(t, 1)

    def second_derivative(self, t: Any) -> np.ndarray:
        """Second derivative ``d^2 alpha / dt^2`` with respect to the global parameter.

        Parameters
        ----------
        t : array_like
            Global parameters, scalar or any shape.

        Returns
        -------
        numpy.ndarray
            ``t.shape + (3,)`` (mm per unit t squared).
        """
        return self._poly(t, 2)

    def _unit_tangent(self, t: np.ndarray) -> np.ndarray:
        """Unit tangents (M, 3) at flat parameters ``t`` (M,), with the documented fallbacks."""
        tan, norm = _normalise_rows(self.derivative(t))
        bad = norm <= self._deriv_eps
        if not bad.any():
            return tan
        idx = np.flatnonzero(bad)
        for h in (1e-4 / self.n_segments, 1.0 / self.n_segments):
            tb = t[idx]
            chord = self.evaluate(np.clip(tb + h, 0.0, 1.0)) - self.evaluate(
                np.clip(tb - h, 0.0, 1.0)
            )
            unit, length = _normalise_rows(chord)
            ok = length > 1e-13 * self._scale
            tan[idx[ok]] = unit[ok]
            idx = idx[~ok]
            if len(idx) == 0:
                return tan
        ends = self.control_points[-1] - self.control_points[0]
        fallback = ends / np.linalg.norm(ends) if np.any(ends) else np.array([1.0, 0.0, 0.0])
        tan[idx] = fallback
        return tan

    # ---------------------------------------------------------------- arc length
    def _pieces(self, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
        """Parameter intervals covering [t0, t1] that each lie inside one segment."""
        inner = np.arange(1, self.n_segments) / self.n_segments
        inner = inner[(inner > t0) & (inner < t1)]
        bp = np.concatenate([[t0], inner, [t1]])
        return bp[:-1], bp[1:]

    def _chord_sum(
        self, a: np.ndarray, b: np.ndarray, k: int
    ) -> tuple[np.ndarray, np.ndarray, float]:
        """Polyline of ``k`` equal steps per piece: params (P, k+1), chords (P, k), total."""
        frac = np.arange(k + 1) / k
        tt = a[:, None] + (b - a)[:, None] * frac
        pts = self.evaluate(tt.ravel()).reshape(len(a), k + 1, 3)
        d = np.diff(pts, axis=1)
        chords = np.sqrt(np.einsum("pki,pki->pk", d, d))
        return tt, chords, float(chords.sum())

    def _converged_polyline(
        self, precision: float, t0: float, t1: float
    ) -> tuple[np.ndarray, np.ndarray, float]:
        """Eq. 4: double the subdivision until the chord sum changes by < precision (rel.)."""
        if not (isinstance(precision, int | float) and math.isfinite(precision)):
            raise WarpError(f"precision must be a number in (0, 1); got {precision!r}")
        if not 0.0 < precision < 1.0:
            raise WarpError(f"precision must be in (0, 1) (e.g. 1e-4); got {precision}")
        a, b = self._pieces(t0, t1)
        k = _FIRST_SUBDIVISION
        tt, chords, length = self._chord_sum(a, b, k)
        while len(a) * (2 * k + 1) <= _MAX_POLYLINE_POINTS:
            k *= 2
            tt, chords, finer = self._chord_sum(a, b, k)
            done = abs(finer - length) <= precision * finer
            length = finer
            if done:
                break
        return tt, chords, length

    def arc_length(
        self, precision: float = DEFAULT_LENGTH_PRECISION, t0: float = 0.0, t1: float = 1.0
    ) -> float:
        """Length of the curve between parameters ``t0`` and ``t1`` (eq. 4, chord sums).

        The subdivision of every segment is doubled until the relative change of the chord
        sum is below ``precision``; the result underestimates the length by about
        ``precision / 3`` (relative). The subdivision stops growing at about 4e6 points in
        all, which bounds the precision reachable on long curves.

        Parameters
        ----------
        precision : float
            Relative change that ends the refinement, in (0, 1).
        t0, t1 : float
            Parameter interval, ``0 <= t0 <= t1 <= 1``.

        Returns
        -------
        float
            Length in mm.

        Raises
        ------
        WarpError
            Precision outside (0, 1), or a parameter interval outside [0, 1] or reversed.
        """
        lo, hi = (float(x) for x in _as_params([t0, t1]))
        if not 0.0 <= lo <= hi <= 1.0:
            raise WarpError(f"arc_length needs 0 <= t0 <= t1 <= 1; got t0={t0}, t1={t1}")
        return self._converged_polyline(precision, lo, hi)[2]

    @cached_property
    def length(self) -> float:
        """Arc length of the whole curve (mm), :meth:`arc_length` at its default precision."""
        return self.arc_length()

    def arc_length_table(
        self, n: int, precision: float = DEFAULT_LENGTH_PRECISION
    ) -> tuple[np.ndarray, np.ndarray]:
        """Parameters at equal arc-length fractions, and their cumulative lengths.

        The converged polyline of :meth:`arc_length` is inverted by linear interpolation of
        the parameter against its cumulative chord length.

        Parameters
        ----------
        n : int
            Number of entries, at least 2.
        precision : float
            Passed to the arc-length refinement.

        Returns
        -------
        t : numpy.ndarray
            (n,) parameters with ``s(t_i) = L * i / (n - 1)``; ``t_0 = 0``, ``t_{n-1} = 1``,
            non-decreasing.
        s : numpy.ndarray
            (n,) cumulative lengths ``L * i / (n - 1)`` (mm).

        Raises
        ------
        WarpError
            ``n`` not an integer >= 2, or a bad precision.
        """
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 2:
            raise WarpError(f"arc_length_table needs an integer n >= 2; got {n!r}")
        tt, chords, length = self._converged_polyline(precision, 0.0, 1.0)
        t_dense = np.concatenate([tt[:, :-1].ravel(), [1.0]])
        s_dense = np.concatenate([[0.0], np.cumsum(chords.ravel())])
        s = np.linspace(0.0, length, int(n))
        t = np.interp(s, s_dense, t_dense)
        t[0], t[-1] = 0.0, 1.0
        return t, s

    # ---------------------------------------------------------------- closest point
    def _coarse_tree(self) -> tuple[np.ndarray, cKDTree, np.ndarray]:
        if self._tree is None:
            t = np.linspace(0.0, 1.0, _COARSE_PER_SEGMENT * self.n_segments + 1)
            x = self.evaluate(t)
            self._tree = (t, cKDTree(x), x)
        return self._tree

    def closest_point(
        self, points: Any, precision: float = DEFAULT_CLOSEST_PRECISION
    ) -> tuple[np.ndarray, np.ndarray]:
        """Parameter and distance of the closest curve point, by subdivision.

        Coarse samples (64 per segment) and a k-d tree give a starting bracket of +-1 coarse
        step; each round samples 9 parameters across the bracket and shrinks it 4x around
        the best, until it is narrower than ``precision``. See the module docstring.

        Parameters
        ----------
        points : array_like
            (M, 3) query points (mm), or one point (3,).
        precision : float
            Final bracket width in ``t``, in (0, 1); the returned ``t`` is within about
            ``precision / 8`` of the local minimiser.

        Returns
        -------
        t : numpy.ndarray
            (M,) parameters in [0, 1] (0-d for one point).
        distance : numpy.ndarray
            (M,) Euclidean distances |alpha(t) - p| (mm).

        Raises
        ------
        WarpError
            Points not finite (M, 3) / (3,) numbers, or a precision outside (0, 1).

        Notes
        -----
        Timings: docs/benchmarks.md, section 'voxwarp.deform.wires.curves: speed and frame
        accuracy'.
        """
        if not (isinstance(precision, int | float) and 0.0 < precision < 1.0):
            raise WarpError(f"precision must be a number in (0, 1) (e.g. 1e-3); got {precision!r}")
        pts = _as_vector(points, "points")
        single = pts.ndim == 1
        pts = np.atleast_2d(pts)
        m = len(pts)
        t_out = np.empty(m)
        d_out = np.empty(m)
        if m:
            t_coarse, tree, _ = self._coarse_tree()
            half = 1.0 / (_COARSE_PER_SEGMENT * self.n_segments)
            steps = np.arange(_REFINE_STEPS + 1) / _REFINE_STEPS
            for start in range(0, m, _CHUNK):
                p = pts[start : start + _CHUNK]
                _, idx = tree.query(p)
                tc = t_coarse[idx]
                lo = np.maximum(tc - half, 0.0)
                hi = np.minimum(tc + half, 1.0)
                while True:
                    tt = lo[:, None] + (hi - lo)[:, None] * steps
                    diff = self.evaluate(tt) - p[:, None, :]
                    d2 = np.einsum("pki,pki->pk", diff, diff)
                    j = np.argmin(d2, axis=1)
                    rows = np.arange(len(p))
                    best_t = tt[rows, j]
                    best_d2 = d2[rows, j]
                    h = (hi - lo) / _REFINE_STEPS
                    if (hi - lo).max() <= precision:
                        break
                    lo = np.maximum(best_t - h, 0.0)
                    hi = np.minimum(best_t + h, 1.0)
                t_out[start : start + len(p)] = best_t
                d_out[start : start + len(p)] = np.sqrt(best_d2)
        if single:
            return t_out[0], d_out[0]
        return t_out, d_out

    # ---------------------------------------------------------------- frames
    def _rmf_samples(
        self, initial_normal: Any, samples: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """RMF at ``samples`` arc-length-equidistant params: (t (S,), T (S, 3), N (S, 3))."""
        if initial_normal is not None:
            n0 = _as_vector(initial_normal, "initial_normal")
            if n0.ndim != 1:
                raise WarpError(f"initial_normal must be one 3-vector; got shape {n0.shape}")
            key: tuple[Any, ...] = (samples, *n0.tolist())
        else:
            n0 = None
            key = (samples,)
        cached = self._rmf_cache.get(key)
        if cached is not None:
            return cached
        ts, _ = self.arc_length_table(samples)
        x = self.evaluate(ts)
        tan = self._unit_tangent(ts)
        t0 = tan[0]
        if n0 is None:
            axis = np.zeros(3)
            axis[np.argmin(np.abs(t0))] = 1.0
            r0 = axis - np.dot(axis, t0) * t0
        else:
            r0 = n0 - np.dot(n0, t0) * t0
            if np.linalg.norm(r0) <= 1e-6 * np.linalg.norm(n0):
                raise WarpError(
                    f"initial_normal {tuple(n0.tolist())} is parallel to the curve's tangent "
                    f"at t=0, {tuple(np.round(t0, 6).tolist())}; pass a vector not parallel to it"
                )
        r0 = r0 / np.linalg.norm(r0)
        # double reflection (Wang et al. 2008): R_i = H2_i H1_i takes frame i to frame i+1
        eye = np.eye(3)
        v1 = x[1:] - x[:-1]
        c1 = np.einsum("ij,ij->i", v1, v1)
        ok1 = c1 > (1e-13 * self._scale) ** 2
        c1s = np.where(ok1, c1, 1.0)
        h1 = eye - np.where(ok1, 2.0 / c1s, 0.0)[:, None, None] * (v1[:, :, None] * v1[:, None, :])
        t_left = (
            tan[:-1]
            - (np.where(ok1, 2.0 / c1s, 0.0) * np.einsum("ij,ij->i", v1, tan[:-1]))[:, None] * v1
        )
        v2 = tan[1:] - t_left
        c2 = np.einsum("ij,ij->i", v2, v2)
        ok2 = c2 > 1e-16
        h2 = eye - np.where(ok2, 2.0 / np.where(ok2, c2, 1.0), 0.0)[:, None, None] * (
            v2[:, :, None] * v2[:, None, :]
        )
        prod = h2 @ h1  # (S-1, 3, 3)
        offset = 1
        while offset < len(prod):  # inclusive prefix scan: prod[i] = R_i ... R_0
            prod[offset:] = prod[offset:] @ prod[:-offset]
            offset *= 2
        normals = np.empty_like(x)
        normals[0] = r0
        normals[1:] = prod @ r0
        normals -= np.einsum("ij,ij->i", normals, tan)[:, None] * tan
        normals = _normalise_rows(normals)[0]
        result = (ts, tan, normals)
        if len(self._rmf_cache) >= _RMF_CACHE_SIZE:  # drop the oldest entry
            del self._rmf_cache[next(iter(self._rmf_cache))]
        self._rmf_cache[key] = result
        return result

    def frames(
        self, t: Any, initial_normal: Any = None, samples: int = DEFAULT_FRAME_SAMPLES
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rotation-minimising frames ``(T, N, B)`` at parameters ``t``.

        The frame is computed by double reflection at ``samples`` parameters equally spaced
        in arc length, from ``N(0)`` = ``initial_normal`` made orthogonal to ``T(0)``
        (default: the world axis least aligned with ``T(0)``, made orthogonal), and cached
        per ``(initial_normal, samples)``. At ``t``, the normals of the two neighbouring
        samples are carried to the exact tangent ``T(t)`` by minimal rotations, interpolated
        linearly in ``t`` and re-normalised (where the two cancel, across a cusp, the left
        sample's carried normal is used); ``B = T x N``.

        Parameters
        ----------
        t : array_like
            Parameters in [0, 1], scalar or (M,) (any shape is accepted).
        initial_normal : array_like, optional
            Direction of ``N`` at ``t = 0`` (projected orthogonal to ``T(0)``); must not be
            parallel to ``T(0)``.
        samples : int
            Number of RMF samples along the curve, at least 2.

        Returns
        -------
        T, N, B : numpy.ndarray
            Each ``t.shape + (3,)``: unit tangent, normal and binormal, orthonormal and
            right-handed (``det [T N B] = 1``).

        Raises
        ------
        WarpError
            Bad ``t``, ``samples`` or ``initial_normal`` (not finite, or parallel to T(0)).
        """
        if (
            isinstance(samples, bool)
            or not isinstance(samples, int | np.integer)
            or not 2 <= samples <= _MAX_FRAME_SAMPLES
        ):
            raise WarpError(
                f"frames needs an integer number of samples in [2, {_MAX_FRAME_SAMPLES}]; "
                f"got {samples!r}"
            )
        tt = _as_params(t)
        shape = tt.shape
        flat = tt.ravel()
        ts, tan_s, nrm_s = self._rmf_samples(initial_normal, int(samples))
        j = np.clip(np.searchsorted(ts, flat, side="right") - 1, 0, len(ts) - 2)
        span = ts[j + 1] - ts[j]
        w = np.clip((flat - ts[j]) / np.where(span > 0.0, span, 1.0), 0.0, 1.0)
        w = np.where(span > 0.0, w, 0.0)[:, None]
        tan = self._unit_tangent(flat)
        # carry both neighbouring sample normals to T(t) by the minimal rotation, then blend
        normal = (1.0 - w) * _rotate_minimal(tan_s[j], tan, nrm_s[j])
        normal += w * _rotate_minimal(tan_s[j + 1], tan, nrm_s[j + 1])
        normal -= np.einsum("ij,ij->i", normal, tan)[:, None] * tan
        normal, length = _normalise_rows(normal)
        bad = length <= 1e-6  # the two carried normals nearly opposite (a cusp between)
        if bad.any():
            carried = _rotate_minimal(tan_s[j[bad]], tan[bad], nrm_s[j[bad]])
            normal[bad] = _normalise_rows(carried)[0]
        binormal = np.cross(tan, normal)
        return (
            tan.reshape(*shape, 3),
            normal.reshape(*shape, 3),
            binormal.reshape(*shape, 3),
        )

    # ---------------------------------------------------------------- misc
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned box ``(lo, hi)`` that contains the whole curve (t in [0, 1]).

        Bézier: the box of the control points (convex-hull property). Catmull-Rom: the box
        of the equivalent Bézier control points of every segment, whose hulls contain the
        segments; it contains all the Catmull-Rom control points too. Conservative, not
        tight.

        Returns
        -------
        lo, hi : numpy.ndarray
            (3,) corners (mm).
        """
        if self.kind == "bezier":
            pts = self.control_points
        else:
            pts = np.einsum("ij,sjk->sik", _POWER_TO_BEZIER, self._coeffs).reshape(-1, 3)
        return pts.min(axis=0).copy(), pts.max(axis=0).copy()

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly form: ``{"kind": ..., "control_points": [[x, y, z], ...]}``."""
        return {"kind": self.kind, "control_points": self.control_points.tolist()}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Curve:
        """Build a curve from :meth:`to_dict`'s form.

        Parameters
        ----------
        d : Mapping
            ``{"kind": "bezier" | "catmull-rom", "control_points": [[x, y, z], ...]}``.

        Returns
        -------
        Curve

        Raises
        ------
        WarpError
            Not a mapping, missing or unknown keys, wrong types, or any error of
            :class:`Curve` itself.
        """
        expected = '{"kind": "bezier" | "catmull-rom", "control_points": [[x, y, z], ...]}'
        if not isinstance(d, Mapping):
            raise WarpError(f"a curve entry must be a dict {expected}; got {type(d).__name__}")
        missing = [k for k in ("kind", "control_points") if k not in d]
        if missing:
            raise WarpError(f"a curve entry is missing {missing}; expected {expected}")
        unknown = sorted(str(k) for k in d if k not in ("kind", "control_points"))
        if unknown:
            raise WarpError(f"a curve entry has unknown keys {unknown}; expected {expected}")
        if not isinstance(d["kind"], str):
            raise WarpError(
                f"a curve entry's 'kind' must be a string, 'bezier' or 'catmull-rom'; got "
                f"{type(d['kind']).__name__}"
            )
        if isinstance(d["control_points"], str | bytes | Mapping):
            raise WarpError(
                "a curve entry's 'control_points' must be a list of [x, y, z] lists; got "
                f"{type(d['control_points']).__name__}"
            )
        return cls(d["control_points"], kind=d["kind"])

    def __repr__(self) -> str:
        return (
            f"Curve(kind={self.kind!r}, {len(self.control_points)} control points, "
            f"{self.n_segments} segments)"
        )
