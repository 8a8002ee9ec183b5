"""A push through a face of the volume's box, on the command line: with the default grid
margin (the drag) the content goes 15 mm beyond the face and ``export-volume --grid
deformed`` and ``--frame deformed`` include it; with ``--grid-margin 0`` (the volume's
box, as before the margin) it is cut at the face."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.run_cli import run_cli
from voxwarp.core.camera import Camera
from voxwarp.core.volume import Volume
from voxwarp.io.volumes import load_volume, save_volume

#: a bright block in a 40 mm cube of 1 mm voxels (centres 0..39), touching the top
#: face (+y: voxel centres up to 39, the face at 39.5)
TOP = 39.0
PUSH = 15.0


@pytest.fixture(scope="module")
def block(tmp_path_factory: pytest.TempPathFactory) -> Path:
    data = np.zeros((40, 40, 40), np.uint8)
    data[14:27, 24:40, 14:27] = 200
    folder = tmp_path_factory.mktemp("grid_margin")
    return save_volume(Volume(data, name="block"), folder / "block.nii.gz")


def push(block: Path, tmp_path: Path, *extra: str) -> tuple[Path, str]:
    """Render the block pushed up by PUSH mm (ChainMail, the element nearest the top
    face's centre), save its scene and camera, export the deformed grid."""
    scene, out = tmp_path / "s.json", tmp_path / "deformed.nii.gz"
    drag = ["--chainmail", "11", "--drag-at", f"20,{TOP},20:0,{PUSH},0", *extra]
    r = run_cli(
        "render", str(block), *drag, "--frame", "deformed", "--mode", "mip",
        "--size", "96x96", "--save-scene", str(scene),
        "--save-camera", str(tmp_path / "camera.json"), "-o", str(tmp_path / "p.png"),
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    e = run_cli("export-volume", str(scene), "--grid", "deformed", "-o", str(out), "--no-progress")
    assert e.returncode == 0, e.stderr
    return out, r.stderr


@pytest.mark.gl
@pytest.mark.slow
def test_push_through_the_top_face_goes_beyond_it(block: Path, tmp_path: Path) -> None:
    out, err = push(block, tmp_path)
    assert f"grid margin: the element grid reaches {PUSH:g} mm beyond" in err
    vol = load_volume(out)
    world = vol.index_to_world(np.argwhere(np.asarray(vol.data) > 100).astype(float))
    # the export grows to hold the content, and the content's top is 15 mm up
    assert vol.bounds[1][1] >= TOP + PUSH
    assert abs(world[:, 1].max() - (TOP + PUSH)) <= 2.0, world[:, 1].max()
    # --frame deformed: the camera is fitted to the grown box and sees the pushed top
    cam = Camera.from_dict(json.loads((tmp_path / "camera.json").read_text()))
    grown = 0.5 * np.linalg.norm([40.0, 40.0 + PUSH, 40.0])  # the box grown to the top
    assert cam.radius >= grown
    corners = np.array([[x, TOP + PUSH, z] for x in (14, 26) for z in (14, 26)], float)
    px = cam.project(corners, (96, 96))
    assert np.all((px >= 0) & (px <= 96)), px


@pytest.mark.gl
@pytest.mark.slow
def test_without_margin_the_push_is_cut_at_the_face(block: Path, tmp_path: Path) -> None:
    out, err = push(block, tmp_path, "--grid-margin", "0")
    assert "grid margin" not in err
    vol = load_volume(out)
    assert vol.shape == (40, 40, 40)  # the deformed box is the volume's box
    cam = Camera.from_dict(json.loads((tmp_path / "camera.json").read_text()))
    assert cam.radius == pytest.approx(0.5 * np.linalg.norm([40.0, 40.0, 40.0]))
    world = vol.index_to_world(np.argwhere(np.asarray(vol.data) > 100).astype(float))
    assert world[:, 1].max() <= TOP + 0.5


@pytest.mark.gl
def test_slice_extent_holds_the_pushed_content(block: Path, tmp_path: Path) -> None:
    """``voxwarp slice``'s plane is sized to the deformed box: it reaches the pushed top."""
    common = ["slice", str(block), "--plane", "z", "--pixel", "1", "--json"]
    drag = ["--chainmail", "11", "--drag-at", f"20,{TOP},20:0,{PUSH},0"]
    tops = {}
    for margin in ("0", None):
        extra = [] if margin is None else ["--grid-margin", margin]
        r = run_cli(*common, *drag, *extra, "-o", str(tmp_path / "s.png"))
        assert r.returncode == 0, r.stderr
        doc = json.loads(r.stdout)
        tops[margin] = doc["center"][1] + 0.5 * doc["size"][1] * doc["pixel_mm"]
    assert tops["0"] == pytest.approx(TOP + 0.5, abs=1.0)  # the volume box (whole pixels)
    assert tops[None] >= TOP + PUSH
