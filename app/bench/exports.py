"""``voxwarp bench exports``: ``export-field`` against ``export-volume`` of the same scene.

The bundled MRI (``sample:colin27``) is resampled trilinearly to ``--size`` voxels a
side (default 256³, the issue's case) and saved; for each deformation (a settled
mass-spring push, drawn through its offset field; a rigid-sided wire bend) the scene
JSON is written and the two commands run in turns, each in a fresh interpreter, as a
user runs them (``voxwarp export-volume SCENE -o v.nii``, ``voxwarp export-field SCENE -o
f.nii``, their defaults: the field at its default spacing with its field check). Each
round runs both, so the shared machine's load falls on both alike; the table gives the
median wall times over ``--rounds`` and their ratio measured in the same run.
``--sampler cpu`` times export-field with the CPU chain sampler, ``gpu`` with the GPU's
on every grid (by default the GPU samples grids of 2^22 nodes or more where an OpenGL
context opens: ``voxwarp export-field --sampler``).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.bench.command import add_bench_parser, emit_report
from voxwarp.bench.slices import massspring_warps, wire_warps
from voxwarp.core.checks import positive_int
from voxwarp.core.volume import Volume
from voxwarp.io.samples import load_sample
from voxwarp.scene import Scene

DEFORMATIONS = {"mass-spring": massspring_warps, "wires": wire_warps}


def resampled_head(size: int, folder: Path) -> Volume:
    """``sample:colin27`` resampled to ``size``³ voxels over its box, saved in
    ``folder`` (a scene JSON names its file) and loaded back."""
    from scipy import ndimage  # deferred: voxwarp --help stays light

    from voxwarp.io.volumes import load_volume, save_volume

    head = load_sample("colin27")
    zoom = [size / n for n in head.shape]
    data = ndimage.zoom(np.asarray(head.data, np.float32), zoom, order=1)
    spacing = tuple(float(s) * n / size for s, n in zip(head.spacing, head.shape, strict=True))
    vol = Volume(data.astype(head.data.dtype), spacing, head.origin, name=f"colin27-{size}")
    return load_volume(save_volume(vol, folder / f"head{size}.nii"))


def _run(argv: list[str]) -> None:
    """``voxwarp ARGV`` in a fresh interpreter, as a user times it (start-up included)."""
    done = subprocess.run(
        [sys.executable, "-m", "voxwarp", *argv], capture_output=True, text=True, check=False
    )
    if done.returncode != 0:
        raise RuntimeError(f"voxwarp {' '.join(argv)}: {done.stderr.strip()[-300:]}")


def bench_exports(
    size: int = 256,
    rounds: int = 1,
    deformations: Sequence[str] = tuple(DEFORMATIONS),
    log: Callable[[str], Any] | None = None,
    sampler: str | None = None,
) -> list[tuple[str, float, float]]:
    """``(deformation, export-volume s, export-field s)`` medians (module docstring);
    ``sampler`` is export-field's ``--sampler`` (``None``: its default)."""
    rows = []
    with tempfile.TemporaryDirectory(prefix="voxwarp-bench-exports-") as tmp:
        folder = Path(tmp)
        vol = resampled_head(size, folder)
        for name in deformations:
            scene = Scene(vol, warps=DEFORMATIONS[name](vol)).save(folder / f"{name}.json")
            times: dict[str, list[float]] = {"volume": [], "field": []}
            for _ in range(rounds):
                for kind in times:
                    t = time.perf_counter()
                    extra = ["--sampler", sampler] if kind == "field" and sampler else []
                    _run([f"export-{kind}", str(scene), "-o", str(folder / f"{kind}.nii"), *extra])
                    times[kind].append(time.perf_counter() - t)
            row = (name, statistics.median(times["volume"]), statistics.median(times["field"]))
            if log:
                log(f"{name}: export-volume {row[1]:.1f} s, export-field {row[2]:.1f} s")
            rows.append(row)
    return rows


def markdown(rows: list[tuple[str, float, float]], size: int, command: str) -> str:
    """The table of :func:`bench_exports`' rows."""
    lines = [
        f"`{command}` ({size}³ voxels, wall time, median over rounds)",
        "",
        "| deformation | export-volume (s) | export-field (s) | field / volume |",
        "|---|---|---|---|",
    ]
    lines += [f"| {n} | {v:.1f} | {f:.1f} | {f / v:.2f}x |" for n, v, f in rows]
    return "\n".join(lines) + "\n"


def cmd_bench_exports(args: argparse.Namespace) -> int:
    """``voxwarp bench exports``."""
    rows = bench_exports(
        args.size, args.rounds, log=lambda s: print(s, file=sys.stderr), sampler=args.sampler
    )
    argv = sys.argv[3:] if sys.argv[1:3] == ["bench", "exports"] else []
    command = " ".join(["voxwarp bench exports", *argv])
    return emit_report(markdown(rows, args.size, command), args.markdown)


def add_bench_exports_parser(bsub: Any) -> None:
    """Add ``exports`` to the ``bench`` sub-commands."""
    p = add_bench_parser(bsub, "exports", "export-field against export-volume", __doc__)
    p.add_argument("--size", type=positive_int, default=256, help="voxels a side (default 256)")
    p.add_argument("--rounds", type=positive_int, default=1, help="timed rounds (default 1)")
    p.add_argument(
        "--sampler",
        choices=("gpu", "cpu"),
        help="export-field's --sampler (default: its own: gpu for grids of 2^22 nodes or more)",
    )
    p.add_argument("--markdown", metavar="FILE", help="also write the table to FILE")
    p.set_defaults(func=cmd_bench_exports)
