"""Trusted paths: a detached NRRD data file is read only beside its header (or in a
folder the caller allows), and the files a scene JSON names resolve against the scene's
folder, with a warning for one outside it (issue 17, finding 6)."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

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


def _load_recording(path: Path) -> tuple[Scene, list[str]]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = Scene.load(path)
    return scene, [str(w.message) for w in caught if "outside the scene's folder" in str(w.message)]


def test_scene_volume_beside_the_scene_loads_silently(tmp_path: Path) -> None:
    from voxwarp.core.volume import Volume

    save_volume(Volume(DATA), tmp_path / "scn/sub/v.nrrd")
    scene, outside = _load_recording(_write_scene(tmp_path / "scn/s.json", {"path": "sub/v.nrrd"}))
    np.testing.assert_array_equal(scene.volume.data, DATA)
    assert outside == []


def test_scene_volume_climbing_out_of_the_folder_loads_with_one_warning(
    tmp_path: Path,
) -> None:
    from voxwarp.core.volume import Volume

    target = save_volume(Volume(DATA), tmp_path / "shared/v.nrrd")
    named = "../shared/v.nrrd"
    scene, outside = _load_recording(_write_scene(tmp_path / "scn/s.json", {"path": named}))
    np.testing.assert_array_equal(scene.volume.data, DATA)
    assert len(outside) == 1
    assert named in outside[0]
    assert str(target) in outside[0]
    assert "\n" not in outside[0]


def test_scene_volume_named_by_an_absolute_path_loads_without_a_warning(
    tmp_path: Path,
) -> None:
    """An absolute path names its file outright (what voxwarp writes for a volume outside
    the scene's folder): no warning, whatever folder the scene is in."""
    from voxwarp.core.volume import Volume

    target = save_volume(Volume(DATA), tmp_path / "shared/v.nrrd")
    scene, outside = _load_recording(
        _write_scene(tmp_path / "scn/s.json", {"path": str(target.resolve())})
    )
    np.testing.assert_array_equal(scene.volume.data, DATA)
    assert outside == []


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


def test_scene_mesh_paths_resolve_against_the_scene_and_warn_outside(tmp_path: Path) -> None:
    from voxwarp.core.mesh import box_mesh

    box_mesh().save(tmp_path / "scn/box.obj")
    box_mesh().save(tmp_path / "elsewhere/box.obj")
    vol = {"sample": "tubes", "shape": [8, 8, 8]}
    for named, warned in (("box.obj", 0), ("../elsewhere/box.obj", 1)):
        meshes = [{"mesh": {"path": named}}]
        path = _write_scene(tmp_path / "scn/s.json", vol, meshes=meshes)
        scene, outside = _load_recording(path)
        assert scene.meshes[0].mesh.n_faces == 12
        assert len(outside) == warned
    path = _write_scene(tmp_path / "scn/s.json", vol, meshes=[{"mesh": {"path": "gone.obj"}}])
    with pytest.raises(SceneError, match=str(tmp_path / "scn/gone.obj")):
        Scene.load(path)
