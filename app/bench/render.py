"""``voxwarp bench render``: raycaster speed on this machine, against itself without skipping.

Renders one 256³ volume (by default the bundled real CT ``stent``, upsampled x2 in x
and y to 256³) at 512x512 in ``dvr`` and ``mip``, and reports the median of ``frames``
frames after warm-up, each bound by ``ctx.finish()``. References in the same process:

* voxwarp with empty-space skipping off (what skipping buys);
* voxwarp computing shaded samples' gradients on the fly;
* in a checkout, ``python -m benchmarks render`` adds VTK's fixed-point (CPU) and GPU
  raycasters on the same array, transfer function, sample distance, image size and camera
  (``benchmarks/render.py``).

Ratios are ``reference time / voxwarp time`` (above 1: voxwarp is faster).
"""

from __future__ import annotations

import platform
import statistics
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from voxwarp.core.camera import Camera
from voxwarp.core.volume import Volume
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.scene import Scene

#: a reference renderer timed on the same scenes: (report, volume, scenes by mode, camera,
#: image size, frames, warm-up frames, log) -> None, appending its rows to the report
Reference = Callable[..., None]
#: the reference row of shaded scenes without the gradient texture
GRADIENTS_ON_THE_FLY = "voxwarp, gradients on the fly"


@dataclass
class BenchRow:
    """One timed configuration."""

    renderer: str
    mode: str
    median_ms: float
    min_ms: float
    note: str = ""


@dataclass
class BenchReport:
    """All rows of one benchmark run plus its setting."""

    volume: str
    shape: tuple[int, int, int]
    size: tuple[int, int]
    step: float
    frames: int
    gl_renderer: str
    rows: list[BenchRow] = field(default_factory=list)
    #: which case of the standard run this is ("sparse", "dense", ...; "" for one volume)
    label: str = ""
    #: share of the image's pixels the dvr image covers (alpha > 0; -1: not measured)
    covered: float = -1.0

    def find(self, renderer: str, mode: str) -> BenchRow | None:
        """The row of ``renderer`` in ``mode`` (None if absent or skipped)."""
        for r in self.rows:
            if r.renderer == renderer and r.mode == mode and r.median_ms > 0:
                return r
        return None

    def ratio(self, reference: str, mode: str) -> float | None:
        """``reference`` median / voxwarp median for ``mode``."""
        ours, ref = self.find("voxwarp", mode), self.find(reference, mode)
        if ours is None or ref is None:
            return None
        return ref.median_ms / ours.median_ms

    def markdown(self, command: str) -> str:
        """A markdown table of the run, headed by the command that produced it."""
        covered = ""
        if self.covered >= 0:
            covered = f" dvr covers {100 * self.covered:.1f} % of the image;"
        lines = [
            f"Command: `{command}`",
            "",
            f"{self.label + ': ' if self.label else ''}Volume: {self.volume}"
            f" {self.shape[0]}x{self.shape[1]}x{self.shape[2]},"
            f" image {self.size[0]}x{self.size[1]}, sample distance {self.step} voxel,"
            f" median of {self.frames} frames after warm-up;{covered} GL: {self.gl_renderer};"
            f" CPU: {platform.processor() or platform.machine()}",
            "",
            "| renderer | mode | median ms | min ms | voxwarp speed-up | note |",
            "|---|---|---:|---:|---:|---|",
        ]
        for r in self.rows:
            ratio = self.ratio(r.renderer, r.mode) if r.renderer != "voxwarp" else 1.0
            med = f"{r.median_ms:.1f}" if r.median_ms > 0 else "—"
            mn = f"{r.min_ms:.1f}" if r.min_ms > 0 else "—"
            rs = f"{ratio:.2f}x" if ratio else "—"
            lines.append(f"| {r.renderer} | {r.mode} | {med} | {mn} | {rs} | {r.note} |")
        return "\n".join(lines) + "\n"


def benchmark_volume(volume: Volume | None = None) -> Volume:
    """The benchmark volume: ``volume``, or the real CT ``stent`` upsampled to 256³."""
    if volume is not None:
        return volume
    from scipy.ndimage import zoom

    from voxwarp.io.samples import load_sample

    stent = load_sample("stent")
    factors = [256 / s for s in stent.shape]
    data = zoom(stent.data.astype(np.float32), factors, order=1)
    data = np.clip(np.rint(data), 0, 255).astype(np.uint8)
    spacing = tuple(sp / f for sp, f in zip(stent.spacing, factors, strict=True))
    return Volume(data, spacing, name="stent CT (real scan, trilinearly upsampled to 256³)")


def bench_camera(volume: Volume, view: Any = None) -> Camera:
    """Perspective camera (30° field of view) with the volume filling the image, from
    ``view`` (default the oblique (30°, 20°))."""
    lo, hi = volume.bounds
    view = (30.0, 20.0) if view is None else view
    return Camera.fit(lo, hi, view=view, projection="perspective", fov=30.0, zoom=1.6)


def covered_fraction(image: np.ndarray) -> float:
    """Share of the pixels of an (H, W, 4) image rendered on a transparent background
    that the volume touched (alpha > 0)."""
    alpha = image[..., 3]
    return float(np.count_nonzero(alpha > 0)) / max(alpha.size, 1)


def body_phantom(
    shape: tuple[int, int, int] = (256, 256, 133),
    spacing: tuple[float, float, float] = (1.4, 1.4, 2.5),
    noise: float = 10.0,
    seed: int = 0,
) -> Volume:
    """A CT-like body (int16, HU): an elliptic trunk of soft tissue (~40 HU) in a fat
    layer (~-100 HU) with a spine (~700 HU) and ribs, air (-1000 HU) around; Gaussian
    noise of ``noise`` HU inside the body. The dense benchmark case."""
    nx, ny, nz = shape
    x = (np.arange(nx, dtype=np.float32) - (nx - 1) / 2) / (0.44 * nx)
    y = (np.arange(ny, dtype=np.float32) - (ny - 1) / 2) / (0.30 * ny)
    r = np.sqrt(x[:, None] ** 2 + y[None, :] ** 2)  # 1 on the skin
    plane = np.full((nx, ny), -1000, dtype=np.int16)
    plane[r < 1.0] = -100
    plane[r < 0.9] = 40
    spine_y = -0.55  # posterior (RAS: -y)
    plane[np.hypot(x[:, None] / 0.66, y[None, :] - spine_y) < 0.16] = 700
    with_ribs = np.where((r > 0.8) & (r < 0.86) & (y[None, :] > spine_y), np.int16(700), plane)
    rib_slices = (np.arange(nz) % 12) < 4  # a rib every 12 slices, 4 slices thick
    data = np.empty((nx, ny, nz), dtype=np.int16, order="F")  # as Volume keeps it
    data[:, :, :] = plane[:, :, None]
    data[:, :, rib_slices] = with_ribs[:, :, None]
    if noise > 0:
        rng = np.random.default_rng(seed)
        body = data > -1000
        values = data[body].astype(np.float32) + rng.normal(0.0, noise, int(body.sum()))
        data[body] = np.clip(np.rint(values), -1024, 3071).astype(np.int16)
    return Volume(data, spacing, name="CT-like body phantom (int16 HU)")


def dense_transfer_function() -> Any:
    """Air transparent; fat and soft tissue at opacity 0.05 over the whole body; bone
    brighter and more opaque (HU). Makes :func:`body_phantom` a dense case."""
    from voxwarp.core.transfer_function import TransferFunction

    return TransferFunction(
        [
            (-1000.0, 0.0, 0.0, 0.0, 0.0),
            (-300.0, 0.0, 0.0, 0.0, 0.0),
            (-200.0, 0.9, 0.7, 0.5, 0.05),
            (300.0, 0.9, 0.45, 0.35, 0.05),
            (500.0, 1.0, 0.95, 0.85, 0.4),
            (1200.0, 1.0, 1.0, 1.0, 0.8),
        ],
        name="dense: soft tissue 0.05",
    )


@dataclass
class RenderCase:
    """One volume of the standard ``bench render`` run."""

    label: str
    volume: Volume
    transfer_function: Any
    modes: tuple[str, ...] = ("dvr",)


def standard_cases(modes: tuple[str, ...] = ("dvr", "mip")) -> list[RenderCase]:
    """The standard run: sparse (the stent CT at 256³, in ``modes``), dense (the CT-like
    :func:`body_phantom` with soft tissue at 0.05) and the bundled MRI (colin27, mri),
    both dvr."""
    from voxwarp.io.samples import load_sample, suggested_transfer_function

    return [
        RenderCase(
            "sparse", benchmark_volume(), suggested_transfer_function("stent"), tuple(modes)
        ),
        RenderCase("dense CT phantom", body_phantom(), dense_transfer_function()),
        RenderCase("dense MRI", load_sample("colin27"), "mri"),
    ]


def bench_render(
    volume: Volume | None = None,
    *,
    size: tuple[int, int] = (512, 512),
    frames: int = 10,
    warmup: int = 2,
    modes: tuple[str, ...] = ("dvr", "mip"),
    step: float = 1.0,
    transfer_function: Any = None,
    references: Sequence[Reference] = (),
    view: Any = None,
    label: str = "",
    no_skipping: bool = True,
    log: Any = print,
) -> BenchReport:
    """Time voxwarp and the references on one volume (see the module docstring); also
    measure the share of the image the dvr image covers (``report.covered``).
    ``references`` time other renderers on the same scenes and append their rows (the
    lab's VTK comparison: ``python -m benchmarks render``)."""
    vol = benchmark_volume(volume)
    if transfer_function is None:
        from voxwarp.io.samples import suggested_transfer_function

        transfer_function = suggested_transfer_function("stent" if volume is None else vol.name)
    cam = bench_camera(vol, view)
    scenes = {
        m: Scene(vol, mode=m, transfer_function=transfer_function, step=step, camera=cam)
        for m in modes
    }
    with OffscreenRenderer(*size) as r:
        # steady-state frames: the cell maps of a large volume are built on its first
        # draw (a warm-up), not on the second (a timed frame)
        r.renderer.cell_skip_maps = "always"
        report = BenchReport(
            volume=vol.name,
            shape=vol.shape,
            size=size,
            step=step,
            frames=frames,
            gl_renderer=str(r.ctx.info.get("GL_RENDERER", "?")),
            label=label,
        )
        for m, scene in scenes.items():
            t = r.time_frames(scene, frames=frames, warmup=warmup)
            report.rows.append(BenchRow("voxwarp", m, statistics.median(t), min(t)))
            log(f"voxwarp {m}: {statistics.median(t):.1f} ms")
        if "dvr" in scenes:
            clear = scenes["dvr"].copy(background=(0.0, 0.0, 0.0, 0.0))
            report.covered = covered_fraction(r.render(clear))
            log(f"dvr covers {100 * report.covered:.1f} % of the image")
        r.renderer.empty_space_skipping = False
        for m, scene in (scenes if no_skipping else {}).items():
            t = r.time_frames(scene, frames=frames, warmup=warmup)
            row = BenchRow("voxwarp, no skipping", m, statistics.median(t), min(t))
            report.rows.append(row)
            log(f"voxwarp without skipping {m}: {statistics.median(t):.1f} ms")
        r.renderer.empty_space_skipping = True
        _bench_gradients_on_the_fly(r, report, scenes, frames, warmup, log)
    for reference in references:
        reference(report, vol, scenes, cam, size, frames, warmup, log)
    return report


def _bench_gradients_on_the_fly(
    r: OffscreenRenderer,
    report: BenchReport,
    scenes: dict[str, Scene],
    frames: int,
    warmup: int,
    log: Any,
) -> None:
    """Shaded scenes that read the precomputed gradient texture, timed again with six
    volume fetches per shaded sample instead (the reference of issue 19's lever 2)."""
    for m, scene in scenes.items():
        r.render(scene)
        if not r.renderer.last_gradient_texture:
            continue
        r.renderer.gradient_texture = False
        try:
            t = r.time_frames(scene, frames=frames, warmup=warmup)
        finally:
            r.renderer.gradient_texture = "auto"
        report.rows.append(BenchRow(GRADIENTS_ON_THE_FLY, m, statistics.median(t), min(t)))
        log(f"voxwarp with gradients on the fly {m}: {statistics.median(t):.1f} ms")


def bench_render_cases(cases: list[RenderCase], **kwargs: Any) -> list[BenchReport]:
    """:func:`bench_render` of each case (``kwargs`` as there), one report per case."""
    return [
        bench_render(
            c.volume,
            transfer_function=c.transfer_function,
            modes=c.modes,
            label=c.label,
            **kwargs,
        )
        for c in cases
    ]


# ---------------------------------------------------------------------- deformed DVR
@dataclass
class WarpRenderReport:
    """Deformed vs undeformed DVR timings of one run (see :func:`bench_warp_render`)."""

    volume: str
    shape: tuple[int, int, int]
    size: tuple[int, int]
    grid: tuple[int, int, int]
    drag_mm: float
    max_displacement_mm: float
    frames: int
    gl_renderer: str
    rows: list[BenchRow] = field(default_factory=list)

    def ratio(self, renderer: str) -> float | None:
        """``renderer`` median / undeformed median (the cost of deforming; 1 = free)."""
        ref = next((r for r in self.rows if r.renderer == "undeformed"), None)
        row = next((r for r in self.rows if r.renderer == renderer), None)
        if ref is None or row is None:
            return None
        return row.median_ms / ref.median_ms

    def markdown(self, command: str) -> str:
        """A markdown table of the run, headed by the command that produced it."""
        lines = [
            f"Command: `{command}`",
            "",
            f"Volume: {self.volume} {self.shape[0]}x{self.shape[1]}x{self.shape[2]},"
            f" image {self.size[0]}x{self.size[1]}, dvr; mass-spring grid"
            f" {'x'.join(map(str, self.grid))}, one element dragged {self.drag_mm:.1f} mm and"
            f" settled (largest displacement {self.max_displacement_mm:.1f} mm); median of"
            f" {self.frames} frames after warm-up; GL: {self.gl_renderer}",
            "",
            "| render | median ms | min ms | cost vs undeformed | note |",
            "|---|---:|---:|---:|---|",
        ]
        for r in self.rows:
            ratio = self.ratio(r.renderer)
            rs = f"{ratio:.2f}x" if ratio else "—"
            lines.append(f"| {r.renderer} | {r.median_ms:.1f} | {r.min_ms:.1f} | {rs} | {r.note} |")
        return "\n".join(lines) + "\n"

    def print_summary(self, command: str) -> str:
        """Print :meth:`markdown` and the cost of deforming in one line; returns the
        markdown (for a ``--markdown`` file)."""
        text = self.markdown(command)
        print(text)
        cost = self.ratio("offset warp, baked")
        if cost is not None:
            print(f"deformed dvr (offset warp, baked inverse) costs {cost:.2f}x undeformed")
        return text


def _margin_config(vol: Volume, grid: int, margin: float, drag: float, base: Scene) -> tuple:
    """The benchmark row of the baked warp on a grid padded by ``margin`` mm: the same
    element count and centre drag (mm) as the unpadded row, settled alike."""
    from voxwarp.deform import ElementGrid, MassSpring
    from voxwarp.deform.elements.offset_field import OffsetFieldWarp

    padded = ElementGrid(vol, shape=(grid, grid, grid), margin=margin)
    ms = MassSpring(padded, integrator="semi-implicit", shear=True)
    ms.move((grid // 2, grid // 2, grid // 2), (drag, 0.0, 0.0))
    ms.settle(max_steps=20000, tol=1e-3)
    warp = OffsetFieldWarp(padded.lo, padded.hi, ms.displacements(), inverse="baked")
    ms.close()
    name = f"offset warp, baked, margin {margin:g} mm"
    return (name, base.copy(warps=[warp]), True, "the grid padded: same elements, coarser")


def bench_warp_render(
    volume: Volume | None = None,
    *,
    size: tuple[int, int] = (512, 512),
    frames: int = 10,
    warmup: int = 2,
    grid: int = 16,
    drag_spacings: float = 1.5,
    transfer_function: Any = None,
    only: tuple[str, ...] | None = None,
    margin: float | None = None,
    log: Any = print,
) -> WarpRenderReport:
    """Cost of rendering through the mass-spring offset-field warp (dvr).

    A ``grid``³ :class:`~voxwarp.deform.elements.massspring.MassSpring` (CPU; semi-implicit Euler,
    shear
    springs, as ``voxwarp render --massspring``) over the benchmark volume has its
    centre element dragged ``drag_spacings`` element spacings along x and
    settled. Rows, in one process and on one context: the undeformed volume; the
    offset warp with the ``approx`` inverse (the thesis' one fetch per sample), the
    ``baked`` inverse (the default) and the ``exact`` inverse, each with deformed-space
    empty-space skipping; and the ``exact`` warp with per-block checks only (what
    skipping through deformed space buys). ``only`` keeps just the rows of those names
    (e.g. ``("undeformed", "offset warp, baked")`` for a quick run). ``margin`` (mm)
    adds the row ``offset warp, baked, margin M mm``: the same model and drag on a grid
    padded by ``margin`` (the same element count, a coarser spacing, a larger deformed box
    to march).
    """
    from voxwarp.deform import ElementGrid, MassSpring
    from voxwarp.deform.elements.offset_field import OffsetFieldWarp

    vol = benchmark_volume(volume)
    if transfer_function is None:
        from voxwarp.io.samples import suggested_transfer_function

        transfer_function = suggested_transfer_function("stent" if volume is None else vol.name)
    cam = bench_camera(vol)
    elements = ElementGrid(vol, shape=(grid, grid, grid), anchor="corners")
    ms = MassSpring(elements, integrator="semi-implicit", shear=True)
    drag = float(drag_spacings * elements.spacing[0])
    centre = (grid // 2, grid // 2, grid // 2)
    ms.move(centre, (drag, 0.0, 0.0))
    ms.settle(max_steps=20000, tol=1e-3)
    field_mm = ms.displacements()
    base = Scene(vol, mode="dvr", transfer_function=transfer_function, camera=cam)
    lo, hi = elements.lo, elements.hi
    configs = [
        ("undeformed", base, True, ""),
        (
            "offset warp, approx",
            base.copy(warps=[OffsetFieldWarp(lo, hi, field_mm, inverse="approx")]),
            True,
            "1 field fetch per sample (thesis)",
        ),
        (
            "offset warp, baked",
            base.copy(warps=[OffsetFieldWarp(lo, hi, field_mm, inverse="baked")]),
            True,
            "default: seed from the inverse baked 4x finer + 1 step (2 fetches)",
        ),
        (
            "offset warp, exact",
            base.copy(warps=[OffsetFieldWarp(lo, hi, field_mm, inverse="exact")]),
            True,
            "fixed point from p, 6 steps (6 fetches)",
        ),
        (
            "undeformed, no skipping",
            base,
            None,
            "naive raycaster (reference)",
        ),
        (
            "offset warp, approx, no skipping",
            base.copy(warps=[OffsetFieldWarp(lo, hi, field_mm, inverse="approx")]),
            None,
            "naive raycaster + one field fetch per sample",
        ),
        (
            "offset warp, exact, block checks only",
            base.copy(warps=[OffsetFieldWarp(lo, hi, field_mm, inverse="exact")]),
            False,
            "no skipping through deformed space",
        ),
    ]
    if margin is not None:
        configs.append(_margin_config(vol, grid, margin, drag, base))
    if only is not None:
        configs = [c for c in configs if c[0] in only]
    with OffscreenRenderer(*size) as r:
        report = WarpRenderReport(
            volume=vol.name,
            shape=vol.shape,
            size=size,
            grid=elements.shape,
            drag_mm=drag,
            max_displacement_mm=float(np.sqrt((field_mm**2).sum(-1)).max()),
            frames=frames,
            gl_renderer=str(r.ctx.info.get("GL_RENDERER", "?")),
        )
        r.renderer.warped_skip_maps = "always"  # built in the warm-up frames
        for name, scene, cells, note in configs:
            # cells None: no empty-space skipping at all
            r.renderer.empty_space_skipping = cells is not None
            r.renderer.cell_skipping = bool(cells)
            t = r.time_frames(scene, frames=frames, warmup=warmup)
            report.rows.append(BenchRow(name, "dvr", statistics.median(t), min(t), note))
            log(f"{name}: {statistics.median(t):.1f} ms")
        r.renderer.cell_skipping = True
        r.renderer.empty_space_skipping = True
    ms.close()
    return report
