"""The GUI on a volume with a long axis (issue 17, finding 2): a volume over the GPU's 3D
texture limit shows the one-line error (naming the axis and ``--downsample``) instead of
a black view with a traceback on stderr; one at the limit draws."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.ui.windows import shown_window
from voxwarp.editing.session import EditSession
from voxwarp.scene import Scene


@pytest.fixture
def window(qtbot: Any, monkeypatch: pytest.MonkeyPatch) -> Any:
    """A small shown main window on a tiny volume, its first frame drawn."""
    from voxwarp.core.volume import Volume

    data = np.zeros((8, 8, 8), np.uint8)
    data[2:6, 2:6, 2:6] = 200
    session = EditSession(Scene(Volume(data), mode="mip", jitter=False))
    w = shown_window(qtbot, monkeypatch, session, (640, 480))
    yield w
    w.close()


def _draw(w: Any) -> None:
    from PySide6.QtWidgets import QApplication

    n = w.viewport.frames_drawn
    w.viewport.update()
    deadline = time.monotonic() + 60
    while w.viewport.frames_drawn == n and time.monotonic() < deadline:
        QApplication.processEvents()
        time.sleep(0.01)
    assert w.viewport.frames_drawn > n, "no frame was drawn"


def test_volume_over_the_texture_limit_shows_the_error(
    window: Any, tmp_path: Path, capfd: pytest.CaptureFixture
) -> None:
    w = window
    limit = int(w.viewport.ctx.info["GL_MAX_3D_TEXTURE_SIZE"])
    path = tmp_path / "long.npy"
    np.save(path, np.zeros((4, 4, limit + 1), np.uint8))
    w.open_path(path, wait=True)
    _draw(w)
    assert w.errors, "no error was shown"
    msg = w.errors[-1]
    assert "\n" not in msg
    assert f"{limit + 1} voxels along axis 2 (z)" in msg
    assert "--downsample" in msg
    assert "Traceback" not in capfd.readouterr().err


def test_volume_at_the_texture_limit_draws(window: Any, tmp_path: Path) -> None:
    w = window
    limit = int(w.viewport.ctx.info["GL_MAX_3D_TEXTURE_SIZE"])
    data = np.zeros((8, 8, limit), np.uint8)
    for k in (0, limit // 2, limit - 4):
        data[2:6, 2:6, k : k + 4] = 200
    path = tmp_path / "at_limit.npy"
    np.save(path, data)
    errors = len(w.errors)
    w.open_path(path, wait=True)
    assert w.session.volume.shape == (8, 8, limit)
    assert w.session.scene.mode == "dvr"  # cell skipping's mode (its maps overflowed)
    _draw(w)
    assert w.viewport.renderer.last_skip_kind == "blocks"  # the cell map would not fit
    assert len(w.errors) == errors, w.errors[errors:]
    img = w.viewport.screenshot()[..., :3].astype(float)
    assert img.max() > 100  # the spots show, not a black (or red error) view
