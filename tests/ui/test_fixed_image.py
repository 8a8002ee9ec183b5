"""File › Open Fixed Image in a real window (Xvfb, see conftest): the slice views
sample the fixed image on their pixels, the blend slider's ends give the moving and
the fixed colours, the 3D compare choice puts the comparison on the scene (the
difference of an image with itself is the bare background), and a bad file is a
one-line message.

Oracle: the fixed image is the moving volume's data saved to NRRD with its axes in the
other order (LPS: x and y reversed, the affine to match), so it lies at the same world
points: its slice values equal the moving ones (the texture filter's tolerance)."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PySide6.QtWidgets import QApplication, QFileDialog

from tests.ui.windows import shown_window
from voxwarp.core.volume import Volume
from voxwarp.editing.session import EditSession
from voxwarp.io.volumes import save_volume
from voxwarp.render.slice_image import colorize
from voxwarp.scene import Scene

SIZE = (1200, 800)


def _volume() -> Volume:
    i, j, k = np.meshgrid(np.arange(30), np.arange(26), np.arange(20), indexing="ij")
    data = (i * 3 + j * 2 + k * 5 + (i * j) % 7).astype(np.float32)
    return Volume(data, (1.5, 1.0, 1.2), (-20.0, -12.0, -10.0), name="ramp", space="RAS")


@pytest.fixture
def window(qtbot: Any, monkeypatch: pytest.MonkeyPatch) -> Any:
    scene = Scene(_volume(), mode="mip", jitter=False, background=(0, 0, 0, 1))
    w = shown_window(qtbot, monkeypatch, EditSession(scene), SIZE, active=True, layout="2x2")
    qtbot.waitUntil(lambda: all(v.image is not None for v in w.mpr.views), timeout=30000)
    yield w
    w.close()


def _flipped(vol: Volume) -> Volume:
    n = np.asarray(vol.shape)
    origin = np.asarray(vol.origin) + np.array([(n[0] - 1) * vol.spacing[0], 0.0, 0.0])
    origin[1] += (n[1] - 1) * vol.spacing[1]
    data = np.asfortranarray(vol.data[::-1, ::-1])
    direction = np.diag([-1.0, -1.0, 1.0])
    return Volume(data, vol.spacing, origin, direction=direction, space="RAS")


def _open(w: Any, monkeypatch: pytest.MonkeyPatch, path: Path) -> None:
    monkeypatch.setattr(
        QFileDialog, "getOpenFileName", staticmethod(lambda *a, **k: (str(path), ""))
    )
    next(a for a in w.actions() if a.text() == "Open &Fixed Image…").trigger()
    for _ in range(5):
        QApplication.processEvents()


@pytest.mark.slow
def test_open_fixed_image_slices_blend_and_3d(
    window: Any, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    w = window
    assert not w.compare_bar.isVisible()  # no fixed image: no Compare toolbar
    path = save_volume(_flipped(w.session.volume), tmp_path / "fixed_lps.nrrd")
    _open(w, monkeypatch, path)
    assert not w.errors
    assert w.compare_bar.isVisible()
    assert w.fixed_image.volume is not None
    for view in w.mpr.views:
        img = view.image
        assert img.fixed is not None
        inside = np.isfinite(img.values)
        assert inside.mean() > 0.2
        err = np.abs(img.fixed - img.values)[inside]
        assert err.max() < 3 * 200 / 512  # same world points: the filter's tolerance
        assert "   fixed " in view.readout_text()

    # the blend slider's ends: the moving and the fixed colours (a fixed image that
    # differs: the inverted ramp)
    vol = w.session.volume
    other = vol.with_geometry(np.asfortranarray(vol.data.max() - vol.data))
    _open(w, monkeypatch, save_volume(other, tmp_path / "inverted.nrrd"))
    view = w.mpr.views[0]
    w.mpr.set_option("show", "blend")
    win = w.mpr.state.window
    w.compare_controls["blend"].setValue(0)
    shown = view.image.rgba.copy()
    assert np.array_equal(shown, colorize(copy.copy(view.image), window=win, show="deformed"))
    w.compare_controls["blend"].setValue(100)
    shown = view.image.rgba.copy()
    fixed = colorize(copy.copy(view.image), window=win, show="rest")
    assert np.array_equal(shown, fixed)
    moving = colorize(copy.copy(view.image), window=win, show="deformed")
    assert np.abs(moving.astype(int) - fixed).max() > 100  # the two ends differ

    # 3D: the comparison goes on the scene and off again
    w.compare_controls["show_3d"].textActivated.emit("difference")
    cmp = w.session.scene.comparison
    assert cmp is not None
    assert cmp.show == "difference"
    w.compare_controls["show_3d"].textActivated.emit("off")
    assert w.session.scene.comparison is None

    next(a for a in w.actions() if a.text() == "Close Fixed Image").trigger()
    assert w.fixed_image.volume is None
    assert not w.compare_bar.isVisible()
    assert all(v.image.fixed is None for v in w.mpr.views if v.image is not None)
    assert "   rest " in w.mpr.views[0].readout_text()


def test_bad_fixed_file_is_one_line(
    window: Any, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    bad = tmp_path / "not_a_volume.nrrd"
    bad.write_text("hello")
    _open(window, monkeypatch, bad)
    assert len(window.errors) == 1
    assert "could not open the fixed image not_a_volume.nrrd" in window.errors[0]
    assert "\n" not in window.errors[0]
    assert window.fixed_image.volume is None
