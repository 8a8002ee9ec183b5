"""``python -m benchmarks wires``: the wire deformation's costs, against references of the same run.

Measures, in one process, the wire deformation of :mod:`voxwarp.deform.wires.field` (Journal of WSCG
2006, non-linear, non-reconstructive volume deformation by sweeping) on a 256³ volume:
the sample ``fish`` generated at (256, 128, 107) (about 0.375 mm isotropic) and padded
with air (-1000 HU) to 256³ symmetrically in y and z, its origin shifted so that its
voxels keep their mm coordinates and ``sample_volumes/fish_spine_wires.json`` (a bent,
twisted spine) applies. Sections of the report:

1. *Field generation* (the paper's Figure 12): :meth:`voxwarp.deform.wires.field.WireDeformer.build`
   at field scales 1, 2, 4, 8, 16 (1:1 ... 1:4096 voxels), float layout, plus the packed
   layout at the render's scale; median over ``repeats`` builds after an untimed one
   (OpenCL kernels and buffers), each stage's median, and the field's voxel counts.
2. *Propagation*: :func:`voxwarp.deform.wires.propagation.nearest_seed` (OpenCL;
:data:`OPENCL_WARMUP`
   untimed calls first) against
   ``scipy.ndimage.distance_transform_edt(~seeds, sampling, return_indices=True)`` on the
   seeds and grid of the 1:1 build (``WireDeformer.propagation_input``), and
   :func:`benchmarks.propagation.benchmark_nearest_seed` on the full 256³ grid.
3. *Render*: wire-deformed dvr (field scale 2, float and packed layouts) against the
   undeformed volume, at 512x256 by default, per transfer function and camera (the
   generic :func:`voxwarp.bench.render.bench_camera`, and one framing the object and where its wires
   move it, :func:`framed_camera`). Per layout: one untimed field build and two draws
   compile both programs; then the field is rebuilt (what editing a wire does) and the
   *first frame* (block checks, field upload) and the *second frame* (builds the
   deformed-space skip maps, :attr:`voxwarp.render.raycaster.Renderer.warped_skip_maps`) are timed;
   then, after one warm-up draw of each, ``frames`` undeformed and deformed frames are
   timed alternately (each bound by ``ctx.finish()``), so that load changes hit both
   alike. The cost is the deformed median over the undeformed median of the same
   alternation. A reference row renders the undeformed volume through the warped path
   (an all-zero offset field): the cost any non-affine warp pays.
4. *Ray statistics* (the paper's Table 1), on the CPU: the rays of every 4th pixel in x
   and y (each camera, pixel centres), sampled as the raycaster does (lattice anchored
   at the entry into the deformed scene's ray box, one sample per sample distance, no
   jitter: offset 1/2) over the whole ray box (no empty-space skipping, no early ray
   termination), each sample classified by :meth:`voxwarp.deform.wires.field.WireFieldWarp._lookup`:
   identity (ignored), vacated or swept.
5. *Phantoms* (the paper's Tables 2-3): preprocessing (field build), render (first and
   steady frame) and total for the fish and, where present, the ``tubes`` twist
   (``sample_volumes/tubes_twist_wires.json``).

Targets (pass/fail in the report): a 1:8 field (scale 2) builds in <= 0.25 s and a 1:1
field in <= 2 s; OpenCL propagation >= 2x faster than the scipy EDT; deformed dvr <= 1.5x
the undeformed.

``--head`` runs only the field build of issue 19 (lever 4) instead: the bundled Colin27
MRI upsampled to 256³ (:func:`head_volume`), one Bézier wire of radius 40 mm
(:data:`HEAD_WIRE`), 1:8 and 1:1 fields, the OpenCL classification pass against the
numpy classification, interleaved (:func:`bench_head_builds`); targets 1:8 <= 0.2 s and
1:1 <= 1.0 s.
"""

from __future__ import annotations

import argparse
import platform
import shlex
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.shared import best_times
from voxwarp.bench.command import emit_report
from voxwarp.bench.render import bench_camera
from voxwarp.core.checks import image_size, positive_int
from voxwarp.core.timing import cpu_count, load_average
from voxwarp.core.volume import Volume
from voxwarp.teaching.wire_measure import (  # noqa: F401 (this module's names too)
    AIR_HU,
    DEFAULT_SCALES,
    FISH_SHAPE,
    FISH_WIRES,
    FRAMED_VIEW,
    PADDED_EDGE,
    RENDER_SCALE,
    STATS_SUBSAMPLE,
    TUBES_WIRES,
    camera_rays,
    content_box,
    framed_camera,
    load_wires,
    padded_fish,
    ray_samples,
)

#: image size of the paper's timings (W, H)
DEFAULT_SIZE: tuple[int, int] = (512, 256)
#: transfer functions the render is timed with: the fish's suggested one (bone) and one
#: showing the soft tissue of its body
DEFAULT_TFS: tuple[str, ...] = ("ct-bone", "ct-soft")
#: field layouts timed in the render
LAYOUTS: tuple[str, ...] = ("float", "packed")
#: cameras of the render: ``bench`` = :func:`voxwarp.bench.render.bench_camera` (oblique (30°, 20°),
#: the whole 256³ box in view: the fish seen nearly head-on, small); ``framed`` = from
#: :data:`FRAMED_VIEW`, zoomed so that the object and the region its wires move it into
#: fill the image (as the paper's figures)
CAMERAS: tuple[str, ...] = ("bench", "framed")
#: the render's reference warp: an all-zero offset field (``inverse="approx"``, one field
#: fetch per sample) renders the undeformed image through the raycaster's warped path,
#: which separates the cost of that path from the wires' own
REFERENCE_LAYOUT = "zero offset field (reference)"
#: targets: field build seconds per scale, propagation speed-up, render cost
TARGET_BUILD_S: dict[int, float] = {2: 0.25, 1: 2.0}
TARGET_PROPAGATION_SPEEDUP = 2.0
TARGET_RENDER_RATIO = 1.5

#: phantoms of section 5 besides the fish: (label, wire file, load_sample keyword args)
DEFAULT_PHANTOMS: tuple[tuple[str, Path, dict[str, Any]], ...] = (("tubes", TUBES_WIRES, {}),)

#: untimed OpenCL propagations before the timed ones: the first builds the kernels and
#: allocates the buffers, and on PoCL the next run on a new grid size is still about
#: twice as slow as the steady state (measured: 0.37, 0.27, then 0.135 s at 256³)
OPENCL_WARMUP = 2


STAGES: tuple[str, ...] = ("tables", "masks", "box", "seeds", "propagate", "flags", "store")


# ---------------------------------------------------------------------- rows
@dataclass
class BuildRow:
    """Field builds at one scale and layout (medians of the timed builds)."""

    scale: int
    layout: str
    field_shape: tuple[int, int, int]
    repeats: int
    median_s: float
    min_s: float
    #: median seconds of each stage (keys of :data:`STAGES`)
    stages: dict[str, float]
    swept: int
    vacated: int
    ignored: int
    voxels: int
    region_voxels: int
    seeds: int
    planes: int
    backend: str

    @property
    def percent_ignored(self) -> float:
        """Field voxels that render as the identity, in %."""
        return 100.0 * self.ignored / max(self.voxels, 1)


@dataclass
class SampleStats:
    """The paper's Table 1: ray samples of the deformed render and how they classify."""

    size: tuple[int, int]
    camera: str
    subsample: int
    rays: int
    rays_hitting: int
    step_mm: float
    samples: int
    identity: int
    vacated: int
    swept: int
    outside_field: int
    #: the paper's way (Table 1): samples inside the wires' regions of influence, and
    #: those of them that need no mapping (0, 0 when no region was given)
    region_samples: int = 0
    region_identity: int = 0

    @property
    def percent_ignored_in_region(self) -> float | None:
        """Ignored samples in % of the samples inside the regions of influence (the
        paper's Table 1 statistic), or None without a region."""
        if not self.region_samples:
            return None
        return 100.0 * self.region_identity / self.region_samples

    @property
    def ignored(self) -> int:
        """Samples that need no mapping: identity (not swept, not vacated)."""
        return self.identity

    @property
    def percent_ignored(self) -> float:
        """Ignored samples, in % of all samples."""
        return 100.0 * self.ignored / max(self.samples, 1)

    @property
    def percent_not_swept(self) -> float:
        """Samples that are not swept (identity or vacated), in %."""
        return 100.0 * (self.samples - self.swept) / max(self.samples, 1)


@dataclass
class PropagationRow:
    """OpenCL nearest-seed propagation vs the scipy EDT on one grid."""

    grid: str
    shape: tuple[int, int, int]
    seeds: int
    scipy_call: str
    scipy_s: float
    opencl_s: float | None
    agree: bool | None
    note: str = ""

    @property
    def speedup(self) -> float | None:
        """scipy seconds / OpenCL seconds (None without OpenCL)."""
        if self.opencl_s is None or self.opencl_s <= 0:
            return None
        return self.scipy_s / self.opencl_s


@dataclass
class RenderRow:
    """Deformed dvr of one layout against the undeformed volume, alternated frame by frame."""

    size: tuple[int, int]
    camera: str
    tf: str
    layout: str
    scale: int
    #: first draw after a field rebuild (block checks; uploads the field), ms; None for
    #: the reference warp
    first_ms: float | None
    #: second draw (builds the deformed-space skip maps), ms; None for the reference
    second_ms: float | None
    frames: int
    median_ms: float
    min_ms: float
    #: the undeformed frames timed alternately with this layout's
    undeformed_median_ms: float
    undeformed_min_ms: float
    #: share of pixels whose colour the warp changed (sanity: the warp is active), %
    changed_pixels: float = 0.0
    skip_kind: str = ""
    #: a reference warp (not a wire field): :data:`REFERENCE_LAYOUT`
    reference: bool = False

    @property
    def ratio(self) -> float:
        """Deformed median / undeformed median (the cost of deforming; 1 = free)."""
        return self.median_ms / self.undeformed_median_ms


@dataclass
class PhantomRow:
    """The paper's Tables 2-3: preprocessing, render and total for one phantom."""

    phantom: str
    wires_file: str
    volume_shape: tuple[int, int, int]
    scale: int
    layout: str
    tf: str
    size: tuple[int, int]
    build_s: float | None
    first_ms: float | None = None
    frame_ms: float | None = None
    undeformed_ms: float | None = None
    note: str = ""

    @property
    def total_s(self) -> float | None:
        """Build + first frame: from the wires to the first image (s)."""
        if self.build_s is None or self.first_ms is None:
            return None
        return self.build_s + self.first_ms / 1000.0


@dataclass
class Target:
    """One target of the issue with its measurement."""

    name: str
    goal: str
    measured: str
    passed: bool | None
    note: str = ""

    def line(self) -> str:
        """``Target: <name> <goal>: <measured> -> PASS|FAIL|NOT MEASURED``."""
        verdict = {True: "PASS", False: "FAIL", None: "NOT MEASURED"}[self.passed]
        extra = f" ({self.note})" if self.note else ""
        return f"Target: {self.name} {self.goal}: {self.measured} -> {verdict}{extra}"


@dataclass
class WireBenchReport:
    """Everything one ``bench wires`` run measured (see the module docstring)."""

    volume: str
    volume_shape: tuple[int, int, int]
    spacing: tuple[float, float, float]
    wires_file: str
    scales: tuple[int, ...]
    repeats: int
    frames: int
    sizes: tuple[tuple[int, int], ...]
    tfs: tuple[str, ...]
    render: bool
    cameras: tuple[str, ...] = CAMERAS
    gl_renderer: str = "not used"
    opencl_device: str = ""
    cores: int = 1
    load: tuple[float, float] = (-1.0, -1.0)
    wall_s: float = 0.0
    builds: list[BuildRow] = field(default_factory=list)
    propagation: list[PropagationRow] = field(default_factory=list)
    renders: list[RenderRow] = field(default_factory=list)
    render_skipped: str = ""
    stats: list[SampleStats] = field(default_factory=list)
    field_stats: dict[str, Any] = field(default_factory=dict)
    phantoms: list[PhantomRow] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def build(self, scale: int, layout: str = "float") -> BuildRow | None:
        """The build row of ``scale`` and ``layout`` (None if not measured)."""
        for r in self.builds:
            if r.scale == scale and r.layout == layout:
                return r
        return None

    def render_row(
        self, size: tuple[int, int], tf: str, layout: str, camera: str = "framed"
    ) -> RenderRow | None:
        """The render row of an image size, transfer function, layout and camera."""
        for r in self.renders:
            if (r.size, r.tf, r.layout, r.camera) == (tuple(size), tf, layout, camera):
                return r
        return None

    # ------------------------------------------------------------------ targets
    def targets(self) -> list[Target]:
        """Every target of the issue, measured or not."""
        out: list[Target] = []
        for scale, limit in sorted(TARGET_BUILD_S.items(), reverse=True):
            name = f"field build at 1:{scale**3} (scale {scale}, float layout)"
            row = self.build(scale)
            if row is None:
                out.append(Target(name, f"<= {limit:g} s", "not measured", None, "scale not run"))
                continue
            out.append(
                Target(
                    name,
                    f"<= {limit:g} s",
                    f"{row.median_s:.3f} s (median of {row.repeats}) = {row.median_s / limit:.2f}"
                    " x the limit",
                    row.median_s <= limit,
                )
            )
        for p in self.propagation:
            name = f"OpenCL propagation on the {p.grid} grid {'x'.join(map(str, p.shape))}"
            goal = f">= {TARGET_PROPAGATION_SPEEDUP:g}x faster than {p.scipy_call}"
            sp = p.speedup
            if sp is None:
                out.append(Target(name, goal, "not measured", None, p.note or "no OpenCL"))
            else:
                out.append(
                    Target(
                        name,
                        goal,
                        f"{sp:.1f}x ({_s(p.opencl_s)} vs {_s(p.scipy_s)})",
                        sp >= TARGET_PROPAGATION_SPEEDUP,
                    )
                )
        if not self.propagation:
            out.append(
                Target(
                    "OpenCL propagation",
                    f">= {TARGET_PROPAGATION_SPEEDUP:g}x faster than the scipy EDT",
                    "not measured",
                    None,
                )
            )
        goal = f"<= {TARGET_RENDER_RATIO:g}x the undeformed dvr"
        if not self.renders:
            why = self.render_skipped or "render not run"
            out.append(Target("deformed dvr", goal, "not measured", None, why))
        for r in self.renders:
            if r.reference:
                continue
            name = (
                f"deformed dvr {r.size[0]}x{r.size[1]} {r.camera} camera {r.tf}, {r.layout}"
                f" layout, 1:{r.scale**3} field"
            )
            out.append(
                Target(
                    name,
                    goal,
                    f"{r.ratio:.2f}x ({r.median_ms:.1f} vs {r.undeformed_median_ms:.1f} ms)",
                    r.ratio <= TARGET_RENDER_RATIO,
                )
            )
        return out

    def target_lines(self) -> list[str]:
        """The target lines as printed in the report."""
        return [t.line() for t in self.targets()]

    # ------------------------------------------------------------------ markdown
    def markdown(self, command: str) -> str:
        """The report in markdown, headed by the command that produced it."""
        import scipy

        sizes = ", ".join(f"{w}x{h}" for w, h in self.sizes)
        lines = [
            f"Command: `{command}`",
            "",
            f"Volume: {self.volume}, {'x'.join(map(str, self.volume_shape))} voxels of"
            f" {' x '.join(f'{s:.4g}' for s in self.spacing)} mm; wires:"
            f" `{self.wires_file}`. Image {sizes}; timed builds per configuration:"
            f" {self.repeats}; timed frames per render: {self.frames}.",
            "",
            f"Device: GL {self.gl_renderer}; OpenCL {self.opencl_device or 'none'}; CPU"
            f" {platform.processor() or platform.machine()}, {self.cores} cores; numpy"
            f" {np.__version__}, scipy {scipy.__version__}; 1-minute load average before /"
            f" after the run {self.load[0]:.2f} / {self.load[1]:.2f}; the run took"
            f" {self.wall_s:.0f} s.",
            "",
            "## Targets",
            "",
            *[f"* {line}" for line in self.target_lines()],
            "",
            *self._builds_md(),
            *self._propagation_md(),
            *self._render_md(),
            *self._stats_md(),
            *self._phantoms_md(),
        ]
        if self.notes:
            lines += ["## Notes", "", *[f"* {n}" for n in self.notes], ""]
        return "\n".join(lines).rstrip() + "\n"

    def _builds_md(self) -> list[str]:
        lines = [
            "## 1. Field generation (paper Figure 12)",
            "",
            "`WireDeformer.build()`; seconds, median (min) of the timed builds after an"
            " untimed one; stage columns are each stage's median. Voxel counts of the"
            " attribute field: swept, vacated (the bent object's original place), ignored"
            " (identity).",
            "",
            "| scale | voxels | field shape | layout | build s | "
            + " | ".join(STAGES)
            + " | region voxels | seeds | swept | vacated | ignored | % ignored | backend |",
            "|---|---|---|---|---:|" + "---:|" * len(STAGES) + "---:|---:|---:|---:|---:|---:|---|",
        ]
        for r in self.builds:
            stages = " | ".join(f"{r.stages.get(s, 0.0):.3f}" for s in STAGES)
            lines.append(
                f"| {r.scale} | 1:{r.scale**3} | {'x'.join(map(str, r.field_shape))} |"
                f" {r.layout} | {r.median_s:.3f} ({r.min_s:.3f}) | {stages} |"
                f" {r.region_voxels} | {r.seeds} | {r.swept} | {r.vacated} | {r.ignored} |"
                f" {r.percent_ignored:.2f} | {r.backend} |"
            )
        return [*lines, ""]

    def _propagation_md(self) -> list[str]:
        lines = [
            "## 2. Propagation: OpenCL nearest seed vs scipy",
            "",
            "Median wall seconds (host<->device transfers included; OpenCL kernel build,"
            f" buffer allocation and first runs excluded by {OPENCL_WARMUP} untimed calls)."
            " agree: the distances to the chosen seeds match within 1e-4.",
            "",
            "| grid | shape | seeds | OpenCL s | scipy s | scipy call | speed-up | agree | note |",
            "|---|---|---:|---:|---:|---|---:|---|---|",
        ]
        for p in self.propagation:
            sp = f"{p.speedup:.1f}x" if p.speedup is not None else "—"
            agree = "—" if p.agree is None else ("yes" if p.agree else "NO")
            lines.append(
                f"| {p.grid} | {'x'.join(map(str, p.shape))} | {p.seeds} | {_s(p.opencl_s)} |"
                f" {_s(p.scipy_s)} | `{p.scipy_call}` | {sp} | {agree} | {p.note} |"
            )
        return [*lines, ""]

    def _render_md(self) -> list[str]:
        lines = ["## 3. Render: wire-deformed vs undeformed dvr", ""]
        if not self.renders:
            return [*lines, f"Not run: {self.render_skipped or 'render off'}.", ""]
        lines += [
            "Field scale 2 (1:8). first: first draw after a field rebuild (block checks,"
            " field upload); second: the next draw, which builds the deformed-space skip"
            " maps; steady: median (min) of the frames timed alternately with the"
            " undeformed volume after one warm-up draw of each; cost = deformed /"
            " undeformed median. changed: pixels the warp changes (sanity check). Cameras:"
            " bench = `voxwarp.bench.render.bench_camera` (oblique (30°, 20°) view of the"
            " whole volume box: the fish nearly head-on and small); framed = view"
            f" {FRAMED_VIEW} (from -y and above), zoomed so that the fish and the region"
            " its wires bend it into fill the image, as in the paper's figures. The"
            f" {REFERENCE_LAYOUT} row renders the undeformed volume through the warped"
            " path (an all-zero `OffsetFieldWarp`, one field fetch per sample, same skip"
            " maps as the undeformed volume): the part of the cost that any non-affine warp"
            " pays.",
            "",
            "| image | camera | TF | layout | first ms | second ms | steady ms |"
            " undeformed ms | cost | skipping | changed |",
            "|---|---|---|---|---:|---:|---:|---:|---:|---|---:|",
        ]
        for r in self.renders:
            lines.append(
                f"| {r.size[0]}x{r.size[1]} | {r.camera} | {r.tf} | {r.layout} |"
                f" {_ms0(r.first_ms)} |"
                f" {_ms0(r.second_ms)} | {r.median_ms:.1f} ({r.min_ms:.1f}) |"
                f" {r.undeformed_median_ms:.1f} ({r.undeformed_min_ms:.1f}) |"
                f" {r.ratio:.2f}x | {r.skip_kind} | {r.changed_pixels:.1f}% |"
            )
        return [*lines, ""]

    def _stats_md(self) -> list[str]:
        lines = ["## 4. Ray samples and field voxels (paper Table 1)", ""]
        if self.stats:
            sub = self.stats[0].subsample
            lines += [
                f"Rays through every {sub}th pixel in x and y (pixel centres) of each"
                " camera, sampled at the render's sample distance over the deformed"
                " scene's whole ray box (no skipping, no early termination, no jitter),"
                " classified by `WireFieldWarp._lookup` (float layout, scale"
                f" {RENDER_SCALE}). ignored = identity samples (no mapping needed).",
                "",
                "| image | camera | rays traced | rays hitting the box | step mm | samples |"
                " ignored (identity) | vacated | swept | % ignored | % not swept |"
                " outside field |",
                "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
            ]
            for s in self.stats:
                lines.append(
                    f"| {s.size[0]}x{s.size[1]} | {s.camera} | {s.rays} | {s.rays_hitting} |"
                    f" {s.step_mm:.4g} | {s.samples} | {s.identity} | {s.vacated} |"
                    f" {s.swept} | {s.percent_ignored:.2f} | {s.percent_not_swept:.2f} |"
                    f" {s.outside_field} |"
                )
            lines.append("")
        if self.field_stats:
            f = self.field_stats
            lines += [
                f"Field voxels (`WireFieldStats`, scale {f['field_scale']}, {f['layout']}):"
                f" {'x'.join(map(str, f['field_shape']))} = {f['voxels']} voxels, swept"
                f" {f['swept']}, vacated {f['vacated']}, ignored {f['ignored']}"
                f" ({f['percent_ignored']:.2f} %); {f['planes']} mask planes"
                f" ({f['planes_dropped']} dropped; {f.get('mask_bytes_total', 0)} bytes of"
                f" masks, section 7.1's sum a(p) s / 8), {f['seeds']} seeds, propagated region"
                f" {f['region_voxels']} voxels.",
                "",
            ]
        return lines

    def _phantoms_md(self) -> list[str]:
        lines = [
            "## 5. Phantoms: preprocessing, render, total (paper Tables 2-3)",
            "",
            "build: median field build (s); first: first frame after the build (ms);"
            " frame: steady frame (ms); total = build + first frame (s).",
            "",
            "| phantom | wires | volume | field | layout | TF | image | build s | first ms |"
            " frame ms | undeformed ms | total s | note |",
            "|---|---|---|---|---|---|---|---:|---:|---:|---:|---:|---|",
        ]
        for p in self.phantoms:
            lines.append(
                f"| {p.phantom} | `{p.wires_file}` | {'x'.join(map(str, p.volume_shape))} |"
                f" 1:{p.scale**3} | {p.layout} | {p.tf} | {p.size[0]}x{p.size[1]} |"
                f" {_s(p.build_s)} | {_ms(p.first_ms)} | {_ms(p.frame_ms)} |"
                f" {_ms(p.undeformed_ms)} | {_s(p.total_s)} | {p.note} |"
            )
        return [*lines, ""]


def _s(x: float | None) -> str:
    """Seconds, 3 significant digits."""
    return "—" if x is None else f"{x:.3g}"


def _ms(x: float | None) -> str:
    return "—" if x is None else f"{x:.1f}"


def _ms0(x: float | None) -> str:
    return "—" if x is None else f"{x:.0f}"


# ---------------------------------------------------------------------- volume and wires


def check_scales(scales: Sequence[int]) -> tuple[int, ...]:
    """Validate field scales (ValueError naming the allowed ones)."""
    from voxwarp.deform.wires.field import FIELD_SCALES

    out = tuple(int(s) for s in scales)
    bad = [s for s in out if s not in FIELD_SCALES]
    if not out or bad:
        raise ValueError(
            f"field scales must be among {', '.join(map(str, FIELD_SCALES))}; got"
            f" {', '.join(map(str, bad)) if bad else 'none'}"
        )
    return tuple(dict.fromkeys(out))


# ---------------------------------------------------------------------- 1. builds
def time_builds(
    volume: Volume, wires: Sequence[Any], scale: int, layout: str, repeats: int
) -> tuple[BuildRow, Any]:
    """Build the field ``1 + repeats`` times (the first untimed); the row and deformer."""
    from voxwarp.deform.wires.field import WireDeformer

    wd = WireDeformer(volume, wires, field_scale=scale, layout=layout)
    wd.build()  # untimed: OpenCL kernels / buffers of this grid size
    totals: list[float] = []
    stages: dict[str, list[float]] = {s: [] for s in STAGES}
    st = None
    for _ in range(max(1, int(repeats))):
        st = wd.build()
        totals.append(st.timings["total"])
        for s in STAGES:
            stages[s].append(st.timings.get(s, 0.0))
    assert st is not None
    row = BuildRow(
        scale=scale,
        layout=layout,
        field_shape=tuple(int(n) for n in st.field_shape),  # type: ignore[arg-type]
        repeats=len(totals),
        median_s=statistics.median(totals),
        min_s=min(totals),
        stages={s: statistics.median(v) for s, v in stages.items()},
        swept=st.swept,
        vacated=st.vacated,
        ignored=st.ignored,
        voxels=st.voxels,
        region_voxels=st.region_voxels,
        seeds=st.seeds,
        planes=st.planes,
        backend=st.backend,
    )
    return row, wd


# ---------------------------------------------------------------------- 2. propagation
def bench_propagation(
    seeds: np.ndarray, sampling: Sequence[float], repeats: int, grid: str
) -> PropagationRow:
    """OpenCL :func:`~voxwarp.deform.wires.propagation.nearest_seed` vs scipy's EDT on ``seeds``."""
    from scipy import ndimage

    from benchmarks.propagation import seed_distance
    from voxwarp.deform.wires.propagation import nearest_seed, opencl_available

    h = tuple(float(v) for v in sampling)
    call = "distance_transform_edt(~seeds, sampling, return_indices=True)"
    times = []
    dist = None
    for _ in range(max(1, int(repeats))):
        t = time.perf_counter()
        dist, _idx = ndimage.distance_transform_edt(~seeds, sampling=h, return_indices=True)
        times.append(time.perf_counter() - t)
    row = PropagationRow(
        grid=grid,
        shape=tuple(int(n) for n in seeds.shape),  # type: ignore[arg-type]
        seeds=int(seeds.sum()),
        scipy_call=call,
        scipy_s=statistics.median(times),
        opencl_s=None,
        agree=None,
    )
    if not opencl_available():
        row.note = "no OpenCL platform: OpenCL skipped"
        return row
    for _ in range(OPENCL_WARMUP):  # untimed: kernels, buffers, first runs
        nearest_seed(seeds, h, backend="opencl")
    times = []
    got = None
    for _ in range(max(1, int(repeats))):
        t = time.perf_counter()
        got = nearest_seed(seeds, h, backend="opencl")
        times.append(time.perf_counter() - t)
    row.opencl_s = statistics.median(times)
    assert got is not None
    assert dist is not None
    row.agree = bool(np.allclose(seed_distance(got, h), dist, rtol=1e-4, atol=1e-4))
    return row


def bench_full_grid(edge: int, sampling: Sequence[float], repeats: int) -> PropagationRow:
    """:func:`benchmarks.propagation.benchmark_nearest_seed` on an ``edge``³ grid (helix)."""
    from benchmarks.propagation import benchmark_nearest_seed, helix_seeds
    from voxwarp.deform.wires.propagation import MAX_LINE, nearest_seed, opencl_available

    if opencl_available() and edge <= MAX_LINE:
        # benchmark_nearest_seed makes one untimed call; on PoCL the second call on a
        # new grid size is still ~2x slower than the steady state: warm up beforehand
        seeds = helix_seeds((edge,) * 3)
        for _ in range(OPENCL_WARMUP - 1):
            nearest_seed(seeds, tuple(sampling), backend="opencl")
    res = benchmark_nearest_seed((edge,) * 3, tuple(sampling), repeats=repeats)
    row = PropagationRow(
        grid=f"full {edge}³ (helix seeds)",
        shape=tuple(res["shape"]),
        seeds=int(res["n_seeds"]),
        scipy_call="nearest_seed(backend='scipy') = EDT indices only",
        scipy_s=float(res["scipy_s"]),
        opencl_s=res["opencl_s"],
        agree=res["agree"],
    )
    if res["opencl_s"] is None:
        row.note = "no OpenCL platform: OpenCL skipped"
    return row


# ---------------------------------------------------------------------- 4. ray samples


def ray_sample_stats(
    scene: Any,
    camera: Any,
    size: tuple[int, int],
    warp: Any,
    subsample: int = STATS_SUBSAMPLE,
    chunk: int = 1_000_000,
    label: str = "",
    region: Callable[[np.ndarray], np.ndarray] | None = None,
) -> SampleStats:
    """Classify the ray samples of ``scene`` (deformed by ``warp``) on the CPU; with
    ``region`` (points (N, 3) -> bool (N,), e.g. :func:`influence_region`) also count
    the samples inside it (the paper's Table 1 counts only those)."""
    rs = ray_samples(scene, camera, size, subsample, chunk)
    fld = warp.field
    counts = np.zeros(3, dtype=np.int64)
    outside = in_region = region_identity = 0
    for p in rs.chunks:
        state, _, _ = warp._lookup(p)
        counts += np.bincount(state, minlength=3)[:3]
        if region is not None:
            inside = np.asarray(region(p), dtype=bool)
            in_region += int(np.count_nonzero(inside))
            region_identity += int(np.count_nonzero(inside & (state == 0)))
        g = (p - fld.lo) / fld.spacing
        outside += int(np.count_nonzero(~np.all((g >= 0) & (g < np.asarray(fld.shape)), axis=1)))
    return SampleStats(
        size=(int(size[0]), int(size[1])),
        camera=label,
        subsample=int(subsample),
        rays=rs.rays,
        rays_hitting=rs.rays_hitting,
        step_mm=rs.step_mm,
        samples=int(counts.sum()),
        identity=int(counts[0]),
        vacated=int(counts[1]),
        swept=int(counts[2]),
        outside_field=outside,
        region_samples=in_region,
        region_identity=region_identity,
    )


def influence_region(
    wires: Sequence[Any], samples: int = 1025
) -> Callable[[np.ndarray], np.ndarray]:
    """The wires' regions of influence as a point test: within ``radius`` times the
    largest scale of a modified wire (where swept samples land) or within ``radius`` of
    a base wire (the place they left). Distances are to ``samples`` points per curve
    (their spacing, a fraction of a mm on these wires, is the test's tolerance)."""
    from scipy.spatial import cKDTree

    parts = []
    u = np.linspace(0.0, 1.0, int(samples))
    for w in wires:
        smax = float(np.max(w.scale[:, 1]))
        parts.append((cKDTree(w.modified.evaluate(u)), w.radius * smax))
        parts.append((cKDTree(w.base.evaluate(u)), w.radius))

    def inside(points: np.ndarray) -> np.ndarray:
        out = np.zeros(len(points), dtype=bool)
        for tree, r in parts:
            d, _ = tree.query(points, distance_upper_bound=r)
            out |= np.isfinite(d)
        return out

    return inside


# ---------------------------------------------------------------------- 3. render
def _frame_ms(r: Any, scene: Any) -> float:
    return float(r.time_frames(scene, frames=1, warmup=0)[0])


def _changed_pixels(r: Any, a: Any, b: Any) -> float:
    ia, ib = r.render(a), r.render(b)
    diff = np.abs(ia.astype(np.int16) - ib.astype(np.int16)).max(axis=-1) > 2
    return 100.0 * float(diff.mean())


def _render_layout(
    r: Any,
    base: Any,
    wd: Any,
    size: tuple[int, int],
    camera: str,
    tf: str,
    frames: int,
    log: Callable[[str], None],
) -> RenderRow:
    """Time one deformer's warp against ``base`` (the programs already compiled)."""
    warp = wd.warp()
    scene = base.copy(warps=[warp])
    wd.build()  # a new field revision, as after editing a wire
    first = _frame_ms(r, scene)
    second = _frame_ms(r, scene)
    _frame_ms(r, base)  # warm-up of each
    _frame_ms(r, scene)
    ours, ref = [], []
    for _ in range(max(1, int(frames))):
        ref.append(_frame_ms(r, base))
        ours.append(_frame_ms(r, scene))
    skip_kind = r.renderer.last_skip_kind  # of the last (deformed) frame
    row = RenderRow(
        size=size,
        camera=camera,
        tf=tf,
        layout=wd.layout,
        scale=wd.field_scale,
        first_ms=first,
        second_ms=second,
        frames=len(ours),
        median_ms=statistics.median(ours),
        min_ms=min(ours),
        undeformed_median_ms=statistics.median(ref),
        undeformed_min_ms=min(ref),
        changed_pixels=_changed_pixels(r, base, scene),
        skip_kind=skip_kind,
    )
    log(
        f"render {size[0]}x{size[1]} {camera} {tf} {wd.layout}: first {first:.0f} ms, second"
        f" {second:.0f} ms, steady {row.median_ms:.1f} ms vs undeformed"
        f" {row.undeformed_median_ms:.1f} ms ({row.ratio:.2f}x)"
    )
    return row


def _render_reference(
    r: Any,
    base: Any,
    size: tuple[int, int],
    camera: str,
    tf: str,
    frames: int,
    log: Callable[[str], None],
) -> RenderRow:
    """The undeformed volume through the warped path (:data:`REFERENCE_LAYOUT`)."""
    from voxwarp.deform.elements.offset_field import OffsetFieldWarp

    lo, hi = base.volume.bounds
    scene = base.copy(warps=[OffsetFieldWarp(lo, hi, np.zeros((2, 2, 2, 3)), inverse="approx")])
    for _ in range(2):  # block checks, then the skip maps
        _frame_ms(r, scene)
    _frame_ms(r, base)
    _frame_ms(r, scene)
    ours, ref = [], []
    for _ in range(max(1, int(frames))):
        ref.append(_frame_ms(r, base))
        ours.append(_frame_ms(r, scene))
    row = RenderRow(
        size=size,
        camera=camera,
        tf=tf,
        layout=REFERENCE_LAYOUT,
        scale=0,
        first_ms=None,
        second_ms=None,
        frames=len(ours),
        median_ms=statistics.median(ours),
        min_ms=min(ours),
        undeformed_median_ms=statistics.median(ref),
        undeformed_min_ms=min(ref),
        changed_pixels=_changed_pixels(r, base, scene),
        skip_kind=r.renderer.last_skip_kind,
        reference=True,
    )
    log(
        f"render {size[0]}x{size[1]} {camera} {tf} zero offset field: {row.median_ms:.1f} ms"
        f" vs undeformed {row.undeformed_median_ms:.1f} ms ({row.ratio:.2f}x)"
    )
    return row


def make_camera(kind: str, volume: Volume, wires: Sequence[Any], size: tuple[int, int]) -> Any:
    """The ``bench`` or ``framed`` camera (see :data:`CAMERAS`)."""
    if kind == "bench":
        return bench_camera(volume)
    if kind == "framed":
        return framed_camera(volume, wires, size)
    raise ValueError(f"unknown camera {kind!r}; cameras: {', '.join(CAMERAS)}")


def _prime(r: Any, scene: Any) -> None:
    """Two draws of a deformed scene: compile its block-check and skip-map programs."""
    r.render(scene)
    r.render(scene)


# ---------------------------------------------------------------------- the benchmark
def bench_wires(
    volume: Volume | None = None,
    *,
    wires_file: Path = FISH_WIRES,
    scales: Sequence[int] = DEFAULT_SCALES,
    repeats: int = 3,
    frames: int = 5,
    sizes: Sequence[tuple[int, int]] = (DEFAULT_SIZE,),
    tfs: Sequence[str] = DEFAULT_TFS,
    cameras: Sequence[str] = CAMERAS,
    render: bool = True,
    reference: bool = True,
    full_grid: int = PADDED_EDGE,
    subsample: int = STATS_SUBSAMPLE,
    phantoms: Sequence[tuple[str, Path, dict[str, Any]]] = DEFAULT_PHANTOMS,
    ctx: Any = None,
    log: Callable[[str], None] = print,
) -> WireBenchReport:
    """Run the wire benchmark (see the module docstring).

    Parameters
    ----------
    volume
        The volume the wires of ``wires_file`` bend; default :func:`padded_fish` (256³).
    scales
        Field scales of section 1 (each in 1, 2, 4, 8, 16).
    repeats
        Timed builds / propagations per configuration.
    frames
        Timed frames per render configuration (and as many undeformed ones).
    sizes
        Image sizes (W, H) of the renders.
    tfs
        Transfer functions (preset names) of the renders.
    cameras
        Cameras of the renders and ray statistics (:data:`CAMERAS`).
    render
        Time the renders (needs an OpenGL 4.3 context).
    reference
        Also time the reference warp (:data:`REFERENCE_LAYOUT`) per camera and TF.
    full_grid
        Edge of the cube of :func:`benchmarks.propagation.benchmark_nearest_seed` (0: skip).
    subsample
        Ray statistics trace every ``subsample``-th pixel in x and y.
    phantoms
        Section 5 phantoms besides the bench volume: (label, wire file, keyword arguments
        of :func:`voxwarp.io.samples.load_sample`); a missing file gives a row with a note.
    ctx
        moderngl context to render on (current); by default a standalone one is made.
    log
        Progress messages go here.
    """
    from voxwarp.deform.wires.propagation import opencl_device_name

    scales = check_scales(scales)
    repeats = max(1, int(repeats))
    frames = max(1, int(frames))
    sizes = tuple((int(w), int(h)) for w, h in sizes)
    if not sizes:
        raise ValueError("give at least one image size")
    cameras = tuple(dict.fromkeys(cameras))
    if not cameras or any(c not in CAMERAS for c in cameras):
        raise ValueError(f"cameras must be among {', '.join(CAMERAS)}; got {cameras}")
    if not tfs:
        raise ValueError("give at least one transfer function")
    t_start = time.perf_counter()
    load_start = load_average()
    if volume is None:
        log(f"generating the fish at {'x'.join(map(str, FISH_SHAPE))}, padding to 256³ ...")
        volume = padded_fish()
    wires, spec = load_wires(wires_file)
    report = WireBenchReport(
        volume=volume.name,
        volume_shape=volume.shape,
        spacing=tuple(float(s) for s in volume.spacing),  # type: ignore[arg-type]
        wires_file=_display_path(wires_file),
        scales=scales,
        repeats=repeats,
        frames=frames,
        sizes=sizes,
        tfs=tuple(tfs),
        render=bool(render),
        cameras=cameras,
        cores=cpu_count(),
    )
    report.opencl_device = opencl_device_name()

    # 1. field generation per scale (float), and packed at the render scale
    prop_input = None
    prop_scale = min(scales)
    deformers: dict[tuple[int, str], Any] = {}
    for scale in sorted(scales, reverse=True):
        row, wd = time_builds(volume, wires, scale, "float", repeats)
        report.builds.append(row)
        log(
            f"build 1:{scale**3} (scale {scale}) {'x'.join(map(str, row.field_shape))}:"
            f" {row.median_s:.3f} s (masks {row.stages['masks']:.3f}, propagate"
            f" {row.stages['propagate']:.3f}, flags {row.stages['flags']:.3f})"
        )
        if scale == prop_scale:
            prop_input = wd.propagation_input
        if scale == RENDER_SCALE:
            deformers[(scale, "float")] = wd
    report.builds.sort(key=lambda r: r.scale)
    row, wd = time_builds(volume, wires, RENDER_SCALE, "packed", repeats)
    report.builds.append(row)
    deformers[(RENDER_SCALE, "packed")] = wd
    if (RENDER_SCALE, "float") not in deformers:
        deformers[(RENDER_SCALE, "float")] = time_builds(volume, wires, RENDER_SCALE, "float", 1)[1]
    log(f"build 1:{RENDER_SCALE**3} packed: {row.median_s:.3f} s")

    # 2. propagation
    if prop_input is not None:
        seeds, h = prop_input
        grid = f"1:{prop_scale**3} field's region"
        if prop_scale != 1:
            report.notes.append(
                f"Scale 1 was not run: propagation timed on the scale-{prop_scale} grid."
            )
        prow = bench_propagation(seeds, h, repeats, grid)
        report.propagation.append(prow)
        log(
            f"propagation {grid} {prow.shape}: OpenCL {_s(prow.opencl_s)} s,"
            f" scipy {prow.scipy_s:.3f} s"
        )
    if full_grid:
        prow = bench_full_grid(int(full_grid), volume.spacing, repeats)
        report.propagation.append(prow)
        log(f"propagation {prow.grid}: OpenCL {_s(prow.opencl_s)} s, scipy {prow.scipy_s:.3f} s")
    if not report.opencl_device:
        report.notes.append("No OpenCL platform: the OpenCL propagation was skipped.")

    # 4. ray statistics (CPU) and field statistics of the render's field
    wd_float = deformers[(RENDER_SCALE, "float")]
    warp_float = wd_float.warp()
    report.field_stats = wd_float.stats.as_dict()
    from voxwarp.scene import Scene

    for size in sizes:
        for kind in cameras:
            cam = make_camera(kind, volume, wires, size)
            scene = Scene(
                volume, mode="dvr", transfer_function=tfs[0], camera=cam, warps=[warp_float]
            )
            st = ray_sample_stats(scene, cam, size, warp_float, subsample, label=kind)
            report.stats.append(st)
            log(
                f"ray samples {size[0]}x{size[1]} {kind} camera (every {subsample}th pixel):"
                f" {st.samples}, {st.percent_ignored:.2f}% ignored"
            )

    # 3. render (and 5. phantoms' render times)
    fish_render: dict[str, RenderRow] = {}
    own_ctx = False
    if render:
        from voxwarp.errors import RenderError
        from voxwarp.render.context import create_context

        try:
            if ctx is None:
                ctx = create_context()
                own_ctx = True
            report.gl_renderer = str(ctx.info.get("GL_RENDERER", "?"))
        except RenderError as exc:
            report.render_skipped = f"no OpenGL 4.3 context: {exc}"
            log(f"render skipped: {exc}")
            ctx = None
    else:
        report.render_skipped = "--no-render"
    try:
        if ctx is not None:
            _bench_renders(
                report, volume, wires, deformers, sizes, tfs, frames, ctx, log, reference
            )
            for row in report.renders:
                if row.size == sizes[0] and row.tf == _fish_tf() and row.camera == cameras[-1]:
                    fish_render[row.layout] = row
        _bench_phantoms(
            report,
            volume,
            spec,
            fish_render,
            sizes[0],
            cameras[-1],
            phantoms,
            repeats,
            frames,
            ctx,
            log,
        )
    finally:
        if own_ctx and ctx is not None:
            ctx.release()
    report.load = (load_start, load_average())
    report.wall_s = time.perf_counter() - t_start
    return report


def _fish_tf() -> str:
    from voxwarp.io.samples import suggested_transfer_function

    return str(suggested_transfer_function("fish"))


def _display_path(path: Path) -> str:
    try:
        return str(Path(path).resolve().relative_to(FISH_WIRES.parent.parent))
    except ValueError:
        return str(path)


def _bench_renders(
    report: WireBenchReport,
    volume: Volume,
    wires: Sequence[Any],
    deformers: dict[tuple[int, str], Any],
    sizes: Sequence[tuple[int, int]],
    tfs: Sequence[str],
    frames: int,
    ctx: Any,
    log: Callable[[str], None],
    reference: bool = True,
) -> None:
    from voxwarp.render.offscreen import OffscreenRenderer
    from voxwarp.scene import Scene

    for size in sizes:
        with OffscreenRenderer(*size, ctx=ctx) as r:
            primed = False
            for kind in report.cameras:
                cam = make_camera(kind, volume, wires, size)
                for tf in tfs:
                    base = Scene(volume, mode="dvr", transfer_function=tf, camera=cam)
                    r.render(base)  # volume upload, program, this TF's skip maps
                    for layout in LAYOUTS:
                        wd = deformers[(RENDER_SCALE, layout)]
                        if not primed:
                            _prime(r, base.copy(warps=[wd.warp()]))
                        report.renders.append(
                            _render_layout(r, base, wd, size, kind, tf, frames, log)
                        )
                    primed = True
                    if reference:
                        report.renders.append(
                            _render_reference(r, base, size, kind, tf, frames, log)
                        )


def _bench_phantoms(
    report: WireBenchReport,
    volume: Volume,
    spec: dict[str, Any],
    fish_render: dict[str, RenderRow],
    size: tuple[int, int],
    camera: str,
    phantoms: Sequence[tuple[str, Path, dict[str, Any]]],
    repeats: int,
    frames: int,
    ctx: Any,
    log: Callable[[str], None],
) -> None:
    """Section 5: the bench volume's rows (from sections 1 and 3), then each phantom."""
    scale = int(spec.get("field_scale", RENDER_SCALE))
    for layout in LAYOUTS:
        b = report.build(RENDER_SCALE, layout)
        fr = fish_render.get(layout)
        report.phantoms.append(
            PhantomRow(
                phantom="fish (bench volume)",
                wires_file=report.wires_file,
                volume_shape=volume.shape,
                scale=RENDER_SCALE,
                layout=layout,
                tf=_fish_tf(),
                size=size,
                build_s=b.median_s if b else None,
                first_ms=fr.first_ms if fr else None,
                frame_ms=fr.median_ms if fr else None,
                undeformed_ms=fr.undeformed_median_ms if fr else None,
                note=(
                    f"from sections 1 and 3 ({camera} camera)"
                    + ("" if scale == RENDER_SCALE else f"; the wire file asks scale {scale}")
                    + ("" if fr else "; render not run")
                ),
            )
        )
    for label, path, kwargs in phantoms:
        report.phantoms.append(
            _phantom_row(label, Path(path), kwargs, size, camera, repeats, frames, ctx, log)
        )


def _phantom_row(
    label: str,
    path: Path,
    kwargs: dict[str, Any],
    size: tuple[int, int],
    camera: str,
    repeats: int,
    frames: int,
    ctx: Any,
    log: Callable[[str], None],
) -> PhantomRow:
    from voxwarp.io.samples import load_sample, suggested_transfer_function
    from voxwarp.scene import Scene

    if not path.exists():
        log(f"{label}: {path.name} is missing: skipped")
        return PhantomRow(
            label,
            _display_path(path),
            (0, 0, 0),
            RENDER_SCALE,
            "float",
            "—",
            size,
            None,
            note=f"skipped: {_display_path(path)} does not exist",
        )
    wires, spec = load_wires(path)
    sample = str(spec.get("sample", label))
    vol = load_sample(sample, **kwargs)
    scale = int(spec.get("field_scale", RENDER_SCALE))
    layout = str(spec.get("layout", "float"))
    tf = str(suggested_transfer_function(sample))
    row_b, wd = time_builds(vol, wires, scale, layout, repeats)
    row = PhantomRow(label, _display_path(path), vol.shape, scale, layout, tf, size, row_b.median_s)
    log(f"{label}: build 1:{scale**3} {row_b.median_s:.3f} s")
    if ctx is None:
        row.note = "render not run"
        return row
    from voxwarp.render.offscreen import OffscreenRenderer

    cam = make_camera(camera, vol, wires, size)
    base = Scene(vol, mode="dvr", transfer_function=tf, camera=cam)
    with OffscreenRenderer(*size, ctx=ctx) as r:
        r.render(base)
        _prime(r, base.copy(warps=[wd.warp()]))
        rr = _render_layout(r, base, wd, size, camera, tf, frames, log)
    row.first_ms, row.frame_ms, row.undeformed_ms = (
        rr.first_ms,
        rr.median_ms,
        rr.undeformed_median_ms,
    )
    row.note = (
        f"{camera} camera; steady cost {rr.ratio:.2f}x undeformed; second frame (skip"
        f" maps) {rr.second_ms:.0f} ms;"
        f" {row_b.swept} swept field voxels, {row_b.percent_ignored:.2f}% ignored"
    )
    return row


# ---------------------------------------------------------------------- command line
# ---------------------------------------------------------------------- MRI head build
#: the head case of issue 19 (lever 4): the bundled Colin27 MRI (91x109x91, 2 mm)
#: upsampled trilinearly to HEAD_EDGE³ (no real 256³ MRI head is bundled), one Bézier
#: wire of radius 40 mm bent and twisted through it, β = MRI values 40..255
HEAD_EDGE = 256
HEAD_WIRE: dict[str, Any] = {
    "base": [[0, -20, -60], [0, -20, -10], [0, -20, 40], [0, -20, 90]],
    "modified": [[0, -20, -60], [0, -10, -10], [15, 0, 40], [25, 0, 80]],
    "kind": "bezier",
    "radius": 40.0,
    "beta": [40, 255],
    "twist": [[0, 0], [1, 0.5]],
    "sides": "rigid",  # the paper's sweep (its build times are the targets)
}
#: field scales of the head case (1:8, 1:1) and its targets (s)
HEAD_SCALES: tuple[int, ...] = (2, 1)
TARGET_HEAD_BUILD_S: dict[int, float] = {2: 0.2, 1: 1.0}
#: the build paths the head case compares in one run (see :func:`bench_head_builds`)
HEAD_PATHS: tuple[str, ...] = ("opencl pass", "numpy classification")


@dataclass
class HeadBuildRow:
    """Medians of the head case's builds at one scale on one path."""

    scale: int
    path: str
    field_shape: tuple[int, int, int]
    median_s: float
    stages: dict[str, float]
    swept: int
    vacated: int


def head_volume(edge: int = HEAD_EDGE) -> Volume:
    """The Colin27 MRI upsampled (trilinear) to ``edge``³, covering the same mm box."""
    from scipy import ndimage

    from voxwarp.io.samples import load_sample

    v = load_sample("colin27")
    d = np.asarray(v.data)
    up = ndimage.zoom(d, [edge / n for n in d.shape], order=1)
    spacing = np.asarray(v.spacing) * np.asarray(d.shape) / np.asarray(up.shape)
    origin = np.asarray(v.origin) - 0.5 * np.asarray(v.spacing) + 0.5 * spacing
    return Volume(np.asfortranarray(up), spacing, origin, name=f"colin27 upsampled to {edge}³")


def bench_head_builds(
    volume: Volume | None = None,
    scales: Sequence[int] = HEAD_SCALES,
    repeats: int = 3,
    log: Callable[[str], None] = print,
) -> list[HeadBuildRow]:
    """Time the head case's field build per scale on both paths, interleaved.

    ``"opencl pass"`` propagates and flags in one OpenCL pass
    (:mod:`voxwarp.deform.wires.classify`; the numpy path where the device cannot);
    ``"numpy classification"`` is the same build with the flags computed in numpy after
    the OpenCL propagation (the path of a device without double precision). One untimed
    build each, then ``repeats`` builds alternating the two paths; medians per stage.
    """
    from voxwarp.deform.wires.field import Wire, WireDeformer

    volume = head_volume() if volume is None else volume
    rows = []
    for scale in check_scales(scales):
        builds = {}
        for path in HEAD_PATHS:
            wd = WireDeformer(volume, [Wire(**HEAD_WIRE)], field_scale=scale)
            if path != HEAD_PATHS[0]:
                wd.classify_on_device = lambda: False  # type: ignore[method-assign]
            wd.build()  # untimed: kernels, buffers
            builds[path] = (wd, [])
        for _ in range(max(1, int(repeats))):
            for wd, timings in builds.values():
                timings.append(wd.build().timings)
        for path, (wd, timings) in builds.items():
            st = wd.stats
            row = HeadBuildRow(
                scale=scale,
                path=path,
                field_shape=tuple(int(n) for n in st.field_shape),  # type: ignore[arg-type]
                median_s=statistics.median(t["total"] for t in timings),
                stages={s: statistics.median(t.get(s, 0.0) for t in timings) for s in STAGES},
                swept=st.swept,
                vacated=st.vacated,
            )
            rows.append(row)
            log(f"head 1:{scale**3} {path}: {row.median_s:.3f} s")
    return rows


def head_markdown(rows: Sequence[HeadBuildRow], command: str) -> str:
    """The head case's table and targets in markdown."""
    lines = [
        f"Command: `{command}`",
        "",
        "| field | path | shape | build s | " + " | ".join(STAGES) + " | swept | vacated |",
        "|---|---|---|---:|" + "---:|" * len(STAGES) + "---:|---:|",
    ]
    for r in rows:
        stages = " | ".join(f"{r.stages[s]:.3f}" for s in STAGES)
        lines.append(
            f"| 1:{r.scale**3} | {r.path} | {'x'.join(map(str, r.field_shape))} |"
            f" {r.median_s:.3f} | {stages} | {r.swept} | {r.vacated} |"
        )
    lines.append("")
    for r in rows:
        limit = TARGET_HEAD_BUILD_S.get(r.scale)
        if r.path == HEAD_PATHS[0] and limit is not None:
            verdict = "PASS" if r.median_s <= limit else "FAIL"
            lines.append(
                f"* Target: head field build at 1:{r.scale**3} <= {limit:g} s:"
                f" {r.median_s:.3f} s -> {verdict}"
            )
    return "\n".join(lines) + "\n"


def _scales_arg(text: str) -> tuple[int, ...]:
    try:
        return check_scales([int(v) for v in text.split(",") if v.strip()])
    except ValueError as exc:
        if "field scales" in str(exc):
            raise argparse.ArgumentTypeError(str(exc)) from None
        raise argparse.ArgumentTypeError(
            f"field scales are comma-separated integers among 1, 2, 4, 8, 16; got {text!r}"
        ) from None


def add_bench_wires_parser(bsub: Any) -> None:
    """Add ``wires`` to the ``bench`` sub-commands (``bsub``: their sub-parsers object)."""
    from voxwarp.core.transfer_function import PRESETS

    p = bsub.add_parser(
        "wires",
        help="wire deformation: field build per scale, propagation vs scipy, deformed vs"
        " undeformed dvr (the wire paper's Figure 12 and Tables 1-3)",
        description="The wire deformation's costs, against references measured in the same run.",
    )
    p.add_argument(
        "--scales",
        type=_scales_arg,
        default=DEFAULT_SCALES,
        metavar="S,S,...",
        help="field scales to build (1, 2, 4, 8, 16 = 1:1 ... 1:4096 voxels; default all)",
    )
    p.add_argument(
        "--repeats", type=positive_int, default=3, help="timed builds per scale (default 3)"
    )
    p.add_argument(
        "--frames",
        type=positive_int,
        default=5,
        help="timed frames per render configuration (default 5)",
    )
    p.add_argument(
        "--size",
        type=image_size,
        action="append",
        metavar="WxH",
        help="image size (default 512x256, the paper's); repeat for more, e.g."
        " --size 512x256 --size 512x512",
    )
    p.add_argument(
        "--tf",
        action="append",
        choices=PRESETS,
        metavar="PRESET",
        help=f"transfer function preset to render with; repeatable (default"
        f" {' and '.join(DEFAULT_TFS)})",
    )
    p.add_argument(
        "--camera",
        action="append",
        choices=CAMERAS,
        help="camera of the renders and ray statistics; repeatable (default both: bench ="
        " voxwarp.bench.render.bench_camera, framed = the object and where its wires move it fill"
        " the image)",
    )
    p.add_argument("--no-render", action="store_true", help="skip the render timings")
    p.add_argument(
        "--head",
        action="store_true",
        help="instead: the MRI head field build of issue 19 (Colin27 upsampled to 256³, one"
        " Bézier wire of radius 40 mm) at --scales (default 2,1), OpenCL pass vs numpy"
        " classification, interleaved",
    )
    p.add_argument(
        "--storage",
        action="store_true",
        help="instead: the wire paper's storage (float / packed / paper layouts, mask"
        " memory) and propagation over the region vs flagged voxels, on the fish and tubes"
        " (benchmarks.wire_storage); --repeats interleaved builds, --frames dvr frames"
        " per layout (--no-render: no images)",
    )
    p.add_argument("--markdown", metavar="FILE", help="also write the report to FILE")
    p.set_defaults(func=cmd_bench_wires)


def command_line(args: argparse.Namespace) -> str:
    """The command that produced a report, rebuilt from ``args``."""
    parts = ["python", "-m", "benchmarks", "wires"]
    if tuple(args.scales) != DEFAULT_SCALES:
        parts += ["--scales", ",".join(map(str, args.scales))]
    if args.repeats != 3:
        parts += ["--repeats", str(args.repeats)]
    if args.frames != 5:
        parts += ["--frames", str(args.frames)]
    for w, h in args.size or ():
        parts += ["--size", f"{w}x{h}"]
    for tf in args.tf or ():
        parts += ["--tf", tf]
    for cam in args.camera or ():
        parts += ["--camera", cam]
    if args.no_render:
        parts.append("--no-render")
    if getattr(args, "head", False):
        parts.append("--head")
    if getattr(args, "storage", False):
        parts.append("--storage")
    if args.markdown:
        parts += ["--markdown", shlex.quote(str(args.markdown))]
    return " ".join(parts)


def cmd_bench_wires(args: argparse.Namespace) -> int:
    """``python -m benchmarks wires``: see the module docstring."""
    from voxwarp.core.files import atomic_write_text

    if getattr(args, "storage", False):
        from benchmarks.wire_storage import bench_storage, markdown

        storage, modes = bench_storage(
            args.repeats,
            images=not args.no_render,
            frames=args.frames,
            log=lambda s: print(s, file=sys.stderr),
        )
        text = markdown(storage, modes, command_line(args))
        print(text)
        if args.markdown:
            atomic_write_text(Path(args.markdown), text)
        return 0
    if args.head:
        scales = HEAD_SCALES if tuple(args.scales) == DEFAULT_SCALES else args.scales
        rows = bench_head_builds(None, scales, args.repeats, lambda s: print(s, file=sys.stderr))
        text = head_markdown(rows, command_line(args))
        print(text)
        if args.markdown:
            atomic_write_text(Path(args.markdown), text)
        return 0
    report = bench_wires(
        scales=args.scales,
        repeats=args.repeats,
        frames=args.frames,
        sizes=tuple(args.size or (DEFAULT_SIZE,)),
        tfs=tuple(args.tf or DEFAULT_TFS),
        cameras=tuple(args.camera or CAMERAS),
        render=not args.no_render,
        log=lambda s: print(s, file=sys.stderr),
    )
    text = report.markdown(command_line(args))
    return emit_report(text, args.markdown)


__all__ = [
    "DEFAULT_SCALES",
    "BuildRow",
    "PhantomRow",
    "PropagationRow",
    "RenderRow",
    "SampleStats",
    "Target",
    "WireBenchReport",
    "add_bench_wires_parser",
    "bench_curve_speed",
    "bench_head_builds",
    "bench_wires",
    "camera_rays",
    "cmd_bench_wires",
    "head_markdown",
    "head_volume",
    "padded_fish",
    "ray_sample_stats",
]


# ---------------------------------------------------------------------- curves
def bench_curve_speed(
    parameters: int = 1_000_000,
    points: int = 100_000,
    control_points: int = 9,
    repeats: int = 3,
    seed: int = 24,
) -> dict[str, float]:
    """Seconds (best of ``repeats``) of the vectorised :class:`~voxwarp.deform.wires.curves.Curve`
    methods a wire uses, on a random Catmull-Rom curve of ``control_points`` points
    (normal, sd 30 mm).

    ``evaluate_derivative``: ``evaluate`` and ``derivative`` of ``parameters`` uniform
    parameters together; ``closest_point``: ``points`` normal (sd 30 mm) points at the
    default precision (the curve's k-d tree built before timing). Run it with
    ``python -c "from benchmarks.wires import bench_curve_speed; print(bench_curve_speed())"``.
    """
    from voxwarp.deform.wires.curves import Curve

    rng = np.random.default_rng(seed)
    curve = Curve(rng.normal(scale=30.0, size=(int(control_points), 3)), kind="catmull-rom")
    t = rng.uniform(0.0, 1.0, int(parameters))
    pts = rng.normal(scale=30.0, size=(int(points), 3))
    curve.evaluate(t[:10])
    curve.closest_point(pts[:10])
    along, closest = best_times(
        repeats, lambda: (curve.evaluate(t), curve.derivative(t)), lambda: curve.closest_point(pts)
    )
    return {
        "parameters": float(parameters),
        "points": float(points),
        "evaluate_derivative_s": along,
        "closest_point_s": closest,
    }
