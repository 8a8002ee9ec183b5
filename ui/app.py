"""Start the desktop application: Qt settings for OpenGL 4.3+ and the main window."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

from PySide6.QtCore import QTimer
from PySide6.QtGui import QSurfaceFormat
from PySide6.QtWidgets import QApplication

from voxwarp.errors import VoxwarpError
from voxwarp.io.frames import FrameChoiceError
from voxwarp.io.samples import DEFAULT_SAMPLE

#: after the first frame, the time given to the docks to paint before a screenshot (ms)
SCREENSHOT_SETTLE_MS = 300
#: with --screenshot, the longest wait for the final (full-quality, at rest) frame (ms)
SCREENSHOT_TIMEOUT_MS = 120_000


def guard_none_refcount() -> None:
    """Keep CPython 3.11 from aborting on PySide6's lost references to ``None``.

    PySide6 6.12 drops one reference to ``None`` on every call of a Qt method that
    returns nothing (``label.setText``, ``spin.setValue``, ``widget.setEnabled`` ...).
    From Python 3.12 on ``None`` is immortal and that is harmless; on 3.11 a long
    session (or a long GUI test run) brings its reference count to zero and CPython
    aborts with "none_dealloc: deallocating None". ``None`` is a static object that is
    never freed, so its count is raised once by far more than any session can use up,
    which is what 3.12's immortality does. Idempotent in effect; a no-op on 3.12+.
    """
    if sys.version_info >= (3, 12) or getattr(guard_none_refcount, "done", False):
        return
    import ctypes

    ctypes.c_ssize_t.from_address(id(None)).value += 1 << 40
    guard_none_refcount.done = True  # type: ignore[attr-defined]


def configure_qt() -> None:
    """Ask Qt for an OpenGL 4.5 core context with depth, through EGL on X11.

    EGL is how Mesa's software rasteriser (llvmpipe) gives 4.5 core on machines without
    a GPU, and works on GPU drivers too; ``QT_XCB_GL_INTEGRATION`` set by the user wins.
    Must run before the ``QApplication`` is made.
    """
    guard_none_refcount()
    os.environ.setdefault("QT_XCB_GL_INTEGRATION", "xcb_egl")
    fmt = QSurfaceFormat()
    fmt.setVersion(4, 5)
    fmt.setProfile(QSurfaceFormat.OpenGLContextProfile.CoreProfile)
    fmt.setDepthBufferSize(24)
    fmt.setSwapInterval(0)
    QSurfaceFormat.setDefaultFormat(fmt)


def application() -> QApplication:
    """The running ``QApplication``, made (after :func:`configure_qt`) if needed."""
    app = QApplication.instance()
    if app is None:
        configure_qt()
        app = QApplication(sys.argv[:1])
        app.setApplicationName("voxwarp")
        app.setOrganizationName("voxwarp")
    return app  # type: ignore[return-value]


def open_window(
    input_spec: str,
    size: tuple[int, int] = (1280, 820),
    series: int | str | None = None,
    fallback: bool = True,
    interactive_downsample: int | None = None,
    **pick: int,
) -> Any:
    """Show the main window on ``input_spec``. With ``fallback``, an INPUT that cannot be
    opened (a :class:`~voxwarp.errors.VoxwarpError`) still opens the window, on the
    bundled sample, and shows the one-line error in a dialog (and on stderr), as File >
    Open does; without, the error is raised. ``interactive_downsample`` (when given)
    replaces the scene's volume resolution of interactive frames."""
    # the window loads moderngl and scipy: Qt set-up (configure_qt) stays light without it
    from voxwarp.ui.main_window import MainWindow, load_session_input

    error: str | None = None
    try:
        session = _session_asking(input_spec, series, pick, ask=fallback)
    except VoxwarpError as exc:
        if not fallback:
            raise
        error = str(exc)
        print(f"voxwarp: error: {error}", file=sys.stderr)
        input_spec = f"sample:{DEFAULT_SAMPLE}"
        session = load_session_input(input_spec)
    if interactive_downsample is not None:
        session.scene.interactive_downsample = interactive_downsample
    window = MainWindow(session, input_spec)
    window.resize(*size)
    window.show()
    if error is not None:
        QTimer.singleShot(0, lambda: window.show_error(error))  # over the shown window
    return window


def _session_asking(spec: str, series: Any, pick: dict[str, int], ask: bool) -> Any:
    """The session for INPUT; a 4-D file opened without a choice asks which volume
    (:func:`voxwarp.ui.frame_dialog.ask_frame`) when ``ask``, else the one-line error."""
    from voxwarp.ui.main_window import load_session_input

    try:
        return load_session_input(spec, series=series, **pick)
    except FrameChoiceError as exc:
        from voxwarp.ui.frame_dialog import ask_frame

        choice = ask_frame(None, Path(spec).name, exc) if ask else None
        if choice is None:
            raise
        return load_session_input(spec, series=series, **choice)


def run_gui(
    input_spec: str,
    screenshot: str | None = None,
    size: tuple[int, int] = (1280, 820),
    tour: str | None = None,
    series: int | str | None = None,
    interactive_downsample: int | None = None,
    **pick: int,
) -> int:
    """Open the window on ``input_spec``; with ``tour``, step through a teaching demo's
    tour (its first scene replaces ``input_spec``); with ``screenshot``, save a PNG of
    the whole window once the first frame is drawn and quit; ``interactive_downsample``:
    the volume resolution of interactive frames (:func:`open_window`). A bad INPUT opens the window
    on the sample with the error in a dialog (:func:`open_window`), or with
    ``screenshot`` returns 2 without a window. Returns the exit code."""
    app = application()
    try:  # with --screenshot (a script) a bad INPUT ends it: no window to wait on
        window = open_window(
            input_spec,
            size=size,
            series=series,
            fallback=not screenshot,
            interactive_downsample=interactive_downsample,
            **pick,
        )
    except VoxwarpError as exc:
        print(f"voxwarp: error: {exc}", file=sys.stderr)
        return 2
    if tour is not None:
        window.start_tour(tour)
    status = {"code": 0}
    if screenshot:
        out = Path(screenshot)

        def shoot() -> None:
            if window.export_screenshot(out, whole_window=True) is None:
                status["code"] = 1
            else:
                print(out)
            window.close()
            app.quit()

        def once() -> None:
            if not status.get("shot"):
                status["shot"] = 1
                shoot()

        def frame_drawn(_ms: float) -> None:
            # a coarse frame drawn while a big volume's skip maps build is not the picture
            if window.viewport.showing_final_frame():
                window.viewport.frameDrawn.disconnect(frame_drawn)
                QTimer.singleShot(SCREENSHOT_SETTLE_MS, once)

        window.viewport.frameDrawn.connect(frame_drawn)
        QTimer.singleShot(SCREENSHOT_TIMEOUT_MS, once)  # never wait forever
    app.exec()
    return status["code"]
