"""Before / after of ``ChainMail.relax`` on the GPU backend; not a test.

Run: ``PYTHONPATH=. .venv/bin/python scripts/chainmail_relax_readback.py [REPEATS]``.
In the scene of ``python -m benchmarks chainmail --relax`` (``benchmarks.chainmail_relax``)
on 16³ and 32³ grids it times, taking turns, 4 relaxation steps the way the GPU backend
did them before issue 35 (read the positions back, red-black sweeps of the numba kernel
over the whole grid, upload) and ``ChainMail.relax(4)`` (GLSL half-sweeps), each bound
by ``ctx.finish()``; prints a markdown row per size: median (min–max) ms and the ratio.
"""

from __future__ import annotations

import statistics
import sys
import time
from collections.abc import Callable

import numpy as np

from benchmarks.chainmail import _grid
from benchmarks.chainmail_relax import _scene
from voxwarp.deform.elements import chainmail_cpu
from voxwarp.deform.elements.chainmail import ChainMail
from voxwarp.render.context import create_context

STEPS = 4


def _readback(cm: ChainMail) -> Callable[[], None]:
    """The removed path: read back, relax the whole grid on the CPU, upload."""
    mn, mx, sh, links = cm._flat_limits()
    shape = np.asarray(cm.grid.shape, np.int64)
    n = int(shape[0])
    full = np.array([0, n, 0, n, 0, n], np.int64)

    def run() -> None:
        x = np.ascontiguousarray(cm.positions().reshape(-1, 3))
        for _ in range(STEPS):
            for colour in (0, 1):
                chainmail_cpu.relax_sweep(
                    x, cm._rest, mn, mx, sh, links, cm._pinned, shape, full, colour
                )
        cm._solver.set_positions(x.reshape((n, n, n, 3)).copy())

    return run


def main(repeats: int = 9) -> None:
    ctx = create_context()
    for n in (16, 32):
        cm = ChainMail(_grid(n), backend="gpu", ctx=ctx)
        runs = {"before": _readback(cm), "after": lambda cm=cm: cm.relax(STEPS)}
        t: dict[str, list[float]] = {"before": [], "after": []}
        for rep in range(repeats + 1):  # the first round warms up
            for name, run in runs.items():
                _scene(cm, STEPS)
                ctx.finish()
                t0 = time.perf_counter()
                run()
                ctx.finish()
                if rep:
                    t[name].append(1e3 * (time.perf_counter() - t0))
        cells = [f"{statistics.median(v):.3g} ({min(v):.3g}–{max(v):.3g})" for v in t.values()]
        ratio = statistics.median(t["after"]) / statistics.median(t["before"])
        print(f"| {n}³ | {cells[0]} | {cells[1]} | {ratio:.2f}x |")
        cm.close()
    ctx.release()


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 9)
