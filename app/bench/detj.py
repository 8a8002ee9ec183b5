"""``voxwarp bench detj``: what the det J overlay costs, in 3D and in slices (issue 32).

For each volume (the MRI head ``sample:colin27`` and the CT ``sample:stent``), each
deformation (a settled mass-spring push drawn through its offset field, a wire bend
drawn through its wire field) and each image size, the run times in turns, in the same
rounds: the full-resolution 3D frame in ``dvr`` and in ``mip`` without and with the
overlay (:attr:`~voxwarp.render.raycaster.Renderer.jacobian_overlay`: one chain
Jacobian and determinant per visible sample, in GLSL), and one axial slice view
(``render_slice``) without and with ``overlay="jacobian"`` (det J of the chain at
every pixel centre on the CPU, blended with its legend). The tables give medians over
the rounds (one warm-up round left out) and the ratio of each frame with the overlay to
the same frame without it.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from voxwarp.bench.command import add_bench_parser, emit_report
from voxwarp.bench.slices import _frame, _interleaved, _names, _scenes, _sizes
from voxwarp.core.checks import positive_int
from voxwarp.core.slice_plane import plane_names
from voxwarp.render.jacobian_overlay import JacobianOverlay
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.scene import Scene

VOLUMES: tuple[str, ...] = ("colin27", "stent")
DEFORMATIONS: tuple[str, ...] = ("mass-spring", "wires")
SIZES: tuple[int, ...] = (512,)
#: the 3D modes timed
MODES: tuple[str, ...] = ("dvr", "mip")


@dataclass
class DetJRow:
    """Median times (ms) of one volume, deformation, size and view, without and with
    the overlay."""

    volume: str
    deformation: str
    size: int
    view: str
    plain_ms: float
    overlay_ms: float

    @property
    def ratio(self) -> float:
        """With the overlay / without it."""
        return self.overlay_ms / self.plain_ms


@dataclass
class DetJReport:
    """Every row, the rounds and the renderer."""

    rounds: int
    rows: list[DetJRow] = field(default_factory=list)
    renderer: str = ""

    def markdown(self, command: str) -> str:
        """The table, with the command that produced it."""
        lines = [
            f"`{command}` — {self.renderer}, median of {self.rounds} interleaved rounds"
            " after a warm-up; ratio: the same frame with the det J overlay / without",
            "",
            "| volume | deformation | size | view | without | with det J | ratio |",
            "|---|---|---|---|---|---|---|",
        ]
        for r in self.rows:
            lines.append(
                f"| {r.volume} | {r.deformation} | {r.size}² | {r.view} |"
                f" {r.plain_ms:.1f} ms | {r.overlay_ms:.1f} ms | {r.ratio:.2f}x |"
            )
        return "\n".join(lines) + "\n"


def _with_overlay(r: OffscreenRenderer, on: bool, fn: Callable[[], Any]) -> Any:
    r.renderer.jacobian_overlay = JacobianOverlay() if on else None
    try:
        return fn()
    finally:
        r.renderer.jacobian_overlay = None


def _cases(r: OffscreenRenderer, scene: Scene, plane: str) -> dict[str, Callable[[], Any]]:
    cases: dict[str, Callable[[], Any]] = {}
    for mode in MODES:
        s = scene.copy(mode=mode)
        for on in (False, True):
            cases[f"3D {mode} {on}"] = lambda s=s, on=on: _with_overlay(r, on, lambda: _frame(r, s))
    for on in (False, True):
        overlay = ("jacobian",) if on else ()
        cases[f"slice {on}"] = lambda o=overlay: r.render_slice(scene, plane, overlay=o)
    return cases


def bench_detj(
    volumes: Sequence[str] = VOLUMES,
    sizes: Sequence[int] = SIZES,
    rounds: int = 5,
    deformations: Sequence[str] = DEFORMATIONS,
    log: Callable[[str], Any] | None = None,
) -> DetJReport:
    """Time the det J overlay against the same frames without it (module docstring)."""
    report = DetJReport(rounds)
    for name in volumes:
        vol, scenes = _scenes(name, deformations)
        plane = plane_names(vol.space)[0]
        for n in sizes:
            with OffscreenRenderer(n, n) as r:
                report.renderer = str(r.ctx.info.get("GL_RENDERER", ""))
                for d, scene in scenes.items():
                    ms = _interleaved(_cases(r, scene, plane), rounds)
                    views = [(f"3D {m}", f"3D {m} False", f"3D {m} True") for m in MODES]
                    views.append((f"slice ({plane})", "slice False", "slice True"))
                    for view, off, on in views:
                        row = DetJRow(name, d, n, view, ms[off], ms[on])
                        report.rows.append(row)
                        if log:
                            log(f"{name} {d} {n}² {view}: {row.ratio:.2f}x")
    return report


def cmd_bench_detj(args: argparse.Namespace) -> int:
    """``voxwarp bench detj``."""
    report = bench_detj(
        volumes=args.volumes,
        sizes=args.sizes,
        rounds=args.rounds,
        log=lambda s: print(s, file=sys.stderr),
    )
    argv = sys.argv[3:] if sys.argv[1:3] == ["bench", "detj"] else []
    return emit_report(report.markdown(" ".join(["voxwarp bench detj", *argv])), args.markdown)


def add_bench_detj_parser(bsub: Any) -> None:
    """Add ``detj`` to the ``bench`` sub-commands."""
    p = add_bench_parser(bsub, "detj", "det J overlay cost in 3D and slices", __doc__)
    p.add_argument("--volumes", type=_names, default=VOLUMES, help="samples, e.g. colin27,stent")
    p.add_argument("--sizes", type=_sizes, default=SIZES, help="square image sides, e.g. 512,256")
    p.add_argument("--rounds", type=positive_int, default=5, help="timed rounds per case")
    p.add_argument("--markdown", metavar="FILE", help="also write the table to FILE")
    p.set_defaults(func=cmd_bench_detj)
