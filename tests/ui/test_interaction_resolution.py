"""The volume resolution of interactive frames in the window (Xvfb, see conftest): the
Volume panel's Interaction box sets ``Scene.interactive_downsample`` as an undoable
edit; frames drawn while the user orbits use the reduced volume, the frame at rest and
a screenshot taken mid-drag the full one."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PySide6.QtCore import QPoint, Qt

from tests.ui.test_main_window import frame
from tests.ui.windows import fish_window, next_frame
from voxwarp.io.images import read_image

SIZE = (900, 700)


@pytest.fixture
def window(qtbot: Any, monkeypatch: pytest.MonkeyPatch) -> Any:
    """A shown main window on the fish phantom (64³, DVR)."""
    w = fish_window(qtbot, monkeypatch, SIZE)
    yield w
    w.close()


def test_interaction_box_is_an_undoable_scene_setting(window: Any) -> None:
    spin = window.volume_panel.resolution_spin
    scene = window.session.scene
    assert spin.value() == 1
    assert scene.interactive_downsample == 1
    spin.setValue(4)
    assert scene.interactive_downsample == 4
    assert window.undo_stack.undoText() == "Interaction resolution"
    assert window.session.to_dict()["interactive_downsample"] == 4
    window.undo_stack.undo()
    assert scene.interactive_downsample == 1
    assert spin.value() == 1
    window.undo_stack.redo()
    assert scene.interactive_downsample == 4


def test_interactive_frames_draw_the_reduced_volume_stills_the_full_one(
    window: Any, qtbot: Any, tmp_path: Path
) -> None:
    vp = window.viewport
    full = window.session.scene.volume
    rest = frame(window)
    window.volume_panel.resolution_spin.setValue(2)
    start = QPoint(30, 30)
    qtbot.mousePress(vp, Qt.MouseButton.LeftButton, pos=start)
    try:
        for k in range(1, 4):
            qtbot.mouseMove(vp, pos=start + QPoint(20 * k, 8 * k))
        assert vp.interacting()
        next_frame(qtbot, vp)
        # the reduced copy is made on a worker: the full volume draws until it is in
        qtbot.waitUntil(lambda: vp.interaction_volumes.cached(full, 2) is not None, timeout=30000)
        next_frame(qtbot, vp)
        assert vp.interacting()
        assert vp.last_volume is not full
        assert vp.last_volume.shape == (32, 32, 32)
        np.testing.assert_allclose(vp.last_volume.bounds, full.bounds)
        camera = vp.camera
        # a screenshot taken mid-drag is a still: full volume, full quality
        out = window.export_screenshot(tmp_path / "still.png")
        assert out is not None
        assert vp.last_volume is full
        still = read_image(out)[..., :3].astype(np.float64)
        assert still.shape[:2] == rest.shape[:2]
    finally:
        qtbot.mouseRelease(vp, Qt.MouseButton.LeftButton, pos=start + QPoint(60, 24))
    vp.camera = camera
    after = frame(window)
    assert vp.last_volume is full
    np.testing.assert_array_equal(after, still)  # the still is the rest frame
