"""Quick timing of joining ChainMail links (``link_pairs``) against cutting them
(``cut_pairs``) and a local drag, on an n³ grid (default 64³); not a test.

Run: ``.venv/bin/python scripts/join_timing.py [N]``. A plane of n² links along x is
cut and joined again at rest (``"refuse"``: every link checked, all touch), joined
with ``"skip"`` after a drag pulled one side 3 spacings away near the middle, and
with ``"pull"`` (the suture) from that state; the least and the median of
:data:`REPEATS` runs (the least is the cost on a loaded machine), after a warm-up run
(numba compilation). Prints the load average next to the numbers.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from voxwarp.deform.elements.chainmail import ChainMail, neighbour_pairs
from voxwarp.deform.elements.grid import ElementGrid

#: runs per measurement
REPEATS = 15


def _times_ms(setup: Callable[[], ChainMail], run: Callable[[ChainMail], object]) -> np.ndarray:
    times = []
    for _ in range(REPEATS):
        cm = setup()
        t = time.perf_counter()
        run(cm)
        times.append(1e3 * (time.perf_counter() - t))
    return np.asarray(times)


def main(n: int = 64) -> None:
    grid = ElementGrid(((0.0, 0.0, 0.0), (n - 1.0,) * 3), shape=n, anchor="corners")
    left = np.zeros(grid.shape, dtype=bool)
    left[: n // 2] = True
    plane = neighbour_pairs(left)  # the n² links along x between the halves
    c = (n // 2, n // 2, n // 2)

    def whole() -> ChainMail:
        return ChainMail(grid)

    def cut() -> ChainMail:
        cm = ChainMail(grid)
        cm.cut_pairs(plane)
        return cm

    def pulled() -> ChainMail:
        cm = cut()
        cm.move(c, (3.0, 0.0, 0.0))
        cm.release()
        return cm

    pulled().link_pairs(plane, stretched="pull")  # compile
    rows = [
        ("drag 1 spacing (reference)", _times_ms(whole, lambda cm: cm.move(c, (1.0, 0, 0)))),
        (f"cut_pairs, {len(plane)} links", _times_ms(whole, lambda cm: cm.cut_pairs(plane))),
        ("link_pairs at rest (refuse)", _times_ms(cut, lambda cm: cm.link_pairs(plane))),
        ("link_pairs, gap (skip)", _times_ms(pulled, lambda cm: cm.link_pairs(plane, "skip"))),
        ("link_pairs, gap (pull)", _times_ms(pulled, lambda cm: cm.link_pairs(plane, "pull"))),
    ]
    cm = pulled()
    far = len(plane) - cm.link_pairs(plane, "skip")
    print(f"grid {grid.shape} ({grid.count:,} elements), {far} links stretched by the gap")
    print(f"load average: {Path('/proc/loadavg').read_text().split()[:3]}")
    ref = rows[1][1].min()
    print(f"{'':34s} {'least':>9s}    {'median':>9s}    least / cut_pairs")
    for label, ms in rows:
        print(f"{label:34s} {ms.min():9.2f} ms {np.median(ms):9.2f} ms {ms.min() / ref:7.2f}x")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 64)
