"""``python -m benchmarks segments``: piecewise-linear warped rays against per-sample warping.

For each deformation (the ``python -m benchmarks interactive`` edits of mass-spring, wires
and lattice on the bundled CT, and a smooth registration-like displacement field of
32³ nodes), the rest frame with deformed-space skip maps is timed with the warp chain
evaluated at every sample (``Renderer.ray_segment = 1``), with the automatic segment
map (``"auto"``, tolerance ``--tolerance`` texels) and with fixed segments of 4 and 8
samples. Frames of all settings and the undeformed frame are interleaved, medians
taken; each is given as a ratio to the undeformed frame of the same run, with the
image difference to the per-sample frame (max and mean, /255) and the share of the
segment map's cells allowing at least 4 samples.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from benchmarks.fields import smooth_field
from voxwarp.bench.command import add_bench_parser, emit_report
from voxwarp.bench.interactive import edit_family
from voxwarp.core.checks import image_size, positive_int
from voxwarp.editing.session import EditSession
from voxwarp.io.samples import DEFAULT_SAMPLE, load_sample, suggested_transfer_function
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.render.skipping.segments import RaySegments, segment_lengths
from voxwarp.scene import Scene

CASES = ("massspring", "wires", "lattice", "field")
SETTINGS: tuple[Any, ...] = (1, "auto", 4, 8)


@dataclass
class SegmentRow:
    """One deformation: ratio to undeformed and image difference per setting."""

    case: str
    ratios: dict[str, float]
    max_diff: dict[str, float]
    mean_diff: dict[str, float]
    long_cells: float


@dataclass
class SegmentReport:
    """The rows and what they were measured on."""

    size: tuple[int, int]
    tolerance: float
    reference_ms: float
    rows: list[SegmentRow] = field(default_factory=list)
    renderer: str = ""

    def markdown(self, command: str) -> str:
        """The table, with the command that produced it."""
        w, h = self.size
        names = [str(s) for s in SETTINGS]
        lines = [
            f"`{command}` — {self.renderer}, {w}x{h}, bundled CT, dvr, rest frames with"
            f" skip maps; ratio to the undeformed frame ({self.reference_ms:.0f} ms) and"
            f" image difference to the per-sample frame (max / mean, /255); auto tolerance"
            f" {self.tolerance:g} texel",
            "",
            "| deformation | " + " | ".join(f"K = {n}" for n in names) + " | cells with K >= 4 |",
            "|---|" + "---|" * (len(names) + 1),
        ]
        for r in self.rows:
            cells = [
                f"{r.ratios[n]:.2f}x ({r.max_diff[n]:.0f} / {r.mean_diff[n]:.3f})" for n in names
            ]
            lines.append(f"| {r.case} | " + " | ".join(cells) + f" | {r.long_cells:.0%} |")
        return "\n".join(lines) + "\n"


def _scene(base: Scene, case: str) -> tuple[Scene, EditSession | None]:
    if case == "field":
        return base.copy(warps=[smooth_field(base.volume, 32)]), None
    session = EditSession(base.copy(warps=[]))
    edit_family(session, case)
    return session.scene, session


def _time(draw: Any, scene: Scene) -> float:
    t = time.perf_counter()
    draw(scene)
    return (time.perf_counter() - t) * 1000


def _long_cells(scene: Scene, tolerance: float) -> float:
    """Share of the scene's segment-map cells that allow 4 samples or more."""
    vol = scene.volume
    lo, hi = scene.ray_bounds()
    longest = RaySegments().max_length(vol)
    m = segment_lengths(scene.warps, lo, hi, vol.world_to_texel_matrix(), tolerance, longest)
    return float(np.mean(m.lengths >= 4 * scene.sample_distance_mm))


def _case_row(
    r: OffscreenRenderer, base: Scene, case: str, frames: int, tolerance: float, refs: list
) -> SegmentRow:
    """One deformation: its images per setting, then frames of every setting interleaved
    with the undeformed one (appended to ``refs``)."""
    scene, session = _scene(base, case)
    rr = r.renderer

    def draw(sc: Scene) -> None:
        with r.current():
            rr.draw(sc, r.framebuffer)
            r.ctx.finish()

    try:
        images, times = {}, {str(s): [] for s in SETTINGS}
        for s in SETTINGS:
            rr.ray_segment = s
            images[str(s)] = r.render(scene)[..., :3].astype(float)
        for _ in range(frames):
            refs.append(_time(draw, base))
            for s in SETTINGS:
                rr.ray_segment = s
                times[str(s)].append(_time(draw, scene))
        ref = statistics.median(refs[-frames:])
        diffs = {k: np.abs(v - images["1"]) for k, v in images.items()}
        return SegmentRow(
            case,
            {k: statistics.median(v) / ref for k, v in times.items()},
            {k: float(d.max()) for k, d in diffs.items()},
            {k: float(d.mean()) for k, d in diffs.items()},
            _long_cells(scene, tolerance),
        )
    finally:
        rr.ray_segment = 1
        if session is not None:
            session.close()


def bench_segments(
    size: tuple[int, int] = (512, 512),
    frames: int = 5,
    cases: tuple[str, ...] = CASES,
    tolerance: float = 0.1,
    log: Any = None,
) -> SegmentReport:
    """Time and compare the segment settings per deformation (module docstring)."""
    vol = load_sample(DEFAULT_SAMPLE)
    tf = suggested_transfer_function(DEFAULT_SAMPLE)
    base = Scene(vol, transfer_function=tf, view=(-60, 20), zoom=1.2, jitter=False)
    with OffscreenRenderer(*size) as r:
        r.renderer.warped_skip_maps = "always"
        r.renderer.ray_tolerance = tolerance
        report = SegmentReport(size, tolerance, 0.0, renderer=str(r.ctx.info.get("GL_RENDERER")))
        refs: list[float] = []
        for case in cases:
            row = _case_row(r, base, case, frames, tolerance, refs)
            report.rows.append(row)
            if log:
                log(f"{case}: " + ", ".join(f"K={k} {v:.2f}x" for k, v in row.ratios.items()))
        report.reference_ms = statistics.median(refs)
    return report


def cmd_bench_segments(args: argparse.Namespace) -> int:
    """``python -m benchmarks segments``."""
    report = bench_segments(
        size=args.size,
        frames=args.frames,
        tolerance=args.tolerance,
        log=lambda s: print(s, file=sys.stderr),
    )
    text = report.markdown("python -m benchmarks segments " + " ".join(sys.argv[2:]))
    return emit_report(text, args.markdown)


def add_bench_segments_parser(bsub: Any) -> None:
    """Add ``segments`` to the ``bench`` sub-commands."""
    p = add_bench_parser(
        bsub, "segments", "piecewise-linear warped rays vs the chain at every sample", __doc__
    )
    p.add_argument("--size", type=image_size, default=(512, 512), help="image WxH")
    p.add_argument("--frames", type=positive_int, default=5, help="timed frames per setting")
    p.add_argument(
        "--tolerance", type=float, default=0.1, help="chord error of 'auto' segments (texels)"
    )
    p.add_argument("--markdown", metavar="FILE", help="also write the table to FILE")
    p.set_defaults(func=cmd_bench_segments)
