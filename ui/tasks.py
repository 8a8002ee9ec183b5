"""Work off the GUI thread: a worker thread, progress and cancel, results back on the
GUI thread through queued Qt signals (the UI never freezes on a long load or build)."""

from __future__ import annotations

import threading
import traceback
from collections.abc import Callable
from typing import Any

from PySide6.QtCore import QObject, Qt, QTimer, Signal
from PySide6.QtWidgets import QProgressDialog, QWidget

from voxwarp.errors import VoxwarpError

#: a job runs ``fn(progress, cancelled)``; progress(fraction, text), cancelled() -> bool
Job = Callable[[Callable[[float, str], None], Callable[[], bool]], Any]
#: dialogs appear only for work longer than this (ms)
DIALOG_DELAY_MS = 100


class Task(QObject):
    """One job on a Python thread; its signals arrive on the GUI thread.

    Signals
    -------
    progressed(float, str)
        Fraction done and what is being done.
    succeeded(object)
        The job's result.
    failed(str)
        The error message (the clear message of a voxwarp error; other exceptions get
        their type and message, never a traceback in the dialog).
    finished()
        After either.
    """

    progressed = Signal(float, str)
    succeeded = Signal(object)
    failed = Signal(str)
    finished = Signal()

    def __init__(self, job: Job, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self._job = job
        self._cancel = threading.Event()
        self._thread: threading.Thread | None = None
        self.result: Any = None
        self.error: str | None = None
        self._done = False

    def start(self) -> Task:
        """Run the job on a new daemon thread."""
        self._thread = threading.Thread(target=self._run, name="voxwarp-task", daemon=True)
        self._thread.start()
        return self

    def cancel(self) -> None:
        """Ask the job to stop (it checks ``cancelled()``); its result is dropped."""
        self._cancel.set()

    @property
    def cancelled(self) -> bool:
        """Whether :meth:`cancel` was called."""
        return self._cancel.is_set()

    @property
    def running(self) -> bool:
        """Whether the job is still to finish (also before its thread started)."""
        return not self._done

    def wait(self, timeout: float | None = None) -> bool:
        """Block until the thread ends (tests, shutdown: a window waits for its tasks
        before Qt deletes them with it); True if it ended."""
        if self._thread is not None:
            self._thread.join(timeout)
        return self._done

    def _run(self) -> None:
        try:
            result = self._job(
                lambda f, text="": self.progressed.emit(float(f), text), self._cancel.is_set
            )
        except VoxwarpError as exc:
            self.error = str(exc)
        except MemoryError:
            self.error = "out of memory: close other programs or use a smaller volume"
        except Exception as exc:
            self.error = f"{type(exc).__name__}: {exc}"
            traceback.print_exc()
        else:
            self.result = result
        if self.error is not None:
            self.failed.emit(self.error)
        elif not self.cancelled:
            self.succeeded.emit(self.result)
        self.finished.emit()
        # done only once the thread is past its emits: whoever waits for the task (a
        # window closing) may then delete it without a signal leaving a deleted object
        self._done = True


def run_with_progress(
    parent: QWidget,
    title: str,
    job: Job,
    on_success: Callable[[Any], None],
    on_failure: Callable[[str], None],
) -> Task:
    """Run ``job`` off the GUI thread behind a cancellable progress dialog that shows
    only if the job takes longer than :data:`DIALOG_DELAY_MS`."""
    task = Task(job, parent)
    dialog = QProgressDialog(title, "Cancel", 0, 1000, parent)
    dialog.setWindowTitle("voxwarp")
    dialog.setWindowModality(Qt.WindowModality.WindowModal)
    dialog.setMinimumDuration(DIALOG_DELAY_MS)
    dialog.setAutoClose(False)
    dialog.setAutoReset(False)
    dialog.setValue(0)
    dialog.canceled.connect(task.cancel)

    def progressed(f: float, text: str) -> None:
        dialog.setValue(int(1000 * max(0.0, min(1.0, f))))
        if text:
            dialog.setLabelText(f"{title}: {text}")

    def finished() -> None:
        dialog.reset()
        dialog.hide()
        dialog.deleteLater()

    task.progressed.connect(progressed)
    task.succeeded.connect(on_success)
    task.failed.connect(on_failure)
    task.finished.connect(finished)
    QTimer.singleShot(0, task.start)
    return task
