"""File › Open of a 4-D file asks which time point to open (ui/frame_dialog.py).

The dialog is answered programmatically: the window's ``ask_frame`` is replaced by one
that builds the real :class:`FrameDialog`, checks what it shows, sets its spin box and
returns its choice. Oracle: the opened volume equals that frame of the nibabel array.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.ui.test_main_window import window  # noqa: F401 - the fixture
from voxwarp.io.frames import FrameChoiceError
from voxwarp.io.volumes import load_volume

nib = pytest.importorskip("nibabel")


def _series(tmp_path: Path) -> tuple[Path, np.ndarray]:
    data = np.arange(8 * 9 * 10 * 4, dtype=np.int16).reshape(8, 9, 10, 4)
    img = nib.Nifti1Image(data, np.diag([2.0, 2.0, 3.0, 1.0]))
    img.header.set_xyzt_units("mm", "sec")
    img.header["pixdim"][4] = 1.5
    path = tmp_path / "series.nii.gz"
    nib.save(img, str(path))
    return path, data


def test_dialog_shows_shape_count_and_step(qtbot: Any, tmp_path: Path) -> None:
    from PySide6.QtWidgets import QLabel

    from voxwarp.ui.frame_dialog import FrameDialog

    path, _ = _series(tmp_path)
    with pytest.raises(FrameChoiceError) as info:
        load_volume(path)
    dialog = FrameDialog(None, path.name, info.value)
    qtbot.addWidget(dialog)
    labels = " ".join(w.text() for w in dialog.findChildren(QLabel))
    assert "4 time points (1.5 s apart)" in labels
    assert "8 × 9 × 10 × 4" in labels
    assert list(dialog.spins) == ["frame_index"]
    spin = dialog.spins["frame_index"]
    assert (spin.minimum(), spin.maximum()) == (0, 3)
    spin.setValue(2)
    assert dialog.choice() == {"frame_index": 2}


def test_open_asks_and_loads_the_chosen_frame(
    window: Any,  # noqa: F811
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from PySide6.QtWidgets import QApplication

    import voxwarp.ui.main_window as main_window
    from voxwarp.ui.frame_dialog import FrameDialog

    path, data = _series(tmp_path)
    asked: list[str] = []

    def answer(parent: Any, name: str, error: FrameChoiceError) -> dict[str, int]:
        dialog = FrameDialog(parent, name, error)
        asked.append(name)
        dialog.spins["frame_index"].setValue(3)
        return dialog.choice()

    monkeypatch.setattr(main_window, "ask_frame", answer)
    first = window.open_path(path, wait=True)
    end = time.monotonic() + 60  # the second open, with the choice, runs off the GUI thread
    while (window._open_task is first or window._open_task.running) and time.monotonic() < end:
        QApplication.processEvents()
        time.sleep(0.01)
    for _ in range(5):
        QApplication.processEvents()
    assert asked == ["series.nii.gz"]
    vol = window.session.volume
    assert vol.frame_choice == {"frame_index": 3}
    np.testing.assert_array_equal(vol.data, load_volume(path, frame_index=3).data)
    np.testing.assert_array_equal(vol.data, data[..., 3])


def test_cancel_keeps_the_open_volume(
    window: Any,  # noqa: F811
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import voxwarp.ui.main_window as main_window

    path, _ = _series(tmp_path)
    before = window.session.volume
    monkeypatch.setattr(main_window, "ask_frame", lambda *a: None)
    window.open_path(path, wait=True)
    assert window.session.volume is before


def test_gui_input_of_a_4d_file_asks_before_the_window_opens(
    qtbot: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import voxwarp.ui.frame_dialog as frame_dialog
    from voxwarp.ui.app import open_window

    path, data = _series(tmp_path)
    monkeypatch.setattr(frame_dialog, "ask_frame", lambda parent, name, error: {"frame_index": 1})
    opened = open_window(str(path), size=(640, 480))
    qtbot.addWidget(opened)
    assert opened.session.volume.frame_choice == {"frame_index": 1}
    np.testing.assert_array_equal(opened.session.volume.data, data[..., 1])
    opened.close()
