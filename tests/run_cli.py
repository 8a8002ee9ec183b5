"""Running the ``voxwarp`` command line in a child process, as a user would (tests)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

#: the repository root (the child imports voxwarp from here)
REPO = Path(__file__).resolve().parents[1]


def run_cli(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    """``voxwarp ARGS...`` in the repository root; output captured, no check."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run(
        [sys.executable, "-m", "voxwarp.cli.main", *args],
        capture_output=True,
        text=True,
        env=env,
        cwd=REPO,
        timeout=timeout,
        check=False,
    )
