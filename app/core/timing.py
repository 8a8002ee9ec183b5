"""What every measurement shares: the cores this process may use, the load average and the
CPU's model.

The installed ``voxwarp bench``, the teaching demos (``voxwarp demo``, ``voxwarp
reproduce``) and the lab in the checkout (``python -m benchmarks``) all report these
beside their numbers, since timings on shared machines are noisy.
"""

from __future__ import annotations

import os
import platform


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
