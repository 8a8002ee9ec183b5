"""The wire panel's Ends row (smooth / rigid, voxwarp.deform.wires.field.Wire.ends) and the
session call behind it."""

from __future__ import annotations

from typing import Any

import pytest

from tests.ui.test_panels import FakeWindow, make_panel, make_session
from voxwarp.editing.families.wires import WiresFamily
from voxwarp.editing.session import EditorError
from voxwarp.ui.panels import DeformationPanel


def test_session_sets_a_wires_ends() -> None:
    s = make_session()
    s.set_deformation("wires")
    assert s.adapter(WiresFamily).wires[0].ends == "smooth"  # the default of a new wire
    s.adapter(WiresFamily).set_wire_parameters(0, ends="rigid")
    assert s.adapter(WiresFamily).wires[0].ends == "rigid"
    assert s.family.field_stale
    with pytest.raises(EditorError, match="wire ends must be one of smooth, rigid"):
        s.adapter(WiresFamily).set_wire_parameters(0, ends="soft")


def test_ends_combo_edits_the_selected_wire(qtbot: Any) -> None:
    window = FakeWindow(make_session())
    window.session.set_deformation("wires")
    panel = make_panel(qtbot, window, DeformationPanel)
    s = window.session
    assert panel.wire_ends_combo.currentText() == s.adapter(WiresFamily).wires[0].ends == "smooth"
    panel.wire_ends_combo.setCurrentText("rigid")
    assert s.adapter(WiresFamily).wires[0].ends == "rigid"
    assert window.edits[-1][0] == "Wire ends rigid"
    assert not s.family.field_stale  # the panel asked for a rebuild
    s.adapter(WiresFamily).set_wire_parameters(0, ends="smooth")
    window.refresh_panels()
    assert panel.wire_ends_combo.currentText() == "smooth"
    assert window.errors == []
