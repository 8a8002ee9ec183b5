"""``Scene.save`` killed with SIGKILL at random moments never leaves a partial scene.

A child process saves two different scenes to one path in a loop; the test kills it at
random times (seeded) and checks after every kill that the file is one of the two whole
scenes (never a mix or a truncated file), and that the next save removes the temporary
files the killed writers left (their process is gone).
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from voxwarp.core.files import is_temp_name

CHILD = r"""
import sys
import numpy as np
from voxwarp.core.volume import Volume
from voxwarp.scene import Scene

path = sys.argv[1]
vol = Volume(np.arange(4096, dtype=np.uint8).reshape(16, 16, 16), name="v")
scenes = [Scene(vol, mode="mip", seed=s, view="+z") for s in (1, 2)]
print("ready", flush=True)
i = 0
while True:
    scenes[i % 2].save(path)
    i += 1
"""


@pytest.mark.slow
def test_scene_save_killed_at_random_moments_keeps_a_whole_scene(tmp_path: Path) -> None:
    path = tmp_path / "scene.json"
    rng = random.Random(17)
    seen = set()
    for _ in range(8):
        child = subprocess.Popen(
            [sys.executable, "-c", CHILD, str(path)], stdout=subprocess.PIPE, text=True
        )
        assert child.stdout is not None
        assert child.stdout.readline().strip() == "ready"
        time.sleep(rng.uniform(0.05, 0.4))
        os.kill(child.pid, signal.SIGKILL)
        child.wait()
        if path.exists():
            d = json.loads(path.read_text())  # whole JSON: never a partial file
            assert d["format"] == "voxwarp-scene"
            seen.add(d["seed"])
            assert d["seed"] in (1, 2)
    assert seen, "no save finished in 8 runs"
    # a later save cleans the temporaries the killed writers left
    from voxwarp.scene import Scene

    Scene.load(path).save(path)
    left = [p.name for p in tmp_path.iterdir() if is_temp_name(p.name)]
    assert left == []
