"""Quick timing of ChainMail drags on a 128³ grid (2.1 M elements); not a test.

Run: ``.venv/bin/python scripts/chainmail_timing.py [N]``. For both variants it times
a local drag (one element by one spacing, from rest), a large drag (one element by 20
spacings) and a relaxation step, excluding the first call (numba compilation).
Default limits: stiffness 0.5, i.e. stretch 0.75..1.25 spacings, shear 0.25 spacings.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from voxwarp.deform.elements.chainmail import ChainMail
from voxwarp.deform.elements.grid import ElementGrid


def main(n: int = 128) -> None:
    grid = ElementGrid(((0.0, 0.0, 0.0), (n - 1.0,) * 3), shape=n)  # 1 mm spacing
    c = (n // 2,) * 3
    print(f"grid {grid.shape} ({grid.count:,} elements), spacing 1 mm")
    for variant in ("gibson", "enhanced"):
        t = time.perf_counter()
        cm = ChainMail(grid, variant=variant)
        print(f"\n{variant}: construct {1e3 * (time.perf_counter() - t):.0f} ms")
        cm.move(c, (1.0, 0.0, 0.0))  # compile (or load the cache)
        cm.reset()
        for label, off in (
            ("local drag 1 spacing", (1.0, 0.0, 0.0)),
            ("local drag 1 spacing, oblique", (0.6, -0.6, 0.5)),
            ("large drag 20 spacings", (20.0, 0.0, 0.0)),
            ("large drag 20 spacings, oblique", (12.0, -12.0, 10.0)),
        ):
            times = []
            for _ in range(3):
                cm.reset()
                t = time.perf_counter()
                s = cm.move(c, off)
                times.append(time.perf_counter() - t)
            print(
                f"  {label:34s} move() {1e3 * min(times):8.2f} ms (stats.seconds"
                f" {1e3 * s.seconds:8.2f} ms), touched {s.touched:>9,}, checks {s.checks:>9,},"
                f" cleanup {s.cleanup:>8,}, violation {cm.violation():.1e}"
            )
        # an incremental drag: 10 steps of 0.5 spacings, each from the last position
        cm.reset()
        steps = []
        for k in range(1, 11):
            s = cm.move(c, (0.5 * k, 0.0, 0.0))
            steps.append(s.seconds)
        print(
            f"  {'drag in 10 steps of 0.5 spacing':34s} per step mean"
            f" {1e3 * float(np.mean(steps)):8.2f} ms, max {1e3 * max(steps):8.2f} ms"
        )
        cm.relax(1)  # compile
        t = time.perf_counter()
        cm.relax(1)
        print(f"  {'relax(1)':34s} {1e3 * (time.perf_counter() - t):8.2f} ms")
        t = time.perf_counter()
        cm.warp()
        cm.move(c, (1.0, 0.0, 0.0))
        print(f"  {'move() with a warp to update':34s} {1e3 * (time.perf_counter() - t):8.2f} ms")
        cm.close()


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 128)
