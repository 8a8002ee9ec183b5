"""``python -m benchmarks costs``: what a deformation, a big volume and the GUI cost, before
and after a change, in one run.

Measures every line of :data:`benchmarks.costs_table.LINES` (deformed frames over the
undeformed frame, undeformed dvr against VTK's fixed-point raycaster per covered pixel,
the wire field's build on an MRI head, a 512³ volume's first frame and memory, the GUI's
frame rate while dragging) on each ``--volume`` (default: the bundled real scans
``sample:stent``, a sparse CT, and ``sample:colin27``, a dense MRI), at 512x512 in dvr.

``--before REV`` (default: the merge base of HEAD and ``main``; ``none``: the checkout
alone) measures the same lines with the code of REV in the same run: REV's files are
exported (``git archive``) to a temporary folder and imported as ``voxwarp`` by a worker
process of their own (:mod:`benchmarks.costs_tree`); the checkout's working tree is
measured by a second worker. Both workers stay up for the whole run and their repeats
alternate (before, after, after, before, ...), so that load drift on a shared machine
hits both columns alike. Every number is the median of ``--repeats`` repeats, each a
ratio against its reference measured in the same repeat (or seconds for the wire field);
the load average is printed beside each line. ``--only`` measures some of the lines
(e.g. ``--only chainmail_local,massspring_settled``: the deformed frames, minutes instead
of the whole table's quarter hour). ``--quick`` (64x64 images, 32³ volumes, one repeat)
checks that the harness runs; its numbers mean nothing.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import IO, Any

from benchmarks import ROOT, child_env
from benchmarks.costs_table import GLOBAL, LINES, MEASUREMENTS, markdown, medians
from benchmarks.costs_worker import MARK
from voxwarp.bench.command import add_bench_parser

#: the volumes measured when no ``--volume`` is given
DEFAULT_VOLUMES: tuple[str, ...] = ("sample:stent", "sample:colin27")
DEFAULT_REPEATS = 5


def _log(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


class Worker:
    """A :mod:`benchmarks.costs_worker` process measuring the tree ``tree``."""

    def __init__(
        self, label: str, commit: str, tree: Path, quick: bool, tf: str | None = None
    ) -> None:
        self.label, self.commit, self.tree = label, commit, tree
        cmd = [sys.executable, "-m", "benchmarks.costs_worker", "--tree", str(tree)]
        cmd += ["--quick"] if quick else []
        cmd += ["--tf", tf] if tf else []
        self.proc = subprocess.Popen(
            cmd,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            env=child_env(),
            cwd=str(ROOT),
        )
        #: the folder the worker imported ``voxwarp`` from ("" if it failed to start)
        self.imported = str(self._read().get("voxwarp", ""))

    def ask(self, measure: str, volume: str) -> dict[str, Any]:
        """One repeat of ``measure`` on ``volume``: ``{"values": ...}`` and/or ``{"error":
        ...}`` (also when the worker died)."""
        stdin = self._pipes()[0]
        try:
            stdin.write(json.dumps({"row": measure, "volume": volume}) + "\n")
            stdin.flush()
        except OSError:
            return {"error": f"the {self.label} worker exited ({self.proc.poll()})"}
        return self._read()

    def _read(self) -> dict[str, Any]:
        """The worker's next answer line (an error when it exited)."""
        for line in self._pipes()[1]:
            at = line.find(MARK)
            if at >= 0:
                return json.loads(line[at + len(MARK) :])
        return {"error": f"the {self.label} worker exited ({self.proc.wait()})"}

    def _pipes(self) -> tuple[IO[str], IO[str]]:
        assert self.proc.stdin is not None
        assert self.proc.stdout is not None
        return self.proc.stdin, self.proc.stdout

    def close(self) -> None:
        """End the worker (end of input; killed if it does not exit in 60 s)."""
        stdin, stdout = self._pipes()
        try:
            stdin.close()
            self.proc.wait(timeout=60)
        except (OSError, subprocess.TimeoutExpired):
            self.proc.kill()
            self.proc.wait()
        stdout.close()


def _git(*args: str) -> str:
    res = subprocess.run(
        ["git", "-C", str(ROOT), *args], capture_output=True, text=True, check=False
    )
    return res.stdout.strip() if res.returncode == 0 else ""


def _checkout_commit() -> str:
    commit = _git("rev-parse", "HEAD") or "unknown"
    return commit + (" + working tree changes" if _git("status", "--porcelain") else "")


def check_volumes(volumes: Sequence[str], tf: str | None = None) -> None:
    """Load each volume spec once here (and resolve ``tf`` on it), so a bad one is one
    line before any worker."""
    from voxwarp.inputs import load_input
    from voxwarp.scene import Scene

    for spec in volumes:
        volume = load_input(spec)
        if tf:
            Scene(volume, transfer_function=tf)


def _machine() -> tuple[dict[str, Any], str]:
    from benchmarks.hardware import probe_hardware

    hw = probe_hardware()
    gl = hw.get("gl", {})
    text = (
        f"{hw.get('cpu', '?')}, {hw.get('cores', '?')} cores, {hw.get('ram_gib', 0):.0f} GiB,"
        f" GL: {gl.get('error') or gl.get('renderer', '?')}"
    )
    return hw, text


def _tasks(
    volumes: Sequence[str], measures: Sequence[str] = MEASUREMENTS
) -> list[tuple[str, str | None]]:
    """(measurement, volume; None for one made once) in running order."""
    return [
        task
        for m in MEASUREMENTS
        if m in measures
        for task in ([(m, None)] if m in GLOBAL else [(m, v) for v in volumes])
    ]


def check_measures(measures: Sequence[str]) -> None:
    """Raise InputError naming the unknown ones among ``measures``."""
    from voxwarp.errors import InputError

    unknown = [m for m in measures if m not in MEASUREMENTS]
    if unknown:
        raise InputError(
            f"unknown measurement {', '.join(unknown)}; pick from {', '.join(MEASUREMENTS)}"
        )


def measure_all(
    workers: Sequence[Worker],
    volumes: Sequence[str],
    repeats: int,
    log: Callable[[str], Any] = _log,
    measures: Sequence[str] = MEASUREMENTS,
) -> dict[tuple[str, str | None], dict[str, Any]]:
    """Each of ``measures`` (default: all) on every volume: per task, per worker label,
    the repeats' numbers and the first error; the repeats of the workers alternate."""
    from voxwarp.core.timing import load_average

    out: dict[tuple[str, str | None], dict[str, Any]] = {}
    for measure, volume in _tasks(volumes, measures):
        res: dict[str, Any] = {w.label: {"repeats": [], "error": ""} for w in workers}
        loads: list[float] = []
        for i in range(repeats):
            order = list(workers) if i % 2 == 0 else list(reversed(workers))
            for w in order:
                mine = res[w.label]
                if mine["error"] and not mine["repeats"]:
                    continue  # failed on its first try: it will again
                reply = w.ask(measure, volume or volumes[0])
                if "values" in reply:
                    mine["repeats"].append(reply["values"])
                mine["error"] = mine["error"] or reply.get("error", "")
            loads.append(load_average())
            done = ", ".join(f"{w.label} {_brief(res[w.label])}" for w in workers)
            log(f"{measure} {volume or ''} repeat {i + 1}/{repeats}: {done} (load {loads[-1]:.1f})")
        for mine in res.values():
            mine["median"] = medians(mine["repeats"])
        out[(measure, volume)] = {"results": res, "load": loads}
    return out


def _brief(result: dict[str, Any]) -> str:
    if not result["repeats"]:
        return f"failed ({result['error']})"
    last = result["repeats"][-1]
    return " ".join(f"{k}={v:.3g}" for k, v in last.items())


def table_rows(
    measured: dict[tuple[str, str | None], dict[str, Any]], volumes: Sequence[str]
) -> list[dict[str, Any]]:
    """The table's rows (line, volume, results by label, load averages) in line order."""
    rows = []
    for line in LINES:
        for volume in volumes if line.per_volume else [None]:
            found = measured.get((line.measure, volume))
            if found is not None:
                rows.append({"line": line.key, "volume": volume, **found})
    return rows


def run_costs(
    volumes: Sequence[str] = DEFAULT_VOLUMES,
    *,
    before: str | None = None,
    repeats: int = DEFAULT_REPEATS,
    quick: bool = False,
    command: str = "python -m benchmarks costs",
    log: Callable[[str], Any] = _log,
    measures: Sequence[str] = MEASUREMENTS,
    tf: str | None = None,
) -> dict[str, Any]:
    """Measure the table (see the module docstring; ``measures``: some of its
    measurements) with the code of ``before`` (a git revision; None: the checkout alone)
    and of the checkout; the run as JSON-ready dict. ``tf``: the transfer function
    (preset name or file) of every volume's frames instead of its default."""
    from benchmarks.costs_tree import export_revision, resolve_revision
    from voxwarp.core.timing import load_average

    check_measures(measures)
    commit = None if before is None else resolve_revision(ROOT, before)
    check_volumes(volumes, tf)
    t0, load0 = time.perf_counter(), load_average()
    hw, machine = _machine()
    log(f"machine: {machine}; load average {load0:.1f}")
    with tempfile.TemporaryDirectory(prefix="voxwarp-costs-") as tmp:
        trees = []
        if before is not None and commit is not None:
            log(f"before: {before} ({commit[:10]}), exported to {tmp}")
            trees.append(("before", before, commit, export_revision(ROOT, commit, Path(tmp))))
        trees.append(("after", "the checkout", _checkout_commit(), ROOT))
        workers = [Worker(label, c, tree, quick, tf) for label, _, c, tree in trees]
        try:
            measured = measure_all(workers, volumes, repeats, log, measures)
        finally:
            for w in workers:
                w.close()
    return {
        "command": command,
        "machine": machine,
        "hardware": hw,
        "quick": quick,
        "repeats": repeats,
        "size": [64, 64] if quick else [512, 512],
        "volumes": list(volumes),
        "transfer_function": tf,
        "revisions": [
            {"label": w.label, "rev": rev, "commit": w.commit, "voxwarp": w.imported}
            for w, (_, rev, _, _) in zip(workers, trees, strict=True)
        ],
        "load": [load0, load_average()],
        "wall_s": round(time.perf_counter() - t0, 1),
        "rows": table_rows(measured, volumes),
    }


# ---------------------------------------------------------------------- command line
def add_bench_costs_parser(bsub: Any) -> None:
    """Add ``costs`` to the ``python -m benchmarks`` sub-commands."""
    p = add_bench_parser(
        bsub,
        "costs",
        "the cost table (deformed frames, VTK, wire field, 512³, GUI) before vs after",
        __doc__,
    )
    p.add_argument(
        "--volume",
        action="append",
        metavar="SPEC",
        help="a volume to measure (sample:NAME or a file; repeat the option for more);"
        f" default {' and '.join(DEFAULT_VOLUMES)}",
    )
    p.add_argument(
        "--before",
        metavar="REV",
        default="",
        help="git revision measured beside the checkout in the same run (default: the"
        " merge base of HEAD and main); 'none': the checkout alone",
    )
    p.add_argument(
        "--repeats",
        type=int,
        default=None,
        help=f"repeats per line and revision, medians reported (default {DEFAULT_REPEATS},"
        " 1 with --quick)",
    )
    p.add_argument(
        "--only",
        metavar="MEASURES",
        default="",
        help=f"comma-separated measurements to run (default all: {', '.join(MEASUREMENTS)})",
    )
    p.add_argument(
        "--tf",
        metavar="NAME",
        help="transfer function of every volume's frames (a preset such as ct-soft, or a"
        " file) instead of its default (a bundled sample's suggested one, a file's"
        " modality default: ct-bone for a CT)",
    )
    p.add_argument("--quick", action="store_true", help="64x64, 32³ volumes: checks the harness")
    p.add_argument("--json", metavar="FILE", help="write the run (every repeat) as JSON")
    p.add_argument("--markdown-out", metavar="FILE", help="write the table to FILE")
    p.set_defaults(func=cmd_bench_costs)


def _before(text: str) -> str | None:
    from benchmarks.costs_tree import default_before

    if text.lower() == "none":
        return None
    return text or default_before(ROOT)


def cmd_bench_costs(args: argparse.Namespace) -> int:
    """``python -m benchmarks costs``: see the module docstring."""
    from benchmarks.costs_tree import TreeError
    from voxwarp.core.files import atomic_write_text
    from voxwarp.errors import InputError

    repeats = args.repeats if args.repeats is not None else (1 if args.quick else DEFAULT_REPEATS)
    if repeats < 1:
        raise InputError(f"--repeats must be at least 1; got {repeats}")
    argv = sys.argv[2:] if sys.argv[1:2] == ["costs"] else []
    command = " ".join(["python -m benchmarks costs", *argv])
    try:
        run = run_costs(
            tuple(args.volume or DEFAULT_VOLUMES),
            before=_before(args.before),
            repeats=repeats,
            quick=args.quick,
            command=command,
            measures=tuple(m for m in args.only.split(",") if m) or MEASUREMENTS,
            tf=args.tf,
        )
    except TreeError as exc:
        raise InputError(str(exc)) from None
    text = markdown(run)
    print(text)
    if args.json:
        atomic_write_text(Path(args.json), json.dumps(run, indent=1, default=str) + "\n")
    if args.markdown_out:
        atomic_write_text(Path(args.markdown_out), text)
    return 0
