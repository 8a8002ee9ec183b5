"""Frame time of a scene at each interactive volume resolution, against full resolution
in the same run.

``python scripts/interaction_resolution_bench.py [--input sample:stent] [--size 512]
[--levels 1,2,4] [--frames 5] [--rounds 2]``

Renders INPUT (DVR, no jitter, the fitted camera) offscreen at ``size``² through
:class:`voxwarp.render.interaction_volume.InteractionVolumes` at each level of
``Scene.interactive_downsample``: the median frame time of ``frames`` frames after 2
warm-up frames, best of ``rounds`` interleaved rounds, its ratio against level 1, and the
one-time cost of making each reduced copy, with the 1-minute load average before and
after (for ``docs/benchmarks.md`` on a shared machine).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from voxwarp.inputs import load_input
from voxwarp.render.interaction_volume import reduced_volume
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.scene import Scene


def _load() -> str:
    with open("/proc/loadavg", encoding="ascii") as f:
        return f.read().split()[0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--input", default="sample:stent")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--levels", default="1,2,4")
    ap.add_argument("--frames", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args()
    levels = [int(v) for v in args.levels.split(",")]
    vol = load_input(args.input)
    vol = vol.volume if isinstance(vol, Scene) else vol
    print(f"load {_load()}; {vol.name} {vol.shape}; {args.size}x{args.size}")
    scene = Scene(vol, mode="dvr", jitter=False)
    scenes, made = {}, {}
    for f in levels:
        t0 = time.perf_counter()
        small = reduced_volume(vol, f)
        made[f] = time.perf_counter() - t0
        scenes[f] = scene.copy(volume=small, window=scene.window, camera=scene.resolved_camera())
    best: dict[int, float] = {}
    with OffscreenRenderer(args.size, args.size) as r:
        for _ in range(args.rounds):
            for f in levels:
                ms = float(np.median(r.time_frames(scenes[f], frames=args.frames, warmup=2)))
                best[f] = min(best.get(f, ms), ms)
    for f in levels:
        shape = "x".join(map(str, scenes[f].volume.shape))
        print(
            f"1/{f}: {shape}, frame {best[f]:.1f} ms = {best[f] / best[levels[0]]:.3f}x of"
            f" 1/{levels[0]}; reduced copy made in {made[f]:.3f} s"
        )
    print(f"load {_load()}")


if __name__ == "__main__":
    main()
