"""``python -m benchmarks massspring``: mass-spring steps per second, CPU, GPU and taichi.

For each grid size ``n`` (n³ elements, by default 16, 32, 64 and 128) the same model is
stepped by up to four solvers in one process:

* ``numpy``: :class:`voxwarp.deform.elements.massspring.CpuSpringSolver` (float64,
  vectorised numpy), through ``MassSpring(backend="cpu")``;
* ``gpu``: :class:`voxwarp.deform.elements.massspring_gpu.GpuSpringSolver` (float32
  fragment shaders) through ``MassSpring(backend="gpu")`` on a standalone EGL context (on a machine
  without a GPU: Mesa llvmpipe);
* ``taichi``: :class:`benchmarks.taichi.TaichiSpringSolver` (float32, taichi's CPU
  backend on all cores), when ``taichi`` is installed (extra ``[bench]``);
* ``taichi-min``: :class:`benchmarks.taichi.MinimalTaichiSprings`, the least a step
  can do (6 springs, one material for the grid, no pinning; issue 19's floor for the
  GPU step), with taichi.

Model (the defaults of :class:`voxwarp.deform.elements.massspring.MassSpring`): structural springs,
an
``ElementGrid`` over a 100 mm box with its 8 corners fixed, default materials, the
explicit integrator at its stable time step, the displacement clamp at half the
spacing; the centre element is dragged 10 mm along +z so the whole grid is in motion.

Timing: per backend, two steps first (shader / JIT compilation, both ping-pong
directions), then two timed steps to size its blocks: a block is ``steps`` steps, fewer
where one block would take longer than ``max_block_s`` (128³ on numpy), never fewer
than 1. Then ``repeats`` rounds, each timing one block of every backend in turn
(numpy, taichi, GPU), so that a change in the machine's load affects all alike; each
block is bound by ``ctx.finish()`` (GPU) or ``ti.sync()`` (taichi). A rate is steps /
block seconds; the report gives the median (and min, max) over the blocks and the
ratios ``gpu / taichi`` and ``gpu / numpy`` of the medians, all from the same run.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import gpu_context
from benchmarks.shared import int_list
from voxwarp.core.checks import positive_int
from voxwarp.core.timing import cpu_count, load_average

#: the benchmark's grid sizes (elements per axis)
DEFAULT_SIZES: tuple[int, ...] = (16, 32, 64, 128)
#: the box the element grid spans (mm)
BOX: tuple[tuple[float, float, float], tuple[float, float, float]] = (
    (0.0, 0.0, 0.0),
    (100.0, 100.0, 100.0),
)
#: drag of the centre element (mm)
DRAG_MM: tuple[float, float, float] = (0.0, 0.0, 10.0)
#: backends in report order, and their names in the table
BACKENDS: tuple[str, ...] = ("numpy", "gpu", "taichi", "taichi-min")
BACKEND_NAMES: dict[str, str] = {
    "numpy": "numpy CPU",
    "gpu": "GPU",
    "taichi": "taichi CPU",
    "taichi-min": "taichi minimal",
}


@dataclass
class SpringBenchRow:
    """Timings of one backend at one grid size (rates 0 when skipped; see ``note``)."""

    size: int
    backend: str
    steps: int
    repeats: int
    median_sps: float
    min_sps: float
    max_sps: float
    note: str = ""


@dataclass
class SpringBenchReport:
    """All rows of one ``bench massspring`` run and its setting."""

    sizes: tuple[int, ...]
    steps: int
    repeats: int
    integrator: str
    dt: float
    max_step_fraction: float
    springs: int
    gl_renderer: str
    taichi: str
    rows: list[SpringBenchRow] = field(default_factory=list)
    #: 1-minute load average of the machine before and after the run (-1: unknown)
    load: tuple[float, float] = (-1.0, -1.0)

    def find(self, size: int, backend: str) -> SpringBenchRow | None:
        """The row of ``backend`` at ``size`` (None if absent or skipped)."""
        for r in self.rows:
            if r.size == size and r.backend == backend and r.median_sps > 0:
                return r
        return None

    def ratio(self, size: int, backend: str, reference: str) -> float | None:
        """Median steps/s of ``backend`` over that of ``reference`` at ``size``."""
        a, b = self.find(size, backend), self.find(size, reference)
        if a is None or b is None:
            return None
        return a.median_sps / b.median_sps

    def notes(self, size: int) -> list[str]:
        """Skip notes of the backends at ``size``."""
        return [
            f"{BACKEND_NAMES[r.backend]}: {r.note}" for r in self.rows if r.size == size and r.note
        ]

    def markdown(self, command: str) -> str:
        """A markdown table of the run, headed by the command that produced it."""
        taichi = f"taichi {self.taichi} (float32, CPU backend)" if self.taichi else "no taichi"
        lines = [
            f"Command: `{command}`",
            "",
            f"Model: {self.springs} structural springs per element; n³ elements over a"
            " 100 mm box (corners fixed), default materials (stiffness 0.5, damping 1/s,"
            " mass 1), spring constant 50, spring damping 0.5; "
            f"{self.integrator} Euler at the stable dt {self.dt * 1000:.2f} ms, clamp"
            f" {self.max_step_fraction:g} x spacing; the centre element dragged 10 mm"
            " along +z.",
            "",
            "Rates: steps/s, median (min–max) of the timed blocks after warm-up (the"
            " backends' blocks taking turns); a"
            " block is `steps x blocks` steps (fewer steps per block where one block"
            " would take over 2 s); GPU blocks end with `ctx.finish()`, taichi blocks"
            f" with `ti.sync()`. GL: {self.gl_renderer}; CPU:"
            f" {platform.processor() or platform.machine()}, {cpu_count()} cores;"
            f" numpy {np.__version__} (float64);"
            f" {taichi};"
            f" 1-minute load average before / after the run {self.load[0]:.2f} /"
            f" {self.load[1]:.2f}.",
            "",
            "| grid | numpy CPU steps/s | GPU steps/s | taichi CPU steps/s"
            " | taichi minimal steps/s | GPU / taichi | GPU / taichi minimal | GPU / numpy"
            " | steps x blocks (numpy, GPU, taichi, minimal) |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---|",
        ]
        for n in self.sizes:
            cells = []
            blocks = []
            for b in BACKENDS:
                r = self.find(n, b)
                cells.append(_rate(r))
                blocks.append(f"{r.steps}x{r.repeats}" if r else "—")
            gt = self.ratio(n, "gpu", "taichi")
            gm = self.ratio(n, "gpu", "taichi-min")
            gn = self.ratio(n, "gpu", "numpy")
            lines.append(
                f"| {n}³ | {' | '.join(cells)} | {_ratio(gt)} | {_ratio(gm)} | {_ratio(gn)}"
                f" | {', '.join(blocks)} |"
            )
        notes = [f"{n}³ {note}" for n in self.sizes for note in self.notes(n)]
        if notes:
            lines += ["", *(f"* {s}" for s in notes)]
        return "\n".join(lines) + "\n"


def _rate(r: SpringBenchRow | None) -> str:
    if r is None:
        return "—"
    return f"{_num(r.median_sps)} ({_num(r.min_sps)}–{_num(r.max_sps)})"


def _num(x: float) -> str:
    return f"{x:.1f}" if x < 100 else f"{x:.0f}"


def _ratio(x: float | None) -> str:
    return f"{x:.2f}x" if x is not None else "—"


def block_size(
    step: Callable[[int], None],
    finish: Callable[[], None],
    *,
    steps: int,
    max_block_s: float = 2.0,
) -> int:
    """Warm ``step`` up and choose its block size (see the module doc).

    Parameters
    ----------
    step
        ``step(n)`` advances n steps (may return before the work is done).
    finish
        Waits until all work launched so far is done.
    steps
        Most steps per block.
    max_block_s
        A block has fewer steps than ``steps`` where it would take longer than this
        (estimated from two timed steps after warm-up), and at least 1.
    """
    step(2)  # compile / JIT / first draw, both directions of a ping-pong
    finish()
    t = time.perf_counter()
    step(2)
    finish()
    one = max(time.perf_counter() - t, 1e-9) / 2
    return max(1, min(int(steps), int(max_block_s / one)))


def time_block(step: Callable[[int], None], finish: Callable[[], None], block: int) -> float:
    """Steps per second of one block of ``block`` steps, bound by ``finish()``."""
    t = time.perf_counter()
    step(block)
    finish()
    return block / (time.perf_counter() - t)


@dataclass
class _Runner:
    backend: str
    step: Callable[[int], None]
    finish: Callable[[], None]
    close: Callable[[], None]
    block: int = 0
    rates: list[float] = field(default_factory=list)


def _grid(n: int) -> Any:
    from voxwarp.deform.elements.grid import ElementGrid

    return ElementGrid(BOX, shape=n, anchor="corners")


def _centre(n: int) -> tuple[int, int, int]:
    return (n // 2, n // 2, n // 2)


def _dragged_mass_spring(n: int, backend: str = "cpu", ctx: Any = None) -> Any:
    """The benchmark's ``MassSpring`` of an n³ grid, centre element dragged."""
    from voxwarp.deform.elements.massspring import MassSpring

    ms = MassSpring(_grid(n), backend=backend, ctx=ctx)
    ms.move(_centre(n), DRAG_MM)
    return ms


def _constraints(ms: Any) -> tuple[np.ndarray, np.ndarray]:
    """Pinned elements and their targets of the benchmark's drag (as MassSpring has them)."""
    n = ms.grid.shape[0]
    pinned = ms.grid.fixed | ms.held
    targets = np.array(ms.model.rest, dtype=np.float64)
    targets[_centre(n)] += DRAG_MM
    return pinned, targets


def _row(size: int, backend: str, block: int, rates: list[float], note: str = "") -> SpringBenchRow:
    return SpringBenchRow(
        size,
        backend,
        block,
        len(rates),
        statistics.median(rates),
        min(rates),
        max(rates),
        note,
    )


def bench_massspring(
    sizes: tuple[int, ...] = DEFAULT_SIZES,
    *,
    steps: int = 50,
    repeats: int = 5,
    use_taichi: bool = True,
    use_gpu: bool = True,
    use_numpy: bool = True,
    ctx: Any = None,
    max_block_s: float = 2.0,
    log: Any = print,
) -> SpringBenchReport:
    """Time the numpy, GPU and taichi solvers on the benchmark model (see the module doc).

    Parameters
    ----------
    sizes
        Elements per axis of each grid (2..128).
    steps
        Most steps per timed block.
    repeats
        Timed blocks per backend and size.
    use_taichi
        Time the taichi solver (skipped with a note when taichi is not installed).
    use_gpu
        Time the GPU solver (skipped with a note when no OpenGL 4.3 context can be made).
    use_numpy
        Time the numpy solver (the slowest by far at 64³ and above).
    ctx
        moderngl context of the GPU solver, made current by the caller; by default a
        standalone EGL context is created (and released at the end).
    max_block_s
        Longest block (s): see :func:`block_size`.
    log
        Progress messages go here.
    """
    from benchmarks import taichi as bench_taichi

    probe = _dragged_mass_spring(2)
    report = SpringBenchReport(
        sizes=tuple(int(n) for n in sizes),
        steps=int(steps),
        repeats=int(repeats),
        integrator=probe.integrator,
        dt=probe.dt,
        max_step_fraction=probe.max_step / float(np.min(probe.grid.spacing)),
        springs=len(probe.model.offsets),
        gl_renderer="not used",
        taichi="",
    )
    load_start = load_average()
    ctx, own_ctx, gpu_skip = gpu_context(ctx, use_gpu)
    if ctx is not None and not gpu_skip:
        report.gl_renderer = str(ctx.info.get("GL_RENDERER", "?"))
    taichi_skip = "" if use_taichi else "skipped (--no-taichi)"
    if use_taichi and not bench_taichi.taichi_available():
        taichi_skip = "skipped: taichi not installed (pip install '.[bench]')"
    if not taichi_skip:
        report.taichi = bench_taichi.taichi_version()
    try:
        for n in report.sizes:
            skips = {"gpu": gpu_skip, "taichi": taichi_skip}
            skips["numpy"] = "" if use_numpy else "skipped (--no-numpy)"
            report.rows += _bench_size(n, ctx, skips, steps, repeats, max_block_s, log)
    finally:
        if own_ctx:
            ctx.release()
    report.load = (load_start, load_average())
    if taichi_skip:
        log(f"taichi rows {taichi_skip}")
    return report


def _bench_size(
    n: int,
    ctx: Any,
    skips: dict[str, str],
    steps: int,
    repeats: int,
    max_block_s: float,
    log: Any,
) -> list[SpringBenchRow]:
    """Rows of the backends at n³, their timed blocks interleaved.

    The blocks take turns (numpy, taichi, taichi minimal, GPU, numpy, ...), so that a
    change of the machine's load during the run affects every backend alike. ``skips``
    maps "numpy", "gpu" and "taichi" (which also skips the minimal kernel) to a skip note
    ("" to run it).
    """
    from benchmarks import taichi as bench_taichi

    runners: list[_Runner] = []
    skipped: list[SpringBenchRow] = []
    ms = None
    try:
        ms = _dragged_mass_spring(n)
        if skips["numpy"]:
            skipped.append(SpringBenchRow(n, "numpy", 0, 0, 0, 0, 0, skips["numpy"]))
        else:
            runners.append(_Runner("numpy", ms.step, lambda: None, ms.close))
        if skips["taichi"]:
            for b in ("taichi", "taichi-min"):
                skipped.append(SpringBenchRow(n, b, 0, 0, 0, 0, 0, skips["taichi"]))
        else:  # the same model and constraints
            solver = bench_taichi.make_taichi_solver(ms.model)
            solver.set_constraints(*_constraints(ms))
            runners.append(_Runner("taichi", solver.step, solver.sync, solver.release))
            mini = bench_taichi.make_minimal_taichi_solver(ms.model)
            runners.append(_Runner("taichi-min", mini.step, mini.sync, mini.release))
        if skips["gpu"]:
            skipped.append(SpringBenchRow(n, "gpu", 0, 0, 0, 0, 0, skips["gpu"]))
        else:
            gms = _dragged_mass_spring(n, "gpu", ctx)
            runners.append(_Runner("gpu", gms.step, ctx.finish, gms.close))
        for r in runners:
            r.block = block_size(r.step, r.finish, steps=steps, max_block_s=max_block_s)
        for _ in range(int(repeats)):
            for r in runners:
                r.rates.append(time_block(r.step, r.finish, r.block))
    finally:
        for r in runners:
            r.close()
        if skips["numpy"] and ms is not None:
            ms.close()
    rows = [_row(n, r.backend, r.block, r.rates) for r in runners] + skipped
    for row in rows:
        if row.median_sps > 0:
            log(
                f"{n}³ {BACKEND_NAMES[row.backend]}: {row.median_sps:.1f} steps/s"
                f" ({row.steps} steps x {row.repeats})"
            )
    return rows


#: ``--sizes``: element grids per axis
SIZES_ARG = int_list(2, 128, "size", "16,32,64")


def add_bench_massspring_parser(bsub: Any) -> None:
    """The ``massspring`` sub-command (the options of the former ``voxwarp bench massspring``)."""
    pbm = bsub.add_parser("massspring", help="mass-spring steps/s: numpy, GPU and taichi")
    pbm.add_argument(
        "--sizes",
        type=SIZES_ARG,
        default=(16, 32, 64, 128),
        metavar="N,N,...",
        help="grids of N³ elements (default 16,32,64,128)",
    )
    pbm.add_argument(
        "--steps",
        type=positive_int,
        default=50,
        metavar="N",
        help="steps per timed block (fewer where a block would take over 2 s)",
    )
    pbm.add_argument("--repeats", type=positive_int, default=5, help="timed blocks per solver")
    pbm.add_argument("--no-taichi", action="store_true", help="skip the taichi reference")
    pbm.add_argument("--no-numpy", action="store_true", help="skip the numpy solver")
    pbm.add_argument(
        "--render",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="also time deformed vs undeformed dvr through the offset warp (default on)",
    )
    pbm.add_argument(
        "--frames", type=positive_int, default=10, help="timed frames per render (default 10)"
    )
    pbm.add_argument("--markdown", metavar="FILE", help="also write the table to FILE")
    pbm.set_defaults(func=cmd_bench_massspring)


def cmd_bench_massspring(args: argparse.Namespace) -> int:
    """``python -m benchmarks massspring``: solver steps/s (see the module docstring)."""
    from voxwarp.core.files import atomic_write_text

    report = bench_massspring(
        args.sizes,
        steps=args.steps,
        repeats=args.repeats,
        use_taichi=not args.no_taichi,
        use_numpy=not args.no_numpy,
        log=lambda s: print(s, file=sys.stderr),
    )
    command = "python -m benchmarks " + " ".join(sys.argv[1:])
    text = report.markdown(command)
    print(text)
    for n in report.sizes:
        ratio = report.ratio(n, "gpu", "taichi")
        if ratio is not None:
            print(f"{n}³: the GPU solver runs {ratio:.2f}x the steps/s of taichi on the CPU")
        ratio = report.ratio(n, "gpu", "taichi-min")
        if ratio is not None:
            print(f"{n}³: the GPU solver runs {ratio:.2f}x the minimal taichi kernel's steps/s")
    if args.render:
        from voxwarp.bench.render import bench_warp_render

        warp_report = bench_warp_render(
            frames=args.frames, warmup=2, log=lambda s: print(s, file=sys.stderr)
        )
        text += "\n" + warp_report.print_summary(command)
    if args.markdown:
        atomic_write_text(Path(args.markdown), text)
    return 0
