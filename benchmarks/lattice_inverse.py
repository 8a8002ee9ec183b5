"""Section 3 of ``python -m benchmarks lattice``: the lattice-on-volume inverse, accuracy
beside cost.

A :class:`~voxwarp.deform.lattice.warp.LatticeWarp` renders a volume through the inverse of
the lattice: a baked seed refined by Newton steps until a step moves the original point by
at most ``tolerance`` mm (the default), or by fixed steps (the former default: 2). Two
measurements, each variant against references from the same run:

* *Accuracy* (CPU, exactly the shader's rule in float64):
  :func:`~voxwarp.deform.lattice.warp.inverse_error_study` over random lattices proven
  not to fold (1-4 cells per axis, 40-120 mm boxes, every node or one node moved by a
  large part of a cell), points uniform and on the cells' faces: the distribution of the
  point error ``|q' - q|`` (median, 99th percentile, max), the largest residual, the
  Newton steps taken and the points stopped by the cap.
* *Render cost*: the ``stent`` CT downsampled to :data:`VOLUME_SIZE`³, dvr with its
  suggested transfer function, :data:`IMAGE` pixels, deformed-space skip maps, under the
  bent 4³-cell lattice of :func:`~voxwarp.deform.lattice.warp.bent_grid` on the volume's
  box (one copy of the volume per variant, so that each keeps its skip maps). After two
  warm-up frames of each variant (shader compile, skip maps), each round
  draws every variant once (the order rotates each round, every frame bound by
  ``ctx.finish()``); the medians over the rounds are compared with the baked seed alone
  and with the fixed 2 steps.
"""

from __future__ import annotations

import statistics
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from voxwarp.deform.lattice.warp import (
    DEFAULT_TOLERANCE,
    STUDY_VARIANTS,
    LatticeWarp,
    bent_grid,
    format_error_study,
    inverse_error_study,
)

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


__all__ = ["InverseReport", "RenderRow", "bench_inverse", "time_render_variants"]
