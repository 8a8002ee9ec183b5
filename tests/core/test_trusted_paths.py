"""Trusted paths: a detached NRRD data file is read only beside its header (or in a
folder the caller allows), and the files a scene JSON names resolve against the scene's
folder, with a warning for one outside it (issue 17, finding 6)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from voxwarp.errors import SceneError, VolumeError
from voxwarp.io.volumes import NRRD_DATA_DIRS_ENV, load_volume, save_volume
from voxwarp.scene import Scene

DATA = np.arange(24, dtype=np.uint8).reshape(2, 3, 4, order="F")


def _detached(header: Path, data_file: str, data_at: Path | None = None) -> Path:
    """A detached NRRD header naming ``data_file``; the voxels written to ``data_at``."""
    if data_at is not None:
        data_at.parent.mkdir(parents=True, exist_ok=True)
        data_at.write_bytes(DATA.tobytes(order="F"))
    header.parent.mkdir(parents=True, exist_ok=True)
    header.write_text(
        "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 3 4\nencoding: raw\n"
        f"data file: {data_file}\n\n"
    )
    return header


@pytest.mark.parametrize("field", ["data file", "datafile"])
def test_data_file_beside_the_header_loads(tmp_path: Path, field: str) -> None:
    h = _detached(tmp_path / "v.nhdr", "v.raw", tmp_path / "v.raw")
    h.write_text(h.read_text().replace("data file", field))
    np.testing.assert_array_equal(load_volume(h).data, DATA)


def test_data_file_in_a_subfolder_loads(tmp_path: Path) -> None:
    h = _detached(tmp_path / "v.nhdr", "sub/deeper/v.raw", tmp_path / "sub/deeper/v.raw")
    np.testing.assert_array_equal(load_volume(h).data, DATA)


def test_absolute_system_file_is_refused(tmp_path: Path) -> None:
    h = _detached(tmp_path / "v.nhdr", "/etc/passwd")
    with pytest.raises(VolumeError) as err:
        load_volume(h)
    msg = str(err.value)
    assert "\n" not in msg
    assert "/etc/passwd" in msg
    assert str(h) in msg
    assert "allow_data_dirs" in msg
    assert "beside the header" in msg


@pytest.mark.parametrize("name", ["../outside/v.raw", "sub/../../outside/v.raw"])
def test_parent_relative_data_file_is_refused(tmp_path: Path, name: str) -> None:
    h = _detached(tmp_path / "scan/v.nhdr", name, tmp_path / "outside/v.raw")
    with pytest.raises(VolumeError, match=r"outside the header's folder") as err:
        load_volume(h)
    assert str(tmp_path / "outside/v.raw") in str(err.value)


def test_symlink_leaving_the_folder_is_refused(tmp_path: Path) -> None:
    (tmp_path / "outside").mkdir()
    (tmp_path / "outside/v.raw").write_bytes(DATA.tobytes(order="F"))
    (tmp_path / "scan").mkdir()
    (tmp_path / "scan/v.raw").symlink_to(tmp_path / "outside/v.raw")
    h = _detached(tmp_path / "scan/v.nhdr", "v.raw")
    with pytest.raises(VolumeError, match="outside the header's folder"):
        load_volume(h)


def test_allowed_folder_loads(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    h = _detached(tmp_path / "scan/v.nhdr", "../shared/v.raw", tmp_path / "shared/v.raw")
    vol = load_volume(h, allow_data_dirs=[tmp_path / "shared"])
    np.testing.assert_array_equal(vol.data, DATA)
    with pytest.raises(VolumeError):  # the permission lasts for that call only
        load_volume(h)
    monkeypatch.setenv(NRRD_DATA_DIRS_ENV, str(tmp_path / "shared"))
    np.testing.assert_array_equal(load_volume(h).data, DATA)


def test_list_and_format_forms_are_checked(tmp_path: Path) -> None:
    h = tmp_path / "v.nhdr"
    h.write_text(
        "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 3 4\nencoding: raw\n"
        "data file: LIST\nv0.raw\n/etc/passwd\n"
    )
    with pytest.raises(VolumeError, match="/etc/passwd"):
        load_volume(h)
    h.write_text(h.read_text().replace("/etc/passwd", "v1.raw"))
    with pytest.raises(VolumeError, match="LIST"):  # inside, but pynrrd cannot read it
        load_volume(h)
    _detached(h, "../up/slice%03d.raw 1 4 1 2")
    with pytest.raises(VolumeError, match="slice%03d"):
        load_volume(h)


def test_attached_nrrd_still_loads(tmp_path: Path) -> None:
    from voxwarp.core.volume import Volume

    path = save_volume(Volume(DATA), tmp_path / "v.nrrd")
    np.testing.assert_array_equal(load_volume(path).data, DATA)


# ---------------------------------------------------------------------------- scene paths
def _write_scene(path: Path, volume: dict, **extra: object) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"format": "voxwarp-scene", "volume": volume, **extra}))
    return path


def _refusal(path: Path, **kw: object) -> str:
    with pytest.raises(SceneError) as err:
        Scene.load(path, **kw)
    msg = str(err.value)
    assert "\n" not in msg
    return msg


def test_scene_volume_beside_the_scene_loads(tmp_path: Path) -> None:
    from voxwarp.core.volume import Volume

    save_volume(Volume(DATA), tmp_path / "scn/sub/v.nrrd")
    scene = Scene.load(_write_scene(tmp_path / "scn/s.json", {"path": "sub/v.nrrd"}))
    np.testing.assert_array_equal(scene.volume.data, DATA)


@pytest.mark.parametrize("form", ["relative", "absolute", "link"])
def test_scene_volume_outside_the_folder_is_refused_unless_allowed(
    tmp_path: Path, form: str
) -> None:
    """``../shared/v.nrrd``, ``/abs/shared/v.nrrd`` or a link inside the folder pointing
    out: one line naming the file and the folder to allow; then loads once allowed."""
    from voxwarp.core.volume import Volume

    target = save_volume(Volume(DATA), tmp_path / "shared/v.nrrd").resolve()
    named = {"relative": "../shared/v.nrrd", "absolute": str(target), "link": "v.nrrd"}[form]
    scene_path = _write_scene(tmp_path / "scn/s.json", {"path": named})
    if form == "link":
        (tmp_path / "scn/v.nrrd").symlink_to(target)
    msg = _refusal(scene_path)
    assert str(target) in msg
    assert f"--allow-dir {target.parent}" in msg
    assert "outside the scene's folder" in msg
    scene = Scene.load(scene_path, allow_dirs=[tmp_path / "shared"])
    np.testing.assert_array_equal(scene.volume.data, DATA)


def test_allowed_folder_from_the_environment(tmp_path: Path, monkeypatch: Any) -> None:
    from voxwarp.core.volume import Volume

    save_volume(Volume(DATA), tmp_path / "shared/v.nrrd")
    scene_path = _write_scene(tmp_path / "scn/s.json", {"path": "../shared/v.nrrd"})
    monkeypatch.setenv(NRRD_DATA_DIRS_ENV, str(tmp_path / "shared"))
    np.testing.assert_array_equal(Scene.load(scene_path).volume.data, DATA)


def test_a_saved_scene_naming_a_file_elsewhere_reopens_by_its_seal(
    tmp_path: Path, monkeypatch: Any
) -> None:
    """Scene.save seals the absolute paths it writes with this user's key: the scene
    reopens; an edited path, or another user's key, trusts nothing (refused)."""
    from voxwarp.core.scene_seal import SEAL_KEY
    from voxwarp.core.volume import Volume

    vol = load_volume(save_volume(Volume(DATA), tmp_path / "shared/v.nrrd"))
    saved = Scene(vol).save(tmp_path / "scn/s.json")
    d = json.loads(saved.read_text())
    assert len(d[SEAL_KEY]) == 64
    np.testing.assert_array_equal(Scene.load(saved).volume.data, DATA)

    other = save_volume(Volume(DATA + 1), tmp_path / "other/w.nrrd").resolve()
    d["volume"]["path"] = str(other)  # edited by hand (or by someone else): seal broken
    saved.write_text(json.dumps(d))
    assert str(other) in _refusal(saved)

    Scene(vol).save(saved)  # resealed ...
    monkeypatch.setenv("VOXWARP_CONFIG_DIR", str(tmp_path / "another-user"))
    twin = tmp_path / "scn2/s.json"  # ... a copy read by another user: not trusted
    twin.parent.mkdir()
    twin.write_text(saved.read_text().replace(str(tmp_path / "shared"), str(tmp_path / "sh2")))
    save_volume(Volume(DATA), tmp_path / "sh2/v.nrrd")
    assert "outside the scene's folder" in _refusal(twin)


def test_scene_missing_volume_is_one_line_naming_the_resolved_path(tmp_path: Path) -> None:
    path = _write_scene(tmp_path / "scn/s.json", {"path": "data/none.nrrd"})
    with pytest.raises(SceneError) as err:
        Scene.load(path)
    msg = str(err.value)
    assert "\n" not in msg
    assert str(tmp_path / "scn/data/none.nrrd") in msg


def test_scene_cannot_reach_system_files_through_an_nrrd_header(tmp_path: Path) -> None:
    """The attack of finding 6: a scene names a header beside it that names /etc/passwd."""
    _detached(tmp_path / "scn/evil.nhdr", "/etc/passwd")
    with pytest.raises(SceneError, match="/etc/passwd") as err:
        Scene.load(_write_scene(tmp_path / "scn/s.json", {"path": "evil.nhdr"}))
    assert "\n" not in str(err.value)


def test_scene_mesh_paths_resolve_against_the_scene_and_refuse_outside(tmp_path: Path) -> None:
    from voxwarp.core.mesh import box_mesh

    box_mesh().save(tmp_path / "scn/box.obj")
    box_mesh().save(tmp_path / "elsewhere/box.obj")
    vol = {"sample": "tubes", "shape": [8, 8, 8]}
    path = _write_scene(tmp_path / "scn/s.json", vol, meshes=[{"mesh": {"path": "box.obj"}}])
    assert Scene.load(path).meshes[0].mesh.n_faces == 12
    meshes = [{"mesh": {"path": "../elsewhere/box.obj"}}]
    path = _write_scene(tmp_path / "scn/s.json", vol, meshes=meshes)
    assert str(tmp_path / "elsewhere/box.obj") in _refusal(path)
    assert Scene.load(path, allow_dirs=[tmp_path / "elsewhere"]).meshes[0].mesh.n_faces == 12
    path = _write_scene(tmp_path / "scn/s.json", vol, meshes=[{"mesh": {"path": "gone.obj"}}])
    with pytest.raises(SceneError, match=str(tmp_path / "scn/gone.obj")):
        Scene.load(path)
