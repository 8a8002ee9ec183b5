"""Tests of voxwarp.deform.lattice.scene_graph: matrices and trilinear lattices in a hierarchy, one
map per
leaf.

Oracles: the matrix product of a linear chain; the chain applied step by step (each grid
evaluated by an independent trilinear interpolator written here, on the box-normalised
coordinates); identity lattices (x -> x); central differences of the composed map (exact
for a trilinear cell along one axis); the paper's corner order for a single cell.
"""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip(
    "voxwarp.deform.lattice.trilinear",
    reason="deform/lattice/trilinear.py (TrilinearGrid) is not available yet",
)

from voxwarp.deform.lattice.scene_graph import (
    ComposedTransform,
    SceneNode,
    compose_path,
    compose_scene,
)
from voxwarp.deform.lattice.trilinear import TrilinearGrid, TrilinearTransform
from voxwarp.deform.warp import WarpError

RNG = np.random.default_rng(20100517)


# --------------------------------------------------------------------------- helpers
def affine(angle_z: float = 0.0, scale: float = 1.0, t=(0.0, 0.0, 0.0), angle_x: float = 0.0):
    """4x4: translate @ rot_z @ rot_x @ uniform scale."""
    cz, sz = np.cos(angle_z), np.sin(angle_z)
    cx, sx = np.cos(angle_x), np.sin(angle_x)
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    m = np.eye(4)
    m[:3, :3] = rz @ rx * scale
    m[:3, 3] = t
    return m


def unit_nodes(cells) -> np.ndarray:
    axes = [np.arange(n + 1) / n for n in cells]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)


def grid_from(f, cells) -> TrilinearGrid:
    """Grid whose node (i, j, k) is f((i/nx, j/ny, k/nz)); built from raw nodes."""
    u = unit_nodes(cells)
    return TrilinearGrid(f(u.reshape(-1, 3)).reshape(u.shape))


def trilinear(nodes: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Independent trilinear interpolation of a node array at unit coords in [0, 1]^3."""
    n = np.array(nodes.shape[:3]) - 1
    s = u * n
    i = np.clip(np.floor(s).astype(int), 0, n - 1)
    f = s - i
    out = np.zeros((u.shape[0], 3))
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                w = (
                    (f[:, 0] if dx else 1 - f[:, 0])
                    * (f[:, 1] if dy else 1 - f[:, 1])
                    * (f[:, 2] if dz else 1 - f[:, 2])
                )
                out += w[:, None] * nodes[i[:, 0] + dx, i[:, 1] + dy, i[:, 2] + dz]
    return out


def step(transform, box, x: np.ndarray) -> np.ndarray:
    """One node's local -> parent map, written independently of the module."""
    if transform is None:
        return x
    if isinstance(transform, TrilinearGrid):
        lo, hi = (np.asarray(b, float) for b in box)
        u = (x - lo) / (hi - lo)
        assert np.all(u > -1e-9), "oracle point outside the lattice"
        assert np.all(u < 1 + 1e-9), "oracle point outside the lattice"
        return trilinear(np.asarray(transform.nodes, float), np.clip(u, 0, 1))
    return x @ transform[:3, :3].T + transform[:3, 3]


def chain(steps, x: np.ndarray) -> np.ndarray:
    """Apply [(transform, box) root first, ..., leaf] to leaf-local points, leaf first."""
    for transform, box in reversed(steps):
        x = step(transform, box, x)
    return x


def in_box(box, n: int) -> np.ndarray:
    lo, hi = (np.asarray(b, float) for b in box)
    return lo + RNG.random((n, 3)) * (hi - lo)


def box_nodes(box, cells) -> np.ndarray:
    lo, hi = (np.asarray(b, float) for b in box)
    return lo + unit_nodes(cells).reshape(-1, 3) * (hi - lo)


P_BOX = ((-10.0, -10.0, -10.0), (10.0, 10.0, 10.0))
C_BOX = ((-6.0, -6.0, -6.0), (6.0, 6.0, 6.0))


def bend(u: np.ndarray) -> np.ndarray:
    """Smooth non-trilinear bend of P_BOX (unit -> the parent's coordinates)."""
    lo, hi = np.array(P_BOX)
    x = lo + u * (hi - lo)
    x[:, 1] += 3.0 * np.sin(np.pi * u[:, 0]) + 1.5 * u[:, 2] ** 2
    x[:, 2] += 2.0 * u[:, 0] * u[:, 1]
    return x


def twist(u: np.ndarray) -> np.ndarray:
    """Twist of C_BOX about z, into the parent's local coordinates (inside P_BOX)."""
    lo, hi = np.array(C_BOX)
    x = lo + u * (hi - lo)
    a = 0.6 * u[:, 2] - 0.3
    c, s = np.cos(a), np.sin(a)
    return np.stack([c * x[:, 0] - s * x[:, 1], s * x[:, 0] + c * x[:, 1], x[:, 2]], axis=1)


def bend_with_linear_child():
    g = grid_from(bend, (4, 4, 4))
    m = affine(angle_z=0.45, scale=0.6, t=(1.0, 0.5, -1.0), angle_x=0.2)
    root = SceneNode("bend", transform=g, box=P_BOX)
    leaf = root.add(SceneNode("part", transform=m, box=C_BOX, geometry="part.obj"))
    return root, leaf, [(g, P_BOX), (m, C_BOX)]


def nested_grids():
    g = grid_from(bend, (4, 4, 4))
    h = grid_from(twist, (3, 3, 2))
    root = SceneNode("bend", transform=g, box=P_BOX)
    leaf = root.add(SceneNode("twisted", transform=h, box=C_BOX, geometry="part.obj"))
    return root, leaf, [(g, P_BOX), (h, C_BOX)]


def rms_error(composed: ComposedTransform, steps, x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((composed(x) - chain(steps, x)) ** 2, axis=1))))


# --------------------------------------------------------------------------- linear chains
def test_linear_chain_is_the_matrix_product():
    m0 = affine(angle_z=0.3, scale=2.0, t=(5.0, -1.0, 0.0))
    m1 = affine(angle_x=-0.7, t=(0.0, 3.0, 1.0))
    m2 = affine(angle_z=1.1, scale=0.5, t=(-2.0, 0.0, 4.0), angle_x=0.4)
    root = SceneNode("root", transform=m0)
    mid = root.add(SceneNode("mid", transform=m1))
    mid.add(SceneNode("empty"))  # no geometry: not a leaf
    leaf = mid.add(SceneNode("leaf", transform=m2, geometry=object()))
    out = compose_scene(root)
    assert [c.node for c in out] == [leaf]
    (c,) = out
    assert c.is_linear
    assert c.grid is None
    assert c.box is None
    assert [n.name for n in c.path] == ["root", "mid", "leaf"]
    np.testing.assert_allclose(c.matrix, m0 @ m1 @ m2, rtol=0, atol=1e-12)
    x = RNG.normal(size=(50, 3)) * 10
    expected = chain([(m0, None), (m1, None), (m2, None)], x)
    np.testing.assert_allclose(c(x), expected, rtol=0, atol=1e-10)
    np.testing.assert_allclose(c.reference(x), expected, rtol=0, atol=1e-10)
    np.testing.assert_allclose(c.jacobian(x)[7], (m0 @ m1 @ m2)[:3, :3], atol=1e-12)
    # a geometry node higher up gets its own (shorter) product; identity nodes are neutral
    mid.geometry = "mid.stl"
    out = compose_scene(root, resolution=16)  # resolution does not turn matrices into grids
    assert [o.node.name for o in out] == ["mid", "leaf"]
    np.testing.assert_allclose(out[0].matrix, m0 @ m1, atol=1e-12)
    assert all(o.grid is None for o in out)


def test_walk_order_depth_add_remove():
    root = SceneNode("r")
    a = root.add(SceneNode("a"))
    b = a.add(SceneNode("b"))
    c = root.add(SceneNode("c"))
    assert [(n.name, d) for n, d in root.walk()] == [("r", 0), ("a", 1), ("b", 2), ("c", 1)]
    assert b.parent is a
    assert b.ancestors() == [a, root]
    assert root.remove(a) is a
    assert a.parent is None
    assert [n.name for n, _ in root.walk()] == ["r", "c"]
    c.add(a)  # after removal it may be added elsewhere
    assert [(n.name, d) for n, d in root.walk()] == [("r", 0), ("c", 1), ("a", 2), ("b", 3)]
    with pytest.raises(WarpError, match="not a child"):
        root.remove(b)


# --------------------------------------------------------------------------- grid + linear child
def test_bend_grid_with_linear_child_is_exact_at_nodes():
    root, leaf, steps = bend_with_linear_child()
    for resolution, cells in [(None, (4, 4, 4)), (6, (6, 6, 6)), ((8, 2, 5), (8, 4, 5))]:
        (c,) = compose_scene(root, resolution=resolution)
        assert c.node is leaf
        assert c.matrix is None
        assert not c.is_linear
        assert tuple(c.grid.shape) == cells
        np.testing.assert_allclose(c.box[0], C_BOX[0])
        xn = box_nodes(C_BOX, cells)
        exact = chain(steps, xn)
        np.testing.assert_allclose(c(xn), exact, rtol=0, atol=1e-9)
        np.testing.assert_allclose(
            np.asarray(c.grid.nodes).reshape(-1, 3), exact, rtol=0, atol=1e-9
        )
        np.testing.assert_allclose(c.reference(xn), exact, rtol=0, atol=1e-9)


def test_bend_grid_with_linear_child_error_shrinks_with_resolution():
    root, _, steps = bend_with_linear_child()
    x = in_box(C_BOX, 3000)
    errors = [rms_error(compose_scene(root, resolution=r)[0], steps, x) for r in (4, 8, 16, 32)]
    assert errors[0] > 1e-3, "the linear child is rotated: the composition is not exact at 4"
    assert all(b < a for a, b in itertools.pairwise(errors)), errors
    assert errors[-1] < errors[0] / 4, errors


# --------------------------------------------------------------------------- nested grids
def test_nested_grids_exact_at_nodes_and_error_shrinks():
    root, _leaf, steps = nested_grids()
    (c,) = compose_scene(root)
    assert tuple(c.grid.shape) == (4, 4, 4)  # the finer of (4, 4, 4) and (3, 3, 2), per axis
    xn = box_nodes(C_BOX, (4, 4, 4))
    np.testing.assert_allclose(c(xn), chain(steps, xn), rtol=0, atol=1e-9)
    x = in_box(C_BOX, 3000)
    errors = [rms_error(compose_scene(root, resolution=r)[0], steps, x) for r in (4, 8, 16, 32)]
    assert errors[0] > 1e-3, errors
    assert all(b < a for a, b in itertools.pairwise(errors)), errors
    assert errors[-1] < errors[0] / 4, errors


def test_matrix_between_grids_and_leaf_without_transform():
    # grid -> matrix -> grid -> (identity) leaf: a 4x4 under a grid is sampled like a grid
    g = grid_from(bend, (4, 4, 4))
    m = affine(angle_z=-0.3, scale=0.7, t=(0.5, 0.0, 0.5))
    h = grid_from(twist, (2, 2, 6))
    leaf_box = ((-4.0, -4.0, -5.0), (4.0, 4.0, 5.0))
    root = SceneNode("g", transform=g, box=P_BOX)
    mid = root.add(SceneNode("m", transform=m))
    inner = mid.add(SceneNode("h", transform=h, box=C_BOX))
    leaf = inner.add(SceneNode("leaf", box=leaf_box, geometry=Path("leaf.vtk")))
    (c,) = compose_scene(root)
    assert c.node is leaf
    assert tuple(c.grid.shape) == (4, 4, 6)
    steps = [(g, P_BOX), (m, None), (h, C_BOX), (None, leaf_box)]
    xn = box_nodes(leaf_box, (4, 4, 6))
    np.testing.assert_allclose(c(xn), chain(steps, xn), rtol=0, atol=1e-9)
    # compose_path on the same path gives the same
    c2 = compose_path([root, mid, inner, leaf])
    np.testing.assert_array_equal(np.asarray(c2.grid.nodes), np.asarray(c.grid.nodes))


# --------------------------------------------------------------------------- depth
def test_chain_of_identity_grids_composes_to_the_identity():
    boxes = [
        ((-(2.0**k), -(2.0**k), -3.0 * 2**k), (2.0**k, 1.5 * 2**k, 2.0**k)) for k in (5, 4, 3, 2, 1)
    ]
    cells = [(2, 1, 1), (1, 3, 1), (4, 1, 2), (1, 1, 1), (3, 2, 5)]
    nodes = []
    for box, n in zip(boxes, cells, strict=True):
        lo, hi = (np.asarray(b) for b in box)
        ident = grid_from(lambda u, lo=lo, hi=hi: lo + u * (hi - lo), n)
        nodes.append(SceneNode(f"n{len(nodes)}", transform=ident, box=box))
    for parent, child in itertools.pairwise(nodes):
        parent.add(child)
    nodes[-1].geometry = "leaf"
    (c,) = compose_scene(nodes[0])
    assert len(c.path) == 5
    assert tuple(c.grid.shape) == (4, 3, 5)  # the finest per axis met on the path
    np.testing.assert_allclose(
        np.asarray(c.grid.nodes).reshape(-1, 3), box_nodes(boxes[-1], (4, 3, 5)), rtol=0, atol=1e-12
    )
    x = in_box(boxes[-1], 500)
    np.testing.assert_allclose(c(x), x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        c.jacobian(x), np.broadcast_to(np.eye(3), (500, 3, 3)), rtol=0, atol=1e-12
    )
    # the leaf's one grid gives the same as composing only the leaf itself: depth is free
    alone = SceneNode("alone", transform=nodes[-1].transform, box=boxes[-1], geometry="x")
    (c1,) = compose_scene(alone, resolution=(4, 3, 5))
    np.testing.assert_allclose(
        np.asarray(c.grid.nodes), np.asarray(c1.grid.nodes), rtol=0, atol=1e-12
    )


# --------------------------------------------------------------------------- jacobians
@pytest.mark.parametrize("build", [bend_with_linear_child, nested_grids])
def test_composed_jacobian_matches_finite_differences(build):
    root, _, _ = build()
    (c,) = compose_scene(root, resolution=5)
    lo, hi = (np.asarray(b) for b in C_BOX)
    # points inside cells (trilinear is linear along each axis there: differences are exact)
    cell = RNG.integers(0, 5, size=(40, 3))
    u = (cell + 0.15 + 0.7 * RNG.random((40, 3))) / 5
    x = lo + u * (hi - lo)
    h = 1e-4
    fd = np.empty((40, 3, 3))
    for a in range(3):
        e = np.zeros(3)
        e[a] = h
        fd[:, :, a] = (c(x + e) - c(x - e)) / (2 * h)
    jac = c.jacobian(x)
    assert jac.shape == (40, 3, 3)
    np.testing.assert_allclose(jac, fd, rtol=1e-7, atol=1e-9)
    # the node's own local jacobian, likewise
    leaf = c.node
    fd_local = np.empty((40, 3, 3))
    for a in range(3):
        e = np.zeros(3)
        e[a] = h
        fd_local[:, :, a] = (leaf.apply(x + e) - leaf.apply(x - e)) / (2 * h)
    np.testing.assert_allclose(leaf.local_jacobian(x), fd_local, rtol=1e-6, atol=1e-8)


def test_single_trilinear_cell_uses_the_paper_corner_order():
    corners = np.array([[0, 0, 0], [2, 0, 0], [0, 1, 0], [2, 1.5, 0]] * 2, float)
    corners[4:, 2] = 3.0
    corners[7] += (0.5, 0.5, 0.5)
    t = TrilinearTransform(corners)
    box = ((1.0, 1.0, 1.0), (3.0, 5.0, 2.0))
    node = SceneNode("cell", transform=t, box=box)
    assert isinstance(node.transform, TrilinearGrid)
    assert tuple(node.transform.shape) == (1, 1, 1)
    lo, hi = (np.asarray(b) for b in box)
    # corner k of the box (index x + 2 y + 4 z) maps to corners[k]
    for k in range(8):
        bits = np.array([k & 1, (k >> 1) & 1, (k >> 2) & 1], float)
        np.testing.assert_allclose(node.apply((lo + bits * (hi - lo))[None]), corners[k][None])
    u = RNG.random((20, 3))
    np.testing.assert_allclose(node.apply(lo + u * (hi - lo)), t(u), atol=1e-12)


# --------------------------------------------------------------------------- errors
def test_grid_without_box_is_refused():
    g = grid_from(bend, (2, 2, 2))
    with pytest.raises(WarpError, match=r"no box.*box=\(lo, hi\)"):
        SceneNode("g", transform=g)
    node = SceneNode("g")
    with pytest.raises(WarpError, match="no box"):
        node.transform = g
    node = SceneNode("g", transform=g, box=P_BOX)
    with pytest.raises(WarpError, match="no box"):
        node.box = None
    # a geometry leaf under a grid needs a box to build its lattice over
    root = SceneNode("g", transform=g, box=P_BOX)
    root.add(SceneNode("leaf", geometry="x"))
    with pytest.raises(
        WarpError, match=r"'leaf' has geometry under the grid of node 'g' but no box"
    ):
        compose_scene(root)


@pytest.mark.parametrize(
    ("box", "fragment"),
    [
        (((0, 0, 0), (1, 0, 1)), "lo >= hi on axis y"),
        (((0, 2, 0), (1, 1, -1)), "lo >= hi on axis y, z"),
        (((0, 0), (1, 1)), "3 coordinates"),
        (((0, 0, 0), (1, 1, 1), (2, 2, 2)), "3 coordinates"),
        ("box", "3 coordinates"),
        (((0, 0, 0), (1, np.inf, 1)), "non-finite"),
    ],
)
def test_bad_box_is_refused(box, fragment):
    with pytest.raises(WarpError, match=fragment):
        SceneNode("b", box=box)


def test_bad_matrix_and_resolution_are_refused():
    m = np.eye(4)
    m[3, 0] = 0.5
    with pytest.raises(WarpError, match="not affine"):
        SceneNode("p", transform=m)
    with pytest.raises(WarpError, match="4x4"):
        SceneNode("p", transform=np.eye(3))
    root, _, _ = bend_with_linear_child()
    for bad in (0, (4, 4), 2.5, "8", True):
        with pytest.raises(WarpError, match="resolution must be"):
            compose_scene(root, resolution=bad)


def test_cycles_and_second_parents_are_refused():
    root = SceneNode("root")
    a = root.add(SceneNode("a"))
    b = a.add(SceneNode("b"))
    with pytest.raises(WarpError, match="cycle"):
        a.add(a)
    with pytest.raises(WarpError, match="cycle"):
        b.add(root)
    other = SceneNode("other")
    with pytest.raises(WarpError, match="'b' is already a child of 'a'"):
        other.add(b)
    with pytest.raises(WarpError, match="takes a SceneNode"):
        root.add("not a node")
    # a cycle made behind add()'s back is found by walk / compose_scene / to_dict
    b.geometry = "b"
    b.children.append(root)
    with pytest.raises(WarpError, match="reached twice"):
        compose_scene(root)
    with pytest.raises(WarpError, match="reached twice"):
        root.to_dict()
    b.children.clear()
    # ... and so is a node shared by two parents
    shared = SceneNode("shared", geometry="s")
    root.add(shared)
    b.children.append(shared)
    with pytest.raises(WarpError, match="'shared' is reached twice"):
        list(root.walk())


def test_content_outside_a_grid_box_is_refused_unless_not_strict():
    root, leaf, _ = bend_with_linear_child()
    leaf.transform = affine(t=(8.0, 0.0, 0.0))  # C_BOX shifted by 8 sticks out of P_BOX
    with pytest.raises(WarpError, match="outside the box of grid node 'bend'; enlarge"):
        compose_scene(root)
    (c,) = compose_scene(root, strict=False)
    assert np.all(np.isfinite(np.asarray(c.grid.nodes)))


# --------------------------------------------------------------------------- serialisation
def test_to_dict_from_dict_round_trip_gives_the_same_composed_transforms():
    g = grid_from(bend, (4, 4, 4))
    h = grid_from(twist, (3, 3, 2))
    m = affine(angle_z=0.45, scale=0.6, t=(1.0, 0.5, -1.0))
    root = SceneNode("world", transform=affine(t=(100.0, 0.0, 0.0), scale=2.0))
    bent = root.add(SceneNode("bent", transform=g, box=P_BOX))
    bent.add(SceneNode("twisted", transform=h, box=C_BOX, geometry="meshes/a.obj"))
    bent.add(SceneNode("moved", transform=m, box=C_BOX, geometry=Path("meshes/b.obj")))
    root.add(SceneNode("plain", transform=m, geometry="c.nrrd"))
    root.add(SceneNode("opaque", geometry=np.zeros(3)))  # content that is not a reference
    d = root.to_dict()
    text = json.dumps(d)
    assert "geometry" not in d["children"][2]
    assert d["children"][1]["transform"] == {"matrix": m.tolist()}
    assert set(d["children"][0]["transform"]) == {"grid"}
    back = SceneNode.from_dict(json.loads(text))
    assert [(n.name, k) for n, k in back.walk()] == [(n.name, k) for n, k in root.walk()]
    assert back.children[0].children[1].geometry == "meshes/b.obj"
    assert back.children[2].geometry is None  # opaque content is not saved
    before = compose_scene(root, resolution=6)
    after = compose_scene(back, resolution=6)
    assert [c.node.name for c in before] == ["twisted", "moved", "plain", "opaque"]
    assert [c.node.name for c in after] == ["twisted", "moved", "plain"]
    for b, a in zip(before[:3], after, strict=True):
        assert (b.matrix is None) == (a.matrix is None)
        if b.matrix is not None:
            np.testing.assert_array_equal(a.matrix, b.matrix)
        else:
            np.testing.assert_allclose(
                np.asarray(a.grid.nodes), np.asarray(b.grid.nodes), rtol=0, atol=1e-12
            )
            np.testing.assert_array_equal(a.box[0], b.box[0])
            np.testing.assert_array_equal(a.box[1], b.box[1])
    assert json.loads(json.dumps(back.to_dict())) == json.loads(text)  # a fixed point


def test_from_dict_refuses_malformed_entries():
    with pytest.raises(WarpError, match="must be null"):
        SceneNode.from_dict({"name": "x", "transform": {"matrix": np.eye(4).tolist(), "grid": {}}})
    with pytest.raises(WarpError, match="unknown keys"):
        SceneNode.from_dict({"name": "x", "transfrom": None})
    with pytest.raises(WarpError, match="lo >= hi"):
        SceneNode.from_dict({"name": "x", "box": [[0, 0, 0], [0, 1, 1]]})
    with pytest.raises(WarpError, match="must be an object"):
        SceneNode.from_dict([1, 2])
