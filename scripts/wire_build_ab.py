"""The wire field build of another commit against this checkout's, in one process.

``python scripts/wire_build_ab.py --before REV [--scales 2 1] [--repeats 5] [--edit]``

Loads ``deform/wires/{geometry,classify,masks,sides,build}.py`` as they were at ``REV``
(``git show``) beside the current modules, builds the head case of ``python -m
benchmarks wires --head`` (:data:`benchmarks.wires.HEAD_WIRE` on
:func:`benchmarks.wires.head_volume`) with both, checks that the two fields are
bit-identical (state, t, code, weight), then times the builds interleaved: medians of
wall and CPU seconds (all threads of the process) per stage, with the 1-minute load
average. ``--edit`` also times this checkout's rebuild after a drag of the deformed wire
against a plain rebuild. For the before/after tables of ``docs/benchmarks.md`` on a
shared machine.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
import types
from pathlib import Path
from typing import Any

import numpy as np
from scipy import ndimage

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: the build's timed stages (WireFieldStats.timings keys)
STAGES = ("tables", "masks", "seeds", "propagate", "flags", "store")
#: the modules loaded at the old commit, in import order (every module the build's
#: classes come from: one left out would be shared with this checkout); those the old
#: commit does not have yet are skipped
OLD_MODULES = (
    "geometry",
    "classify",
    "fade_cl",
    "masks",
    "sides",
    "field_box",
    "field_geometry",
    "build",
)


def load_before(rev: str) -> Any:
    """The ``WireDeformer`` class of commit ``rev`` (its build modules loaded from git,
    the rest of the package shared with this checkout)."""
    names = [f"voxwarp.deform.wires.{m}" for m in OLD_MODULES]
    saved = {n: sys.modules.get(n) for n in names}
    try:
        for name, short in zip(names, OLD_MODULES, strict=True):
            path = f"deform/wires/{short}.py"
            res = subprocess.run(
                ["git", "-C", str(ROOT), "show", f"{rev}:{path}"],
                check=False,
                capture_output=True,
                text=True,
            )
            if res.returncode != 0:  # not there yet at rev
                continue
            src = res.stdout
            mod = types.ModuleType(name)
            mod.__file__ = f"{rev}:{path}"
            sys.modules[name] = mod
            exec(compile(src, mod.__file__, "exec"), mod.__dict__)
        return sys.modules[names[-1]].WireDeformer
    finally:
        for n, m in saved.items():  # this checkout's modules again (or none yet)
            if m is None:
                sys.modules.pop(n, None)
            else:
                sys.modules[n] = m


def same_field(a: Any, b: Any) -> bool:
    """Whether two built fields hold the same bits (state, code, weight), and t where a
    swept sample's trilinear lookup reads it (swept voxels and their 26 neighbours: a
    smaller propagated region leaves other voxels' t unset)."""
    for key in ("state", "code", "weight"):
        x, y = getattr(a, key), getattr(b, key)
        if (x is None) != (y is None):
            return False
        if x is not None and not (x.dtype == y.dtype and np.array_equal(x, y)):
            return False
    if (a.t is None) != (b.t is None):
        return False
    if a.t is None:
        return True
    read = ndimage.maximum_filter(a.decode()[0] == 2, size=3, mode="constant")
    return a.t.dtype == b.t.dtype and np.array_equal(a.t[read], b.t[read])


def timed(wd: Any) -> dict[str, float]:
    """One build's stage seconds, its wall ``total`` and ``cpu`` seconds."""
    c0 = time.process_time()
    t = dict(wd.build().timings)
    t["cpu"] = time.process_time() - c0
    # the smooth ends' trim has no stage of its own: what the stages leave of the total
    t["rest"] = t["total"] - sum(t.get(k, 0.0) for k in STAGES)
    t["load"] = float(Path("/proc/loadavg").read_text().split()[0])
    return t


def bench_edit(volume: Any, scale: int, repeats: int) -> None:
    """Time a rebuild against a rebuild after a drag of the deformed wire (its last
    control point moved 2 or 4 mm sideways), interleaved, this checkout's build."""
    from benchmarks.wires import HEAD_WIRE
    from voxwarp.deform.wires.build import WireDeformer
    from voxwarp.deform.wires.curves import Curve
    from voxwarp.deform.wires.wire import Wire

    wd = WireDeformer(volume, [Wire(**HEAD_WIRE)], field_scale=scale)
    wd.build()
    tip = np.asarray(HEAD_WIRE["modified"], dtype=np.float64)
    runs: dict[str, list[dict[str, float]]] = {"rebuild": [], "edit": []}
    for r in range(repeats):
        for name, rs in runs.items():
            if name == "edit":
                moved = tip.copy()
                moved[-1, 0] += 2.0 * (1 + r % 2)
                wd.wires[0].modified = Curve(moved, HEAD_WIRE["kind"])
            rs.append(timed(wd))
    for name, rs in runs.items():
        print(
            f"1:{scale**3} {name:8s} total {statistics.median(r['total'] for r in rs):.3f}"
            f" cpu {statistics.median(r['cpu'] for r in rs):.3f}"
            f" load {min(r['load'] for r in rs):.1f}-{max(r['load'] for r in rs):.1f}"
        )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--before", required=True, help="git revision of the old build")
    p.add_argument("--scales", type=int, nargs="+", default=[2, 1])
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--edit", action="store_true", help="also time rebuilds after a wire drag")
    args = p.parse_args(argv)

    from benchmarks.wires import HEAD_WIRE, head_volume
    from voxwarp.deform.wires.build import WireDeformer
    from voxwarp.deform.wires.wire import Wire

    before = load_before(args.before)
    volume = head_volume()
    keys = ("total", "cpu", *STAGES, "rest")
    for scale in args.scales:
        builds = {
            "before": before(volume, [Wire(**HEAD_WIRE)], field_scale=scale),
            "after": WireDeformer(volume, [Wire(**HEAD_WIRE)], field_scale=scale),
        }
        for wd in builds.values():
            wd.build()  # untimed: kernels, buffers
        ok = same_field(builds["before"].field, builds["after"].field)
        print(f"1:{scale**3} field {builds['after'].stats.field_shape}: bit-identical={ok}")
        runs: dict[str, list[dict[str, float]]] = {k: [] for k in builds}
        for _ in range(args.repeats):
            for name, wd in builds.items():
                runs[name].append(timed(wd))
        for name, rs in runs.items():
            med = {k: statistics.median(r.get(k, 0.0) for r in rs) for k in keys}
            loads = [r["load"] for r in rs]
            print(
                f"1:{scale**3} {name:6s} "
                + " ".join(f"{k} {v:.3f}" for k, v in med.items())
                + f" load {min(loads):.1f}-{max(loads):.1f}"
            )
        ratio = statistics.median(r["total"] for r in runs["after"]) / statistics.median(
            r["total"] for r in runs["before"]
        )
        cpu = statistics.median(r["cpu"] for r in runs["after"]) / statistics.median(
            r["cpu"] for r in runs["before"]
        )
        print(f"1:{scale**3} after/before: wall {ratio:.2f}x, cpu {cpu:.2f}x")
        if args.edit:
            bench_edit(volume, scale, args.repeats)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
