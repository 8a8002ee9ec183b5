"""Tests of voxwarp.ui.tf_editor: mouse/key editing, signals, presets, files, histogram, painting.

Mouse events go to the real canvas through pytest-qt (QTest) on the private Xvfb the
conftest starts; expected values come from the canvas's own pixel <-> value mapping,
which is itself checked against the plot rectangle.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PySide6.QtCore import QPoint, QPointF, Qt
from PySide6.QtGui import QColor, QImage
from PySide6.QtWidgets import QColorDialog, QFileDialog, QMessageBox

from voxwarp.core.transfer_function import PRESETS, TransferFunction
from voxwarp.core.volume import Volume
from voxwarp.ui.tf_editor import HISTOGRAM_BINS, TransferFunctionEditor, value_histogram

POINTS = [
    (0.0, 0.0, 0.0, 0.0, 0.0),
    (40.0, 1.0, 0.0, 0.0, 0.2),
    (60.0, 0.0, 1.0, 0.0, 0.6),
    (100.0, 1.0, 1.0, 1.0, 0.9),
]


def make_tf() -> TransferFunction:
    return TransferFunction(list(POINTS))


def small_volume() -> Volume:
    """Synthetic float volume, values roughly 20..80 (inside the TF's 0..100)."""
    data = np.random.default_rng(0).normal(50.0, 8.0, size=(24, 24, 16)).astype(np.float32)
    return Volume(data, name="noise")


@pytest.fixture
def editor(qtbot: Any) -> TransferFunctionEditor:
    ed = TransferFunctionEditor(make_tf())
    qtbot.addWidget(ed)
    ed.resize(640, 320)
    with qtbot.waitExposed(ed):
        ed.show()
    return ed


def record(editor: TransferFunctionEditor) -> list[TransferFunction]:
    got: list[TransferFunction] = []
    editor.transferFunctionChanged.connect(got.append)
    return got


def drag(qtbot: Any, editor: TransferFunctionEditor, start: QPoint, end: QPoint) -> None:
    """Press at ``start``, move in a few steps to ``end``, release there."""
    canvas = editor.canvas
    qtbot.mousePress(canvas, Qt.MouseButton.LeftButton, pos=start)
    for t in (0.25, 0.5, 0.75, 1.0):
        p = QPoint(
            round(start.x() + t * (end.x() - start.x())),
            round(start.y() + t * (end.y() - start.y())),
        )
        qtbot.mouseMove(canvas, pos=p)
    qtbot.mouseRelease(canvas, Qt.MouseButton.LeftButton, pos=end)


# ---------------------------------------------------------------------- mapping
def test_canvas_mapping_spans_the_plot(editor: TransferFunctionEditor) -> None:
    canvas = editor.canvas
    plot = canvas.plot_rect()
    assert plot.width() > 200
    assert plot.height() > 100
    assert canvas.view_range == (0.0, 100.0)  # no volume: the TF's own range
    first, last = editor.point_position(0), editor.point_position(3)
    assert first.x() == pytest.approx(plot.left())
    assert first.y() == pytest.approx(plot.bottom())  # opacity 0
    assert last.x() == pytest.approx(plot.right())
    assert last.y() == pytest.approx(plot.bottom() - 0.9 * plot.height())
    assert canvas.x_to_value(canvas.value_to_x(37.5)) == pytest.approx(37.5)
    assert canvas.y_to_opacity(canvas.opacity_to_y(0.3)) == pytest.approx(0.3)


# ---------------------------------------------------------------------- dragging
def test_drag_moves_point_and_emits(qtbot: Any, editor: TransferFunctionEditor) -> None:
    canvas = editor.canvas
    got = record(editor)
    p1 = editor.point_position(1)
    start = p1.toPoint()
    offset = p1 - QPointF(start)  # the point keeps its sub-pixel offset from the mouse
    # to the right (still left of point 2 at value 60) and up
    end = QPoint(round(canvas.value_to_x(52.0)), round(canvas.opacity_to_y(0.7)))
    drag(qtbot, editor, start, end)

    assert len(got) >= 1
    tf = editor.transfer_function
    assert got[-1] is tf
    v, r, g, b, a = tf.points[1]
    assert v == pytest.approx(canvas.x_to_value(end.x() + offset.x()))
    assert a == pytest.approx(canvas.y_to_opacity(end.y() + offset.y()))
    assert v == pytest.approx(52.0, abs=0.5)  # one pixel is < 0.2 in value here
    assert a == pytest.approx(0.7, abs=0.02)
    assert (r, g, b) == (1.0, 0.0, 0.0)  # colour kept
    assert tf.points[0] == POINTS[0]
    assert tf.points[2:] == POINTS[2:]
    assert canvas.selected == 1


def test_drag_past_neighbour_keeps_order(qtbot: Any, editor: TransferFunctionEditor) -> None:
    canvas = editor.canvas
    got = record(editor)
    start = editor.point_position(1).toPoint()
    # far right of point 2 (value 60) and above the plot (opacity > 1)
    end = QPoint(round(canvas.value_to_x(90.0)), round(canvas.plot_rect().top()) - 30)
    drag(qtbot, editor, start, end)

    assert got
    pts = editor.transfer_function.points
    values = [p[0] for p in pts]
    assert values == sorted(values)
    assert pts[1][0] == pytest.approx(60.0)  # stopped at its right neighbour
    assert pts[1][1:4] == (1.0, 0.0, 0.0)  # it is still the red point, at index 1
    assert pts[1][4] == 1.0  # opacity clamped
    assert pts[2] == POINTS[2]


def test_drag_endpoint_below_plot_clamps_to_zero(
    qtbot: Any, editor: TransferFunctionEditor
) -> None:
    canvas = editor.canvas
    start = editor.point_position(3).toPoint()
    end = QPoint(round(canvas.plot_rect().right()) + 40, round(canvas.plot_rect().bottom()) + 60)
    drag(qtbot, editor, start, end)
    last = editor.transfer_function.points[-1]
    assert last[0] == pytest.approx(100.0)  # cannot leave the view range
    assert last[4] == 0.0


# ---------------------------------------------------------------------- add / remove
def test_click_adds_point_with_interpolated_colour(
    qtbot: Any, editor: TransferFunctionEditor
) -> None:
    canvas = editor.canvas
    got = record(editor)
    pos = QPoint(round(canvas.value_to_x(20.0)), round(canvas.opacity_to_y(0.5)))
    old = make_tf()
    qtbot.mouseClick(canvas, Qt.MouseButton.LeftButton, pos=pos)

    pts = editor.transfer_function.points
    assert len(pts) == 5
    assert len(got) == 1
    v, r, g, b, a = pts[1]
    assert v == pytest.approx(canvas.x_to_value(pos.x()))
    assert a == pytest.approx(canvas.y_to_opacity(pos.y()))
    assert (r, g, b) == pytest.approx(tuple(old(v)[:3]))
    assert r == pytest.approx(v / 40.0)  # halfway-ish between black (0) and red (40)
    assert canvas.selected == 1


def test_right_click_removes_but_not_below_two(qtbot: Any, editor: TransferFunctionEditor) -> None:
    canvas = editor.canvas
    got = record(editor)
    qtbot.mouseClick(canvas, Qt.MouseButton.RightButton, pos=editor.point_position(1).toPoint())
    assert [p[0] for p in editor.transfer_function.points] == [0.0, 60.0, 100.0]
    qtbot.mouseClick(canvas, Qt.MouseButton.RightButton, pos=editor.point_position(1).toPoint())
    assert [p[0] for p in editor.transfer_function.points] == [0.0, 100.0]
    assert len(got) == 2
    qtbot.mouseClick(canvas, Qt.MouseButton.RightButton, pos=editor.point_position(0).toPoint())
    qtbot.mouseClick(canvas, Qt.MouseButton.RightButton, pos=editor.point_position(1).toPoint())
    assert [p[0] for p in editor.transfer_function.points] == [0.0, 100.0]
    assert len(got) == 2  # refused removals do not emit


def test_right_click_on_empty_space_does_nothing(
    qtbot: Any, editor: TransferFunctionEditor
) -> None:
    canvas = editor.canvas
    got = record(editor)
    pos = QPoint(round(canvas.value_to_x(20.0)), round(canvas.opacity_to_y(0.8)))
    qtbot.mouseClick(canvas, Qt.MouseButton.RightButton, pos=pos)
    assert editor.transfer_function.points == POINTS
    assert got == []


def test_added_point_removed_by_right_click(qtbot: Any, editor: TransferFunctionEditor) -> None:
    canvas = editor.canvas
    pos = QPoint(round(canvas.value_to_x(80.0)), round(canvas.opacity_to_y(0.3)))
    qtbot.mouseClick(canvas, Qt.MouseButton.LeftButton, pos=pos)
    assert len(editor.transfer_function.points) == 5
    qtbot.mouseClick(canvas, Qt.MouseButton.RightButton, pos=editor.point_position(3).toPoint())
    assert editor.transfer_function.points == POINTS


def test_delete_key_removes_selected_point(qtbot: Any, editor: TransferFunctionEditor) -> None:
    canvas = editor.canvas
    got = record(editor)
    qtbot.keyClick(canvas, Qt.Key.Key_Delete)  # nothing selected: nothing happens
    assert got == []
    qtbot.mouseClick(canvas, Qt.MouseButton.LeftButton, pos=editor.point_position(2).toPoint())
    assert canvas.selected == 2
    assert got == []  # selecting without moving is not an edit
    qtbot.keyClick(canvas, Qt.Key.Key_Delete)
    assert [p[0] for p in editor.transfer_function.points] == [0.0, 40.0, 100.0]
    assert canvas.selected is None
    assert len(got) == 1


def test_double_click_sets_colour(
    qtbot: Any, editor: TransferFunctionEditor, monkeypatch: pytest.MonkeyPatch
) -> None:
    asked: list[QColor] = []

    def fake_get_color(initial: QColor, *args: Any, **kwargs: Any) -> QColor:
        asked.append(QColor(initial))
        return QColor(0, 0, 255)

    monkeypatch.setattr(QColorDialog, "getColor", fake_get_color)
    got = record(editor)
    qtbot.mouseDClick(
        editor.canvas, Qt.MouseButton.LeftButton, pos=editor.point_position(2).toPoint()
    )
    assert len(asked) == 1
    assert asked[0].greenF() == pytest.approx(1.0)
    assert asked[0].redF() == pytest.approx(0.0)
    v, r, g, b, a = editor.transfer_function.points[2]
    assert (v, r, g, b, a) == (60.0, 0.0, 0.0, 1.0, 0.6)
    assert got
    assert got[-1] is editor.transfer_function


def test_cancelled_colour_dialog_changes_nothing(
    qtbot: Any, editor: TransferFunctionEditor, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(QColorDialog, "getColor", lambda *a, **k: QColor())  # invalid
    got = record(editor)
    qtbot.mouseDClick(
        editor.canvas, Qt.MouseButton.LeftButton, pos=editor.point_position(1).toPoint()
    )
    assert editor.transfer_function.points == POINTS
    assert got == []


# ---------------------------------------------------------------------- programmatic
def test_set_transfer_function_does_not_emit(editor: TransferFunctionEditor) -> None:
    got = record(editor)
    new = TransferFunction([(-50.0, 0, 0, 0, 0), (250.0, 1, 1, 1, 1)])
    editor.set_transfer_function(new)
    assert editor.transfer_function is new
    assert editor.canvas.view_range == (-50.0, 250.0)
    assert got == []


def test_set_volume_histogram_covers_union_of_ranges(qtbot: Any) -> None:
    vol = small_volume()
    ed = TransferFunctionEditor(TransferFunction([(30.0, 0, 0, 0, 0), (60.0, 1, 1, 1, 1)]))
    qtbot.addWidget(ed)
    got = record(ed)
    assert ed.canvas.histogram is None
    ed.set_volume(vol)
    dlo, dhi = vol.value_range
    assert dlo < 30.0
    assert dhi > 60.0
    assert ed.canvas.view_range == (dlo, dhi)
    counts, edges = ed.canvas.histogram
    assert counts.shape == (HISTOGRAM_BINS,)
    assert edges[0] == dlo
    assert edges[-1] == dhi
    assert counts.sum() == vol.data.size
    assert got == []
    # a TF wider than the data widens the range
    ed.set_transfer_function(TransferFunction([(-100.0, 0, 0, 0, 0), (60.0, 1, 1, 1, 1)]))
    assert ed.canvas.view_range == (-100.0, dhi)
    assert ed.canvas.histogram[1][0] == -100.0


def test_histogram_samples_at_most_the_cap() -> None:
    data = np.arange(40 * 40 * 40, dtype=np.float32).reshape(40, 40, 40)
    vol = Volume(data)
    counts, _edges = value_histogram(vol, 0.0, float(data.size), bins=16, max_samples=10_000)
    assert 5_000 <= counts.sum() <= 10_000
    # a regular stride over uniform values: every bin gets about the same share
    assert counts.max() - counts.min() <= 2
    full, _ = value_histogram(vol, 0.0, float(data.size), bins=16, max_samples=10**9)
    assert full.sum() == data.size


# ---------------------------------------------------------------------- presets
@pytest.mark.parametrize("name", ["hot", "ct-bone"])
def test_preset_combo_applies_preset(qtbot: Any, name: str) -> None:
    vol = small_volume()
    ed = TransferFunctionEditor(make_tf(), vol)
    qtbot.addWidget(ed)
    got = record(ed)
    ed.preset_combo.setCurrentText(name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # ct-bone warns: the volume is not HU
        expected = TransferFunction.preset(name, vol)
    assert ed.transfer_function.points == expected.points
    assert ed.transfer_function.name == name
    assert len(got) == 1
    assert got[0] is ed.transfer_function
    if name == "ct-bone":  # the rescaling warning is shown to the user, not lost
        assert ed.message.isVisibleTo(ed)
        assert "Hounsfield" in ed.message.text()
    else:
        assert not ed.message.isVisibleTo(ed)


def test_combo_lists_presets_and_follows_edits(qtbot: Any, editor: TransferFunctionEditor) -> None:
    combo = editor.preset_combo
    names = [combo.itemText(i) for i in range(combo.count())]
    assert names[: len(PRESETS) + 1] == ["custom", *PRESETS]  # then colour maps, see test_tf_import
    editor.set_transfer_function(TransferFunction.preset("mri"))
    assert combo.currentText() == "mri"
    qtbot.mouseClick(
        editor.canvas, Qt.MouseButton.RightButton, pos=editor.point_position(2).toPoint()
    )
    assert combo.currentText() == "custom"
    assert editor.transfer_function.name == "custom"


# ---------------------------------------------------------------------- files
def test_save_load_round_trip(editor: TransferFunctionEditor, tmp_path: Path) -> None:
    path = tmp_path / "sub" / "tf.json"
    tf = TransferFunction([(1.5, 0.1, 0.2, 0.3, 0.0), (7.25, 0.9, 0.8, 0.7, 0.4)], name="mine")
    editor.set_transfer_function(tf)
    assert editor.save_to(path)
    assert json.loads(path.read_text(encoding="utf-8")) == tf.to_dict()

    editor.set_transfer_function(make_tf())
    got = record(editor)
    assert editor.load_from(path)
    loaded = editor.transfer_function
    assert loaded.points == tf.points
    assert loaded.name == "mine"
    assert got == [loaded]  # loading is a user edit


def test_broken_file_warns_instead_of_raising(
    editor: TransferFunctionEditor, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    shown: list[tuple[str, str]] = []
    monkeypatch.setattr(
        QMessageBox, "warning", lambda parent, title, text, *a, **k: shown.append((title, text))
    )
    got = record(editor)
    bad = tmp_path / "broken.json"
    bad.write_text('{"points": [[0, 0, 0, 0, 0], ', encoding="utf-8")
    assert editor.load_from(bad) is False
    assert len(shown) == 1
    _title, text = shown[0]
    assert "broken.json" in text
    assert "cannot read" in text
    assert "Traceback" not in text
    assert editor.transfer_function.points == POINTS
    assert got == []

    invalid = tmp_path / "invalid.json"
    invalid.write_text(json.dumps({"points": [[0, 2.0, 0, 0, 0]]}), encoding="utf-8")
    assert editor.load_from(invalid) is False
    assert "[0, 1]" in shown[-1][1]
    assert editor.load_from(tmp_path / "missing.json") is False
    assert "missing.json" in shown[-1][1]
    assert len(shown) == 3


def test_save_error_warns(
    editor: TransferFunctionEditor, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    shown: list[str] = []
    monkeypatch.setattr(
        QMessageBox, "warning", lambda parent, title, text, *a, **k: shown.append(text)
    )
    blocker = tmp_path / "file"
    blocker.write_text("x", encoding="utf-8")
    assert editor.save_to(blocker / "tf.json") is False  # parent is a file
    assert len(shown) == 1
    assert "tf.json" in shown[0]


def test_buttons_use_file_dialogs(
    qtbot: Any, editor: TransferFunctionEditor, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    target = tmp_path / "saved"  # no suffix: .json is added
    monkeypatch.setattr(QFileDialog, "getSaveFileName", lambda *a, **k: (str(target), ""))
    qtbot.mouseClick(editor.save_button, Qt.MouseButton.LeftButton)
    saved = tmp_path / "saved.json"
    assert json.loads(saved.read_text(encoding="utf-8")) == make_tf().to_dict()

    other = TransferFunction([(5.0, 1, 0, 0, 0.1), (9.0, 0, 0, 1, 0.9)])
    other_path = tmp_path / "other.json"
    other_path.write_text(json.dumps(other.to_dict()), encoding="utf-8")
    monkeypatch.setattr(QFileDialog, "getOpenFileName", lambda *a, **k: (str(other_path), ""))
    qtbot.mouseClick(editor.load_button, Qt.MouseButton.LeftButton)
    assert editor.transfer_function.points == other.points

    monkeypatch.setattr(QFileDialog, "getOpenFileName", lambda *a, **k: ("", ""))  # cancelled
    qtbot.mouseClick(editor.load_button, Qt.MouseButton.LeftButton)
    assert editor.transfer_function.points == other.points


# ---------------------------------------------------------------------- painting
def test_render_with_histogram(qtbot: Any, tmp_path: Path) -> None:
    vol = small_volume()
    ed = TransferFunctionEditor(make_tf(), vol)
    qtbot.addWidget(ed)
    ed.resize(640, 320)
    with qtbot.waitExposed(ed):
        ed.show()
    ed.canvas._set_selected(2)
    out = tmp_path / "tf_editor.png"
    assert ed.grab().save(str(out))
    img = QImage(str(out))
    assert img.width() >= 600

    canvas = ed.canvas
    shot = canvas.grab().toImage()
    plot = canvas.plot_rect()
    dpr = shot.devicePixelRatio()

    def pixel(x: float, y: float) -> QColor:
        return shot.pixelColor(round(x * dpr), round(y * dpr))

    # histogram: grey near the bottom at the data's mode (50), plain background far out
    near_bottom = plot.bottom() - 3
    hist = pixel(canvas.value_to_x(48.0), near_bottom)
    empty = pixel(canvas.value_to_x(99.0), plot.top() + 3)
    assert hist.value() > empty.value() + 20
    # colour bar: black at value 0, green at 60, white at 100
    bar = canvas.bar_rect()
    yb = bar.center().y()
    assert pixel(canvas.value_to_x(1.0), yb).value() < 20
    green = pixel(canvas.value_to_x(60.0), yb)
    assert green.green() > 200
    assert green.red() < 60
    assert green.blue() < 60
    assert pixel(canvas.value_to_x(99.0), yb).lightness() > 230
    # the selected point (green) is drawn at its position
    c = canvas.point_position(2)
    disc = pixel(c.x(), c.y())
    assert disc.green() > 200
    assert disc.red() < 60
