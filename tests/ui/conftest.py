"""GUI tests: a real window on an X server this conftest starts itself (Xvfb).

Qt's ``offscreen`` platform cannot host a ``QOpenGLWidget``, so these tests run the
``xcb`` platform with EGL (``QT_XCB_GL_INTEGRATION=xcb_egl``, Mesa llvmpipe on machines
without a GPU) against a private Xvfb display started here, before pytest-qt makes the
``QApplication``. An existing ``DISPLAY`` is never used: tests must not pop windows on a
developer's desktop nor depend on one. ``scripts/install-system-deps.sh`` installs Xvfb
and the xcb libraries; without Xvfb the GUI tests fail with that instruction.
"""

from __future__ import annotations

import atexit
import os
import shutil

import pytest

from tests.xvfb import start_xvfb


def _start_xvfb() -> None:
    """Start ``Xvfb`` on a free display (``-displayfd``) and point Qt at it."""
    if shutil.which("Xvfb") is None:
        raise pytest.UsageError(
            "the GUI tests need Xvfb: run `bash scripts/install-system-deps.sh` as root"
            " (Debian package xvfb and the xcb libraries it lists)"
        )
    proc, number = start_xvfb("1600x1200x24")
    if not number:
        proc.kill()
        raise pytest.UsageError("Xvfb did not start (no display number reported)")
    atexit.register(proc.kill)
    os.environ["DISPLAY"] = f":{number}"
    os.environ["QT_QPA_PLATFORM"] = "xcb"
    os.environ["QT_XCB_GL_INTEGRATION"] = "xcb_egl"
    os.environ.pop("WAYLAND_DISPLAY", None)


_start_xvfb()

# PySide6 6.12 loses references to None on CPython 3.11 (see guard_none_refcount):
# without this guard a long GUI test run aborts when the interpreter finalizes
from voxwarp.ui.app import guard_none_refcount  # noqa: E402

guard_none_refcount()


@pytest.fixture(autouse=True, scope="session")
def _private_settings(tmp_path_factory: pytest.TempPathFactory) -> None:
    """Qt settings (recent files) go to a temporary folder, never to the user's."""
    from PySide6.QtCore import QSettings

    folder = str(tmp_path_factory.mktemp("qt-settings"))
    for fmt in (QSettings.Format.NativeFormat, QSettings.Format.IniFormat):
        QSettings.setPath(fmt, QSettings.Scope.UserScope, folder)
