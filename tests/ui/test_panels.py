"""Tests of voxwarp.ui.panels against a fake main window over a real EditSession.

The fake window implements the window contract the panels code against (see the module
docstring of ``voxwarp.ui.panels``): it records every ``edit`` (text and merge key), runs the
edit's function, turns VoxwarpErrors into recorded errors (the real window shows them
in a dialog) and refreshes its panels afterwards, as the real window does. Wire builds
run synchronously here.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QTreeWidgetItem, QWidget

from voxwarp.core.mesh import MeshInstance, box_mesh
from voxwarp.core.volume import Volume
from voxwarp.editing.families.wires import WiresFamily
from voxwarp.editing.session import (
    DEFORMATIONS,
    DisplayOptions,
    EditorError,
    EditSession,
    Placement,
)
from voxwarp.errors import VoxwarpError
from voxwarp.scene import MODES, Scene
from voxwarp.ui.family_panels.wires import wire_of_handle
from voxwarp.ui.panels import (
    DeformationPanel,
    DisplayPanel,
    ScenePanel,
    VolumePanel,
)

TF = [(0.0, 0.0, 0.0, 0.0, 0.0), (100.0, 1.0, 1.0, 1.0, 1.0)]


def make_session(shape: tuple[int, int, int] = (16, 16, 12), name: str = "ramp") -> EditSession:
    """A session over a float ramp 0..100 along x, spacing (1, 1, 2) mm."""
    x = np.linspace(0.0, 100.0, shape[0], dtype=np.float32)
    data = np.broadcast_to(x[:, None, None], shape).copy()
    vol = Volume(data, spacing=(1.0, 1.0, 2.0), name=name)
    return EditSession(Scene(vol, transfer_function=TF))


class FakeViewport:
    """What the panels use of the viewport."""

    def __init__(self) -> None:
        self.display = DisplayOptions()
        self.updates = 0

    def update(self) -> None:
        self.updates += 1


class FakeStatusBar:
    """What the panels use of the window's status bar: the messages shown."""

    def __init__(self) -> None:
        self.messages: list[str] = []

    def showMessage(self, text: str, timeout: int = 0) -> None:
        self.messages.append(text)

    def currentMessage(self) -> str:
        return self.messages[-1] if self.messages else ""


class FakeWindow:
    """The main-window contract of voxwarp.ui.panels, recording what the panels ask for."""

    def __init__(self, session: EditSession) -> None:
        self.session = session
        self.viewport = FakeViewport()
        self.panels: list[Any] = []
        self.edits: list[tuple[str, str | None]] = []
        self.errors: list[VoxwarpError] = []
        self.refreshes = 0
        self.scene_changes = 0
        self.wire_builds = 0
        self.running: list[bool] = []
        self.opens = 0
        self.status = FakeStatusBar()

    def statusBar(self) -> FakeStatusBar:
        return self.status

    def add(self, panel: Any) -> Any:
        self.panels.append(panel)
        return panel

    def refresh_panels(self) -> None:
        self.refreshes += 1
        for p in self.panels:
            p.refresh()

    def edit(self, text: str, fn: Callable[[], Any], merge: str | None = None) -> Any:
        self.edits.append((text, merge))
        try:
            result = fn()
        except VoxwarpError as exc:
            self.errors.append(exc)
            result = None
        self.refresh_panels()
        return result

    def scene_changed(self) -> None:
        self.scene_changes += 1

    def request_field_build(self) -> None:
        self.wire_builds += 1
        if self.session.family.field_stale:
            job = self.session.family.build_job()
            job.run()
            assert self.session.family.install(job)

    def set_running(self, running: bool) -> None:
        self.running.append(running)
        self.session.set_option("running", running)
        self.refresh_panels()

    def open_file_dialog(self) -> None:
        self.opens += 1


@pytest.fixture
def window() -> FakeWindow:
    return FakeWindow(make_session())


def make_panel(qtbot: Any, window: FakeWindow, cls: type[QWidget]) -> Any:
    panel = cls(window)
    qtbot.addWidget(panel)
    window.add(panel)
    return panel


def click(qtbot: Any, button: QWidget) -> None:
    assert button.isEnabled(), f"{button.text()!r} is disabled"
    qtbot.mouseClick(button, Qt.MouseButton.LeftButton)


# ---------------------------------------------------------------------------- volume
def test_volume_panel_shows_the_volume(qtbot: Any, window: FakeWindow) -> None:
    panel = make_panel(qtbot, window, VolumePanel)
    text = panel.info_label.text()
    assert "ramp" in text
    assert "16×16×12 voxels" in text
    assert "1×1×2 mm" in text
    assert "no patient orientation" in text
    assert [panel.mode_combo.itemText(i) for i in range(panel.mode_combo.count())] == list(MODES)
    assert window.edits == []


def test_mode_combo_sets_the_mode_through_edit(qtbot: Any, window: FakeWindow) -> None:
    panel = make_panel(qtbot, window, VolumePanel)
    assert window.session.scene.mode == "dvr"
    panel.mode_combo.setCurrentText("mip")
    assert window.session.scene.mode == "mip"
    assert window.edits == [("Mode mip", None)]
    assert window.scene_changes == 1


def test_sample_distance_spin_edits_with_a_merge_key(qtbot: Any, window: FakeWindow) -> None:
    panel = make_panel(qtbot, window, VolumePanel)
    panel.step_spin.setValue(2.5)
    assert window.session.scene.step == pytest.approx(2.5)
    # typed values count once typing is finished (Enter), not per keystroke
    with qtbot.waitExposed(panel):
        panel.show()
    panel.step_spin.setFocus()
    panel.step_spin.selectAll()
    qtbot.keyClicks(panel.step_spin, "0.5")
    assert window.session.scene.step == pytest.approx(2.5)
    qtbot.keyClick(panel.step_spin, Qt.Key.Key_Return)
    assert window.session.scene.step == pytest.approx(0.5)
    assert window.edits == [("Sample distance", "sample distance")] * 2
    assert window.scene_changes == 2


def test_window_shading_jitter_projection(qtbot: Any, window: FakeWindow) -> None:
    panel = make_panel(qtbot, window, VolumePanel)
    scene = window.session.scene
    panel.width_spin.setValue(20.0)
    assert scene.window[1] == pytest.approx(20.0)
    panel.level_spin.setValue(30.0)
    assert scene.window == pytest.approx((30.0, 20.0))
    assert [m for _, m in window.edits] == ["window", "window"]
    panel.shading_combo.setCurrentText("off")
    assert scene.shading is False
    panel.shading_combo.setCurrentText("auto")
    assert scene.shading is None
    jitter = scene.jitter
    panel.jitter_check.setChecked(not jitter)
    assert scene.jitter is (not jitter)
    panel.projection_combo.setCurrentText("orthographic")
    assert scene.projection == "orthographic"
    assert window.errors == []


def test_clip_box(qtbot: Any, window: FakeWindow) -> None:
    panel = make_panel(qtbot, window, VolumePanel)
    scene = window.session.scene
    lo, hi = window.session.volume.bounds
    assert not panel.clip_spins[0][0].isEnabled()
    panel.clip_check.setChecked(True)
    assert scene.clip_box == (tuple(lo), tuple(hi))
    panel.clip_spins[2][1].setValue(10.0)
    assert scene.clip_box[1][2] == pytest.approx(10.0)
    assert window.edits[-1] == ("Clipping box", "clip box")
    # a low side pushed past the high side stops short of it: the box stays non-empty
    panel.clip_spins[2][0].setValue(15.0)
    (z0, z1) = (scene.clip_box[0][2], scene.clip_box[1][2])
    assert z0 < z1 == pytest.approx(10.0)
    assert window.errors == []
    panel.clip_check.setChecked(False)
    assert scene.clip_box is None
    assert not panel.clip_spins[0][0].isEnabled()


def test_refresh_reads_the_session_without_edits(qtbot: Any, window: FakeWindow) -> None:
    volume_panel = make_panel(qtbot, window, VolumePanel)
    deform_panel = make_panel(qtbot, window, DeformationPanel)
    scene = window.session.scene
    scene.mode = "average"
    scene.step = 3.0
    scene.window = (40.0, 12.0)
    scene.shading = True
    scene.jitter = False
    scene.clip_box = ((1.0, 2.0, 3.0), (9.0, 10.0, 11.0))
    window.session.set_deformation("chainmail", resolution=5)
    window.session.options.integrator = "explicit"
    window.session.set_option("relax_steps", 7)
    window.refresh_panels()
    assert volume_panel.mode_combo.currentText() == "average"
    assert volume_panel.step_spin.value() == pytest.approx(3.0)
    assert volume_panel.level_spin.value() == pytest.approx(40.0)
    assert volume_panel.width_spin.value() == pytest.approx(12.0)
    assert volume_panel.shading_combo.currentText() == "on"
    assert not volume_panel.jitter_check.isChecked()
    assert volume_panel.clip_check.isChecked()
    assert volume_panel.clip_spins[1][0].value() == pytest.approx(2.0)
    assert volume_panel.clip_spins[2][1].value() == pytest.approx(11.0)
    assert deform_panel.model_combo.currentData() == "chainmail"
    assert deform_panel.resolution_spin.value() == 5
    assert deform_panel.integrator_combo.currentText() == "explicit"
    assert deform_panel.relax_spin.value() == 7
    assert deform_panel.simulation_group.isVisibleTo(deform_panel)
    assert window.edits == []
    assert window.scene_changes == 0
    assert window.session.scene.clip_box == ((1.0, 2.0, 3.0), (9.0, 10.0, 11.0))


def test_refresh_follows_a_new_session(qtbot: Any, window: FakeWindow) -> None:
    panel = make_panel(qtbot, window, VolumePanel)
    old = window.session
    window.session = make_session((20, 8, 8), name="other")
    window.session.scene.mode = "iso"
    window.refresh_panels()
    assert "other" in panel.info_label.text()
    assert panel.mode_combo.currentText() == "iso"
    assert panel.clip_spins[0][1].maximum() == pytest.approx(19.5)
    panel.mode_combo.setCurrentText("mip")
    assert window.session.scene.mode == "mip"
    assert old.scene.mode == "dvr"
    assert window.edits == [("Mode mip", None)]


def test_open_button(qtbot: Any, window: FakeWindow) -> None:
    panel = make_panel(qtbot, window, VolumePanel)
    click(qtbot, panel.open_button)
    assert window.opens == 1


# ---------------------------------------------------------------------------- deformation
def test_model_combo_builds_a_mass_spring_model(qtbot: Any, window: FakeWindow) -> None:
    panel = make_panel(qtbot, window, DeformationPanel)
    assert [panel.model_combo.itemData(i) for i in range(panel.model_combo.count())] == list(
        DEFORMATIONS
    )
    panel.resolution_spin.setValue(4)
    panel.integrator_combo.setCurrentText("explicit")
    assert window.edits == []
    panel.model_combo.setCurrentIndex(panel.model_combo.findData("massspring"))
    s = window.session
    assert s.kind == "massspring"
    assert s.model is not None
    assert s.model.grid.shape == (4, 4, 4)
    assert s.options.integrator == "explicit"
    assert window.edits == [("New mass-spring model", None)]
    assert window.errors == []


def test_model_combo_switch_keeps_the_deformation_and_says_so(
    qtbot: Any, window: FakeWindow
) -> None:
    """mass-spring -> ChainMail on the same grid: the held drag stays, the limits hold,
    the status bar names how far they moved elements; another kind starts at rest."""
    panel = make_panel(qtbot, window, DeformationPanel)
    panel.resolution_spin.setValue(5)
    panel.model_combo.setCurrentIndex(panel.model_combo.findData("massspring"))
    s = window.session
    s.model.move((2, 2, 2), (1.5, 0.0, 0.0))  # beyond ChainMail's slack, nothing followed
    held = s.model.positions()[2, 2, 2]
    panel.model_combo.setCurrentIndex(panel.model_combo.findData("chainmail"))
    assert window.errors == []
    assert window.edits[-1] == ("New ChainMail model", None)
    np.testing.assert_array_equal(s.model.positions()[2, 2, 2], held)
    assert s.model.violation() <= 1e-6
    report = s.model.switch_report
    assert report is not None
    assert report.moved > 1
    assert window.status.currentMessage() == s.family.switch_note
    assert f"ChainMail: deformation kept; {report.moved} element(s)" in s.family.switch_note
    shown = len(window.status.messages)
    panel.model_combo.setCurrentIndex(panel.model_combo.findData("lattice"))
    assert len(window.status.messages) == shown  # nothing kept, nothing to say


def test_apply_rebuilds_with_the_settings(qtbot: Any, window: FakeWindow) -> None:
    panel = make_panel(qtbot, window, DeformationPanel)
    panel.model_combo.setCurrentIndex(panel.model_combo.findData("chainmail"))
    first = window.session.model
    panel.resolution_spin.setValue(3)
    panel.stiffness_spin.setValue(0.25)
    click(qtbot, panel.apply_button)
    s = window.session
    assert s.model is not first
    assert s.model.grid.shape == (3, 3, 3)
    assert s.options.stiffness == pytest.approx(0.25)
    assert window.edits[-1] == ("New ChainMail model", None)


def test_the_margin_row_defaults_to_auto_and_builds_with_what_is_typed(
    qtbot: Any, window: FakeWindow
) -> None:
    """The Margin row shows "auto" (10 % of the volume box's largest side, resolved
    when the model is built; the tooltip and the boundary line say the mm); a typed
    number and 0 (the volume's box) are used."""
    panel = make_panel(qtbot, window, DeformationPanel)
    assert panel.margin_spin.text() == "auto"
    panel.model_combo.setCurrentIndex(panel.model_combo.findData("chainmail"))
    s = window.session
    lo, hi = (np.asarray(b) for b in s.volume.bounds)
    auto = 0.1 * float(np.max(hi - lo))  # the ramp's box: 16 x 16 x 24 mm
    assert auto == pytest.approx(2.4)
    np.testing.assert_allclose(s.model.grid.lo, lo - auto)
    assert s.options.margin == "auto"
    assert panel.margin_spin.text() == "auto"
    assert "In use: 2.4 mm" in panel.margin_spin.toolTip()
    assert "grid margin 2.4 mm beyond the volume's box" in panel.boundary_label.text()
    panel.margin_spin.setValue(12.0)
    click(qtbot, panel.apply_button)
    np.testing.assert_allclose(s.model.grid.lo, lo - 12.0)
    assert s.options.margin == 12.0
    assert "In use: 12.0 mm" in panel.margin_spin.toolTip()
    panel.margin_spin.setValue(0.0)
    click(qtbot, panel.apply_button)
    np.testing.assert_allclose(s.model.grid.lo, lo)
    np.testing.assert_allclose(s.model.grid.hi, hi)
    assert "grid margin 0 mm (the volume's box)" in panel.boundary_label.text()
    panel.margin_spin.setValue(-1.0)  # back to auto
    click(qtbot, panel.apply_button)
    assert s.options.margin == "auto"
    np.testing.assert_allclose(s.model.grid.hi, hi + auto)


def test_gpu_backend_without_context_is_an_error_and_the_combo_follows(
    qtbot: Any, window: FakeWindow
) -> None:
    panel = make_panel(qtbot, window, DeformationPanel)
    panel.backend_combo.setCurrentText("gpu")
    panel.model_combo.setCurrentIndex(panel.model_combo.findData("massspring"))
    assert len(window.errors) == 1
    assert isinstance(window.errors[0], EditorError)
    assert window.session.kind == "none"
    assert panel.model_combo.currentData() == "none"


def test_fix_and_free_selected(qtbot: Any, window: FakeWindow) -> None:
    window.session.set_deformation("massspring", resolution=3, anchor="corners")
    panel = make_panel(qtbot, window, DeformationPanel)
    corners = window.session.model.grid.fixed.reshape(-1).copy()  # fixed by default
    assert not corners[5]
    assert not corners[7]
    window.session.select([5, 7])
    click(qtbot, panel.fix_button)
    fixed = window.session.model.grid.fixed.reshape(-1)
    assert fixed[5]
    assert fixed[7]
    assert fixed.sum() == corners.sum() + 2
    assert window.edits == [("Fix selected", None)]
    window.session.select([7])
    click(qtbot, panel.free_button)
    fixed = window.session.model.grid.fixed.reshape(-1)
    assert fixed[5]
    assert not fixed[7]
    # nothing selected: the window reports it
    window.session.select([])
    click(qtbot, panel.fix_button)
    assert len(window.errors) == 1
    assert window.session.model.grid.fixed.sum() == corners.sum() + 1


def test_simulation_buttons_and_options(qtbot: Any, window: FakeWindow) -> None:
    window.session.set_deformation("massspring", resolution=3)
    panel = make_panel(qtbot, window, DeformationPanel)
    assert panel.run_button.isChecked()
    assert panel.run_button.text() == "Pause"
    click(qtbot, panel.run_button)
    assert window.running == [False]
    assert window.session.running is False
    assert panel.run_button.text() == "Run"
    s = window.session
    # pull the centre element (the corners are fixed) and let go: it springs back
    offsets = np.zeros((1, 3))
    offsets[0, 0] = 3.0
    s.model.move(np.array([[1, 1, 1]]), offsets)
    s.model.release()
    before = s.model.positions().copy()
    click(qtbot, panel.step_button)
    assert window.edits[-1] == ("Single step", None)
    assert not np.allclose(s.model.positions(), before)
    click(qtbot, panel.reset_button)
    assert np.allclose(s.model.positions(), s.model.grid.rest_positions)
    panel.steps_spin.setValue(25)
    assert s.options.steps_per_frame == 25
    assert window.edits[-1] == ("Steps per frame", "steps per frame")
    assert panel.simulation_form.isRowVisible(panel.steps_spin)
    assert not panel.simulation_form.isRowVisible(panel.relax_spin)


def test_relax_steps_for_chainmail(qtbot: Any, window: FakeWindow) -> None:
    window.session.set_deformation("chainmail", resolution=3)
    panel = make_panel(qtbot, window, DeformationPanel)
    assert panel.relax_spin.maximum() == 16
    panel.relax_spin.setValue(4)
    assert window.session.options.relax_steps == 4
    assert window.session.model.relax_steps == 4
    assert window.edits == [("Relaxation steps", "relax steps")]
    assert panel.simulation_form.isRowVisible(panel.relax_spin)
    assert not panel.simulation_form.isRowVisible(panel.steps_spin)


def test_groups_follow_the_model(qtbot: Any, window: FakeWindow) -> None:
    panel = make_panel(qtbot, window, DeformationPanel)
    expected = {
        "none": (False, False, False),
        "massspring": (True, False, True),
        "chainmail": (True, False, True),
        "wires": (False, True, True),
        "lattice": (False, False, True),
    }
    for kind, (sim, wires, place) in expected.items():
        panel.model_combo.setCurrentIndex(panel.model_combo.findData(kind))
        assert window.session.kind == kind
        assert panel.simulation_group.isVisibleTo(panel) is sim, kind
        assert panel.wire_group.isVisibleTo(panel) is wires, kind
        assert panel.placement_group.isVisibleTo(panel) is place, kind
        assert panel.model_form.isRowVisible(panel.integrator_combo) is (kind == "massspring")
        assert panel.model_form.isRowVisible(panel.variant_combo) is (kind == "chainmail")
    assert window.errors == []


def test_set_twist_at_point(qtbot: Any, window: FakeWindow) -> None:
    window.session.set_deformation("wires")
    panel = make_panel(qtbot, window, DeformationPanel)
    assert panel.wire_group.isVisibleTo(panel)
    # no reference point: the button is off, and the edit refuses
    assert not panel.set_key_button.isEnabled()
    panel._set_wire_key()
    assert len(window.errors) == 1
    window.session.select([1])
    window.refresh_panels()
    assert "point 2" in panel.wire_label.text()
    panel.twist_spin.setValue(90.0)
    panel.scale_spin.setValue(1.5)
    builds = window.wire_builds
    click(qtbot, panel.set_key_button)
    wire = window.session.adapter(WiresFamily).wires[0]
    keys = np.asarray(wire.twist)
    new = keys[keys[:, 0] > 0]  # besides the default key (0, 0)
    assert new.shape == (1, 2)
    assert 0.2 < new[0, 0] < 0.5  # control point 2 of 4, at 0.1, 0.37, 0.63, 0.9
    assert new[0, 1] == pytest.approx(math.pi / 2)
    assert wire.scale_at(new[0, 0]) == pytest.approx(1.5)
    assert window.wire_builds == builds + 1
    assert not window.session.family.field_stale
    # the spins show the keys at the point after a refresh
    panel.twist_spin.setValue(0.0)
    window.refresh_panels()
    assert panel.twist_spin.value() == pytest.approx(90.0)
    assert panel.scale_spin.value() == pytest.approx(1.5)


def test_wire_parameters(qtbot: Any, window: FakeWindow) -> None:
    window.session.set_deformation("wires")
    panel = make_panel(qtbot, window, DeformationPanel)
    s = window.session
    assert panel.radius_spin.value() == pytest.approx(s.adapter(WiresFamily).wires[0].radius)
    panel.radius_spin.setValue(3.0)
    assert s.adapter(WiresFamily).wires[0].radius == pytest.approx(3.0)
    assert window.edits[-1] == ("Wire radius", "wire radius 0")
    assert not s.family.field_stale
    panel.beta_lo_spin.setValue(20.0)  # classification off: no edit
    n = len(window.edits)
    assert s.adapter(WiresFamily).wires[0].beta is None
    panel.beta_check.setChecked(True)
    assert len(window.edits) == n + 1
    assert s.adapter(WiresFamily).wires[0].beta == pytest.approx((20.0, 100.0))
    panel.beta_hi_spin.setValue(60.0)
    assert s.adapter(WiresFamily).wires[0].beta == pytest.approx((20.0, 60.0))
    panel.beta_check.setChecked(False)
    assert s.adapter(WiresFamily).wires[0].beta is None
    panel.wire_kind_combo.setCurrentText("bezier")
    assert s.adapter(WiresFamily).wires[0].kind == "bezier"
    panel.field_scale_combo.setCurrentIndex(panel.field_scale_combo.findData(4))
    assert s.options.wire_settings["field_scale"] == 4
    assert not s.family.field_stale
    assert window.errors == []


def test_lay_and_finish_a_wire(qtbot: Any, window: FakeWindow) -> None:
    window.session.set_deformation("wires")
    panel = make_panel(qtbot, window, DeformationPanel)
    s = window.session
    assert not panel.finish_button.isEnabled()
    click(qtbot, panel.lay_button)
    assert s.family.placing is True
    # while laying, curve and radius are the new wire's, not edits of wire 1
    n = len(window.edits)
    panel.radius_spin.setValue(2.5)
    panel.wire_kind_combo.setCurrentText("bezier")
    assert len(window.edits) == n
    assert (panel.wire_kind(), panel.wire_radius()) == ("bezier", 2.5)
    assert s.adapter(WiresFamily).wires[0].kind == "catmull-rom"
    panel.wire_kind_combo.setCurrentText("catmull-rom")
    s.adapter(WiresFamily).pending_wire = [np.array([2.0, 2.0, 2.0]), np.array([12.0, 8.0, 10.0])]
    window.refresh_panels()
    assert "2 points laid" in panel.wire_label.text()
    click(qtbot, panel.finish_button)
    assert len(s.adapter(WiresFamily).wires) == 2
    assert s.adapter(WiresFamily).wires[1].radius == pytest.approx(2.5)
    assert s.adapter(WiresFamily).pending_wire == []
    assert s.family.placing is False
    assert not panel.lay_button.isChecked()
    assert not s.family.field_stale
    s.select(
        [len(s.adapter(WiresFamily).wires[0].modified.control_points)]
    )  # first point of wire 2
    window.refresh_panels()
    assert wire_of_handle(s, s.reference) == (1, 0)
    assert "Wire 2 of 2" in panel.wire_label.text()
    click(qtbot, panel.remove_wire_button)
    assert len(s.adapter(WiresFamily).wires) == 1
    assert not panel.remove_wire_button.isEnabled()


def test_placement_spins(qtbot: Any, window: FakeWindow) -> None:
    window.session.set_deformation("lattice", resolution=3)
    panel = make_panel(qtbot, window, DeformationPanel)
    panel.translate_spins[0].setValue(4.0)
    panel.rotate_spins[2].setValue(30.0)
    panel.scale_spins[1].setValue(1.5)
    assert window.session.placement == Placement((4, 0, 0), (0, 0, 30), (1, 1.5, 1))
    assert window.edits == [("Place grid", "placement")] * 3
    assert len(window.session.scene.warps) == 3
    click(qtbot, panel.place_reset_button)
    assert window.session.placement.is_identity
    assert panel.translate_spins[0].value() == 0.0


def test_timings_label(qtbot: Any, window: FakeWindow) -> None:
    window.session.set_deformation("massspring", resolution=3)
    panel = make_panel(qtbot, window, DeformationPanel)
    window.session.timings["step"] = 1.234
    panel.refresh_timings()
    text = panel.timings_label.text()
    assert "step 1.23 ms" in text
    # the frame rate has one readout, the window's status bar (test_main_window)
    assert "fps" not in text
    assert "frame" not in text


# ---------------------------------------------------------------------------- display
def test_display_panel_toggles_options(qtbot: Any, window: FakeWindow) -> None:
    panel = make_panel(qtbot, window, DisplayPanel)
    display = window.viewport.display
    assert set(panel.checks) == set(DisplayOptions.__dataclass_fields__)
    assert panel.checks["links"].isChecked()
    panel.checks["links"].setChecked(False)
    assert display.links is False
    assert window.viewport.updates == 1
    assert window.edits == []
    display.clip_box = True
    panel.refresh()
    assert panel.checks["clip_box"].isChecked()
    assert window.viewport.updates == 1


# ---------------------------------------------------------------------------- scene tree
def tree_rows(item: QTreeWidgetItem) -> list[tuple[str, str]]:
    return [(item.child(i).text(0), item.child(i).text(1)) for i in range(item.childCount())]


def test_scene_panel_lists_volume_deformation_and_meshes(qtbot: Any, window: FakeWindow) -> None:
    panel = make_panel(qtbot, window, ScenePanel)
    top = {
        panel.tree.topLevelItem(i).text(0): panel.tree.topLevelItem(i)
        for i in range(panel.tree.topLevelItemCount())
    }
    assert set(top) == {"Volume", "Deformation", "Meshes"}
    assert top["Volume"].text(1) == "ramp, 16×16×12"
    assert top["Deformation"].text(1) == "none"
    assert top["Deformation"].childCount() == 0
    window.session.set_deformation("lattice", resolution=3)
    window.session.set_placement(Placement(translate=(1, 0, 0)))
    window.session.scene.meshes = [MeshInstance(box_mesh(), name="cube")]
    panel.refresh()
    deformation = panel.tree.findItems("Deformation", Qt.MatchFlag.MatchExactly)[0]
    assert deformation.text(1) == "lattice, 2×2×2 cells"
    assert [name for name, _ in tree_rows(deformation)] == [
        "AffineWarp",
        "LatticeWarp",
        "AffineWarp",
    ]
    meshes = panel.tree.findItems("Meshes", Qt.MatchFlag.MatchExactly)[0]
    assert tree_rows(meshes) == [("cube", "12 faces, matrix")]
    assert window.edits == []


def test_scene_panel_mesh_visibility(qtbot: Any, window: FakeWindow) -> None:
    class ShowableInstance(MeshInstance):
        visible = True

    window.session.scene.meshes = [ShowableInstance(box_mesh(), name="cube")]
    panel = make_panel(qtbot, window, ScenePanel)
    item = panel.tree.findItems("Meshes", Qt.MatchFlag.MatchExactly)[0].child(0)
    assert item.checkState(0) == Qt.CheckState.Checked
    item.setCheckState(0, Qt.CheckState.Unchecked)
    assert window.session.scene.meshes[0].visible is False
    assert item.checkState(0) == Qt.CheckState.Unchecked
    assert window.edits == [("Hide mesh", None)]
    assert window.scene_changes == 1


def test_all_panels_grab(qtbot: Any, window: FakeWindow, tmp_path: Any) -> None:
    """Every panel paints, for every deformation family (no exceptions in refresh)."""
    panels = [make_panel(qtbot, window, cls) for cls in (VolumePanel, DeformationPanel)]
    panels += [make_panel(qtbot, window, cls) for cls in (DisplayPanel, ScenePanel)]
    for kind in DEFORMATIONS:
        window.session.set_deformation(kind, resolution=3)
        window.refresh_panels()
        for p in panels:
            p.resize(300, p.sizeHint().height())
            image = p.grab().toImage()
            assert image.width() == 300
    assert window.edits == []
