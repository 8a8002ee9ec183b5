"""A real napari viewer with the voxwarp dock widget, headless on a private Xvfb.

napari runs in a child process (tests/napari/viewer_check.py): its Qt application
needs Qt's default GLX integration (vispy draws nothing and crashes under the
``xcb_egl`` integration and the OpenGL 4.5 core default format that the voxwarp
window's tests set up in this process), and one process holds one QApplication.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.napari.xvfb import x_env, xvfb_display

CHECK = Path(__file__).with_name("viewer_check.py")


@pytest.mark.slow
def test_widget_renders_the_deformed_view_into_napari(tmp_path: Path) -> None:
    with xvfb_display() as display:
        result = subprocess.run(
            [sys.executable, str(CHECK), str(tmp_path)],
            env=x_env(display, gl_integration=None),
            capture_output=True,
            text=True,
            timeout=300,
        )
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-4000:]
    r = json.loads((tmp_path / "result.json").read_text())
    assert r["listed"] == ["fish"]  # the 2D layer is not offered
    # ... and selecting it says why, keeping the layer that can be rendered
    assert r["flat_status"].startswith("voxwarp: layer 'flat' has 2 dimensions"), r["flat_status"]
    assert r["flat_choice"] == "fish"
    for key in ("none", "push"):
        assert r[key]["rgb"] is True
        assert r[key]["shape"] == [160, 160, 3]
        assert r[key]["std"] > 10, f"{key} render is blank"
    assert r["layers"][-2:] == ["fish (voxwarp, none)", "fish (voxwarp, mass-spring push)"]
    assert r["push_vs_none_mean_abs"] > 1.0  # the push changes the picture
    assert r["voxwarp_started"], r["scene"]
    assert r["refused"]
    assert r["error_status"] == "voxwarp: deformation 'scene file' needs a scene JSON: pick one"
    assert r["worker_error_status"].startswith("voxwarp: no such scene file: ")
    assert r["view_error_status"].startswith("voxwarp: view 'anterior' needs a patient")
    assert r["layer_count_after_error"] == 4  # nothing added
    assert (tmp_path / "window.png").stat().st_size > 10_000
    # File > Open of a scene JSON: voxwarp is its only reader; the volume and its render
    assert r["scene_layers"] == [
        ["head", [24, 24, 24]],
        ["head (voxwarp deformed view)", [256, 256, 3]],
    ]
    (name, shape), *_ = r["nifti_layers"]
    assert name == "tilted"
    assert sorted(shape) == [16, 20, 24]
    rotation = np.asarray(r["nifti_affine"])[:3, :3]
    assert abs(abs(rotation[1, 2]) - np.sin(np.radians(25))) < 1e-4  # the tilt, zyx order
    assert r["canvas_3d_std"] > 1  # napari draws the oblique volume in 3D
