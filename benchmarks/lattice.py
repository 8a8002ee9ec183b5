"""``python -m benchmarks lattice``: trilinear lattices against 4x4 matrices, in one run.

Knuth, Kohlhammer and Kuijper ("Embedding hierarchical deformation within a realtime
scene graph", GRAPP 2010) replace the 4x4 matrices of a scene graph by grids of trilinear
cells, compose the transforms of every root-to-leaf path into one per geometry leaf
(:func:`voxwarp.deform.lattice.scene_graph.compose_scene`) and apply that one transform in the
vertex
shader (:class:`voxwarp.render.mesh_pass.MeshRenderer`); their evaluation found the trilinear
version at 75-80 % of the linear frame rate. This benchmark measures the same two
things here, every ratio against a linear reference timed in the same run:

1. *Vertex throughput*: one torus of about ``triangles`` triangles
   (:func:`voxwarp.core.mesh.torus_mesh`, as :func:`benchmarks.lattice.bench_mesh_throughput`)
   drawn
   at ``size`` under the twist + bend lattice of ``benchmarks.lattice.bend_grid`` at each
   cell count (``cells`` per axis), against the same mesh drawn with a 4x4 (identity)
   matrix. Per cell count: both normal methods (``normal``: the direct J n; ``tangent``:
   two tangents through J, crossed) with exact positions, and ``normal`` with the hardware trilinear
   position fetch. Each row alternates lattice and linear frames (the order flips every
   frame, each frame bound by ``ctx.finish()``) after one warm-up draw of each, and
   reports the medians and FPS ratio = linear median / lattice median (= lattice FPS /
   linear FPS). The *vertex stage* rows repeat this with ``GL_RASTERIZER_DISCARD``
   (no rasterisation, no fragments). A cross-check row runs
   :func:`benchmarks.lattice.bench_mesh_throughput` itself once (it times each case in a
   block, not alternated).
2. *Composition*: a scene graph of ``objects`` small meshes (one shared 48-triangle
   :func:`voxwarp.core.mesh.uv_sphere`) under nested nodes, root -> groups -> objects: the root
   and every group carry a twist + bend lattice (:data:`ROOT_CELLS`, :data:`GROUP_CELLS`
   cells per axis), every object a 4x4 (rotation, scale, translation into its group's
   box). The linear graph is the same with the root's and groups' lattices replaced by
   4x4 matrices (identity for the root, the group's translation for a group). A frame is
   what an animated scene pays: :func:`~voxwarp.deform.lattice.scene_graph.compose_scene` (the
   propagation world -> leaves, timed alone), wrapping each composed transform in a
   :class:`~voxwarp.core.mesh.MeshInstance` (as
   :func:`voxwarp.core.mesh.instances_from_scene_graph` does),
   and drawing the instances (``MeshRenderer.draw`` + ``ctx.finish()``; a new composed
   lattice is a new node texture, so this includes their uploads and the release of the
   previous frame's). The *static* draw redraws the same instances (textures cached): a
   scene whose composition did not change. Frames of the two graphs alternate.

3. *Lattice over a volume* (:mod:`benchmarks.lattice_inverse`): the accuracy of the
   volume's inverse (Newton to a tolerance, fixed steps, the baked seed) over random
   non-folding lattices beside its render cost, against the baked seed and the former
   fixed 2 steps in the same run (``--inverse-frames``; ``--inverse-only``: this alone).
4. *Linear fast path* (GRAPP 2010, section 4.1, last paragraph): the torus of section 1
   under an affine lattice, drawn by the trilinear program and by the ``LINEAR`` one that
   :class:`~voxwarp.render.mesh_pass.MeshRenderer` picks for it, frames alternated.
5. *Lattice normals* (:mod:`benchmarks.lattice_normals`, GRAPP 2010 section 4.2): the
   direct and the tangent-space normals against the exact normals of the smooth shape a
   lattice samples, and their seams at cell faces (not timed).

The image is ``size`` (default 512x512), ``frames`` timed frames per configuration
(default 5), medians everywhere.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import platform
import shlex
import statistics
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from benchmarks.lattice_inverse import DEFAULT_FRAMES as INVERSE_FRAMES
from benchmarks.lattice_inverse import bench_inverse
from benchmarks.lattice_normals import markdown_lines as normals_markdown
from benchmarks.lattice_normals import normals_study
from benchmarks.shared import best_times
from voxwarp.bench.command import emit_report
from voxwarp.core.camera import Camera
from voxwarp.core.mesh import DEFAULT_NORMAL_METHOD, MeshInstance
from voxwarp.core.timing import cpu_count, load_average
from voxwarp.deform.lattice.trilinear import TrilinearGrid
from voxwarp.render.mesh_pass import POSITIONS, MeshRenderer
from voxwarp.teaching.papers import lattice_ratio_range

#: the paper's scene size (triangles) and image
DEFAULT_TRIANGLES = 1_500_000
DEFAULT_SIZE: tuple[int, int] = (512, 512)
#: lattice cells per axis timed in section 1
DEFAULT_CELLS: tuple[int, ...] = (1, 4, 16)
DEFAULT_OBJECTS = 2000
DEFAULT_FRAMES = 5
#: limits of the options
MIN_TRIANGLES, MAX_TRIANGLES = 100, 20_000_000
MAX_OBJECTS = 100_000
MAX_CELLS = 64
#: normal methods of the lattice (GRAPP 2010, section 4.2)
NORMAL_METHODS: tuple[str, ...] = ("normal", "tangent")
#: section 1 rows per cell count: (stage, normal method, position)
THROUGHPUT_CONFIGS: tuple[tuple[str, str, str], ...] = (
    ("frame", "normal", "exact"),
    ("frame", "tangent", "exact"),
    ("frame", "normal", "hardware"),
    ("vertex", "normal", "exact"),
    ("vertex", "tangent", "exact"),
)
#: section 4: cells per axis of the affine lattice timed through both programs
FAST_PATH_CELLS = 4
#: section 4: the affine lattice's linear part (a shear with non-uniform scale)
FAST_PATH_MATRIX: tuple[tuple[float, ...], ...] = (
    (1.2, 0.3, 0.0),
    (-0.1, 0.9, 0.2),
    (0.1, 0.0, 1.1),
)
#: the torus of section 1 and the box its lattice acts on (bench_mesh_throughput's)
TORUS_RADII = (1.0, 0.35)
TORUS_BOX: tuple[tuple[float, float, float], tuple[float, float, float]] = (
    (-1.4, -1.4, -0.4),
    (1.4, 1.4, 0.4),
)
#: camera view (azimuth, elevation) of both sections
VIEW: tuple[float, float] = (30.0, 35.0)
#: section 2: cells per axis of the root's and the groups' lattices
ROOT_CELLS = 4
GROUP_CELLS = 4
#: section 2: the object mesh (uv_sphere rows x cols: 48 triangles, 26 vertices)
OBJECT_RADIUS = 0.1
OBJECT_ROWS, OBJECT_COLS = 4, 8
#: section 2: distance of object slots in a group, gap between groups
SLOT = 0.3
GROUP_GAP = 0.6
#: the variants of section 2
VARIANTS: tuple[str, ...] = ("trilinear", "linear")
#: the paper's result (GRAPP 2010, section 6 table): trilinear at 76.4-80.6 % of the
#: linear frame rate (its text rounds them to 75-80 %)
PAPER_RATIO = lattice_ratio_range()


# ---------------------------------------------------------------------- rows
@dataclass
class ThroughputRow:
    """Section 1: one lattice configuration alternated with the 4x4 reference."""

    cells: int
    stage: str  # "frame" (full draw) or "vertex" (rasterisation discarded)
    normal_method: str
    position: str  # "exact" or "hardware"
    frames: int
    lattice_ms: float  # median
    lattice_min_ms: float
    linear_ms: float  # median of the linear frames alternated with this row's
    linear_min_ms: float
    #: pixels covered (alpha > 0), % of the image; None for the vertex stage
    lattice_coverage: float | None = None
    linear_coverage: float | None = None
    #: pixels whose colour differs from the linear image's (> 2/255 in a channel), %:
    #: the lattice deforms the mesh; None for the vertex stage
    changed: float | None = None

    @property
    def fps_ratio(self) -> float:
        """Lattice FPS / linear FPS = linear median / lattice median (1 = as fast)."""
        return self.linear_ms / self.lattice_ms

    @property
    def lattice_fps(self) -> float:
        return 1000.0 / self.lattice_ms

    @property
    def linear_fps(self) -> float:
        return 1000.0 / self.linear_ms


@dataclass
class FastPathRow:
    """Section 4: an affine lattice through the trilinear program vs the LINEAR one."""

    stage: str  # "frame" or "vertex"
    cells: int
    frames: int
    trilinear_ms: float  # median
    trilinear_min_ms: float
    fast_ms: float  # median
    fast_min_ms: float
    #: pixels whose colour differs between the two programs (> 2/255), %; None: vertex
    changed: float | None = None

    @property
    def speedup(self) -> float:
        """Trilinear ms / fast-path ms (> 1: the fast path is faster)."""
        return self.trilinear_ms / self.fast_ms


@dataclass
class CrossCheck:
    """:func:`benchmarks.lattice.bench_mesh_throughput`, run once as it is."""

    cells: tuple[int, int, int]
    size: int
    triangles: int
    ms: dict[str, float]
    vertex_stage_ms: dict[str, float]
    note: str = ""

    def fps_ratio(self, case: str) -> float:
        """Linear median / ``case`` median (its ``ratio`` inverted)."""
        return self.ms["linear"] / self.ms[case]

    @property
    def vertex_fps_ratio(self) -> float:
        return self.vertex_stage_ms["linear"] / self.vertex_stage_ms["lattice_normal"]


@dataclass
class CompositionRow:
    """Section 2: one scene graph (lattice or linear) over its timed frames (medians)."""

    variant: str
    objects: int
    groups: int
    nodes: int
    depth: int
    triangles: int
    grid_leaves: int  # leaves whose composed transform is a lattice
    composed_cells: tuple[int, int, int] | None  # resolution of the composed lattices
    frames: int
    compose_ms: float  # compose_scene
    wrap_ms: float  # MeshInstance per composed transform
    draw_ms: float  # draw of the new instances (node textures uploaded), finish()
    static_draw_ms: float  # the same instances redrawn (textures cached)
    frame_ms: float  # median over frames of compose + wrap + draw
    frame_min_ms: float
    coverage: float = 0.0  # pixels covered, %

    @property
    def fps(self) -> float:
        return 1000.0 / self.frame_ms

    @property
    def static_fps(self) -> float:
        return 1000.0 / self.static_draw_ms


@dataclass
class LatticeBenchReport:
    """Everything one ``bench lattice`` run measured (see the module docstring)."""

    triangles_requested: int
    triangles: int
    vertices: int
    objects: int
    cells: tuple[int, ...]
    frames: int
    size: tuple[int, int]
    gl_renderer: str = "?"
    cores: int = 1
    load: tuple[float, float] = (-1.0, -1.0)
    wall_s: float = 0.0
    throughput: list[ThroughputRow] = field(default_factory=list)
    crosscheck: CrossCheck | None = None
    composition: list[CompositionRow] = field(default_factory=list)
    fast_path: list[FastPathRow] = field(default_factory=list)
    #: section 5 (:class:`benchmarks.lattice_normals.NormalsRow`)
    normals: list[Any] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    #: section 3 (:class:`benchmarks.lattice_inverse.InverseReport`), None when skipped
    inverse: Any = None

    def row(self, cells: int, stage: str, normal_method: str, position: str = "exact") -> Any:
        """The section 1 row of a configuration (None if not measured)."""
        for r in self.throughput:
            if (r.cells, r.stage, r.normal_method, r.position) == (
                cells,
                stage,
                normal_method,
                position,
            ):
                return r
        return None

    def variant(self, name: str) -> CompositionRow | None:
        """The section 2 row of ``trilinear`` or ``linear``."""
        for r in self.composition:
            if r.variant == name:
                return r
        return None

    @property
    def composition_fps_ratio(self) -> float | None:
        """Trilinear FPS / linear FPS of whole frames (compose + wrap + draw)."""
        tri, lin = self.variant("trilinear"), self.variant("linear")
        if tri is None or lin is None:
            return None
        return lin.frame_ms / tri.frame_ms

    @property
    def static_fps_ratio(self) -> float | None:
        """Trilinear / linear FPS of the static draw (composition not redone)."""
        tri, lin = self.variant("trilinear"), self.variant("linear")
        if tri is None or lin is None:
            return None
        return lin.static_draw_ms / tri.static_draw_ms

    @property
    def compose_ratio(self) -> float | None:
        """compose_scene time trilinear / linear (> 1: the lattices compose slower)."""
        tri, lin = self.variant("trilinear"), self.variant("linear")
        if tri is None or lin is None:
            return None
        return tri.compose_ms / lin.compose_ms

    # ------------------------------------------------------------------ markdown
    def summary_lines(self) -> list[str]:
        """One line per headline ratio."""
        lo, hi = PAPER_RATIO
        out = [f"Paper (GRAPP 2010): trilinear at {lo:.1%}-{hi:.1%} of the linear FPS."]
        for stage, what in (("frame", "full frame"), ("vertex", "vertex stage only")):
            parts = []
            for c in self.cells:
                vals = []
                for m in NORMAL_METHODS:
                    r = self.row(c, stage, m)
                    if r is not None:
                        vals.append(f"{m} {r.fps_ratio:.0%}")
                if vals:
                    parts.append(f"{c}³ cells: {', '.join(vals)}")
            if parts:
                out.append(
                    f"Vertex throughput, {self.triangles} triangles, {what}: FPS trilinear /"
                    f" linear = {'; '.join(parts)}."
                )
        ratio = self.composition_fps_ratio
        if ratio is not None:
            tri, lin = self.variant("trilinear"), self.variant("linear")
            assert tri is not None
            assert lin is not None
            out.append(
                f"Composition, {self.objects} objects: FPS trilinear / linear = {ratio:.0%}"
                f" per animated frame ({tri.frame_ms:.1f} vs {lin.frame_ms:.1f} ms; compose_scene"
                f" {tri.compose_ms:.1f} vs {lin.compose_ms:.1f} ms = {self.compose_ratio:.1f}x),"
                f" {self.static_fps_ratio:.0%} for a static redraw ({tri.static_draw_ms:.1f} vs"
                f" {lin.static_draw_ms:.1f} ms)."
            )
        for r in self.fast_path:
            out.append(
                f"Linear fast path (section 4.1), {r.stage} stage: an affine {r.cells}³-cell"
                f" lattice drawn by the trilinear program takes {r.speedup:.2f}x the time of the"
                " LINEAR program."
            )
        return out

    def markdown(self, command: str) -> str:
        """The report in markdown, headed by the command that produced it."""
        w, h = self.size
        lines = [
            f"Command: `{command}`",
            "",
            f"Image {w}x{h}; timed frames per configuration: {self.frames} (medians, after one"
            f" warm-up draw of each); section 1: a torus of {self.triangles} triangles"
            f" ({self.vertices} vertices; asked {self.triangles_requested}), lattice cells per"
            f" axis {', '.join(map(str, self.cells))}; section 2: {self.objects} objects.",
            "",
            f"Device: GL {self.gl_renderer}; CPU {platform.processor() or platform.machine()},"
            f" {self.cores} cores; numpy {np.__version__}; 1-minute load average before /"
            f" after the run {self.load[0]:.2f} / {self.load[1]:.2f}; the run took"
            f" {self.wall_s:.1f} s.",
            "",
            "## Summary",
            "",
            *[f"* {line}" for line in self.summary_lines()],
            "",
            *self._throughput_md(),
            *self._composition_md(),
            *(self.inverse.markdown_lines() if self.inverse is not None else []),
            *self._fast_path_md(),
            *(normals_markdown(self.normals) if self.normals else []),
        ]
        if self.notes:
            lines += ["## Notes", "", *[f"* {n}" for n in self.notes], ""]
        return "\n".join(lines).rstrip() + "\n"

    def _throughput_md(self) -> list[str]:
        w, h = self.size
        lines = [
            "## 1. Vertex throughput: lattice vs 4x4",
            "",
            f"One `torus_mesh` of {self.triangles} triangles ({self.vertices} vertices), drawn"
            f" at {w}x{h} by `MeshRenderer.draw` (depth test, Blinn-Phong) under the twist +"
            " bend lattice of `benchmarks.lattice.bend_grid` with the given cells per axis, vs"
            " the same mesh with a 4x4 (identity) matrix. Each row alternates lattice and"
            " linear frames (order flipped every frame, `ctx.finish()` after each); ms are"
            " median (min). FPS ratio = linear ms / lattice ms = lattice FPS / linear FPS."
            " stage vertex: `GL_RASTERIZER_DISCARD` (the vertex shader alone). position"
            " hardware: the position from one hardware-filtered texture fetch"
            " (`HW_TRILINEAR`), made in addition to the 8 corner fetches, which the"
            " Jacobian (normals) still needs. coverage: pixels drawn; changed: pixels whose"
            " colour differs from the linear image's (sanity: the lattice bends the torus).",
            "",
            "| cells | stage | normals | position | lattice ms | linear ms | lattice FPS |"
            " linear FPS | FPS ratio | coverage lattice / linear | changed |",
            "|---:|---|---|---|---:|---:|---:|---:|---:|---|---:|",
        ]
        for r in self.throughput:
            cov = (
                "—"
                if r.lattice_coverage is None or r.linear_coverage is None
                else f"{r.lattice_coverage:.1f}% / {r.linear_coverage:.1f}%"
            )
            lines.append(
                f"| {r.cells}³ | {r.stage} | {r.normal_method} | {r.position} |"
                f" {r.lattice_ms:.1f} ({r.lattice_min_ms:.1f}) |"
                f" {r.linear_ms:.1f} ({r.linear_min_ms:.1f}) | {r.lattice_fps:.1f} |"
                f" {r.linear_fps:.1f} | {r.fps_ratio:.2f} | {cov} |"
                f" {'—' if r.changed is None else f'{r.changed:.1f}%'} |"
            )
        lines.append("")
        cc = self.crosscheck
        if cc is not None:
            lines += [
                f"Cross-check: `benchmarks.lattice.bench_mesh_throughput` run as it is (cells"
                f" {'x'.join(map(str, cc.cells))}, {cc.size}x{cc.size}, {cc.triangles}"
                " triangles, same frame count; it times each case in a block after one warm-up"
                " draw, not alternated, so load changes during the run skew it).",
                "",
                "| case | ms | FPS ratio vs linear | vertex stage ms | vertex FPS ratio |",
                "|---|---:|---:|---:|---:|",
            ]
            for case, ms in cc.ms.items():
                vms = cc.vertex_stage_ms.get(case)
                ratio = "1.00" if case == "linear" else f"{cc.fps_ratio(case):.2f}"
                vratio = (
                    "—"
                    if vms is None
                    else "1.00"
                    if case == "linear"
                    else f"{cc.vertex_stage_ms['linear'] / vms:.2f}"
                )
                vtxt = "—" if vms is None else f"{vms:.1f}"
                lines.append(f"| {case} | {ms:.1f} | {ratio} | {vtxt} | {vratio} |")
            if cc.note:
                lines += ["", cc.note]
            lines.append("")
        return lines

    def _composition_md(self) -> list[str]:
        lines = ["## 2. Composition: many small objects under nested nodes", ""]
        if not self.composition:
            return [*lines, "Not run.", ""]
        tri = self.variant("trilinear")
        n = tri or self.composition[0]
        lines += [
            f"{n.objects} instances of one {n.triangles // max(n.objects, 1)}-triangle"
            f" `uv_sphere` ({n.triangles} triangles) in {n.groups} groups: root -> group ->"
            f" object ({n.nodes} nodes, depth {n.depth}). trilinear: the root carries a"
            f" {ROOT_CELLS}³-cell twist + bend lattice, every group a {GROUP_CELLS}³-cell one,"
            " every object a 4x4 (rotation, scale, translation); linear: the same graph with"
            " the root's lattice replaced by the identity 4x4 and each group's by its"
            " translation. Per frame, timed separately: compose = `compose_scene(root)`"
            " (the propagation world -> leaves, one composed transform per object: a 4x4"
            " product, or a lattice whose nodes are pushed through the chain, per leaf from"
            " scratch); wrap = one `MeshInstance` per composed transform (what"
            " `instances_from_scene_graph` adds); draw = `MeshRenderer.draw` of these new"
            " instances + `ctx.finish()` (one draw call per object; every new composed"
            " lattice is a new node texture: uploads, and releases of the previous frame's,"
            " included); frame = compose + wrap + draw (median of the per-frame sums);"
            " static draw = the same instances drawn again (textures cached), what a frame"
            " costs when the composition did not change. Frames of the two graphs"
            " alternate; ms are medians.",
            "",
            "| graph | objects | groups | composed lattices | compose ms | wrap ms | draw ms |"
            " frame ms | FPS | static draw ms | static FPS | coverage |",
            "|---|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for r in self.composition:
            lat = (
                "none (4x4)"
                if not r.grid_leaves
                else f"{r.grid_leaves} x {'x'.join(map(str, r.composed_cells or ()))}"
            )
            lines.append(
                f"| {r.variant} | {r.objects} | {r.groups} | {lat} | {r.compose_ms:.1f} |"
                f" {r.wrap_ms:.1f} | {r.draw_ms:.1f} | {r.frame_ms:.1f} ({r.frame_min_ms:.1f}) |"
                f" {r.fps:.1f} | {r.static_draw_ms:.1f} | {r.static_fps:.1f} |"
                f" {r.coverage:.1f}% |"
            )
        ratio = self.composition_fps_ratio
        if ratio is not None:
            tri, lin = self.variant("trilinear"), self.variant("linear")
            assert tri is not None
            assert lin is not None
            lines += [
                "",
                f"FPS ratio trilinear / linear: animated frame {ratio:.2f} ({lin.frame_ms:.1f} /"
                f" {tri.frame_ms:.1f} ms); static draw {self.static_fps_ratio:.2f}"
                f" ({lin.static_draw_ms:.1f} / {tri.static_draw_ms:.1f} ms); compose_scene"
                f" alone trilinear / linear time {self.compose_ratio:.1f}x"
                f" ({tri.compose_ms:.1f} / {lin.compose_ms:.1f} ms).",
            ]
        return [*lines, ""]

    def _fast_path_md(self) -> list[str]:
        lines = ["## 4. Linear fast path: an affine lattice through both programs", ""]
        if not self.fast_path:
            return [*lines, "Not run.", ""]
        lines += [
            f"The torus of section 1 under an affine {self.fast_path[0].cells}³-cell lattice"
            " (a shear with non-uniform scale; `TrilinearGrid.is_linear`), drawn by"
            " `MeshRenderer(linear_fast_path=False)` (the trilinear vertex shader: 8 node"
            " fetches and the Jacobian per vertex) and by the default `MeshRenderer`, which"
            " draws it with the LINEAR program (one 4x4 product; GRAPP 2010 section 4.1's"
            " parallelepiped check). Frames alternate as in section 1; ms are median (min);"
            " speed-up = trilinear ms / fast-path ms; changed: pixels whose colour differs"
            " between the two images (> 2/255).",
            "",
            "| stage | trilinear program ms | LINEAR program ms | speed-up | changed |",
            "|---|---:|---:|---:|---:|",
        ]
        for r in self.fast_path:
            changed = "—" if r.changed is None else f"{r.changed:.2f}%"
            lines.append(
                f"| {r.stage} | {r.trilinear_ms:.1f} ({r.trilinear_min_ms:.1f}) |"
                f" {r.fast_ms:.1f} ({r.fast_min_ms:.1f}) | {r.speedup:.2f} | {changed} |"
            )
        return [*lines, ""]


# ---------------------------------------------------------------------- section 1
def torus_for(triangles: int) -> Any:
    """The torus of section 1: about ``triangles`` triangles (4 n² for n minor sections),
    as :func:`benchmarks.lattice.bench_mesh_throughput` builds it."""
    from voxwarp.core.mesh import torus_mesh

    nv = max(3, round((int(triangles) / 4) ** 0.5))
    return torus_mesh(*TORUS_RADII, 2 * nv, nv)


def _pixels(color_tex: Any) -> np.ndarray:
    """(pixels, 4) uint8 of an RGBA8 texture."""
    return np.frombuffer(color_tex.read(), dtype=np.uint8).reshape(-1, 4)


def _coverage(color_tex: Any) -> float:
    """Pixels with alpha > 0 in an RGBA8 texture, in %."""
    a = _pixels(color_tex)[:, 3]
    return 100.0 * float(np.count_nonzero(a)) / max(a.size, 1)


def _changed(a: np.ndarray, b: np.ndarray) -> float:
    """Pixels differing by more than 2/255 in a channel, in %."""
    diff = np.abs(a.astype(np.int16) - b.astype(np.int16)).max(axis=1)
    return 100.0 * float(np.count_nonzero(diff > 2)) / max(len(diff), 1)


def _unbind_fbo(ctx: Any) -> None:
    """Bind the default framebuffer: never release the bound one (moderngl re-binds the
    dead name when the next framebuffer is made: GL_INVALID_OPERATION), as
    :class:`voxwarp.render.offscreen.OffscreenRenderer` does."""
    try:
        ctx.detect_framebuffer(0).use()
    except Exception:
        pass


def _alternate(
    ctx: Any, a: Callable[[], None], b: Callable[[], None], frames: int, stage: str = "frame"
) -> tuple[list[float], list[float]]:
    """One warm-up call of each, then ``frames`` timed calls of each, alternated (the order
    flips every frame); ms per call, each bound by ``ctx.finish()``. ``stage`` ``"vertex"``
    times the vertex stage alone (rasterizer discard on)."""
    ta: list[float] = []
    tb: list[float] = []
    with _rasterizer_discard(ctx, stage != "frame"):
        a()
        b()
        ctx.finish()
        for i in range(frames):
            order = ((a, ta), (b, tb)) if i % 2 == 0 else ((b, tb), (a, ta))
            for fn, out in order:
                t = time.perf_counter()
                fn()
                ctx.finish()
                out.append((time.perf_counter() - t) * 1000.0)
    return ta, tb


@contextlib.contextmanager
def _rasterizer_discard(ctx: Any, on: bool) -> Iterator[None]:
    """With ``on``: ``GL_RASTERIZER_DISCARD`` inside the block (the vertex stage alone)."""
    if on:
        ctx.enable(ctx.RASTERIZER_DISCARD)
    try:
        yield
    finally:
        if on:
            ctx.disable(ctx.RASTERIZER_DISCARD)


@contextlib.contextmanager
def _torus_target(report: LatticeBenchReport, ctx: Any) -> Iterator[tuple[Any, Any, Any, Any]]:
    """The torus's box, a camera on it, and an RGBA8 colour texture with its framebuffer
    (plus depth) of the report's size, released on exit: (box, camera, color, fbo)."""
    w, h = report.size
    box = (np.array(TORUS_BOX[0]), np.array(TORUS_BOX[1]))
    cam = Camera.fit(box[0] - 0.3, box[1] + 0.3, VIEW, "perspective")
    color = ctx.texture((w, h), 4, dtype="f1")
    depth = ctx.depth_texture((w, h))
    fbo = ctx.framebuffer(color_attachments=[color], depth_attachment=depth)
    try:
        yield box, cam, color, fbo
    finally:
        _unbind_fbo(ctx)
        fbo.release()
        color.release()
        depth.release()


def bench_throughput(
    report: LatticeBenchReport,
    ctx: Any,
    mesh: Any,
    log: Callable[[str], None],
    crosscheck: bool = True,
) -> None:
    """Section 1 (see the module docstring); appends to ``report.throughput``."""

    with _torus_target(report, ctx) as (box, cam, color, fbo):
        _throughput_rows(report, ctx, mesh, box, cam, color, fbo, log)
    if crosscheck:
        report.crosscheck = run_crosscheck(report, ctx, log)


def _throughput_rows(
    report: LatticeBenchReport,
    ctx: Any,
    mesh: Any,
    box: Any,
    cam: Any,
    color: Any,
    fbo: Any,
    log: Callable[[str], None],
) -> None:
    """Section 1's rows on an open torus target (see :func:`bench_throughput`)."""
    renderers = {p: MeshRenderer(ctx, position=p) for p in ("exact", "hardware")}
    linear = MeshInstance(mesh, np.eye(4))
    try:
        renderers["exact"].draw([linear], fbo, cam)
        ctx.finish()
        linear_cov = _coverage(color)
        linear_img = _pixels(color).copy()
        for c in report.cells:
            grid = bend_grid(box, (c, c, c))
            for stage, method, position in THROUGHPUT_CONFIGS:
                r = renderers[position]
                inst = MeshInstance(mesh, grid, box=box, normal_method=method)
                cov = changed = None
                if stage == "frame":
                    r.draw([inst], fbo, cam)
                    ctx.finish()
                    cov = _coverage(color)
                    changed = _changed(_pixels(color), linear_img)
                t_lat, t_lin = _alternate(
                    ctx,
                    lambda r=r, inst=inst: r.draw([inst], fbo, cam),
                    lambda: renderers["exact"].draw([linear], fbo, cam),
                    report.frames,
                    stage,
                )
                row = ThroughputRow(
                    cells=c,
                    stage=stage,
                    normal_method=method,
                    position=position,
                    frames=report.frames,
                    lattice_ms=statistics.median(t_lat),
                    lattice_min_ms=min(t_lat),
                    linear_ms=statistics.median(t_lin),
                    linear_min_ms=min(t_lin),
                    lattice_coverage=cov,
                    linear_coverage=linear_cov if stage == "frame" else None,
                    changed=changed,
                )
                report.throughput.append(row)
                log(
                    f"throughput {c}³ cells {stage} {method} {position}: lattice"
                    f" {row.lattice_ms:.1f} ms, linear {row.linear_ms:.1f} ms, FPS ratio"
                    f" {row.fps_ratio:.2f}"
                )
    finally:
        for rr in renderers.values():
            rr.release()


def affine_lattice(box: tuple[np.ndarray, np.ndarray], cells: int) -> TrilinearGrid:
    """Section 4's lattice: :data:`FAST_PATH_MATRIX` about the box centre, ``cells`` per axis."""
    lo, hi = box
    a = np.asarray(FAST_PATH_MATRIX)
    mid = 0.5 * (lo + hi)
    return TrilinearGrid.from_function(lambda u: (lo + u * (hi - lo) - mid) @ a.T + mid, cells)


def bench_fast_path(
    report: LatticeBenchReport, ctx: Any, mesh: Any, log: Callable[[str], None]
) -> None:
    """Section 4 (see the module docstring); appends to ``report.fast_path``."""
    with _torus_target(report, ctx) as (box, cam, color, fbo):
        slow, fast = MeshRenderer(ctx, linear_fast_path=False), MeshRenderer(ctx)
        inst = MeshInstance(mesh, affine_lattice(box, FAST_PATH_CELLS), box=box)
        try:
            images = []
            for r in (slow, fast):
                r.draw([inst], fbo, cam)
                ctx.finish()
                images.append(_pixels(color).copy())
            for stage in ("frame", "vertex"):
                t_slow, t_fast = _alternate(
                    ctx,
                    lambda: slow.draw([inst], fbo, cam),
                    lambda: fast.draw([inst], fbo, cam),
                    report.frames,
                    stage,
                )
                row = FastPathRow(
                    stage=stage,
                    cells=FAST_PATH_CELLS,
                    frames=report.frames,
                    trilinear_ms=statistics.median(t_slow),
                    trilinear_min_ms=min(t_slow),
                    fast_ms=statistics.median(t_fast),
                    fast_min_ms=min(t_fast),
                    changed=_changed(*images) if stage == "frame" else None,
                )
                report.fast_path.append(row)
                log(
                    f"fast path {stage}: trilinear program {row.trilinear_ms:.1f} ms, LINEAR"
                    f" {row.fast_ms:.1f} ms, speed-up {row.speedup:.2f}"
                )
            if slow.program_uses["linear"] or not fast.program_uses["linear"]:
                raise RuntimeError("the affine lattice did not take the programs it was meant to")
        finally:
            slow.release()
            fast.release()


def run_crosscheck(
    report: LatticeBenchReport, ctx: Any, log: Callable[[str], None]
) -> CrossCheck | None:
    """:func:`benchmarks.lattice.bench_mesh_throughput` at the middle cell count."""

    w, h = report.size
    c = sorted(report.cells)[len(report.cells) // 2]
    note = ""
    if w != h:
        note = f"bench_mesh_throughput draws square images: run at {w}x{w}, not {w}x{h}."
    res = bench_mesh_throughput(
        triangles=report.triangles_requested,
        cells=(c, c, c),
        size=w,
        frames=report.frames,
        ctx=ctx,
    )
    # it releases its framebuffer while bound: bind the default one before the next is made
    _unbind_fbo(ctx)
    cc = CrossCheck(
        cells=tuple(int(v) for v in res["cells"]),  # type: ignore[arg-type]
        size=int(res["size"]),
        triangles=int(res["triangles"]),
        ms=dict(res["ms"]),
        vertex_stage_ms=dict(res["vertex_stage_ms"]),
        note=note,
    )
    log(
        f"cross-check bench_mesh_throughput {c}³: linear {cc.ms['linear']:.1f} ms,"
        f" lattice_normal {cc.ms['lattice_normal']:.1f} ms"
    )
    return cc


# ---------------------------------------------------------------------- section 2
def object_mesh() -> Any:
    """The small object of section 2: a 48-triangle uv sphere."""
    from voxwarp.core.mesh import uv_sphere

    return uv_sphere(OBJECT_RADIUS, rows=OBJECT_ROWS, cols=OBJECT_COLS)


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    x, y, z = axis / np.linalg.norm(axis)
    c, s = math.cos(angle), math.sin(angle)
    k = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return np.eye(3) + s * k + (1 - c) * (k @ k)


@dataclass
class GraphInfo:
    """Shape of a section 2 scene graph."""

    objects: int
    groups: int
    per_group: int
    nodes: int
    depth: int


def build_scene_graph(objects: int, lattice: bool, mesh: Any = None) -> tuple[Any, GraphInfo]:
    """The scene graph of section 2: root -> groups -> ``objects`` object leaves.

    ``lattice``: the root and the groups carry twist + bend lattices (trilinear graph);
    otherwise 4x4 matrices with the same placement, unbent (linear graph). Objects carry
    the same 4x4s in both (deterministic). Groups hold ``ceil(sqrt(objects))`` objects
    each (the last one the rest), in a cube of slots; groups lie side by side in a square.
    """
    from voxwarp.deform.lattice.scene_graph import SceneNode

    n = int(objects)
    if n < 1:
        raise ValueError(f"objects must be >= 1; got {objects}")
    mesh = object_mesh() if mesh is None else mesh
    per = math.ceil(math.sqrt(n))
    groups = math.ceil(n / per)
    k = math.ceil(per ** (1.0 / 3.0) - 1e-9)  # slots per axis in a group
    side = math.ceil(math.sqrt(groups))
    margin = OBJECT_RADIUS * 1.25 * math.sqrt(3.0)  # a rotated, scaled object's box
    g_lo = np.full(3, -margin)
    g_hi = np.full(3, k * SLOT + margin)
    rng = np.random.default_rng(6)
    offsets = []
    for g in range(groups):
        offsets.append(
            np.array([(g % side), (g // side), 0.0]) * (k * SLOT + 2 * margin + GROUP_GAP)
        )
    # the root's box: where the groups' lattices put their content (the nodes' hull)
    group_grids = []
    for off in offsets:
        bent = bend_grid((g_lo, g_hi), (GROUP_CELLS,) * 3)
        group_grids.append(TrilinearGrid(bent.nodes + off))
    pts = np.concatenate([gg.nodes.reshape(-1, 3) for gg in group_grids])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.05 * (hi - lo).max()
    root_box = (lo - pad, hi + pad)
    root = SceneNode(
        "root",
        bend_grid(root_box, (ROOT_CELLS,) * 3) if lattice else np.eye(4),
        box=root_box,
    )
    count = 0
    nodes = 1
    for g in range(groups):
        if lattice:
            gt: Any = group_grids[g]
        else:
            gt = np.eye(4)
            gt[:3, 3] = offsets[g]
        gnode = root.add(SceneNode(f"group{g}", gt, box=(g_lo, g_hi)))
        nodes += 1
        for i in range(min(per, n - count)):
            slot = np.array([i % k, (i // k) % k, i // (k * k)], dtype=np.float64)
            m = np.eye(4)
            scale = 0.8 + 0.45 * rng.random()
            m[:3, :3] = _rotation(rng.normal(size=3) + 1e-3, rng.random() * math.pi) * scale
            m[:3, 3] = (slot + 0.5) * SLOT
            gnode.add(SceneNode(f"object{count}", m, box=mesh.bounds, geometry=mesh))
            count += 1
            nodes += 1
    return root, GraphInfo(count, groups, per, nodes, 2)


def wrap_instances(composed: Sequence[Any]) -> list[Any]:
    """One :class:`~voxwarp.core.mesh.MeshInstance` per composed transform whose geometry is a
    mesh: what :func:`voxwarp.core.mesh.instances_from_scene_graph` does after its compose_scene."""
    from voxwarp.core.mesh import PALETTE, Mesh, MeshInstance

    out: list[Any] = []
    for c in composed:
        mesh = c.node.geometry
        if not isinstance(mesh, Mesh):
            continue
        transform = np.asarray(c.matrix, dtype=np.float64) if c.matrix is not None else c.grid
        box = c.box
        out.append(
            MeshInstance(
                mesh,
                transform,
                box=None if box is None else (np.asarray(box[0]), np.asarray(box[1])),
                color=PALETTE[len(out) % len(PALETTE)],
                normal_method=DEFAULT_NORMAL_METHOD,
                name=c.node.name or mesh.name,
            )
        )
    return out


def bench_composition(report: LatticeBenchReport, ctx: Any, log: Callable[[str], None]) -> None:
    """Section 2 (see the module docstring); appends one row per variant."""
    from voxwarp.core.mesh_warp import mesh_instances_bounds
    from voxwarp.deform.lattice.scene_graph import compose_scene

    mesh = object_mesh()
    graphs = {v: build_scene_graph(report.objects, v == "trilinear", mesh) for v in VARIANTS}
    # camera: both graphs in view (composed once, untimed)
    boxes = []
    shapes: dict[str, tuple[int, int, tuple[int, int, int] | None]] = {}
    for v, (root, _info) in graphs.items():
        insts = wrap_instances(compose_scene(root))
        boxes.append(mesh_instances_bounds(insts))
        grids = [i.transform for i in insts if i.is_lattice]
        shapes[v] = (
            sum(i.mesh.n_faces for i in insts),
            len(grids),
            tuple(grids[0].shape) if grids else None,
        )
        del insts, grids
    lo = np.min([b[0] for b in boxes], axis=0)
    hi = np.max([b[1] for b in boxes], axis=0)
    cam = Camera.fit(lo, hi, VIEW, "perspective")
    w, h = report.size
    color = ctx.texture((w, h), 4, dtype="f1")
    depth = ctx.depth_texture((w, h))
    fbo = ctx.framebuffer(color_attachments=[color], depth_attachment=depth)
    renderers = {v: MeshRenderer(ctx) for v in VARIANTS}
    times: dict[str, dict[str, list[float]]] = {
        v: {k: [] for k in ("compose", "wrap", "draw", "static", "frame")} for v in VARIANTS
    }
    coverage: dict[str, float] = {}

    def frame(v: str, record: bool) -> None:
        root = graphs[v][0]
        r = renderers[v]
        t0 = time.perf_counter()
        composed = compose_scene(root)
        t1 = time.perf_counter()
        insts = wrap_instances(composed)
        t2 = time.perf_counter()
        r.draw(insts, fbo, cam)
        ctx.finish()
        t3 = time.perf_counter()
        r.draw(insts, fbo, cam)
        ctx.finish()
        t4 = time.perf_counter()
        if record:
            t = times[v]
            t["compose"].append((t1 - t0) * 1000)
            t["wrap"].append((t2 - t1) * 1000)
            t["draw"].append((t3 - t2) * 1000)
            t["static"].append((t4 - t3) * 1000)
            t["frame"].append((t3 - t0) * 1000)
        else:
            coverage[v] = _coverage(color)

    try:
        for v in VARIANTS:  # warm-up: programs, the mesh's buffers; coverage
            frame(v, record=False)
        for i in range(report.frames):
            for v in VARIANTS if i % 2 == 0 else VARIANTS[::-1]:
                frame(v, record=True)
            log(
                f"composition frame {i + 1}/{report.frames}: "
                + ", ".join(f"{v} {times[v]['frame'][-1]:.0f} ms" for v in VARIANTS)
            )
    finally:
        for r in renderers.values():
            r.release()
        _unbind_fbo(ctx)
        fbo.release()
        color.release()
        depth.release()
    for v in VARIANTS:
        info = graphs[v][1]
        t = times[v]
        tris, n_grids, cells = shapes[v]
        row = CompositionRow(
            variant=v,
            objects=info.objects,
            groups=info.groups,
            nodes=info.nodes,
            depth=info.depth,
            triangles=tris,
            grid_leaves=n_grids,
            composed_cells=cells,
            frames=report.frames,
            compose_ms=statistics.median(t["compose"]),
            wrap_ms=statistics.median(t["wrap"]),
            draw_ms=statistics.median(t["draw"]),
            static_draw_ms=statistics.median(t["static"]),
            frame_ms=statistics.median(t["frame"]),
            frame_min_ms=min(t["frame"]),
            coverage=coverage.get(v, 0.0),
        )
        report.composition.append(row)
        log(
            f"composition {v}: compose {row.compose_ms:.1f} ms, wrap {row.wrap_ms:.1f} ms,"
            f" draw {row.draw_ms:.1f} ms, frame {row.frame_ms:.1f} ms, static draw"
            f" {row.static_draw_ms:.1f} ms"
        )


# ---------------------------------------------------------------------- the run
def bench_lattice(
    *,
    triangles: int = DEFAULT_TRIANGLES,
    objects: int = DEFAULT_OBJECTS,
    frames: int = DEFAULT_FRAMES,
    size: tuple[int, int] = DEFAULT_SIZE,
    cells: Sequence[int] = DEFAULT_CELLS,
    crosscheck: bool = True,
    ctx: Any = None,
    log: Callable[[str], None] = print,
    inverse_frames: int | None = None,
    mesh_sections: bool = True,
) -> LatticeBenchReport:
    """Run the sections (see the module docstring) on ``ctx`` (else a new context):
    1, 2 and 4 unless ``mesh_sections`` is False; 3 when ``inverse_frames`` is given (its
    render rounds; 0: its accuracy rows only; the command line's default
    :data:`INVERSE_FRAMES`)."""
    t_start = time.perf_counter()
    load_start = load_average()
    cells = tuple(dict.fromkeys(int(c) for c in cells))
    if not cells or any(not 1 <= c <= MAX_CELLS for c in cells):
        raise ValueError(f"cells per axis must be 1..{MAX_CELLS}; got {cells}")
    if int(frames) < 1 or int(objects) < 1:
        raise ValueError(f"frames and objects must be >= 1; got {frames}, {objects}")
    if not MIN_TRIANGLES <= int(triangles) <= MAX_TRIANGLES:
        raise ValueError(f"triangles must be {MIN_TRIANGLES}..{MAX_TRIANGLES}; got {triangles}")
    if mesh_sections:
        log(f"building a torus of about {int(triangles)} triangles")
    mesh = torus_for(int(triangles) if mesh_sections else MIN_TRIANGLES)
    report = LatticeBenchReport(
        triangles_requested=int(triangles),
        triangles=mesh.n_faces,
        vertices=mesh.n_vertices,
        objects=int(objects),
        cells=cells,
        frames=int(frames),
        size=(int(size[0]), int(size[1])),
        cores=cpu_count(),
    )
    own_ctx = ctx is None
    if own_ctx:
        from voxwarp.render.context import create_context

        ctx = create_context()
    else:
        # a shared context may still have a released framebuffer bound (e.g. after
        # benchmarks.lattice.bench_mesh_throughput): making ours would re-bind that dead name
        _unbind_fbo(ctx)
    try:
        report.gl_renderer = str(ctx.info.get("GL_RENDERER", "?"))
        log(f"GL: {report.gl_renderer}")
        if mesh_sections:
            bench_throughput(report, ctx, mesh, log, crosscheck=crosscheck)
            bench_fast_path(report, ctx, mesh, log)
            report.normals = normals_study()
            del mesh
            bench_composition(report, ctx, log)
        if inverse_frames is not None:
            report.inverse = bench_inverse(ctx, frames=int(inverse_frames), log=log)
    finally:
        if own_ctx:
            ctx.release()
    report.load = (load_start, load_average())
    if load_start > 0.5 * report.cores:
        report.notes.append(
            f"The 1-minute load average was {load_start:.2f} on {report.cores} cores before"
            " the run: the machine was busy; alternated rows are affected alike, the"
            " cross-check (block-timed) is not."
        )
    report.wall_s = time.perf_counter() - t_start
    return report


# ---------------------------------------------------------------------- command line
def _size_arg(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must be WxH, e.g. 512x512; got {text!r}") from None
    if not (1 <= w <= 16384 and 1 <= h <= 16384):
        raise argparse.ArgumentTypeError(f"size must be 1..16384 pixels per side; got {text!r}")
    return w, h


def _int_arg(lo: int, hi: int, what: str) -> Callable[[str], int]:
    def parse(text: str) -> int:
        try:
            x = float(text)
            ok = math.isfinite(x) and x == int(x)
        except ValueError:
            ok = False
        if not ok or not lo <= int(x) <= hi:
            raise argparse.ArgumentTypeError(
                f"{what} must be a whole number {lo}..{hi} (1.5e6 is fine); got {text!r}"
            )
        return int(x)

    return parse


def _cells_arg(text: str) -> tuple[int, ...]:
    try:
        vals = tuple(int(v) for v in text.split(",") if v.strip())
    except ValueError:
        vals = ()
    if not vals or any(not 1 <= v <= MAX_CELLS for v in vals):
        raise argparse.ArgumentTypeError(
            f"cells are comma-separated whole numbers 1..{MAX_CELLS} (cells per axis), e.g."
            f" 1,4,16; got {text!r}"
        )
    return tuple(dict.fromkeys(vals))


def add_bench_lattice_parser(bsub: Any) -> None:
    """Add ``lattice`` to the ``bench`` sub-commands (``bsub``: their sub-parsers object)."""
    p = bsub.add_parser(
        "lattice",
        help="trilinear lattices vs 4x4 matrices: vertex throughput of a 1.5 M-triangle"
        " scene and scene-graph composition of thousands of objects (GRAPP 2010's table)",
        description="Trilinear lattices against 4x4 matrices, measured in the same run.",
    )
    p.add_argument(
        "--triangles",
        type=_int_arg(MIN_TRIANGLES, MAX_TRIANGLES, "--triangles"),
        default=DEFAULT_TRIANGLES,
        metavar="N",
        help="triangles of the vertex-throughput torus (default 1.5e6)",
    )
    p.add_argument(
        "--objects",
        type=_int_arg(1, MAX_OBJECTS, "--objects"),
        default=DEFAULT_OBJECTS,
        metavar="N",
        help=f"objects of the composition scene graph (default {DEFAULT_OBJECTS})",
    )
    p.add_argument(
        "--frames",
        type=_int_arg(1, 10_000, "--frames"),
        default=DEFAULT_FRAMES,
        metavar="N",
        help=f"timed frames per configuration (default {DEFAULT_FRAMES})",
    )
    p.add_argument(
        "--size",
        type=_size_arg,
        default=DEFAULT_SIZE,
        metavar="WxH",
        help="image size (default 512x512)",
    )
    p.add_argument(
        "--cells",
        type=_cells_arg,
        default=DEFAULT_CELLS,
        metavar="C,C,...",
        help="lattice cells per axis of the vertex-throughput rows (default 1,4,16)",
    )
    p.add_argument(
        "--inverse-frames",
        type=_int_arg(0, 10_000, "--inverse-frames"),
        default=INVERSE_FRAMES,
        metavar="N",
        help=f"render rounds of section 3, the volume's inverse (default {INVERSE_FRAMES};"
        " 0: its accuracy rows only)",
    )
    p.add_argument("--inverse-only", action="store_true", help="run section 3 alone")
    p.add_argument("--markdown", metavar="FILE", help="also write the report to FILE")
    p.set_defaults(func=cmd_bench_lattice)


def command_line(args: argparse.Namespace) -> str:
    """The command that produced a report, rebuilt from ``args``."""
    parts = ["python", "-m", "benchmarks", "lattice"]
    if args.triangles != DEFAULT_TRIANGLES:
        parts += ["--triangles", str(args.triangles)]
    if args.objects != DEFAULT_OBJECTS:
        parts += ["--objects", str(args.objects)]
    if args.frames != DEFAULT_FRAMES:
        parts += ["--frames", str(args.frames)]
    if tuple(args.size) != DEFAULT_SIZE:
        parts += ["--size", f"{args.size[0]}x{args.size[1]}"]
    if tuple(args.cells) != DEFAULT_CELLS:
        parts += ["--cells", ",".join(map(str, args.cells))]
    if args.inverse_frames != INVERSE_FRAMES:
        parts += ["--inverse-frames", str(args.inverse_frames)]
    if args.inverse_only:
        parts += ["--inverse-only"]
    if args.markdown:
        parts += ["--markdown", shlex.quote(str(args.markdown))]
    return " ".join(parts)


def cmd_bench_lattice(args: argparse.Namespace) -> int:
    """``python -m benchmarks lattice``: see the module docstring."""
    report = bench_lattice(
        triangles=args.triangles,
        objects=args.objects,
        frames=args.frames,
        size=tuple(args.size),
        cells=tuple(args.cells),
        log=lambda s: print(s, file=sys.stderr),
        inverse_frames=args.inverse_frames,
        mesh_sections=not args.inverse_only,
    )
    text = report.markdown(command_line(args))
    if args.inverse_only:
        text = report.inverse.standalone_markdown(
            command_line(args), report.gl_renderer, report.load, report.wall_s
        )
    return emit_report(text, args.markdown)


__all__ = [
    "DEFAULT_CELLS",
    "CompositionRow",
    "CrossCheck",
    "LatticeBenchReport",
    "ThroughputRow",
    "add_bench_lattice_parser",
    "bench_cpu_grid",
    "bench_lattice",
    "build_scene_graph",
    "cmd_bench_lattice",
    "torus_for",
    "wrap_instances",
]


# ---------------------------------------------------------------------- mesh throughput
def bend_grid(box: tuple[np.ndarray, np.ndarray], cells: Any) -> TrilinearGrid:
    """A smooth twist + bend of ``box`` sampled on ``cells`` (benchmark and demo lattice)."""
    lo, hi = box
    size = hi - lo

    def f(u: np.ndarray) -> np.ndarray:
        p = lo + u * size
        c = (lo + hi) / 2
        a = (u[:, 2] - 0.5) * 0.8  # twist about z
        x, y = p[:, 0] - c[0], p[:, 1] - c[1]
        out = p.copy()
        out[:, 0] = c[0] + np.cos(a) * x - np.sin(a) * y
        out[:, 1] = c[1] + np.sin(a) * x + np.cos(a) * y
        out[:, 2] = p[:, 2] + 0.15 * size[2] * np.sin(np.pi * u[:, 0])  # bend
        return out

    return TrilinearGrid.from_function(f, cells)


def bench_mesh_throughput(
    triangles: int = 1_000_000,
    cells: Any = (4, 4, 4),
    size: int = 512,
    frames: int = 5,
    warmup: int = 1,
    ctx: Any = None,
) -> dict[str, Any]:
    """Median frame times of one torus of ~``triangles`` triangles drawn linear vs lattice.

    Draws a ``size`` x ``size`` image per frame (``ctx.finish()`` bound) with a 4x4
    instance, then the same mesh under a twisted and bent lattice of ``cells`` (both
    normal methods, exact and hardware positions), and once more with rasterisation
    discarded (``GL_RASTERIZER_DISCARD``: the vertex stage alone). Returns milliseconds,
    million vertices per second and the ratios lattice / linear (> 1: the lattice is
    slower), for ``python -m benchmarks lattice``.
    """
    from voxwarp.core.mesh import torus_mesh
    from voxwarp.render.context import create_context

    owns = ctx is None
    if owns:
        ctx = create_context()
    nv = max(3, round((triangles / 4) ** 0.5))
    mesh = torus_mesh(1.0, 0.35, 2 * nv, nv)
    box = (np.array([-1.4, -1.4, -0.4]), np.array([1.4, 1.4, 0.4]))
    grid = bend_grid(box, cells)
    cam = Camera.fit(box[0] - 0.3, box[1] + 0.3, (30.0, 35.0), "perspective")
    color = ctx.texture((size, size), 4, dtype="f1")
    depth = ctx.depth_texture((size, size))
    fbo = ctx.framebuffer(color_attachments=[color], depth_attachment=depth)
    renderers = {p: MeshRenderer(ctx, position=p) for p in POSITIONS}
    cases = {
        "linear": ("exact", MeshInstance(mesh, np.eye(4))),
        "lattice_normal": ("exact", MeshInstance(mesh, grid, box=box, normal_method="normal")),
        "lattice_tangent": ("exact", MeshInstance(mesh, grid, box=box, normal_method="tangent")),
        "lattice_hardware": ("hardware", MeshInstance(mesh, grid, box=box)),
    }

    def median_ms(renderer: MeshRenderer, inst: MeshInstance, discard: bool) -> float:
        times = []
        with _rasterizer_discard(ctx, discard):
            for _ in range(warmup):
                renderer.draw([inst], fbo, cam)
            ctx.finish()
            for _ in range(frames):
                t = time.perf_counter()
                renderer.draw([inst], fbo, cam)
                ctx.finish()
                times.append((time.perf_counter() - t) * 1000)
        return statistics.median(times)

    try:
        ms = {k: median_ms(renderers[p], inst, False) for k, (p, inst) in cases.items()}
        vertex_ms = {
            k: median_ms(renderers[p], inst, True)
            for k, (p, inst) in cases.items()
            if k in ("linear", "lattice_normal")
        }
    finally:
        for r in renderers.values():
            r.release()
        # never delete the bound framebuffer: moderngl would bind the dead name again
        # when the next framebuffer is made on this context (GL_INVALID_OPERATION)
        ctx.detect_framebuffer(0).use()
        fbo.release()
        color.release()
        depth.release()
        if owns:
            ctx.release()
    return {
        "triangles": mesh.n_faces,
        "vertices": mesh.n_vertices,
        "cells": tuple(grid.shape),
        "size": size,
        "frames": frames,
        "ms": ms,
        "vertex_stage_ms": vertex_ms,
        "mvertices_per_s": {k: mesh.n_vertices / v / 1e3 for k, v in vertex_ms.items()},
        "ratio": {k: v / ms["linear"] for k, v in ms.items() if k != "linear"},
        "vertex_stage_ratio": vertex_ms["lattice_normal"] / vertex_ms["linear"],
    }


# ---------------------------------------------------------------------- CPU maps
def bench_cpu_grid(
    points: int = 100_000, cells: int = 8, repeats: int = 3, seed: int = 23
) -> dict[str, float]:
    """Seconds (best of ``repeats``) of the CPU trilinear maps on ``points`` parameters.

    ``forward``: a ``cells``³-cell :class:`~voxwarp.deform.lattice.trilinear.TrilinearGrid`
    (a box of 10 x 20 x 30 mm, nodes jittered by up to 0.1 cell, no folds) and a
    one-cell :class:`~voxwarp.deform.lattice.trilinear.TrilinearTransform` evaluated at
    ``points`` uniform parameters together; ``inverse``: the grid's inverse of the
    mapped points (its bucket grid built before timing). Run it with
    ``python -c "from benchmarks.lattice import bench_cpu_grid; print(bench_cpu_grid())"``.
    """
    from voxwarp.deform.lattice.trilinear import UNIT_CORNERS, TrilinearTransform

    rng = np.random.default_rng(seed)
    g = TrilinearGrid.identity(int(cells))
    size = np.array([10.0, 20.0, 30.0])
    grid = TrilinearGrid(g.nodes * size + rng.uniform(-0.1, 0.1, g.nodes.shape) * size / cells)
    box = np.array([2.0, 3.0, 4.0])
    one = TrilinearTransform(UNIT_CORNERS * box + rng.uniform(-0.12, 0.12, (8, 3)) * box)
    u = rng.uniform(0.0, 1.0, (int(points), 3))
    x = grid(u)
    grid.inverse(x[:10])  # build the bucket grid once
    forward, inverse = best_times(repeats, lambda: (grid(u), one(u)), lambda: grid.inverse(x))
    return {
        "points": float(points),
        "cells": float(cells),
        "forward_s": forward,
        "inverse_s": inverse,
    }
