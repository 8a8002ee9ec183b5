"""``voxwarp gui`` without a display: ``make run`` falls back to the headless render and
says so; ``--screenshot`` refuses with the fix (run it under xvfb-run)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest


def _no_display_env() -> dict[str, str]:
    env = dict(os.environ)
    for name in ("DISPLAY", "WAYLAND_DISPLAY"):
        env.pop(name, None)
    return env


@pytest.mark.slow
def test_gui_without_display_renders_headless_and_says_so(tmp_path: Path) -> None:
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "voxwarp", "gui", "--fallback-out", str(out)]
    res = subprocess.run(cmd, env=_no_display_env(), capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    assert "no display" in res.stderr
    assert "headless" in res.stderr
    assert (out / "stent_dvr.png").is_file()
    assert (out / "stent_dvr_wires.png").is_file()


def test_gui_screenshot_without_display_is_a_clear_error(tmp_path: Path) -> None:
    cmd = [sys.executable, "-m", "voxwarp", "gui", "--screenshot", str(tmp_path / "w.png")]
    res = subprocess.run(cmd, env=_no_display_env(), capture_output=True, text=True, timeout=120)
    assert res.returncode == 2
    assert "xvfb-run" in res.stderr
    assert "Traceback" not in res.stderr
    assert not (tmp_path / "w.png").exists()


@pytest.mark.slow
def test_demo_gui_opens_the_tour_in_the_window(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``voxwarp demo NAME --gui``: figure sheet and tour, then the window on the tour's
    first scene, stepping through the tour (run_gui is replaced: it would block)."""
    import voxwarp.cli.gui
    import voxwarp.cli.main
    import voxwarp.ui.app

    calls: list[tuple[str, str | None]] = []
    monkeypatch.setattr(
        voxwarp.ui.app, "run_gui", lambda spec, tour=None, **k: calls.append((spec, tour)) or 0
    )
    monkeypatch.setattr(voxwarp.cli.gui, "has_display", lambda: True)
    out = tmp_path / "demo"
    assert voxwarp.cli.main.main(["demo", "massspring", "--quick", "--gui", "--out", str(out)]) == 0
    tour = out / "massspring_tour.json"
    assert (out / "massspring.png").is_file()
    assert calls == [(calls[0][0], str(tour))]
    assert Path(calls[0][0]).is_file()  # the first step's scene
    assert Path(calls[0][0]).parent == out / "massspring_tour"


@pytest.mark.slow
def test_demo_gui_without_display_says_where_the_tour_is(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    import voxwarp.cli.gui
    import voxwarp.cli.main

    monkeypatch.setattr(voxwarp.cli.gui, "has_display", lambda: False)
    out = tmp_path / "demo"
    assert voxwarp.cli.main.main(["demo", "lattice", "--quick", "--gui", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert f"voxwarp gui --tour {out / 'lattice_tour.json'}" in err
    assert (out / "lattice_tour.json").is_file()
