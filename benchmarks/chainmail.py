"""``python -m benchmarks chainmail``: time for 3D ChainMail to settle one drag, vs grid size.

For each grid size ``n`` (n³ elements over a 100 mm box, by default 16, 32, 64 and
128; no fixed elements, so that no drag is limited; default limits: stiffness 0.5, a
link stretches, compresses and shears by up to a quarter spacing) two drags of the
centre element are timed:

* ``local``: 1 spacing along +x, the issue's "1 element by 1 spacing"; a fixed
  number of elements follow (63 whatever ``n``), so it should cost the same at any
  size;
* ``large``: 20 spacings along the oblique direction (2, 1, 1) / sqrt(6): about 20
  spacings of taut links in every direction, so at 32³ and less every element moves.

Solvers: the CPU kernels of :class:`voxwarp.deform.elements.chainmail.ChainMail` (numba, float64),
in
both variants (``"gibson"``: sponsor lists, ``"enhanced"``: priority queue), and the
GPU backend (``backend="gpu"``; fragment-shader passes on a standalone EGL context, on
a machine without a GPU Mesa llvmpipe) when it can be created; otherwise its rows say
``skipped: <reason>``.

Timing: per size, drag and solver one warm-up move from rest (numba compilation or
loading from its cache, shader compilation, first touch of the scratch arrays), then
``repeats`` rounds, each timing one move from rest (:meth:`ChainMail.reset` first, not
timed) of every solver in turn, so that a change in the machine's load affects all
alike. A time is the wall time of :meth:`ChainMail.move` (GPU: bound by
``ctx.finish()`` before and after); the report gives the median (and min, max). A
solver whose warm-up move took longer than ``slow_s`` is timed once. ``touched``: the
elements the move changed (CPU: :attr:`MoveStats.touched`; GPU, which does not count
them: the elements displaced from rest by more than 1e-4 mm after the move, read
back untimed).

The issue's target is "a local drag on 128³ settles in < 100 ms on the CPU":
:meth:`ChainBenchReport.target_line` states it with the measured ratio.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from benchmarks import gpu_context
from benchmarks.shared import int_list
from voxwarp.bench.command import emit_report
from voxwarp.core.checks import positive_int
from voxwarp.core.timing import cpu_count, load_average
from voxwarp.deform.elements.chainmail_gpu import GpuChainMailSolver
from voxwarp.deform.elements.chainmail_model import ChainMailModel
from voxwarp.render.context import create_context

#: the benchmark's grid sizes (elements per axis)
DEFAULT_SIZES: tuple[int, ...] = (16, 32, 64, 128)
#: the box the element grid spans (mm)
BOX: tuple[tuple[float, float, float], tuple[float, float, float]] = (
    (0.0, 0.0, 0.0),
    (100.0, 100.0, 100.0),
)
#: the drags, in spacings: (name, direction, length)
DRAGS: tuple[tuple[str, tuple[float, float, float], float], ...] = (
    ("local", (1.0, 0.0, 0.0), 1.0),
    ("large", (2.0, 1.0, 1.0), 20.0),
)
#: solvers in report order, and their names in the table
SOLVERS: tuple[str, ...] = ("gibson", "enhanced", "gpu")
SOLVER_NAMES: dict[str, str] = {
    "gibson": "CPU gibson",
    "enhanced": "CPU enhanced",
    "gpu": "GPU",
}
#: the issue's target: a local drag on this grid settles within this many ms on the CPU
TARGET_SIZE = 128
#: a GPU element counts as touched when displaced by more than this (mm)
GPU_MOVED_MM = 1e-4
TARGET_MS = 100.0


@dataclass
class ChainBenchRow:
    """Timings of one solver and drag at one grid size (0 when skipped; see ``note``)."""

    size: int
    solver: str
    drag: str
    repeats: int
    median_ms: float
    min_ms: float
    max_ms: float
    touched: int
    fraction: float = 1.0
    note: str = ""


@dataclass
class ChainBenchReport:
    """All rows of one ``bench chainmail`` run and its setting."""

    sizes: tuple[int, ...]
    repeats: int
    gl_renderer: str = "not used"
    rows: list[ChainBenchRow] = field(default_factory=list)
    #: 1-minute load average of the machine before and after the run (-1: unknown)
    load: tuple[float, float] = (-1.0, -1.0)

    def find(self, size: int, solver: str, drag: str) -> ChainBenchRow | None:
        """The timed row of ``solver`` and ``drag`` at ``size`` (None if absent/skipped)."""
        for r in self.rows:
            if (r.size, r.solver, r.drag) == (size, solver, drag) and r.repeats > 0:
                return r
        return None

    def skipped(self, size: int, solver: str) -> str:
        """The skip note of ``solver`` at ``size`` ("" when it ran)."""
        for r in self.rows:
            if r.size == size and r.solver == solver and r.note.startswith("skipped"):
                return r.note
        return ""

    def target_line(self) -> str:
        """The issue's target, "a local drag on 128³ settles in < 100 ms on the CPU",
        with the measured times and their ratio to it."""
        head = f"Target: a local drag on {TARGET_SIZE}³ settles in < {TARGET_MS:g} ms on the CPU"
        parts = []
        for solver in ("gibson", "enhanced"):
            r = self.find(TARGET_SIZE, solver, "local")
            if r is not None:
                ratio = r.median_ms / TARGET_MS
                verdict = f"met, {1 / ratio:.0f}x faster than needed" if ratio < 1 else "MISSED"
                parts.append(
                    f"{solver} {_ms(r.median_ms)} ms = {ratio:.4f} x the target ({verdict})"
                )
        if not parts:
            return f"{head}: not measured ({TARGET_SIZE} is not among the sizes)."
        return f"{head}: measured {'; '.join(parts)}."

    def markdown(self, command: str) -> str:
        """A markdown table of the run, headed by the command that produced it."""
        drags = "; ".join(
            f"`{name}`: {length:g} spacing{'s' * (length != 1)} along"
            f" ({', '.join(f'{v:g}' for v in d)}){'' if name == 'local' else ' normalised'}"
            for name, d, length in DRAGS
        )
        lines = [
            f"Command: `{command}`",
            "",
            "Model: n³ elements over a 100 mm box, no fixed elements, default limits"
            " (stiffness 0.5: a link stretches, compresses and shears by up to 1/4"
            f" spacing); the centre element dragged from rest. Drags: {drags}.",
            "",
            "Times: wall time of one `ChainMail.move` from rest, median (min–max) of the"
            " timed moves after a warm-up move (numba / shader compilation excluded), the"
            " solvers taking turns; GPU moves bound by `ctx.finish()`. touched: elements"
            " the move changed (GPU: elements displaced by more than"
            f" {GPU_MOVED_MM:g} mm after it). GL:"
            f" {self.gl_renderer}; CPU: {platform.processor() or platform.machine()},"
            f" {cpu_count()} cores; numpy {np.__version__}, numba {_numba_version()};"
            f" 1-minute load average before / after the run {self.load[0]:.2f} /"
            f" {self.load[1]:.2f}.",
            "",
            "| grid | drag | CPU gibson ms | CPU enhanced ms | GPU ms | touched (CPU / GPU)"
            " | GPU / CPU enhanced | moves timed |",
            "|---|---|---:|---:|---:|---|---:|---|",
        ]
        for n in self.sizes:
            for name, _, _ in DRAGS:
                rs = {s: self.find(n, s, name) for s in SOLVERS}
                cells = [_time(rs[s]) for s in SOLVERS]
                cpu = rs["enhanced"] or rs["gibson"]
                touched = (
                    f"{cpu.touched if cpu else '—'} / {rs['gpu'].touched if rs['gpu'] else '—'}"
                )
                g, e = rs["gpu"], rs["enhanced"]
                ratio = "—"
                if g is not None and e is not None and g.fraction == e.fraction == 1.0:
                    ratio = f"{g.median_ms / e.median_ms:.1f}x"
                timed = ", ".join(str(rs[s].repeats) if rs[s] else "—" for s in SOLVERS)
                lines.append(
                    f"| {n}³ | {name} | {' | '.join(cells)} | {touched} | {ratio} | {timed} |"
                )
        # one line per solver and note, naming the sizes (and drags) it applies to
        where: dict[tuple[str, str], dict[int, list[str]]] = {}
        for r in self.rows:
            if r.note:
                where.setdefault((r.solver, r.note), {}).setdefault(r.size, []).append(r.drag)
        notes = []
        for (solver, note), at in where.items():
            places = ", ".join(
                f"{n}³" if len(d) == len(DRAGS) else f"{n}³ {'/'.join(d)}" for n, d in at.items()
            )
            notes.append(f"* {SOLVER_NAMES[solver]} ({places}): {note}")
        if notes:
            lines += ["", *notes]
        lines += ["", self.target_line()]
        return "\n".join(lines) + "\n"


def _numba_version() -> str:
    try:
        import numba
    except ImportError:
        return "not installed"
    return str(numba.__version__)


def _ms(x: float) -> str:
    return f"{x:.3g}" if x < 100 else f"{x:.0f}"


def _time(r: ChainBenchRow | None) -> str:
    if r is None:
        return "—"
    mark = " †" if r.fraction < 1.0 else ""
    if r.repeats == 1:
        return _ms(r.median_ms) + mark
    return f"{_ms(r.median_ms)} ({_ms(r.min_ms)}–{_ms(r.max_ms)}){mark}"


def drag_offset(n: int, drag: str) -> np.ndarray:
    """The (3,) offset (mm) of ``drag`` (a name of :data:`DRAGS`) on the n³ grid."""
    for name, direction, length in DRAGS:
        if name == drag:
            d = np.asarray(direction, dtype=np.float64)
            spacing = (BOX[1][0] - BOX[0][0]) / (n - 1)
            return d / np.linalg.norm(d) * length * spacing
    raise ValueError(f"unknown drag {drag!r}; valid drags: {[d[0] for d in DRAGS]}")


def _grid(n: int) -> Any:
    from voxwarp.deform.elements.grid import ElementGrid

    grid = ElementGrid(BOX, shape=n, anchor="corners")
    grid.free(grid.corner_mask())
    return grid


@dataclass
class _Runner:
    solver: str
    cm: Any
    finish: Callable[[], None]
    times: list[float] = field(default_factory=list)
    touched: int = 0
    fraction: float = 1.0
    note: str = ""

    def move(self, offset: np.ndarray) -> float:
        """Reset (untimed), then time one drag of the centre element (ms)."""
        n = self.cm.grid.shape[0]
        self.cm.reset()
        self.finish()
        t = time.perf_counter()
        stats = self.cm.move((n // 2, n // 2, n // 2), offset)
        self.finish()
        ms = (time.perf_counter() - t) * 1000
        self.fraction = stats.fraction
        if stats.touched >= 0:
            self.touched = stats.touched
        else:  # the GPU does not count them: the elements displaced from rest (by
            # more than float32 round-off of coordinates up to 100 mm)
            u = self.cm.displacements()
            self.touched = int(np.count_nonzero(np.abs(u).max(-1) > GPU_MOVED_MM))
        return ms


def bench_chainmail(
    sizes: tuple[int, ...] = DEFAULT_SIZES,
    *,
    repeats: int = 5,
    use_gpu: bool = True,
    ctx: Any = None,
    slow_s: float = 5.0,
    log: Any = print,
) -> ChainBenchReport:
    """Time the ChainMail solvers on the benchmark drags (see the module doc).

    Parameters
    ----------
    sizes
        Elements per axis of each grid (2..128).
    repeats
        Timed moves per solver, drag and size.
    use_gpu
        Time the GPU backend (rows ``skipped: <reason>`` when it cannot be created).
    ctx
        moderngl context of the GPU backend, current; by default a standalone EGL
        context is created (and released at the end).
    slow_s
        A solver whose warm-up move took longer than this (s) is timed once.
    log
        Progress messages go here.
    """
    report = ChainBenchReport(sizes=tuple(int(n) for n in sizes), repeats=int(repeats))
    load_start = load_average()
    ctx, own_ctx, gpu_skip = gpu_context(ctx, use_gpu)
    if ctx is not None and not gpu_skip:
        report.gl_renderer = str(ctx.info.get("GL_RENDERER", "?"))
    try:
        _compile_kernels()  # so that no warm-up move pays numba's first compilation
        for n in report.sizes:
            rows, gpu_note = _bench_size(n, ctx, gpu_skip, repeats, slow_s, log)
            report.rows += rows
            if gpu_note and not gpu_skip and gpu_note.startswith("skipped"):
                log(f"{n}³ GPU {gpu_note}")
    finally:
        if own_ctx:
            ctx.release()
    report.load = (load_start, load_average())
    return report


def _compile_kernels() -> None:
    """One drag and one relaxation step of each variant on a 3³ grid: numba compiles
    (or loads from its cache) the kernels here, not in a timed or warm-up move."""
    from voxwarp.deform.elements.chainmail import ChainMail

    for variant in ("gibson", "enhanced"):
        cm = ChainMail(_grid(3), variant=variant)
        cm.move((1, 1, 1), (0.1, 0.0, 0.0))
        cm.relax(1)


def _bench_size(
    n: int, ctx: Any, gpu_skip: str, repeats: int, slow_s: float, log: Any
) -> tuple[list[ChainBenchRow], str]:
    """Rows of every solver and drag at n³ (the solvers' timed moves interleaved)."""
    from voxwarp.deform.elements.chainmail import ChainMail

    rows: list[ChainBenchRow] = []
    runners: list[_Runner] = []
    gpu_note = gpu_skip
    try:
        for variant in ("gibson", "enhanced"):
            runners.append(_Runner(variant, ChainMail(_grid(n), variant=variant), lambda: None))
        if not gpu_skip:
            try:
                gpu = ChainMail(_grid(n), backend="gpu", ctx=ctx)
                runners.append(_Runner("gpu", gpu, ctx.finish))
            except Exception as exc:  # any failure of the backend: a skipped row
                gpu_note = f"skipped: {type(exc).__name__}: {exc}"
        for drag, _, _ in DRAGS:
            offset = drag_offset(n, drag)
            timed: list[_Runner] = []
            for r in runners:
                r.times, r.note = [], ""
                try:
                    t = time.perf_counter()
                    r.move(offset)  # warm-up
                    warm = time.perf_counter() - t
                except Exception as exc:  # the GPU backend failing: a skipped row
                    if r.solver != "gpu":
                        raise
                    r.note = f"skipped: {type(exc).__name__}: {exc}"
                    continue
                r.note = f"timed once: the warm-up move took {warm:.1f} s" if warm > slow_s else ""
                timed.append(r)
            for rep in range(int(repeats)):
                for r in timed:
                    if rep == 0 or not r.note:
                        r.times.append(r.move(offset))
            for r in runners:
                if not r.times:
                    rows.append(ChainBenchRow(n, r.solver, drag, 0, 0, 0, 0, 0, 1.0, r.note))
                    continue
                if r.fraction < 1.0:  # cannot happen without fixed elements: flag it
                    r.note = (r.note + "; " if r.note else "") + (
                        f"† limited: the drag went only {r.fraction:.3f} of the way (the"
                        " grid has no fixed elements, so the solver should not limit it;"
                        " its time and touched count are not comparable)"
                    )
                rows.append(
                    ChainBenchRow(
                        n,
                        r.solver,
                        drag,
                        len(r.times),
                        statistics.median(r.times),
                        min(r.times),
                        max(r.times),
                        r.touched,
                        r.fraction,
                        r.note,
                    )
                )
                log(
                    f"{n}³ {drag} {SOLVER_NAMES[r.solver]}: {statistics.median(r.times):.3g} ms"
                    f" ({len(r.times)} moves, {r.touched} touched)"
                )
    finally:
        for r in runners:
            r.cm.close()
    if gpu_note:
        for drag, _, _ in DRAGS:
            rows.append(ChainBenchRow(n, "gpu", drag, 0, 0, 0, 0, 0, 1.0, gpu_note))
    return rows, gpu_note


# ---------------------------------------------------------------------- GPU enforce
def _bench_model(n: int, spacing: float = 1.0) -> ChainMailModel:
    """An n³ grid, 10 % stretch/compression slack and shear 0.1 spacing, bottom fixed."""
    shape = (n, n, n)
    idx = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), axis=-1)
    fixed = np.zeros(shape, bool)
    fixed[:, :, 0] = True
    return ChainMailModel(
        rest=idx * spacing,
        spacing=np.full(3, spacing),
        min_dist=0.9 * spacing,
        max_dist=1.1 * spacing,
        max_shear=0.1 * spacing,
        links=np.ones((*shape, 3), bool),
        fixed=fixed,
    )


def gpu_enforce_table(
    ctx: Any = None, sizes: tuple[int, ...] = (32, 64, 128), frames: int = 10, jumps: int = 3
) -> list[dict[str, Any]]:
    """Time local drags with the growing box (``local``) and with full-grid passes.

    One element at the centre of the top face of an n³ grid (:func:`_bench_model`) is
    held. ``frame``: it is dragged by (0.05, 0, -0.02) spacing per frame, one
    :meth:`~voxwarp.deform.elements.chainmail_gpu.GpuChainMailSolver.enforce` each, from the
    last frame's state. ``jump``: it is moved by (2, 0, -1) spacing in one enforce, from
    rest. Each enforce is timed to the end of its GPU work; both variants run on the
    same solver and context, one after the other, each from the same state
    (``set_positions`` plus one untimed enforce that checks the whole grid).

    Parameters
    ----------
    ctx
        moderngl context (OpenGL 4.3+) to time on; ``None`` makes a standalone EGL one.
    sizes, frames, jumps
        Grid sizes n (n³ elements), timed frames and jumps per size.

    Returns
    -------
    list of dict
        Per size and scenario: median ms per enforce, passes and elements shaded of
        both variants (``box_*``, ``full_*``) and the largest violation left.
    """
    own = ctx is None
    if own:
        ctx = create_context()
    rows = []
    try:
        for n in sizes:
            model = _bench_model(n)
            solver = GpuChainMailSolver(model, ctx)
            held = np.zeros(model.shape, bool)
            centre = (n // 2, n // 2, n - 1)
            held[centre] = True
            for scenario in ("frame", "jump"):
                row: dict[str, Any] = {"n": n, "scenario": scenario}
                for local in (True, False):
                    solver.local = local
                    times, passes, elements = [], [], []
                    targets = model.rest.copy()
                    for i in range(frames if scenario == "frame" else jumps):
                        if scenario == "jump" or i == 0:
                            solver.set_positions(model.rest)
                            targets = model.rest.copy()
                            solver.enforce(held, targets)
                        step = (0.05, 0.0, -0.02) if scenario == "frame" else (2.0, 0.0, -1.0)
                        targets[centre] += step
                        ctx.finish()
                        t0 = time.perf_counter()
                        solver.enforce(held, targets)
                        ctx.finish()
                        times.append(time.perf_counter() - t0)
                        passes.append(solver.last_passes)
                        elements.append(solver.last_elements)
                    key = "box" if local else "full"
                    row[f"{key}_ms"] = round(1e3 * float(np.median(times)), 2)
                    row[f"{key}_passes"] = float(np.median(passes))
                    row[f"{key}_elements"] = float(np.median(elements))
                    row[f"{key}_violation"] = model.violation(solver.positions())
                rows.append(row)
            solver.release()
    finally:
        if own:
            ctx.release()
    return rows


#: ``--sizes``: element grids per axis
SIZES_ARG = int_list(2, 128, "size", "16,32,64")


def add_bench_chainmail_parser(bsub: Any) -> None:
    """The ``chainmail`` sub-command (the options of the former ``voxwarp bench chainmail``)."""
    pbc = bsub.add_parser(
        "chainmail", help="3D ChainMail: time to settle a local and a large drag vs grid size"
    )
    pbc.add_argument(
        "--sizes",
        type=SIZES_ARG,
        default=None,
        metavar="N,N,...",
        help="grids of N³ elements (default 16,32,64,128; with --relax 16,32)",
    )
    pbc.add_argument(
        "--repeats", type=positive_int, default=5, help="timed moves per solver (default 5)"
    )
    pbc.add_argument("--no-gpu", action="store_true", help="skip the GPU backend")
    pbc.add_argument(
        "--relax",
        type=positive_int,
        metavar="STEPS",
        help="time STEPS relaxation steps after a local drag instead (CPU vs GPU, full vs"
        " local; benchmarks.chainmail_relax; sizes default 16,32)",
    )
    pbc.add_argument("--markdown", metavar="FILE", help="also write the table to FILE")
    pbc.set_defaults(func=cmd_bench_chainmail)


def cmd_bench_chainmail(args: argparse.Namespace) -> int:
    """``python -m benchmarks chainmail``: time to settle one drag (see the module docstring);
    with ``--relax``, time the relaxation (:mod:`benchmarks.chainmail_relax`)."""
    command = "python -m benchmarks " + " ".join(sys.argv[1:])
    if args.relax:
        from benchmarks.chainmail_relax import bench_relax, relax_markdown

        sizes = args.sizes or (16, 32)
        rel = bench_relax(sizes, steps=args.relax, repeats=args.repeats, use_gpu=not args.no_gpu)
        return emit_report(relax_markdown(rel, command), args.markdown)
    report = bench_chainmail(
        args.sizes or DEFAULT_SIZES,
        repeats=args.repeats,
        use_gpu=not args.no_gpu,
        log=lambda s: print(s, file=sys.stderr),
    )
    return emit_report(report.markdown(command), args.markdown)
