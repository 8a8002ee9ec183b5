"""Open in voxwarp: the files handed over, and the voxwarp window opening them."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from napari.layers import Image

from tests.napari.xvfb import x_env, xvfb_display
from voxwarp.napari_plugin.convert import layer_scene_options, layer_to_volume
from voxwarp.napari_plugin.handoff import voxwarp_command, write_handoff
from voxwarp.scene import Scene


def _layer() -> Image:
    data = np.zeros((20, 24, 28), np.float32)  # z, y, x
    data[5:15, 6:18, 7:21] = 100.0
    data[8:12, 10:14, 12:16] = 300.0
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    affine = np.array([[1, 0, 0, 4], [0, c, -s, -3], [0, s, c, 2], [0, 0, 0, 1]])
    return Image(
        data,
        scale=(2.0, 1.0, 0.5),
        affine=affine,
        contrast_limits=(50, 250),
        colormap="viridis",
        name="box/1",
    )


def test_handoff_writes_a_scene_voxwarp_loads(tmp_path: Path) -> None:
    layer = _layer()
    volume = layer_to_volume(layer)
    scene_path = write_handoff(volume, layer_scene_options(layer), tmp_path)
    assert scene_path == tmp_path / "scene.json"
    assert (tmp_path / "box_1.nrrd").is_file()
    scene = Scene.load(scene_path)
    np.testing.assert_array_equal(scene.volume.data, volume.data)
    np.testing.assert_allclose(scene.volume.affine, volume.affine, atol=1e-9)
    assert scene.window == (150.0, 200.0)
    assert scene.mode == "mip"
    assert scene.transfer_function.name == "napari:viridis"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["box_1.nrrd", "scene.json"]


def test_command_runs_this_python_without_a_shell() -> None:
    assert voxwarp_command("/x/scene.json") == [
        sys.executable,
        "-m",
        "voxwarp",
        "gui",
        "/x/scene.json",
    ]


@pytest.mark.slow
def test_voxwarp_window_opens_the_handed_scene(tmp_path: Path) -> None:
    layer = _layer()
    scene_path = write_handoff(layer_to_volume(layer), layer_scene_options(layer), tmp_path)
    shot = tmp_path / "window.png"
    with xvfb_display() as display:
        result = subprocess.run(
            [*voxwarp_command(scene_path), "--screenshot", str(shot), "--size", "640x480"],
            env=x_env(display, gl_integration="xcb_egl"),
            capture_output=True,
            text=True,
            timeout=300,
        )
    assert result.returncode == 0, result.stderr[-3000:]
    from voxwarp.io.images import read_image

    image = np.asarray(read_image(shot))
    assert image.shape[0] >= 400
    assert image.std() > 5
