"""The GUI shows the modality-aware defaults line when a volume opens (status bar)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tests.core.test_modality import PAD, padded_ct
from tests.ui.test_main_window import window  # noqa: F401 - the fixture
from voxwarp.io.volumes import save_volume


def test_opening_a_volume_shows_its_defaults(window: Any, tmp_path: Path) -> None:  # noqa: F811
    w = window
    path = save_volume(padded_ct(), tmp_path / "padded_ct.npz")
    w.open_path(path, wait=True)
    assert w.session.volume.data.min() > PAD  # the padding was masked on opening
    assert w.session.scene.transfer_function.name == "ct-bone"
    message = w.statusBar().currentMessage()
    assert message.startswith("CT (values look like HU")
    assert "tf ct-bone, shaded DVR" in message
    assert f"padding {PAD} masked" in message
