"""``python -m benchmarks wire-tables``: the wire paper's Tables 1-3, measured its way.

* **Table 1** (ray samples that need no mapping): the paper counts only the samples
  inside its attribute field. voxwarp's field covers the whole volume, so the share
  over every sample of the ray box (today's statistic of ``python -m benchmarks wires``) is
  not comparable. This counts both: over the ray box, and over the samples inside the
  wires' regions of influence only (:func:`benchmarks.wires.influence_region`),
  with the dataset's own (bending) wires.
* **Tables 2 and 3** (standard render vs the same render through an identity
  deformation, section 9): each wire's modified curve is set to its base curve, no
  twist, no scale, so every sample is classified and mapped as in a real deformation
  but the image stays the same (the changed-pixel share checks that). Reported as
  ratios, as the paper's absolute times (a 2006 software raycaster) cannot compare:
  render ratio = identity render / standard render (paper: Table 3 render / Table 2),
  total ratio = (preprocessing + identity render) / standard render (Table 3 total /
  Table 2). Preprocessing is the attribute field build (lookup tables, masks, seeds,
  propagation, flags).

Warm-up is excluded: one untimed build before the timed ones (OpenCL kernels, numba
code and buffers of the grid size), two untimed frames of every scene before the timed
ones (program compilation, volume upload, skip maps); standard and identity frames are
interleaved and medians taken.

Datasets: the fish with ``sample_volumes/fish_spine_wires.json``, the tubes with
``tubes_twist_wires.json``, and the bundled real CT (``stent``: an aorta with a stent
graft) with a wire laid along the object's principal axis (:func:`axis_wire`).
"""

from __future__ import annotations

import argparse
import statistics
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from benchmarks.wires import (
    FISH_SHAPE,
    FISH_WIRES,
    TUBES_WIRES,
    SampleStats,
    framed_camera,
    influence_region,
    load_wires,
    ray_sample_stats,
)
from voxwarp.bench.command import add_bench_parser, emit_report
from voxwarp.core.checks import image_size, positive_int
from voxwarp.core.volume import Volume
from voxwarp.teaching.papers import WIRE_TABLE1, WIRE_TIMINGS, fmt_ratio

#: image size of the paper's Tables 2-3
DEFAULT_SIZE: tuple[int, int] = (512, 256)
#: datasets of the run, in order
DATASETS: tuple[str, ...] = ("fish", "tubes", "stent")
#: field scale of every dataset (1:8 in voxels, the wire files' scale)
FIELD_SCALE = 2
#: rays through every STATS_SUBSAMPLE-th pixel for Table 1
STATS_SUBSAMPLE = 4


@dataclass
class TablesRow:
    """One dataset: Table 1 (its bending wires) and Tables 2-3 (identity wires)."""

    dataset: str
    volume_shape: tuple[int, int, int]
    field_shape: tuple[int, int, int]
    samples: SampleStats
    build_s: float
    standard_ms: float
    identity_ms: float
    frames: int
    changed_pixels: float

    @property
    def render_ratio(self) -> float:
        """Identity render / standard render (the paper's Table 3 render / Table 2)."""
        return self.identity_ms / self.standard_ms

    @property
    def total_ratio(self) -> float:
        """(Preprocessing + identity render) / standard render (Table 3 total / Table 2)."""
        return (self.build_s * 1000.0 + self.identity_ms) / self.standard_ms

    def as_dict(self) -> dict[str, Any]:
        """Plain dict (JSON-ready), ratios included."""
        s = self.samples
        return {
            "dataset": self.dataset,
            "volume_shape": list(self.volume_shape),
            "field_shape": list(self.field_shape),
            "samples": s.samples,
            "percent_ignored": s.percent_ignored,
            "region_samples": s.region_samples,
            "percent_ignored_in_region": s.percent_ignored_in_region,
            "build_s": self.build_s,
            "standard_ms": self.standard_ms,
            "identity_ms": self.identity_ms,
            "frames": self.frames,
            "render_ratio": self.render_ratio,
            "total_ratio": self.total_ratio,
            "changed_pixels": self.changed_pixels,
        }


def identity_wires(wires: Sequence[Any]) -> list[Any]:
    """Copies of ``wires`` whose modified curve is the base curve, without twist or
    scale: the paper's identity deformation of Tables 2-3."""
    from voxwarp.deform.wires.field import Wire

    out = []
    for w in wires:
        d = w.to_dict()
        d.update(modified=d["base"], twist=[[0.0, 0.0]], scale=[[0.0, 1.0]])
        out.append(Wire.from_dict(d))
    return out


def axis_wire(volume: Volume, threshold: float, bend: float = 0.15) -> Any:
    """A Catmull-Rom wire through the voxels above ``threshold``: along their principal
    axis, from 2 % before the first to 2 % past the last of them (ends outside the
    object), through the centroid of each quarter; radius = the 99th percentile of
    their distances from the axis; the modified wire bends the second half sideways by
    ``bend`` times the length. β is ``(threshold, max)``."""
    from voxwarp.deform.wires.field import Wire

    idx = np.argwhere(volume.data > threshold)
    if len(idx) < 8:
        raise ValueError(f"fewer than 8 voxels above {threshold:g}: no object to lay a wire")
    pts = volume.index_to_world(idx.astype(np.float64))
    centre = pts.mean(0)
    _, _, vt = np.linalg.svd(pts - centre, full_matrices=False)
    axis = vt[0]
    s = (pts - centre) @ axis
    length = float(s.max() - s.min())
    stops = np.linspace(s.min() - 0.02 * length, s.max() + 0.02 * length, 5)
    base = []
    for k, a in enumerate(stops):
        near = np.abs(s - a) < length / 8
        c = pts[near].mean(0) if k not in (0, 4) and near.any() else centre
        base.append(c + (a - (c - centre) @ axis) * axis)
    base = np.asarray(base)
    radial = np.linalg.norm((pts - centre) - np.outer(s, axis), axis=1)
    side = vt[1]
    t = np.linspace(0.0, 1.0, len(base))
    modified = base + np.outer(bend * length * np.clip(2 * t - 1, 0, None) ** 2, side)
    hi = float(volume.data.max())
    return Wire(
        base,
        modified,
        radius=float(np.percentile(radial, 99)) + 2.0 * float(max(volume.spacing)),
        beta=(threshold, hi),
        name="principal axis",
        ends="rigid",  # the paper's sweep
        sides="rigid",
    )


def dataset(name: str) -> tuple[Volume, list[Any], str]:
    """The volume, its bending wires and transfer function of one of :data:`DATASETS`."""
    from voxwarp.io.samples import load_sample, suggested_transfer_function

    if name == "fish":
        wires, _ = load_wires(FISH_WIRES)
        return load_sample("fish", shape=FISH_SHAPE), wires, suggested_transfer_function("fish")
    if name == "tubes":
        wires, _ = load_wires(TUBES_WIRES)
        return load_sample("tubes"), wires, suggested_transfer_function("tubes")
    if name == "stent":
        vol = load_sample("stent")
        lo, hi = float(vol.data.min()), float(vol.data.max())
        wire = axis_wire(vol, lo + 0.5 * (hi - lo))
        return vol, [wire], suggested_transfer_function("stent")
    raise ValueError(f"unknown dataset {name!r}; datasets: {', '.join(DATASETS)}")


def _median_build(wd: Any, repeats: int) -> float:
    wd.build()  # untimed: kernels, code and buffers of this grid size
    return statistics.median(wd.build().timings["total"] for _ in range(max(1, repeats)))


def _changed(a: np.ndarray, b: np.ndarray) -> float:
    diff = np.abs(a.astype(np.int16) - b.astype(np.int16)).max(axis=-1) > 2
    return 100.0 * float(diff.mean())


def measure(
    name: str,
    size: tuple[int, int] = DEFAULT_SIZE,
    frames: int = 5,
    repeats: int = 3,
    ctx: Any = None,
    log: Callable[[str], None] = print,
) -> TablesRow:
    """Tables 1-3 for one dataset (see the module docstring)."""
    from voxwarp.deform.wires.field import WireDeformer
    from voxwarp.render.offscreen import OffscreenRenderer
    from voxwarp.scene import Scene

    vol, wires, tf = dataset(name)
    cam = framed_camera(vol, wires, size)
    bent = WireDeformer(vol, wires, field_scale=FIELD_SCALE)
    bent.build()
    warp = bent.warp()  # classified on the CPU only: no GPU textures to release
    bent_scene = Scene(vol, mode="dvr", transfer_function=tf, camera=cam, warps=[warp])
    stats = ray_sample_stats(
        bent_scene, cam, size, warp, STATS_SUBSAMPLE, region=influence_region(wires)
    )
    wd = WireDeformer(vol, identity_wires(wires), field_scale=FIELD_SCALE)
    build_s = _median_build(wd, repeats)
    standard = Scene(vol, mode="dvr", transfer_function=tf, camera=cam, jitter=False)
    identity = standard.copy(warps=[wd.warp()])
    with OffscreenRenderer(*size, ctx=ctx) as r:
        for scene in (standard, identity):
            r.time_frames(scene, frames=0, warmup=2)
        times: dict[str, list[float]] = {"standard": [], "identity": []}
        for _ in range(max(1, frames)):
            times["standard"] += r.time_frames(standard, frames=1, warmup=0)
            times["identity"] += r.time_frames(identity, frames=1, warmup=0)
        changed = _changed(r.render(standard), r.render(identity))
        wd.warp().release()  # its textures live on the renderer's (maybe shared) context
    row = TablesRow(
        dataset=f"{name} {'x'.join(map(str, vol.shape))}",
        volume_shape=tuple(int(n) for n in vol.shape),  # type: ignore[arg-type]
        field_shape=tuple(int(n) for n in wd.field.shape),  # type: ignore[arg-type]
        samples=stats,
        build_s=build_s,
        standard_ms=statistics.median(times["standard"]),
        identity_ms=statistics.median(times["identity"]),
        frames=max(1, frames),
        changed_pixels=changed,
    )
    log(
        f"{name}: {row.samples.percent_ignored:.1f} % ignored over the ray box,"
        f" {row.samples.percent_ignored_in_region or 0:.1f} % in the regions; identity"
        f" render {fmt_ratio(row.render_ratio)}, with preprocessing {fmt_ratio(row.total_ratio)}"
    )
    return row


def bench_wire_tables(
    datasets: Sequence[str] = DATASETS,
    size: tuple[int, int] = DEFAULT_SIZE,
    frames: int = 5,
    repeats: int = 3,
    ctx: Any = None,
    log: Callable[[str], None] = print,
) -> list[TablesRow]:
    """:func:`measure` for each dataset."""
    return [measure(n, size, frames, repeats, ctx, log) for n in datasets]


def table1_markdown(rows: Sequence[TablesRow]) -> list[str]:
    """Table 1 beside the paper's, as markdown lines."""
    lines = [
        "| dataset | samples (ray box) | % ignored (ray box) | samples in the regions"
        " | % ignored in the regions (the paper's way) |",
        "|---|---:|---:|---:|---:|",
    ]
    for p in WIRE_TABLE1:
        lines.append(f"| paper (Table 1): {p.dataset} | — | — | {p.samples:,} | {p.percent:.1f} |")
    for r in rows:
        s = r.samples
        inside = s.percent_ignored_in_region
        lines.append(
            f"| {r.dataset} | {s.samples:,} | {s.percent_ignored:.1f} | {s.region_samples:,}"
            f" | {'—' if inside is None else f'{inside:.1f}'} |"
        )
    return [*lines, ""]


def tables23_markdown(rows: Sequence[TablesRow]) -> list[str]:
    """Tables 2-3 as ratios beside the paper's, as markdown lines."""
    lines = [
        "| dataset | standard ms | preprocessing s | identity render ms | render ratio"
        " | total ratio | pixels changed % |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for p in WIRE_TIMINGS:
        lines.append(
            f"| paper (Tables 2-3): {p.dataset} | {p.standard_s * 1000:.0f} |"
            f" {p.preprocessing_s:.2f} | {p.render_s * 1000:.0f} | {fmt_ratio(p.render_ratio)}"
            f" | {fmt_ratio(p.total_ratio)} | — |"
        )
    for r in rows:
        lines.append(
            f"| {r.dataset} | {r.standard_ms:.1f} | {r.build_s:.3f} | {r.identity_ms:.1f} |"
            f" {fmt_ratio(r.render_ratio)} | {fmt_ratio(r.total_ratio)} |"
            f" {r.changed_pixels:.2f} |"
        )
    return [*lines, ""]


def markdown(rows: Sequence[TablesRow], command: str) -> str:
    """The whole report."""
    return "\n".join(
        [
            f"Command: `{command}`",
            "",
            *table1_markdown(rows),
            *tables23_markdown(rows),
        ]
    )


def cmd_bench_wire_tables(args: argparse.Namespace) -> int:
    """``python -m benchmarks wire-tables``."""
    rows = bench_wire_tables(
        args.datasets or DATASETS,
        size=args.size,
        frames=args.frames,
        repeats=args.repeats,
        log=lambda s: print(s, file=sys.stderr),
    )
    text = markdown(rows, "python -m benchmarks wire-tables " + " ".join(sys.argv[2:]))
    return emit_report(text, args.markdown)


def add_bench_wire_tables_parser(bsub: Any) -> None:
    """Add ``wire-tables`` to the ``bench`` sub-commands."""
    p = add_bench_parser(
        bsub,
        "wire-tables",
        "the wire paper's Tables 1-3 measured its way (identity deformation)",
        __doc__,
    )
    p.add_argument(
        "--dataset",
        dest="datasets",
        action="append",
        choices=DATASETS,
        help="a dataset (repeat for several; default all)",
    )
    p.add_argument("--size", type=image_size, default=DEFAULT_SIZE, help="image WxH")
    p.add_argument("--frames", type=positive_int, default=5, help="timed frames of each")
    p.add_argument("--repeats", type=positive_int, default=3, help="timed field builds")
    p.add_argument("--markdown", metavar="FILE", help="also write the tables to FILE")
    p.set_defaults(func=cmd_bench_wire_tables)
