"""The linked slice views in the real window (Xvfb, see conftest): a click sets the
crosshair in all views, the wheel scrolls by one voxel spacing, a right drag changes the
window, a handle dragged in a slice moves in that plane (undoably), the layouts, and the
readout's values.

Events go through Qt (``qtbot``) to the :class:`~voxwarp.ui.slice_view.SliceView`
widgets; their images are the slices' own colours (``SliceView.image.rgba``)."""

from __future__ import annotations

import re
from typing import Any

import numpy as np
import pytest
from PySide6.QtCore import QPoint, QPointF, Qt
from PySide6.QtGui import QWheelEvent
from PySide6.QtWidgets import QApplication

from tests.ui.windows import press_shortcut, shown_window
from voxwarp.core.volume import Volume
from voxwarp.editing.session import EditSession
from voxwarp.editing.slice_views import handles_near
from voxwarp.scene import Scene

SIZE = (1200, 800)
SPACING = (1.5, 1.0, 0.8)


def _session() -> EditSession:
    """A small RAS volume of distinct integer values (smooth along the axes, so a
    slice is not noise)."""
    i, j, k = np.meshgrid(np.arange(40), np.arange(36), np.arange(32), indexing="ij")
    data = (i * 3 + j * 2 + k * 5 + (i * j) % 7).astype(np.float32)
    vol = Volume(data, SPACING, (-30.0, -18.0, -12.0), name="ramp", space="RAS")
    return EditSession(Scene(vol, mode="mip", zoom=1.2, jitter=False))


@pytest.fixture
def window(qtbot: Any, monkeypatch: pytest.MonkeyPatch) -> Any:
    w = shown_window(qtbot, monkeypatch, _session(), SIZE, active=True, layout="2x2")
    qtbot.waitUntil(lambda: all(v.image is not None for v in w.mpr.views), timeout=30000)
    yield w
    w.close()


def settle(w: Any) -> None:
    """Deliver the queued redraws (the slices follow the 3D view's frames)."""
    for _ in range(5):
        QApplication.processEvents()


def point(xy: np.ndarray) -> QPoint:
    return QPoint(round(float(xy[0])), round(float(xy[1])))


def wheel(widget: Any, pos: QPoint, notches: int, ctrl: bool = False, shift: bool = False) -> None:
    mods = Qt.KeyboardModifier.NoModifier
    if ctrl:
        mods |= Qt.KeyboardModifier.ControlModifier
    if shift:
        mods |= Qt.KeyboardModifier.ShiftModifier
    event = QWheelEvent(
        QPointF(pos),
        QPointF(widget.mapToGlobal(pos)),
        QPoint(0, 0),
        QPoint(0, 120 * notches),
        Qt.MouseButton.NoButton,
        mods,
        Qt.ScrollPhase.NoScrollPhase,
        False,
    )
    QApplication.sendEvent(widget, event)


def test_click_in_one_view_moves_the_crosshair_in_all(window: Any, qtbot: Any) -> None:
    w = window
    axial, coronal, sagittal = w.mpr.views
    assert [v.name for v in w.mpr.views] == ["axial", "coronal", "sagittal"]
    renders = [v.renders for v in w.mpr.views]
    inside = w.session.volume.index_to_world(np.array([28.0, 30.0, 16.0]))
    pos = point(axial.to_widget(inside[None])[0])
    target = axial.world_at(pos.x(), pos.y())
    qtbot.mouseClick(axial, Qt.MouseButton.LeftButton, pos=pos)
    settle(w)
    np.testing.assert_allclose(w.mpr.state.crosshair, target, atol=1e-9)
    for view in (coronal, sagittal):
        plane = view.plane()
        assert abs((target - plane.center) @ plane.normal) < 1e-9
        # the crosshair is drawn where the click was in the clicked view and on the
        # other planes' lines in theirs
        assert view.renders > renders[w.mpr.views.index(view)]
    np.testing.assert_allclose(axial.to_widget(target[None])[0], [pos.x(), pos.y()], atol=1e-6)
    # the clicked view's own plane stays where it was (a click moves the others)
    assert axial.plane().position == pytest.approx(target[2])
    # radiological: the patient's right (+x in RAS) on the image's left, anterior up
    assert pos.x() < axial.width() / 2
    assert pos.y() < axial.height() / 2


def test_wheel_scrolls_one_voxel_spacing(window: Any) -> None:
    w = window
    for index, axis in ((0, 2), (1, 1), (2, 0)):
        view = w.mpr.views[index]
        before = w.mpr.state.crosshair.copy()
        old = view.plane().position
        wheel(view, QPoint(view.width() // 2, view.height() // 2), 1)
        settle(w)
        moved = w.mpr.state.crosshair - before
        assert moved[axis] == pytest.approx(SPACING[axis])
        assert np.count_nonzero(moved) == 1
        assert view.plane().position == pytest.approx(old + SPACING[axis])
    # Ctrl + wheel zooms instead (the plane stays)
    view = w.mpr.views[0]
    before, height = w.mpr.state.crosshair.copy(), view.plane().height_mm
    wheel(view, QPoint(20, 20), 2, ctrl=True)
    np.testing.assert_array_equal(w.mpr.state.crosshair, before)
    assert view.plane().height_mm < height / 1.2


def test_right_drag_changes_the_window_and_the_grey_values(window: Any, qtbot: Any) -> None:
    w = window
    view = w.mpr.views[1]
    before_window = w.mpr.state.window
    before = [v.image.rgba.copy() for v in w.mpr.views]
    values = view.image.values.copy()
    renders = [v.renders for v in w.mpr.views]
    start = QPoint(view.width() // 2, view.height() // 2)
    qtbot.mousePress(view, Qt.MouseButton.RightButton, pos=start)
    for k in range(1, 5):
        qtbot.mouseMove(view, start + QPoint(-15 * k, 10 * k))
    qtbot.mouseRelease(view, Qt.MouseButton.RightButton, pos=start + QPoint(-60, 40))
    level, width = w.mpr.state.window
    assert width < before_window[1]  # dragged left: a narrower window
    assert level > before_window[0]  # dragged down: a higher level
    for v, old in zip(w.mpr.views, before, strict=True):
        changed = np.mean(np.any(v.image.rgba != old, axis=-1))
        assert changed > 0.2, f"{v.name}: only {changed:.1%} of the pixels changed"
    # a window drag only re-colours: no slice drawn again, the values as they were
    assert [v.renders for v in w.mpr.views] == renders
    np.testing.assert_array_equal(view.image.values, values)


def test_dragging_an_element_in_the_axial_view_moves_it_in_that_plane(
    window: Any, qtbot: Any
) -> None:
    w = window
    w.edit("New mass-spring", lambda: w.session.set_deformation("massspring", resolution=5))
    axial = w.mpr.views[0]
    pts = w.session.handles().copy()
    w.mpr.state.set_crosshair(pts[len(pts) // 2])  # a layer of elements on the plane
    w.mpr.planes_changed()
    plane = axial.plane()
    near = handles_near(pts, plane, axial.size_px())
    assert len(near) == 25  # one 5 x 5 layer of the grid
    xy = axial.to_widget(pts[near], plane)
    centre = np.array(axial.size_px()) / 2
    i = int(near[np.argmin(np.hypot(*(xy - centre).T))])
    start = point(axial.to_widget(pts[i : i + 1], plane)[0])
    qtbot.mousePress(axial, Qt.MouseButton.LeftButton, pos=start)
    for k in range(1, 5):
        qtbot.mouseMove(axial, start + QPoint(10 * k, -5 * k))
    qtbot.mouseRelease(axial, Qt.MouseButton.LeftButton, pos=start + QPoint(40, -20))
    assert w.session.selection == [i]
    moved = w.session.handles()[i] - pts[i]
    px = plane.pixel_mm(axial.size_px())
    expected = 40 * px * plane.right + 20 * px * plane.up
    np.testing.assert_allclose(moved, expected, atol=1e-6)
    assert moved @ plane.normal == pytest.approx(0.0, abs=1e-9)  # in the plane
    # the window's undo flow: one "Drag" step that undo takes back exactly
    assert w.undo_stack.undoText().startswith("Drag")
    w.undo_action.trigger()
    np.testing.assert_allclose(w.session.handles()[i], pts[i], atol=1e-12)
    # the click position did not move the crosshair: the press picked the handle
    assert abs((w.mpr.state.crosshair - pts[len(pts) // 2]) @ plane.normal) < 1e-9


def test_slices_follow_the_running_simulation(window: Any, qtbot: Any) -> None:
    w = window
    w.edit("New mass-spring", lambda: w.session.set_deformation("massspring", resolution=5))
    session = w.session
    pts = session.handles()
    i = len(pts) // 2
    w.mpr.state.set_crosshair(pts[i])
    w.mpr.planes_changed()
    qtbot.waitUntil(lambda: w.mpr.views[0].image is not None)
    before = w.mpr.views[0].image.values.copy()
    session.select([i])
    cam = w.mpr.views[0].plane().camera()
    size = w.mpr.views[0].size_px()
    xy = cam.project(pts[i : i + 1], size)[0]
    session.begin_drag(cam, size, xy)
    session.drag_to(xy + np.array([30.0, 0.0]))
    session.end_drag()
    w.set_running(True)
    view = w.mpr.views[0]
    renders = view.renders
    qtbot.waitUntil(lambda: view.renders >= renders + 3, timeout=30000)
    # while the model moves the slices are drawn at half resolution, then in full
    live = view.image.values.shape
    assert live[0] < 0.6 * before.shape[0]
    w.set_running(False)
    qtbot.waitUntil(lambda: view.image.values.shape == before.shape, timeout=30000)
    after = view.image.values
    changed = np.mean(np.abs(np.nan_to_num(after) - np.nan_to_num(before)) > 1)
    assert changed > 0.01, f"only {changed:.2%} of the slice changed"


def test_layout_switch_hides_and_shows_the_slices(window: Any, qtbot: Any) -> None:
    w = window
    views = w.mpr.views
    assert all(v.isVisible() for v in views)
    assert len(w.mpr.state.outline_layers()) == 3
    assert len(w.mpr._outlines(w.viewport.display)) == 3
    press_shortcut(qtbot, w, Qt.Key.Key_3, Qt.KeyboardModifier.ControlModifier)
    assert w.mpr.state.layout == "3d"
    assert not any(v.isVisible() for v in views)
    assert w.mpr._outlines(w.viewport.display) == []  # no planes drawn in 3D alone
    assert w.layout_actions["3d"].isChecked()
    press_shortcut(qtbot, w, Qt.Key.Key_2, Qt.KeyboardModifier.ControlModifier)
    qtbot.waitUntil(lambda: all(v.isVisible() for v in views))
    settle(w)
    xs = {v.geometry().x() for v in views}
    assert len(xs) == 1  # one column
    assert w.viewport.width() > 2 * views[0].width()
    assert w.slice_controls["layout"].currentText() == "1x3"
    press_shortcut(qtbot, w, Qt.Key.Key_1, Qt.KeyboardModifier.ControlModifier)
    settle(w)
    assert len({v.geometry().x() for v in views}) == 2  # four-up: two columns
    assert w.layout_actions["2x2"].isChecked()


def test_readout_shows_the_array_value_under_the_cursor(window: Any, qtbot: Any) -> None:
    w = window
    w.mpr.set_option("interpolation", "nearest")
    vol = w.session.volume
    view = w.mpr.views[2]  # sagittal
    for index in ((20, 10, 7), (20, 25, 20), (20, 3, 28)):
        world = vol.index_to_world(np.asarray(index, float))
        w.mpr.state.set_crosshair(world)
        w.mpr.planes_changed()
        pos = point(view.to_widget(world[None])[0])
        qtbot.mouseMove(view, pos)
        qtbot.waitUntil(lambda: view._hover is not None)
        text = view.readout_text()
        value = float(vol.data[index])
        got = re.search(r"deformed (\S+)\s+rest (\S+)", text)
        assert got is not None, text
        assert float(got.group(1)) == value, text
        assert float(got.group(2)) == value, text
        sign = {"R": 1, "L": -1, "A": 1, "P": -1, "S": 1, "I": -1}
        found = re.findall(r"([RLAPSI]) ([\d.]+)", text)
        r, a, s = (sign[letter] * float(v) for letter, v in found)
        hovered = view.world_at(pos.x(), pos.y())
        np.testing.assert_allclose([r, a, s], hovered, atol=0.051)


def test_shift_wheel_tilts_a_plane_through_the_crosshair(window: Any) -> None:
    w = window
    axial, coronal, _ = w.mpr.views
    crosshair = w.mpr.state.crosshair.copy()
    wheel(axial, QPoint(30, 30), 3, shift=True)  # 15 degrees about the view's vertical
    plane = axial.plane()
    assert plane.name == "oblique"
    assert np.degrees(np.arccos(abs(plane.normal[2]))) == pytest.approx(15.0)
    assert abs((crosshair - plane.center) @ plane.normal) < 1e-9
    np.testing.assert_array_equal(w.mpr.state.crosshair, crosshair)
    # the coronal view draws the tilted plane's line through the crosshair, tilted
    line = np.cross(coronal.plane().normal, plane.normal)
    assert abs(line @ coronal.plane().up) > 0.2
    w.mpr.reset()
    assert axial.plane().name == "axial"


def test_opening_another_volume_gives_its_planes(window: Any, qtbot: Any) -> None:
    w = window
    vol = Volume(np.random.default_rng(0).random((24, 20, 16), dtype=np.float32), (1, 1, 2))
    w.set_session(EditSession(Scene(vol, jitter=False)))
    assert w.mpr.state.names == ("z", "y", "x")
    renders = w.mpr.views[0].renders
    qtbot.waitUntil(lambda: w.mpr.views[0].renders > renders, timeout=30000)
    assert w.mpr.views[0].image.values.shape[::-1] == w.mpr.views[0].size_px()
    assert np.nanmax(w.mpr.views[0].image.values) <= 1.0
