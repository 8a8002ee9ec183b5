"""The model combo switches mass-spring <-> ChainMail keeping the deformation (Knoche
2008, §5) as one undoable edit, and the status bar says how far ChainMail's limits
moved elements (a real window on Xvfb, see conftest)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from PySide6.QtCore import QPoint

from tests.ui.test_main_window import _session, central_free_element, drag, handle_pixel
from tests.ui.windows import shown_window
from voxwarp.deform.elements.chainmail import ChainMail
from voxwarp.deform.elements.massspring import MassSpring

SIZE = (1280, 820)


@pytest.fixture
def window(qtbot: Any, monkeypatch: pytest.MonkeyPatch) -> Any:
    w = shown_window(qtbot, monkeypatch, _session(), SIZE, active=True)
    yield w
    w.close()


def _choose(w: Any, kind: str) -> None:
    combo = w.deformation_panel.model_combo
    combo.setCurrentIndex(combo.findData(kind))


def _positions(w: Any) -> np.ndarray:
    w.session.wait_for_model()
    return w.viewport.with_context(w.session.model.positions)


@pytest.mark.slow
def test_switching_models_keeps_the_drag_and_undo_brings_the_old_model_back(
    window: Any, qtbot: Any
) -> None:
    w = window
    _choose(w, "massspring")
    assert isinstance(w.session.model, MassSpring)
    i = central_free_element(w.session, w.viewport.camera)
    start = handle_pixel(w, i)
    drag(qtbot, w.viewport, start, start + QPoint(0, -20))
    dragged = w.session.snapshot()
    ms_x = _positions(w)
    rest = w.session.model.grid.rest_positions
    moved = np.linalg.norm((ms_x - rest).reshape(-1, 3), axis=1)
    assert moved[i] > 1.0  # the drag moved the element

    _choose(w, "chainmail")
    cm = w.session.model
    assert isinstance(cm, ChainMail)
    cm_x = _positions(w)
    assert cm.violation() <= 1e-6  # every link within the limits
    np.testing.assert_array_equal(cm_x.reshape(-1, 3)[i], ms_x.reshape(-1, 3)[i])  # held
    assert cm.held.reshape(-1)[i]
    report = cm.switch_report
    assert report is not None
    assert report.moved > 0  # an unsettled mass-spring drag breaks the limits
    message = w.statusBar().currentMessage()
    assert f"{report.moved} element(s) moved" in message
    assert w.undo_stack.undoText() == "New ChainMail model"

    _choose(w, "massspring")  # back: always possible, positions kept exactly
    np.testing.assert_array_equal(_positions(w), cm_x)

    w.undo_action.trigger()  # the ChainMail again, where it was
    assert isinstance(w.session.model, ChainMail)
    np.testing.assert_allclose(_positions(w), cm_x, atol=1e-9)
    w.undo_action.trigger()  # the mass-spring model as dragged
    assert isinstance(w.session.model, MassSpring)
    assert w.session.snapshot().same_as(dragged)
    np.testing.assert_array_equal(_positions(w), ms_x)
