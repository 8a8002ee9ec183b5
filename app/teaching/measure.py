"""The compare demo's own timings: mass-spring steps per second and ChainMail ms per move,
CPU against GPU, on small grids.

The same models and drags as the lab's full studies (``python -m benchmarks massspring``
and ``python -m benchmarks chainmail``, which add taichi, block sizing and every grid up
to 128³), measured here in a few lines: each solver runs once untimed (shader compilation,
numba kernels), then ``repeats`` timed blocks or moves, each bound by ``ctx.finish()`` on
the GPU.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np

#: the box the element grids span (mm)
BOX = ((0.0, 0.0, 0.0), (100.0, 100.0, 100.0))
#: the mass-spring drag of the centre element (mm)
SPRING_DRAG_MM = (0.0, 0.0, 10.0)
#: the ChainMail drags of the centre element, in spacings: (name, direction, length)
CHAIN_DRAGS = (("local", (1.0, 0.0, 0.0), 1.0), ("large", (2.0, 1.0, 1.0), 20.0))
#: a GPU ChainMail element counts as moved when displaced by more than this (mm)
GPU_MOVED_MM = 1e-4


def _stats(values: list[float]) -> tuple[float, float, float]:
    return statistics.median(values), min(values), max(values)


def massspring_rates(
    sizes: tuple[int, ...], *, steps: int, repeats: int, ctx: Any, log: Callable[[str], None]
) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Steps per second of the numpy and the GPU solver on n³ grids (8 corners fixed, the
    centre dragged 10 mm): rows ``{size, backend, steps_per_s, min, max, note}`` and the
    model's ``{integrator, dt}``."""
    from voxwarp.deform.elements.grid import ElementGrid
    from voxwarp.deform.elements.massspring import MassSpring

    rows: list[dict[str, Any]] = []
    model: dict[str, Any] = {}
    for n in sizes:
        for backend, name in (("cpu", "numpy"), ("gpu", "gpu")):
            gl = ctx if backend == "gpu" else None
            ms = MassSpring(ElementGrid(BOX, shape=n, anchor="corners"), backend=backend, ctx=gl)
            finish = ctx.finish if backend == "gpu" else (lambda: None)
            try:
                ms.move((n // 2, n // 2, n // 2), SPRING_DRAG_MM)
                model = {"integrator": ms.integrator, "dt": ms.dt}
                ms.step(2)  # untimed: compilation, both ping-pong directions
                finish()
                rates = []
                for _ in range(max(1, int(repeats))):
                    t = time.perf_counter()
                    ms.step(int(steps))
                    finish()
                    rates.append(int(steps) / (time.perf_counter() - t))
            finally:
                ms.close()
            med, lo, hi = _stats(rates)
            rows.append(
                {"size": n, "backend": name, "steps_per_s": med, "min": lo, "max": hi, "note": ""}
            )
            log(f"{n}³ mass-spring {name}: {med:.1f} steps/s")
    return rows, model


def chainmail_times(
    sizes: tuple[int, ...], *, repeats: int, ctx: Any, log: Callable[[str], None]
) -> list[dict[str, Any]]:
    """Milliseconds per move of the Gibson and the enhanced CPU solver and the GPU backend
    on n³ grids (no fixed element), for each drag of :data:`CHAIN_DRAGS`: rows ``{size,
    solver, drag, ms, min, max, touched, note}``."""
    from voxwarp.deform.elements.chainmail import ChainMail
    from voxwarp.deform.elements.grid import ElementGrid

    rows: list[dict[str, Any]] = []
    for n in sizes:
        centre = (n // 2, n // 2, n // 2)
        for solver in ("gibson", "enhanced", "gpu"):
            grid = ElementGrid(BOX, shape=n, anchor="corners")
            grid.free(grid.corner_mask())
            gpu = solver == "gpu"
            cm = ChainMail(grid, backend="gpu", ctx=ctx) if gpu else ChainMail(grid, variant=solver)
            finish = ctx.finish if gpu else (lambda: None)
            try:
                for drag, direction, length in CHAIN_DRAGS:
                    d = np.asarray(direction, dtype=np.float64)
                    offset = d / np.linalg.norm(d) * length * (BOX[1][0] - BOX[0][0]) / (n - 1)
                    times = []
                    for i in range(max(1, int(repeats)) + 1):  # the first untimed
                        cm.reset()
                        finish()
                        t = time.perf_counter()
                        stats = cm.move(centre, offset)
                        finish()
                        if i:
                            times.append((time.perf_counter() - t) * 1000)
                    touched = stats.touched
                    if touched < 0:  # the GPU does not count them: the displaced elements
                        u = cm.displacements()
                        touched = int(np.count_nonzero(np.abs(u).max(-1) > GPU_MOVED_MM))
                    med, lo, hi = _stats(times)
                    row = {"size": n, "solver": solver, "drag": drag, "ms": med, "min": lo}
                    rows.append({**row, "max": hi, "touched": touched, "note": ""})
                    log(f"{n}³ {drag} ChainMail {solver}: {med:.3g} ms ({touched} touched)")
            finally:
                cm.close()
    return rows
