"""What every measurement shares: the cores this process may use, the load average, the
CPU's model, and the best wall time of a few steps.

The installed ``voxwarp bench``, the teaching demos (``voxwarp demo``, ``voxwarp
reproduce``) and the lab in the checkout (``python -m benchmarks``) all report these
beside their numbers, since timings on shared machines are noisy.
"""

from __future__ import annotations

import math
import os
import platform
import time
from collections.abc import Callable
from typing import Any


def cpu_count() -> int:
    """CPU cores this process may run on (for the benchmark reports)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def load_average() -> float:
    """The 1-minute load average (-1 where the platform has none): benchmark reports
    record it before and after a run, since these machines are shared."""
    try:
        return float(os.getloadavg()[0])
    except (AttributeError, OSError):  # not available on this platform
        return -1.0


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo (else :func:`platform.processor`)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def best_times(repeats: int, *steps: Callable[[], Any]) -> list[float]:
    """The shortest wall time (s) of each of ``steps`` over ``repeats`` rounds (each
    round runs every step once, in order)."""
    best = [math.inf] * len(steps)
    for _ in range(max(1, int(repeats))):
        for i, step in enumerate(steps):
            start = time.perf_counter()
            step()
            best[i] = min(best[i], time.perf_counter() - start)
    return best
