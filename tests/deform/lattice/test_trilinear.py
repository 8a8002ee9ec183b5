"""Tests of voxwarp.deform.lattice.trilinear: trilinear transformations and grids of trilinear
cells.

Oracles: the paper's corner form (eq. 1) against the coefficient form (eqs. 2-4) and
the explicit alternating edge sums of ``C``; corners reproduced at the cube corners; an
affine map applied to the unit cube (a parallelepiped) against its 4x4 matrix; the
forward map (the inverse must undo it); finite differences (Jacobians); the matrix
product (composition of linear grids); the exact composed function (composition error
~ h^2); a cell with two corners swapped (``det J`` changes sign: folded).
"""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from voxwarp.deform.lattice.trilinear import (
    MONOMIALS,
    UNIT_CORNERS,
    TrilinearGrid,
    TrilinearTransform,
)
from voxwarp.deform.warp import WarpError


# -------------------------------------------------------------------- helpers
def random_affine(rng: np.random.Generator, scale: float = 3.0) -> np.ndarray:
    """A random, well-conditioned, orientation-preserving 4x4 affine matrix."""
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    m = np.eye(4)
    m[:3, :3] = (
        q @ np.diag(rng.uniform(0.5, 2.0, 3) * scale) @ (np.eye(3) + 0.2 * rng.normal(size=(3, 3)))
    )
    m[:3, 3] = rng.normal(size=3) * 10
    if np.linalg.det(m[:3, :3]) < 0:
        m[:3, 0] *= -1
    return m


def mild_corners(rng: np.random.Generator, amount: float = 0.12) -> np.ndarray:
    """Box corners (sizes 2, 3, 4) moved by up to ``amount`` of the box: no folds."""
    size = np.array([2.0, 3.0, 4.0])
    return UNIT_CORNERS * size + rng.uniform(-amount, amount, (8, 3)) * size + 5.0


def mild_grid(rng: np.random.Generator, cells: int = 8, amount: float = 0.1) -> TrilinearGrid:
    """A box lattice (10 x 20 x 30 mm) with nodes moved by up to ``amount`` cells."""
    g = TrilinearGrid.identity(cells)
    size = np.array([10.0, 20.0, 30.0])
    jitter = rng.uniform(-amount, amount, g.nodes.shape) * size / cells
    return TrilinearGrid(g.nodes * size + jitter - 3.0)


def bend(u: np.ndarray) -> np.ndarray:
    """A smooth, non-trilinear map of the unit cube (a bend about the y axis)."""
    x, y, z = u[:, 0], u[:, 1], u[:, 2]
    r = 2.0 + z
    a = 0.9 * (x - 0.5)
    return np.stack([r * np.sin(a), 1.5 * y + 0.2 * np.sin(3.0 * x), r * np.cos(a)], axis=1)


def squeeze(u: np.ndarray) -> np.ndarray:
    """A smooth map of the unit cube into itself (the inner map of compositions)."""
    s = np.sin(np.pi * u)
    return 0.1 + 0.8 * u + 0.05 * np.stack([s[:, 1] * s[:, 2], s[:, 0], s[:, 0] * s[:, 1]], 1)


def fd_jacobian(f, u: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central finite differences (N, 3, 3)."""
    cols = []
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        cols.append((f(u + e) - f(u - e)) / (2 * h))
    return np.stack(cols, axis=-1)


# ========================================================= TrilinearTransform
@pytest.mark.parametrize("seed", range(5))
def test_corner_form_equals_coefficient_form(seed: int) -> None:
    rng = np.random.default_rng(seed)
    t = TrilinearTransform(rng.normal(size=(8, 3)) * 10)
    u = rng.uniform(-0.5, 1.5, (500, 3))
    np.testing.assert_allclose(t.evaluate_corners(u), t.evaluate_coefficients(u), atol=1e-12)
    np.testing.assert_allclose(t(u), t.evaluate_corners(u), atol=1e-12)


def test_coefficients_are_the_papers_edge_sums() -> None:
    rng = np.random.default_rng(1)
    p = rng.normal(size=(8, 3))
    c = TrilinearTransform(p).coefficients
    assert c.shape == (3, 8)
    col = dict(zip(MONOMIALS, c.T, strict=True))
    np.testing.assert_allclose(col["1"], p[0])
    np.testing.assert_allclose(col["x"], p[1] - p[0])
    np.testing.assert_allclose(col["y"], p[2] - p[0])
    np.testing.assert_allclose(col["z"], p[4] - p[0])
    np.testing.assert_allclose(col["xy"], p[3] - p[2] - p[1] + p[0])
    np.testing.assert_allclose(col["xz"], p[5] - p[4] - p[1] + p[0])
    np.testing.assert_allclose(col["yz"], p[6] - p[4] - p[2] + p[0])
    xyz = p[7] - p[6] - p[5] - p[3] + p[4] + p[2] + p[1] - p[0]
    np.testing.assert_allclose(col["xyz"], xyz, atol=1e-14)


def test_corners_are_reproduced() -> None:
    rng = np.random.default_rng(2)
    p = rng.normal(size=(8, 3))
    t = TrilinearTransform(p)
    # corner order: index = x + 2 y + 4 z
    np.testing.assert_array_equal(UNIT_CORNERS[3], [1, 1, 0])
    np.testing.assert_array_equal(UNIT_CORNERS[6], [0, 1, 1])
    np.testing.assert_allclose(t(UNIT_CORNERS), p, atol=1e-14)
    np.testing.assert_allclose(t.evaluate_coefficients(UNIT_CORNERS), p, atol=1e-14)
    np.testing.assert_allclose(t(UNIT_CORNERS[5]), p[5], atol=1e-14)  # single point (3,)


@pytest.mark.parametrize("seed", range(4))
def test_parallelepiped_is_linear_and_equals_its_matrix(seed: int) -> None:
    rng = np.random.default_rng(seed)
    m = random_affine(rng)
    corners = UNIT_CORNERS @ m[:3, :3].T + m[:3, 3]  # the affine image of the unit cube
    t = TrilinearTransform(corners)
    assert t.is_linear
    np.testing.assert_allclose(np.abs(t.coefficients[:, :4]).max(), 0.0, atol=1e-12)
    np.testing.assert_allclose(t.matrix(), m, atol=1e-12)
    u = rng.uniform(-1, 2, (200, 3))
    expected = u @ m[:3, :3].T + m[:3, 3]
    np.testing.assert_allclose(t(u), expected, atol=1e-11)
    np.testing.assert_allclose(t.evaluate_corners(u), expected, atol=1e-11)
    np.testing.assert_allclose(TrilinearTransform.from_matrix(m).corners, corners, atol=1e-12)
    np.testing.assert_allclose(t.jacobian(u), np.broadcast_to(m[:3, :3], (200, 3, 3)))
    np.testing.assert_allclose(t.inverse(expected), u, atol=1e-10)


def test_non_parallelepiped_is_not_linear() -> None:
    rng = np.random.default_rng(3)
    m = random_affine(rng)
    corners = UNIT_CORNERS @ m[:3, :3].T + m[:3, 3]
    corners[7] += [0.05, 0.0, 0.0]  # one corner off the parallelepiped
    t = TrilinearTransform(corners)
    assert not t.is_linear
    with pytest.raises(WarpError, match="not linear"):
        t.matrix()
    assert TrilinearTransform.identity().is_linear
    box = TrilinearTransform.from_box([1, 2, 3], [2, 4, 7])
    np.testing.assert_allclose(box.matrix()[:3, :3], np.diag([1, 2, 4]))


def test_jacobian_matches_finite_differences() -> None:
    rng = np.random.default_rng(4)
    t = TrilinearTransform(rng.normal(size=(8, 3)))
    u = rng.uniform(-0.2, 1.2, (50, 3))
    np.testing.assert_allclose(t.jacobian(u), fd_jacobian(t, u), atol=1e-7)
    assert t.jacobian(u[0]).shape == (3, 3)


@pytest.mark.parametrize("seed", range(6))
def test_inverse_undoes_forward(seed: int) -> None:
    rng = np.random.default_rng(seed)
    t = TrilinearTransform(mild_corners(rng))
    assert not t.is_linear
    assert not t.folds()
    u = rng.uniform(0, 1, (2000, 3))
    back, conv, folded = t.inverse(t(u), return_info=True)
    assert conv.all()
    assert not folded.any()
    np.testing.assert_allclose(back, u, atol=1e-9)
    np.testing.assert_allclose(t.inverse(t(u[0])), u[0], atol=1e-9)


def test_mirrored_transform_inverts_without_folds() -> None:
    corners = UNIT_CORNERS * [-1.0, 2.0, 1.0]  # reflection: det J < 0 everywhere
    corners[7] += [0.1, 0.1, -0.1]  # and not linear
    t = TrilinearTransform(corners)
    assert t.volume < 0
    assert not t.folds()
    u = np.random.default_rng(0).uniform(0, 1, (300, 3))
    back, conv, folded = t.inverse(t(u), return_info=True)
    assert conv.all()
    assert not folded.any()
    np.testing.assert_allclose(back, u, atol=1e-9)


def test_swapped_corners_fold() -> None:
    corners = UNIT_CORNERS.copy()
    corners[[0, 1]] = corners[[1, 0]]  # T_x = x + (1 - 2x)(1 - y)(1 - z)
    t = TrilinearTransform(corners)
    assert t.folds()
    assert not TrilinearTransform(mild_corners(np.random.default_rng(0))).folds()
    # dT_x/dx = 1 - 2 (1 - y)(1 - z) < 0 near the swapped edge, > 0 near the far edges
    u = np.array([[0.3, 0.05, 0.05], [0.7, 0.1, 0.02], [0.4, 0.8, 0.9]])
    assert np.linalg.det(t.jacobian(u[:2])).max() < 0 < np.linalg.det(t.jacobian(u[2]))
    back, conv, folded = t.inverse(t(u), return_info=True)
    np.testing.assert_array_equal(folded, [True, True, False])
    assert conv.all()
    np.testing.assert_allclose(t(back), t(u), atol=1e-10)


def test_points_far_outside_do_not_converge_or_are_exact() -> None:
    # outside the cube the polynomial may fold; a reported solution is always exact
    corners = mild_corners(np.random.default_rng(7), amount=0.2)
    t = TrilinearTransform(corners)
    x = np.random.default_rng(8).uniform(-40, 40, (500, 3))
    back, conv, _ = t.inverse(x, max_iter=30, return_info=True)
    assert np.isnan(back[~conv]).all()
    np.testing.assert_allclose(t(back[conv]), x[conv], atol=1e-8)


def test_flat_transform_has_no_inverse() -> None:
    flat = UNIT_CORNERS * [1.0, 1.0, 0.0]  # all corners in the plane z = 0
    flat[7, 1] += 0.3  # and not linear
    t = TrilinearTransform(flat)
    assert t.is_flat()
    with pytest.raises(WarpError, match="flat"):
        t.inverse([[0.5, 0.5, 0.0]])
    with pytest.raises(WarpError, match="flat"):
        TrilinearTransform(np.zeros((8, 3))).inverse([0.0, 0.0, 0.0])


@pytest.mark.parametrize(
    ("corners", "fragment"),
    [
        (np.zeros((4, 3)), r"shape \(8, 3\)"),
        (np.zeros((8, 2)), r"shape \(8, 3\)"),
        (np.full((8, 3), np.nan), "NaN"),
        ("abc", "array of numbers"),
    ],
)
def test_bad_corners(corners: object, fragment: str) -> None:
    with pytest.raises(WarpError, match=fragment):
        TrilinearTransform(corners)


def test_bad_points_and_matrices() -> None:
    t = TrilinearTransform(mild_corners(np.random.default_rng(0)))
    with pytest.raises(WarpError, match="NaN"):
        t([[0.1, np.nan, 0.2]])
    with pytest.raises(WarpError, match="NaN"):
        t.inverse([[0.1, 0.2, np.inf]])
    with pytest.raises(WarpError, match=r"shape \(N, 3\)"):
        t.jacobian(np.zeros((4, 2)))
    bad = np.eye(4)
    bad[3, 0] = 1.0
    with pytest.raises(WarpError, match="last row"):
        TrilinearTransform.from_matrix(bad)
    with pytest.raises(WarpError, match="4x4"):
        TrilinearGrid.from_matrix(np.eye(3))
    with pytest.raises(WarpError, match="lo < hi"):
        TrilinearTransform.from_box([0, 0, 0], [1, 0, 1])


def test_transform_dict_round_trip() -> None:
    t = TrilinearTransform(mild_corners(np.random.default_rng(3)))
    t2 = TrilinearTransform.from_dict(json.loads(json.dumps(t.to_dict())))
    np.testing.assert_array_equal(t2.corners, t.corners)
    with pytest.raises(WarpError, match="corners"):
        TrilinearTransform.from_dict({"nodes": []})


# ============================================================== TrilinearGrid
def test_grid_nodes_cells_and_extrapolation() -> None:
    rng = np.random.default_rng(10)
    g = mild_grid(rng, cells=3)
    nx, ny, nz = g.shape
    assert g.shape == (3, 3, 3)
    assert g.n_cells == 27
    unit = TrilinearGrid.identity((nx, ny, nz)).nodes
    np.testing.assert_allclose(g(unit), g.nodes, atol=1e-12)
    # inside a cell: the cell's trilinear transform at local coordinates
    cell = g.cell(1, 2, 0)
    t = rng.uniform(0, 1, (100, 3))
    np.testing.assert_allclose(g((np.array([1, 2, 0]) + t) / 3.0), cell(t), atol=1e-12)
    # outside [0,1]^3: the border cell's polynomial, extrapolated
    t_out = rng.uniform(-1, 0, (100, 3)) * [1, 0, 0] + [0, 0.5, 0.25]
    u_out = (np.array([0, 2, 0]) + t_out) / 3.0
    np.testing.assert_allclose(g(u_out), g.cell(0, 2, 0)(t_out), atol=1e-12)
    with pytest.raises(WarpError, match="out of range"):
        g.cell(3, 0, 0)


def test_grid_from_transform_is_exact() -> None:
    t = TrilinearTransform(mild_corners(np.random.default_rng(11), amount=0.2))
    g = TrilinearGrid.from_transform(t, (2, 3, 5))
    u = np.random.default_rng(12).uniform(0, 1, (500, 3))
    np.testing.assert_allclose(g(u), t(u), atol=1e-12)
    assert not g.is_linear
    # resampling at multiples of the cell counts is exact too
    np.testing.assert_allclose(g.resample((4, 6, 10))(u), t(u), atol=1e-12)


def test_grid_jacobian_matches_finite_differences() -> None:
    rng = np.random.default_rng(13)
    g = mild_grid(rng, cells=4, amount=0.2)
    # keep away from the cell faces (the Jacobian jumps there)
    u = (rng.integers(0, 4, (100, 3)) + rng.uniform(0.1, 0.9, (100, 3))) / 4.0
    np.testing.assert_allclose(g.jacobian(u), fd_jacobian(g, u), rtol=1e-6, atol=1e-6)


def test_linear_grid_is_its_matrix() -> None:
    rng = np.random.default_rng(14)
    m = random_affine(rng)
    g = TrilinearGrid.from_matrix(m, (2, 3, 4))
    assert g.is_linear
    np.testing.assert_allclose(g.matrix(), m, atol=1e-10)
    u = rng.uniform(0, 1, (100, 3))
    np.testing.assert_allclose(g(u), u @ m[:3, :3].T + m[:3, 3], atol=1e-10)
    np.testing.assert_allclose(g.inverse(g(u)), u, atol=1e-10)
    assert not mild_grid(rng).is_linear
    with pytest.raises(WarpError, match="not one affine map"):
        mild_grid(rng).matrix()


def test_composing_linear_grids_is_the_matrix_product() -> None:
    rng = np.random.default_rng(15)
    outer_m, inner_m = random_affine(rng), random_affine(rng, scale=0.4)
    outer = TrilinearGrid.from_matrix(outer_m, (2, 1, 3))
    inner = TrilinearGrid.from_matrix(inner_m, (1, 4, 2))
    c = outer.compose(inner)
    assert c.shape == (2, 4, 3)
    assert c.is_linear
    np.testing.assert_allclose(c.matrix(), outer_m @ inner_m, atol=1e-9)
    np.testing.assert_allclose(outer.compose(inner_m).matrix(), outer_m @ inner_m, atol=1e-9)
    assert outer.compose(inner, cells=5).shape == (5, 5, 5)


def test_composition_error_shrinks_like_h_squared() -> None:
    u = np.random.default_rng(16).uniform(0, 1, (20000, 3))
    exact = bend(squeeze(u))  # the exact composed function, evaluated densely
    cells = [2, 4, 8, 16]
    errors = []
    for n in cells:
        outer = TrilinearGrid.from_function(bend, n)
        inner = TrilinearGrid.from_function(squeeze, n)
        composed = outer.compose(inner)
        assert composed.shape == (n, n, n)
        errors.append(float(np.abs(composed(u) - exact).max()))
    assert all(a > b for a, b in itertools.pairwise(errors)), errors
    ratios = np.array(errors[:-1]) / np.array(errors[1:])  # measured 2.97, 3.58, 3.89
    assert (ratios > 2.5).all(), ratios
    assert (ratios < 6.0).all(), ratios
    assert ratios[-1] > 3.5, ratios  # ~4 = 2^2 once asymptotic: O(h^2)
    # a coarser inner grid is resampled to the outer resolution first
    coarse = TrilinearGrid.from_function(bend, 16).compose(TrilinearGrid.from_function(squeeze, 4))
    assert coarse.shape == (16, 16, 16)
    assert float(np.abs(coarse(u) - exact).max()) < errors[1]


def test_grid_inverse_undoes_forward() -> None:
    rng = np.random.default_rng(17)
    g = mild_grid(rng, cells=8)
    assert not g.folds()
    u = rng.uniform(0, 1, (20000, 3))
    nodes = TrilinearGrid.identity(8).nodes.reshape(-1, 3)  # incl. faces, edges, corners
    u = np.concatenate([u, nodes])
    back, conv, folded = g.inverse(g(u), return_info=True)
    assert conv.all()
    assert not folded.any()
    np.testing.assert_allclose(back, u, atol=1e-5)
    assert float(np.abs(back - u).max()) < 1e-9
    np.testing.assert_allclose(g.inverse(g(u[0])), u[0], atol=1e-9)


def test_grid_inverse_outside_the_lattice() -> None:
    rng = np.random.default_rng(18)
    g = mild_grid(rng, cells=4)
    u = rng.uniform(0, 1, (300, 3))
    u[:150, 0] = rng.uniform(1.02, 1.1, 150)  # beyond the x = 1 face
    u[150:, 1] = rng.uniform(-0.1, -0.02, 150)  # beyond the y = 0 face
    x = g(u)  # the extrapolated map
    back, conv, _folded = g.inverse(x, return_info=True)
    assert not conv.any()
    assert np.isnan(back).all()
    back, conv, _ = g.inverse(x, return_info=True, outside="extrapolate")
    assert conv.all()
    np.testing.assert_allclose(back, u, atol=1e-8)
    far = np.full((1, 3), 1e4)
    back, conv, _ = g.inverse(far, return_info=True)
    assert not conv[0]
    assert np.isnan(back).all()
    with pytest.raises(WarpError, match="outside"):
        g.inverse(far, outside="clamp")


def test_grid_with_swapped_nodes_reports_folds() -> None:
    g0 = TrilinearGrid.identity(4)
    nodes = g0.nodes.copy()
    nodes[[1, 2], 1, 1] = nodes[[2, 1], 1, 1]  # swap two neighbouring nodes along x
    g = TrilinearGrid(nodes)
    assert g.folds()
    assert not g0.folds()
    # points of the cells around the swapped nodes
    rng = np.random.default_rng(19)
    u = rng.uniform(0.2, 0.55, (2000, 3))
    back, conv, folded = g.inverse(g(u), return_info=True)
    assert folded.any()
    # wherever a solution is reported, it is a preimage
    np.testing.assert_allclose(g(back[conv]), g(u)[conv], atol=1e-9)
    # far from the fold nothing is flagged
    far = rng.uniform(0.8, 1.0, (200, 3))
    back, conv, folded = g.inverse(g(far), return_info=True)
    assert conv.all()
    assert not folded.any()
    np.testing.assert_allclose(back, far, atol=1e-9)


def test_flat_grid_has_no_inverse() -> None:
    nodes = TrilinearGrid.identity(3).nodes.copy()
    nodes[..., 2] = 0.0
    nodes[1, 1, :, 1] += 0.1  # not linear either
    with pytest.raises(WarpError, match="flat"):
        TrilinearGrid(nodes).inverse([[0.5, 0.5, 0.0]])
    with pytest.raises(WarpError, match="flat"):
        TrilinearGrid.from_matrix(np.diag([1.0, 1.0, 0.0, 1.0])).inverse([[0.5, 0.5, 0.0]])


def test_texture_data_layout() -> None:
    g = mild_grid(np.random.default_rng(20), cells=2)
    g = TrilinearGrid(g.nodes[:, :2, :])  # (3, 2, 3) nodes: shapes differ per axis
    tex = g.texture_data()
    assert tex.dtype == np.float32
    assert tex.shape == (3, 2, 3, 4)
    assert tex.flags.c_contiguous
    np.testing.assert_array_equal(tex[..., 3], 1.0)
    for i, j, k in [(0, 0, 0), (2, 1, 0), (1, 0, 2), (2, 1, 2)]:
        np.testing.assert_allclose(tex[k, j, i, :3], g.nodes[i, j, k], rtol=1e-6)
    # x fastest: consecutive texels in memory step along x
    flat = tex.reshape(-1, 4)
    np.testing.assert_allclose(flat[1, :3], g.nodes[1, 0, 0], rtol=1e-6)
    np.testing.assert_allclose(flat[3, :3], g.nodes[0, 1, 0], rtol=1e-6)


def test_grid_dict_round_trip_and_box() -> None:
    g = mild_grid(np.random.default_rng(21), cells=3)
    g2 = TrilinearGrid.from_dict(json.loads(json.dumps(g.to_dict())))
    np.testing.assert_array_equal(g2.nodes, g.nodes)
    assert set(g.to_dict()) == {"nodes"}
    box = TrilinearGrid.identity(2).with_box([1, 2, 3], [3, 3, 7])
    np.testing.assert_allclose(box.nodes, TrilinearGrid.from_box([1, 2, 3], [3, 3, 7], 2).nodes)
    np.testing.assert_allclose(box.matrix()[:3, :3], np.diag([2.0, 1.0, 4.0]), atol=1e-12)
    with pytest.raises(WarpError, match="nodes"):
        TrilinearGrid.from_dict({"corners": []})


@pytest.mark.parametrize(
    ("nodes", "fragment"),
    [
        (np.zeros((2, 2, 1, 3)), "at least 2 nodes"),
        (np.zeros((2, 2, 2, 2)), r"\(nx\+1, ny\+1, nz\+1, 3\)"),
        (np.zeros((8, 3)), r"\(nx\+1, ny\+1, nz\+1, 3\)"),
        (np.full((2, 2, 2, 3), np.nan), "NaN"),
    ],
)
def test_bad_grid_nodes(nodes: np.ndarray, fragment: str) -> None:
    with pytest.raises(WarpError, match=fragment):
        TrilinearGrid(nodes)


def test_bad_grid_arguments() -> None:
    g = mild_grid(np.random.default_rng(22), cells=2)
    with pytest.raises(WarpError, match="NaN"):
        g.inverse([[np.nan, 0, 0]])
    with pytest.raises(WarpError, match="NaN"):
        g([[np.nan, 0, 0]])
    with pytest.raises(WarpError, match="cells"):
        TrilinearGrid.identity(0)
    with pytest.raises(WarpError, match="4x4"):
        g.compose(np.eye(3))
    with pytest.raises(WarpError, match=r"\(N, 3\)"):
        TrilinearGrid.from_function(lambda u: u[:, :2], 2)


def test_vectorised_maps_equal_point_by_point_maps() -> None:
    """The vectorised forward maps and inverse give, for a batch, what they give for
    each point alone (their speed is measured by ``benchmarks.lattice.bench_cpu_grid``,
    see docs/benchmarks.md, not asserted here)."""
    rng = np.random.default_rng(23)
    g = mild_grid(rng, cells=8)
    t = TrilinearTransform(mild_corners(rng))
    u = rng.uniform(0, 1, (100, 3))
    x = g(u)
    single = np.array([g(p[None])[0] for p in u])
    np.testing.assert_allclose(x, single, rtol=0, atol=1e-12)
    np.testing.assert_allclose(t(u), np.array([t(p[None])[0] for p in u]), rtol=0, atol=1e-12)
    back = g.inverse(x)
    np.testing.assert_allclose(back, u, atol=1e-8)
    np.testing.assert_allclose(back, np.array([g.inverse(p[None])[0] for p in x]), atol=1e-10)


def test_serial_and_threaded_grid_kernels_agree_bit_for_bit() -> None:
    from voxwarp.deform.lattice import kernel as k

    rng = np.random.default_rng(7)
    nodes = rng.normal(size=(4, 3, 5, 3))
    t = rng.uniform(-0.2, 1.2, (k.PARALLEL_MIN_POINTS + 3, 3))  # border cells extrapolate
    threaded, serial, picked = (np.empty_like(t) for _ in range(3))
    k.eval_grid_kernel(nodes, t, threaded)
    k.eval_grid_serial(nodes, t, serial)
    assert np.array_equal(threaded, serial)
    for n in (1, 125, k.PARALLEL_MIN_POINTS + 3):
        k.eval_grid(nodes, t[:n], picked[:n])
        assert np.array_equal(picked[:n], serial[:n])
