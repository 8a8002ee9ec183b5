"""``voxwarp bench startup``: how long the command line takes to start, against Python.

Each run starts a fresh interpreter: ``python -c pass`` (the reference, measured in the
same run), ``python -m voxwarp --help`` and ``python -c "import voxwarp"``. The report
gives the medians, their ratio to the reference, and the heavy modules each one loaded
(none is the target: numba, scipy, pyopencl, Qt, dask and matplotlib load when used).
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass

#: modules ``import voxwarp`` and ``voxwarp --help`` must not load
HEAVY = ("numba", "scipy", "pyopencl", "PySide6", "dask", "distributed", "matplotlib")
#: what is timed: label -> Python code run by a fresh interpreter
CASES: dict[str, str] = {
    "python -c pass (reference)": "pass",
    "voxwarp --help": (
        "import sys; sys.argv = ['voxwarp', '--help']\n"
        "from voxwarp.ui.cli import main\n"
        "try:\n    main()\nexcept SystemExit:\n    pass"
    ),
    "import voxwarp": "import voxwarp",
}


@dataclass
class StartupRow:
    """One case: median wall seconds of ``repeats`` runs and the heavy modules loaded."""

    label: str
    seconds: float
    heavy: list[str]


def _run(code: str) -> tuple[float, list[str]]:
    probe = f"{code}\nimport json, sys\nprint(json.dumps(sorted(sys.modules)))"
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    if res.returncode != 0:
        raise RuntimeError(res.stderr.strip().splitlines()[-1])
    loaded = json.loads(res.stdout.strip().splitlines()[-1])
    return seconds, sorted({m.split(".")[0] for m in loaded} & set(HEAVY))


def bench_startup(repeats: int = 5) -> list[StartupRow]:
    """Time every case of :data:`CASES` ``repeats`` times (interleaved), medians."""
    times: dict[str, list[float]] = {label: [] for label in CASES}
    heavy: dict[str, list[str]] = {}
    for _ in range(repeats):
        for label, code in CASES.items():
            seconds, heavy[label] = _run(code)
            times[label].append(seconds)
    return [StartupRow(k, statistics.median(v), heavy[k]) for k, v in times.items()]


def markdown(rows: list[StartupRow], command: str) -> str:
    """The report: a table with each case's ratio to the reference (the first row)."""
    ref = rows[0].seconds
    lines = [
        f"`{command}`",
        "",
        "| case | median wall (ms) | / python startup | heavy modules loaded |",
        "|---|---|---|---|",
    ]
    for r in rows:
        heavy = ", ".join(r.heavy) or "none"
        lines.append(f"| {r.label} | {1e3 * r.seconds:.0f} | {r.seconds / ref:.2f}x | {heavy} |")
    return "\n".join(lines)
