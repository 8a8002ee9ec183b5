"""Typed window/level, presets, the window in each view and a readout that fits
(issue 32, item 7).

Oracles: the preset table (a CT in HU opens at mediastinum 40/400; choosing bone gives
400/1800; an MR offers its percentile window only), the typed numbers, a right-drag
shown back in the fields, each view's corner label, and the widths of the readout's
lines measured with the font the view paints them in, at the default 1280x800 window
in the 2x2 layout, for the longest position and values the volume can produce."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from PySide6.QtGui import QFont, QFontMetricsF

from tests.ui.windows import shown_window
from voxwarp.core.volume import Volume
from voxwarp.editing.reading import split_readout
from voxwarp.editing.session import EditSession
from voxwarp.editing.slice_views import readout
from voxwarp.scene import Scene


def _session(modality: str) -> EditSession:
    i, j, k = np.meshgrid(np.arange(40), np.arange(36), np.arange(32), indexing="ij")
    if modality == "CT":
        data = (i * 40 + j * 10 - 1000).astype(np.int16)
        vol = Volume(data, (1.0, 1.0, 1.0), (-300.0, -300.0, -300.0), units="HU", space="RAS")
    else:
        data = (i * 3 + j * 2 + k * 5).astype(np.float32)
        vol = Volume(data, (1.0, 1.0, 1.0), modality="MR", space="RAS")
    return EditSession(Scene(vol, jitter=False))


def _open(qtbot: Any, monkeypatch: pytest.MonkeyPatch, modality: str) -> Any:
    w = shown_window(qtbot, monkeypatch, _session(modality), (1280, 800), layout="2x2")
    qtbot.waitUntil(lambda: all(v.image is not None for v in w.mpr.views), timeout=30000)
    return w


def test_ct_presets_typed_window_and_drag(qtbot: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    w = _open(qtbot, monkeypatch, "CT")
    try:
        bar = w.window_level
        assert w.mpr.state.window == (40.0, 400.0)
        assert bar.preset.currentText() == "mediastinum"
        assert (bar.level.value(), bar.width.value()) == (40.0, 400.0)
        items = [bar.preset.itemText(i) for i in range(bar.preset.count())]
        assert items[:4] == ["lung", "mediastinum", "bone", "brain"]
        assert all(v.window_text() == "W 400 L 40" for v in w.mpr.views)
        before = w.mpr.views[0]._qimage.copy()
        bar.preset.textActivated.emit("bone")
        assert w.mpr.state.window == (400.0, 1800.0)
        assert bar.level.value() == 400.0
        assert w.mpr.views[0]._qimage != before  # re-coloured
        bar.level.setValue(-50.0)
        bar.width.setValue(250.0)
        bar.width.editingFinished.emit()
        assert w.mpr.state.window == (-50.0, 250.0)
        assert bar.preset.currentText() == "custom"
        assert w.mpr.views[1].window_text() == "W 250 L -50"
        w.mpr.state.window_drag(40, -20)  # what a right drag does, then the re-colouring
        w.mpr.recolor_all()
        level, width = w.mpr.state.window
        assert (bar.level.value(), bar.width.value()) == pytest.approx((level, width), abs=0.05)
        assert width > 250.0
        w.mpr.reset()
        assert bar.preset.currentText() == "mediastinum"
    finally:
        w.close()


def test_mr_keeps_its_percentile_window(qtbot: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    w = _open(qtbot, monkeypatch, "MR")
    try:
        bar = w.window_level
        items = [bar.preset.itemText(i) for i in range(bar.preset.count())]
        assert items == ["percentile", "custom"]
        assert bar.preset.currentText() == "percentile"
        assert w.mpr.state.window == w.session.scene.window  # the percentile default
        bar.preset.textActivated.emit("lung")  # not offered; refused, window kept
        assert bar.preset.currentText() == "percentile"
    finally:
        w.close()


def test_readout_fits_at_1280(qtbot: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    w = _open(qtbot, monkeypatch, "CT")
    try:
        font = QFont(w.mpr.views[0].font())
        font.setPointSizeF(9.0)  # as SliceView._paint_labels
        fm = QFontMetricsF(font)
        longest = readout((-300.0, -300.0, -300.0), "RAS", -1000.25, -1000.25)
        for view in w.mpr.views:
            for line in (*split_readout(longest), view.window_text()):
                assert fm.horizontalAdvance(line) <= view.width() - 12, (line, view.width())
            assert fm.horizontalAdvance(longest) > view.width() - 12  # one line did not
    finally:
        w.close()


def test_one_to_one_views_show_voxels(qtbot: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    """View > Slice Views 1:1: a pixel per voxel, each pixel centre on a voxel centre
    (nearest and linear sampling then agree: the readout is the voxel's value)."""
    w = _open(qtbot, monkeypatch, "CT")
    try:
        w.mpr.state.set_crosshair(w.session.volume.index_to_world(np.array([9.4, 20.7, 13.2])))
        w.mpr.one_to_one()
        vol = w.session.volume
        for view in w.mpr.views:
            plane, size = view.plane(), view.size_px()
            assert plane.pixel_mm(size) == pytest.approx(min(vol.spacing))
            m = plane.pixel_to_world(size)
            corners = np.array([[0, 0, 0, 1], [size[0] - 1, size[1] - 1, 0, 1]], float)
            idx = vol.world_to_index((corners @ m.T)[:, :3])
            axis = {"axial": 2, "coronal": 1, "sagittal": 0}[view.name]
            in_plane = np.delete(idx, axis, axis=1)
            assert np.abs(in_plane - np.round(in_plane)).max() < 1e-6, view.name
    finally:
        w.close()
