"""A worker thread that steps an element model off the GUI thread.

The desktop GUI drags elements and runs the mass-spring and ChainMail models while it
draws; a ChainMail move or a few mass-spring steps take tens of ms, and on the GUI thread
every one of them delays the next frame and the next mouse event. :class:`ModelWorker`
runs such *jobs* on one worker thread instead:

* the GUI thread :meth:`~ModelWorker.post`\\ s a job under a key (``"move"``,
  ``"advance"``); a job posted under a key whose job has not started yet replaces it, so
  drags coalesce (the newest target wins) and the queue never holds more than one job
  per key; pending jobs run in the order their keys were first posted;
* each finished job's result is handed back through one slot: the newest replaces an
  unread older one, and :meth:`~ModelWorker.take` swaps it out (the lock guarding the
  slot is held only for that swap, never during a job, so the GUI thread never waits on
  a step);
* :meth:`~ModelWorker.wait_idle` waits until nothing is pending or running (undo, saves,
  scripts: they then see one consistent model state).

The worker knows nothing of models, GL or Qt: the family adapter
(:class:`voxwarp.editing.families.elements.ElementFamily`) makes the jobs and uploads
what they return on the GUI thread, where the GL context is current. Without a worker
(``EditSession.set_model_thread(False)``, the default of scripts and the notebook) the
same adapter steps the model synchronously.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from voxwarp.errors import VoxwarpError

__all__ = ["ModelWorker", "ModelWorkerError"]

#: seconds :meth:`ModelWorker.wait_idle` waits by default (a step takes milliseconds)
WAIT_S = 60.0


class ModelWorkerError(VoxwarpError):
    """The model worker is closed, or did not finish its steps in time."""


class ModelWorker:
    """Runs posted jobs one at a time on a daemon thread (see the module docstring).

    Parameters
    ----------
    name
        The thread's name (shows in debuggers and thread dumps).
    on_result
        Optional ``() -> None`` called on the worker thread after each job's result is
        in the slot (e.g. to wake the GUI thread; it must not block).
    """

    def __init__(self, name: str = "voxwarp-model", on_result: Callable[[], Any] | None = None):
        self._cond = threading.Condition()
        self._pending: dict[str, Callable[[], Any]] = {}
        self._running = False
        self._result: tuple[int, Any] | None = None
        self._error: BaseException | None = None
        self._closed = False
        self._jobs_done = 0
        self.on_result = on_result
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self._thread.start()

    # ---------------------------------------------------------------- GUI thread
    def post(self, key: str, job: Callable[[], Any]) -> None:
        """Queue ``job`` (``() -> result``) under ``key``, replacing a job of that key
        that has not started."""
        with self._cond:
            if self._closed:
                raise ModelWorkerError("the model worker is closed; start a new session")
            self._pending[key] = job
            self._cond.notify_all()

    def pending(self, key: str) -> bool:
        """Whether a job of ``key`` waits to start."""
        with self._cond:
            return key in self._pending

    @property
    def idle(self) -> bool:
        """Whether no job is pending or running."""
        with self._cond:
            return not self._pending and not self._running

    @property
    def has_result(self) -> bool:
        """Whether a result (or an error) waits for :meth:`take`."""
        with self._cond:
            return self._result is not None or self._error is not None

    @property
    def jobs_done(self) -> int:
        """Jobs finished since the worker started (their results numbered 1, 2, ...)."""
        return self._jobs_done

    def take(self) -> Any:
        """The newest finished job's result not taken yet, else None; re-raises (once)
        an exception a job raised."""
        with self._cond:
            result, self._result = self._result, None
            error, self._error = self._error, None
        if error is not None:
            raise error
        return None if result is None else result[1]

    def wait_idle(self, timeout: float = WAIT_S) -> None:
        """Wait until no job is pending or running; a :class:`ModelWorkerError` after
        ``timeout`` seconds."""
        with self._cond:
            done = self._cond.wait_for(
                lambda: self._closed or (not self._pending and not self._running), timeout
            )
        if not done:
            raise ModelWorkerError(
                f"the model's steps did not finish in {timeout:g} s; lower the grid"
                " resolution or the steps per frame"
            )

    def close(self, timeout: float = WAIT_S) -> None:
        """Drop pending jobs, let a running one finish and stop the thread (idempotent)."""
        with self._cond:
            self._closed = True
            self._pending.clear()
            self._cond.notify_all()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout)

    # ---------------------------------------------------------------- worker thread
    def _next_job(self) -> Callable[[], Any] | None:
        with self._cond:
            self._cond.wait_for(lambda: self._closed or bool(self._pending))
            if self._closed:
                return None
            key = next(iter(self._pending))
            self._running = True
            return self._pending.pop(key)

    def _loop(self) -> None:
        while (job := self._next_job()) is not None:
            result: Any = None
            error: BaseException | None = None
            try:
                result = job()
            except BaseException as exc:  # handed to the GUI thread by take()
                error = exc
            with self._cond:
                self._jobs_done += 1
                if error is None:
                    self._result = (self._jobs_done, result)
                else:
                    self._error = error
                self._running = False
                self._cond.notify_all()
            callback = self.on_result
            if callback is not None:
                callback()
