"""EditSession's imported warps (File -> Add Displacement Field in the GUI, Qt-free):
chain order, removal, undo through snapshots, scene JSON by path, and the field slice
view's ``"field |u|"`` sampled at world points of a rotated field grid."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from voxwarp.core.volume import Volume
from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.deform.warp import AffineWarp, rotation_matrix
from voxwarp.editing.families.lattice import LatticeFamily
from voxwarp.editing.session import EditorError, EditSession, Placement
from voxwarp.io.fields import load_transform, save_displacement_field
from voxwarp.render import field_views
from voxwarp.scene import Scene


def make_session() -> EditSession:
    data = np.arange(16 * 12 * 10, dtype=np.float32).reshape(16, 12, 10)
    return EditSession(Scene(Volume(data, spacing=(1.0, 1.5, 2.0))))


def smooth_field(
    affine: np.ndarray | None = None, path: str | None = None
) -> DisplacementFieldWarp:
    """u = (0.1 x, 0, 0.05 z) mm on an 9 x 8 x 7 grid (affine: index -> world)."""
    a = np.diag([2.0, 2.0, 3.0, 1.0]) if affine is None else affine
    idx = np.stack(np.meshgrid(*(np.arange(n) for n in (9, 8, 7)), indexing="ij"), -1)
    world = idx @ a[:3, :3].T + a[:3, 3]
    u = np.zeros_like(world)
    u[..., 0] = 0.1 * world[..., 0]
    u[..., 2] = 0.05 * world[..., 2]
    return DisplacementFieldWarp(u, a, path=path)


def test_imported_warps_go_after_the_model_and_come_out_again() -> None:
    s = make_session()
    s.set_deformation("lattice", resolution=3)
    s.set_placement(Placement(translate=(1.0, 0.0, 0.0)))
    model_chain = list(s.scene.warps)
    volume = s.scene.volume
    before = volume.data.copy()
    f1, f2 = smooth_field(), smooth_field()
    assert s.add_warps_front([f1]) == 1
    # the model corrects the displayed space: it comes before the registration field
    assert s.scene.warps[-1] is f1
    assert [w.kind for w in s.scene.warps[:3]] == [w.kind for w in model_chain]
    assert s.scene.warps[1] is model_chain[1]
    assert s.add_warps_front([f2]) == 2  # a newer file goes in front of older ones
    assert s.scene.warps[3:] == [f2, f1]
    assert s.scene.warps[1] is model_chain[1]
    assert len(s.scene.warps) == 5
    assert s.model_warp() is model_chain[1]
    # editing the model keeps the imported warps last
    s.set_deformation("lattice", resolution=4)
    assert s.scene.warps[3:] == [f2, f1]
    assert len(s.scene.warps) == 5
    assert s.remove_imported_warps() == 2
    assert s.imported_warps == []
    assert len(s.scene.warps) == 3
    assert s.take_released_warps()[-2:] == [f2, f1]  # their textures get released
    assert s.scene.volume is volume
    assert np.array_equal(volume.data, before)


def test_add_warps_front_refuses_no_warps() -> None:
    s = make_session()
    with pytest.raises(EditorError, match="non-empty list of warps"):
        s.add_warps_front([])
    with pytest.raises(EditorError, match="non-empty list of warps"):
        s.add_warps_front([np.eye(4)])  # type: ignore[list-item]
    assert s.scene.warps == []


def test_snapshots_undo_adding_and_removing() -> None:
    s = make_session()
    empty = s.snapshot()
    f = smooth_field()
    s.add_warps_front([f])
    added = s.snapshot()
    assert not added.same_as(empty)
    s.restore(empty)
    assert s.scene.warps == []
    assert s.imported_warps == []
    s.restore(added)
    assert s.scene.warps == [f]


def test_scene_json_keeps_the_field_by_path_and_resumes(tmp_path: Path) -> None:
    field_path = save_displacement_field(smooth_field(), tmp_path / "u.nii.gz")
    s = make_session()
    s.set_deformation("lattice", resolution=3)
    nodes = s.adapter(LatticeFamily).lattice_nodes.copy()
    nodes[1, 1, 1] += (1.0, 0.5, 0.0)
    s.adapter(LatticeFamily).set_lattice_nodes(nodes)
    s.add_warps_front(load_transform(field_path))
    scene_path = s.save(tmp_path / "scene.json")
    raw = json.loads(scene_path.read_text())
    assert raw["warps"][-1] == {"type": "displacement_field", "path": "u.nii.gz"}
    assert raw["editor"]["imported_warps"] == 1
    assert raw["editor"]["imported_at"] == "end"
    assert raw["editor"]["model_warp"] == 0
    again = EditSession.load(scene_path)
    assert again.kind == "lattice"
    assert len(again.imported_warps) == 1
    assert isinstance(again.scene.warps[-1], DisplacementFieldWarp)
    assert np.allclose(again.adapter(LatticeFamily).lattice_nodes, nodes)
    p = np.array([[3.0, 4.0, 5.0]])
    assert np.allclose(again.scene.warps[-1].apply(p), [[3.3, 4.0, 5.25]], atol=1e-4)


def test_an_older_scene_with_the_field_first_resumes_with_it_last(tmp_path: Path) -> None:
    field_path = save_displacement_field(smooth_field(), tmp_path / "u.nii.gz")
    s = make_session()
    s.set_deformation("lattice", resolution=3)
    lattice = s.model_warp()
    field = load_transform(field_path)[0]
    old = Scene(s.volume, warps=[field, lattice])  # the layout before "imported_at"
    raw = old.to_dict(base_dir=tmp_path)
    raw["editor"] = {"imported_warps": 1, "deformation": "lattice", "model_warp": 1}
    (tmp_path / "old.json").write_text(json.dumps(raw))
    again = EditSession.load(tmp_path / "old.json")
    assert again.kind == "lattice"
    assert [w.kind for w in again.scene.warps] == [lattice.kind, field.kind]


def test_a_scene_of_only_a_field_opens_with_it_imported(tmp_path: Path) -> None:
    field_path = save_displacement_field(smooth_field(), tmp_path / "u.nrrd")
    scene = Scene(make_session().volume, warps=load_transform(field_path))
    scene_path = scene.save(tmp_path / "plain.json")
    s = EditSession.load(scene_path)
    assert s.kind == "none"
    assert len(s.imported_warps) == 1
    assert s.field_view_warps()[0][0] == "u.nrrd"


def test_field_view_shows_u_at_world_points_of_a_rotated_grid() -> None:
    a = np.eye(4)
    a[:3, :3] = rotation_matrix((0.0, 0.0, 1.0), 30.0) @ np.diag([2.0, 2.0, 3.0])
    a[:3, 3] = (-4.0, -2.0, -1.0)
    f = smooth_field(a)
    s = make_session()
    s.add_warps_front([f, AffineWarp(np.eye(4))])
    labels = [label for label, _ in s.field_view_warps()]
    assert labels == ["imported displacement_field 1", "imported affine 2"]
    assert field_views.views_for(f) == ("field |u|", "displacement")
    fs = field_views.field_slice(f, s.volume, "field |u|", 2, 0.5, 64)
    top = float(fs.legend.split(" .. ")[1].split(" mm")[0])
    # the oracle: u sampled at the image's pixel centres, scaled to the slice maximum
    h, w = fs.image.shape[:2]
    left, right, bottom, upper = fs.extent
    lo, hi = s.volume.bounds
    zc = lo[2] + 0.5 * (hi[2] - lo[2])
    xs = left + (np.arange(w) + 0.5) * (right - left) / w
    ys = upper - (np.arange(h) + 0.5) * (upper - bottom) / h
    pts = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    pts = np.column_stack([pts, np.full(len(pts), zc)])
    mag = np.linalg.norm(f.displacement_at(pts), axis=1).reshape(h, w)
    assert top == pytest.approx(mag.max(), rel=1e-2)
    expect = field_views.colormap(mag / mag.max()).astype(int)
    assert np.abs(fs.image.astype(int) - expect).max() <= 1
    assert "whole field max" in fs.legend
    assert (fs.image == field_views.VIRIDIS[0].astype(np.uint8)).all(axis=-1).any()  # 0 outside


def test_a_render_scene_with_a_correction_before_the_field_resumes(tmp_path: Path) -> None:
    """``render --displacement F --lattice L --save-scene`` writes [correction, field]
    without an editor entry: the field is imported, the correction editable."""
    field_path = save_displacement_field(smooth_field(), tmp_path / "u.nii.gz")
    s = make_session()
    s.set_deformation("lattice", resolution=3)
    lattice = s.model_warp()
    field = load_transform(field_path)[0]
    Scene(s.volume, warps=[lattice, field]).save(tmp_path / "render.json")
    again = EditSession.load(tmp_path / "render.json")
    assert again.kind == "lattice"
    assert len(again.imported_warps) == 1
    assert [w.kind for w in again.scene.warps] == [lattice.kind, field.kind]
