"""``voxwarp gui`` without a display: ``make run`` falls back to the headless render and
says so; ``--screenshot`` refuses with the fix (run it under xvfb-run)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path


def _no_display_env() -> dict[str, str]:
    env = dict(os.environ)
    for name in ("DISPLAY", "WAYLAND_DISPLAY"):
        env.pop(name, None)
    return env


def test_gui_without_display_renders_headless_and_says_so(tmp_path: Path) -> None:
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "ui.cli", "gui", "--fallback-out", str(out)]
    res = subprocess.run(cmd, env=_no_display_env(), capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    assert "no display" in res.stderr
    assert "headless" in res.stderr
    assert (out / "stent_dvr.png").is_file()
    assert (out / "stent_dvr_wires.png").is_file()


def test_gui_screenshot_without_display_is_a_clear_error(tmp_path: Path) -> None:
    cmd = [sys.executable, "-m", "ui.cli", "gui", "--screenshot", str(tmp_path / "w.png")]
    res = subprocess.run(cmd, env=_no_display_env(), capture_output=True, text=True, timeout=120)
    assert res.returncode == 2
    assert "xvfb-run" in res.stderr
    assert "Traceback" not in res.stderr
    assert not (tmp_path / "w.png").exists()
