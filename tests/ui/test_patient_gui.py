"""The GUI for patient coordinates (issue 16): orientation marker, anatomical views,
window controls only where they act, one fps readout, docks that fit at 1280x800,
clip and placement controls in patient mm with orientation letters.

Panels are tested against the fake window of ``test_panels``; the rest in a real main
window (Xvfb, see conftest) at 1280x800 over an in-memory RAS volume.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import pytest
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QApplication, QLabel

from tests.render.test_orientation_marker import find_letter
from tests.ui.test_panels import TF, FakeWindow, make_panel
from tests.ui.windows import press_shortcut, shown_window
from voxwarp.core.camera import view_rotation
from voxwarp.core.orientation import ANATOMICAL_VIEWS
from voxwarp.core.volume import Volume
from voxwarp.editing.session import EditSession
from voxwarp.render.orientation_marker import AXIS_COLORS, marker_layout
from voxwarp.scene import MODES, Scene
from voxwarp.ui.panels import DeformationPanel, VolumePanel, window_acts

#: the modes whose shaders read the grey-value window (mode_*.glsl: window_gray)
WINDOW_MODES = {"mip", "minip", "average", "xray"}
SIZE = (1280, 800)


def volume(space: str = "RAS", shape: tuple[int, int, int] = (16, 16, 12)) -> Volume:
    """A ramp along x, spacing (2, 1, 1) mm, origin (-20, 5, -7): its box is x -21..11,
    y 4.5..20.5, z -7.5..4.5 mm."""
    x = np.linspace(0.0, 100.0, shape[0], dtype=np.float32)
    data = np.broadcast_to(x[:, None, None], shape).copy()
    return Volume(data, spacing=(2.0, 1.0, 1.0), origin=(-20.0, 5.0, -7.0), space=space)


def session(space: str = "RAS", **scene: Any) -> EditSession:
    return EditSession(Scene(volume(space), transfer_function=TF, **scene))


# ---------------------------------------------------------------------- panels
def test_window_acts_in_the_modes_whose_shader_reads_it() -> None:
    assert {m for m in MODES if window_acts(m)} == WINDOW_MODES & set(MODES)
    assert not window_acts("dvr")
    assert not window_acts("no-such-mode")


def test_window_controls_only_where_they_act(qtbot: Any) -> None:
    window = FakeWindow(session())
    panel = make_panel(qtbot, window, VolumePanel)
    assert window.session.scene.mode == "dvr"
    assert not panel.level_spin.isEnabled()
    assert not panel.width_spin.isEnabled()
    assert "acts in mip" in panel.window_label.toolTip()
    for mode in MODES:
        panel.mode_combo.setCurrentText(mode)
        assert window.session.scene.mode == mode
        acts = mode in WINDOW_MODES
        assert panel.level_spin.isEnabled() is acts, mode
        assert panel.width_spin.isEnabled() is acts, mode
    # an undo (a refresh from the session) follows too
    window.session.scene.mode = "mip"
    window.refresh_panels()
    assert panel.level_spin.isEnabled()
    window.session.scene.mode = "dvr"
    window.refresh_panels()
    assert not panel.width_spin.isEnabled()


def test_clip_controls_show_patient_letters_in_world_mm(qtbot: Any) -> None:
    window = FakeWindow(session("RAS"))
    panel = make_panel(qtbot, window, VolumePanel)
    assert [label.text() for label in panel.clip_labels] == ["L–R", "P–A", "I–S"]
    lo, hi = window.session.volume.bounds  # the world (RAS) box
    np.testing.assert_allclose(lo, (-21.0, 4.5, -7.5))
    for a in range(3):
        assert panel.clip_spins[a][0].minimum() == pytest.approx(lo[a])
        assert panel.clip_spins[a][1].maximum() == pytest.approx(hi[a])
    x_lo, x_hi = panel.clip_spins[0]
    assert x_lo.text() == "L 21.00 mm"  # x = -21: 21 mm towards the patient's left
    assert x_hi.text() == "R 11.00 mm"
    assert panel.clip_spins[1][0].text() == "A 4.50 mm"  # y = +4.5: anterior
    assert panel.clip_spins[2][1].text() == "S 4.50 mm"
    # the value stays the signed world coordinate: clipping to x >= -3 ("L 3")
    panel.clip_check.setChecked(True)
    with qtbot.waitExposed(panel):
        panel.show()
    for typed, expected in (("L 3", -3.0), ("r 2.5", 2.5), ("-4", -4.0)):
        x_lo.setFocus()
        x_lo.selectAll()
        qtbot.keyClicks(x_lo, typed)
        qtbot.keyClick(x_lo, Qt.Key.Key_Return)
        assert window.session.scene.clip_box[0][0] == pytest.approx(expected), typed
    assert x_lo.text() == "L 4.00 mm"
    # a letter of another axis is refused as it is typed
    x_lo.selectAll()
    qtbot.keyClicks(x_lo, "A")
    assert x_lo.lineEdit().text() == "L 4.00 mm"
    qtbot.keyClick(x_lo, Qt.Key.Key_Return)
    assert window.session.scene.clip_box[0][0] == pytest.approx(-4.0)
    assert window.errors == []


def test_clip_controls_of_an_unoriented_volume_say_x_y_z(qtbot: Any) -> None:
    window = FakeWindow(session(""))
    panel = make_panel(qtbot, window, VolumePanel)
    assert [label.text() for label in panel.clip_labels] == ["x", "y", "z"]
    assert panel.clip_spins[0][0].text() == "-21.00 mm"
    assert "no patient orientation" in panel.info_label.text()
    # opening an oriented volume brings the letters
    window.session = session("RAS")
    window.refresh_panels()
    assert panel.clip_labels[0].text() == "L–R"
    assert panel.clip_spins[0][0].text() == "L 21.00 mm"
    assert "patient RAS" in panel.info_label.text()


def test_placement_controls_show_patient_letters(qtbot: Any) -> None:
    window = FakeWindow(session("RAS"))
    window.session.set_deformation("chainmail", resolution=3)
    panel = make_panel(qtbot, window, DeformationPanel)
    assert [label.text() for label in panel.placement_labels] == ["L–R", "P–A", "I–S"]
    panel.translate_spins[0].setValue(-5.0)
    assert window.session.placement.translate == (-5.0, 0.0, 0.0)
    assert panel.translate_spins[0].text() == "L 5.0"
    panel.translate_spins[1].setValue(2.0)
    assert panel.translate_spins[1].text() == "A 2.0"
    window.session = session("")
    window.session.set_deformation("chainmail", resolution=3)
    window.refresh_panels()
    assert [label.text() for label in panel.placement_labels] == ["x", "y", "z"]


# ---------------------------------------------------------------------- main window
@pytest.fixture
def window(qtbot: Any, monkeypatch: pytest.MonkeyPatch) -> Any:
    """A main window of 1280x800 on a RAS volume (anterior view), first frame drawn."""
    vol = volume("RAS", shape=(32, 32, 32))
    session = EditSession(Scene(vol, transfer_function=TF, view="+y", jitter=False))
    w = shown_window(qtbot, monkeypatch, session, SIZE, active=True)
    settle()
    yield w
    w.close()


def settle(seconds: float = 0.3) -> None:
    """Let queued layout work (the docks' first sizes) and repaints run."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        QApplication.processEvents()
        time.sleep(0.01)


def marker_corner(w: Any) -> np.ndarray:
    """The viewport's frame (RGB), drawn now, cropped to the marker's corner."""
    img = w.viewport.screenshot()[..., :3]
    side = w.viewport.marker_image().shape[0]
    return np.ascontiguousarray(img[-side:, :side])


def has_color(img: np.ndarray, rgb: tuple[int, int, int]) -> bool:
    return bool(np.any(np.all(np.abs(img.astype(int) - rgb) <= 1, axis=-1)))


def test_clipping_group_is_visible_at_1280x800(window: Any) -> None:
    w = window
    assert (w.width(), w.height()) == SIZE
    panel = w.volume_panel
    group = panel.clip_group
    assert w.docks["Volume"].isVisible()
    assert group.isVisible()
    # no scrolling needed: the whole group lies inside the scroll area's viewport
    scroll = panel._scroll
    assert scroll.verticalScrollBar().value() == 0
    top_left = group.mapTo(scroll.viewport(), group.rect().topLeft())
    bottom_right = group.mapTo(scroll.viewport(), group.rect().bottomRight())
    assert scroll.viewport().rect().contains(top_left)
    assert scroll.viewport().rect().contains(bottom_right)
    assert group.visibleRegion().boundingRect().size() == group.size()
    # and its last row of spin boxes is inside the window
    last = panel.clip_spins[2][1]
    bottom = last.mapTo(w, last.rect().bottomRight())
    assert 0 < bottom.y() < w.height()
    # the transfer function editor keeps a usable height below it
    assert w.docks["Transfer function"].height() >= 250


def test_one_fps_readout(window: Any, qtbot: Any) -> None:
    w = window
    n = w.viewport.frames_drawn
    w.viewport.update()
    qtbot.waitUntil(lambda: w.viewport.frames_drawn > n, timeout=30000)
    settle(0.1)
    readouts = [label for label in w.findChildren(QLabel) if "fps" in label.text()]
    assert readouts == [w.fps_label]
    assert "frame" in w.fps_label.text()


def test_window_controls_in_the_real_window(window: Any) -> None:
    panel = window.volume_panel
    assert window.session.scene.mode == "dvr"
    assert not panel.level_spin.isEnabled()
    panel.mode_combo.setCurrentText("mip")
    assert panel.level_spin.isEnabled()
    assert panel.width_spin.isEnabled()
    window.undo_stack.undo()
    assert window.session.scene.mode == "dvr"
    assert not panel.width_spin.isEnabled()


def test_marker_in_the_viewport_and_its_toggle(window: Any) -> None:
    w = window
    texts = [a.text().replace("&", "") for a in w.menuBar().actions()]
    view_menu = w.menuBar().actions()[texts.index("View")].menu()
    assert w.marker_action in view_menu.actions()
    assert w.marker_action.isChecked()
    corner = marker_corner(w)
    assert has_color(corner, AXIS_COLORS[0])
    assert has_color(corner, AXIS_COLORS[2])
    # anterior view of a RAS volume: R on the left of the marker's centre, S above it
    lay = marker_layout(w.viewport.camera, True, corner.shape[1::-1])
    r, s = find_letter(corner, "R", lay.scale), find_letter(corner, "S", lay.scale)
    assert r is not None
    assert s is not None
    assert r[0] < lay.center[0] - lay.length
    assert s[1] < lay.center[1] - lay.length
    w.marker_action.trigger()
    assert not w.viewport.show_marker
    corner = marker_corner(w)
    assert not has_color(corner, AXIS_COLORS[0])
    assert not has_color(corner, AXIS_COLORS[2])
    w.marker_action.trigger()
    assert has_color(marker_corner(w), AXIS_COLORS[0])


@pytest.mark.parametrize(
    ("key", "view"),
    [
        (Qt.Key.Key_A, "anterior"),
        (Qt.Key.Key_P, "posterior"),
        (Qt.Key.Key_L, "left"),
        (Qt.Key.Key_R, "right"),
        (Qt.Key.Key_S, "superior"),
        (Qt.Key.Key_I, "inferior"),
    ],
)
def test_anatomical_view_keys(
    window: Any, qtbot: Any, monkeypatch: pytest.MonkeyPatch, key: Any, view: str
) -> None:
    w = window
    assert w.anatomical_view_actions[view].isEnabled()
    steps: list[int] = []
    monkeypatch.setattr(w, "single_step", lambda: steps.append(1))
    w.viewport.set_view("+x" if view != "right" else "-x")  # start elsewhere
    press_shortcut(qtbot, w, key, Qt.KeyboardModifier.ShiftModifier)
    np.testing.assert_allclose(
        w.viewport.camera.rotation, view_rotation(ANATOMICAL_VIEWS[view]), atol=1e-12
    )
    assert steps == []  # Shift+S is the superior view, not S's single step


def test_inferior_view_marker_is_radiological(window: Any) -> None:
    w = window
    w.anatomical_view_actions["inferior"].trigger()
    corner = marker_corner(w)
    lay = marker_layout(w.viewport.camera, True, corner.shape[1::-1])
    a, r = find_letter(corner, "A", lay.scale), find_letter(corner, "R", lay.scale)
    assert a is not None
    assert r is not None
    assert a[1] < lay.center[1] - lay.length  # anterior up
    assert r[0] < lay.center[0] - lay.length  # the patient's right on the image's left


def test_unoriented_volume_has_no_anatomical_views(window: Any, qtbot: Any) -> None:
    w = window
    w.set_session(session("", view="+z"))
    settle()
    assert not any(a.isEnabled() for a in w.anatomical_view_actions.values())
    assert w.axis_view_actions["+y"].text() == "View from +y"
    before = w.viewport.camera.rotation.copy()
    w.set_anatomical_view("anterior")
    np.testing.assert_array_equal(w.viewport.camera.rotation, before)
    assert "no patient orientation" in w.statusBar().currentMessage()
    # the marker says x y z
    corner = marker_corner(w)
    lay = marker_layout(w.viewport.camera, False, corner.shape[1::-1])
    assert find_letter(corner, "R", lay.scale) is None
    x_at = find_letter(corner, "x", lay.scale)
    assert x_at is not None
    assert x_at[0] > lay.center[0] + lay.length  # +z view: +x to the right
    # back to an oriented volume: enabled, axis views named by the side
    w.set_session(session("RAS"))
    assert all(a.isEnabled() for a in w.anatomical_view_actions.values())
    assert w.axis_view_actions["+y"].text() == "View from +y (anterior)"
