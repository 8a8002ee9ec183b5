"""Section 3 of ``python -m benchmarks lattice``: the lattice-on-volume inverse, accuracy
beside cost.

A :class:`~voxwarp.deform.lattice.warp.LatticeWarp` renders a volume through the inverse of
the lattice: a baked seed refined by Newton steps until a step moves the original point by
at most ``tolerance`` mm (the default), or by fixed steps (the former default: 2). Two
measurements, each variant against references from the same run:

* *Accuracy* (CPU, exactly the shader's rule in float64):
  :func:`inverse_error_study` over random lattices proven
  not to fold (1-4 cells per axis, 40-120 mm boxes, every node or one node moved by a
  large part of a cell), points uniform and on the cells' faces: the distribution of the
  point error ``|q' - q|`` (median, 99th percentile, max), the largest residual, the
  Newton steps taken and the points stopped by the cap.
* *Render cost*: the ``stent`` CT downsampled to :data:`VOLUME_SIZE`³, dvr with its
  suggested transfer function, :data:`IMAGE` pixels, deformed-space skip maps, under the
  bent 4³-cell lattice of :func:`bent_grid` on the volume's
  box (one copy of the volume per variant, so that each keeps its skip maps). After two
  warm-up frames of each variant (shader compile, skip maps), each round
  draws every variant once (the order rotates each round, every frame bound by
  ``ctx.finish()``); the medians over the rounds are compared with the baked seed alone
  and with the fixed 2 steps.

The study's code lives here, not in the installed package: the test cases
(:func:`bent_grid`, :func:`random_lattice` with :func:`certified_nonfolding`,
:func:`study_cases`), the accuracy over random lattices (:func:`inverse_error_study`) and
on the one bent lattice (:func:`inverse_error_table`, which chose the former default of
2 fixed steps), each with its markdown table.
"""

from __future__ import annotations

import statistics
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from voxwarp.deform.lattice.trilinear import TrilinearGrid
from voxwarp.deform.lattice.warp import DEFAULT_TOLERANCE, LatticeWarp, lattice_eval

#: random lattices and points per lattice of the accuracy rows
DEFAULT_TRIALS = 24
DEFAULT_POINTS = 4000
#: timed rounds of the render rows (0: accuracy only)
DEFAULT_FRAMES = 15
#: the rendered volume (voxels per axis) and image
VOLUME_SIZE = 128
IMAGE: tuple[int, int] = (256, 256)
#: the render rows: (label, LatticeWarp keywords)
RENDER_VARIANTS: tuple[tuple[str, dict[str, Any]], ...] = (
    ("baked seed", {"inverse": "baked"}),
    ("newton k=2 (former default)", {"iterations": 2}),
    ("newton k=1", {"iterations": 1}),
    # the loop's own cost: every sample leaves it after its first step
    ("loop left after 1 step (tol=1e3 mm)", {"tolerance": 1e3}),
    ("newton tol=1e-2 mm", {"tolerance": 1e-2}),
    (f"newton tol={DEFAULT_TOLERANCE:g} mm (default)", {}),
    ("newton tol=1e-4 mm", {"tolerance": 1e-4}),
)


# ---------------------------------------------------------------------- error study
def bent_grid(
    cells: int | Sequence[int] = 4,
    lo: Sequence[float] = (0.0, 0.0, 0.0),
    hi: Sequence[float] = (128.0, 128.0, 128.0),
    bend: float = 0.25,
) -> TrilinearGrid:
    """A bent lattice over the box ``[lo, hi]``: the error study's test case.

    In box units: the middle is pushed along +z by ``bend sin(pi u_x)`` (an arc), twisted
    by ``0.15 (u_y - 0.5) sin(pi u_x)`` along z, shifted along y by ``0.1 sin(pi u_z)``
    and sheared along x by ``0.06 sin(pi u_z) (u_y - 0.5)``; sampled at the nodes of
    ``cells`` cells per axis
    (:meth:`~voxwarp.deform.lattice.trilinear.TrilinearGrid.from_function`).
    """
    lo_a, hi_a = np.asarray(lo, float), np.asarray(hi, float)
    size = hi_a - lo_a
    c = (cells,) * 3 if isinstance(cells, int | np.integer) else tuple(int(v) for v in cells)

    def f(u: np.ndarray) -> np.ndarray:
        x, y, z = u[:, 0], u[:, 1], u[:, 2]
        v = np.stack(
            [
                x + 0.06 * np.sin(np.pi * z) * (y - 0.5),
                y + 0.1 * np.sin(np.pi * z),
                z + bend * np.sin(np.pi * x) + 0.15 * (y - 0.5) * np.sin(np.pi * x),
            ],
            axis=1,
        )
        return lo_a + v * size

    return TrilinearGrid.from_function(f, c)


def _cell_dets(nodes: np.ndarray, f: np.ndarray) -> np.ndarray:
    """``det J`` of every cell at local coordinates ``f`` (M, 3) in ``[0, 1]³``: ``(cells
    flattened, M)``."""
    n = np.asarray(nodes.shape[:3]) - 1
    c = {
        o: nodes[o[0] : o[0] + n[0], o[1] : o[1] + n[1], o[2] : o[2] + n[2]].reshape(-1, 1, 3)
        for o in np.ndindex(2, 2, 2)
    }
    fx, fy, fz = (f[None, :, a : a + 1] for a in range(3))

    def mix(a: np.ndarray, b: np.ndarray, t: np.ndarray) -> np.ndarray:
        return a + (b - a) * t

    x00, x10 = mix(c[0, 0, 0], c[1, 0, 0], fx), mix(c[0, 1, 0], c[1, 1, 0], fx)
    x01, x11 = mix(c[0, 0, 1], c[1, 0, 1], fx), mix(c[0, 1, 1], c[1, 1, 1], fx)
    dx = mix(
        mix(c[1, 0, 0] - c[0, 0, 0], c[1, 1, 0] - c[0, 1, 0], fy),
        mix(c[1, 0, 1] - c[0, 0, 1], c[1, 1, 1] - c[0, 1, 1], fy),
        fz,
    )
    dy = mix(x10 - x00, x11 - x01, fz)
    dz = mix(x01, x11, fy) - mix(x00, x10, fy)
    return np.sum(dx * np.cross(dy, dz), axis=-1)


def certified_nonfolding(grid: TrilinearGrid) -> bool:
    """True when ``det J > 0`` is proven everywhere in the lattice.

    Within a cell ``det J`` is a polynomial of degree 2 in each local coordinate (each
    column of J is bilinear in the other two), so it is the combination of the 27
    tensor-product Bernstein polynomials of degree 2 with the coefficients computed here
    from its values at the 3x3x3 points ``{0, 1/2, 1}³``. The Bernstein polynomials are
    non-negative and sum to 1: when all coefficients are positive, so is ``det J``. (A
    sufficient test: a lattice can be non-folding and fail it.)
    """
    nodes = np.asarray(grid.nodes, dtype=np.float64)
    t = np.array([0.0, 0.5, 1.0])
    f = np.stack(np.meshgrid(t, t, t, indexing="ij"), -1).reshape(-1, 3)
    vals = _cell_dets(nodes, f).reshape(-1, 3, 3, 3)
    # values at 0, 1/2, 1 of b0 + 2 t (1 - t) b1 + ... -> Bernstein coefficients, per axis
    to_bernstein = np.linalg.inv(np.array([[1.0, 0.0, 0.0], [0.25, 0.5, 0.25], [0.0, 0.0, 1.0]]))
    coef = np.einsum("ai,bj,ck,nijk->nabc", to_bernstein, to_bernstein, to_bernstein, vals)
    return bool(np.all(coef > 0.0))


def random_lattice(
    rng: np.random.Generator,
    cells: int,
    box: tuple[np.ndarray, np.ndarray],
    fraction: float,
    moved: str = "all",
) -> TrilinearGrid:
    """A random non-folding lattice over ``box``: the error study's test cases.

    The box's regular lattice of ``cells`` cells per axis with every node (``moved="all"``)
    or one random node (``"one"``) moved by up to ``fraction`` of a cell per axis
    (uniform), drawn again with half the fraction until :func:`certified_nonfolding`
    proves ``det J > 0`` everywhere.
    """
    lo, hi = np.asarray(box[0], float), np.asarray(box[1], float)
    base = np.asarray(TrilinearGrid.from_box(lo, hi, cells=cells).nodes, dtype=np.float64)
    h = (hi - lo) / cells
    while True:
        move = rng.uniform(-fraction, fraction, base.shape) * h
        if moved == "one":
            keep = np.zeros(base.shape[:3], bool)
            keep[tuple(rng.integers(0, cells + 1, 3))] = True
            move = np.where(keep[..., None], move, 0.0)
        grid = TrilinearGrid(base + move)
        if certified_nonfolding(grid):
            return grid
        fraction *= 0.5


#: The inverse variants of :func:`inverse_error_study`: (label, LatticeWarp keywords).
STUDY_VARIANTS: tuple[tuple[str, dict[str, Any]], ...] = (
    ("baked seed", {"inverse": "baked"}),
    ("newton k=1", {"iterations": 1}),
    ("newton k=2 (former default)", {"iterations": 2}),
    ("newton k=3", {"iterations": 3}),
    ("newton tol=1e-2 mm", {"tolerance": 1e-2}),
    ("newton tol=1e-3 mm (default)", {}),
    ("newton tol=1e-4 mm", {"tolerance": 1e-4}),
)


def study_cases(
    trials: int = 24, points: int = 4000, seed: int = 0
) -> list[tuple[TrilinearGrid, tuple[np.ndarray, np.ndarray], np.ndarray]]:
    """The random non-folding lattices of :func:`inverse_error_study`: ``(grid, box, u)``.

    Trial t: ``1 + t % 4`` cells per axis over a box of 40-120 mm per axis; every node
    moved by up to 0.3 of a cell (even t) or one node by up to 0.6 (odd t), per axis
    (:func:`random_lattice`: proven non-folding); ``points`` unit-cube points u, two
    thirds uniform and a third on the lattice's inner cell faces (its kinks, where the
    seed is worst).
    """
    rng = np.random.default_rng(seed)
    cases = []
    for t in range(trials):
        cells = 1 + t % 4
        lo = rng.uniform(-50.0, 50.0, 3)
        box = (lo, lo + rng.uniform(40.0, 120.0, 3))
        one = t % 2 == 1
        grid = random_lattice(rng, cells, box, 0.6 if one else 0.3, "one" if one else "all")
        u = rng.uniform(0.0, 1.0, (points, 3))
        if cells > 1:
            rows = np.arange(points // 3)
            axis = rng.integers(0, 3, len(rows))
            u[rows, axis] = rng.integers(1, cells, len(rows)) / cells
        cases.append((grid, box, u))
    return cases


def inverse_error_study(
    trials: int = 24,
    points: int = 4000,
    seed: int = 0,
    variants: Sequence[tuple[str, Mapping[str, Any]]] = STUDY_VARIANTS,
) -> list[dict[str, Any]]:
    """Accuracy of each inverse variant over random non-folding lattices.

    On :func:`study_cases` (``trials``, ``points``, ``seed``), with the general path
    (``fold_linear=False``), for each variant: the point error ``|q' - q|`` (mm) between
    the computed original point and the true one, its median, 99th percentile and
    maximum over all points; the largest residual ``|grid(u') - p|`` (mm); the mean and
    most Newton steps; the points where the iteration stopped at its cap or at a
    singular J, not converged (None for fixed steps); and the share of points declared
    outside (lost).

    Returns
    -------
    list of dict
        Rows ``{"label", "median", "p99", "max", "residual", "mean_steps", "max_steps",
        "unconverged", "lost"}``.
    """
    cases = study_cases(trials, points, seed)
    rows = []
    for label, kw in variants:
        err, res, steps, lost = [], [], [], 0
        unconverged: int | None = None
        for grid, box, u in cases:
            w = LatticeWarp(grid, box, fold_linear=False, **kw)
            nodes = np.asarray(grid.nodes, dtype=np.float64)
            p = lattice_eval(nodes, u, jacobian=False)[0]
            uc, inside, st, conv = w.solve(p)
            err.append(np.linalg.norm((uc - u) * w.size, axis=1))
            res.append(np.linalg.norm(lattice_eval(nodes, uc, jacobian=False)[0] - p, axis=1))
            steps.append(st)
            if w.adaptive:
                unconverged = (unconverged or 0) + int(np.sum(~conv))
            lost += int(np.sum(~inside))
        e, st_all = np.concatenate(err), np.concatenate(steps)
        rows.append(
            {
                "label": label,
                "median": float(np.median(e)),
                "p99": float(np.percentile(e, 99)),
                "max": float(e.max()),
                "residual": float(np.concatenate(res).max()),
                "mean_steps": float(st_all.mean()),
                "max_steps": int(st_all.max()),
                "unconverged": unconverged,
                "lost": lost / len(e),
            }
        )
    return rows


def format_error_study(rows: Sequence[Mapping[str, Any]]) -> str:
    """Markdown table of :func:`inverse_error_study` rows."""
    lines = [
        "| inverse | median (mm) | 99th pct (mm) | max (mm) | max residual (mm) |"
        " steps mean / max | not converged | lost |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['label']} | {r['median']:.2g} | {r['p99']:.2g} | {r['max']:.2g} |"
            f" {r['residual']:.2g} | {r['mean_steps']:.2f} / {r['max_steps']} |"
            f" {'-' if r['unconverged'] is None else r['unconverged']} |"
            f" {100 * r['lost']:.3f} % |"
        )
    return "\n".join(lines)


def inverse_error_table(
    cells: int = 4,
    bend: float = 0.25,
    iterations: Sequence[int] = (1, 2, 3),
    points: int = 20000,
    seed: int = 0,
) -> list[dict[str, Any]]:
    """Accuracy of the inverse on one bent lattice (random lattices:
    :func:`inverse_error_study`).

    :func:`bent_grid` (``cells``, ``bend``) over a 128 mm box; ``points`` points
    ``p = grid(u)`` with u uniform in the unit cube (``seed``); for ``"baked"`` (the
    seed alone), ``"newton"`` with each of ``iterations`` fixed steps and the default
    ``"newton"`` (to :data:`DEFAULT_TOLERANCE`; ``iterations`` None), the residual
    ``|grid(u') - p|`` (mm) of the computed u' (before the inside test) and the share of
    points declared outside.

    Returns
    -------
    list of dict
        Rows ``{"inverse", "iterations", "max", "median", "lost"}`` (mm, mm, fraction).
    """
    box = (np.zeros(3), np.full(3, 128.0))
    grid = bent_grid(cells, *box, bend=bend)
    rng = np.random.default_rng(seed)
    u = rng.uniform(0.0, 1.0, (points, 3))
    nodes = np.asarray(grid.nodes, dtype=np.float64)
    p = lattice_eval(nodes, u, jacobian=False)[0]
    rows: list[dict[str, Any]] = []
    variants: list[tuple[str, int | None]] = [("baked", 0)]
    variants += [("newton", int(k)) for k in iterations] + [("newton", None)]
    for mode, k in variants:
        w = LatticeWarp(grid, box, inverse=mode, iterations=k)
        uc, inside = w.lattice_coordinates(p)
        res = np.linalg.norm(lattice_eval(nodes, uc, jacobian=False)[0] - p, axis=1)
        rows.append(
            {
                "inverse": mode,
                "iterations": k,
                "max": float(res.max()),
                "median": float(np.median(res)),
                "lost": float(np.mean(~inside)),
            }
        )
    return rows


def format_error_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """Markdown table of :func:`inverse_error_table` rows."""

    def steps(k: int | None) -> str:
        return f"tol={DEFAULT_TOLERANCE:g} mm" if k is None else f"k={k}"

    lines = ["| inverse | max (mm) | median (mm) | lost |", "|---|---|---|---|"]
    for r in rows:
        lines.append(
            f"| {r['inverse']} {steps(r['iterations'])} | {r['max']:.3g} | {r['median']:.3g}"
            f" | {100 * r['lost']:.2f} % |"
        )
    return "\n".join(lines)


@dataclass
class RenderRow:
    """Median frame time of one inverse variant."""

    label: str
    median_ms: float
    min_ms: float


@dataclass
class InverseReport:
    """What section 3 measured."""

    trials: int
    points: int
    frames: int
    accuracy: list[dict[str, Any]] = field(default_factory=list)
    render: list[RenderRow] = field(default_factory=list)
    volume: str = ""

    def _ms(self, label_start: str) -> float | None:
        for r in self.render:
            if r.label.startswith(label_start):
                return r.median_ms
        return None

    def standalone_markdown(
        self, command: str, gl_renderer: str, load: tuple[float, float], wall_s: float
    ) -> str:
        """The section alone (``bench lattice --inverse-only``), headed by the command, the
        device and the load."""
        import platform
        import sys

        from voxwarp.core.timing import cpu_count

        lines = [
            f"Command: `{command}`",
            "",
            f"Device: GL {gl_renderer}; CPU {platform.processor() or platform.machine()},"
            f" {cpu_count()} cores; Python {sys.version.split()[0]}, numpy {np.__version__};"
            f" 1-minute load average before / after {load[0]:.2f} / {load[1]:.2f}; the run"
            f" took {wall_s:.1f} s.",
            "",
            *self.markdown_lines(),
        ]
        return "\n".join(lines).rstrip() + "\n"

    def markdown_lines(self) -> list[str]:
        """Section 3 in markdown."""
        lines = [
            "## 3. Lattice over a volume: inverse accuracy and render cost",
            "",
            f"Accuracy: `inverse_error_study` on {self.trials} random lattices proven not to"
            f" fold, {self.points} points each (a third on inner cell faces); point error"
            " |q' - q| (mm) against the true original point; residual |grid(u') - p|;"
            " not converged: points where the iteration stopped at its cap or at a singular J"
            " (only their residual bounds their error); lost: inside points"
            " declared outside.",
            "",
            format_error_study(self.accuracy),
            "",
        ]
        if not self.render:
            return lines
        seed, fixed = self._ms("baked seed"), self._ms("newton k=2")
        lines += [
            f"Render cost: {self.volume}, dvr, {IMAGE[0]}x{IMAGE[1]}, under the bent 4³-cell"
            f" lattice; medians of {self.frames} interleaved rounds (rotating order) after 2"
            " warm-up frames of each variant.",
            "",
            "| inverse | median ms (min) | vs baked seed | vs fixed k=2 |",
            "|---|---:|---:|---:|",
        ]
        for r in self.render:
            a = f"{r.median_ms / seed:.2f}x" if seed else "-"
            b = f"{r.median_ms / fixed:.2f}x" if fixed else "-"
            lines.append(f"| {r.label} | {r.median_ms:.1f} ({r.min_ms:.1f}) | {a} | {b} |")
        return [*lines, ""]


def render_volume() -> Any:
    """The stent CT trilinearly downsampled to :data:`VOLUME_SIZE`³."""
    from scipy.ndimage import zoom

    from voxwarp.core.volume import Volume
    from voxwarp.io.samples import load_sample

    stent = load_sample("stent")
    factors = [VOLUME_SIZE / s for s in stent.shape]
    data = np.clip(np.rint(zoom(stent.data.astype(np.float32), factors, order=1)), 0, 255)
    spacing = tuple(sp / f for sp, f in zip(stent.spacing, factors, strict=True))
    return Volume(
        data.astype(np.uint8), spacing, name=f"stent CT (real scan, resampled to {VOLUME_SIZE}³)"
    )


def time_render_variants(
    ctx: Any,
    variants: Sequence[tuple[str, Mapping[str, Any]]] = RENDER_VARIANTS,
    frames: int = DEFAULT_FRAMES,
    log: Callable[[str], None] = print,
) -> tuple[list[RenderRow], str]:
    """Interleaved median frame times of each variant (see the module docstring)."""
    from voxwarp.bench.render import bench_camera
    from voxwarp.io.samples import suggested_transfer_function
    from voxwarp.render.offscreen import OffscreenRenderer
    from voxwarp.scene import Scene

    vol = render_volume()
    lo, hi = (np.asarray(b, dtype=np.float64) for b in vol.bounds)
    grid = bent_grid(4, lo, hi)
    base = Scene(
        vol, mode="dvr", transfer_function=suggested_transfer_function("stent"),
        camera=bench_camera(vol),
    )  # fmt: skip
    warps = [LatticeWarp(grid, (lo, hi), **dict(kw)) for _, kw in variants]
    # one Volume object per variant: the renderer keeps the deformed-space skip maps of
    # one warp state per volume, and interleaved variants would rebuild them every frame
    scenes = [base.copy(volume=vol.with_geometry(), warps=[w]) for w in warps]
    times: list[list[float]] = [[] for _ in variants]
    with OffscreenRenderer(*IMAGE, ctx=ctx) as r:
        r.renderer.warped_skip_maps = "always"
        for s in scenes:
            r.time_frames(s, frames=0, warmup=2)
        for k in range(int(frames)):
            for i in np.roll(np.arange(len(scenes)), -k):
                times[i] += r.time_frames(scenes[i], frames=1, warmup=0)
        for w in warps:
            w.release()
    rows = [
        RenderRow(label, statistics.median(t), min(t))
        for (label, _), t in zip(variants, times, strict=True)
    ]
    for row in rows:
        log(f"lattice inverse {row.label}: {row.median_ms:.1f} ms")
    return rows, vol.name


def bench_inverse(
    ctx: Any,
    *,
    trials: int = DEFAULT_TRIALS,
    points: int = DEFAULT_POINTS,
    frames: int = DEFAULT_FRAMES,
    log: Callable[[str], None] = print,
) -> InverseReport:
    """Section 3: the accuracy rows (CPU), then the render rows on ``ctx`` (none with
    ``frames`` 0)."""
    report = InverseReport(trials=int(trials), points=int(points), frames=int(frames))
    log(f"lattice inverse accuracy: {trials} random lattices x {points} points")
    report.accuracy = inverse_error_study(int(trials), int(points), variants=STUDY_VARIANTS)
    if int(frames) > 0:
        report.render, report.volume = time_render_variants(ctx, frames=int(frames), log=log)
    return report


__all__ = [
    "STUDY_VARIANTS",
    "InverseReport",
    "RenderRow",
    "bench_inverse",
    "bent_grid",
    "certified_nonfolding",
    "format_error_study",
    "format_error_table",
    "inverse_error_study",
    "inverse_error_table",
    "random_lattice",
    "study_cases",
    "time_render_variants",
]
