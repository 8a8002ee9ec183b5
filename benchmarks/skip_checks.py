"""``python -m benchmarks.skip_checks``: skip-map checks per straight sample, on this machine.

A lab study behind docs/benchmarks.md, section 'Fewer skip-map fetches per straight
sample'. The undeformed 512² frame of each scan (``--volumes``; the bench camera, the
scan's suggested transfer function) is drawn by renderers that differ only in
``samples_per_check`` (``--per-check``, 1 to 4: lattice samples a straight ray with cell
maps takes per skip-map check, :mod:`voxwarp.render.skipping.checks`; 1 is the schedule
before, one check per sample), interleaved frame by frame in one process; the table
gives their medians and ratios to the first value listed. Every schedule must draw the
same image byte for byte (a sample in an invisible cell adds exactly nothing): a
difference raises.
"""

from __future__ import annotations

import argparse
import statistics
from collections.abc import Sequence
from typing import Any

import numpy as np

from voxwarp.bench.render import bench_camera
from voxwarp.io.samples import load_sample, suggested_transfer_function
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.scene import Scene


def _load() -> str:
    with open("/proc/loadavg") as f:
        return " ".join(f.read().split()[:3])


def measure(
    name: str, mode: str, shading: bool, per_check: Sequence[int], frames: int, size: int = 512
) -> str:
    """One markdown row ``| scan | mode | shading | ms per variant | ratios | load |``."""
    vol = load_sample(name)
    scene = Scene(
        vol,
        mode=mode,  # type: ignore[arg-type]
        transfer_function=suggested_transfer_function(name),
        camera=bench_camera(vol),
        shading=shading,
        background=(0.0, 0.0, 0.0, 0.0),
    )
    with OffscreenRenderer(8, 8) as r0:
        rs = {n: OffscreenRenderer(size, size, ctx=r0.ctx) for n in per_check}
        try:
            images: dict[int, Any] = {}
            for n, r in rs.items():
                r.renderer.samples_per_check = n
                r.render(scene)  # compiles; cell maps from the second draw on
                images[n] = np.asarray(r.render(scene))
                if r.renderer.last_skip_kind != "cells":
                    raise RuntimeError(f"{name}: drawn without cell maps")
            times: dict[int, list[float]] = {n: [] for n in rs}
            for _ in range(frames):
                for n, r in rs.items():
                    times[n] += r.time_frames(scene, frames=1, warmup=0)
        finally:
            for r in rs.values():
                r.release()
    first = per_check[0]
    for n in per_check:
        if not np.array_equal(images[n], images[first]):
            raise RuntimeError(f"{name} {mode}: {n} samples per check change the image")
    med = {n: statistics.median(t) for n, t in times.items()}
    ms = " | ".join(f"{med[n]:.1f}" for n in per_check)
    ratios = " | ".join(f"{med[n] / med[first]:.2f}x" for n in per_check[1:])
    return f"| {name} | {mode} | {'on' if shading else 'off'} | {ms} | {ratios} | {_load()} |"


def main(argv: Sequence[str] | None = None) -> int:
    """Print the table (module docstring)."""
    p = argparse.ArgumentParser(prog="python -m benchmarks.skip_checks", description=__doc__)
    p.add_argument("--volumes", default="colin27,stent", help="bundled scans, comma-separated")
    p.add_argument("--modes", default="dvr", help="dvr, iso, flm, comma-separated")
    p.add_argument("--shading", default="off,on", help="off, on or both")
    p.add_argument("--per-check", default="1,2", help="SAMPLES_PER_CHECK values, 1 to 4")
    p.add_argument("--frames", type=int, default=7, help="timed frames per program")
    args = p.parse_args(argv)
    try:
        per_check = [int(v) for v in args.per_check.split(",")]
    except ValueError:
        per_check = []
    if not per_check or any(not 1 <= n <= 4 for n in per_check):
        p.error(f"--per-check takes values 1 to 4; got {args.per_check}")
    print(f"load average before: {_load()}")
    cols = " | ".join(f"{n}/check ms" for n in per_check)
    ratios = " | ".join(f"{n} vs {per_check[0]}" for n in per_check[1:])
    print(f"| scan | mode | shading | {cols} | {ratios} | load |")
    print("|---" * (3 + 2 * len(per_check)) + "|")
    for name in args.volumes.split(","):
        for mode in args.modes.split(","):
            for shading in args.shading.split(","):
                row = measure(name, mode, shading == "on", per_check, args.frames)
                print(row, flush=True)
    print(f"load average after: {_load()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
