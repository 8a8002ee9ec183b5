"""File › Open of a scene that names a file outside its folder asks to allow that folder
(ui/folder_access.py).

The question is answered programmatically (the window's ``ask_allow_folder`` is replaced).
Oracle: yes opens the scene with the outside volume's voxels; no keeps the open volume.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.ui.test_main_window import window  # noqa: F401 - the fixture
from voxwarp.core import allowed_folders
from voxwarp.core.volume import Volume
from voxwarp.io.volumes import save_volume

DATA = np.arange(6 * 7 * 8, dtype=np.float32).reshape(6, 7, 8)


def _scene_naming_outside(tmp_path: Path) -> tuple[Path, Path]:
    target = save_volume(Volume(DATA), tmp_path / "shared/v.nrrd").resolve()
    scene = tmp_path / "scn/s.json"
    scene.parent.mkdir()
    scene.write_text(json.dumps({"format": "voxwarp-scene", "volume": {"path": str(target)}}))
    return scene, target


def _settle(window: Any, first: Any) -> None:  # noqa: F811
    from PySide6.QtWidgets import QApplication

    end = time.monotonic() + 60  # a second open (after yes) runs off the GUI thread
    while (window._open_task is first or window._open_task.running) and time.monotonic() < end:
        QApplication.processEvents()
        time.sleep(0.01)
    for _ in range(5):
        QApplication.processEvents()


@pytest.mark.parametrize("yes", [True, False])
def test_open_asks_to_allow_the_folder(
    window: Any,  # noqa: F811
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    yes: bool,
) -> None:
    import voxwarp.ui.folder_access as folder_access
    import voxwarp.ui.main_window as main_window

    monkeypatch.setattr(allowed_folders, "_PROCESS", [])  # allowed folders do not leak
    scene, target = _scene_naming_outside(tmp_path)
    asked: list[Path | None] = []

    def answer(parent: Any, error: BaseException) -> bool:
        asked.append(folder_access.outside_folder(error))
        assert "\n" not in str(error)
        if yes:
            allowed_folders.allow_folder(target.parent)
        return yes

    monkeypatch.setattr(main_window, "ask_allow_folder", answer)
    before = window.session.volume
    first = window.open_path(scene, wait=True)
    if yes:
        _settle(window, first)
    assert asked == [target.parent]
    if yes:
        np.testing.assert_array_equal(window.session.volume.data, DATA)
    else:
        assert window.session.volume is before
