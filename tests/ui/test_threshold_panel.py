"""The Volume panel's level row (voxwarp.ui.panels.VolumePanel): the iso value or FLM
threshold the scene uses, Auto (from the histogram, voxwarp.core.levels) or typed, as
undoable look edits; disabled in the modes without a level."""

from __future__ import annotations

from typing import Any

import pytest

from tests.ui.test_panels import FakeWindow, make_panel, window  # noqa: F401 (fixture)
from voxwarp.ui.panels import VolumePanel


def test_level_row_follows_the_mode(qtbot: Any, window: FakeWindow) -> None:  # noqa: F811
    panel = make_panel(qtbot, window, VolumePanel)
    assert not panel.threshold_spin.isEnabled()
    assert not panel.threshold_auto.isEnabled()
    panel.mode_combo.setCurrentText("iso")
    scene = window.session.scene
    assert panel.threshold_label.text() == "Iso value"
    assert panel.threshold_auto.isEnabled()
    assert panel.threshold_auto.isChecked()
    assert not panel.threshold_spin.isEnabled()  # Auto: shows the chosen value
    assert panel.threshold_spin.value() == pytest.approx(scene.resolved_iso_value(), abs=1e-3)
    assert "split" in panel.threshold_label.toolTip()
    panel.mode_combo.setCurrentText("flm")
    assert panel.threshold_label.text() == "Threshold"
    assert panel.threshold_spin.value() == pytest.approx(scene.resolved_flm_threshold(), abs=1e-3)
    assert window.edits == [("Mode iso", None), ("Mode flm", None)]


def test_typed_level_is_an_edit_and_auto_gives_it_back(qtbot: Any, window: FakeWindow) -> None:  # noqa: F811
    panel = make_panel(qtbot, window, VolumePanel)
    panel.mode_combo.setCurrentText("flm")
    scene = window.session.scene
    chosen = scene.resolved_flm_threshold()
    panel.threshold_auto.setChecked(False)
    assert panel.threshold_spin.isEnabled()
    assert scene.flm_threshold == pytest.approx(chosen, abs=1e-3)  # starts from the choice
    panel.threshold_spin.setValue(62.5)
    assert scene.flm_threshold == 62.5
    assert scene.iso_value is None
    assert window.edits[-1] == ("Threshold", "flm_threshold")
    assert "(given)" in panel.threshold_label.toolTip()
    panel.threshold_auto.setChecked(True)
    assert scene.flm_threshold is None
    assert scene.resolved_flm_threshold() == chosen
    assert window.edits[-1] == ("Threshold auto", None)
    assert window.errors == []
