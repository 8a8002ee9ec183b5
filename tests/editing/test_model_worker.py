"""The model worker (voxwarp.editing.model_worker) and the edit session stepping its
element model on it: the same positions as the synchronous path after the same drag,
drags that coalesce (the newest target wins), a drawing thread that never waits on a
step, and snapshots that do wait for it.

Every wait is explicit (an Event the test sets, ``wait_idle`` with a generous timeout);
nothing sleeps and hopes.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
import pytest

from voxwarp.editing.model_worker import ModelWorker, ModelWorkerError
from voxwarp.editing.session import EditSession
from voxwarp.io.samples import load_sample
from voxwarp.scene import Scene

WAIT = 60.0
SIZE = (300, 300)


# ---------------------------------------------------------------------------- the worker
def test_jobs_of_one_key_coalesce_and_the_newest_result_wins() -> None:
    worker = ModelWorker()
    gate, started, ran = threading.Event(), threading.Event(), []
    try:

        def blocking() -> str:
            started.set()
            assert gate.wait(WAIT)
            ran.append("first")
            return "first"

        worker.post("move", blocking)
        assert started.wait(WAIT)
        for k in range(5):  # the worker is busy: each replaces the one before
            worker.post("move", lambda k=k: ran.append(k) or k)
        worker.post("advance", lambda: ran.append("advance") or "advance")
        assert worker.pending("move")
        assert not worker.idle
        gate.set()
        worker.wait_idle(WAIT)
        assert ran == ["first", 4, "advance"]
        assert worker.take() == "advance"  # the newest; the older results are dropped
        assert worker.take() is None
        assert worker.jobs_done == 3
    finally:
        gate.set()
        worker.close()


def test_a_job_error_is_raised_once_by_take() -> None:
    worker = ModelWorker()
    try:
        worker.post("move", lambda: 1 / 0)
        worker.wait_idle(WAIT)
        assert worker.has_result
        with pytest.raises(ZeroDivisionError):
            worker.take()
        assert worker.take() is None
    finally:
        worker.close()


def test_wait_idle_names_a_step_that_does_not_finish_and_close_refuses_jobs() -> None:
    worker = ModelWorker()
    gate = threading.Event()
    try:
        worker.post("move", lambda: gate.wait(WAIT))
        with pytest.raises(ModelWorkerError, match="did not finish"):
            worker.wait_idle(0.05)
    finally:
        gate.set()
        worker.close()
    with pytest.raises(ModelWorkerError, match="closed"):
        worker.post("move", lambda: None)


# ---------------------------------------------------------------------------- the session
def _session(kind: str, threaded: bool) -> EditSession:
    vol = load_sample("fish", shape=(32, 32, 32))
    s = EditSession(Scene(vol, view=(-70, 25), zoom=1.2))
    s.set_model_thread(threaded)
    s.set_deformation(kind, resolution=5)
    return s


def _start_drag(s: EditSession) -> np.ndarray:
    """Select the middle element and press on it; returns its pixel."""
    cam = s.scene.resolved_camera()
    index = int(np.ravel_multi_index((2, 2, 2), s.model.grid.shape))
    s.select([index])
    xy = cam.project(s.handles()[index : index + 1], SIZE)[0]
    assert s.begin_drag(cam, SIZE, xy)
    return xy


def _drag(s: EditSession, targets: list[float], ticks: int = 1) -> None:
    """Drag to each target (pixels up the screen), with ``ticks`` simulation frames
    after each, waiting for the worker after every call (no coalescing)."""
    xy = _start_drag(s)
    for dy in targets:
        s.drag_to(xy + np.array([0.0, -dy]))
        s.wait_for_model()
        for _ in range(ticks):
            s.advance()
            s.wait_for_model()
    s.end_drag()


@pytest.mark.parametrize("kind", ["massspring", "chainmail"])
def test_the_worker_reaches_the_positions_of_the_synchronous_path(kind: str) -> None:
    states = []
    for threaded in (False, True):
        s = _session(kind, threaded)
        try:
            _drag(s, [6.0, 14.0, 25.0], ticks=3)
            snap = s.snapshot()
            states.append((s.model.positions(), s.scene.warps[0].displacements, snap))
        finally:
            s.close()
    (p_sync, u_sync, snap_sync), (p_thread, u_thread, snap_thread) = states
    assert np.abs(p_sync - p_sync[0, 0, 0]).max() > 1.0  # something moved
    assert np.array_equal(p_thread, p_sync)
    assert np.array_equal(u_thread, u_sync)  # the GUI thread's upload is the model's field
    assert snap_thread.state.keys() == snap_sync.state.keys()
    assert snap_thread.state["model"] == snap_sync.state["model"]
    for key in snap_sync.state.keys() - {"model"}:  # positions (and velocities)
        assert np.array_equal(snap_thread.state[key], snap_sync.state[key])


class _Gate:
    """Wraps a model's ``move`` so that its first call, once the move is done, blocks
    until :meth:`open` (the model has changed; the step has not returned)."""

    def __init__(self, model: Any) -> None:
        self.model, self.inner = model, model.move
        self.started, self.gate, self.done = threading.Event(), threading.Event(), []
        model.move = self.move

    def move(self, *args: Any) -> Any:
        out = self.inner(*args)
        if not self.started.is_set():
            self.started.set()
            assert self.gate.wait(WAIT)
        self.done.append(args)
        return out

    def open(self) -> None:
        self.gate.set()


def test_a_long_step_blocks_neither_the_drag_nor_the_drawing_and_the_newest_target_wins() -> None:
    s = _session("chainmail", threaded=True)
    gate = _Gate(s.model)
    try:
        warp = s.scene.warps[0]
        xy = _start_drag(s)
        revision = warp.revision
        s.drag_to(xy + np.array([0.0, -5.0]))
        assert gate.started.wait(WAIT)  # the worker moved the model; the step goes on
        for dy in (10.0, 15.0, 20.0, 25.0):  # the GUI thread goes on: nothing waits
            s.drag_to(xy + np.array([0.0, -dy]))
            assert not s.poll_model()
            s.overlay_layers()
        held = s.handles()[s.selection[0]]
        assert warp.revision == revision  # the worker never writes the drawn warp
        gate.open()
        s.end_drag()
        s.wait_for_model()
        assert len(gate.done) == 2  # the first move and the newest target; 3 dropped
        assert warp.revision != revision
        assert np.allclose(s.handles()[s.selection[0]], held)  # the handle was at the target
        final = s.model.positions()
        assert np.array_equal(warp.displacements, s.model.displacements())
    finally:
        gate.open()
        s.close()
    # the same two moves on the synchronous path
    ref = _session("chainmail", threaded=False)
    try:
        _drag(ref, [5.0, 25.0], ticks=0)
        assert np.array_equal(ref.model.positions(), final)
    finally:
        ref.close()


def test_a_snapshot_waits_for_the_step_in_progress() -> None:
    s = _session("chainmail", threaded=True)
    gate = _Gate(s.model)
    try:
        xy = _start_drag(s)
        s.drag_to(xy + np.array([0.0, -20.0]))
        opener = threading.Thread(target=lambda: (gate.started.wait(WAIT), gate.open()))
        opener.start()
        snap = s.snapshot()  # returns only once the move is done and shown
        opener.join(WAIT)
        assert len(gate.done) == 1
        assert np.array_equal(snap.state["positions"], s.model.positions())
        assert np.array_equal(s.scene.warps[0].displacements, s.model.displacements())
        assert not s.model_busy
    finally:
        gate.open()
        s.close()


def test_a_running_model_steps_on_the_worker_until_it_settles() -> None:
    s = _session("massspring", threaded=True)
    try:
        _drag(s, [20.0], ticks=0)
        before = s.model.positions()
        for _ in range(3):
            assert s.advance() is False  # posts the steps; nothing shown yet
            s.wait_for_model()
        assert "step" in s.timings
        assert not np.array_equal(s.model.positions(), before)
        assert np.array_equal(s.scene.warps[0].displacements, s.model.displacements())
        for _ in range(2000):
            if s.settled:
                break
            s.advance()
            s.wait_for_model()
        assert s.settled
    finally:
        s.close()
