"""The transfer-function editor loads ParaView and Slicer files and offers matplotlib maps.

Runs on the private Xvfb of tests/ui/conftest.py; dialogs (file, list, message box) are
replaced by stubs that record what they were asked. Files as in
tests/core/test_tf_formats.py (copied from Slicer's presets.xml and ParaView's
ColorMaps.json).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QFileDialog, QInputDialog, QMessageBox

from tests.core.test_tf_formats import (
    CT_BONE_COLOUR,
    PARAVIEW_EXPORT,
    PARAVIEW_PRESETS,
    PRESETS_XML,
    hu_volume,
    paraview_json,
)
from voxwarp.core import transfer_function as tfmod
from voxwarp.core.transfer_function import PRESETS, TransferFunction
from voxwarp.ui import tf_editor
from voxwarp.ui.tf_editor import COLORMAP_ENTRIES, TransferFunctionEditor


@pytest.fixture
def editor(qtbot: Any) -> TransferFunctionEditor:
    ed = TransferFunctionEditor(TransferFunction.preset("ct-bone"), hu_volume(1.0))
    qtbot.addWidget(ed)
    ed.resize(640, 320)
    with qtbot.waitExposed(ed):
        ed.show()
    return ed


def stub_get_item(monkeypatch: pytest.MonkeyPatch, answer: str | None) -> list[list[str]]:
    """QInputDialog.getItem answering ``answer`` (None: cancelled); records the lists."""
    asked: list[list[str]] = []

    def get_item(_parent: Any, _title: str, _label: str, items: list[str], *_a: Any) -> Any:
        asked.append(list(items))
        return (answer or "", answer is not None)

    monkeypatch.setattr(QInputDialog, "getItem", get_item)
    return asked


def test_load_button_offers_the_new_formats_and_asks_for_the_preset(
    qtbot: Any, editor: TransferFunctionEditor, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    presets = tmp_path / "presets.xml"
    presets.write_text(PRESETS_XML)
    filters: list[str] = []

    def get_open(_parent: Any, _title: str, _dir: str, flt: str) -> tuple[str, str]:
        filters.append(flt)
        return str(presets), ""

    monkeypatch.setattr(QFileDialog, "getOpenFileName", get_open)
    asked = stub_get_item(monkeypatch, "CT-Bone")
    got: list[TransferFunction] = []
    editor.transferFunctionChanged.connect(got.append)
    qtbot.mouseClick(editor.load_button, Qt.MouseButton.LeftButton)
    assert "*.xml" in filters[0]
    assert "*.vp" in filters[0]
    assert "*.json" in filters[0]
    assert asked == [["CT-AAA", "CT-Bone", "MR-Default"]]
    tf = editor.transfer_function
    assert tf.name == "CT-Bone"
    assert got == [tf]
    for x, r, g, b in CT_BONE_COLOUR:
        np.testing.assert_allclose(tf(x)[:3], (r, g, b), atol=1e-9)
    assert editor.preset_combo.currentText() == "custom"


def test_cancelling_the_preset_choice_keeps_the_function(
    editor: TransferFunctionEditor, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "ColorMaps.json"
    path.write_text(paraview_json(PARAVIEW_PRESETS))
    before = editor.transfer_function.points
    asked = stub_get_item(monkeypatch, None)
    assert editor.load_from(path) is False
    assert asked == [["Cool to Warm", "Black-Body Radiation", "X Ray"]]
    assert editor.transfer_function.points == before


def test_single_map_file_loads_without_asking(
    editor: TransferFunctionEditor, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "bone.json"
    path.write_text(paraview_json(PARAVIEW_EXPORT))
    asked = stub_get_item(monkeypatch, "never")
    assert editor.load_from(path) is True
    assert asked == []
    assert editor.transfer_function.name == "bone-hu"
    assert editor.transfer_function(700.0)[3] == pytest.approx(0.6)


def test_conversion_notes_are_shown_and_errors_are_boxed(
    editor: TransferFunctionEditor, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "de.json"
    de = {**PARAVIEW_PRESETS[0], "ColorSpace": "Lab/CIEDE2000"}  # not reproduced: a note
    path.write_text(paraview_json([de]))
    assert editor.load_from(path) is True
    assert editor.message.isVisibleTo(editor)
    assert "interpolated in RGB" in editor.message.text()

    shown: list[str] = []
    monkeypatch.setattr(QMessageBox, "warning", lambda _p, _t, text: shown.append(text))
    bad = tmp_path / "bad.xml"
    bad.write_text('<MRML><VolumeProperty name="x" scalarOpacity="6 0 0 1 1"/></MRML>')
    before = editor.transfer_function.points
    assert editor.load_from(bad) is False
    assert len(shown) == 1
    assert "no colorTransfer" in shown[0]
    assert editor.transfer_function.points == before


def test_combo_offers_matplotlib_maps(qtbot: Any, editor: TransferFunctionEditor) -> None:
    combo = editor.preset_combo
    names = [combo.itemText(i) for i in range(combo.count())]
    assert names == ["custom", *PRESETS, *COLORMAP_ENTRIES]
    got: list[TransferFunction] = []
    editor.transferFunctionChanged.connect(got.append)
    combo.setCurrentText("magma")
    assert editor.transfer_function.name == "magma"
    assert editor.transfer_function.points == TransferFunction.preset("magma", hu_volume()).points
    assert len(got) == 1
    # a loaded colour map shows its entry again
    editor.set_transfer_function(TransferFunction.preset("cividis", hu_volume()))
    assert combo.currentText() == "cividis"


def test_combo_without_matplotlib_has_only_presets(
    qtbot: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(tf_editor, "colormaps_available", lambda: False)
    monkeypatch.setattr(tfmod, "colormaps_available", lambda: False)
    ed = TransferFunctionEditor(TransferFunction.preset("mri"))
    qtbot.addWidget(ed)
    names = [ed.preset_combo.itemText(i) for i in range(ed.preset_combo.count())]
    assert names == ["custom", *PRESETS]


def test_voxwarp_json_still_loads(editor: TransferFunctionEditor, tmp_path: Path) -> None:
    path = tmp_path / "own.json"
    path.write_text(json.dumps({"points": [[0, 0, 0, 0, 0], [10, 1, 1, 1, 0.5]]}))
    assert editor.load_from(path) is True
    assert editor.transfer_function.points[-1] == (10.0, 1.0, 1.0, 1.0, 0.5)
