"""A private Xvfb display for the napari child processes (as tests/ui/conftest.py
starts one for the voxwarp window; an existing DISPLAY is never used)."""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from tests.xvfb import start_xvfb


@contextmanager
def xvfb_display(screen: str = "1280x1024x24") -> Iterator[str]:
    """Start ``Xvfb`` on a free display for the block; yields ``":N"``."""
    if shutil.which("Xvfb") is None:
        pytest.skip("Xvfb is not installed (bash scripts/install-system-deps.sh)")
    proc, number = start_xvfb(screen)
    try:
        if not number:
            pytest.fail("Xvfb did not start (no display number reported)")
        yield f":{number}"
    finally:
        proc.kill()
        proc.wait()


def x_env(display: str, gl_integration: str | None) -> dict[str, str]:
    """The environment of a Qt child process on ``display``; ``gl_integration`` sets
    ``QT_XCB_GL_INTEGRATION`` (``None``: Qt's default, GLX)."""
    env = {k: v for k, v in os.environ.items() if k not in ("WAYLAND_DISPLAY",)}
    env.update(DISPLAY=display, QT_QPA_PLATFORM="xcb")
    env.pop("QT_XCB_GL_INTEGRATION", None)
    if gl_integration is not None:
        env["QT_XCB_GL_INTEGRATION"] = gl_integration
    return env
