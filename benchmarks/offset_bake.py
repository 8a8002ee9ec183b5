"""The GPU bake of an offset field's inverse: all fixed-point steps at every node, or
stopping where the float fixed point stops changing (bit-identical; the shipped shader).

``python -m benchmarks.offset_bake [--frames N] [--volume NAME]`` times both compute
shaders on the fields of ``python -m benchmarks support`` (a 16³ ChainMail drag over the
scan, the same ChainMail with nothing moved, a settled 16³ mass-spring drag), runs
interleaved, medians, ``ctx.finish()`` after each, and checks the two bakes are equal
byte for byte; then the same for the CPU bake (numpy). A lab study (docs/benchmarks.md,
'The inverse bake stops where it has converged').
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any

import numpy as np

from benchmarks.support import WARPS
from voxwarp import shaders
from voxwarp.deform.elements.offset_field import BAKE_ITERATIONS, OffsetFieldWarp
from voxwarp.io.samples import load_sample
from voxwarp.render.context import create_context

EARLY_EXIT = "if (next == q) break;"


def _bake(ctx: Any, prog: Any, warp: OffsetFieldWarp, tex: Any) -> float:
    """Run one bake of ``warp`` into ``tex``; seconds, GL finished."""
    ctx.finish()
    t = time.perf_counter()
    warp.run_bake(ctx, prog, tex)
    ctx.finish()
    return time.perf_counter() - t


def run(volume: str = "colin27", frames: int = 7) -> list[tuple[str, str, float, float, bool]]:
    """Rows (case, bake shape, all steps ms, early exit ms, bit-identical)."""
    ctx = create_context()
    src = shaders.source("offset_field_bake.comp.glsl")
    progs = {
        "all": ctx.compute_shader(src.replace(EARLY_EXIT, "")),
        "early": ctx.compute_shader(src),
    }
    vol = load_sample(volume)
    rows = []
    for case, make in WARPS.items():
        warp = make(vol)
        assert isinstance(warp, OffsetFieldWarp)
        warp.textures(ctx)["displacement"].use(0)
        texs = {k: ctx.texture3d(warp.bake_shape, 4, dtype="f2") for k in progs}
        times: dict[str, list[float]] = {k: [] for k in progs}
        for _ in range(frames):
            for k, prog in progs.items():
                times[k].append(_bake(ctx, prog, warp, texs[k]))
        same = texs["all"].read() == texs["early"].read()
        shape = "x".join(str(n) for n in warp.bake_shape)
        ms = {k: statistics.median(v) * 1000 for k, v in times.items()}
        rows.append((case, shape, ms["all"], ms["early"], same))
        for t in texs.values():
            t.release()
    return rows


def run_cpu(volume: str = "colin27", frames: int = 3) -> list[tuple[str, float, float]]:
    """Rows (case, all steps ms, early exit ms) of the CPU bake (``baked_inverse``)."""
    vol = load_sample(volume)
    rows = []
    for case, make in WARPS.items():
        warp = make(vol)
        assert isinstance(warp, OffsetFieldWarp)
        u = warp.displacements
        axes = [
            np.linspace(a, b, n) for a, b, n in zip(warp.lo, warp.hi, warp.bake_shape, strict=True)
        ]
        x = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        times: dict[str, list[float]] = {"all": [], "early": []}
        for _ in range(frames):
            t = time.perf_counter()
            q = x.copy()
            for _ in range(BAKE_ITERATIONS):
                q = x - warp._interpolate(q, field=u)
            times["all"].append(time.perf_counter() - t)
            warp._baked_cpu = None
            t = time.perf_counter()
            early = warp.baked_inverse()
            times["early"].append(time.perf_counter() - t)
        assert np.array_equal(early.reshape(-1, 3), x - q)
        ms = {k: statistics.median(v) * 1000 for k, v in times.items()}
        rows.append((case, ms["all"], ms["early"]))
    return rows


def main() -> None:
    p = argparse.ArgumentParser(prog="python -m benchmarks.offset_bake", description=__doc__)
    p.add_argument("--frames", type=int, default=7)
    p.add_argument("--volume", default="colin27")
    a = p.parse_args()
    with open("/proc/loadavg") as f:
        before = " ".join(f.read().split()[:3])
    rows = run(a.volume, a.frames)
    with open("/proc/loadavg") as f:
        after = " ".join(f.read().split()[:3])
    print(f"{a.volume}, median of {a.frames}; load average {before} / {after}\n")
    print("| field | baked nodes | all steps ms | early exit ms | early / all | bit-identical |")
    print("|---|---|---:|---:|---:|---|")
    for case, shape, full, early, same in rows:
        print(f"| {case} | {shape} | {full:.0f} | {early:.0f} | {early / full:.2f} | {same} |")
    print("\nCPU (numpy, `OffsetFieldWarp.baked_inverse`, bit-identical):\n")
    print("| field | all steps ms | early exit ms | early / all |")
    print("|---|---:|---:|---:|")
    for case, full, early in run_cpu(a.volume, max(1, a.frames // 2)):
        print(f"| {case} | {full:.0f} | {early:.0f} | {early / full:.2f} |")


if __name__ == "__main__":
    main()
