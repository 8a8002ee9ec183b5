"""``voxwarp bench interactive``: what the desktop GUI's frames cost while editing.

For each deformation family the GUI edits (none, mass-spring, ChainMail, wires,
lattice), one edit is made through :class:`voxwarp.editing.session.EditSession` on the bundled CT
(an element dragged and the model settled, a wire control point moved, a lattice node
moved), then the frame is timed the ways the GUI draws it:

* ``interactive``: half resolution with per-block checks (while dragging: the warp
  state changes every frame, no skip maps);
* ``rest, no maps``: full resolution with per-block checks (what a naive viewer draws
  when the motion stops);
* ``rest, maps``: full resolution with the deformed-space skip maps (what the GUI
  draws once its worker thread built them), and the seconds that build took;
* ``coarse``: half resolution and twice the sample distance (the GUI's first
  interactive level, :data:`voxwarp.render.adaptive_quality.START_LEVEL`);
* ``adaptive``: :data:`ORBIT_FRAMES` frames of an orbit (the camera turns before each),
  each drawn at the level :class:`~voxwarp.render.adaptive_quality.AdaptiveQuality`
  chose from the frame before (as the GUI does while the user drags, without the
  handles' overlay): their frames per second, beside the fixed half resolution's
  (``1000 / interactive``), and the level the last frame used.

Every time is also given as a ratio to the undeformed full-resolution frame measured
in the same run (these machines are shared; ratios hold better than times).

A second table (``--parts drag``, :mod:`voxwarp.bench.drag`) drags an element of the
mass-spring and ChainMail grids as the desktop window does at its default size (the 3D
view and three live slice views), with the model stepped on the drawing thread (the old
path) and on the model worker (the GUI's default) in alternating rounds: frames per
second while dragging and the seconds from the release to the full-quality frame.
"""

from __future__ import annotations

import argparse
import copy
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from voxwarp.bench.command import add_bench_parser, emit_report
from voxwarp.bench.drag import DRAG_FAMILIES, DRAG_SIZE, DragLoop, bench_drag, drag_markdown
from voxwarp.core.checks import image_size, positive_int
from voxwarp.editing.families.lattice import LatticeFamily
from voxwarp.editing.families.wires import WiresFamily
from voxwarp.editing.session import EditSession
from voxwarp.io.samples import DEFAULT_SAMPLE, load_sample, suggested_transfer_function
from voxwarp.render.adaptive_quality import (
    LEVELS,
    START_LEVEL,
    AdaptiveQuality,
    Quality,
    scene_at,
)
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.scene import Scene

FAMILIES = ("none", "massspring", "chainmail", "wires", "lattice")
#: frames of the adaptive orbit, and the degrees the camera turns before each
ORBIT_FRAMES = 24
ORBIT_DEG = 3.0


@dataclass
class InteractiveRow:
    """Timings (ms) of one deformation family."""

    family: str
    interactive_ms: float
    rest_blocks_ms: float
    rest_cells_ms: float
    maps_s: float
    edit: str
    coarse_ms: float = 0.0
    adaptive_fps: float = 0.0
    adaptive_level: Quality | None = None


@dataclass
class InteractiveReport:
    """The rows, the image size and the reference frame."""

    size: tuple[int, int]
    reference_ms: float
    rows: list[InteractiveRow] = field(default_factory=list)
    renderer: str = ""

    def markdown(self, command: str) -> str:
        """The table, with the command that produced it."""
        w, h = self.size
        ref = self.reference_ms
        lines = [
            f"`{command}` — {self.renderer}, {w}x{h}, bundled CT, median frame times;"
            f" ratios against the undeformed full-resolution frame ({ref:.0f} ms)",
            "",
            "| deformation | edit | interactive (half res) | at rest, block checks |"
            " at rest, skip maps | skip maps built in | coarse (half res, 2x distance) |"
            " dragging fps: half res / adaptive (last level) |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for r in self.rows:
            level = r.adaptive_level
            last = "-" if level is None else f"{level.scale:g}, {level.step_factor:g}x"
            lines.append(
                f"| {r.family} | {r.edit} | {r.interactive_ms:.0f} ms"
                f" ({r.interactive_ms / ref:.2f}x) | {r.rest_blocks_ms:.0f} ms"
                f" ({r.rest_blocks_ms / ref:.2f}x) | {r.rest_cells_ms:.0f} ms"
                f" ({r.rest_cells_ms / ref:.2f}x) | {r.maps_s:.2f} s | {r.coarse_ms:.0f} ms"
                f" ({r.coarse_ms / ref:.2f}x) | {1000 / r.interactive_ms:.1f} /"
                f" {r.adaptive_fps:.1f} ({last}) |"
            )
        return "\n".join(lines) + "\n"


def edit_family(session: EditSession, family: str) -> str:
    """Make the family's benchmark edit; returns what was done."""
    lo, hi = session.box
    size = hi - lo
    if family in ("massspring", "chainmail"):
        session.set_deformation(family, resolution=8)
        model = session.model
        assert model is not None
        shape = model.grid.shape
        idx = (shape[0] // 2, shape[1] // 2, shape[2] // 2)
        offset = (0.2 * size[0], 0.0, 0.1 * size[2])
        model.move(idx, offset)
        if family == "massspring":
            model.settle(max_steps=3000)
        session.model_moved()
        return f"middle element of 8³ dragged {np.linalg.norm(offset):.0f} mm"
    if family == "wires":
        session.set_deformation("wires")
        wires = session.adapter(WiresFamily)
        pts = wires.wires[0].modified.control_points.copy()
        pts[2, 0] += 0.25 * size[0]
        wires.set_wire_points(0, pts)
        wires.rebuild_if_stale()
        return f"control point 3 of 4 moved {0.25 * size[0]:.0f} mm"
    if family == "lattice":
        session.set_deformation("lattice", resolution=4)
        lattice = session.adapter(LatticeFamily)
        nodes = lattice.lattice_nodes
        assert nodes is not None
        nodes = nodes.copy()
        nodes[1, 1, 2, 0] += 0.2 * size[0]
        lattice.set_lattice_nodes(nodes)
        return f"node (1, 1, 2) of 3³ cells moved {0.2 * size[0]:.0f} mm"
    session.set_deformation("none")
    return "-"


def _adaptive_orbit(draw: Any, scene: Scene, camera: Any) -> tuple[float, Quality]:
    """Frames per second of :data:`ORBIT_FRAMES` orbit frames at adaptive quality (the
    controller starts afresh), and the level of the last frame."""
    aq = AdaptiveQuality()
    cam = copy.deepcopy(camera)
    total = 0.0
    for _ in range(ORBIT_FRAMES):
        cam.orbit(ORBIT_DEG, 0.0)
        q = aq.quality
        t = time.perf_counter()
        draw(scene_at(scene, q), q.scale, cam)
        dt = time.perf_counter() - t
        total += dt
        aq.frame_drawn(dt)
    return ORBIT_FRAMES / total, q


def _median_ms(fn: Any, frames: int) -> float:
    times = []
    for _ in range(frames):
        t = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t) * 1000)
    return statistics.median(times)


def bench_interactive(
    size: tuple[int, int] = (750, 830),
    frames: int = 5,
    families: tuple[str, ...] = FAMILIES,
    log: Any = None,
) -> InteractiveReport:
    """Time the GUI's frames per deformation family (see the module docstring)."""
    vol = load_sample(DEFAULT_SAMPLE)
    tf = suggested_transfer_function(DEFAULT_SAMPLE)
    with OffscreenRenderer(*size) as r:
        rr = r.renderer
        draw = _finished_draw(r)

        base = Scene(vol, transfer_function=tf, view=(-60, 20), zoom=1.2, jitter=False)
        draw(base, 1.0)
        report = InteractiveReport(size, _median_ms(lambda: draw(base, 1.0), frames))
        report.renderer = str(r.ctx.info.get("GL_RENDERER", ""))
        for family in families:
            session = EditSession(base.copy(warps=[]))
            edit = edit_family(session, family)
            scene = session.scene
            rr.warped_skip_maps = "never"
            draw(scene, 0.5)
            interactive = _median_ms(lambda s=scene: draw(s, 0.5), frames)
            coarse = scene_at(scene, LEVELS[START_LEVEL])
            half = LEVELS[START_LEVEL].scale
            draw(coarse, half)
            coarse_ms = _median_ms(lambda s=coarse, k=half: draw(s, k), frames)
            fps, level = _adaptive_orbit(draw, scene, scene.resolved_camera())
            rest_blocks = _median_ms(lambda s=scene: draw(s, 1.0), frames)
            rr.warped_skip_maps = "background"
            maps_s = 0.0
            if rr.needs_skip_maps(scene):
                draw(scene, 1.0)
                wanted = rr.skip_map_job()
                if wanted is not None:
                    t = time.perf_counter()
                    result = wanted[1]()
                    maps_s = time.perf_counter() - t
                    rr.install_skip_map(wanted[0], result)
            draw(scene, 1.0)
            rest_cells = _median_ms(lambda s=scene: draw(s, 1.0), frames)
            rr.warped_skip_maps = "auto"
            row = InteractiveRow(
                family, interactive, rest_blocks, rest_cells, maps_s, edit, coarse_ms, fps, level
            )
            report.rows.append(row)
            if log:
                log(
                    f"{family}: interactive {interactive:.0f} ms, coarse {coarse_ms:.0f} ms,"
                    f" adaptive drag {fps:.1f} fps, rest {rest_blocks:.0f} ms"
                    f" (blocks) / {rest_cells:.0f} ms (maps, built in {maps_s:.2f} s)"
                )
            session.close()
    return report


def bench_scripted_drag(
    size: tuple[int, int] = DRAG_SIZE,
    rounds: int = 5,
    resolution: int = 8,
    log: Any = None,
    families: tuple[str, ...] = DRAG_FAMILIES,
) -> str:
    """The scripted drag's table (:mod:`voxwarp.bench.drag`) on the bundled CT."""
    vol = load_sample(DEFAULT_SAMPLE)
    tf = suggested_transfer_function(DEFAULT_SAMPLE)
    base = Scene(vol, transfer_function=tf, view=(-60, 20), zoom=1.2, jitter=False)
    with OffscreenRenderer(*size) as r:
        rr = r.renderer
        draw = _finished_draw(r)

        with r.current():
            loop = DragLoop(rr, draw, size)
            draw(base, 1.0)
            reference = _median_ms(lambda: draw(base, 1.0), 5)
            rows = bench_drag(loop, base, rounds, resolution, families, log=log)
    return drag_markdown(rows, size, reference)


def cmd_bench_interactive(args: argparse.Namespace) -> int:
    """``voxwarp bench interactive``."""
    log = lambda s: print(s, file=sys.stderr)  # noqa: E731
    command = "voxwarp bench interactive" + "".join(
        f" {a}" for a in (sys.argv[3:] if sys.argv[1:3] == ["bench", "interactive"] else [])
    )
    parts = []
    if "frames" in args.parts:
        parts.append(
            bench_interactive(size=args.size, frames=args.frames, log=log).markdown(command)
        )
    if "drag" in args.parts:
        table = bench_scripted_drag(args.drag_size, args.rounds, args.resolution, log=log)
        parts.append(table if parts else f"`{command}`\n\n{table}")
    return emit_report("\n".join(parts), args.markdown)


def _parts(text: str) -> tuple[str, ...]:
    """``--parts``: a comma-separated subset of ``frames,drag``."""
    names = tuple(p.strip() for p in text.split(",") if p.strip())
    if not names or any(p not in ("frames", "drag") for p in names):
        raise argparse.ArgumentTypeError(
            f"parts are frames and/or drag (e.g. frames,drag); got {text!r}"
        )
    return names


def add_bench_interactive_parser(bsub: Any) -> None:
    """Add ``interactive`` to the ``bench`` sub-commands."""
    p = add_bench_parser(
        bsub, "interactive", "the GUI's frame costs while editing each deformation family", __doc__
    )
    p.add_argument("--size", type=image_size, default=(750, 830), help="viewport WxH")
    p.add_argument("--frames", type=positive_int, default=5, help="timed frames per case")
    p.add_argument(
        "--parts",
        type=_parts,
        default=("frames", "drag"),
        help="what to run: frames (the frame costs per family), drag (the scripted drag,"
        " model on the drawing thread vs the model worker); default frames,drag",
    )
    p.add_argument(
        "--drag-size",
        type=image_size,
        default=DRAG_SIZE,
        help="WxH of the 3D view and of each slice view in the scripted drag (default"
        f" {DRAG_SIZE[0]}x{DRAG_SIZE[1]}: the default window's four-up layout)",
    )
    p.add_argument(
        "--rounds", type=positive_int, default=5, help="scripted drags per family and path"
    )
    p.add_argument(
        "--resolution",
        type=positive_int,
        default=8,
        help="elements per axis of the dragged grid (default 8, the GUI's)",
    )
    p.add_argument("--markdown", metavar="FILE", help="also write the table to FILE")
    p.set_defaults(func=cmd_bench_interactive)


def _finished_draw(r: OffscreenRenderer) -> Callable[..., None]:
    """``draw(scene, scale, camera=None)``: one frame of ``r`` at ``scale`` of its size,
    waited for (``ctx.finish``), as the GUI's viewport draws it."""

    def draw(scene: Scene, scale: float, camera: Any = None) -> None:
        with r.current():
            r.renderer.draw_scaled(scene, r.framebuffer, None, camera, scale)
            r.ctx.finish()

    return draw
