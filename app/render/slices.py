"""Slice views through the warp chain on the GPU: multi-planar reformatting (MPR).

:class:`SliceRenderer` draws one plane of a :class:`~voxwarp.scene.Scene` per call, on
the renderer's context, with the technique of ``shaders/slice.frag.glsl``: each pixel's
world point goes through the scene's warp chain, as a raycaster sample does, and the
original volume is sampled there (never resampled). The result is data, not colour: an
RGBA32F image holding per pixel the deformed value, the fraction of its slab inside the
volume, and the same two for the rest state. Colour (window/level, the transfer
function, rest vs deformed overlays) is applied afterwards on the CPU by
:mod:`voxwarp.render.slice_image`, so a window/level drag costs no GPU work.

Use it through :meth:`voxwarp.render.raycaster.Renderer.slice_values` (any
pixel -> world affine, e.g. an output grid's slices for ``export-volume``) or
:meth:`voxwarp.render.offscreen.OffscreenRenderer.render_slice` (a
:class:`~voxwarp.core.slice_plane.SlicePlane`, coloured).
"""

from __future__ import annotations

import math
from typing import Any, Literal

import numpy as np

from voxwarp import shaders
from voxwarp.deform import gl_programs
from voxwarp.deform.warp import compose_glsl, fold_affine
from voxwarp.errors import RenderError
from voxwarp.render.float_target import FloatTarget
from voxwarp.render.gl_uniforms import bind_warps, set_uniform, warp_textures
from voxwarp.render.skipping.support import SupportCache
from voxwarp.render.volume_texture import layout_defines
from voxwarp.scene import Scene

SlabMode = Literal["mip", "minip", "average"]
#: slab combinations and their shader codes
SLAB_MODES: dict[str, int] = {"mip": 0, "minip": 1, "average": 2}
Interpolation = Literal["linear", "nearest"]
INTERPOLATIONS: tuple[str, ...] = ("linear", "nearest")
#: most samples across one slab
MAX_SLAB_SAMPLES = 1024
#: largest slice image side
MAX_SLICE_SIDE = 16384


def slab_sampling(slab_mm: float, sample_mm: float) -> tuple[int, float]:
    """Samples across a slab ``slab_mm`` thick (at most ``sample_mm`` apart, at most
    :data:`MAX_SLAB_SAMPLES`) and their spacing in mm; ``(1, 0.0)`` for a thin slice."""
    slab = float(slab_mm)
    if not (math.isfinite(slab) and slab >= 0):
        raise RenderError(f"slab thickness must be a finite number of mm >= 0; got {slab_mm}")
    if slab == 0:
        return 1, 0.0
    n = min(max(1, math.ceil(slab / float(sample_mm))), MAX_SLAB_SAMPLES)
    return n, slab / n


def check_slice_options(slab_mode: str, interpolation: str) -> None:
    """Raise :class:`RenderError` naming the allowed values for a bad mode."""
    if slab_mode not in SLAB_MODES:
        raise RenderError(f"slab mode must be one of {', '.join(SLAB_MODES)}; got {slab_mode!r}")
    if interpolation not in INTERPOLATIONS:
        raise RenderError(
            f"interpolation must be one of {', '.join(INTERPOLATIONS)}; got {interpolation!r}"
        )


class SliceRenderer:
    """Draws slice planes of scenes on a given moderngl context (owned by the caller).

    GPU resources: one compiled program per warp chain signature, texture layout and
    interpolation, one empty vertex array per program, and the float target of
    :meth:`values`; freed by :meth:`release`.
    """

    def __init__(self, ctx: Any) -> None:
        self.ctx = ctx
        self._programs = gl_programs.KeyedPrograms(ctx, shaders.read("upscale.vert.glsl"))
        self._vaos: dict[int, Any] = {}
        self._target = FloatTarget(ctx, (4, 1))
        #: the chain's support: pixels outside it sample straight (see
        #: :attr:`voxwarp.render.raycaster.Renderer.support_skipping`)
        self.support = SupportCache(ctx)
        self._released = False

    def _program(
        self, scene: Scene, layout: str, nearest: bool, detj: bool, support: bool = False
    ) -> Any:
        key = (tuple(w.signature() for w in scene.warps), layout, nearest, detj, support)

        def fragment() -> str:
            frag = shaders.source(
                "slice.frag.glsl", extra={"warps.glsl": compose_glsl(list(scene.warps))}
            )
            defines = layout_defines(layout) + (["#define NEAREST"] if nearest else [])
            defines += ["#define DETJ"] if detj else []
            defines += ["#define SUPPORT_MAP"] if support else []
            return shaders.with_defines(frag, defines)

        try:
            return self._programs.get(key, fragment)
        except Exception as exc:
            raise RenderError(f"slice shader failed to compile/link for {key}: {exc}") from exc

    def draw(
        self,
        gpu: Any,
        scene: Scene,
        pixel_to_world: np.ndarray,
        framebuffer: Any,
        viewport: tuple[int, int, int, int],
        *,
        slab_mm: float = 0.0,
        slab_mode: str = "mip",
        interpolation: str = "linear",
        detj: bool = False,
    ) -> None:
        """Draw the slice whose pixel ``(col, row)`` (row 0 at the top) lies at
        ``pixel_to_world @ (col, row, 0, 1)`` into ``viewport`` of ``framebuffer``;
        the slab runs along ``pixel_to_world``'s third column (unit length expected).
        ``gpu`` is the renderer's copy of the scene's volume. ``detj``: draw the
        chain's det J at each pixel's point instead (channel r; g = 1)."""
        if self._released:
            raise RenderError("this SliceRenderer was released")
        check_slice_options(slab_mode, interpolation)
        m = np.asarray(pixel_to_world, dtype=np.float64)
        if m.shape != (4, 4) or not np.all(np.isfinite(m)):
            raise RenderError("pixel_to_world must be a finite 4x4 matrix")
        samples, spacing = slab_sampling(slab_mm, scene.sample_distance_mm)
        normal = m[:3, 2] / max(float(np.linalg.norm(m[:3, 2])), 1e-12)
        scene, support = self._support_plan(scene, detj)
        prog = self._program(scene, gpu.layout, interpolation == "nearest", detj, support)
        textures = warp_textures(self.ctx, scene.warps)  # first: may run GPU passes
        vol = scene.volume
        values: dict[str, Any] = {
            "u_pixel_to_world": m,
            "u_viewport": tuple(float(v) for v in viewport),
            "u_slab_step": tuple(float(v) for v in normal * spacing),
            "u_slab_samples": int(samples),
            "u_slab_mode": SLAB_MODES[slab_mode],
            "u_dims": tuple(float(s) for s in vol.shape),
            "u_inv_dims": tuple(1.0 / s for s in vol.shape),
            "u_value_map": gpu.value_map,
            "u_spacing": tuple(float(s) for s in vol.spacing),
            "u_origin": tuple(float(o) for o in vol.origin),
            "u_direction": vol.direction,
            "u_volume": 0,
        }
        for name, value in values.items():
            set_uniform(prog, name, value)
        gpu.texture.use(0)
        unit = bind_warps(prog, scene.warps, textures, 1)
        if support:
            box = _slice_box(scene)
            self.support.texture(scene, box).use(unit)
            values = {"u_support": unit, **self.support.uniforms(scene, box)}
            for name, value in values.items():
                set_uniform(prog, name, value)
        vao = self._vaos.get(id(prog))
        if vao is None:
            vao = self._vaos[id(prog)] = self.ctx.vertex_array(prog, [])
        framebuffer.use()
        framebuffer.viewport = viewport
        with self.ctx.scope(framebuffer, enable_only=0):  # no blending or depth: data
            vao.render(self.ctx.TRIANGLES, vertices=3)

    def _support_plan(self, scene: Scene, detj: bool) -> tuple[Scene, bool]:
        """The scene a slice draws (without its warps when they move nothing beyond
        the tolerance) and whether its pixels look the support map up."""
        if detj or fold_affine(scene.warps) is not None:
            return scene, False
        plan = self.support.plan(scene, _slice_box(scene))
        if plan == "none":
            return scene.copy(warps=[]), False
        return scene, plan == "map"

    def values(
        self,
        gpu: Any,
        scene: Scene,
        pixel_to_world: np.ndarray,
        size: tuple[int, int],
        **options: Any,
    ) -> np.ndarray:
        """The slice as data: an (H, W, 4) float32 array, row 0 at the top, channels
        (deformed value, deformed coverage, rest value, rest coverage); see
        :meth:`draw` for the options. With ``detj=True`` a fifth channel holds the
        chain's det J at each pixel's point (the same draw)."""
        w, h = (int(v) for v in size)
        if not (1 <= w <= MAX_SLICE_SIDE and 1 <= h <= MAX_SLICE_SIDE):
            raise RenderError(f"slice size must be 1..{MAX_SLICE_SIDE} pixels a side; got {w}x{h}")
        fbo = self._target.framebuffer(w, h)
        self.draw(gpu, scene, pixel_to_world, fbo, (0, 0, w, h), **options)
        raw = fbo.read(viewport=(0, 0, w, h), components=4, dtype="f4", alignment=1)
        data = np.frombuffer(raw, dtype=np.float32).reshape(h, w, 4)
        if not options.get("detj"):
            return data[::-1].copy()
        raw = fbo.read(viewport=(0, 0, w, h), components=1, attachment=1, dtype="f4", alignment=1)
        det = np.frombuffer(raw, dtype=np.float32).reshape(h, w, 1)
        return np.concatenate([data, det], axis=2)[::-1].copy()

    def release(self) -> None:
        """Free every GPU resource this renderer made; idempotent."""
        if self._released:
            return
        for vao in self._vaos.values():
            vao.release()
        self._vaos.clear()
        self._programs.release()
        self._target.release()
        self.support.release()
        self._released = True


def _slice_box(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """The box a slice's support map covers: the chain's deformed volume box and the
    volume's own (beyond it the shader pays for the chain)."""
    lo, hi = scene.deformed_bounds()
    vlo, vhi = scene.volume.bounds
    return np.minimum(lo, vlo), np.maximum(hi, vhi)
