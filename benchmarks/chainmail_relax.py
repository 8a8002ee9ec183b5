"""``python -m benchmarks chainmail --relax``: ChainMail relaxation, CPU vs GPU, full vs
local, after one local drag.

Scene per grid size ``n`` (n³ elements over the 100 mm box of ``python -m benchmarks
chainmail``, no fixed elements): an earlier drag deformed one corner of the grid (the
element at ``n // 4`` on every axis dragged 2 spacings along (1, 1, 0) and relaxed
``steps`` steps, still held), then the *local drag* (the element at ``3 n // 4`` dragged
1 spacing along +x). Timed: ``relax(steps)`` after it, in three modes: ``grid``, every
element in every half-sweep (the thesis' scheme; the scene's state set again with
``set_state``, which marks every element as changed), ``full`` (the default: from the
box of every displaced element, the same result) and ``local`` (``local=True``: from
the box of the elements the local drag moved); on the CPU (numba, float64) and on the
GPU backend (GLSL half-sweeps; llvmpipe without a GPU). Every timed call starts from the same scene,
rebuilt untimed (reset, the two drags) before it; the four variants take turns, so a
change of the machine's load affects all alike. GPU times are bound by ``ctx.finish()``.

Reported per size and variant: median (min–max) ms, the elements the half-sweeps
covered (the sum of their boxes' volumes), and per size the largest difference between
local and full relaxation (mm; they differ because the earlier drag's few relaxation
steps left it off the rule's fixed point, which full relaxation goes on smoothing) and
between the GPU and the CPU (mm, full relaxation).
"""

from __future__ import annotations

import math
import statistics
import time
from typing import Any

import numpy as np

from benchmarks import gpu_context
from voxwarp.core.timing import load_average
from voxwarp.deform.elements.chainmail_model import relax_boxes

#: (backend, mode) of the timed variants, in report order
VARIANTS: tuple[tuple[str, str], ...] = tuple(
    (b, m) for b in ("cpu", "gpu") for m in ("grid", "full", "local")
)
#: the modes' names in the table
MODES: dict[str, str] = {"grid": "whole grid", "full": "full (default)", "local": "local"}
#: default grid sizes (elements per axis)
DEFAULT_SIZES: tuple[int, ...] = (16, 32)


def _scene(cm: Any, steps: int) -> None:
    """Reset, the earlier (relaxed) drag and the local drag (see the module doc)."""
    n = cm.grid.shape[0]
    s = cm.grid.spacing[0]
    cm.reset()
    cm.move((n // 4,) * 3, (2.0 * s / math.sqrt(2.0), 2.0 * s / math.sqrt(2.0), 0.0))
    cm.relax(steps)
    cm.move((3 * n // 4,) * 3, (s, 0.0, 0.0))


def _covered(cm: Any, local: bool, steps: int) -> int:
    """Elements the half-sweeps of ``relax(steps, local=local)`` cover from here."""
    boxes = relax_boxes(cm.relax_region(local), steps, cm.grid.shape)
    return sum(math.prod(h - lo for lo, h in zip(*b, strict=True)) for b in boxes)


def bench_relax(
    sizes: tuple[int, ...] = DEFAULT_SIZES,
    *,
    steps: int = 4,
    repeats: int = 5,
    use_gpu: bool = True,
    ctx: Any = None,
) -> dict[str, Any]:
    """Time the relaxation variants (module doc); returns ``{"rows", "load",
    "renderer", "steps"}``, a row per size and variant plus the per-size differences."""
    from benchmarks.chainmail import _grid
    from voxwarp.deform.elements.chainmail import ChainMail

    load = load_average()
    ctx, own, skip = gpu_context(ctx, use_gpu)
    renderer = "not used" if skip else str(ctx.info.get("GL_RENDERER", "?"))
    rows: list[dict[str, Any]] = []
    try:
        for n in sizes:
            models = {"cpu": ChainMail(_grid(n))}
            if not skip:
                models["gpu"] = ChainMail(_grid(n), backend="gpu", ctx=ctx)
            finish = ctx.finish if not skip else (lambda: None)
            times: dict[tuple[str, str], list[float]] = {v: [] for v in VARIANTS}
            result: dict[tuple[str, str], np.ndarray] = {}
            covered: dict[tuple[str, str], int] = {}
            for rep in range(repeats + 1):  # the first round warms up (compiles)
                for backend, mode in VARIANTS:
                    if backend not in models:
                        continue
                    cm = models[backend]
                    _scene(cm, steps)
                    if mode == "grid":
                        cm.set_state(cm.positions())
                    covered[backend, mode] = _covered(cm, mode == "local", steps)
                    finish()
                    t0 = time.perf_counter()
                    cm.relax(steps, local=mode == "local")
                    finish()
                    if rep:
                        times[backend, mode].append(1e3 * (time.perf_counter() - t0))
                    result[backend, mode] = cm.positions()
            full, part = result["cpu", "full"], result["cpu", "local"]
            gpu_diff = (
                float(np.abs(result["gpu", "full"] - full).max()) if "gpu" in models else None
            )
            for backend, mode in VARIANTS:
                t = times[backend, mode]
                rows.append(
                    {
                        "n": n,
                        "backend": backend,
                        "mode": mode,
                        "median_ms": statistics.median(t) if t else None,
                        "min_ms": min(t) if t else None,
                        "max_ms": max(t) if t else None,
                        "covered": covered.get((backend, mode)),
                        "grid_vs_full_mm": float(np.abs(result["cpu", "grid"] - full).max()),
                        "local_vs_full_mm": float(np.abs(part - full).max()),
                        "gpu_vs_cpu_mm": gpu_diff,
                    }
                )
            for cm in models.values():
                cm.close()
    finally:
        if own:
            ctx.release()
    return {"rows": rows, "load": (load, load_average()), "renderer": renderer, "steps": steps}


def relax_markdown(report: dict[str, Any], command: str) -> str:
    """The report of :func:`bench_relax` as markdown, headed by its command."""
    steps = report["steps"]
    lines = [
        f"Command: `{command}`",
        "",
        f"`relax({steps})` after a local drag (module doc of `benchmarks.chainmail_relax`);"
        f" GL: {report['renderer']}; 1-minute load average before / after"
        f" {report['load'][0]:.2f} / {report['load'][1]:.2f}.",
        "",
        "| grid | backend | relaxation | ms, median (min–max) | elements covered"
        " | / CPU whole-grid time | whole grid vs full (mm) | local vs full (mm)"
        " | GPU vs CPU, full (mm) |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in report["rows"]:
        if r["median_ms"] is None:
            continue
        base = next(
            q["median_ms"]
            for q in report["rows"]
            if q["n"] == r["n"] and q["backend"] == "cpu" and q["mode"] == "grid"
        )
        gpu = "—" if r["gpu_vs_cpu_mm"] is None else f"{r['gpu_vs_cpu_mm']:.1e}"
        lines.append(
            f"| {r['n']}³ | {r['backend'].upper()} | {MODES[r['mode']]}"
            f" | {r['median_ms']:.3g} ({r['min_ms']:.3g}–{r['max_ms']:.3g})"
            f" | {r['covered']} | {r['median_ms'] / base:.2f}x"
            f" | {r['grid_vs_full_mm']:.1e} | {r['local_vs_full_mm']:.3g} | {gpu} |"
        )
    return "\n".join(lines) + "\n"
