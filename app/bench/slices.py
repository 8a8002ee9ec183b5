"""``voxwarp bench slices``: what a slice view costs against the 3D frame (issue 21).

For each volume (the MRI head ``sample:colin27`` and the CT ``sample:stent``) and each
deformation (none; a settled mass-spring push, drawn through its offset field; a wire
bend, drawn through its wire field), at each image size, the run times in turns:

* ``3D``: one full-resolution DVR frame of the scene (the reference);
* ``slice``: one slice view as the GUI draws it (``render_slice``: the plane through
  the warp chain, read back, coloured with the window), the mean over the three
  orthogonal planes;
* ``values``: the same three planes' data alone (the GPU draw and the float read-back,
  no colouring on the CPU);
* ``slab``: the axial (or z) view as a 10 mm MIP slab.

and, per volume and size, a drag: one mass-spring step of a held element through
:class:`~voxwarp.editing.session.EditSession` (the model's new state re-uploaded as a
new warp, whose textures the next draw makes) alone, then with the three slice views,
then with the 3D frame (without the deformed-space skip maps, as the GUI draws while the model
moves), against the undeformed 3D frame. Every case is timed once per round, the cases
of a volume and size alternating, so the shared machine's load falls on all of them
alike; the tables give medians over the rounds (one warm-up round, which compiles the
shaders, left out) and ratios against the 3D frame measured in the same rounds.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from voxwarp.bench.command import add_bench_parser, emit_report
from voxwarp.core.checks import positive_int
from voxwarp.core.slice_plane import SlicePlane, plane_names
from voxwarp.core.volume import Volume
from voxwarp.deform.elements.grid import ElementGrid
from voxwarp.deform.elements.massspring import MassSpring
from voxwarp.deform.warp import Warp
from voxwarp.deform.wires.field import Wire, WireDeformer
from voxwarp.editing.session import EditSession
from voxwarp.io.samples import load_sample, suggested_transfer_function
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.scene import Scene

VOLUMES: tuple[str, ...] = ("colin27", "stent")
DEFORMATIONS: tuple[str, ...] = ("undeformed", "mass-spring", "wires")
SIZES: tuple[int, ...] = (512, 256)
#: slab thickness (mm) of the MIP case
SLAB_MM = 10.0


@dataclass
class SliceRow:
    """Median times (ms) of one volume, deformation and size."""

    volume: str
    deformation: str
    size: int
    frame_ms: float
    slice_ms: float
    slab_ms: float
    values_ms: float = 0.0

    @property
    def slice_ratio(self) -> float:
        """One slice view / the 3D frame."""
        return self.slice_ms / self.frame_ms

    @property
    def slab_ratio(self) -> float:
        """The 10 mm MIP slab / a thin slice of the same plane."""
        return self.slab_ms / self.slice_ms


@dataclass
class DragRow:
    """Median times (ms) of one drag frame: a model step, then three slices or 3D."""

    volume: str
    size: int
    frame_ms: float
    drag_slices_ms: float
    drag_frame_ms: float
    step_ms: float = 0.0


@dataclass
class SlicesReport:
    """Every row, the rounds and the renderer."""

    rounds: int
    rows: list[SliceRow] = field(default_factory=list)
    drags: list[DragRow] = field(default_factory=list)
    renderer: str = ""

    def ratio(self, volume: str, deformation: str, size: int) -> float | None:
        """One slice view / the 3D frame for that case, or None if not measured."""
        for r in self.rows:
            if (r.volume, r.deformation, r.size) == (volume, deformation, size):
                return r.slice_ratio
        return None

    def markdown(self, command: str) -> str:
        """The two tables, with the command that produced them."""
        lines = [
            f"`{command}` — {self.renderer}, median of {self.rounds} interleaved rounds"
            " after a warm-up; ratios against the full-resolution DVR frame of the same"
            " scene and size",
            "",
            "| volume | deformation | size | 3D frame | one slice view | slice / 3D |"
            " of which GPU + read-back |"
            f" {SLAB_MM:g} mm MIP slab | slab / thin slice |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for r in self.rows:
            lines.append(
                f"| {r.volume} | {r.deformation} | {r.size}² | {r.frame_ms:.0f} ms |"
                f" {r.slice_ms:.1f} ms | {r.slice_ratio:.3f}x | {r.values_ms:.1f} ms |"
                f" {r.slab_ms:.1f} ms | {r.slab_ratio:.1f}x |"
            )
        lines += [
            "",
            "While dragging (mass-spring: one step of a held element, the warp re-made),"
            " against the undeformed 3D frame:",
            "",
            "| volume | size | step alone | step + three slice views | / 3D frame |"
            " step + 3D frame | / 3D frame |",
            "|---|---|---|---|---|---|---|",
        ]
        for d in self.drags:
            lines.append(
                f"| {d.volume} | {d.size}² | {d.step_ms:.0f} ms | {d.drag_slices_ms:.0f} ms |"
                f" {d.drag_slices_ms / d.frame_ms:.2f}x | {d.drag_frame_ms:.0f} ms |"
                f" {d.drag_frame_ms / d.frame_ms:.2f}x |"
            )
        return "\n".join(lines) + "\n"


def massspring_warps(vol: Volume) -> list[Warp]:
    """A settled push of a 6³ mass-spring: bottom fixed, the top's middle moved +x by a
    fifth of the box (its warp: the offset field)."""
    lo, hi = vol.bounds
    ms = MassSpring(ElementGrid(vol, shape=6, anchor="corners"))
    ms.fix([(i, j, 0) for i in range(6) for j in range(6)])
    top = [(i, j, 4) for i in range(1, 5) for j in range(1, 5)]
    ms.move(top, np.tile([0.2 * (hi[0] - lo[0]), 0.0, 0.0], (len(top), 1)))
    ms.settle(max_steps=2000)
    return [ms.warp()]


def wire_warps(vol: Volume) -> list[Warp]:
    """A wire along y through the centre, its middle bent +x by a sixth of the box."""
    lo, hi = vol.bounds
    c = vol.center
    ys = np.linspace(lo[1] + 0.1 * (hi[1] - lo[1]), hi[1] - 0.1 * (hi[1] - lo[1]), 4)
    dx = (hi[0] - lo[0]) / 6
    base = [[c[0], y, c[2]] for y in ys]
    bent = [[c[0] + s, y, c[2]] for y, s in zip(ys, (0.0, dx, dx, 0.0), strict=True)]
    radius = 0.3 * float(np.max(hi - lo))
    wd = WireDeformer(vol, [Wire(base, bent, radius=radius, ends="smooth", sides="rigid")])
    wd.build()
    return [wd.warp()]


def _interleaved(cases: dict[str, Callable[[], Any]], rounds: int) -> dict[str, float]:
    """Median milliseconds of each case over ``rounds`` rounds (each round runs every
    case once, in turn), after one warm-up round."""
    times: dict[str, list[float]] = {k: [] for k in cases}
    for n in range(rounds + 1):
        for name, fn in cases.items():
            t = time.perf_counter()
            fn()
            if n:
                times[name].append((time.perf_counter() - t) * 1000)
    return {k: statistics.median(v) for k, v in times.items()}


def _scenes(name: str, deformations: Sequence[str]) -> tuple[Volume, dict[str, Scene]]:
    vol = load_sample(name)
    base = Scene(
        vol, transfer_function=suggested_transfer_function(name), view=(-60, 20), jitter=False
    )
    makers = {"undeformed": lambda v: [], "mass-spring": massspring_warps, "wires": wire_warps}
    return vol, {d: base.copy(warps=makers[d](vol)) for d in deformations}


def _frame(r: OffscreenRenderer, scene: Scene) -> None:
    with r.current():
        r.renderer.draw_scaled(scene, r.framebuffer, None, None, 1.0)
        r.ctx.finish()


def _slice_rows(
    r: OffscreenRenderer, vol: Volume, scenes: dict[str, Scene], rounds: int
) -> list[SliceRow]:
    planes = plane_names(vol.space)
    n = r.size[0]
    cases: dict[str, Callable[[], Any]] = {}
    for d, scene in scenes.items():
        cases[f"{d} 3D"] = lambda s=scene: _frame(r, s)
        cases[f"{d} slices"] = lambda s=scene: [r.render_slice(s, p, size=r.size) for p in planes]
        cases[f"{d} slab"] = lambda s=scene: r.render_slice(
            s, planes[0], size=r.size, slab_mm=SLAB_MM
        )
        cases[f"{d} values"] = lambda s=scene: _values(r, s, planes)
    ms = _interleaved(cases, rounds)
    return [
        SliceRow(
            vol.name,
            d,
            n,
            ms[f"{d} 3D"],
            ms[f"{d} slices"] / 3,
            ms[f"{d} slab"],
            ms[f"{d} values"] / 3,
        )
        for d in scenes
    ]


def _values(r: OffscreenRenderer, scene: Scene, planes: Sequence[str]) -> None:
    """The three planes' data alone (GPU draw and read-back, no colouring)."""
    size = r.size
    with r.current():
        for p in planes:
            m = SlicePlane.named(p, scene.deformed_bounds()).pixel_to_world(size)
            r.renderer.slice_values(scene, m, size)


def _drag_row(r: OffscreenRenderer, vol: Volume, scene: Scene, rounds: int) -> DragRow:
    """One mass-spring step per drawn frame, as the GUI's timer runs a held drag, and
    the undeformed 3D frame of ``scene`` as the reference."""
    session = EditSession(scene.copy(warps=[]))
    try:
        session.set_deformation("massspring", resolution=8)
        model = session.model
        assert model is not None
        shape = model.grid.shape
        lo, hi = session.box
        model.move((shape[0] // 2, shape[1] // 2, shape[2] // 2), 0.2 * (hi - lo))
        session.model_moved()
        planes = plane_names(vol.space)

        def step_slices() -> None:
            session.single_step()
            for p in planes:
                r.render_slice(session.scene, p)

        def step_frame() -> None:
            session.single_step()
            _frame(r, session.scene)

        cases = {
            "3D": lambda: _frame(r, scene),
            "step": session.single_step,
            "slices": step_slices,
            "frame": step_frame,
        }
        r.renderer.warped_skip_maps = "never"  # as the GUI draws while the model moves
        ms = _interleaved(cases, rounds)
    finally:
        r.renderer.warped_skip_maps = "auto"
        session.close()
    return DragRow(vol.name, r.size[0], ms["3D"], ms["slices"], ms["frame"], ms["step"])


def bench_slices(
    volumes: Sequence[str] = VOLUMES,
    sizes: Sequence[int] = SIZES,
    rounds: int = 5,
    deformations: Sequence[str] = DEFORMATIONS,
    drag: bool = True,
    log: Callable[[str], Any] | None = None,
) -> SlicesReport:
    """Time slice views against the 3D frame (see the module docstring)."""
    report = SlicesReport(rounds)
    for name in volumes:
        vol, scenes = _scenes(name, deformations)
        for n in sizes:
            with OffscreenRenderer(n, n) as r:
                report.renderer = str(r.ctx.info.get("GL_RENDERER", ""))
                rows = _slice_rows(r, vol, scenes, rounds)
                report.rows += rows
                if drag:
                    report.drags.append(_drag_row(r, vol, scenes["undeformed"], rounds))
            if log:
                for row in rows:
                    log(
                        f"{name} {row.deformation} {n}²: 3D {row.frame_ms:.0f} ms, slice"
                        f" {row.slice_ms:.1f} ms ({row.slice_ratio:.3f}x), slab"
                        f" {row.slab_ratio:.1f}x thin"
                    )
    return report


def cmd_bench_slices(args: argparse.Namespace) -> int:
    """``voxwarp bench slices``."""
    report = bench_slices(
        volumes=args.volumes,
        sizes=args.sizes,
        rounds=args.rounds,
        log=lambda s: print(s, file=sys.stderr),
    )
    argv = sys.argv[3:] if sys.argv[1:3] == ["bench", "slices"] else []
    return emit_report(report.markdown(" ".join(["voxwarp bench slices", *argv])), args.markdown)


def _names(text: str) -> tuple[str, ...]:
    names = tuple(v.strip() for v in text.split(",") if v.strip())
    if not names or any(n not in VOLUMES for n in names):
        raise argparse.ArgumentTypeError(f"choose volumes from {','.join(VOLUMES)}; got {text!r}")
    return names


def _sizes(text: str) -> tuple[int, ...]:
    try:
        return tuple(positive_int(v) for v in text.split(","))
    except (argparse.ArgumentTypeError, ValueError) as exc:
        raise argparse.ArgumentTypeError(
            f"sizes: pixels a side, e.g. 512,256; got {text!r}"
        ) from exc


def add_bench_slices_parser(bsub: Any) -> None:
    """Add ``slices`` to the ``bench`` sub-commands."""
    p = add_bench_parser(bsub, "slices", "slice views' cost against the 3D frame", __doc__)
    p.add_argument("--volumes", type=_names, default=VOLUMES, help="samples, e.g. colin27,stent")
    p.add_argument("--sizes", type=_sizes, default=SIZES, help="square image sides, e.g. 512,256")
    p.add_argument("--rounds", type=positive_int, default=5, help="timed rounds per case")
    p.add_argument("--markdown", metavar="FILE", help="also write the tables to FILE")
    p.set_defaults(func=cmd_bench_slices)
