"""``python -m benchmarks fields``: rendering through imported displacement fields.

A smooth random displacement field (a few mm; a grid slightly larger than the volume,
rotated 5° about z) on ``n``³ nodes (default 64³ and 128³) is imported as a
:class:`~voxwarp.deform.fields.displacement.DisplacementFieldWarp` over the benchmark
volume (the bundled CT upsampled to 256³, as ``python -m benchmarks render``) and timed in
three parts, in one process:

* **frames**: the warped frame (dvr and mip, 512x512, deformed-space skip maps built
  in the warm-up) against the undeformed frame of the same scene and camera, the two
  timed alternately (median of ``frames`` frames each after warm-up, each bound by
  ``ctx.finish()``); plus the first frame after importing the field (texture upload,
  deformed-space skip maps and the draw; shaders already compiled);
* **resample instead** (3D Slicer's way, ``SimpleITK``): the whole volume resampled
  through an ITK ``DisplacementFieldTransform`` of the same field
  (:func:`voxwarp.io.itk.resample`, linear) and the first (undeformed) frame of the
  result, against voxwarp's warped frame; extra memory computed from array sizes (the
  SimpleITK field image, float64 LPS vectors, and the float32 resampled volume) next to
  the growth of the process' resident set across the step (``/proc/self/statm``, with
  the transform and the result still held; transient peaks are not seen) and
  voxwarp's field texture (RGBA16F);
* **export**: the pull-back field of the warp chain sampled on the volume's grid
  (:func:`~voxwarp.deform.fields.displacement.sample_chain_field`) and written as
  ``.nii.gz`` and ``.nrrd`` (:func:`voxwarp.io.fields.save_displacement_field`).

Ratios are against the undeformed frame (frames) or voxwarp's warped frame (resample)
measured in the same run: these machines are shared and noisy.
"""

from __future__ import annotations

import argparse
import math
import resource
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.shared import int_list
from voxwarp.bench.command import add_bench_parser
from voxwarp.bench.render import bench_camera, benchmark_volume
from voxwarp.core.checks import image_size, positive_int
from voxwarp.core.timing import load_average
from voxwarp.core.volume import Volume
from voxwarp.deform.fields.displacement import DisplacementFieldWarp, sample_chain_field
from voxwarp.deform.warp import chain_apply
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.scene import Scene

MIB = float(1 << 20)


@dataclass
class FrameRow:
    """Frame times (ms) of one scene in one mode."""

    name: str
    mode: str
    median_ms: float
    min_ms: float
    first_ms: float = 0.0
    reference_ms: float = 0.0


@dataclass
class ResampleRow:
    """The resample-then-render alternative for one field (dvr)."""

    field: str
    resample_s: float
    first_frame_ms: float
    extra_mib: float
    rss_growth_mib: float
    texture_mib: float
    note: str = ""

    @property
    def total_ms(self) -> float:
        """Resampling plus the first frame of the result (ms)."""
        return self.resample_s * 1000.0 + self.first_frame_ms


@dataclass
class ExportRow:
    """One export step: seconds and the written file's size (0 for no file)."""

    step: str
    seconds: float
    mib: float = 0.0


@dataclass
class FieldsReport:
    """All parts of one ``python -m benchmarks fields`` run."""

    volume: str
    shape: tuple[int, int, int]
    size: tuple[int, int]
    frames: int
    gl_renderer: str
    max_displacement_mm: float
    frame_rows: list[FrameRow] = field(default_factory=list)
    resample_rows: list[ResampleRow] = field(default_factory=list)
    export_rows: list[ExportRow] = field(default_factory=list)
    load: tuple[float, float] = (-1.0, -1.0)

    def frame(self, name: str, mode: str) -> FrameRow | None:
        """The frame row ``name`` in ``mode`` (None if absent)."""
        return next((r for r in self.frame_rows if r.name == name and r.mode == mode), None)

    def ratio(self, name: str, mode: str) -> float | None:
        """``name``'s median frame / the undeformed median in ``mode`` (1 = free): the
        undeformed frames timed alternately with ``name``'s where there are some."""
        row, ref = self.frame(name, mode), self.frame("undeformed", mode)
        if row is None or ref is None:
            return None
        base = row.reference_ms if row.reference_ms > 0 else ref.median_ms
        return row.median_ms / base if base > 0 else None

    def resample_ratio(self, row: ResampleRow) -> float | None:
        """Resample + first frame / voxwarp's warped dvr frame through the same field."""
        ours = self.frame(row.field, "dvr")
        if ours is None or ours.median_ms <= 0 or row.resample_s <= 0:
            return None
        return row.total_ms / ours.median_ms

    def markdown(self, command: str) -> str:
        """The three tables of the run, headed by the command that produced it."""
        lines = [
            f"Command: `{command}`",
            "",
            f"Volume: {self.volume} {'x'.join(map(str, self.shape))}, image"
            f" {self.size[0]}x{self.size[1]}, median of {self.frames} frames after warm-up;"
            f" smooth random fields, largest displacement {self.max_displacement_mm:.1f} mm;"
            f" GL: {self.gl_renderer}; load average {self.load[0]:.1f} before,"
            f" {self.load[1]:.1f} after",
            "",
            "| render | mode | median ms | min ms | undeformed, alternating ms |"
            " vs undeformed | first frame after import ms |",
            "|---|---|---:|---:|---:|---:|---:|",
        ]
        for r in self.frame_rows:
            ratio = self.ratio(r.name, r.mode)
            first = f"{r.first_ms:.0f}" if r.first_ms > 0 else "—"
            ref = f"{r.reference_ms:.1f}" if r.reference_ms > 0 else "—"
            lines.append(
                f"| {r.name} | {r.mode} | {r.median_ms:.1f} | {r.min_ms:.1f} | {ref} |"
                f" {_x(ratio)} | {first} |"
            )
        lines += [
            "",
            "| resample instead (SimpleITK, linear) | resample s | first frame ms |"
            " total vs voxwarp warped dvr frame | extra memory MiB (sizes) |"
            " RSS growth MiB | voxwarp field texture MiB | note |",
            "|---|---:|---:|---:|---:|---:|---:|---|",
        ]
        for r in self.resample_rows:
            lines.append(
                f"| {r.field} | {r.resample_s:.2f} | {r.first_frame_ms:.0f} |"
                f" {_x(self.resample_ratio(r))} | {r.extra_mib:.0f} | {r.rss_growth_mib:.0f} |"
                f" {r.texture_mib:.1f} | {r.note} |"
            )
        lines += ["", "| export | s | file MiB |", "|---|---:|---:|"]
        for e in self.export_rows:
            mib = f"{e.mib:.1f}" if e.mib > 0 else "—"
            lines.append(f"| {e.step} | {e.seconds:.2f} | {mib} |")
        return "\n".join(lines) + "\n"


def _x(ratio: float | None) -> str:
    return f"{ratio:.2f}x" if ratio is not None and math.isfinite(ratio) else "—"


def smooth_field(
    volume: Volume, nodes: int, *, amplitude_mm: float = 3.0, angle_deg: float = 5.0, seed: int = 0
) -> DisplacementFieldWarp:
    """A smooth random field of ``nodes``³ nodes covering ``volume`` (10% margin, the grid
    rotated ``angle_deg`` about z), largest displacement ``amplitude_mm``."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, nodes)
    u = np.zeros((nodes, nodes, nodes, 3), dtype=np.float32)
    for c in range(3):
        for _ in range(3):  # separable low-frequency modes: 1-2 periods over the grid
            f = rng.uniform(1.0, 2.0, 3) * 2 * np.pi
            ph = rng.uniform(0, 2 * np.pi, 3)
            sx, sy, sz = (np.sin(f[a] * t + ph[a]).astype(np.float32) for a in range(3))
            u[..., c] += rng.normal() * sx[:, None, None] * sy[None, :, None] * sz[None, None, :]
    u *= amplitude_mm / max(float(np.sqrt((u**2).sum(-1)).max()), 1e-12)
    lo, hi = volume.bounds
    extent = (np.asarray(hi) - np.asarray(lo)) * 1.1
    a = math.radians(angle_deg)
    rot = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    affine = np.eye(4)
    affine[:3, :3] = rot @ np.diag(extent / (nodes - 1))
    affine[:3, 3] = (np.asarray(lo) + np.asarray(hi)) / 2 - rot @ (extent / 2)
    return DisplacementFieldWarp(u, affine)


def quick_volume() -> Volume:
    """A 32³ synthetic volume (a bright ball in a dimmer shell) for ``--quick``."""
    g = np.linspace(-1.0, 1.0, 32)
    r = np.sqrt(g[:, None, None] ** 2 + g[None, :, None] ** 2 + g[None, None, :] ** 2)
    data = np.where(r < 0.5, 250, np.where(r < 0.8, 120, 0)).astype(np.uint8)
    return Volume(data, (2.0, 2.0, 2.0), name="synthetic ball")


def _time_frames(r: OffscreenRenderer, scene: Scene, frames: int, warmup: int) -> list[float]:
    return r.time_frames(scene, frames=frames, warmup=warmup)


def bench_fields(
    volume: Volume | None = None,
    *,
    nodes: Sequence[int] = (64, 128),
    size: tuple[int, int] = (512, 512),
    frames: int = 10,
    warmup: int = 2,
    modes: tuple[str, ...] = ("dvr", "mip"),
    resample: bool = True,
    export: bool = True,
    zero: bool = False,
    log: Callable[[str], Any] | None = print,
) -> FieldsReport:
    """Time rendering through imported fields, the resample alternative and the export
    (see the module docstring). ``volume`` defaults to the 256³ benchmark CT."""
    say = log or (lambda s: None)
    load_before = load_average()
    vol = benchmark_volume(volume)
    from voxwarp.io.samples import suggested_transfer_function

    tf = suggested_transfer_function("stent") if volume is None else "grayscale"
    cam = bench_camera(vol)
    fields = {f"field {n}³": smooth_field(vol, n) for n in nodes}
    warps = dict(fields)
    if zero:  # the same grids holding zeros: the cost of the field's texture alone
        for n, w in zip(nodes, fields.values(), strict=True):
            warps[f"zero field {n}³"] = DisplacementFieldWarp(
                np.zeros_like(w.displacements), w.affine
            )
    base = {m: Scene(vol, mode=m, transfer_function=tf, camera=cam) for m in modes}
    with OffscreenRenderer(*size) as r:
        report = FieldsReport(
            volume=vol.name,
            shape=vol.shape,
            size=size,
            frames=frames,
            gl_renderer=str(r.ctx.info.get("GL_RENDERER", "?")),
            max_displacement_mm=max(w.max_displacement() for w in fields.values()),
        )
        r.renderer.warped_skip_maps = "always"  # built in the first (warm-up) frame
        keep: list[DisplacementFieldWarp] = []
        for scene in base.values():
            report.frame_rows.extend(_frame_rows(r, scene, warps, frames, warmup, keep, say))
        if resample:
            for name, w in fields.items():
                report.resample_rows.append(_resample_row(r, base, vol, name, w))
                say(f"resample through {name}: {report.resample_rows[-1].resample_s:.2f} s")
    if export:
        report.export_rows.extend(_export_rows(vol, list(fields.values())[-1], say))
    report.load = (load_before, load_average())
    return report


def _frame_rows(
    r: OffscreenRenderer,
    scene: Scene,
    warps: dict[str, DisplacementFieldWarp],
    frames: int,
    warmup: int,
    keep: list[DisplacementFieldWarp],
    say: Callable[[str], Any],
) -> list[FrameRow]:
    """The undeformed frame of ``scene`` and the frame through each field; each field's
    frames alternate with undeformed ones (its ``reference_ms``), so that a change of
    the machine's load hits both sides of the ratio."""
    mode = scene.mode
    _time_frames(r, scene, 0, warmup)
    rows, plain = [], []
    for name, w in warps.items():
        _time_frames(r, scene.copy(warps=[w]), 1, 0)  # compiles the shaders
        # a fresh warp object: its texture upload and skip maps count as "first"
        fresh = DisplacementFieldWarp(w.displacements, w.affine)
        keep.append(fresh)  # alive: the skip-map cache keys warps by id()
        warped = scene.copy(warps=[fresh])
        first = _time_frames(r, warped, 1, 0)[0]
        _time_frames(r, warped, 0, max(0, warmup - 1))
        ours, ref = [], []
        for _ in range(frames):
            ref += _time_frames(r, scene, 1, 0)
            ours += _time_frames(r, warped, 1, 0)
        plain += ref
        row = FrameRow(name, mode, statistics.median(ours), min(ours), first)
        row.reference_ms = statistics.median(ref)
        rows.append(row)
        say(
            f"{name} {mode}: {row.median_ms:.1f} ms vs undeformed {row.reference_ms:.1f} ms"
            f" (first frame {first:.0f} ms)"
        )
    if not plain:
        plain = _time_frames(r, scene, frames, 0)
    say(f"undeformed {mode}: {statistics.median(plain):.1f} ms")
    return [FrameRow("undeformed", mode, statistics.median(plain), min(plain)), *rows]


def _texture_mib(w: DisplacementFieldWarp) -> float:
    return math.prod(w.shape) * 4 * 2 / MIB  # RGBA16F


def _rss_mib() -> float:
    """The resident set size now (Linux ``/proc/self/statm``), else the peak so far."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
        return pages * resource.getpagesize() / MIB
    except (OSError, ValueError, IndexError):  # not Linux
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _resample_row(
    r: OffscreenRenderer,
    base: dict[str, Scene],
    vol: Volume,
    name: str,
    w: DisplacementFieldWarp,
) -> ResampleRow:
    """SimpleITK resampling of ``vol`` through ``w`` and the first dvr frame of the result."""
    from voxwarp.errors import VoxwarpError

    try:
        from voxwarp.io.fields import field_image
        from voxwarp.io.itk import resample, sitk_module

        sitk = sitk_module("python -m benchmarks fields")
    except VoxwarpError as exc:
        return ResampleRow(name, 0.0, 0.0, 0.0, 0.0, _texture_mib(w), f"skipped: {exc}")
    field_bytes = math.prod(w.shape) * 3 * 8  # float64 LPS vectors
    volume_bytes = math.prod(vol.shape) * 4  # float32 output of the resampling
    rss0 = _rss_mib()
    start = time.perf_counter()
    transform = sitk.DisplacementFieldTransform(field_image(w))
    out = resample(vol, transform)
    resample_s = time.perf_counter() - start
    rss_growth = _rss_mib() - rss0
    scene = base.get("dvr", next(iter(base.values())))
    first = _time_frames(r, scene.copy(volume=out, warps=[]), 1, 0)[0]
    return ResampleRow(
        name,
        resample_s,
        first,
        (field_bytes + volume_bytes) / MIB,
        rss_growth,
        _texture_mib(w),
        "float32 result, as voxwarp.io.itk.resample returns it",
    )


def _export_rows(
    vol: Volume, w: DisplacementFieldWarp, say: Callable[[str], Any]
) -> list[ExportRow]:
    """Sample the chain ``[w]`` on ``vol``'s grid and write it as .nii.gz and .nrrd."""
    from voxwarp.io.fields import save_displacement_field

    rows = []
    start = time.perf_counter()
    u = sample_chain_field(lambda p: chain_apply([w], p), vol.affine, vol.shape)
    grid = "x".join(map(str, vol.shape))
    rows.append(ExportRow(f"sample the chain on the {grid} grid", time.perf_counter() - start))
    sampled = DisplacementFieldWarp(u, vol.affine)
    with tempfile.TemporaryDirectory(prefix="voxwarp-bench-fields-") as tmp:
        for suffix in (".nii.gz", ".nrrd"):
            path = Path(tmp) / f"field{suffix}"
            start = time.perf_counter()
            save_displacement_field(sampled, path)
            seconds = time.perf_counter() - start
            rows.append(ExportRow(f"write {suffix}", seconds, path.stat().st_size / MIB))
    for row in rows:
        say(f"export: {row.step}: {row.seconds:.2f} s")
    return rows


#: ``--nodes``: fields of N³ nodes
_nodes = int_list(2, 256, "node count", "64,128")


def cmd_bench_fields(args: argparse.Namespace) -> int:
    """``python -m benchmarks fields``."""
    from voxwarp.core.files import atomic_write_text

    quick = bool(args.quick)
    report = bench_fields(
        quick_volume() if quick else None,
        nodes=(4, 8) if quick else args.nodes,
        size=(64, 64) if quick else args.size,
        frames=1 if quick else args.frames,
        warmup=1 if quick else args.warmup,
        resample=not args.no_resample,
        zero=bool(args.zero),
        log=lambda s: print(s, file=sys.stderr),
    )
    argv = sys.argv[2:] if sys.argv[1:2] == ["fields"] else []
    text = report.markdown("python -m benchmarks fields" + "".join(f" {a}" for a in argv))
    print(text)
    for mode in ("dvr", "mip"):
        for row in report.frame_rows:
            ratio = report.ratio(row.name, mode) if row.mode == mode else None
            if row.name != "undeformed" and ratio is not None:
                print(f"{row.name} {mode}: {ratio:.2f}x the undeformed frame")
    if args.markdown:
        atomic_write_text(Path(args.markdown), text)
    return 0


def add_bench_fields_parser(bsub: Any) -> None:
    """Add ``fields`` to the ``bench`` sub-commands."""
    p = add_bench_parser(
        bsub,
        "fields",
        "rendering through imported displacement fields vs resampling; field export",
        __doc__,
    )
    p.add_argument("--size", type=image_size, default=(512, 512), help="image WxH")
    p.add_argument("--frames", type=positive_int, default=10, help="timed frames per case")
    p.add_argument("--warmup", type=positive_int, default=2, help="frames before timing")
    p.add_argument(
        "--nodes",
        type=_nodes,
        default=(64, 128),
        metavar="N,N,...",
        help="fields of N³ nodes (default 64,128)",
    )
    p.add_argument("--no-resample", action="store_true", help="skip the SimpleITK reference")
    p.add_argument(
        "--zero",
        action="store_true",
        help="also time fields of the same grids holding zeros (the texture's cost alone)",
    )
    p.add_argument(
        "--quick", action="store_true", help="tiny sizes (a 32³ volume, 64x64, 4³ and 8³ fields)"
    )
    p.add_argument("--markdown", metavar="FILE", help="also write the tables to FILE")
    p.set_defaults(func=cmd_bench_fields)
