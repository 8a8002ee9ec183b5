"""``python -m benchmarks all``: every benchmark in one command, one table.

Prints the hardware first (:mod:`benchmarks.hardware`), then runs each benchmark of
:data:`BENCHMARKS` in a subprocess of its own (``python -m benchmarks.all --child NAME``;
``--in-process`` runs them in this process instead): a benchmark that crashes, raises or
runs past its time limit is reported as failed with its one-line error and the others
still run. ``--quick`` gives each benchmark its small options (fewer frames, sizes and
repeats) so that the whole run stays within a few minutes on a 2-core software renderer.

Each runner of :data:`RUNNERS` returns a record: its key ratios (``ratios``), the lines of
issue 19's "Where it stands" table it measures (``issue``: key of :data:`ISSUE_ROWS` ->
text) and its own markdown report. The JSON output keeps every record; the markdown
output is the hardware and one table of the issue's rows, with the benchmarks' status
below it. The exit status is 0 when at least one benchmark ran, 1 when all failed.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from benchmarks import child_env
from voxwarp.bench.command import add_bench_parser

#: every benchmark, in running order
BENCHMARKS: tuple[str, ...] = (
    "startup",
    "render",
    "scale",
    "massspring",
    "chainmail",
    "wires",
    "wire-tables",
    "wire-ends",
    "lattice",
    "interactive",
    "fields",
    "segments",
    "support",
    "slices",
    "detj",
    "costs",
)
#: seconds one benchmark may run before it is stopped (quick, full)
TIMEOUT_S: tuple[float, float] = (240.0, 3600.0)

#: issue 19's "Where it stands" rows: key, what, target
ISSUE_ROWS: tuple[tuple[str, str, str], ...] = (
    (
        "render",
        "undeformed dvr, sparse and dense cases (vs VTK fixed-point when installed)",
        ">= 2.5x VTK fixed-point on sparse and dense data",
    ),
    ("massspring_dvr", "mass-spring offset-field dvr / undeformed (16³, baked inverse)", "<= 1.3x"),
    ("wire_dvr", "wire-field dvr / undeformed", "<= 1.3x"),
    ("lattice_dvr", "lattice over a volume / undeformed", "<= 1.5x"),
    (
        "gui_frame",
        "GUI frame while dragging (half resolution) / undeformed full frame",
        ">= 15 fps at the default window",
    ),
    ("wire_build", "wire attribute field build, 1:8 and 1:1", "1:8 <= 0.2 s, 1:1 <= 1.0 s"),
    (
        "gpu_massspring",
        "GLSL mass-spring steps/s vs taichi-CPU",
        ">= 1.0x the minimal kernel",
    ),
    ("startup", "`voxwarp render sample:stent -o x.png` end to end", "<= 1.0 s"),
    ("first_frame", "first frame of a new volume (load -> image, 512², dvr)", "512³ <= 2 s"),
    ("memory", "memory of the first render beyond the array", "<= 2x the volume's bytes"),
    ("gpu_table", "datacenter GPU: 512³ -> 1024², deformed dvr", ">= 60 fps"),
    (
        "segments",
        "piecewise-linear warped rays ('auto') / the chain at every sample",
        "< 1.0x, image within the stated tolerance",
    ),
    (
        "support_drag",
        "local ChainMail drag (16³, one element 15 mm) / undeformed, straight outside its"
        " support (in brackets: the chain at every sample)",
        "<= 1.3x",
    ),
)


@dataclass
class Record:
    """One benchmark's outcome."""

    name: str
    status: str  # "ok" or "failed"
    seconds: float
    ratios: dict[str, Any] = field(default_factory=dict)
    issue: dict[str, str] = field(default_factory=dict)
    markdown: str = ""
    error: str = ""


def _log(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def _x(v: float | None) -> str:
    return "—" if v is None else f"{v:.2f}x"


# ---------------------------------------------------------------------- runners
def run_startup(quick: bool) -> dict[str, Any]:
    """``bench startup`` (2 repeats with ``quick``, else 5), whose cases include the whole
    ``voxwarp render sample:stent -o x.png``."""
    from benchmarks.startup import RENDER_CASE, bench_startup, markdown

    repeats = 2 if quick else 5
    rows = bench_startup(repeats)
    ref = rows[0].seconds
    ratios: dict[str, Any] = {f"{r.label} / python": round(r.seconds / ref, 2) for r in rows[1:]}
    render = next((r for r in rows if r.label == RENDER_CASE), None)
    issue = {}
    if render is not None:
        ratios["render sample:stent s"] = round(render.seconds, 3)
        cpu = "" if render.cpu_seconds is None else f", {render.cpu_seconds:.2f} s CPU"
        issue["startup"] = f"{render.seconds:.2f} s wall{cpu} (median of {repeats})"
    text = markdown(rows, f"python -m benchmarks startup --repeats {repeats}")
    return {"ratios": ratios, "issue": issue, "markdown": text}


def run_render(quick: bool) -> dict[str, Any]:
    """The standard ``bench render`` cases (sparse, dense phantom, MRI); with ``quick``
    dvr only, 2 frames after 1 warm-up, and of VTK only the fixed-point reference."""
    from benchmarks.render import bench_render_cases, case_summary
    from voxwarp.bench.render import standard_cases

    reports = bench_render_cases(
        standard_cases(("dvr",) if quick else ("dvr", "mip")),
        frames=2 if quick else 10,
        warmup=1 if quick else 2,
        vtk_mappers=("fixed_point",) if quick else ("fixed_point", "gpu"),
        log=_log,
    )
    summaries = [case_summary(r) for r in reports]
    parts = []
    for s in summaries:
        vtk = s["speedup_vs_VTK fixed-point (CPU)"]
        vs = f"{vtk:.2f}x VTK fixed-point" if vtk else "VTK not installed"
        parts.append(
            f"{s['case']}: {s['voxwarp_dvr_ms']:.0f} ms, {100 * s['covered']:.0f} % covered, {vs}"
        )
    command = (
        "python -m benchmarks render --frames 2 --warmup 1 (dvr)"
        if quick
        else "python -m benchmarks render"
    )
    return {
        "ratios": {"cases": summaries},
        "issue": {"render": "; ".join(parts)},
        "markdown": "\n".join(r.markdown(command) for r in reports),
    }


def run_scale(quick: bool) -> dict[str, Any]:
    """``bench scale`` (with ``quick``: 128³ and 256³, 2 steady frames)."""
    from benchmarks.scale import DEFAULT_SIZES, QUICK_SIZES, bench_scale

    sizes = QUICK_SIZES if quick else DEFAULT_SIZES
    report = bench_scale(sizes, frames=2 if quick else 5, log=_log)
    first = " / ".join(f"{r.first_ms / 1000:.2f} s" for r in report.rows)
    labels = " / ".join(r.label for r in report.rows)
    big = report.rows[-1]
    times = big.peak_rss_mib / (big.nbytes / 2**20)
    mem = f"{big.label}: +{big.peak_rss_mib:.0f} MiB peak RSS ({times:.1f}x the array)"
    if big.kept_mib >= 0:
        mem += f", {big.kept_mib / (big.nbytes / 2**20):.1f}x kept after its cell maps"
    if big.steady_ms > 0:
        first += f" (first / steady of {big.label}: {big.first_ms / big.steady_ms:.1f}x)"
    data = report.to_dict()
    ratios = {r["label"]: r["growth"] for r in data["rows"]}
    command = "python -m benchmarks scale" + (" --quick" if quick else "")
    return {
        "ratios": ratios,
        "issue": {"first_frame": f"{labels}: {first}", "memory": mem},
        "markdown": report.markdown(command),
    }


def run_massspring(quick: bool) -> dict[str, Any]:
    """``bench massspring`` (with ``quick``: the 32³ grid, short blocks, and of the
    deformed renders only the undeformed and the baked-inverse rows) and its deformed
    renders."""
    from benchmarks.massspring import bench_massspring
    from voxwarp.bench.render import bench_warp_render

    sizes = (32,) if quick else (16, 32, 64, 128)
    report = bench_massspring(
        sizes,
        steps=10 if quick else 50,
        repeats=2 if quick else 5,
        max_block_s=0.5 if quick else 2.0,
        log=_log,
    )
    warp = bench_warp_render(
        frames=3 if quick else 10,
        warmup=1 if quick else 2,
        only=("undeformed", "offset warp, baked") if quick else None,
        log=_log,
    )
    baked = warp.ratio("offset warp, baked")
    ratios: dict[str, Any] = {"offset warp baked / undeformed": baked}
    for n in sizes:
        ratios[f"{n}³ gpu / numpy"] = report.ratio(n, "gpu", "numpy")
        ratios[f"{n}³ gpu / taichi"] = report.ratio(n, "gpu", "taichi")
        ratios[f"{n}³ gpu / taichi minimal"] = report.ratio(n, "gpu", "taichi-min")
    big = max(sizes)
    taichi = report.ratio(big, "gpu", "taichi")
    gpu = report.find(big, "gpu")
    gpu_text = "not measured" if gpu is None else f"{big}³ GPU {gpu.median_sps:.0f} steps/s"
    gpu_text += ", taichi not installed" if taichi is None else f", {taichi:.2f}x taichi"
    minimal = report.ratio(big, "gpu", "taichi-min")
    gpu_text += "" if minimal is None else f", {minimal:.2f}x the minimal kernel"
    command = "python -m benchmarks massspring" + (" (quick)" if quick else "")
    return {
        "ratios": ratios,
        "issue": {"massspring_dvr": _x(baked), "gpu_massspring": gpu_text},
        "markdown": report.markdown(command) + "\n" + warp.markdown(command),
    }


def run_chainmail(quick: bool) -> dict[str, Any]:
    """``bench chainmail`` (16³ only with ``quick``)."""
    from benchmarks.chainmail import bench_chainmail

    sizes = (16,) if quick else (16, 32, 64, 128)
    report = bench_chainmail(sizes, repeats=2 if quick else 5, log=_log)
    ratios = {
        f"{r.size}³ {r.solver} {r.drag} ms": round(r.median_ms, 3)
        for r in report.rows
        if r.repeats > 0
    }
    return {
        "ratios": ratios,
        "issue": {},
        "markdown": report.markdown("python -m benchmarks chainmail"),
    }


def run_wires(quick: bool) -> dict[str, Any]:
    """``bench wires`` (with ``quick``: scale 2 only, one build each, 256x128 framed,
    ct-bone, no reference warp, full-grid propagation or phantoms)."""
    from benchmarks.wires import bench_wires

    kw: dict[str, Any] = {}
    if quick:
        kw = {
            "scales": (2,),
            "repeats": 1,
            "frames": 2,
            "tfs": ("ct-bone",),
            "cameras": ("framed",),
            "sizes": ((256, 128),),
            "reference": False,
            "full_grid": 0,
            "subsample": 16,
            "phantoms": (),
        }
    report = bench_wires(log=_log, **kw)
    ratios = {
        f"{r.layout} {r.tf} {r.camera} / undeformed": round(r.ratio, 3)
        for r in report.renders
        if not r.reference
    }
    builds = {f"1:{b.scale**3} {b.layout} s": round(b.median_s, 3) for b in report.builds}
    ratios.update(builds)
    dvr = [v for k, v in ratios.items() if k.endswith("/ undeformed")]
    build_text = ", ".join(f"{k} {v:.2f}" for k, v in builds.items() if "float" in k)
    return {
        "ratios": ratios,
        "issue": {
            "wire_dvr": f"{min(dvr):.2f}x–{max(dvr):.2f}x" if dvr else "not measured",
            "wire_build": f"{report.volume}: {build_text or 'not measured'}",
        },
        "markdown": report.markdown("python -m benchmarks wires" + (" (quick)" if quick else "")),
    }


def run_wire_tables(quick: bool) -> dict[str, Any]:
    """``bench wire-tables`` (with ``quick``: the tubes alone, 256x128, 2 frames)."""
    from benchmarks.wire_tables import DATASETS, bench_wire_tables, markdown

    kw: dict[str, Any] = {"datasets": DATASETS}
    if quick:
        kw = {"datasets": ("tubes",), "size": (256, 128), "frames": 2, "repeats": 1}
    rows = bench_wire_tables(log=_log, **kw)
    ratios: dict[str, float] = {}
    for r in rows:
        ratios[f"{r.dataset} identity render / standard"] = round(r.render_ratio, 3)
        ratios[f"{r.dataset} (build + identity render) / standard"] = round(r.total_ratio, 3)
    command = "python -m benchmarks wire-tables" + (" (quick)" if quick else "")
    return {"ratios": ratios, "issue": {}, "markdown": markdown(rows, command)}


def run_wire_ends(quick: bool) -> dict[str, Any]:
    """``bench wire-ends`` (with ``quick``: the MRI head alone at 192x192)."""
    from benchmarks.wire_ends import CASES, bench_wire_ends, markdown

    rows = bench_wire_ends(
        ("colin27",) if quick else CASES, (192, 192) if quick else (384, 384), _log
    )
    ratios = {f"{r.case} {r.ends} 1:8 % pixels off 1:1": round(r.seams[2][0], 3) for r in rows}
    command = "python -m benchmarks wire-ends" + (" (quick)" if quick else "")
    return {"ratios": ratios, "issue": {}, "markdown": markdown(rows, command)}


def run_lattice(quick: bool) -> dict[str, Any]:
    """``bench lattice`` (with ``quick``: 100k triangles, 200 objects, 256², cells 1,4)."""
    from benchmarks.lattice import bench_lattice

    kw: dict[str, Any] = {}
    if quick:
        kw = {
            "triangles": 100_000,
            "objects": 200,
            "frames": 2,
            "size": (256, 256),
            "cells": (1, 4),
            "crosscheck": False,
        }
    report = bench_lattice(log=_log, **kw)
    ratio = report.composition_fps_ratio
    return {
        "ratios": {"composition trilinear fps / linear fps": ratio},
        "issue": {},
        "markdown": report.markdown("python -m benchmarks lattice" + (" (quick)" if quick else "")),
    }


def run_interactive(quick: bool) -> dict[str, Any]:
    """``bench interactive`` at the default window (with ``quick``: half of it each way,
    375x415, and 1 frame per case)."""
    from voxwarp.bench.interactive import bench_interactive

    size = (375, 415) if quick else (750, 830)
    report = bench_interactive(size=size, frames=1 if quick else 5, log=_log)
    ref = report.reference_ms
    ratios: dict[str, Any] = {"reference ms": round(ref, 1)}
    drag = []
    for r in report.rows:
        ratios[f"{r.family} interactive / undeformed"] = round(r.interactive_ms / ref, 3)
        ratios[f"{r.family} at rest / undeformed"] = round(r.rest_cells_ms / ref, 3)
        drag.append(f"{r.family} {r.interactive_ms / ref:.1f}x ({1000 / r.interactive_ms:.1f} fps)")
    window = f"{size[0]}x{size[1]} window: "
    issue = {"gui_frame": window + ", ".join(drag)}
    lattice = next((r for r in report.rows if r.family == "lattice"), None)
    if lattice is not None:
        issue["lattice_dvr"] = (
            f"{lattice.rest_cells_ms / ref:.2f}x (bench interactive: lattice family at rest,"
            " bundled CT)"
        )
    command = (
        f"python -m benchmarks interactive --size {size[0]}x{size[1]} --frames {1 if quick else 5}"
    )
    return {"ratios": ratios, "issue": issue, "markdown": report.markdown(command)}


def run_fields(quick: bool) -> dict[str, Any]:
    """``bench fields`` (its own ``--quick``: a 32³ volume, 64², 4³ and 8³ fields)."""
    from benchmarks.fields import bench_fields, quick_volume

    if quick:
        report = bench_fields(
            quick_volume(), nodes=(4, 8), size=(64, 64), frames=1, warmup=1, log=_log
        )
    else:
        report = bench_fields(log=_log)
    ratios = {
        f"{r.name} {r.mode} / undeformed": report.ratio(r.name, r.mode)
        for r in report.frame_rows
        if r.name != "undeformed"
    }
    command = "python -m benchmarks fields" + (" --quick" if quick else "")
    return {"ratios": ratios, "issue": {}, "markdown": report.markdown(command)}


def run_segments(quick: bool) -> dict[str, Any]:
    """``bench segments`` (with ``quick``: 256², 2 frames)."""
    from benchmarks.segments import bench_segments

    size, frames = ((256, 256), 2) if quick else ((512, 512), 5)
    report = bench_segments(size=size, frames=frames, log=_log)
    ratios = {}
    for r in report.rows:
        ratios[f"{r.case} auto / per-sample"] = r.ratios["auto"] / r.ratios["1"]
        ratios[f"{r.case} per-sample / undeformed"] = r.ratios["1"]
    text = ", ".join(
        f"{r.case} {r.ratios['auto'] / r.ratios['1']:.2f}x (max diff {r.max_diff['auto']:.0f})"
        for r in report.rows
    )
    command = f"python -m benchmarks segments --size {size[0]}x{size[1]} --frames {frames}"
    return {"ratios": ratios, "issue": {"segments": text}, "markdown": report.markdown(command)}


def run_support(quick: bool) -> dict[str, Any]:
    """``bench support`` (with ``quick``: 256², 2 frames)."""
    from benchmarks.support import bench_support

    size, frames = ((256, 256), 2) if quick else ((512, 512), 5)
    report = bench_support(size=size, frames=frames, log=_log)
    ratios = {}
    for r in report.rows:
        ratios[f"{r.volume} {r.case} / undeformed"] = r.new
        ratios[f"{r.volume} {r.case} old / undeformed"] = r.old
    text = ", ".join(
        f"{r.volume} {r.new:.2f}x ({r.old:.2f}x)" for r in report.rows if r.case == "chainmail drag"
    )
    command = f"python -m benchmarks support --size {size[0]}x{size[1]} --frames {frames}"
    return {
        "ratios": ratios,
        "issue": {"support_drag": text},
        "markdown": report.markdown(command),
    }


def run_slices(quick: bool) -> dict[str, Any]:
    """``bench slices`` (with ``quick``: 256² only, 3 rounds)."""
    from voxwarp.bench.slices import bench_slices

    sizes, rounds = ((256,), 3) if quick else ((512, 256), 5)
    report = bench_slices(sizes=sizes, rounds=rounds, log=_log)
    ratios: dict[str, Any] = {
        f"{r.volume} {r.deformation} {r.size}² slice / 3D": round(r.slice_ratio, 4)
        for r in report.rows
    }
    for r in report.rows:
        ratios[f"{r.volume} {r.deformation} {r.size}² slab / slice"] = round(r.slab_ratio, 2)
    for d in report.drags:
        ratios[f"{d.volume} {d.size}² drag step + 3 slices / 3D"] = round(
            d.drag_slices_ms / d.frame_ms, 3
        )
    command = f"python -m benchmarks slices --sizes {','.join(map(str, sizes))} --rounds {rounds}"
    return {"ratios": ratios, "issue": {}, "markdown": report.markdown(command)}


def run_detj(quick: bool) -> dict[str, Any]:
    """``bench detj`` (with ``quick``: 256², 3 rounds): the det J overlay's cost."""
    from voxwarp.bench.detj import bench_detj

    sizes, rounds = ((256,), 3) if quick else ((512,), 5)
    report = bench_detj(sizes=sizes, rounds=rounds, log=_log)
    ratios: dict[str, Any] = {
        f"{r.volume} {r.deformation} {r.size}² {r.view} det J / without": round(r.ratio, 3)
        for r in report.rows
    }
    command = f"python -m benchmarks detj --sizes {','.join(map(str, sizes))} --rounds {rounds}"
    return {"ratios": ratios, "issue": {}, "markdown": report.markdown(command)}


def run_costs_table(quick: bool) -> dict[str, Any]:
    """``costs`` on its default volumes, the checkout alone (``--before none``; 3 repeats,
    with ``quick`` its own quick mode): the medians of every line."""
    from benchmarks.costs import DEFAULT_VOLUMES, run_costs
    from benchmarks.costs_table import markdown

    command = "python -m benchmarks costs --before none " + ("--quick" if quick else "--repeats 3")
    run = run_costs(DEFAULT_VOLUMES, repeats=1 if quick else 3, quick=quick, command=command)
    ratios = {
        f"{row['line']} {row['volume'] or ''}".strip(): row["results"]["after"]["median"]
        for row in run["rows"]
    }
    return {"ratios": ratios, "issue": {}, "markdown": markdown(run)}


#: benchmark name -> runner(quick) -> {"ratios", "issue", "markdown"}
RUNNERS: dict[str, Callable[[bool], dict[str, Any]]] = {
    "startup": run_startup,
    "render": run_render,
    "scale": run_scale,
    "massspring": run_massspring,
    "chainmail": run_chainmail,
    "wires": run_wires,
    "wire-tables": run_wire_tables,
    "wire-ends": run_wire_ends,
    "lattice": run_lattice,
    "interactive": run_interactive,
    "fields": run_fields,
    "segments": run_segments,
    "support": run_support,
    "slices": run_slices,
    "detj": run_detj,
    "costs": run_costs_table,
}


# ---------------------------------------------------------------------- running
def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}".strip()


def run_in_process(name: str, quick: bool) -> Record:
    """Run benchmark ``name`` here; an exception makes a failed record."""
    t = time.perf_counter()
    try:
        out = RUNNERS[name](quick)
    except Exception as exc:  # a failing benchmark is reported, not fatal
        return Record(name, "failed", time.perf_counter() - t, error=_one_line(exc))
    return Record(
        name,
        "ok",
        time.perf_counter() - t,
        ratios=out.get("ratios", {}),
        issue=out.get("issue", {}),
        markdown=out.get("markdown", ""),
    )


def run_subprocess(name: str, quick: bool, timeout_s: float | None = None) -> Record:
    """Run benchmark ``name`` in a child interpreter (see the module docstring)."""
    timeout = timeout_s or TIMEOUT_S[0 if quick else 1]
    t = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "record.json"
        cmd = [sys.executable, "-m", "benchmarks.all", "--child", name, "--out", str(out)]
        if quick:
            cmd.append("--quick")
        try:
            res = subprocess.run(
                cmd, capture_output=True, text=True, timeout=timeout, env=child_env()
            )
        except subprocess.TimeoutExpired:
            return Record(
                name, "failed", time.perf_counter() - t, error=f"timed out after {timeout:.0f} s"
            )
        seconds = time.perf_counter() - t
        if res.returncode != 0 or not out.exists():
            lines = [ln for ln in res.stderr.strip().splitlines() if ln.strip()]
            why = lines[-1] if lines else f"exit status {res.returncode}"
            return Record(name, "failed", seconds, error=why.strip()[:300])
        data = json.loads(out.read_text())
    data["seconds"] = seconds
    return Record(**data)


def bench_all(
    names: Sequence[str] = BENCHMARKS,
    *,
    quick: bool = False,
    in_process: bool = False,
    log: Callable[[str], Any] = _log,
) -> tuple[dict[str, Any], list[Record]]:
    """The hardware and one record per benchmark of ``names``, run in order."""
    from benchmarks.hardware import hardware_lines, probe_hardware

    hw = probe_hardware()
    for line in hardware_lines(hw):
        log(line)
    records = []
    for name in names:
        log(f"== {name}{' (quick)' if quick else ''}")
        rec = run_in_process(name, quick) if in_process else run_subprocess(name, quick)
        status = rec.status if rec.status == "ok" else f"FAILED: {rec.error}"
        log(f"== {name}: {status} ({rec.seconds:.0f} s)")
        records.append(rec)
    return hw, records


# ---------------------------------------------------------------------- outputs
def to_json(hw: dict[str, Any], records: list[Record], wall_s: float, quick: bool) -> str:
    """The machine-readable report: hardware, wall time and every record."""
    return (
        json.dumps(
            {
                "hardware": hw,
                "quick": quick,
                "wall_s": round(wall_s, 1),
                "benchmarks": [asdict(r) for r in records],
            },
            indent=2,
            default=str,
        )
        + "\n"
    )


def to_markdown(
    hw: dict[str, Any], records: list[Record], wall_s: float, quick: bool, command: str
) -> str:
    """The hardware, one table of issue 19's rows and the benchmarks' status."""
    from benchmarks.hardware import hardware_lines

    found: dict[str, tuple[str, str]] = {}
    for rec in records:
        for key, text in rec.issue.items():
            found.setdefault(key, (text, rec.name))
    failed = {r.name: r.error for r in records if r.status != "ok"}
    lines = [
        f"Command: `{command}` — {len(records) - len(failed)} of {len(records)} benchmarks ran,"
        f" wall time {wall_s:.0f} s{' (quick options)' if quick else ''}",
        "",
        *(f"* {line}" for line in hardware_lines(hw)),
        "",
        "| what | this run | target | benchmark |",
        "|---|---|---|---|",
    ]
    for key, what, target in ISSUE_ROWS:
        text, source = found.get(key, ("not measured by bench all", "—"))
        lines.append(f"| {what} | {text} | {target} | {source} |")
    lines.append("")
    for rec in records:
        state = "ok" if rec.status == "ok" else f"**failed**: {rec.error}"
        lines.append(f"* `{rec.name}`: {state} ({rec.seconds:.0f} s)")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------- command line
def _names_arg(text: str) -> tuple[str, ...]:
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    bad = [n for n in names if n not in BENCHMARKS]
    if not names or bad:
        raise argparse.ArgumentTypeError(
            f"unknown benchmark {', '.join(bad) if bad else repr(text)};"
            f" choose from {','.join(BENCHMARKS)}"
        )
    return names


def add_bench_all_parser(bsub: Any) -> None:
    """Add ``all`` to the ``bench`` sub-commands."""
    p = add_bench_parser(
        bsub,
        "all",
        "every benchmark in one command: hardware, JSON and one markdown table",
        __doc__,
    )
    p.add_argument("--quick", action="store_true", help="small options: a few minutes in all")
    p.add_argument("--json", metavar="FILE", help="write every record as JSON")
    p.add_argument("--markdown", metavar="FILE", help="write the table to FILE")
    p.add_argument(
        "--only",
        type=_names_arg,
        metavar="NAME,...",
        help=f"run only these ({','.join(BENCHMARKS)})",
    )
    p.add_argument(
        "--in-process",
        action="store_true",
        help="run the benchmarks in this process (default: one subprocess each)",
    )
    p.set_defaults(func=cmd_bench_all)


def cmd_bench_all(args: argparse.Namespace) -> int:
    """``python -m benchmarks all``: see the module docstring."""
    from voxwarp.core.files import atomic_write_text

    t = time.perf_counter()
    hw, records = bench_all(args.only or BENCHMARKS, quick=args.quick, in_process=args.in_process)
    wall = time.perf_counter() - t
    argv = sys.argv[2:] if sys.argv[1:2] == ["all"] else []
    text = to_markdown(hw, records, wall, args.quick, " ".join(["python -m benchmarks all", *argv]))
    print(text)
    if args.json:
        atomic_write_text(Path(args.json), to_json(hw, records, wall, args.quick))
    if args.markdown:
        atomic_write_text(Path(args.markdown), text)
    failed = sum(r.status != "ok" for r in records)
    if failed:
        _log(f"voxwarp: {failed} of {len(records)} benchmarks failed (see the table)")
    return 1 if failed == len(records) else 0


def _child(argv: Sequence[str]) -> int:
    """``python -m benchmarks.all --child NAME --out FILE [--quick]``: run one benchmark
    and write its record (an exception exits nonzero with its one line on stderr)."""
    from voxwarp.core.files import atomic_write_text

    p = argparse.ArgumentParser(prog="benchmarks.all")
    p.add_argument("--child", required=True, choices=BENCHMARKS)
    p.add_argument("--out", required=True)
    p.add_argument("--quick", action="store_true")
    args = p.parse_args(argv)
    t = time.perf_counter()
    try:
        out = RUNNERS[args.child](args.quick)
    except Exception as exc:
        print(_one_line(exc), file=sys.stderr)
        return 1
    rec = Record(args.child, "ok", time.perf_counter() - t, **out)
    atomic_write_text(Path(args.out), json.dumps(asdict(rec), default=str))
    return 0


if __name__ == "__main__":
    sys.exit(_child(sys.argv[1:]))
