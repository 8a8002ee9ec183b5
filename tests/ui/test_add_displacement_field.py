"""File -> Add Displacement Field in a real window (Xvfb, see conftest): the field goes
first in the scene's warps, the picture changes, the field slice view shows ``|u|``,
undo and Remove take it out again, and a bad file is a one-line message."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PySide6.QtWidgets import QFileDialog

from tests.ui.test_main_window import _session, frame
from tests.ui.windows import shown_window
from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.io.fields import save_displacement_field


@pytest.fixture
def window(qtbot: Any, monkeypatch: pytest.MonkeyPatch) -> Any:
    """A shown main window on the fish (64³), first frame drawn, simulation paused."""
    w = shown_window(qtbot, monkeypatch, _session(), (1000, 700))
    yield w
    w.close()


def smooth_field(volume: Any) -> DisplacementFieldWarp:
    """A smooth swirl over the volume's box: up to ~6 mm, 0 at the box's faces."""
    lo, hi = (np.asarray(b, dtype=np.float64) for b in volume.bounds)
    n = np.array([16, 12, 10])
    spacing = (hi - lo) / (n - 1)
    affine = np.diag([*spacing, 1.0])
    affine[:3, 3] = lo
    idx = np.stack(np.meshgrid(*(np.arange(k) for k in n), indexing="ij"), -1)
    t = idx / (n - 1)  # 0..1 across the box
    bump = np.sin(np.pi * t[..., 0]) * np.sin(np.pi * t[..., 1]) * np.sin(np.pi * t[..., 2])
    u = np.zeros((*n, 3))
    u[..., 0] = 6.0 * bump * np.cos(2 * np.pi * t[..., 2])
    u[..., 1] = 6.0 * bump * np.sin(2 * np.pi * t[..., 2])
    return DisplacementFieldWarp(u, affine)


def choose(monkeypatch: pytest.MonkeyPatch, path: Path) -> None:
    monkeypatch.setattr(
        QFileDialog, "getOpenFileName", staticmethod(lambda *a, **k: (str(path), ""))
    )


def action(w: Any, text: str) -> Any:
    return next(a for a in w.actions() if a.text() == text)


def test_add_field_warps_the_view_and_shows_u(
    window: Any, qtbot: Any, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    w = window
    volume = w.session.volume
    path = save_displacement_field(smooth_field(volume), tmp_path / "swirl.nii.gz")
    before = frame(w)
    choose(monkeypatch, path)
    action(w, "Add &Displacement Field…").trigger()
    assert not w.errors
    warps = w.session.scene.warps
    assert len(warps) == 1
    assert isinstance(warps[0], DisplacementFieldWarp)
    assert warps[0].path == str(path)
    assert "swirl.nii.gz" in w.statusBar().currentMessage()
    assert "grid 16 x 12 x 10" in w.statusBar().currentMessage()
    assert w.session.volume is volume
    after = frame(w)
    changed = np.abs(after - before).max(axis=-1) > 8
    assert changed.mean() > 0.01  # the fish moved

    # the field slice view offers and shows |u| of the field
    view = w.display_panel.field_view
    view.show_check.setChecked(True)
    assert view.view_combo.currentText() == "field |u| · swirl.nii.gz"
    qtbot.waitUntil(lambda: view.slice is not None, timeout=10000)
    assert view.title_label.text().startswith("displacement field |u|, z = ")
    top = float(view.legend_label.text().split(" .. ")[1].split(" mm")[0])
    assert 3.0 < top <= 6.0
    shot = tmp_path / "field_view.png"
    assert view.grab().save(str(shot))

    # undo takes it out, redo puts it back, Remove takes it out again
    w.undo_stack.undo()
    assert w.session.scene.warps == []
    w.undo_stack.redo()
    assert w.session.scene.warps == warps
    action(w, "Remove Displacement Fields").trigger()
    assert w.session.scene.warps == []
    assert w.session.imported_warps == []
    np.testing.assert_allclose(frame(w), before, atol=2)


def test_bad_field_file_is_a_one_line_message(
    window: Any, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    import SimpleITK as sitk

    w = window
    bad = tmp_path / "two.nii.gz"
    sitk.WriteImage(
        sitk.GetImageFromArray(np.zeros((4, 4, 4, 2), np.float32), isVector=True), str(bad)
    )
    choose(monkeypatch, bad)
    action(w, "Add &Displacement Field…").trigger()
    assert len(w.errors) == 1
    assert "\n" not in w.errors[0]
    assert "two.nii.gz" in w.errors[0]
    assert "2 components" in w.errors[0]
    assert w.session.scene.warps == []
    assert w.undo_stack.count() == 0
