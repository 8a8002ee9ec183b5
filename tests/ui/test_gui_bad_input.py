"""``voxwarp gui BAD_FILE``: the window opens (on the bundled sample) and the one-line
error shows in a dialog, as for a bad file opened from the File menu; with
``--screenshot`` (a script) it is exit code 2 and no window (issue 17, finding 9)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from PySide6.QtWidgets import QApplication, QMessageBox


@pytest.fixture
def dialogs(monkeypatch: pytest.MonkeyPatch) -> list[tuple[Any, str, str]]:
    """The message boxes the window shows, recorded instead of blocking the test."""
    monkeypatch.delenv("VOXWARP_GUI_NO_DIALOGS", raising=False)
    shown: list[tuple[Any, str, str]] = []

    def record(parent: Any, title: str, text: str, *args: Any, **kwargs: Any) -> Any:
        shown.append((parent, title, text))
        return QMessageBox.StandardButton.Ok

    for kind in ("warning", "critical"):
        monkeypatch.setattr(QMessageBox, kind, staticmethod(record))
    return shown


def _bad_scene(tmp_path: Path) -> Path:
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "voxwarp-scene",\n  "volume": {"sample": "fish"},\n  oops\n}')
    return bad


def _main_windows() -> list[Any]:
    from voxwarp.ui.main_window import MainWindow

    return [w for w in QApplication.topLevelWidgets() if isinstance(w, MainWindow)]


def test_bad_file_opens_the_window_with_the_error_dialog(
    qtbot: Any,
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
    dialogs: list[tuple[Any, str, str]],
    capsys: pytest.CaptureFixture,
) -> None:
    import voxwarp.ui.app

    before = set(map(id, _main_windows()))

    class _App:  # stands in for QApplication.exec: run until the dialog came, then close
        def exec(self) -> int:
            qtbot.waitUntil(lambda: bool(dialogs), timeout=60000)
            new = [w for w in _main_windows() if id(w) not in before]
            assert len(new) == 1
            assert new[0].isVisible()
            assert dialogs[0][0] is new[0]  # and the dialog sits on it
            new[0].close()
            return 0

        def quit(self) -> None:
            pass

    monkeypatch.setattr(voxwarp.ui.app, "application", lambda: _App())
    bad = _bad_scene(tmp_path)
    assert voxwarp.ui.app.run_gui(str(bad), size=(640, 480)) == 0
    assert len(dialogs) == 1
    text = dialogs[0][2]
    assert "\n" not in text
    assert str(bad) in text
    assert "not valid JSON" in text
    assert "line 3, column 3" in text
    assert f"voxwarp: error: {text}" in capsys.readouterr().err


def test_bad_file_with_screenshot_is_exit_2_without_a_window(
    qtbot: Any, tmp_path: Path, dialogs: list[tuple[Any, str, str]], capsys: pytest.CaptureFixture
) -> None:
    from voxwarp.ui.app import run_gui

    before = len(_main_windows())
    shot = tmp_path / "w.png"
    assert run_gui(str(tmp_path / "missing.nrrd"), screenshot=str(shot)) == 2
    err = capsys.readouterr().err
    assert err.startswith("voxwarp: error: ")
    assert "missing.nrrd" in err
    assert err.count("\n") == 1
    assert "Traceback" not in err
    assert len(_main_windows()) == before
    assert not dialogs
    assert not shot.exists()
