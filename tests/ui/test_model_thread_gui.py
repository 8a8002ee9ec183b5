"""The window steps the element model on its worker thread: during a long ChainMail
move (one that blocks on an Event until the test opens it) the GUI thread keeps
processing events and drawing frames, the mouse drag goes on, and the release's undo
entry holds the state of the newest target (Xvfb, see conftest).

No sleeps-and-hope: the test waits on the Event the worker sets when the move starts,
and on frame counters with pytest-qt's ``waitUntil`` and a generous timeout.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
import pytest
from PySide6.QtCore import QPoint, Qt

from tests.ui.test_main_window import _session, central_free_element, handle_pixel
from tests.ui.windows import shown_window

SIZE = (1280, 820)
WAIT_S = 60.0


@pytest.fixture
def window(qtbot: Any, monkeypatch: pytest.MonkeyPatch) -> Any:
    monkeypatch.delenv("VOXWARP_MODEL_THREAD", raising=False)
    w = shown_window(qtbot, monkeypatch, _session(), SIZE)
    yield w
    w.close()


@pytest.mark.slow
def test_the_event_loop_draws_while_a_long_move_runs_on_the_worker(
    window: Any, qtbot: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    w = window
    assert w.session.model_worker is not None  # the window's default
    w.edit("New ChainMail", lambda: w.session.set_deformation("chainmail", resolution=5))
    model = w.session.model
    i = central_free_element(w.session, w.viewport.camera)
    started, gate, moves = threading.Event(), threading.Event(), []
    inner = model.move

    def blocking_move(*args: Any) -> Any:
        if not started.is_set():
            started.set()
            assert gate.wait(WAIT_S)
        moves.append(args)
        return inner(*args)

    monkeypatch.setattr(model, "move", blocking_move)
    start = handle_pixel(w, i)
    try:
        qtbot.mousePress(w.viewport, Qt.MouseButton.LeftButton, pos=start)
        qtbot.mouseMove(w.viewport, pos=start + QPoint(0, -20))
        assert started.wait(WAIT_S)  # the worker is inside the first move now
        # the GUI thread is free: more drag events and frames are processed
        for k in (2, 3, 4):
            qtbot.mouseMove(w.viewport, pos=start + QPoint(0, -20 * k))
            n = w.viewport.frames_drawn
            w.viewport.update()
            qtbot.waitUntil(lambda n=n: w.viewport.frames_drawn > n, timeout=int(WAIT_S * 1000))
        assert moves == []  # all that while, the first move had not finished
        assert w.session.model_busy
    finally:
        gate.set()
    qtbot.mouseRelease(w.viewport, Qt.MouseButton.LeftButton, pos=start + QPoint(0, -80))
    # the release's undo entry waited for the worker: the first and the newest move ran
    assert not w.session.model_busy
    assert len(moves) in (2, 3)  # the release's own move may or may not coalesce
    assert w.undo_stack.undoText().startswith("Drag")
    disp = w.session.model.displacements()
    assert np.array_equal(w.session.scene.warps[0].displacements, disp)
    held = w.session.model.to_dict()["held"]
    assert [h["index"] for h in held] == [list(np.unravel_index(i, model.grid.shape))]
    up = w.viewport.camera.rotation[:, 1]
    assert disp.reshape(-1, 3)[i] @ up > 5.0  # dragged up the screen
    w.undo_stack.undo()
    assert np.abs(w.session.model.displacements()).max() == 0.0
