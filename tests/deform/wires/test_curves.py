"""Tests of voxwarp.deform.wires.curves: cubic curves, arc length, closest points,
rotation-minimising
frames.

Oracles: straight lines (length = distance), the Bézier quarter circle (length against
adaptive quadrature of |alpha'| and against pi r / 2), the definitions of the bases
(interpolation, end tangents), finite differences, brute-force dense sampling for the
closest point, planar curves (whose RMF normal is constant or in-plane), a fine-step
parallel transport as an independent RMF, and the Frenet frame's twist on a helix.
"""

from __future__ import annotations

import itertools
import json
from typing import Any

import numpy as np
import pytest
from scipy.integrate import quad

from voxwarp.deform.warp import WarpError
from voxwarp.deform.wires.curves import KINDS, Curve, minimal_rotation

R = 10.0
KAPPA = 4.0 / 3.0 * (np.sqrt(2.0) - 1.0)  # handle length of the standard quarter circle


def quarter_circle(r: float = R) -> Curve:
    """Bézier approximation of the quarter circle of radius r in the z = 0 plane (CCW)."""
    k = KAPPA * r
    return Curve([[r, 0, 0], [r, k, 0], [k, r, 0], [0, r, 0]], kind="bezier")


def true_length(curve: Curve, t0: float = 0.0, t1: float = 1.0) -> float:
    """Arc length by adaptive quadrature of |alpha'(t)|, segment by segment."""
    n = curve.n_segments
    edges = sorted({t0, t1, *[s / n for s in range(1, n) if t0 < s / n < t1]})
    total = 0.0
    for a, b in itertools.pairwise(edges):
        mid = 0.5 * (a + b)  # evaluate each piece with its own segment's polynomial
        seg = min(int(mid * n), n - 1)
        c = curve._coeffs[seg]

        def speed(t: float, c: np.ndarray = c, seg: int = seg) -> float:
            u = t * n - seg
            return float(np.linalg.norm(n * (c[1] + 2 * c[2] * u + 3 * c[3] * u * u)))

        total += quad(speed, a, b, epsabs=1e-13, epsrel=1e-12, limit=200)[0]
    return total


def random_curve(kind: str, n_points: int, seed: int = 0) -> Curve:
    rng = np.random.default_rng(seed)
    return Curve(rng.normal(scale=30.0, size=(n_points, 3)), kind=kind)


def helix_points(n: int = 49, radius: float = 10.0, pitch: float = 5.0, turns: float = 2.0):
    a = np.linspace(0.0, 2.0 * np.pi * turns, n)
    return np.stack([radius * np.cos(a), radius * np.sin(a), pitch * a / (2 * np.pi)], axis=1)


def smooth_3d_curve(kind: str = "catmull-rom") -> Curve:
    """A gently bent, non-planar curve (radius of curvature >= ~10 mm over ~200 mm).

    Random control points can make near-cusps (turns of radius < 1 mm) that 1024 frame
    samples do not resolve; the frame accuracy tests use this curve instead.
    """
    a = np.linspace(0.0, 1.5 * np.pi, 10)
    pts = np.stack([40 * np.cos(a), 40 * np.sin(a), 15 * np.sin(2 * a)], axis=1)
    if kind == "bezier":  # C1 Bézier through every third point: handles from the tangents
        cr = Curve(pts)
        knots = np.arange(len(pts)) / (len(pts) - 1)
        tangents = cr.derivative(knots) / cr.n_segments / 3.0
        bez = [pts[0]]
        for i in range(len(pts) - 1):
            bez += [pts[i] + tangents[i], pts[i + 1] - tangents[i + 1], pts[i + 1]]
        return Curve(np.array(bez), kind="bezier")
    return Curve(pts)


def smooth_arc() -> Curve:
    """A non-self-intersecting 3D Catmull-Rom curve (part of a loose helix)."""
    return Curve(helix_points(n=9, radius=20.0, pitch=30.0, turns=0.75))


# ----------------------------------------------------------------- construction/validation
@pytest.mark.parametrize(
    ("points", "kind", "match"),
    [
        ([[0.0, 0.0, 0.0]], "catmull-rom", r"at least 2 control points; got 1"),
        (np.zeros((0, 3)), "catmull-rom", r"at least 2 control points; got 0"),
        (np.arange(15.0).reshape(5, 3), "bezier", r"3k\+1 control points \(4, 7, 10, \.\.\.\)"),
        (np.arange(9.0).reshape(3, 3), "bezier", r"got 3: add or remove points"),
        ([[0, 0, 0], [1, np.nan, 0], [2, 0, 0]], "catmull-rom", r"finite; point 1 .*NaN/inf"),
        ([[0, 0, 0], [1, np.inf, 0]], "catmull-rom", r"finite; point 1"),
        ([[1, 2, 3]] * 4, "bezier", r"zero length .*move at least one control point"),
        ([[1, 2, 3]] * 3, "catmull-rom", r"zero length"),
        (np.zeros((4, 3)), "catmull-rom", r"zero length"),
        ([[0, 0], [1, 1]], "catmull-rom", r"\(N, 3\) array .*got shape \(2, 2\)"),
        ([0.0, 1.0, 2.0], "catmull-rom", r"\(N, 3\) array .*got shape \(3,\)"),
        (np.zeros((2, 3, 1)), "catmull-rom", r"\(N, 3\) array"),
        ([["a", "b", "c"], ["d", "e", "f"]], "catmull-rom", r"numbers"),
        ([[0, 0, 0], [1, 1]], "catmull-rom", r"\(N, 3\) array"),  # ragged
        ([[0, 0, 0], [1, 0, 0]], "bspline", r"unknown curve kind 'bspline'; use one of 'bezier'"),
        ([[0, 0, 0], [1, 0, 0]], "Bezier", r"'catmull-rom'"),
        ([[0, 0, 0], [1, 0, 0]], None, r"unknown curve kind None"),
    ],
)
def test_invalid_curves_raise_warp_error_naming_the_fix(points: Any, kind: Any, match: str):
    with pytest.raises(WarpError, match=match):
        Curve(points, kind=kind)


def test_warp_error_is_a_value_error():
    with pytest.raises(ValueError, match="3k"):
        Curve(np.zeros((5, 3)), kind="bezier")


@pytest.mark.parametrize(
    ("kind", "n_points", "n_segments"),
    [("catmull-rom", 2, 1), ("catmull-rom", 7, 6), ("bezier", 4, 1), ("bezier", 10, 3)],
)
def test_segment_count(kind: str, n_points: int, n_segments: int):
    c = random_curve(kind, n_points)
    assert c.n_segments == n_segments
    assert c.kind == kind
    assert c.control_points.shape == (n_points, 3)
    assert c.control_points.dtype == np.float64


def test_default_kind_is_catmull_rom_and_integers_are_accepted():
    c = Curve([[0, 0, 0], [1, 0, 0], [2, 1, 0]])
    assert c.kind == "catmull-rom"
    assert c.control_points.dtype == np.float64
    assert KINDS == ("bezier", "catmull-rom")


def test_control_points_are_a_read_only_copy():
    pts = np.array([[0.0, 0, 0], [1, 0, 0], [2, 1, 0]])
    c = Curve(pts)
    pts[0] = 99.0
    assert c.control_points[0].tolist() == [0.0, 0.0, 0.0]
    with pytest.raises(ValueError, match="read-only"):
        c.control_points[0, 0] = 5.0


# ----------------------------------------------------------------------- evaluation
def test_segment_of_maps_global_to_local_parameters():
    c = random_curve("catmull-rom", 5)  # 4 segments
    s, u = c.segment_of(np.array([0.0, 0.1, 0.25, 0.5, 0.99, 1.0]))
    assert s.tolist() == [0, 0, 1, 2, 3, 3]
    np.testing.assert_allclose(u, [0.0, 0.4, 0.0, 0.0, 0.96, 1.0], atol=1e-12)
    s0, u0 = c.segment_of(0.3)
    assert int(s0) == 1
    assert float(u0) == pytest.approx(0.2)


def test_evaluate_shapes():
    c = random_curve("bezier", 7)
    assert c.evaluate(0.3).shape == (3,)
    assert c.evaluate(np.linspace(0, 1, 11)).shape == (11, 3)
    assert c.evaluate(np.zeros((2, 5))).shape == (2, 5, 3)
    assert c.derivative([0.1, 0.2]).shape == (2, 3)
    assert c.second_derivative(1.0).shape == (3,)
    assert c.evaluate(np.array([])).shape == (0, 3)


@pytest.mark.parametrize("bad", [np.nan, [0.5, np.inf], "half"])
def test_bad_parameters_raise(bad: Any):
    c = random_curve("catmull-rom", 4)
    with pytest.raises(WarpError, match="parameters t must be"):
        c.evaluate(bad)


@pytest.mark.parametrize("n_points", [2, 3, 6])
def test_catmull_rom_interpolates_its_control_points(n_points: int):
    c = random_curve("catmull-rom", n_points, seed=n_points)
    t = np.arange(n_points) / (n_points - 1)
    np.testing.assert_allclose(c.evaluate(t), c.control_points, atol=1e-12)


def test_catmull_rom_tangents_are_central_differences():
    # uniform Catmull-Rom: d alpha / du at P_i = (P_{i+1} - P_{i-1}) / 2, with phantom ends
    c = random_curve("catmull-rom", 6, seed=3)
    p, n = c.control_points, c.n_segments
    padded = np.concatenate([[2 * p[0] - p[1]], p, [2 * p[-1] - p[-2]]])
    expected = n * 0.5 * (padded[2:] - padded[:-2])
    np.testing.assert_allclose(c.derivative(np.arange(6) / 5), expected, rtol=1e-12, atol=1e-9)


def test_catmull_rom_is_c1_at_every_join():
    c = random_curve("catmull-rom", 6, seed=4)
    for s in range(1, c.n_segments):
        left = c._coeffs[s - 1]
        right = c._coeffs[s]
        # segment s-1 at u = 1 against segment s at u = 0
        np.testing.assert_allclose(left.sum(axis=0), right[0], atol=1e-10)
        np.testing.assert_allclose(left[1] + 2 * left[2] + 3 * left[3], right[1], atol=1e-10)


def test_bezier_interpolates_end_points_with_handle_tangents():
    c = random_curve("bezier", 7, seed=5)
    p, n = c.control_points, c.n_segments
    np.testing.assert_allclose(c.evaluate([0.0, 0.5, 1.0]), p[[0, 3, 6]], atol=1e-12)
    np.testing.assert_allclose(c.derivative(0.0), n * 3 * (p[1] - p[0]), rtol=1e-12)
    np.testing.assert_allclose(c.derivative(1.0), n * 3 * (p[6] - p[5]), rtol=1e-12)
    np.testing.assert_allclose(c.derivative(0.5), n * 3 * (p[4] - p[3]), rtol=1e-12)
    # the curve does not pass through the handles (it is not interpolating)
    d = np.linalg.norm(c.evaluate(np.linspace(0, 1, 2001))[:, None] - p[[1, 2]], axis=2)
    assert d.min() > 1e-3


def test_bezier_c1_across_joins_only_with_collinear_handles():
    rng = np.random.default_rng(6)
    p = rng.normal(scale=20.0, size=(7, 3))
    p[4] = 2 * p[3] - p[2]  # P2, P3, P4 collinear and equally spaced: C1 at the join
    smooth = Curve(p, kind="bezier")
    eps = 1e-9
    left, right = smooth.derivative([0.5 - eps, 0.5])
    np.testing.assert_allclose(left, right, rtol=1e-6)
    p[4] += [5.0, -3.0, 2.0]  # break collinearity: the derivative jumps
    kinked = Curve(p, kind="bezier")
    left, right = kinked.derivative([0.5 - eps, 0.5])
    assert np.linalg.norm(left - right) > 1.0
    # still C0
    a, b = kinked.evaluate([0.5 - eps, 0.5])
    assert np.linalg.norm(a - b) < 1e-6


@pytest.mark.parametrize("kind", ["catmull-rom", "bezier"])
def test_derivatives_match_finite_differences(kind: str):
    c = random_curve(kind, 7, seed=7)
    rng = np.random.default_rng(8)
    n = c.n_segments
    # stay away from the joins, where the one-sided polynomials differ (Bézier)
    s = rng.integers(0, n, 50)
    t = (s + rng.uniform(0.05, 0.95, 50)) / n
    h = 1e-6
    fd1 = (c.evaluate(t + h) - c.evaluate(t - h)) / (2 * h)
    fd2 = (c.derivative(t + h) - c.derivative(t - h)) / (2 * h)
    scale1 = np.abs(c.derivative(t)).max()
    scale2 = np.abs(c.second_derivative(t)).max()
    np.testing.assert_allclose(c.derivative(t), fd1, atol=1e-6 * scale1)
    np.testing.assert_allclose(c.second_derivative(t), fd2, atol=1e-6 * scale2)


def test_parameters_outside_unit_interval_extrapolate_end_segments():
    c = Curve([[0, 0, 0], [1, 0, 0], [2, 0, 0]])  # straight, uniform speed 2 per unit t
    np.testing.assert_allclose(c.evaluate([-0.5, 1.5]), [[-1, 0, 0], [3, 0, 0]], atol=1e-12)


# ----------------------------------------------------------------------- arc length
def test_straight_catmull_rom_length_is_the_distance():
    a, b = np.array([1.0, -2.0, 3.0]), np.array([31.0, 18.0, -7.0])
    pts = a + np.linspace(0, 1, 6)[:, None] * (b - a)
    c = Curve(pts)
    assert c.arc_length() == pytest.approx(np.linalg.norm(b - a), rel=1e-12)
    # uniform speed: a sub-interval's length is proportional to it
    assert c.arc_length(t0=0.2, t1=0.7) == pytest.approx(0.5 * np.linalg.norm(b - a), rel=1e-12)


def test_straight_bezier_length_is_the_distance():
    a, b = np.array([0.0, 0.0, 0.0]), np.array([3.0, 4.0, 12.0])
    # collinear handles, unevenly placed (non-uniform speed) but monotone
    c = Curve([a, a + 0.1 * (b - a), a + 0.8 * (b - a), b], kind="bezier")
    assert c.length == pytest.approx(13.0, rel=1e-12)


def test_quarter_circle_length():
    c = quarter_circle()
    exact = true_length(c)
    length = c.arc_length(1e-4)
    # the Bézier quarter circle is ~1.4e-4 longer than the circle (its radius overshoots by
    # up to 2.7e-4): within 1e-3 of pi r / 2
    assert length == pytest.approx(np.pi / 2 * R, rel=1e-3)
    assert exact / (np.pi / 2 * R) - 1 == pytest.approx(1.4e-4, abs=0.2e-4)
    # an inscribed polyline underestimates, by about precision / 3
    assert exact - 1e-4 * exact <= length <= exact


def test_arc_length_converges_as_precision_tightens():
    c = random_curve("catmull-rom", 6, seed=9)
    exact = true_length(c)
    precisions = [1e-2, 1e-3, 1e-4, 1e-5, 1e-7]
    lengths = [c.arc_length(p) for p in precisions]
    errors = [(exact - length) / exact for length in lengths]
    assert all(e >= -1e-12 for e in errors)  # lower bounds
    assert all(e <= p for e, p in zip(errors, precisions, strict=True))
    assert all(b <= a for a, b in itertools.pairwise(errors))
    assert errors[-1] < 1e-7
    assert errors[0] > 10 * errors[-1]  # a real change, not a fixed answer


def test_arc_length_of_sub_intervals_adds_up_and_matches_quadrature():
    c = random_curve("bezier", 10, seed=10)
    parts = [c.arc_length(1e-7, a, b) for a, b in [(0.0, 0.13), (0.13, 0.5), (0.5, 1.0)]]
    assert sum(parts) == pytest.approx(c.arc_length(1e-7), rel=1e-6)
    assert c.arc_length(1e-7, 0.13, 0.5) == pytest.approx(true_length(c, 0.13, 0.5), rel=1e-6)
    assert c.arc_length(t0=0.4, t1=0.4) == 0.0


def test_length_property_is_cached_arc_length():
    c = random_curve("catmull-rom", 4)
    assert c.length == c.arc_length()
    assert "length" in c.__dict__


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"precision": 0.0}, r"precision must be in \(0, 1\)"),
        ({"precision": -1e-3}, r"precision must be in \(0, 1\)"),
        ({"precision": 1.5}, r"precision must be in \(0, 1\)"),
        ({"precision": float("nan")}, r"precision must be a number"),
        ({"precision": "fine"}, r"precision must be a number"),
        ({"t0": 0.6, "t1": 0.2}, r"0 <= t0 <= t1 <= 1"),
        ({"t0": -0.1}, r"0 <= t0 <= t1 <= 1"),
        ({"t1": 1.1}, r"0 <= t0 <= t1 <= 1"),
    ],
)
def test_arc_length_rejects_bad_arguments(kwargs: dict[str, Any], match: str):
    with pytest.raises(WarpError, match=match):
        random_curve("catmull-rom", 3).arc_length(**kwargs)


def test_arc_length_table_is_equally_spaced_in_length():
    c = random_curve("catmull-rom", 6, seed=11)
    t, s = c.arc_length_table(33, precision=1e-6)
    assert t.shape == s.shape == (33,)
    assert t[0] == 0.0
    assert t[-1] == 1.0
    assert np.all(np.diff(t) > 0)
    np.testing.assert_allclose(np.diff(s), s[-1] / 32, rtol=1e-12)
    assert s[-1] == pytest.approx(true_length(c), rel=1e-6)
    # independent check: the length from 0 to each t_i is s_i
    measured = np.array([true_length(c, 0.0, ti) for ti in t[1:-1]])
    np.testing.assert_allclose(measured, s[1:-1], atol=1e-5 * s[-1])


@pytest.mark.parametrize("n", [1, 0, 2.5, True])
def test_arc_length_table_rejects_bad_n(n: Any):
    with pytest.raises(WarpError, match="integer n >= 2"):
        random_curve("catmull-rom", 3).arc_length_table(n)


# ----------------------------------------------------------------------- closest point
@pytest.mark.parametrize("kind", ["catmull-rom", "bezier"])
@pytest.mark.slow
def test_closest_point_matches_brute_force(kind: str):
    c = random_curve(kind, 10, seed=12)
    rng = np.random.default_rng(13)
    lo, hi = c.bounds()
    pts = rng.uniform(lo - 10, hi + 10, size=(500, 3))
    t, d = c.closest_point(pts)
    dense = c.evaluate(np.linspace(0, 1, 200_001))
    brute = np.array([np.linalg.norm(dense - p, axis=1).min() for p in pts])
    assert t.shape == d.shape == (500,)
    assert np.all((t >= 0) & (t <= 1))
    np.testing.assert_allclose(d, np.linalg.norm(c.evaluate(t) - pts, axis=1), rtol=1e-12)
    np.testing.assert_allclose(d, brute, atol=1e-3 * c.length)
    # typically far better than the tolerance; dense sampling itself errs upwards
    assert np.median(np.abs(d - brute)) < 1e-5 * c.length


@pytest.mark.parametrize("precision", [1e-3, 1e-6])
def test_closest_point_of_points_on_the_curve_returns_their_parameter(precision: float):
    c = smooth_arc()
    t_true = np.random.default_rng(14).uniform(0, 1, 1000)
    t, d = c.closest_point(c.evaluate(t_true), precision=precision)
    np.testing.assert_allclose(t, t_true, atol=precision)
    max_speed = np.linalg.norm(c.derivative(np.linspace(0, 1, 1001)), axis=1).max()
    assert np.all(d <= max_speed * precision)
    t_end, d_end = c.closest_point(c.control_points[[0, -1]], precision=precision)
    np.testing.assert_allclose(t_end, [0.0, 1.0], atol=1e-15)
    np.testing.assert_allclose(d_end, 0.0, atol=1e-9)


def test_closest_point_of_offset_points_on_a_circle_is_radial():
    c = quarter_circle()
    angles = np.linspace(0.05, np.pi / 2 - 0.05, 40)
    for rr in (3.0, 25.0):
        pts = np.stack([rr * np.cos(angles), rr * np.sin(angles), np.full(40, 4.0)], axis=1)
        t, d = c.closest_point(pts, precision=1e-7)
        foot = c.evaluate(t)
        # the foot is (almost) on the ray through the point: the Bézier is almost a circle
        # (its normals deviate from radial by ~1e-3 rad, more off at points near the centre)
        np.testing.assert_allclose(np.arctan2(foot[:, 1], foot[:, 0]), angles, atol=5e-3)
        np.testing.assert_allclose(d, np.hypot(rr - R, 4.0), rtol=1e-3)
        # and the segment foot -> point is orthogonal to the tangent (a true local minimum)
        cosang = np.einsum("ij,ij->i", pts - foot, c.derivative(t)) / (
            d * np.linalg.norm(c.derivative(t), axis=1)
        )
        assert np.abs(cosang).max() < 1e-5


def test_closest_point_shapes_and_errors():
    c = random_curve("catmull-rom", 4)
    t, d = c.closest_point([1.0, 2.0, 3.0])
    assert np.ndim(t) == 0
    assert np.ndim(d) == 0
    t, d = c.closest_point(np.zeros((0, 3)))
    assert t.shape == d.shape == (0,)
    with pytest.raises(WarpError, match=r"points must be a 3-vector \(or an \(M, 3\) array\)"):
        c.closest_point(np.zeros((4, 2)))
    with pytest.raises(WarpError, match="points must be finite"):
        c.closest_point([[0, 0, np.nan]])
    with pytest.raises(WarpError, match=r"precision must be a number in \(0, 1\)"):
        c.closest_point([0, 0, 0], precision=0.0)


# ----------------------------------------------------------------------- frames
def frame_det(tan: np.ndarray, nrm: np.ndarray, bin_: np.ndarray) -> np.ndarray:
    return np.linalg.det(np.stack([tan, nrm, bin_], axis=-1))


@pytest.mark.parametrize("kind", ["catmull-rom", "bezier"])
def test_frames_are_orthonormal_and_right_handed(kind: str):
    c = random_curve(kind, 10, seed=15)
    t = np.random.default_rng(16).uniform(0, 1, 5000)
    tan, nrm, bin_ = c.frames(t)
    for v in (tan, nrm, bin_):
        np.testing.assert_allclose(np.linalg.norm(v, axis=1), 1.0, atol=1e-12)
    for a, b in ((tan, nrm), (tan, bin_), (nrm, bin_)):
        assert np.abs(np.einsum("ij,ij->i", a, b)).max() < 1e-12
    np.testing.assert_allclose(frame_det(tan, nrm, bin_), 1.0, atol=1e-12)
    np.testing.assert_allclose(bin_, np.cross(tan, nrm), atol=1e-12)
    d = c.derivative(t)
    np.testing.assert_allclose(tan, d / np.linalg.norm(d, axis=1)[:, None], atol=1e-12)


def test_frames_shapes():
    c = random_curve("catmull-rom", 5)
    assert all(v.shape == (3,) for v in c.frames(0.4))
    assert all(v.shape == (7, 3) for v in c.frames(np.linspace(0, 1, 7)))


def test_initial_normal_is_projected_and_default_is_least_aligned_axis():
    c = Curve([[0, 0, 0], [10, 1, 3], [20, 0, 8]])
    t0 = c.derivative(0.0) / np.linalg.norm(c.derivative(0.0))
    assert np.argmin(np.abs(t0)) == 1  # y is the least aligned world axis
    _, n_default, _ = c.frames(0.0)
    y = np.array([0.0, 1.0, 0.0])
    expected = y - y.dot(t0) * t0
    np.testing.assert_allclose(n_default, expected / np.linalg.norm(expected), atol=1e-12)
    given = np.array([1.0, 2.0, -5.0])
    _, n_given, _ = c.frames(0.0, initial_normal=given)
    expected = given - given.dot(t0) * t0
    np.testing.assert_allclose(n_given, expected / np.linalg.norm(expected), atol=1e-12)


def test_initial_normal_parallel_to_tangent_raises():
    c = Curve([[0, 0, 0], [10, 0, 0], [20, 5, 0]])
    tangent = c.derivative(0.0)
    with pytest.raises(WarpError, match=r"parallel to the curve's tangent .*not parallel"):
        c.frames(0.5, initial_normal=-3 * tangent)
    with pytest.raises(WarpError, match="initial_normal must be finite"):
        c.frames(0.5, initial_normal=[0, np.nan, 1])
    with pytest.raises(WarpError, match="initial_normal must be a 3-vector"):
        c.frames(0.5, initial_normal=[0, 1])


def test_frames_are_cached_per_initial_normal_and_the_cache_is_bounded():
    c = smooth_3d_curve()
    first = c.frames(0.3, initial_normal=[0, 0, 1])
    assert len(c._rmf_cache) == 1
    again = c.frames(0.3, initial_normal=[0, 0, 1])
    np.testing.assert_array_equal(np.stack(first), np.stack(again))
    assert len(c._rmf_cache) == 1
    other = c.frames(0.3, initial_normal=[0, 1, 0])
    assert not np.allclose(first[1], other[1])
    for i in range(20):
        c.frames(0.3, initial_normal=[1, i, 3])
    assert len(c._rmf_cache) <= 8
    np.testing.assert_array_equal(c.frames(0.3, initial_normal=[0, 0, 1])[1], first[1])


@pytest.mark.parametrize("samples", [1, 0, 2.0, True])
def test_frames_rejects_bad_sample_counts(samples: Any):
    with pytest.raises(WarpError, match="integer number of samples"):
        random_curve("catmull-rom", 3).frames(0.5, samples=samples)


@pytest.mark.parametrize("kind", ["catmull-rom", "bezier"])
def test_rmf_of_planar_curve_keeps_the_plane_normal(kind: str):
    rng = np.random.default_rng(17)
    pts = np.zeros((7, 3))
    pts[:, :2] = rng.normal(scale=30.0, size=(7, 2))
    pts[:, 2] = 4.0  # plane z = 4
    c = Curve(pts, kind=kind)
    t = np.linspace(0, 1, 3001)
    tan, nrm, bin_ = c.frames(t, initial_normal=[0.0, 0.0, 1.0])
    np.testing.assert_allclose(nrm, np.tile([0.0, 0.0, 1.0], (len(t), 1)), atol=1e-9)
    assert np.abs(tan[:, 2]).max() < 1e-12
    assert np.abs(bin_[:, 2]).max() < 1e-9


def test_rmf_of_planar_curve_with_in_plane_normal_turns_with_the_tangent():
    c = quarter_circle()
    t = np.linspace(0, 1, 501)
    tan, nrm, _ = c.frames(t, initial_normal=[-1.0, 0.0, 0.0])  # inward at (R, 0, 0)
    inward = np.cross([0.0, 0.0, 1.0], tan)  # the tangent turned by +90 degrees in the plane
    np.testing.assert_allclose(nrm, inward, atol=1e-9)
    # so at the end (0, R, 0) it points inward again: -y
    np.testing.assert_allclose(nrm[-1], [0.0, -1.0, 0.0], atol=1e-9)


def twist_angles(tan: np.ndarray, nrm: np.ndarray) -> np.ndarray:
    """Rotation of N about T between neighbours, after removing the tangent's own turn."""
    rot = minimal_rotation(tan[:-1], tan[1:])
    carried = np.einsum("mij,mj->mi", rot, nrm[:-1])
    sin = np.einsum("ij,ij->i", np.cross(carried, nrm[1:]), tan[1:])
    cos = np.einsum("ij,ij->i", carried, nrm[1:])
    return np.arctan2(sin, cos)


def test_twist_measure_on_the_exact_helix_frenet_frame():
    # sanity of twist_angles: the exact helix's Frenet normal (pointing at the axis) turns
    # about T by tau * L in all, tau = c / (r^2 + c^2), c = pitch / 2 pi
    radius, pitch = 10.0, 5.0
    a = np.linspace(0.0, 4 * np.pi, 4001)
    cc = pitch / (2 * np.pi)
    d = np.stack([-radius * np.sin(a), radius * np.cos(a), np.full_like(a, cc)], axis=1)
    tan = d / np.linalg.norm(d, axis=1)[:, None]
    frenet = np.stack([-np.cos(a), -np.sin(a), np.zeros_like(a)], axis=1)
    length = 4 * np.pi * np.hypot(radius, cc)
    twist = twist_angles(tan, frenet)
    assert np.abs(twist).sum() == pytest.approx(cc / (radius**2 + cc**2) * length, rel=1e-4)


def test_rmf_of_helix_has_far_less_twist_than_the_frenet_frame():
    c = Curve(helix_points(n=49, radius=10.0, pitch=5.0, turns=2.0))
    t = np.linspace(0, 1, 2001)
    tan, nrm, _ = c.frames(t)
    d2 = c.second_derivative(t)
    frenet = d2 - np.einsum("ij,ij->i", d2, tan)[:, None] * tan
    frenet /= np.linalg.norm(frenet, axis=1)[:, None]
    rmf_twist = np.abs(twist_angles(tan, nrm))
    frenet_twist = np.abs(twist_angles(tan, frenet))
    # the spline's Frenet frame twists at least by the helix' torsion (~1 rad over 2 turns;
    # more, as its curvature vector also jumps at the C1 joins); the RMF does not twist
    assert frenet_twist.sum() > 0.9
    assert rmf_twist.sum() < 1e-4 * frenet_twist.sum()
    assert rmf_twist.max() < 1e-6


@pytest.mark.parametrize("kind", ["catmull-rom", "bezier"])
def test_rmf_matches_fine_step_parallel_transport(kind: str):
    # independent construction: carry N0 by the minimal rotation between the tangents of
    # 100 000 consecutive fine samples (discrete parallel transport, error ~1e-7 here)
    c = smooth_3d_curve(kind)
    t_query = np.sort(np.random.default_rng(18).uniform(0, 1, 40))
    t_fine = np.union1d(np.linspace(0, 1, 100_001), t_query)
    d = c.derivative(t_fine)
    tan_fine = d / np.linalg.norm(d, axis=1)[:, None]
    rots = minimal_rotation(tan_fine[:-1], tan_fine[1:])
    n0 = np.array([0.3, -0.2, 0.9])
    n = n0 - n0.dot(tan_fine[0]) * tan_fine[0]
    n /= np.linalg.norm(n)
    transported = [n]
    for rot in rots:
        n = rot @ n
        transported.append(n)
    expected = np.array(transported)[np.searchsorted(t_fine, t_query)]
    _, nrm, _ = c.frames(t_query, initial_normal=n0)
    angle = np.arccos(np.clip(np.einsum("ij,ij->i", nrm, expected), -1, 1))
    assert angle.max() < 1e-6


def test_frames_converge_with_more_samples_and_vary_smoothly():
    c = smooth_3d_curve("bezier")
    t = np.linspace(0, 1, 777)
    _, n_ref, _ = c.frames(t, samples=16384)
    _, n_few, _ = c.frames(t, samples=32)
    _, n_default, _ = c.frames(t)
    err_few = np.linalg.norm(n_few - n_ref, axis=1).max()
    err_default = np.linalg.norm(n_default - n_ref, axis=1).max()
    assert err_default < 1e-6
    assert err_few > 100 * err_default
    # no jumps between neighbouring parameters
    assert np.linalg.norm(np.diff(n_default, axis=0), axis=1).max() < 0.05


def test_frames_survive_a_tight_turn_and_a_kink():
    # random control points: a Bézier with kinks at the joins and near-cusps
    for kind, n_points in (("bezier", 10), ("catmull-rom", 8)):
        c = random_curve(kind, n_points, seed=18)
        tan, nrm, bin_ = c.frames(np.linspace(0, 1, 3001))
        assert np.all(np.isfinite(nrm))
        assert np.abs(np.einsum("ij,ij->i", tan, nrm)).max() < 1e-12
        np.testing.assert_allclose(frame_det(tan, nrm, bin_), 1.0, atol=1e-12)


def test_coincident_bezier_handles_use_the_limit_tangent():
    p0, p2, p3 = np.array([0.0, 0, 0]), np.array([10.0, 5, 0]), np.array([20.0, 0, 3])
    c = Curve([p0, p0, p2, p3], kind="bezier")  # P1 == P0: alpha'(0) = 0
    assert np.linalg.norm(c.derivative(0.0)) == 0.0
    tan, nrm, bin_ = c.frames(np.array([0.0, 0.5, 1.0]))
    assert np.all(np.isfinite(np.stack([tan, nrm, bin_])))
    # the limit of the tangent at t -> 0 is along alpha''(0) ~ P2 - P0
    limit = (p2 - p0) / np.linalg.norm(p2 - p0)
    assert np.dot(tan[0], limit) > 1 - 1e-6
    np.testing.assert_allclose(frame_det(tan, nrm, bin_), 1.0, atol=1e-12)
    # closest point and length work too
    assert c.closest_point(p0)[1] == pytest.approx(0.0, abs=1e-9)
    assert c.length == pytest.approx(true_length(c), rel=1e-4)


# ----------------------------------------------------------------------- minimal_rotation
def assert_rotation(rot: np.ndarray) -> None:
    np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(rot) == pytest.approx(1.0, abs=1e-12)


def test_minimal_rotation_maps_a_to_b_about_their_cross_product():
    rng = np.random.default_rng(20)
    for _ in range(200):
        a, b = rng.normal(size=(2, 3))
        rot = minimal_rotation(a, b)
        assert_rotation(rot)
        an, bn = a / np.linalg.norm(a), b / np.linalg.norm(b)
        np.testing.assert_allclose(rot @ an, bn, atol=1e-12)
        axis = np.cross(an, bn)
        np.testing.assert_allclose(rot @ axis, axis, atol=1e-12)  # the axis is a x b
        angle = np.arccos(np.clip((np.trace(rot) - 1) / 2, -1, 1))
        assert angle == pytest.approx(np.arccos(np.clip(an @ bn, -1, 1)), abs=1e-7)


def test_minimal_rotation_equal_and_opposite_vectors():
    a = np.array([0.2, -0.5, 0.8])
    a /= np.linalg.norm(a)
    np.testing.assert_allclose(minimal_rotation(a, a), np.eye(3), atol=1e-15)
    np.testing.assert_allclose(minimal_rotation(a, 3 * a), np.eye(3), atol=1e-15)
    for v in (a, np.array([1.0, 0, 0]), np.array([0.0, 0, -1])):
        half_turn = minimal_rotation(v, -v)
        assert_rotation(half_turn)
        np.testing.assert_allclose(half_turn @ v, -v, atol=1e-15)
    # nearly opposite: still exact
    b = -a + np.array([1e-9, -2e-9, 0.0])
    b /= np.linalg.norm(b)
    rot = minimal_rotation(a, b)
    assert_rotation(rot)
    np.testing.assert_allclose(rot @ a, b, atol=1e-12)
    # nearly equal
    b = a + np.array([0.0, 1e-12, 1e-12])
    rot = minimal_rotation(a, b)
    np.testing.assert_allclose(rot @ a, b / np.linalg.norm(b), atol=1e-15)


def test_minimal_rotation_batch_and_errors():
    rng = np.random.default_rng(21)
    a, b = rng.normal(size=(2, 50, 3))
    rots = minimal_rotation(a, b)
    assert rots.shape == (50, 3, 3)
    bn = b / np.linalg.norm(b, axis=1)[:, None]
    an = a / np.linalg.norm(a, axis=1)[:, None]
    np.testing.assert_allclose(np.einsum("mij,mj->mi", rots, an), bn, atol=1e-12)
    with pytest.raises(WarpError, match="non-zero vectors"):
        minimal_rotation([0, 0, 0], [1, 0, 0])
    with pytest.raises(WarpError, match="same shape"):
        minimal_rotation([1, 0, 0], [[1, 0, 0]])
    with pytest.raises(WarpError, match="must be finite"):
        minimal_rotation([1, 0, np.nan], [1, 0, 0])


# ----------------------------------------------------------------------- bounds, dict
@pytest.mark.parametrize("kind", ["catmull-rom", "bezier"])
def test_bounds_contain_the_curve(kind: str):
    c = random_curve(kind, 10, seed=22)
    lo, hi = c.bounds()
    pts = c.evaluate(np.linspace(0, 1, 100_001))
    assert np.all(pts >= lo - 1e-9)
    assert np.all(pts <= hi + 1e-9)
    assert np.all(c.control_points >= lo - 1e-9)
    assert np.all(c.control_points <= hi + 1e-9)
    if kind == "bezier":
        np.testing.assert_array_equal(lo, c.control_points.min(axis=0))
        np.testing.assert_array_equal(hi, c.control_points.max(axis=0))


def test_catmull_rom_bounds_cover_its_overshoot():
    # a sharp turn: the curve bulges beyond the control points' box, the bounds do not miss it
    c = Curve([[0, 0, 0], [10, 0, 0], [10, 1, 0], [0, 1, 0]])
    pts = c.evaluate(np.linspace(0, 1, 10_001))
    assert pts[:, 0].max() > 10.5  # overshoot past x = 10
    lo, hi = c.bounds()
    assert np.all(pts >= lo - 1e-12)
    assert np.all(pts <= hi + 1e-12)
    assert hi[0] < 10.0 + 5.0  # and not absurdly loose


@pytest.mark.parametrize("kind", ["catmull-rom", "bezier"])
def test_dict_round_trip(kind: str):
    c = random_curve(kind, 7, seed=23)
    d = c.to_dict()
    assert set(d) == {"kind", "control_points"}
    assert d["kind"] == kind
    again = Curve.from_dict(json.loads(json.dumps(d)))
    assert again.kind == kind
    np.testing.assert_array_equal(again.control_points, c.control_points)
    np.testing.assert_array_equal(again.evaluate([0.3, 0.9]), c.evaluate([0.3, 0.9]))


@pytest.mark.parametrize(
    ("d", "match"),
    [
        ([1, 2], r"must be a dict .*got list"),
        ({"kind": "bezier"}, r"missing \['control_points'\]"),
        ({"control_points": [[0, 0, 0], [1, 0, 0]]}, r"missing \['kind'\]"),
        ({}, r"missing \['kind', 'control_points'\]"),
        (
            {"kind": "bezier", "control_points": np.zeros((4, 3)).tolist(), "colour": "red"},
            r"unknown keys \['colour'\]",
        ),
        ({"kind": 3, "control_points": [[0, 0, 0], [1, 0, 0]]}, r"'kind' must be a string"),
        ({"kind": "bezier", "control_points": "0 0 0"}, r"list of \[x, y, z\] lists; got str"),
        ({"kind": "bezier", "control_points": [[0, 0, 0], [1, 0, 0]]}, r"3k\+1"),
        ({"kind": "spline", "control_points": [[0, 0, 0], [1, 0, 0]]}, "unknown curve kind"),
        ({"kind": "catmull-rom", "control_points": [[0, 0], [1, 0]]}, r"\(N, 3\)"),
    ],
)
def test_from_dict_rejects_bad_entries(d: Any, match: str):
    with pytest.raises(WarpError, match=match):
        Curve.from_dict(d)


def test_repr_names_kind_and_sizes():
    assert repr(random_curve("bezier", 7)) == "Curve(kind='bezier', 7 control points, 2 segments)"


# ----------------------------------------------------------------------- vectorised
def test_vectorised_methods_equal_point_by_point_calls() -> None:
    """``evaluate``, ``derivative`` and ``closest_point`` of a batch give what they give
    for each parameter or point alone (their speed is measured by
    ``benchmarks.wires.bench_curve_speed``, see docs/benchmarks.md, not asserted here)."""
    c = random_curve("catmull-rom", 9, seed=24)
    rng = np.random.default_rng(25)
    t = np.concatenate([[0.0, 1.0, 0.5, 1 / 8, 7 / 8], rng.uniform(0, 1, 200)])
    np.testing.assert_allclose(
        c.evaluate(t), np.array([c.evaluate(float(s)) for s in t]).reshape(-1, 3), atol=1e-12
    )
    np.testing.assert_allclose(
        c.derivative(t), np.array([c.derivative(float(s)) for s in t]).reshape(-1, 3), atol=1e-12
    )
    pts = rng.normal(scale=30.0, size=(100, 3))
    tb, db = c.closest_point(pts)
    single = [c.closest_point(p) for p in pts]
    np.testing.assert_allclose(tb, np.array([float(np.squeeze(s[0])) for s in single]), atol=1e-12)
    np.testing.assert_allclose(db, np.array([float(np.squeeze(s[1])) for s in single]), atol=1e-12)
