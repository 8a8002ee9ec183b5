"""``python -m benchmarks scale``: how the first frame, the steady frame and the memory of a new
volume grow with its voxels.

For synthetic uint8 volumes of N³ voxels (default 128³, 256³, 512³; ``--long`` adds a
512x512x1100 int16 CT-like phantom) it measures, through the public
:class:`~voxwarp.render.raycaster.Renderer` API on one headless context, at 512x512 in dvr:

* **first frame**: a new :class:`~voxwarp.core.volume.Volume` made from the array (the
  array itself exists already) to the first image read back; shader programs are compiled
  beforehand on a tiny volume so the frame holds no compilation;
* **second frame**: with the renderer's default ``cell_skip_maps`` "auto", a large
  volume's first frame skips by blocks and its second builds the cell maps (the report
  names the skipping of both);
* **phases** of another first frame (a new Volume of the same array), drawn into a
  16x16 image (same camera, so the draw itself costs little) step by step with the
  renderer's skipping settings: skipping off (upload with block min/max + a plain draw),
  block skipping on (transfer-function visibility of the 4³ blocks and their skip
  distances), cell skipping on with ``cell_skip_maps`` "always" (cell visibility and the
  octant distance maps); each phase is that first draw minus the faster of two repeated
  draws of the same setting. Block min/max alone is timed through
  :func:`voxwarp.render.skipping.maps.block_min_max`, which the upload calls;
* **steady frame**: median of the frames after the second;
* **memory beyond the array** during the first frame: the process' peak resident set
  (``VmHWM`` of ``/proc/self/status``, reset through ``/proc/self/clear_refs`` just before,
  minus ``VmRSS`` then; on llvmpipe textures live in process memory, so it includes them)
  and, in a third first frame, the peak of Python/numpy allocations (``tracemalloc``);
  **kept**: the resident set after the second frame (cell maps built) beyond that before
  the Volume was made;
* ``--sampling auto,slice_pairs`` measures every volume once per renderer ``sampling``
  (texture layout, :mod:`voxwarp.render.volume_texture`), interleaved in one process:
  the layout before (slice pairs, each voxel twice) beside the default.

Growth is each number over that of the smallest volume, beside the voxel ratio.
"""

from __future__ import annotations

import argparse
import gc
import math
import statistics
import sys
import time
import tracemalloc
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.bench.command import add_bench_parser

#: default cube edges, and those of ``--quick``
DEFAULT_SIZES: tuple[int, ...] = (128, 256, 512)
QUICK_SIZES: tuple[int, ...] = (128, 256)
#: the ``--long`` volume: a CT-like int16 phantom of this shape
LONG_SHAPE: tuple[int, int, int] = (512, 512, 1100)
IMAGE_SIZE: tuple[int, int] = (512, 512)
#: the image the phases are drawn into: small, so that a draw costs little beside them
PHASE_IMAGE: tuple[int, int] = (16, 16)
#: the phases of a first frame, in drawing order
PHASES: tuple[str, ...] = (
    "upload + block min/max",
    "block skipping (TF visibility, block distances)",
    "cell skipping (cell visibility, octant maps)",
)
BLOCK_MIN_MAX = "block min/max alone (CPU function)"


@dataclass
class ScaleRow:
    """One volume: times in ms, memory in MiB."""

    label: str
    shape: tuple[int, int, int]
    dtype: str
    nbytes: int
    first_ms: float
    steady_ms: float
    #: the second frame (where a large volume builds its cell maps; see skip_kind)
    second_ms: float = -1.0
    phases: dict[str, float] = field(default_factory=dict)
    peak_rss_mib: float = -1.0
    traced_mib: float = -1.0
    skip_kind: str = ""
    #: the texture layout the volume got (the renderer's sampling setting resolved)
    layout: str = ""
    #: resident set after the second frame beyond that before the Volume, MiB
    kept_mib: float = -1.0

    @property
    def voxels(self) -> int:
        """Voxels of the volume."""
        return int(math.prod(self.shape))


@dataclass
class ScaleReport:
    """All rows of one ``bench scale`` run and its setting."""

    size: tuple[int, int]
    frames: int
    gl_renderer: str
    rss_method: str
    rows: list[ScaleRow] = field(default_factory=list)
    load: tuple[float, float] = (-1.0, -1.0)

    def growth(self, row: ScaleRow, value: Callable[[ScaleRow], float]) -> float | None:
        """``value(row)`` over ``value`` of the first (smallest) row; None if unmeasured."""
        a, b = value(row), value(self.rows[0])
        if a is None or b is None or a <= 0 or b <= 0:
            return None
        return a / b

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the setting, each row and its growth ratios against the first."""
        rows = []
        for r in self.rows:
            d = asdict(r)
            d["voxels"] = r.voxels
            d["growth"] = {
                "voxels": r.voxels / self.rows[0].voxels,
                "first_frame": self.growth(r, lambda x: x.first_ms),
                "steady_frame": self.growth(r, lambda x: x.steady_ms),
                "peak_rss": self.growth(r, lambda x: x.peak_rss_mib),
            }
            rows.append(d)
        return {
            "size": list(self.size),
            "frames": self.frames,
            "gl_renderer": self.gl_renderer,
            "rss_method": self.rss_method,
            "load": list(self.load),
            "rows": rows,
        }

    def markdown(self, command: str) -> str:
        """Two tables (times and growth; phases), headed by the command."""
        first = self.rows[0]
        lines = [
            f"Command: `{command}`",
            "",
            f"Image {self.size[0]}x{self.size[1]}, dvr, sample distance 1 voxel; steady ="
            f" median of {self.frames} frames; GL: {self.gl_renderer}; memory beyond the"
            f" array: {self.rss_method}; tracemalloc peak of numpy/Python allocations;"
            f" 1-minute load average {self.load[0]:.2f} before, {self.load[1]:.2f} after."
            f" Growth = value / value of {first.label}.",
            "",
            "| volume | layout | MiB | first frame ms | second frame ms | steady frame ms |"
            " first / steady | skipping (first, then) | peak RSS beyond array MiB (x volume)"
            " | kept after cell maps MiB (x) | tracemalloc peak MiB |"
            " growth: voxels | first | steady | RSS |",
            "|---|---|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for r in self.rows:
            mib = r.nbytes / 2**20
            rss = (
                "—" if r.peak_rss_mib < 0 else f"{r.peak_rss_mib:.0f} ({r.peak_rss_mib / mib:.1f}x)"
            )
            traced = "—" if r.traced_mib < 0 else f"{r.traced_mib:.0f}"
            kept = "—" if r.kept_mib < 0 else f"{r.kept_mib:.0f} ({r.kept_mib / mib:.1f}x)"
            ratio = r.first_ms / r.steady_ms if r.steady_ms > 0 else float("nan")
            mib_text = f"{mib:.0f}" if mib >= 10 else f"{mib:.2g}"
            g = [
                r.voxels / first.voxels,
                self.growth(r, lambda x: x.first_ms),
                self.growth(r, lambda x: x.steady_ms),
                self.growth(r, lambda x: x.peak_rss_mib),
            ]
            gs = " | ".join("—" if v is None else f"{v:.1f}x" for v in g)
            lines.append(
                f"| {r.label} | {r.layout} | {mib_text} | {r.first_ms:.0f} | {r.second_ms:.0f} |"
                f" {r.steady_ms:.1f} | {ratio:.1f}x | {r.skip_kind} | {rss} | {kept} |"
                f" {traced} | {gs} |"
            )
        names = [*PHASES, BLOCK_MIN_MAX]
        lines += [
            "",
            "| volume | layout | " + " | ".join(f"{n} ms" for n in names) + " | steady draw ms |",
            "|---|---|" + "---:|" * (len(names) + 1),
        ]
        for r in self.rows:
            cells = [f"{r.phases[n]:.0f}" if n in r.phases else "—" for n in names]
            lines.append(f"| {r.label} | {r.layout} | {' | '.join(cells)} | {r.steady_ms:.1f} |")
        return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------- volumes
def synthetic_cube(n: int) -> np.ndarray:
    """An n³ uint8 volume (x, y, z), Fortran-ordered as :class:`~voxwarp.core.volume.Volume`
    keeps it (so making the Volume copies nothing): a ball of 200 in a shell of 80 with a
    dimmer core rod of 140, air (0) around, built slice by slice (no full-size float
    temporaries)."""
    c = (n - 1) / 2
    x = (np.arange(n, dtype=np.float32) - c) / n
    r2_xy = x[:, None] ** 2 + x[None, :] ** 2
    rod = (r2_xy < 0.06**2).astype(bool)
    out = np.empty((n, n, n), dtype=np.uint8, order="F")
    for k in range(n):
        r2 = r2_xy + x[k] ** 2
        sl = np.where(r2 < 0.45**2, np.uint8(80), np.uint8(0))
        sl[r2 < 0.35**2] = 200
        sl[rod & (r2 < 0.35**2)] = 140
        out[:, :, k] = sl
    return out


def scale_transfer_function() -> Any:
    """Air clear, the shell at low opacity, the ball brighter (uint8 values)."""
    from voxwarp.core.transfer_function import TransferFunction

    return TransferFunction(
        [
            (0.0, 0.0, 0.0, 0.0, 0.0),
            (40.0, 0.0, 0.0, 0.0, 0.0),
            (80.0, 0.8, 0.5, 0.4, 0.05),
            (140.0, 0.9, 0.7, 0.5, 0.2),
            (200.0, 1.0, 0.95, 0.9, 0.6),
        ],
        name="scale",
    )


# ---------------------------------------------------------------------- memory
_STATUS = Path("/proc/self/status")


def _status_kib(key: str) -> int:
    try:
        for line in _STATUS.read_text().splitlines():
            if line.startswith(key + ":"):
                return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return -1


def reset_peak_rss() -> bool:
    """Reset ``VmHWM`` to the current resident set (Linux ``clear_refs`` 5)."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        return False
    return True


class PeakRSS:
    """``with PeakRSS() as m: ...``; then ``m.mib``: the peak resident set during the
    block beyond the resident set at its start (-1 where ``/proc`` is not available)."""

    def __init__(self) -> None:
        self.mib = -1.0
        self.reset = False
        self._start = -1

    def __enter__(self) -> PeakRSS:
        self.reset = reset_peak_rss()
        self._start = _status_kib("VmRSS")
        return self

    def __exit__(self, *exc: object) -> None:
        peak = _status_kib("VmHWM")
        if peak >= 0 and self._start >= 0:
            self.mib = max(peak - self._start, 0) / 1024


def rss_method() -> str:
    """How :class:`PeakRSS` measures here (for the report)."""
    if _status_kib("VmHWM") < 0:
        return "not available (no /proc/self/status)"
    if reset_peak_rss():
        return "VmHWM after a clear_refs reset minus VmRSS before (/proc/self/status)"
    return "VmHWM minus VmRSS before, without a reset (may under-count after a larger volume)"


# ---------------------------------------------------------------------- measuring
class _Bench:
    """The renderers, scene settings and helpers of one run: ``r`` draws the timed frames,
    ``small`` (16x16 on the same context) the phases, where the drawing costs little."""

    def __init__(self, r: Any, frames: int, coarse_cell_maps: str = "auto") -> None:
        from voxwarp.render.offscreen import OffscreenRenderer
        from voxwarp.scene import Scene

        self.r = r
        with r.current():
            self.small = OffscreenRenderer(*PHASE_IMAGE, ctx=r.ctx)
        self.frames = frames
        self.coarse_cell_maps = coarse_cell_maps
        self.tf = scale_transfer_function()
        self._scene_type = Scene

    def release(self) -> None:
        with self.r.current():
            self.small.release()

    def scene(self, volume: Any) -> Any:
        from voxwarp.bench.render import bench_camera

        return self._scene_type(
            volume, mode="dvr", transfer_function=self.tf, camera=bench_camera(volume)
        )

    def draw_ms(self, scene: Any, small: bool = False) -> float:
        """One frame (of ``small`` or the timed renderer): draw, finish and read back, ms."""
        t = time.perf_counter()
        if small:
            with self.r.current():
                self.small.render(scene)
        else:
            self.r.render(scene)
        return (time.perf_counter() - t) * 1000

    def use_sampling(self, sampling: str) -> None:
        """Draw with new renderers of this ``sampling`` (texture layout) setting."""
        from voxwarp.render.raycaster import Renderer

        with self.r.current():
            for off in (self.r, self.small):
                off.renderer.release()
                off.renderer = Renderer(self.r.ctx, sampling=sampling)
        self.settings(True, True)

    def settings(self, skipping: bool, cells: bool, cell_maps: str = "auto") -> None:
        for r in (self.r.renderer, self.small.renderer):
            r.empty_space_skipping = skipping
            r.cell_skipping = cells
            r.cell_skip_maps = cell_maps
            r.coarse_cell_maps = self.coarse_cell_maps

    def warm(self, layout: str | None = None) -> None:
        """Compile every program variant the run draws with on a tiny volume (in the
        texture ``layout`` the measured volume gets), and drop the textures of volumes
        no longer alive."""
        from voxwarp.core.volume import Volume

        tiny = self.scene(Volume(synthetic_cube(16), (1.0, 1.0, 1.0)))
        renderers = (self.r.renderer, self.small.renderer)
        settings = [r.sampling for r in renderers]
        for r in renderers:
            r.sampling = layout or r.sampling
        for skipping, cells in ((False, False), (True, False), (True, True)):
            self.settings(skipping, cells)
            self.draw_ms(tiny)
            self.draw_ms(tiny, small=True)
        for r, setting in zip(renderers, settings, strict=True):
            r.sampling = setting
        gc.collect()
        self.draw_ms(tiny)  # evicts the textures of dead volumes
        self.draw_ms(tiny, small=True)


def _new_volume(data: np.ndarray, label: str) -> Any:
    from voxwarp.core.volume import Volume

    return Volume(data, (1.0, 1.0, 1.0), name=label)


def measure(bench: _Bench, data: np.ndarray, label: str, memory: bool = True) -> ScaleRow:
    """First frame, its phases, steady frames and memory of one array (see module doc)."""
    layout = bench.r.renderer.layout_for(data.shape, data.dtype)
    bench.warm(layout)
    base = _status_kib("VmRSS")
    with PeakRSS() as peak:
        t = time.perf_counter()
        scene = bench.scene(_new_volume(data, label))
        bench.r.render(scene)
        first = (time.perf_counter() - t) * 1000
    first_kind = bench.r.renderer.last_skip_kind
    second = bench.draw_ms(scene)
    kept = (_status_kib("VmRSS") - base) / 1024
    steady = statistics.median(bench.draw_ms(scene) for _ in range(bench.frames))
    row = ScaleRow(label, tuple(data.shape), str(data.dtype), int(data.nbytes), first, steady)
    row.second_ms = second
    row.layout = layout
    row.kept_mib = kept if memory and base >= 0 else -1.0
    row.skip_kind = f"{first_kind}, then {bench.r.renderer.last_skip_kind}"
    row.peak_rss_mib = peak.mib if memory else -1.0
    del scene
    bench.warm(layout)
    row.phases = _phases(bench, data, label)
    if memory:
        bench.warm(layout)
        tracemalloc.start()
        try:
            bench.r.render(bench.scene(_new_volume(data, label)))
            row.traced_mib = tracemalloc.get_traced_memory()[1] / 2**20
        finally:
            tracemalloc.stop()
    bench.settings(True, True)
    bench.warm(layout)
    return row


def _phases(bench: _Bench, data: np.ndarray, label: str) -> dict[str, float]:
    from voxwarp.render.skipping.maps import block_min_max

    scene = bench.scene(_new_volume(data, label))
    out: dict[str, float] = {}
    for name, (skipping, cells) in zip(
        PHASES, ((False, False), (True, False), (True, True)), strict=True
    ):
        # "always": the cell phase builds its maps at once, whatever the volume's size
        bench.settings(skipping, cells, "always")
        first = bench.draw_ms(scene, small=True)
        again = min(bench.draw_ms(scene, small=True) for _ in range(2))
        out[name] = max(first - again, 0.0)
    t = time.perf_counter()
    block_min_max(data)
    out[BLOCK_MIN_MAX] = (time.perf_counter() - t) * 1000
    bench.settings(True, True)
    return out


def bench_scale(
    sizes: Sequence[int] = DEFAULT_SIZES,
    *,
    long: bool = False,
    frames: int = 5,
    memory: bool = True,
    size: tuple[int, int] = IMAGE_SIZE,
    ctx: Any = None,
    log: Callable[[str], Any] = print,
    samplings: Sequence[str] = ("auto",),
    coarse_cell_maps: str = "auto",
) -> ScaleReport:
    """Measure every size (ascending) and, with ``long``, the long CT-like volume, at
    ``size`` pixels on ``ctx`` (default: a new headless context), once per renderer
    ``samplings`` setting (interleaved: each volume in every setting before the next),
    with the renderers' ``coarse_cell_maps`` setting."""
    from voxwarp.bench.render import body_phantom
    from voxwarp.core.timing import load_average
    from voxwarp.render.offscreen import OffscreenRenderer

    load0 = load_average()
    with OffscreenRenderer(*size, ctx=ctx) as r:
        report = ScaleReport(
            (int(size[0]), int(size[1])),
            int(frames),
            str(r.ctx.info.get("GL_RENDERER", "?")),
            rss_method(),
        )
        bench = _Bench(r, int(frames), coarse_cell_maps)
        try:
            for n in sorted(set(int(s) for s in sizes)):
                data = synthetic_cube(n)
                for sampling in samplings:
                    bench.use_sampling(sampling)
                    row = measure(bench, data, f"{n}³ uint8", memory)
                    report.rows.append(row)
                    log(_row_line(row))
                del data
            if long:
                nx, ny, nz = LONG_SHAPE
                vol = body_phantom(LONG_SHAPE, (0.7, 0.7, 0.8), noise=0.0)
                bench.tf = _long_tf()
                for sampling in samplings:
                    bench.use_sampling(sampling)
                    row = measure(bench, vol.data, f"{nx}x{ny}x{nz} int16 CT-like", memory)
                    report.rows.append(row)
                    log(_row_line(row))
        finally:
            bench.release()
    report.load = (load0, load_average())
    return report


def _row_line(row: ScaleRow) -> str:
    return (
        f"{row.label} ({row.layout}): first frame {row.first_ms:.0f} ms,"
        f" second {row.second_ms:.0f} ms, steady {row.steady_ms:.1f} ms ({row.skip_kind})"
    )


def _long_tf() -> Any:
    from voxwarp.bench.render import dense_transfer_function

    return dense_transfer_function()


# ---------------------------------------------------------------------- command line
def _sizes_arg(text: str) -> tuple[int, ...]:
    try:
        sizes = tuple(int(v) for v in text.split(","))
    except ValueError:
        sizes = ()
    if not sizes or any(not 8 <= n <= 1024 for n in sizes):
        raise argparse.ArgumentTypeError(
            f"sizes must be cube edges 8..1024 separated by commas, e.g. 128,256,512; got {text!r}"
        )
    return sizes


def _samplings_arg(text: str) -> tuple[str, ...]:
    from voxwarp.render.volume_texture import LAYOUTS

    names = tuple(v.strip() for v in text.split(","))
    bad = [n for n in names if n not in ("auto", *LAYOUTS)]
    if bad or not names:
        raise argparse.ArgumentTypeError(
            f"sampling must be auto or one of {', '.join(LAYOUTS)}, separated by commas;"
            f" got {text!r}"
        )
    return names


def add_bench_scale_parser(bsub: Any) -> None:
    """Add ``scale`` to the ``bench`` sub-commands."""
    from voxwarp.core.checks import positive_int

    p = add_bench_parser(
        bsub,
        "scale",
        "first frame, its phases, steady frame and memory of 128³/256³/512³ volumes",
        __doc__,
    )
    p.add_argument(
        "--sizes",
        type=_sizes_arg,
        metavar="N,N,...",
        help="cube edges (default 128,256,512; with --quick 128,256)",
    )
    p.add_argument("--quick", action="store_true", help="128³ and 256³ only, 3 steady frames")
    p.add_argument("--long", action="store_true", help="also a 512x512x1100 int16 CT-like volume")
    p.add_argument("--frames", type=positive_int, help="steady frames (default 5, --quick 3)")
    p.add_argument("--no-memory", action="store_true", help="skip the memory measurements")
    p.add_argument(
        "--sampling",
        type=_samplings_arg,
        metavar="S,S,...",
        help="renderer sampling settings to measure each volume with, interleaved"
        " (auto, slice_pairs, slice_layers, texture3d; default auto)",
    )
    p.add_argument(
        "--coarse-cell-maps",
        choices=("auto", "always", "never"),
        default="auto",
        help="the renderers' octant skip maps per 2³ cells: auto (volumes over 2^22 cells,"
        " the default), always, never (per cell, as before)",
    )
    p.add_argument("--json", metavar="FILE", help="also write the report as JSON")
    p.add_argument("--markdown", metavar="FILE", help="also write the tables to FILE")
    p.set_defaults(func=cmd_bench_scale)


def run_args(args: argparse.Namespace, log: Callable[[str], Any]) -> ScaleReport:
    """Run ``bench scale`` as its parsed arguments ask."""
    sizes = args.sizes or (QUICK_SIZES if args.quick else DEFAULT_SIZES)
    frames = args.frames or (3 if args.quick else 5)
    return bench_scale(
        sizes,
        long=args.long,
        frames=frames,
        memory=not args.no_memory,
        log=log,
        samplings=args.sampling or ("auto",),
        coarse_cell_maps=args.coarse_cell_maps,
    )


def cmd_bench_scale(args: argparse.Namespace) -> int:
    """``python -m benchmarks scale``: see the module docstring."""
    import json

    from voxwarp.core.files import atomic_write_text

    report = run_args(args, lambda s: print(s, file=sys.stderr))
    argv = sys.argv[2:] if sys.argv[1:2] == ["scale"] else []
    text = report.markdown(" ".join(["python -m benchmarks scale", *argv]))
    print(text)
    for r in report.rows[1:]:
        first = report.growth(r, lambda x: x.first_ms)
        if first is not None:
            print(
                f"{r.label}: {r.voxels / report.rows[0].voxels:.0f}x the voxels of"
                f" {report.rows[0].label}, first frame {first:.1f}x"
            )
    if args.json:
        atomic_write_text(Path(args.json), json.dumps(report.to_dict(), indent=2) + "\n")
    if args.markdown:
        atomic_write_text(Path(args.markdown), text)
    return 0
