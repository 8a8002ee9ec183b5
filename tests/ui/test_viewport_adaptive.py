"""Interactive frames of the viewport (Xvfb, see conftest): while the user orbits, the
frame is drawn at the adaptive level (lower resolution, longer sample distance); once
the view rests, the frame is exactly the one drawn without any interaction."""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest
from PySide6.QtCore import QPoint, Qt

from tests.ui.test_main_window import frame
from tests.ui.windows import fish_window, next_frame
from voxwarp.render.adaptive_quality import FULL, LEVELS

SIZE = (900, 700)


@pytest.fixture
def window(qtbot: Any, monkeypatch: pytest.MonkeyPatch) -> Any:
    """A shown main window on the fish phantom (64³, DVR: the sample distance shows)."""
    w = fish_window(qtbot, monkeypatch, SIZE)
    yield w
    w.close()


def test_orbit_draws_coarse_frames_and_the_rest_frame_equals_the_uninteracted_one(
    window: Any, qtbot: Any
) -> None:
    vp = window.viewport
    rest = frame(window)
    camera = copy.deepcopy(vp.camera)
    # orbit from an empty corner (no handles without a deformation), button held
    start = QPoint(30, 30)
    qtbot.mousePress(vp, Qt.MouseButton.LeftButton, pos=start)
    for k in range(1, 5):
        qtbot.mouseMove(vp, pos=start + QPoint(25 * k, 10 * k))
    assert vp.interacting()
    assert not np.allclose(vp.camera.rotation, camera.rotation)  # it orbited
    next_frame(qtbot, vp)
    assert vp.last_quality != FULL
    assert vp.last_quality in LEVELS
    # back to the first view while still dragging: the coarse frame is not the rest frame
    vp.camera = copy.deepcopy(camera)
    coarse = vp.screenshot()[..., :3].astype(np.float64)
    assert vp.last_quality != FULL
    assert np.abs(coarse - rest).max() > 8  # lower resolution and sampling show
    assert np.abs(coarse - rest).mean() < 20  # but it is the same picture
    qtbot.mouseRelease(vp, Qt.MouseButton.LeftButton, pos=start + QPoint(100, 40))
    vp.camera = copy.deepcopy(camera)  # the release does not move it; be explicit
    after = frame(window)
    assert vp.last_quality == FULL
    assert np.array_equal(after, rest)


def test_the_live_slices_count_in_the_frame_budget(window: Any, qtbot: Any) -> None:
    """The slice views redrawn after each interactive frame take part of the budget:
    with their time over it, the next level is coarser however fast the 3D frame was."""
    vp = window.viewport
    start = QPoint(30, 30)
    qtbot.mousePress(vp, Qt.MouseButton.LeftButton, pos=start)
    qtbot.mouseMove(vp, pos=start + QPoint(40, 10))
    try:
        assert vp.interacting()  # the button is held and the mouse moved
        vp.adaptive.level = 3  # a middle level: room both ways
        vp.companion_s = 10.0  # the slices took 10 s (the budget is 1/15 s)
        next_frame(qtbot, vp)
        assert vp.last_quality == LEVELS[3]
        assert vp.adaptive.level == 4
    finally:
        vp.companion_s = 0.0
        qtbot.mouseRelease(vp, Qt.MouseButton.LeftButton, pos=start + QPoint(40, 10))
