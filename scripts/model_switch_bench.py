"""Switching a dragged mass-spring model to ChainMail: what it costs and moves.

``python scripts/model_switch_bench.py [--shapes 16 32] [--repeats 3]``

Per grid (shell anchor, stiffness 0.5, the centre element dragged 0.8 spacing along x
and 0.6 along y, then 200 mass-spring steps: a drag in progress) it prints, with the
1-minute load average:

* ``rebuild``: the switch before (a new ChainMail at rest on the grid) in ms: the
  reference the switch's time is a ratio to; it kept no displacement;
* ``switch``: ``ChainMail.from_model`` (projection onto the limits, propagation) in ms,
  medians of ``--repeats``, and its ratio to ``rebuild``;
* what the switch moved (elements, max and RMS mm, the worst violation before, the
  projection's sweeps) and the propagation's own repair of the same positions
  (``ChainMail.set_state``): its sum of squared movements as a multiple of the
  projection's, or "failed" when the greedy repair cannot meet the limits with the
  fixed and held elements where they are.

Each grid is measured twice: the dragged element held, and released (positions kept).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from voxwarp.deform.elements.chainmail import ChainMail, ChainMailError
from voxwarp.deform.elements.grid import ElementGrid
from voxwarp.deform.elements.massspring import MassSpring


def _case(n: int) -> MassSpring:
    grid = ElementGrid(((0.0, 0.0, 0.0), (100.0, 100.0, 100.0)), shape=n)
    ms = MassSpring(grid)
    s = float(grid.spacing[0])
    ms.move((n // 2, n // 2, n // 2), (0.8 * s, 0.6 * s, 0.0))
    ms.step(200)
    return ms


def _ms(fn: object, repeats: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()  # type: ignore[operator]
        times.append((time.perf_counter() - t) * 1000)
    return statistics.median(times), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--shapes", type=int, nargs="+", default=[16, 32])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    ChainMail.from_model(_case(4))  # numba kernels compiled/loaded before timing
    for n in args.shapes:
        for released in (False, True):
            ms = _case(n)
            if released:
                ms.release()  # the positions stay: nothing held
            _row(n, ms, released, args.repeats)


def _row(n: int, ms: MassSpring, released: bool, repeats: int) -> None:
    y = ms.positions()
    rebuild, _ = _ms(lambda: ChainMail(ms.grid), repeats)
    switch, cm = _ms(lambda: ChainMail.from_model(ms), repeats)
    r = cm.switch_report  # type: ignore[union-attr]
    least = float(np.sum((cm.positions() - y) ** 2))  # type: ignore[union-attr]
    repaired = ChainMail(ms.grid)
    for idx in np.argwhere(ms.held):
        repaired.move(tuple(idx), ms.held_offsets[tuple(idx)])
    try:
        repaired.set_state(y)
        greedy = f"{float(np.sum((repaired.positions() - y) ** 2)) / least:.2f}x"
    except ChainMailError:
        greedy = "failed"
    print(
        f"{n}^3 {'released' if released else 'held'}: rebuild {rebuild:.1f} ms, switch"
        f" {switch:.1f} ms ({switch / rebuild:.1f}x); moved {r.moved}, max {r.max_mm:.2f} mm,"
        f" RMS {r.rms_mm:.3f} mm, worst violation {r.violation_before:.2f} mm,"
        f" {r.sweeps} sweeps; propagation repair's sum of squares: {greedy};"
        f" load {os.getloadavg()[0]:.2f}"
    )


if __name__ == "__main__":
    main()
