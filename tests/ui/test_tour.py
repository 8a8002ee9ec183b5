"""The guided step-through of a teaching demo's tour in the window."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import pytest

from voxwarp.editing.session import EditSession
from voxwarp.io.samples import load_sample
from voxwarp.scene import Scene
from voxwarp.teaching.tour import TourError, read_tour


def _tour(tmp_path: Path) -> Path:
    """Two steps: a mass-spring scene, then a lattice scene."""
    vol = load_sample("fish", shape=(32, 32, 32))
    for i, kind in enumerate(("massspring", "lattice"), start=1):
        s = EditSession(Scene(vol, jitter=False))
        s.set_deformation(kind, resolution=4)
        s.save(tmp_path / "t" / f"{i:02d}.json")
    doc = {
        "format": "voxwarp-tour",
        "version": 1,
        "demo": "compare",
        "title": "Two models",
        "figure": None,
        "steps": [
            {"title": "Springs", "text": "A mass-spring grid.", "scene": "t/01.json"},
            {"title": "Cells", "text": "A trilinear lattice.", "scene": "t/02.json"},
            {"title": "Summary", "text": "No scene: the view stays.", "scene": None},
        ],
    }
    path = tmp_path / "compare_tour.json"
    path.write_text(json.dumps(doc))
    return path


def _wait(pred: Any, seconds: float = 60) -> bool:
    from PySide6.QtWidgets import QApplication

    end = time.monotonic() + seconds
    while not pred() and time.monotonic() < end:
        QApplication.processEvents()
        time.sleep(0.01)
    return bool(pred())


def test_read_tour_checks_the_file(tmp_path: Path) -> None:
    path = _tour(tmp_path)
    tour = read_tour(path)
    assert [s.title for s in tour.steps] == ["Springs", "Cells", "Summary"]
    assert tour.steps[0].scene == (tmp_path / "t" / "01.json").resolve()
    assert tour.steps[2].scene is None
    bad = json.loads(path.read_text())
    bad["steps"][1]["scene"] = "t/missing.json"
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    with pytest.raises(TourError, match=r"step 2 scene path .*: no such scene file .*missing"):
        read_tour(tmp_path / "bad.json")
    bad["steps"][1]["scene"] = "../elsewhere.json"  # a tour reads only in its folder
    (tmp_path.parent / "elsewhere.json").write_text("{}")
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    with pytest.raises(TourError, match=r"outside the tour's folder.*--allow-dir"):
        read_tour(tmp_path / "bad.json")
    with pytest.raises(TourError, match="voxwarp demo NAME --gui"):
        read_tour(tmp_path / "nope.json")


@pytest.mark.slow
def test_tour_steps_open_their_scenes(qtbot: Any, tmp_path: Path, monkeypatch: Any) -> None:
    monkeypatch.setenv("VOXWARP_GUI_NO_DIALOGS", "1")
    from voxwarp.ui.app import configure_qt

    configure_qt()
    from voxwarp.ui.main_window import MainWindow

    vol = load_sample("fish", shape=(32, 32, 32))
    w = MainWindow(EditSession(Scene(vol, jitter=False)))
    qtbot.addWidget(w)
    with qtbot.waitExposed(w):
        w.show()
    w.start_tour(_tour(tmp_path))
    panel = w.tour_panel
    assert "Tour" in w.docks
    assert _wait(lambda: w.session.kind == "massspring")
    assert not panel.back_button.isEnabled()
    panel.next_button.click()
    assert _wait(lambda: w.session.kind == "lattice")
    assert "Cells" in panel.title_label.text()
    panel.next_button.click()  # no scene: the lattice stays
    assert _wait(lambda: panel.counter.text() == "3 / 3")
    assert w.session.kind == "lattice"
    assert not panel.next_button.isEnabled()
    panel.back_button.click()
    panel.back_button.click()  # two opens in flight: the newest wins
    assert _wait(lambda: w.session.kind == "massspring" and not w._open_task.running)
    _wait(lambda: False, 0.5)  # a late result of the older open would land now
    assert w.session.kind == "massspring"
    w.start_tour(tmp_path / "nope.json")
    assert "no such tour file" in w.errors[-1]
    w.close()
