"""From a wire edit to the frames after it: another commit against this checkout.

``python scripts/wire_edit_frames.py --before REV [--scales 2 1] [--repeats 3]``

The head case of ``python -m benchmarks wires --head`` (:data:`benchmarks.wires.HEAD_WIRE`
on :func:`benchmarks.wires.head_volume`) drawn at 512², dvr: after one untimed edit of
the deformed wire (compiling and warming everything), each repeat moves the wire's
last control point 2 mm and times the rebuild, the first frame (the chain everywhere,
no warped skip maps yet), the second frame (builds the warped skip maps and the
chain's support) and a steady frame; with the process's peak resident memory. Each
revision runs in its own worker process (``benchmarks.costs_tree``: ``--before`` is
exported with ``git archive``), the revisions alternating repeat by repeat. For the
tables of ``docs/benchmarks.md`` on a shared machine: medians, and the load average.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
#: what one repeat reports per scale
KEYS = ("build_s", "first_s", "second_s", "steady_s")


def worker(tree: str, scales: list[int]) -> None:
    """One repeat of every scale with the ``voxwarp`` of ``tree``; JSON on stdout."""
    sys.path.insert(0, str(ROOT))
    from benchmarks.costs_tree import use_tree

    use_tree(Path(tree))
    import numpy as np

    from benchmarks.wires import HEAD_WIRE, head_volume
    from voxwarp.deform.wires.build import WireDeformer
    from voxwarp.deform.wires.curves import Curve
    from voxwarp.deform.wires.wire import Wire
    from voxwarp.render.offscreen import OffscreenRenderer
    from voxwarp.scene import Scene

    vol = head_volume()
    out: dict[str, Any] = {}
    with OffscreenRenderer(512, 512) as r:
        base = Scene(vol, mode="dvr")
        r.render(base)
        for s in scales:
            wd = WireDeformer(vol, [Wire(**HEAD_WIRE)], field_scale=s)
            wd.build()
            scene = base.copy(warps=[wd.warp()])
            tip = np.asarray(HEAD_WIRE["modified"], dtype=np.float64)
            for _ in range(2):  # the first edit compiles and warms up
                tip[-1, 0] += 2.0
                wd.wires[0].modified = Curve(tip.copy(), HEAD_WIRE["kind"])
                t0 = time.perf_counter()
                wd.build()
                row = {"build_s": time.perf_counter() - t0}
                for key in KEYS[1:]:
                    row[key] = r.time_frames(scene, frames=1, warmup=0)[0] / 1000.0
            out[str(s)] = row
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM"):
            out["peak_mib"] = int(line.split()[1]) / 1024.0
    print(json.dumps(out))


def run(tree: Path, scales: list[int]) -> dict[str, Any]:
    """One worker's results."""
    cmd = [sys.executable, __file__, "--worker", str(tree), "--scales", *map(str, scales)]
    res = subprocess.run(cmd, capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--before", help="git revision to compare with this checkout")
    p.add_argument("--scales", type=int, nargs="+", default=[2, 1])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--worker", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        worker(args.worker, args.scales)
        return 0
    sys.path.insert(0, str(ROOT))
    from benchmarks.costs_tree import export_revision, resolve_revision

    load0 = Path("/proc/loadavg").read_text().split()[:3]
    with tempfile.TemporaryDirectory(prefix="voxwarp-edit-") as tmp:
        trees = {"after": ROOT}
        if args.before:
            commit = resolve_revision(ROOT, args.before)
            trees = {"before": export_revision(ROOT, commit, Path(tmp)), **trees}
        runs: dict[str, list[dict[str, Any]]] = {k: [] for k in trees}
        for _ in range(args.repeats):
            for name, tree in trees.items():
                runs[name].append(run(tree, args.scales))
    load1 = Path("/proc/loadavg").read_text().split()[:3]
    print(f"load average before / after: {' '.join(load0)} / {' '.join(load1)}")
    print("| revision | field | build s | first frame s | second frame s | steady s | peak MiB |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for name, rs in runs.items():
        peak = statistics.median(r["peak_mib"] for r in rs)
        for s in args.scales:
            med = [statistics.median(r[str(s)][k] for r in rs) for k in KEYS]
            cells = " | ".join(f"{v:.2f}" for v in med)
            print(f"| {name} | 1:{s**3} | {cells} | {peak:.0f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
