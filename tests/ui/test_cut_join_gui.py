"""The window's *Cut selected* / *Join selected* / *Pull and join* (ChainMail): buttons
clicked in a real window (Xvfb, see conftest), each an undoable edit; undo and redo
restore the links and the positions exactly.

Oracles: 24 links around a 2³ block of a 5³ grid; elements outside the cut-loose block
at rest after a drag; the links left cut by a join exactly the stretched ones, counted
by hand (:func:`tests.editing.test_cut_join.stretched_cuts`); snapshots compared
bit for bit after undo and redo.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from PySide6.QtCore import Qt

from tests.editing.test_cut_join import SHAPE, block, stretched_cuts
from tests.ui.windows import shown_window
from voxwarp.editing.session import EditSession
from voxwarp.io.samples import load_sample
from voxwarp.scene import Scene


@pytest.fixture
def window(qtbot: Any, monkeypatch: pytest.MonkeyPatch) -> Any:
    session = EditSession(Scene(load_sample("fish", shape=(32, 32, 32)), jitter=False))
    w = shown_window(qtbot, monkeypatch, session, (1000, 700))
    yield w
    w.close()


def _state(w: Any) -> tuple[int, np.ndarray]:
    return len(w.session.model.cuts), w.session.model.positions()


def _click(qtbot: Any, button: Any) -> None:
    assert button.isVisible()
    assert button.isEnabled()
    qtbot.waitUntil(lambda: button.height() > 0)  # laid out once its row is shown
    qtbot.mouseClick(button, Qt.MouseButton.LeftButton)


@pytest.mark.slow
def test_cut_join_undo_redo(window: Any, qtbot: Any) -> None:
    w = window
    panel = w.deformation_panel
    w.edit("New mass-spring", lambda: w.session.set_deformation("massspring", resolution=3))
    assert not panel.cut_button.isVisible()  # only ChainMail has links to cut
    w.edit(
        "New ChainMail",
        lambda: w.session.set_deformation("chainmail", resolution=SHAPE[0], anchor="corners"),
    )
    rest = _state(w)
    sel, mask = block()
    w.session.select(sel)
    _click(qtbot, panel.cut_button)
    assert w.errors == []
    assert w.undo_stack.undoText() == "Cut selected"
    assert w.statusBar().currentMessage() == "Cut 24 link(s)"
    assert _state(w)[0] == 24
    offset = (0.6 * w.session.model.grid.spacing[0], 0.0, 0.0)
    w.edit("Drag", lambda: w.session.model.move((2, 2, 2), offset))
    dragged = _state(w)
    assert not np.any(dragged[1][~mask] - rest[1][~mask])  # the block came loose
    far = stretched_cuts(w.session)
    assert 0 < far < 24
    w.session.select(sel)
    _click(qtbot, panel.join_button)
    assert w.undo_stack.undoText() == "Join selected"
    assert w.statusBar().currentMessage().startswith(f"Joined {24 - far} link(s); {far} stay")
    joined = _state(w)
    assert joined[0] == far
    np.testing.assert_array_equal(joined[1], dragged[1])  # joining moves nothing
    for expected, step in ((dragged, "undo"), (joined, "redo")):
        getattr(w.undo_stack, step)()
        assert _state(w)[0] == expected[0]
        np.testing.assert_array_equal(_state(w)[1], expected[1])
    _click(qtbot, panel.pull_button)  # the stretched ones too, pulling the sides together
    assert w.undo_stack.undoText() == "Pull and join"
    assert w.statusBar().currentMessage() == f"Joined {far} link(s)"
    pulled = _state(w)
    assert pulled[0] == 0
    assert w.session.model.violation() <= 1e-6
    assert np.any(pulled[1] != joined[1])
    for _ in range(4):  # pull, join, drag, cut
        w.undo_stack.undo()
    assert _state(w)[0] == 0
    np.testing.assert_array_equal(_state(w)[1], rest[1])
    for _ in range(4):
        w.undo_stack.redo()
    assert _state(w)[0] == 0
    np.testing.assert_array_equal(_state(w)[1], pulled[1])
    w.undo_stack.undo()
    assert _state(w)[0] == far
    np.testing.assert_array_equal(_state(w)[1], joined[1])
