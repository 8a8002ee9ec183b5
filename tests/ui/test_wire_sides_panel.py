"""The wire panel's Sides, Side falloff and Vacated rows
(voxwarp.deform.wires.field.Wire.sides, side_falloff, vacated) and the session call
behind them."""

from __future__ import annotations

from typing import Any

import pytest

from tests.ui.test_panels import FakeWindow, make_panel, make_session
from voxwarp.editing.families.wires import WiresFamily
from voxwarp.editing.session import EditorError
from voxwarp.ui.panels import DeformationPanel


def test_session_sets_a_wires_sides_falloff_and_vacated() -> None:
    s = make_session()
    s.set_deformation("wires")
    wires = s.adapter(WiresFamily)
    assert wires.wires[0].sides == "smooth"  # the default of a new wire
    wires.set_wire_parameters(0, side_falloff=12.5)
    assert wires.wires[0].side_falloff == 12.5
    wires.set_wire_parameters(0, side_falloff=None)  # back to the default
    assert wires.wires[0].side_falloff_mm is None
    wires.set_wire_parameters(0, sides="rigid", vacated="rest")
    assert (wires.wires[0].sides, wires.wires[0].vacated) == ("rigid", "rest")
    assert s.family.field_stale
    with pytest.raises(EditorError, match="wire sides must be one of smooth, rigid"):
        wires.set_wire_parameters(0, sides="soft")
    with pytest.raises(EditorError, match="wire vacated must be one of empty, rest"):
        wires.set_wire_parameters(0, vacated="black")


def test_sides_rows_edit_the_selected_wire(qtbot: Any) -> None:
    window = FakeWindow(make_session())
    window.session.set_deformation("wires")
    panel = make_panel(qtbot, window, DeformationPanel)
    s = window.session
    wire = s.adapter(WiresFamily).wires
    assert panel.wire_sides_combo.currentText() == wire[0].sides == "smooth"
    assert panel.side_falloff_spin.isEnabled()
    assert not panel.wire_vacated_combo.isEnabled()  # only a rigid sweep vacates
    panel.side_falloff_spin.setValue(20.0)
    assert s.adapter(WiresFamily).wires[0].side_falloff == 20.0
    assert window.edits[-1][0] == "Wire side falloff"
    panel.wire_sides_combo.setCurrentText("rigid")
    assert s.adapter(WiresFamily).wires[0].sides == "rigid"
    assert window.edits[-1][0] == "Wire sides rigid"
    window.refresh_panels()
    assert panel.wire_vacated_combo.isEnabled()
    panel.wire_vacated_combo.setCurrentText("rest")
    assert s.adapter(WiresFamily).wires[0].vacated == "rest"
    assert not s.family.field_stale  # the panel asked for a rebuild
    assert window.errors == []
