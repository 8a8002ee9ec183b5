"""``python -m benchmarks support``: warped rays that pay for the chain only inside its support.

Per bundled scan (``--volumes``, default the MRI head ``colin27`` and the CT ``stent``),
at ``--size`` in dvr with the scan's suggested transfer function, three deformations
are drawn with the warp chain at every sample (the old path,
``Renderer.support_skipping = False``) and with support skipping (the default): a
local ChainMail drag (16³ grid, the centre element moved 15 mm along x, relaxed), the
same ChainMail with nothing moved (an identity warp), and a settled 16³ mass-spring
drag with the grid's corners fixed (everything moves). With support skipping, the chain
runs either within the box around the support bricks (``Renderer.support_ranges =
False``, "support box") or between each ray's first and last crossing of the support's
surface (the default, "per-ray ranges"). Frames of every setting and of
the undeformed scene are interleaved per round and medians taken; each is given as a
ratio to the undeformed frame of the same run, with the image difference between the
two paths (max, /255), the share of the ray box's bricks in the support, and the load
average before and after.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from voxwarp.bench.command import add_bench_parser, emit_report
from voxwarp.core.checks import image_size, positive_int
from voxwarp.deform.elements.chainmail import ChainMail
from voxwarp.deform.elements.grid import ElementGrid
from voxwarp.deform.elements.massspring import MassSpring
from voxwarp.deform.support import chain_support
from voxwarp.deform.warp import Warp
from voxwarp.io.samples import load_sample, suggested_transfer_function
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.render.skipping.support import BRICK_VOXELS, TOLERANCE_VOXELS
from voxwarp.scene import Scene

VOLUMES = ("colin27", "stent")
CASES = ("chainmail drag", "chainmail identity", "massspring settled")
DRAG_MM = 15.0
#: the chain at every sample; within the support's box; between each ray's crossings
SETTINGS = ("old", "box", "ranges")


def _chainmail(vol: Any, drag: bool) -> Warp:
    cm = ChainMail(ElementGrid(vol, 16))
    if drag:
        cm.move((8, 8, 8), (DRAG_MM, 0.0, 0.0))
        cm.relax(20)
    return cm.warp()


def _massspring(vol: Any) -> Warp:
    ms = MassSpring(ElementGrid(vol, 16, anchor="corners"))
    ms.move((8, 8, 8), (DRAG_MM, 0.0, 0.0))
    ms.settle(max_steps=3000)
    return ms.warp()


WARPS: dict[str, Callable[[Any], Warp]] = {
    "chainmail drag": lambda v: _chainmail(v, True),
    "chainmail identity": lambda v: _chainmail(v, False),
    "massspring settled": _massspring,
}


@dataclass
class SupportRow:
    """One deformation of one scan: cost of each path and what the support covers."""

    volume: str
    case: str
    old: float
    box: float
    new: float
    max_diff: float
    bricks: float
    plan: str


@dataclass
class SupportReport:
    """The rows, and what they were measured on."""

    size: tuple[int, int]
    frames: int
    renderer: str = ""
    reference_ms: dict[str, float] = field(default_factory=dict)
    load: list[str] = field(default_factory=list)
    rows: list[SupportRow] = field(default_factory=list)

    def markdown(self, command: str) -> str:
        """The table, headed by the command and the load averages."""
        w, h = self.size
        refs = ", ".join(f"{k} {v:.0f} ms" for k, v in self.reference_ms.items())
        lines = [
            f"`{command}` — {self.renderer}, {w}x{h}, dvr, median of {self.frames} interleaved"
            f" frames; cost = frame / undeformed frame of the same run ({refs}); load"
            f" average before / after: {' / '.join(self.load)}",
            "",
            "| scan | deformation | chain at every sample | support box | per-ray ranges"
            " | ranges / old | max diff (/255) | bricks in support | path |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for r in self.rows:
            lines.append(
                f"| {r.volume} | {r.case} | {r.old:.2f}x | {r.box:.2f}x | {r.new:.2f}x"
                f" | {r.new / r.old:.2f}"
                f" | {r.max_diff:.0f} | {r.bricks:.0%} | {r.plan} |"
            )
        return "\n".join(lines) + "\n"


def _load() -> str:
    with open("/proc/loadavg") as f:
        return " ".join(f.read().split()[:3])


def _bricks(scene: Scene) -> float:
    voxel = float(np.min(scene.volume.spacing))
    lo, hi = scene.ray_bounds()
    smap = chain_support(scene.warps, lo, hi, BRICK_VOXELS * voxel, TOLERANCE_VOXELS * voxel)
    return smap.fraction


def _volume_rows(ctx: Any, name: str, size: tuple, frames: int, report: SupportReport) -> None:
    """Time the undeformed scan and each deformation, both paths, interleaved. Each scene
    has a renderer of its own on ``ctx``: a renderer keeps the deformed-space skip maps of
    one warp state, so interleaving states on one would rebuild them every frame."""
    vol = load_sample(name)
    base = Scene(vol, transfer_function=suggested_transfer_function(name), jitter=False)
    scenes = {"undeformed": base, **{c: base.copy(warps=[WARPS[c](vol)]) for c in CASES}}
    renderers = {c: OffscreenRenderer(*size, ctx=ctx) for c in scenes}

    def frame(case: str, setting: str) -> float:
        r = renderers[case]
        r.renderer.support_skipping = setting != "old"
        r.renderer.support_ranges = setting == "ranges"
        with r.current():
            t = time.perf_counter()
            r.renderer.draw(scenes[case], r.framebuffer)
            r.ctx.finish()
            return (time.perf_counter() - t) * 1000

    try:
        images, plans = {}, {}
        for c, r in renderers.items():
            r.renderer.warped_skip_maps = "always"
            r.renderer.support_maps = "always"
            for setting in SETTINGS:
                r.renderer.support_skipping = setting != "old"
                r.renderer.support_ranges = setting == "ranges"
                images[c, setting] = r.render(scenes[c])[..., :3].astype(int)
                plans[c, setting] = r.renderer.last_support
        times: dict[Any, list[float]] = {}
        for _ in range(frames):
            times.setdefault("ref", []).append(frame("undeformed", "ranges"))
            for c in CASES:
                for setting in SETTINGS:
                    times.setdefault((c, setting), []).append(frame(c, setting))
    finally:
        for r in renderers.values():
            r.release()
    ref = statistics.median(times["ref"])
    report.reference_ms[name] = ref
    for c in CASES:
        old, box, new = (statistics.median(times[c, s]) / ref for s in SETTINGS)
        diff = float(np.abs(images[c, "ranges"] - images[c, "old"]).max())
        bricks = _bricks(scenes[c])
        report.rows.append(SupportRow(name, c, old, box, new, diff, bricks, plans[c, "ranges"]))


def bench_support(
    size: tuple[int, int] = (512, 512),
    frames: int = 5,
    volumes: tuple[str, ...] = VOLUMES,
    log: Any = None,
) -> SupportReport:
    """Time both paths per scan and deformation (module docstring)."""
    report = SupportReport(size, frames, load=[_load()])
    with OffscreenRenderer(8, 8) as r:
        report.renderer = str(r.ctx.info.get("GL_RENDERER"))
        for name in volumes:
            _volume_rows(r.ctx, name, size, frames, report)
            if log:
                for row in report.rows[-len(CASES) :]:
                    log(f"{name} {row.case}: old {row.old:.2f}x, new {row.new:.2f}x")
    report.load.append(_load())
    return report


def cmd_bench_support(args: argparse.Namespace) -> int:
    """``python -m benchmarks support``."""
    report = bench_support(
        size=args.size,
        frames=args.frames,
        volumes=tuple(args.volumes.split(",")),
        log=lambda s: print(s, file=sys.stderr),
    )
    text = report.markdown("python -m benchmarks support " + " ".join(sys.argv[2:]))
    return emit_report(text, args.markdown)


def add_bench_support_parser(bsub: Any) -> None:
    """Add ``support`` to the ``bench`` sub-commands."""
    p = add_bench_parser(
        bsub, "support", "warped rays straight outside the chain's support vs everywhere", __doc__
    )
    p.add_argument("--size", type=image_size, default=(512, 512), help="image WxH")
    p.add_argument("--frames", type=positive_int, default=5, help="timed frames per setting")
    p.add_argument("--volumes", default=",".join(VOLUMES), help="bundled scans, comma-separated")
    p.add_argument("--markdown", metavar="FILE", help="also write the table to FILE")
    p.set_defaults(func=cmd_bench_support)
