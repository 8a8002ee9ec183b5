"""Scene JSON errors say what is wrong with the JSON: syntax errors with line and column,
a scene without its "format" key, strict JSON types ("1" is not a number), unknown scene
and camera keys; each a one-line SceneError / InputError, exit code 2 on the command
line (issue 17, finding 8)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from voxwarp.cli.main import main
from voxwarp.core.camera import Camera
from voxwarp.errors import InputError, SceneError, VoxwarpError
from voxwarp.inputs import load_input
from voxwarp.scene import SCENE_KEYS, Scene, check_scene_json

VOLUME = {"sample": "tubes", "shape": [8, 8, 8]}


def _scene(tmp_path: Path, text_or_dict: str | dict[str, Any]) -> Path:
    path = tmp_path / "scene.json"
    text = text_or_dict if isinstance(text_or_dict, str) else json.dumps(text_or_dict)
    path.write_text(text)
    return path


def _one_line(exc: BaseException) -> str:
    msg = str(exc)
    assert msg
    assert "\n" not in msg
    return msg


def test_syntax_error_names_line_and_column(tmp_path: Path) -> None:
    path = _scene(
        tmp_path, '{"format": "voxwarp-scene",\n "volume": {"sample": "tubes"},\n "step" 2\n}'
    )
    with pytest.raises(SceneError) as err:
        Scene.load(path)
    msg = _one_line(err.value)
    assert "not valid JSON" in msg
    assert "line 3, column 9" in msg
    with pytest.raises(InputError) as err2:  # INPUT on the command line, not a raw sidecar
        load_input(str(path))
    msg = _one_line(err2.value)
    assert "line 3, column 9" in msg
    assert "sidecar" not in msg


def test_scene_without_format_is_reported_as_such(tmp_path: Path) -> None:
    path = _scene(tmp_path, {"volume": VOLUME, "mode": "mip"})
    with pytest.raises(InputError) as err:
        load_input(str(path))
    msg = _one_line(err.value)
    assert "looks like a scene" in msg
    assert '"format": "voxwarp-scene"' in msg


def test_raw_sidecar_json_still_opens_as_a_volume(tmp_path: Path) -> None:
    data = np.arange(24, dtype=np.uint8).reshape(2, 3, 4, order="F")
    (tmp_path / "v.raw").write_bytes(data.tobytes(order="F"))
    (tmp_path / "v.json").write_text(json.dumps({"dims": [2, 3, 4], "dtype": "uint8"}))
    vol = load_input(str(tmp_path / "v.json"), keep_padding=True)
    np.testing.assert_array_equal(vol.data, data)


@pytest.mark.parametrize(
    ("key", "value", "expected"),
    [
        ("step", "1", "must be a number"),
        ("step", True, "must be a number"),
        ("zoom", "2", "must be a number"),
        ("fov", None, "must be a number"),
        ("seed", 1.5, "must be an integer"),
        ("seed", "0", "must be an integer"),
        ("jitter", 1, "must be true or false"),
        ("shading", "yes", "true, false or null"),
        ("iso_value", "100", "or null"),
        ("flm_threshold", [1], "or null"),
        ("window", ["40", 400], "[level, width]"),
        ("window", [40], "[level, width]"),
        ("clip_box", [[0, 0, 0], [1, 1]], "[[x0, y0, z0], [x1, y1, z1]]"),
        ("background", "black", "[r, g, b]"),
        ("background", [0, 0, "0"], "[r, g, b]"),
        ("view", 90, "[azimuth, elevation]"),
        ("mode", 3, "one of the strings"),
        ("camera", "front", "camera object"),
        ("warps", {"type": "affine"}, "list of warp objects"),
    ],
)
def test_strict_json_types(key: str, value: Any, expected: str) -> None:
    with pytest.raises(SceneError) as err:
        Scene.from_dict({"format": "voxwarp-scene", "volume": VOLUME, key: value})
    msg = _one_line(err.value)
    assert f"'{key}'" in msg  # names the key
    assert expected in msg  # and what it must be
    assert json.dumps(value) in msg  # and what it got


def test_correct_types_still_load() -> None:
    scene = Scene.from_dict(
        {
            "format": "voxwarp-scene",
            "volume": VOLUME,
            "step": 2,
            "zoom": 1.5,
            "seed": 3,
            "window": [100, 200.5],
            "clip_box": [[0, 0, 0], [4, 4, 4]],
            "background": [0, 0, 0],
            "view": [30, 10],
            "iso_value": None,
            "description": "a note",
        }
    )
    assert scene.step == 2.0
    assert scene.seed == 3
    assert scene.view == (30.0, 10.0)


def test_unknown_scene_key_is_an_error_listing_the_allowed() -> None:
    with pytest.raises(SceneError) as err:
        Scene.from_dict({"format": "voxwarp-scene", "volume": VOLUME, "stepsize": 2})
    msg = _one_line(err.value)
    assert "'stepsize'" in msg
    assert all(k in msg for k in SCENE_KEYS)


def test_every_key_a_saved_scene_writes_is_allowed(tmp_path: Path) -> None:
    """The oracle for the key list: what Scene.save writes (meshes included) reads back."""
    from voxwarp.core.mesh import MeshInstance, box_mesh

    scene = Scene.from_dict({"format": "voxwarp-scene", "volume": VOLUME})
    scene = scene.copy(meshes=[MeshInstance(box_mesh())], camera=scene.resolved_camera())
    d = scene.to_dict()
    check_scene_json(d)
    assert set(d) <= set(SCENE_KEYS)


def test_unknown_camera_key_is_an_error() -> None:
    cam = Camera().to_dict()
    with pytest.raises(SceneError) as err:
        Scene.from_dict(
            {"format": "voxwarp-scene", "volume": VOLUME, "camera": {**cam, "zooom": 2}}
        )
    msg = _one_line(err.value)
    assert "'zooom'" in msg
    assert "center, rotation, distance, fov, projection, ortho_height, radius" in msg


@pytest.mark.parametrize(
    ("key", "value"), [("fov", "30"), ("distance", True), ("center", [0, 0]), ("projection", 1)]
)
def test_camera_strict_types(key: str, value: Any) -> None:
    with pytest.raises(SceneError, match=f"camera '{key}' must be") as err:
        Camera.from_dict({**Camera().to_dict(), key: value})
    _one_line(err.value)


@pytest.mark.parametrize(
    "content",
    [
        '{"format": "voxwarp-scene", "volume": ',
        {"volume": VOLUME, "mode": "mip"},
        {"format": "voxwarp-scene", "volume": VOLUME, "step": "1"},
        {"format": "voxwarp-scene", "volume": VOLUME, "colour": "red"},
        {"format": "voxwarp-scene", "volume": VOLUME, "camera": {"fov": 30, "up": [0, 0, 1]}},
    ],
)
def test_cli_exit_2_one_line_no_traceback(
    tmp_path: Path, capsys: pytest.CaptureFixture, content: Any
) -> None:
    path = _scene(tmp_path, content)
    assert main(["render", str(path), "-o", str(tmp_path / "out.png")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("voxwarp: error: ")
    assert err.count("\n") == 1
    assert "Traceback" not in err
    assert not (tmp_path / "out.png").exists()


def test_errors_are_voxwarp_errors() -> None:
    assert issubclass(SceneError, VoxwarpError)
    assert issubclass(InputError, VoxwarpError)


def test_lattice_file_unknown_key_lists_the_allowed(tmp_path: Path) -> None:
    from voxwarp.core.volume import Volume
    from voxwarp.deform.lattice.trilinear import TrilinearGrid
    from voxwarp.inputs import load_lattice_file

    grid = TrilinearGrid.from_function(lambda u: u * 4.0, (1, 1, 1)).to_dict()
    path = tmp_path / "lattice.json"
    path.write_text(json.dumps({"grid": grid, "description": "a note", "itertions": 3}))
    with pytest.raises(InputError) as err:
        load_lattice_file(path, Volume(np.zeros((4, 4, 4), np.uint8)))
    msg = _one_line(err.value)
    assert "'itertions'" in msg
    assert (
        "allowed: type, grid, box, inverse, iterations, tolerance, max_iterations, fold_linear"
        in msg
    )
