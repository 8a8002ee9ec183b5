"""Tests of voxwarp.core.mesh: loading (OBJ, STL, PLY, GLB), bad meshes, generators, instances,
serialisation, scene-graph instances, and meshes in Scene (pure CPU)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trimesh

from voxwarp.core.mesh import (
    GENERATORS,
    MESH_EMBED_LIMIT_BYTES,
    Mesh,
    MeshInstance,
    MeshWarning,
    box_mesh,
    cylinder_mesh,
    default_box,
    height_tile,
    instances_from_scene_graph,
    load_mesh,
    tile_mesh,
    torus_mesh,
    tube_mesh,
    uv_sphere,
    vertex_normals,
)
from voxwarp.core.mesh_warp import mesh_instances_bounds
from voxwarp.core.volume import Volume
from voxwarp.deform.lattice.scene_graph import SceneNode
from voxwarp.deform.lattice.trilinear import TrilinearGrid
from voxwarp.deform.warp import rotation_matrix
from voxwarp.errors import MeshError, SceneError
from voxwarp.scene import Scene

TRIANGLE = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def signed_volume(mesh: Mesh) -> float:
    v = mesh.vertices.astype(np.float64)
    f = mesh.faces.astype(np.int64)
    return float(np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() / 6)


def tiny_volume() -> Volume:
    return Volume(np.zeros((2, 2, 2), np.uint8), name="empty")


NOTHING = [(0, 0, 0, 0, 0), (255, 0, 0, 0, 0)]  # a transfer function that shows nothing


# ---------------------------------------------------------------------- loading
@pytest.mark.parametrize("ext", ["obj", "stl", "ply", "glb"])
def test_load_round_trip(tmp_path: Path, ext: str) -> None:
    source = trimesh.creation.icosphere(subdivisions=2, radius=2.0)
    source.apply_translation([1.0, -2.0, 3.0])
    path = tmp_path / f"ball.{ext}"
    source.export(path)
    mesh = load_mesh(path)
    assert mesh.n_faces == len(source.faces) == 320
    # STL keeps no shared vertices: equal positions are merged back
    assert mesh.n_vertices == len(source.vertices) == 162
    assert mesh.vertices.dtype == np.float32
    assert mesh.faces.dtype == np.uint32
    lo, hi = mesh.bounds
    np.testing.assert_allclose(lo, source.bounds[0], atol=1e-5)
    np.testing.assert_allclose(hi, source.bounds[1], atol=1e-5)
    assert mesh.is_watertight
    assert mesh.name == "ball"
    assert Path(mesh.source or "").name == f"ball.{ext}"
    # outward normals: radial on a sphere
    radial = mesh.vertices - np.array([1.0, -2.0, 3.0], np.float32)
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    assert np.min(np.sum(radial * mesh.normals, axis=1)) > 0.98


def test_load_glb_scene_applies_node_transforms(tmp_path: Path) -> None:
    scene = trimesh.Scene()
    box = trimesh.creation.box(extents=(1, 1, 1))
    scene.add_geometry(
        box, node_name="a", transform=trimesh.transformations.translation_matrix((5, 0, 0))
    )
    scene.add_geometry(
        box, node_name="b", transform=trimesh.transformations.translation_matrix((0, 0, -5))
    )
    path = tmp_path / "two.glb"
    scene.export(path)
    mesh = load_mesh(path)
    assert mesh.n_faces == 24
    np.testing.assert_allclose(mesh.bounds[0], (-0.5, -0.5, -5.5), atol=1e-6)
    np.testing.assert_allclose(mesh.bounds[1], (5.5, 0.5, 0.5), atol=1e-6)


def test_load_from_trimesh_object() -> None:
    mesh = load_mesh(trimesh.creation.box(extents=(2, 3, 4)), name="crate")
    assert (mesh.n_vertices, mesh.n_faces, mesh.name) == (8, 12, "crate")
    assert mesh.source is None
    np.testing.assert_allclose(mesh.bounds[1], (1, 1.5, 2))


@pytest.mark.parametrize(
    ("content", "name", "fragments"),
    [
        ("", "empty.obj", ["empty", "no faces"]),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "points.obj", ["no faces"]),
        ("v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "nan.obj", ["NaN or Inf", "vertex 0"]),
        ("v 0 0 inf\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "inf.obj", ["NaN or Inf"]),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "index.obj", ["out of range"]),
    ],
)
def test_bad_files(tmp_path: Path, content: str, name: str, fragments: list[str]) -> None:
    path = tmp_path / name
    path.write_text(content)
    with pytest.raises(MeshError) as info:
        load_mesh(path)
    for fragment in fragments:
        assert fragment in str(info.value)


def test_bad_index_ply(tmp_path: Path) -> None:
    # a binary-safe format whose loader does not check indices itself
    path = tmp_path / "bad.ply"
    path.write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
        "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n"
    )
    with pytest.raises(MeshError, match="out of range"):
        load_mesh(path)


def test_missing_file_and_unknown_format(tmp_path: Path) -> None:
    with pytest.raises(MeshError, match="no such mesh file"):
        load_mesh(tmp_path / "nothing.obj")
    other = tmp_path / "mesh.xyz3"
    other.write_text("x")
    with pytest.raises(MeshError, match=r"unknown mesh format '\.xyz3'.*\.obj, \.stl"):
        load_mesh(other)
    with pytest.raises(MeshError, match="needs a path or a trimesh"):
        load_mesh(42)


def test_unreadable_file(tmp_path: Path) -> None:
    path = tmp_path / "junk.glb"
    path.write_bytes(b"\x00\x01 definitely not a glb")
    with pytest.raises(MeshError, match="cannot read mesh file"):
        load_mesh(path)


# ---------------------------------------------------------------------- arrays
def test_from_arrays_checks() -> None:
    with pytest.raises(MeshError, match="no faces"):
        Mesh.from_arrays(TRIANGLE, np.zeros((0, 3), int))
    with pytest.raises(MeshError, match=r"\(N, 3\)"):
        Mesh.from_arrays(np.zeros((3, 2)), [[0, 1, 2]])
    with pytest.raises(MeshError, match=r"\(M, 3\)"):
        Mesh.from_arrays(TRIANGLE, [[0, 1, 2, 0]])
    with pytest.raises(MeshError, match="vertex 3 but the mesh has 3 vertices"):
        Mesh.from_arrays(TRIANGLE, [[0, 1, 3]])
    with pytest.raises(MeshError, match="out of range"):
        Mesh.from_arrays(TRIANGLE, [[0, -1, 2]])
    bad = TRIANGLE.copy()
    bad[2, 1] = np.nan
    with pytest.raises(MeshError, match="vertex 2"):
        Mesh.from_arrays(bad, [[0, 1, 2]])
    with pytest.raises(MeshError, match="integer"):
        Mesh.from_arrays(TRIANGLE, [[0.0, 1.5, 2.0]])


def test_degenerate_faces_dropped_with_warning() -> None:
    v = np.vstack([TRIANGLE, [[2.0, 0.0, 0.0]]])
    faces = [[0, 1, 2], [0, 1, 3], [1, 1, 2]]  # collinear, repeated vertex
    with pytest.warns(MeshWarning, match="dropped 2 degenerate"):
        mesh = Mesh.from_arrays(v, faces)
    assert mesh.faces.tolist() == [[0, 1, 2]]
    with pytest.warns(MeshWarning), pytest.raises(MeshError, match="no faces of non-zero area"):
        Mesh.from_arrays(v, [[0, 1, 3]])


def test_arrays_are_read_only_and_normals_unit() -> None:
    mesh = Mesh.from_arrays(TRIANGLE * 3, [[0, 1, 2]])
    with pytest.raises(ValueError, match="read-only"):
        mesh.vertices[0, 0] = 1.0
    np.testing.assert_allclose(mesh.normals, np.tile([0, 0, 1], (3, 1)))
    custom = Mesh.from_arrays(TRIANGLE, [[0, 1, 2]], normals=np.tile([0, 0, 5.0], (3, 1)))
    np.testing.assert_allclose(custom.normals, np.tile([0, 0, 1], (3, 1)))


def test_non_manifold_loads_but_is_not_watertight() -> None:
    # three triangles on one edge: non-manifold; renders anyway
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1.0]])
    mesh = Mesh.from_arrays(v, [[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    assert mesh.n_faces == 3
    assert not mesh.is_watertight


# ---------------------------------------------------------------------- generators
@pytest.mark.parametrize(
    ("mesh", "volume"),
    [
        (box_mesh((0, 0, 0), (1, 2, 3)), 6.0),
        (uv_sphere(2.0, rows=32, cols=64), 4 / 3 * np.pi * 8),
        (cylinder_mesh(1.0, 2.0, sections=96), np.pi * 2),
        (torus_mesh(2.0, 0.5, 96, 48), 2 * np.pi**2 * 2.0 * 0.25),
    ],
    ids=["box", "sphere", "cylinder", "torus"],
)
def test_closed_generators_are_outward_and_watertight(mesh: Mesh, volume: float) -> None:
    assert mesh.is_watertight
    # outward winding: positive signed volume close to the exact solid's
    assert signed_volume(mesh) == pytest.approx(volume, rel=0.02)
    # vertex normals agree with the winding of the faces around them
    fn = mesh.face_normals()
    for k in range(3):
        assert np.min(np.sum(fn * mesh.normals[mesh.faces[:, k]], axis=1)) > 0.3


def _area_weighted_normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """The formula vertex_normals had before trimesh summed it: np.add.at of the faces'
    cross products, normalised."""
    cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    acc = np.zeros_like(v)
    for k in range(3):
        np.add.at(acc, f[:, k], cross)
    return acc / np.linalg.norm(acc, axis=1, keepdims=True)


def test_vertex_normals_are_area_weighted_at_any_scale() -> None:
    rng = np.random.default_rng(3)
    sphere = uv_sphere(rows=12, cols=20)
    noisy = sphere.vertices.astype(np.float64) * rng.uniform(0.8, 1.2, (sphere.n_vertices, 1))
    for v, f in ((noisy, sphere.faces), (height_tile().vertices, height_tile().faces)):
        v = np.asarray(v, np.float64)
        ref = _area_weighted_normals(v, f)
        np.testing.assert_allclose(vertex_normals(v, f), ref, rtol=0, atol=1e-15)
        # trimesh's own vertex normals weight by angle: a different result, not used
        angle = trimesh.Trimesh(v, f, process=False).vertex_normals
        assert np.abs(angle - ref).max() > 1e-3
    # sub-micron faces keep their normal (trimesh's unitize would zero these sums)
    tiny = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [3.0, 3.0, 3.0]]) * 1e-9
    np.testing.assert_allclose(
        vertex_normals(tiny, np.array([[0, 1, 2]])),
        [[0, -1, 0], [0, -1, 0], [0, -1, 0], [0, 0, 1]],  # unused vertex: +z
    )


def test_generators_keep_their_own_triangulation() -> None:
    """Scene JSON stores generated meshes as recipes, so a generator must keep making
    the same mesh: trimesh.creation's box (8 shared vertices, smooth normals), uv_sphere
    (even rows, doubled columns, seam copies), cylinder (caps share the side's vertices)
    and torus (the same vertices, the other quad diagonal) would change the scenes."""
    assert (box_mesh().n_vertices, box_mesh().n_faces) == (24, 12)
    assert (uv_sphere(rows=16, cols=32).n_vertices, uv_sphere(rows=16, cols=32).n_faces) == (
        482,
        960,
    )
    assert (cylinder_mesh().n_vertices, cylinder_mesh().n_faces) == (130, 128)
    torus = torus_mesh(1.0, 0.3, 48, 24)
    assert (torus.n_vertices, torus.n_faces) == (1152, 2304)
    assert torus.faces[0].tolist() == [0, 24, 25]  # quad (i, j) split along a -> c


def test_tile_mesh() -> None:
    tile = tile_mesh(4, 3, size=(2.0, 1.5), center=(1, 1, 1))
    assert (tile.n_vertices, tile.n_faces) == (20, 24)
    assert not tile.is_watertight
    np.testing.assert_allclose(tile.face_normals(), np.tile([0, 0, 1], (24, 1)), atol=1e-7)
    np.testing.assert_allclose(tile.bounds[0], (0, 0.25, 1))
    lo, hi = default_box(tile)  # flat axis widened to ±5 % of the largest extent
    np.testing.assert_allclose(lo, (0, 0.25, 0.9))
    np.testing.assert_allclose(hi, (2, 1.75, 1.1))


def test_generator_argument_errors() -> None:
    with pytest.raises(MeshError, match="exceed"):
        box_mesh((0, 0, 0), (1, 0, 1))
    with pytest.raises(MeshError, match="minor_radius < major_radius"):
        torus_mesh(1.0, 2.0)
    with pytest.raises(MeshError, match="nx, ny >= 1"):
        tile_mesh(0, 2)


# ---------------------------------------------------------------------- instances
def test_instance_validation() -> None:
    mesh = box_mesh()
    with pytest.raises(MeshError, match="needs a Mesh"):
        MeshInstance("box.obj")  # type: ignore[arg-type]
    with pytest.raises(MeshError, match="affine"):
        MeshInstance(mesh, np.ones((4, 4)))
    with pytest.raises(MeshError, match="4x4"):
        MeshInstance(mesh, np.eye(3))
    with pytest.raises(MeshError, match="normal_method must be one of normal, tangent"):
        MeshInstance(mesh, normal_method="vertex")
    with pytest.raises(MeshError, match=r"\[0, 1\]"):
        MeshInstance(mesh, color=(1.5, 0, 0))
    with pytest.raises(MeshError, match="high corner"):
        MeshInstance(mesh, box=((0, 0, 0), (1, -1, 1)))
    assert MeshInstance(mesh, color=(0.1, 0.2, 0.3)).color == (0.1, 0.2, 0.3, 1.0)
    with pytest.raises(MeshError, match="lattice, not a matrix"):
        MeshInstance(mesh, TrilinearGrid.identity()).matrix()


def test_instance_cpu_reference_and_bounds() -> None:
    mesh = box_mesh((0, 0, 0), (2, 1, 1))
    m = np.eye(4)
    m[:3, :3] = rotation_matrix((0, 0, 1), 90)
    m[:3, 3] = (10, 0, 0)
    inst = MeshInstance(mesh, m)
    np.testing.assert_allclose(inst.local_to_world([[2, 0, 0]]), [[10, 2, 0]], atol=1e-12)
    lo, hi = inst.world_bounds()
    np.testing.assert_allclose(lo, (9, 0, 0), atol=1e-12)
    np.testing.assert_allclose(hi, (10, 2, 1), atol=1e-12)
    # a lattice over the box: the identity grid maps the box onto itself
    ident = MeshInstance(mesh, TrilinearGrid.from_box((0, 0, 0), (2, 1, 1), cells=(2, 1, 1)))
    np.testing.assert_allclose(ident.world_vertices(), mesh.vertices, atol=1e-6)
    lo, hi = ident.world_bounds()
    np.testing.assert_allclose(lo, (0, 0, 0), atol=1e-12)
    np.testing.assert_allclose(hi, (2, 1, 1), atol=1e-12)
    both = mesh_instances_bounds([inst, ident])
    assert both is not None
    np.testing.assert_allclose(both[0], (0, 0, 0), atol=1e-12)
    np.testing.assert_allclose(both[1], (10, 2, 1), atol=1e-12)
    assert mesh_instances_bounds([]) is None


@pytest.mark.parametrize("kind", ["generator", "embedded", "path"])
def test_instance_dict_round_trip(tmp_path: Path, kind: str) -> None:
    if kind == "generator":
        mesh = torus_mesh(1.0, 0.25, 16, 8)
    elif kind == "embedded":
        mesh = Mesh.from_arrays(np.random.default_rng(0).random((30, 3)), [[0, 1, 2], [3, 4, 5]])
    else:
        mesh = load_mesh(uv_sphere(rows=6, cols=8).save(tmp_path / "ball.ply"))
    grid = TrilinearGrid.from_function(lambda u: u * [2, 1, 1] + u[:, :1] ** 2, (3, 2, 1))
    inst = MeshInstance(mesh, grid, box=((-1, -1, -1), (1, 1, 1)), color=(0.1, 0.2, 0.3, 0.5),
                        normal_method="tangent", name="thing")  # fmt: skip
    d = json.loads(json.dumps(inst.to_dict(base_dir=tmp_path)))
    assert kind in d["mesh"] or (kind == "generator" and d["mesh"]["generator"] == "torus_mesh")
    if kind == "path":
        assert d["mesh"]["path"] == "ball.ply"  # relative to base_dir
    back = MeshInstance.from_dict(d, base_dir=tmp_path)
    np.testing.assert_allclose(back.mesh.vertices, mesh.vertices, atol=1e-6)
    np.testing.assert_array_equal(back.mesh.faces, mesh.faces)
    np.testing.assert_allclose(back.transform.nodes, grid.nodes)  # type: ignore[union-attr]
    assert (back.color, back.normal_method, back.name) == (inst.color, "tangent", "thing")
    np.testing.assert_allclose(back.box[1], (1, 1, 1))
    matrix = MeshInstance.from_dict(MeshInstance(mesh, np.diag([2.0, 3, 4, 1])).to_dict())
    np.testing.assert_allclose(matrix.matrix(), np.diag([2.0, 3, 4, 1]))


def test_large_meshes_without_file_are_not_embedded() -> None:
    n = MESH_EMBED_LIMIT_BYTES // 12 + 10
    v = np.random.default_rng(1).random((n, 3))
    mesh = Mesh.from_arrays(v, [[0, 1, 2]])
    with pytest.raises(MeshError, match=r"too large to embed.*mesh\.save"):
        mesh.to_dict()


@pytest.mark.parametrize(
    ("entry", "fragment"),
    [
        ({"generator": "pyramid"}, "unknown mesh generator"),
        ({"generator": "uv_sphere", "args": {"rows": "many"}}, "invalid arguments"),
        ({"embedded": {"n_vertices": 3, "n_faces": 1, "vertices": "AAAA", "faces": ""}}, "match"),
        ({"name": "x"}, "needs one of"),
        ({"path": "/nonexistent/mesh.obj"}, "no such mesh file"),
    ],
)
def test_bad_mesh_entries(entry: dict[str, Any], fragment: str) -> None:
    with pytest.raises(MeshError, match=fragment):
        Mesh.from_dict(entry)


def test_every_generator_round_trips() -> None:
    for name, make in GENERATORS.items():
        mesh = make()
        back = Mesh.from_dict(json.loads(json.dumps(mesh.to_dict())))
        np.testing.assert_array_equal(back.vertices, mesh.vertices, err_msg=name)


# ---------------------------------------------------------------------- scene graph
def test_instances_from_scene_graph() -> None:
    ball, tile = uv_sphere(0.5, rows=6, cols=8), tile_mesh(4, 4)
    tile_box = default_box(tile)
    shift = np.eye(4)
    shift[:3, 3] = (3, 0, 0)
    bend = TrilinearGrid.from_function(
        lambda u: np.c_[u[:, 0] * 4, u[:, 1] * 4, u[:, 2] * 4 + np.sin(np.pi * u[:, 0])], (4, 1, 1)
    )
    root = SceneNode("root", shift)
    root.add(SceneNode("ball", geometry=ball))
    hall = root.add(SceneNode("hall", bend, box=((-2, -2, -2), (2, 2, 2))))
    hall.add(SceneNode("tile", geometry=MeshInstance(tile, color=(1, 0, 0)), box=tile_box))
    root.add(SceneNode("note", geometry="not a mesh"))
    insts = instances_from_scene_graph(root)
    assert [i.name for i in insts] == ["ball", "tile"]
    assert not insts[0].is_lattice
    assert insts[1].is_lattice
    np.testing.assert_allclose(insts[0].matrix(), shift)
    assert insts[1].color == (1.0, 0.0, 0.0, 1.0)
    # the instance's CPU map is the exact chain at the lattice nodes (the tile's corners)
    corners = tile.vertices[[0, 4, 20, 24]].astype(np.float64)
    expected = bend((corners + 2.0) / 4.0) + np.array([3.0, 0.0, 0.0])
    np.testing.assert_allclose(insts[1].local_to_world(corners), expected, atol=1e-9)


def test_scene_graph_instance_with_own_transform_is_refused() -> None:
    root = SceneNode("root")
    root.add(
        SceneNode("x", geometry=MeshInstance(box_mesh(), np.eye(4) * 2 + np.diag([0, 0, 0, -1])))
    )
    with pytest.raises(MeshError, match="own transform"):
        instances_from_scene_graph(root)


# ---------------------------------------------------------------------- scenes
def test_scene_meshes_validation_and_json(tmp_path: Path) -> None:
    vol = tiny_volume()
    plain = Scene(vol, transfer_function=NOTHING)
    assert plain.meshes == []
    assert "meshes" not in plain.to_dict()
    with pytest.raises(SceneError, match="MeshInstance"):
        Scene(vol, transfer_function=NOTHING, meshes=[box_mesh()])  # type: ignore[list-item]
    with pytest.raises(SceneError, match="list"):
        Scene(vol, transfer_function=NOTHING, meshes=MeshInstance(box_mesh()))  # type: ignore[arg-type]
    inst = MeshInstance(box_mesh((5, 5, 5), (6, 7, 8)), color=(0, 1, 0))
    scene = Scene(vol, transfer_function=NOTHING, meshes=[inst])
    assert scene.copy().meshes == [inst]
    assert scene.copy(meshes=[]).meshes == []
    path = scene.save(tmp_path / "scene.json")
    back = Scene.load(path)
    assert len(back.meshes) == 1
    np.testing.assert_allclose(back.meshes[0].mesh.bounds[1], (6, 7, 8))
    assert back.meshes[0].color == (0.0, 1.0, 0.0, 1.0)
    d = scene.to_dict()
    d["meshes"] = [{"mesh": {"generator": "nope"}}]
    with pytest.raises(SceneError, match="invalid mesh in scene"):
        Scene.from_dict(d)
    d["meshes"] = "box"
    with pytest.raises(SceneError, match="list"):
        Scene.from_dict(d)


def test_fitted_camera_frames_volume_and_meshes() -> None:
    vol = tiny_volume()
    far = MeshInstance(box_mesh((20, -3, -3), (26, 3, 3)))
    scene = Scene(
        vol, transfer_function=NOTHING, view="+z", projection="orthographic", meshes=[far]
    )
    pix = scene.resolved_camera().project(far.world_vertices(), (100, 100))
    assert pix.min() >= 0
    assert pix.max() <= 100
    assert (
        Scene(vol, transfer_function=NOTHING, view="+z").resolved_camera().ortho_height < 5
    )  # volume only: small


def test_save_is_atomic(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A failed write leaves the previous file intact and no temporary file behind."""
    from voxwarp.core.mesh import torus_mesh

    path = tmp_path / "ring.ply"
    torus_mesh().save(path)
    before = path.read_bytes()

    def broken(self: object, file_obj: object = None, **kwargs: object) -> None:
        Path(str(file_obj)).write_bytes(b"ply\nhalf")  # a write that dies half way
        raise OSError("disk full")

    monkeypatch.setattr(trimesh.Trimesh, "export", broken)
    with pytest.raises(OSError, match="disk full"):
        torus_mesh(major_sections=12).save(path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ring.ply"]


def test_tube_mesh_at_given_rings_and_phase() -> None:
    xs = [0.0, 0.4, 0.41, 1.0]
    m = tube_mesh(1.0, 0.5, sections=8, ring_x=xs, phase=0.25)
    v = m.vertices.reshape(4, 8, 3)
    np.testing.assert_allclose(v[:, 0, 0], xs, atol=1e-6)  # rings where asked
    first = 2 * np.pi * 0.25 / 8  # a quarter section past +y
    np.testing.assert_allclose(v[0, 0, 1:], [0.5 * np.cos(first), 0.5 * np.sin(first)], atol=1e-6)
    np.testing.assert_allclose(np.hypot(v[..., 1], v[..., 2]), 0.5, atol=1e-6)
    # the recipe rebuilds the same mesh; a default tube's recipe has no new keys
    back = Mesh.from_dict(m.to_dict())
    np.testing.assert_array_equal(back.vertices, m.vertices)
    assert set(tube_mesh(1.0).recipe["args"]) == {"length", "radius", "rings", "sections"}
    with pytest.raises(MeshError, match="ring_x must be at least 2 finite, increasing"):
        tube_mesh(1.0, ring_x=[0.0, 0.5, 0.5])
    with pytest.raises(MeshError, match="ring_x must be"):
        Mesh.from_dict({"generator": "tube_mesh", "args": {"ring_x": [[0, 1], [2, 3]]}})
    with pytest.raises(MeshError, match="finite phase"):
        tube_mesh(1.0, phase=float("nan"))
