"""The shown main window the GUI tests drive (Xvfb; see tests/ui/conftest.py)."""

from __future__ import annotations

from typing import Any

import pytest


def shown_window(
    qtbot: Any,
    monkeypatch: pytest.MonkeyPatch,
    session: Any,
    size: tuple[int, int],
    *,
    active: bool = False,
    layout: str = "3d",
) -> Any:
    """A main window on ``session``, resized, shown, its first frame drawn and the
    simulation paused; ``active``: also the active window (keyboard shortcuts go to it).
    ``layout``: the central area's layout (:mod:`voxwarp.ui.mpr`); the 3D view alone by
    default, as the tests of the viewport click at pixels of a full-size view.
    No dialogs pop up (``VOXWARP_GUI_NO_DIALOGS``). The caller closes it."""
    monkeypatch.setenv("VOXWARP_GUI_NO_DIALOGS", "1")
    from voxwarp.ui.app import configure_qt

    configure_qt()
    from voxwarp.ui.main_window import MainWindow

    w = MainWindow(session)
    w.mpr.set_layout(layout)
    w.resize(*size)
    qtbot.addWidget(w)
    with qtbot.waitExposed(w):  # pytest-qt's waits are context managers: a bare call waits not
        w.show()
    qtbot.waitUntil(lambda: w.viewport.frames_drawn > 0, timeout=30000)
    w.set_running(False)
    if active:
        with qtbot.waitActive(w):
            w.activateWindow()
    return w


def press_shortcut(qtbot: Any, w: Any, key: Any, modifiers: Any = None) -> None:
    """Press a window shortcut on the viewport. Qt routes a shortcut only to the active
    window, and Xvfb without a window manager can drop activation between events, so the
    window is activated again (and waited for: ``waitActive`` is a context manager, a bare
    call returns at once) right before the key."""
    from PySide6.QtCore import Qt

    with qtbot.waitActive(w):
        w.activateWindow()
    w.viewport.setFocus()
    qtbot.keyClick(w.viewport, key, modifiers or Qt.KeyboardModifier.NoModifier)


def fish_window(qtbot: Any, monkeypatch: pytest.MonkeyPatch, size: tuple[int, int]) -> Any:
    """A shown main window of ``size`` on the fish phantom (64³, DVR, no jitter: the
    sample distance shows)."""
    from voxwarp.editing.session import EditSession
    from voxwarp.io.samples import load_sample, suggested_transfer_function
    from voxwarp.scene import Scene

    vol = load_sample("fish", shape=(64, 64, 64))
    tf = suggested_transfer_function("fish")
    scene = Scene(vol, mode="dvr", transfer_function=tf, view=(-70, 25), zoom=1.2, jitter=False)
    return shown_window(qtbot, monkeypatch, EditSession(scene), size)


def next_frame(qtbot: Any, vp: Any, timeout_ms: int = 30000) -> None:
    """Ask the viewport ``vp`` for a frame and wait until it has drawn one more."""
    n = vp.frames_drawn
    vp.update()
    qtbot.waitUntil(lambda: vp.frames_drawn > n, timeout=timeout_ms)
