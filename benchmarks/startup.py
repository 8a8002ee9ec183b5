"""``python -m benchmarks startup``: how long the command line takes to start, against Python.

Each run starts a fresh interpreter: ``python -c pass`` (the reference, measured in the
same run), ``python -m voxwarp --help``, ``python -c "import voxwarp"`` and a whole
``voxwarp render sample:stent -o x.png`` (start, load, render, write the PNG). The
report gives the medians of wall and CPU time, the wall ratio to the reference, and the
heavy modules each one loaded (none is the target for ``--help`` and ``import``: numba,
scipy, pyopencl, Qt, dask and matplotlib load when used; the render must not load the
readers and mesh modules it does not use, :data:`RENDER_UNUSED`).
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass
from typing import Any

from voxwarp.bench.command import emit_report
from voxwarp.core.checks import positive_int

#: modules ``import voxwarp`` and ``voxwarp --help`` must not load
HEAVY = ("numba", "scipy", "pyopencl", "PySide6", "dask", "distributed", "matplotlib")
#: modules ``voxwarp render sample:stent -o x.png`` has no use for (it writes the PNG
#: through OpenImageIO, which it does load; its skip maps stay on numpy below
#: ``voxwarp.render.skipping.maps.COMPILED_MIN_SIZE`` voxels)
RENDER_UNUSED = (
    "numba",
    "scipy",
    "trimesh",
    "pyopencl",
    "nibabel",
    "SimpleITK",
    "PIL",
    "tifffile",
    "pydicom",
    "PySide6",
    "dask",
    "distributed",
    "matplotlib",
)
#: the label of the end-to-end render case
RENDER_CASE = "voxwarp render sample:stent -o x.png"
#: what is timed: label -> Python code run by a fresh interpreter
CASES: dict[str, str] = {
    "python -c pass (reference)": "pass",
    "voxwarp --help": (
        "import sys; sys.argv = ['voxwarp', '--help']\n"
        "from voxwarp.cli.main import main\n"
        "try:\n    main()\nexcept SystemExit:\n    pass"
    ),
    "import voxwarp": "import voxwarp",
    RENDER_CASE: (
        "import sys, tempfile\n"
        "with tempfile.TemporaryDirectory() as tmp:\n"
        "    sys.argv = ['voxwarp', 'render', 'sample:stent', '-o', tmp + '/x.png']\n"
        "    from voxwarp.cli.main import main\n"
        "    assert main() == 0"
    ),
}


@dataclass
class StartupRow:
    """One case: median wall seconds of ``repeats`` runs, the heavy modules (of
    :data:`HEAVY` and :data:`RENDER_UNUSED`) it loaded, and its median CPU seconds (user +
    system, all threads; less disturbed than wall time by other work on the machine)."""

    label: str
    seconds: float
    heavy: list[str]
    cpu_seconds: float | None = None


def _run(code: str) -> tuple[float, float, list[str]]:
    probe = f"{code}\nimport json, sys\nprint(json.dumps(sorted(sys.modules)))"
    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
    if res.returncode != 0:
        raise RuntimeError((res.stderr.strip().splitlines() or ["(no output)"])[-1])
    loaded = json.loads(res.stdout.strip().splitlines()[-1])
    watched = set(HEAVY) | set(RENDER_UNUSED)
    return seconds, cpu, sorted({m.split(".")[0] for m in loaded} & watched)


def bench_startup(repeats: int = 5, cases: dict[str, str] | None = None) -> list[StartupRow]:
    """Time every case of ``cases`` (default :data:`CASES`, whose first entry is the
    reference) ``repeats`` times, interleaved; medians."""
    cases = CASES if cases is None else cases
    times: dict[str, list[float]] = {label: [] for label in cases}
    cpus: dict[str, list[float]] = {label: [] for label in cases}
    heavy: dict[str, list[str]] = {}
    for _ in range(repeats):
        for label, code in cases.items():
            seconds, cpu, heavy[label] = _run(code)
            times[label].append(seconds)
            cpus[label].append(cpu)
    return [
        StartupRow(k, statistics.median(v), heavy[k], statistics.median(cpus[k]))
        for k, v in times.items()
    ]


def markdown(rows: list[StartupRow], command: str) -> str:
    """The report: a table with each case's ratio to the reference (the first row)."""
    ref = rows[0].seconds
    lines = [
        f"`{command}`",
        "",
        "| case | median wall (ms) | / python startup | heavy modules loaded | median CPU (ms) |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        heavy = ", ".join(r.heavy) or "none"
        cpu = "—" if r.cpu_seconds is None else f"{1e3 * r.cpu_seconds:.0f}"
        lines.append(
            f"| {r.label} | {1e3 * r.seconds:.0f} | {r.seconds / ref:.2f}x | {heavy} | {cpu} |"
        )
    return "\n".join(lines)


def add_bench_startup_parser(bsub: Any) -> None:
    """The ``startup`` sub-command (the options of the former ``voxwarp bench startup``)."""
    pbs = bsub.add_parser(
        "startup",
        help="start-up time of voxwarp --help, import voxwarp and a whole render of the"
        " stent sample vs python",
    )
    pbs.add_argument("--repeats", type=positive_int, default=5, help="runs per case")
    pbs.add_argument("--markdown", metavar="FILE", help="also write the table to FILE")
    pbs.set_defaults(func=cmd_bench_startup)


def cmd_bench_startup(args: argparse.Namespace) -> int:
    """``python -m benchmarks startup``: start-up time of the command line."""
    text = markdown(
        bench_startup(args.repeats), f"python -m benchmarks startup --repeats {args.repeats}"
    )
    return emit_report(text, args.markdown)
