"""The raycasting renderer (moderngl); headless use wraps it in
:class:`~voxwarp.render.offscreen.OffscreenRenderer` on a context from
:mod:`voxwarp.render.context`.

:class:`Renderer` draws a :class:`~voxwarp.scene.Scene` into a framebuffer it is given,
on a ``moderngl.Context`` it is given (the GUI passes Qt's, scripts pass an EGL
standalone context); it never creates a window. GPU resources (volume texture,
block min/max grid, transfer-function table, compiled programs) are cached per
volume / transfer function / program variant and freed by :meth:`Renderer.release`.

Each draw first clears its viewport to the scene's background, then draws one NDC
polygon per ray-direction octant present in the image (one polygon covering the
viewport unless octant skip maps are in use; see :mod:`voxwarp.render.skipping.maps`).
Rays that miss the volume, or see nothing visible, discard and leave the background.

Mixed scenes (``Scene(..., meshes=[...])``): the mesh instances are drawn first by
:class:`voxwarp.render.mesh_pass.MeshRenderer` into an internal colour + depth target of the
viewport's size, cleared to the background; the raycaster (``MESH_DEPTH``) then stops
each ray at the mesh surface and composites the volume over that image (front to back,
premultiplied: ``out = volume + (1 - volume.a) * mesh_over_background``). Opaque meshes
are exact; translucent ones write no depth, so the whole ray's volume lies over them.
The meshes move with the scene's warps (their forward map; see
:mod:`voxwarp.core.mesh_warp`). Without meshes nothing of this runs (same programs, same
images).

See ``shaders/raycast.frag.glsl`` for the technique (warp chain, empty-space skipping,
early ray termination, jitter) and ``docs/benchmarks.md`` for what each part buys on a
CPU rasteriser.
"""

from __future__ import annotations

import dataclasses
import math
import os
import weakref
from collections.abc import Callable
from typing import Any

import numpy as np

from voxwarp import shaders
from voxwarp.core.camera import Camera
from voxwarp.core.mesh_warp import mesh_instances_bounds
from voxwarp.core.modes import xray_reference_length
from voxwarp.core.transfer_function import TABLE_SIZE, TransferFunction
from voxwarp.core.volume import Volume
from voxwarp.deform import gl_programs
from voxwarp.deform.warp import box_corners, compose_glsl, fold_affine
from voxwarp.errors import RenderError, VolumeTooLargeError, VoxwarpError
from voxwarp.render import gradients
from voxwarp.render.fixed_texture import FixedTexture, compare_uniforms, uses_gradient_texture
from voxwarp.render.gl_uniforms import bind_warps, set_uniform, warp_textures
from voxwarp.render.jacobian_overlay import DETJ_MODES, JacobianOverlay
from voxwarp.render.mesh_pass import MeshRenderer
from voxwarp.render.skipping.cache import COARSE_FACTOR, SkipMapCache, VolumeSkipMaps
from voxwarp.render.skipping.checks import (
    chained_samples_per_check,
    checked_setting,
    samples_per_check,
)
from voxwarp.render.skipping.maps import (
    BLOCK,
    OCTANT_EPS,
    Octant,
    block_min_max,
    octant_regions,
    ray_direction_coefficients,
)
from voxwarp.render.skipping.segments import MAX_SAMPLES
from voxwarp.render.skipping.support import MAP_MIN_VISIBLE, SupportCache
from voxwarp.render.slices import SliceRenderer
from voxwarp.render.support_ranges import SupportRanges
from voxwarp.render.volume_texture import LAYOUTS, layout_defines, upload_volume_texture
from voxwarp.scene import Scene

#: Default GPU memory budget for one volume texture (override: VOXWARP_TEXTURE_BUDGET_MB).
DEFAULT_TEXTURE_BUDGET = 2 * 1024**3
#: ``sampling="auto"`` on a software rasteriser: volumes whose slice-pair texture (twice
#: their bytes) is at most this big get slice pairs, larger ones slice layers (once)
PAIRS_MAX_BYTES = 64 * 1024**2
#: Blinn-Phong ambient, diffuse, specular, shininess.
LIGHT = (0.25, 0.7, 0.3, 32.0)
#: Corners of the NDC polygons a draw is made of (u_polygon in polygon.vert.glsl).
MAX_POLYGON = 8

_TEX_FORMAT = {
    # dtype: (moderngl dtype, scale, offset) so that value = texel * scale + offset
    np.dtype(np.uint8): ("f1", 255.0, 0.0),
    np.dtype(np.uint16): ("nu2", 65535.0, 0.0),
    np.dtype(np.int16): ("nu2", 65535.0, -32768.0),  # stored as uint16 + 32768: exact
    np.dtype(np.float32): ("f4", 1.0, 0.0),
}


class _VolumeGPU:
    """GPU copy of one volume: texture (a volume_texture layout) + its skip maps
    (VolumeSkipMaps); the raycaster and the slice views read the same texture."""

    def __init__(self, ctx: Any, volume: Volume, layout: str) -> None:
        fmt, scale, offset = _TEX_FORMAT[volume.dtype]
        #: the texture's layout (one of volume_texture.LAYOUTS)
        self.layout = layout
        # slab by slab: no full-volume copy (int16 -> uint16 + 32768, layer pairs)
        self.texture = upload_volume_texture(ctx, volume.data, fmt, layout)
        self.texture.repeat_x = self.texture.repeat_y = False
        if layout == "texture3d":
            self.texture.repeat_z = False
        self.texture.filter = (ctx.LINEAR, ctx.LINEAR)
        self.value_map = (scale, offset)
        bmin, bmax = block_min_max(volume.data, BLOCK)
        self.blocks = bmin.shape
        #: block info, cell and warped skip maps, filled by the renderer's SkipMapCache
        self.skip = VolumeSkipMaps(ctx, volume.data, bmin, bmax)
        self.nbytes = volume.data.nbytes * LAYOUTS[layout]
        #: RGBA16F data gradients for shading (app/render/gradients.py), made on demand
        self.gradient: Any = None

    def gradient_texture(self, ctx: Any, volume: Volume) -> Any:
        """The volume's gradient texture, built on the GPU on first use."""
        if self.gradient is None:
            self.gradient = gradients.gradient_texture(
                ctx, self.texture, volume.shape, self.value_map[0], self.layout
            )
        return self.gradient

    def release(self) -> None:
        if self.texture is not None:
            self.texture.release()
        if self.gradient is not None:
            self.gradient.release()
            self.gradient = None
        self.skip.release()
        self.texture = None  # type: ignore[assignment]


def upload_error(volume: Volume, exc: BaseException) -> Exception:
    """The one-line error of a failed volume upload: moderngl's GL errors (and a
    ``GL_OUT_OF_MEMORY``) are the GPU failing to allocate the texture; host memory
    running out says so; anything else is reported as what it is, not as the GPU's."""
    import moderngl

    detail = " ".join(str(exc).split()) or type(exc).__name__
    if isinstance(exc, VoxwarpError):
        return exc
    if isinstance(exc, moderngl.Error):
        return VolumeTooLargeError(
            f"the GPU could not allocate the texture for volume {volume.shape}"
            f" ({detail}); downsample it (load_volume(..., downsample=2))"
        )
    if isinstance(exc, MemoryError):
        return VolumeTooLargeError(
            f"not enough memory to prepare volume {volume.shape} for the GPU; downsample"
            " it (load_volume(..., downsample=2)) or close other programs"
        )
    return RenderError(
        f"uploading volume {volume.shape} to the GPU failed: {type(exc).__name__}: {detail}"
    )


def _tf_key(tf: TransferFunction) -> tuple:
    return tuple(tf.points)


#: an NDC polygon of a draw and the ray-direction octant whose skip map it uses (or None)
_Region = tuple[Octant | None, list[tuple[float, float]]]


@dataclasses.dataclass
class _Frame:
    """What the steps of one :meth:`Renderer.draw` share (made by ``_begin_frame``)."""

    scene: Scene
    gpu: _VolumeGPU
    camera: Camera
    #: (x, y, w, h) in pixels
    viewport: tuple[int, int, int, int]
    #: the warp chain folded into one matrix; None for warped (non-affine) rays
    fold: np.ndarray | None
    #: the empty-space skipping: "cells", "blocks" or "none"
    skip_kind: str
    #: the raycast program variant
    prog: Any
    #: the scene's background, premultiplied
    background: tuple
    #: shading reads the precomputed gradient texture
    gradients: bool = False
    #: warped rays: 1 evaluates the chain at every sample, 0 interpolates along
    #: segments from the warp state's segment map, K > 1 along segments of K samples
    segment: int = 1
    #: warped rays march straight outside the chain's support brick map (SUPPORT_MAP)
    support: bool = False

    @property
    def linear(self) -> bool:
        """Straight rays: the warp chain is affine."""
        return self.fold is not None


def _downsample_advice(
    shape: tuple[int, ...],
    limits: tuple[int, ...],
    need: int | Callable[[tuple[int, ...]], int],
    budget: int,
) -> tuple[int, int, int]:
    """Per-axis downsample factors (each >= 1, at least one >= 2) that make a volume of
    ``shape`` (``need`` texture bytes, or ``need(shape)`` where the bytes per voxel depend
    on the shape, as the texture layout does) fit ``limits`` voxels per axis and ``budget``
    bytes. Axes over their limit get the factor that fits them; for the budget, the
    smallest common factor ``g`` is applied on top (voxels stay isotropic where they
    were), capped per axis so every axis keeps >= 1 voxel (a uniform factor would empty
    the short axes of a (200000, 2, 2) volume)."""
    n = [max(int(v), 1) for v in shape]
    base = [max(1, math.ceil(v / lim)) for v, lim in zip(n, limits, strict=True)]
    if not callable(need):
        per_voxel = need / math.prod(n)
        need = lambda s: per_voxel * math.prod(s)  # noqa: E731
    for g in range(1, max(n) + 1):
        f = [max(b, min(g, v)) for b, v in zip(base, n, strict=True)]
        fits = need(tuple(v // k for v, k in zip(n, f, strict=True))) <= budget
        if fits and max(f) >= 2:
            return (f[0], f[1], f[2])
    return (n[0], n[1], n[2])


class Renderer:
    """Raycasts scenes into framebuffers on a given moderngl context.

    Parameters
    ----------
    ctx
        A ``moderngl.Context`` (OpenGL 4.3+); the caller owns it.
    texture_budget_bytes
        Largest volume texture accepted; default 2 GiB or ``VOXWARP_TEXTURE_BUDGET_MB``.
    empty_space_skipping
        Jump over space the compositing mode cannot see (default). Turning it off
        never changes the image, only the time; benchmarks use it as a reference.
        Straight rays of dvr/iso/flm use per-octant cell maps (:mod:`voxwarp.render.skipping.maps`):
        one byte per trilinear cell per octant the camera needs, computed on the CPU
        when first needed after a change of what the mode can see (~1 s per octant
        for 256³ on 2 cores) and kept on the volume (at most 8).
    support_skipping
        Warped rays pay for the warp chain only inside its support, the bricks where it
        moves points by more than :attr:`support_tolerance` voxels, and march straight
        elsewhere (:mod:`voxwarp.render.skipping.support`); a chain that moves nothing
        draws as the undeformed scene. Default on; ``False`` (or the environment
        variable ``VOXWARP_SUPPORT_SKIPPING=0``) evaluates the chain at every sample,
        the reference the tests and ``python -m benchmarks support`` compare against.
    sampling
        ``"texture3d"``: one hardware-trilinear fetch per sample (best on GPUs);
        ``"slice_pairs"``: a 2D array texture whose layer k holds slices k and k+1,
        one bilinear fetch + one lerp (half the texel reads; ~1.6x faster per sample
        on llvmpipe, twice the texture memory); ``"slice_layers"``: a 2D array texture
        of one slice per layer, two bilinear fetches + one lerp, each voxel stored once
        (:mod:`voxwarp.render.volume_texture`). ``"auto"`` picks, on software
        rasterisers, slice pairs for volumes of at most :data:`PAIRS_MAX_BYTES` and
        slice layers above (see :meth:`layout_for`); on GPUs ``texture3d``.
    """

    def __init__(
        self,
        ctx: Any,
        *,
        texture_budget_bytes: int | None = None,
        empty_space_skipping: bool = True,
        sampling: str = "auto",
        support_skipping: bool | None = None,
    ) -> None:
        if ctx.version_code < 430:
            raise RenderError(
                f"voxwarp needs OpenGL 4.3 or newer; this context offers {ctx.version_code}"
            )
        self.ctx = ctx
        #: when skip maps are built, reused and dropped (and the settings that decide it)
        self._skip_maps = SkipMapCache(ctx, empty_space_skipping=bool(empty_space_skipping))
        if support_skipping is None:
            support_skipping = os.environ.get("VOXWARP_SUPPORT_SKIPPING", "1") != "0"
        #: the warp chain's support brick map (where warped rays pay for the chain)
        self._support = SupportCache(ctx, enabled=support_skipping)
        #: the empty-space skipping the last draw used ("cells", "blocks" or "none")
        self.last_skip_kind = "none"
        self.gradient_texture: bool | str = "auto"
        #: whether the last draw shaded from the gradient texture
        self.last_gradient_texture = False
        #: the last draw's warped rays: 1 evaluated the chain at every sample, 0 used the
        #: warp state's segment map, K > 1 fixed segments of K samples
        self.last_ray_segment = 1
        #: how the last draw paid for its warp chain: "none" (straight rays: no chain,
        #: an affine one, or one that moves nothing, drawn undeformed), "map" (straight
        #: outside the chain's support) or "all" (the chain at every sample)
        self.last_support = "all"
        #: the last draw's lattice samples per skip-map check of straight rays (and of a
        #: warped ray's straight phases), and of samples through the warp chain
        #: (:mod:`voxwarp.render.skipping.checks`)
        self.last_samples_per_check = 1
        self.last_chained_per_check = 1
        if sampling not in ("auto", *LAYOUTS):
            raise RenderError(
                f"sampling must be 'auto' or one of {', '.join(map(repr, LAYOUTS))};"
                f" got {sampling!r}"
            )
        renderer_name = str(ctx.info.get("GL_RENDERER", "")).lower()
        software = any(w in renderer_name for w in ("llvmpipe", "softpipe", "swr", "swiftshader"))
        self._software = software
        self._samples_per_check: int | str = "auto"
        if sampling == "auto":
            sampling = "auto-software" if software else "texture3d"
        #: "texture3d" (hardware trilinear), "slice_pairs" or "slice_layers" (faster on
        #: CPU rasterisers), or "auto-software" (by volume size, :meth:`layout_for`)
        self.sampling = sampling
        env = os.environ.get("VOXWARP_TEXTURE_BUDGET_MB")
        if texture_budget_bytes is None:
            texture_budget_bytes = int(float(env) * 2**20) if env else DEFAULT_TEXTURE_BUDGET
        self.texture_budget_bytes = int(texture_budget_bytes)
        self.max_texture_size = int(ctx.info.get("GL_MAX_3D_TEXTURE_SIZE", 2048))
        self._volumes: dict[int, tuple[weakref.ref, _VolumeGPU]] = {}
        self._programs: dict[tuple, Any] = {}
        self._tf_tex: Any = None
        self._tf_key: Any = None
        self._vao: dict[int, Any] = {}
        #: draws the meshes of mixed scenes (made on first use)
        self._mesh_renderer: MeshRenderer | None = None
        #: (size, colour texture, depth texture, framebuffer) of the mesh pass
        self._mesh_target: tuple[tuple[int, int], Any, Any, Any] | None = None
        #: draws slice views (made on first use)
        self._slice_renderer: SliceRenderer | None = None
        #: (size, colour texture, framebuffer) of draw_scaled, and its upscaling program
        self._lod_target: tuple[tuple[int, int], Any, Any] | None = None
        self._upscale: tuple[Any, Any] | None = None
        #: the fixed image of a comparison scene (Scene(fixed=...)), uploaded on use
        self._fixed = FixedTexture(ctx)
        #: per-pixel ray ranges through the chain's support (the map path)
        self._support_ranges = SupportRanges(ctx)
        #: chain a warped ray only between its first and last crossing of the support's
        #: surface (off: within the box around the support; ``VOXWARP_SUPPORT_RANGES=0``)
        self.support_ranges = os.environ.get("VOXWARP_SUPPORT_RANGES", "1") != "0"
        #: the det J overlay of the 3D image (:mod:`voxwarp.render.jacobian_overlay`),
        #: None for none; drawn in the modes of its ``DETJ_MODES`` (others draw without)
        self.jacobian_overlay: JacobianOverlay | None = None
        self._released = False

    # ------------------------------------------------------------------ resources
    def check_volume(self, volume: Volume) -> None:
        """Raise :class:`VolumeTooLargeError` if ``volume`` cannot become a texture here."""
        need = self.texture_bytes(volume.shape, volume.dtype)
        limits = self._axis_limits(volume)
        ratios = [n / lim for n, lim in zip(volume.shape, limits, strict=True)]
        axis = int(np.argmax(ratios))
        too_big_dim = ratios[axis] > 1
        if too_big_dim or need > self.texture_budget_bytes:
            factor = _downsample_advice(
                volume.shape,
                limits,
                lambda s: self.texture_bytes(s, volume.dtype),
                self.texture_budget_bytes,
            )
            if too_big_dim:
                limit = (
                    f"maximum 3D texture size {limits[axis]} per axis"
                    if limits[axis] == self.max_texture_size
                    else f"limit of {limits[axis]} for this axis of a 2D array texture"
                )
                what = (
                    f"volume {volume.shape} has {volume.shape[axis]} voxels along axis"
                    f" {axis} ({'xyz'[axis]}), over the GPU's {limit}"
                )
            else:
                what = (
                    f"volume {volume.shape} needs {need / 2**20:.3g} MB of texture memory, over"
                    f" the budget of {self.texture_budget_bytes / 2**20:.3g} MB"
                    " (VOXWARP_TEXTURE_BUDGET_MB)"
                )
            uniform = len(set(factor)) == 1
            arg = str(factor[0]) if uniform else ",".join(map(str, factor))
            raise VolumeTooLargeError(
                f"{what}. Downsample it: load_volume(..., downsample={arg if uniform else factor})"
                f" or `voxwarp render ... --downsample {arg}`."
            )

    def texture_bytes(self, shape: tuple[int, ...], dtype: Any) -> int:
        """Bytes of the texture a volume of ``shape`` and ``dtype`` gets here."""
        fmt_bytes = {"f1": 1, "nu2": 2, "f4": 4}[_TEX_FORMAT[np.dtype(dtype)][0]]
        return int(np.prod(shape)) * fmt_bytes * LAYOUTS[self.layout_for(shape, dtype)]

    def layout_for(self, shape: tuple[int, ...], dtype: Any) -> str:
        """The texture layout a volume of ``shape`` and ``dtype`` gets here (one of
        :data:`volume_texture.LAYOUTS`): the ``sampling`` setting, or with "auto" on a
        software rasteriser slice pairs where their texture takes at most
        :data:`PAIRS_MAX_BYTES`, else slice layers (each voxel once: a big volume's
        texture costs its bytes, not twice; ~1.05-1.5x the time per sample)."""
        if self.sampling != "auto-software":
            return self.sampling
        fmt_bytes = {"f1": 1, "nu2": 2, "f4": 4}[_TEX_FORMAT[np.dtype(dtype)][0]]
        pairs = 2 * int(np.prod(shape)) * fmt_bytes
        return "slice_pairs" if pairs <= PAIRS_MAX_BYTES else "slice_layers"

    def _axis_limits(self, volume: Volume) -> tuple[int, int, int]:
        """Most voxels per axis of ``volume``'s texture here: the 3D texture size, and
        with an array layout also the 2D texture size (x, y) and the array layers (z)."""
        m = self.max_texture_size
        if self.layout_for(volume.shape, volume.dtype) == "texture3d":
            return (m, m, m)
        info = self.ctx.info
        m2 = min(m, int(info.get("GL_MAX_TEXTURE_SIZE", m)))
        return (m2, m2, min(m, int(info.get("GL_MAX_ARRAY_TEXTURE_LAYERS", m))))

    def _volume_gpu(self, volume: Volume) -> _VolumeGPU:
        self._evict_dead()
        key = id(volume)
        hit = self._volumes.get(key)
        if hit is not None and hit[0]() is volume:
            if hit[1].layout == self.layout_for(volume.shape, volume.dtype):
                return hit[1]
            hit[1].release()
        if hit is not None:  # a dead volume reused the id
            hit[1].release()
        self.check_volume(volume)
        self.ctx.error  # noqa: B018 - clear any stale error flag
        try:
            gpu = _VolumeGPU(self.ctx, volume, self.layout_for(volume.shape, volume.dtype))
        except Exception as exc:  # worded by upload_error, the cause kept
            raise upload_error(volume, exc) from exc
        err = self.ctx.error
        if err != "GL_NO_ERROR":
            gpu.release()
            raise VolumeTooLargeError(
                f"OpenGL reported {err} while uploading volume {volume.shape};"
                " downsample it (load_volume(..., downsample=2))"
            )
        self._volumes[key] = (weakref.ref(volume), gpu)
        return gpu

    def _evict_dead(self) -> None:
        # textures of garbage-collected volumes are freed here, while the context is
        # current, rather than from a weakref callback that may run at any time
        for key in [k for k, (ref, _) in self._volumes.items() if ref() is None]:
            self._volumes.pop(key)[1].release()

    def _tf_texture(self, tf: TransferFunction, ratio: float) -> Any:
        key = (_tf_key(tf), ratio)
        if self._tf_tex is None or self._tf_key != key:
            if self._tf_tex is not None:
                self._tf_tex.release()
            table = np.ascontiguousarray(tf.gpu_table(ratio, TABLE_SIZE))
            self._tf_tex = self.ctx.texture((TABLE_SIZE, 2), 4, table.tobytes(), dtype="f4")
            self._tf_tex.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
            self._tf_tex.repeat_x = self._tf_tex.repeat_y = False
            self._tf_key = key
        return self._tf_tex

    # ------------------------------------------------------------------ skip maps
    @property
    def empty_space_skipping(self) -> bool:
        """Skip space the mode cannot see (default); off only to measure what it buys."""
        return self._skip_maps.empty_space_skipping

    @empty_space_skipping.setter
    def empty_space_skipping(self, value: bool) -> None:
        self._skip_maps.empty_space_skipping = value

    @property
    def cell_skipping(self) -> bool:
        """Skip at the resolution of trilinear cells (default; off: 4³ blocks)."""
        return self._skip_maps.cell_skipping

    @cell_skipping.setter
    def cell_skipping(self, value: bool) -> None:
        self._skip_maps.cell_skipping = value

    @property
    def support_skipping(self) -> bool:
        """March straight outside the warp chain's support (see the class docstring)."""
        return self._support.enabled

    @support_skipping.setter
    def support_skipping(self, value: bool) -> None:
        self._support.enabled = bool(value)

    @property
    def support_maps(self) -> str:
        """When a warp state's support map is built, for the 3D view and the slices:
        "auto" (default) when the state is drawn a second time (a drag's ever-changing
        states draw with the chain at every sample and cost no map, nor a GPU model's
        read-back), "always" on first draw, "never" not at all (the window sets it while
        the user interacts, as three slice views draw each state of a drag)."""
        return self._support.build

    @support_maps.setter
    def support_maps(self, value: str) -> None:
        if value not in ("auto", "always", "never"):
            raise RenderError(f"support_maps must be 'auto', 'always' or 'never'; got {value!r}")
        self._support.build = value
        if self._slice_renderer is not None:
            self._slice_renderer.support.build = value

    @property
    def support_tolerance(self) -> float:
        """Largest displacement (voxels of the finest spacing) drawn as no displacement:
        points moved less sample where a straight ray does (default 1e-3)."""
        return self._support.tolerance_voxels

    @support_tolerance.setter
    def support_tolerance(self, value: float) -> None:
        if not (float(value) >= 0.0):
            raise RenderError(f"support_tolerance must be >= 0 voxels; got {value!r}")
        self._support.tolerance_voxels = float(value)

    @property
    def gradient_texture(self) -> bool | str:
        """Shading from a precomputed gradient texture (:mod:`voxwarp.render.gradients`):
        ``"auto"`` for volumes of at most ``gradients.MAX_VOXELS`` voxels, True always,
        False never (six volume fetches per shaded sample)."""
        return self._gradient_texture

    @gradient_texture.setter
    def gradient_texture(self, value: bool | str) -> None:
        if value not in ("auto", True, False):
            raise RenderError(f"gradient_texture must be 'auto', True or False; got {value!r}")
        self._gradient_texture = value if value == "auto" else bool(value)

    @property
    def ray_segment(self) -> int | str:
        """Samples per piecewise-linear segment of warped rays
        (:mod:`voxwarp.render.skipping.segments`): ``"auto"`` lets each region use the
        longest segment whose measured chord error stays within :attr:`ray_tolerance`;
        ``1`` (default) evaluates the warp chain at every sample; K > 1 forces K
        everywhere (for measurements). Only rays that skip through
        deformed-space cell maps (``last_skip_kind == "cells"``) use segments."""
        return self._skip_maps.segments.setting

    @ray_segment.setter
    def ray_segment(self, value: int | str) -> None:
        self._skip_maps.segments.setting = value

    @property
    def ray_tolerance(self) -> float:
        """Largest chord error of a warped-ray segment, in texels (default 0.1)."""
        return self._skip_maps.segments.tolerance

    @ray_tolerance.setter
    def ray_tolerance(self, value: float) -> None:
        self._skip_maps.segments.tolerance = value

    @property
    def warped_skip_maps(self) -> str:
        """Deformed-space skip maps of warped rays: "auto" builds them when a warp state
        is drawn a second time, "always" on first use, "never" keeps per-block checks,
        "background" offers them as :meth:`skip_map_job` (see
        :meth:`voxwarp.render.skipping.cache.SkipMapCache.kind`)."""
        return self._skip_maps.warped_skip_maps

    @warped_skip_maps.setter
    def warped_skip_maps(self, value: str) -> None:
        self._skip_maps.warped_skip_maps = value

    @property
    def cell_skip_maps(self) -> str:
        """Straight-ray cell skip maps: "auto" builds those of a volume of more than
        :data:`voxwarp.render.skipping.cache.EAGER_CELLS` cells on its second draw (the
        first skips per block, the same image), "always" on its first, "background"
        offers their CPU work as :meth:`skip_map_job` (blocks until it is installed)."""
        return self._skip_maps.cell_skip_maps

    @cell_skip_maps.setter
    def cell_skip_maps(self, value: str) -> None:
        if value not in ("auto", "always", "background"):
            raise RenderError(
                f"cell_skip_maps must be 'auto', 'always' or 'background'; got {value!r}"
            )
        self._skip_maps.cell_skip_maps = value

    @property
    def samples_per_check(self) -> int | str:
        """Lattice samples a straight ray with cell maps takes per skip-map check, 1 to
        4, or "auto" (default: by the share of visible cells for unshaded dvr on a CPU
        rasteriser, else 1); samples through the warp chain take at most 2. Never
        changes the image, only the time (:mod:`voxwarp.render.skipping.checks`)."""
        return self._samples_per_check

    @samples_per_check.setter
    def samples_per_check(self, value: int | str) -> None:
        self._samples_per_check = checked_setting(value)

    @property
    def coarse_cell_maps(self) -> str:
        """Straight-ray octant skip maps per 2³ trilinear cells (an eighth of the bytes;
        the same images, rays near visible cells jump a little less far): "auto" for a
        volume of more than :data:`voxwarp.render.skipping.cache.COARSE_MIN_CELLS` cells,
        "always", or "never" (one map cell per trilinear cell, as before)."""
        return self._skip_maps.coarse_cell_maps

    @coarse_cell_maps.setter
    def coarse_cell_maps(self, value: str) -> None:
        if value not in ("auto", "always", "never"):
            raise RenderError(
                f"coarse_cell_maps must be 'auto', 'always' or 'never'; got {value!r}"
            )
        self._skip_maps.coarse_cell_maps = value

    def needs_skip_maps(self, scene: Scene) -> bool:
        """With :attr:`warped_skip_maps` (straight rays: :attr:`cell_skip_maps`)
        "background": whether drawing ``scene`` now would march block by block only
        because its skip maps are not built yet (no side effects; a chain whose support
        map says it moves nothing draws, and so needs, the undeformed maps)."""
        scene = self._support_plan(scene, draw=False)[0]
        entry = self._volumes.get(id(scene.volume))
        return self._skip_maps.needs_maps(scene, None if entry is None else entry[1].skip)

    def skip_map_job(self) -> tuple[Any, Callable[[], Any]] | None:
        """With :attr:`warped_skip_maps` "background": ``(key, job)`` for the warp
        state the last draw drew with block checks, or None. ``job()`` is CPU work (no
        GL) that may run on any thread while the warps it was made from stay alive; hand
        its result to :meth:`install_skip_map`. A state that changed meanwhile simply
        never uses it."""
        return self._skip_maps.take_job()

    def install_skip_map(self, key: Any, result: Any) -> None:
        """Keep a finished :meth:`skip_map_job` result; the next draw of its warp state
        uploads and uses it."""
        self._skip_maps.install(key, result)

    def _program(
        self,
        scene: Scene,
        linear: bool,
        kind: str,
        segment: int,
        gradient_texture: bool,
        layout: str,
        support: bool = False,
        coarse: bool = False,
        checks: tuple[int, int] = (1, 1),
    ) -> Any:
        piecewise = "map" if segment == 0 else "fixed" if segment > 1 else ""
        warps = [] if linear else scene.warps
        meshes = bool(scene.meshes)
        key = (
            scene.mode,
            linear,
            scene.use_shading(),
            kind,
            layout,
            tuple(w.signature() for w in warps),
            meshes,
            piecewise,
            gradient_texture,
            scene.comparison is not None,
            uses_gradient_texture(scene),
            self._detj_on(scene),
            support,
            coarse,
            checks,
        )
        hold = self._programs.get(key)
        if hold is not None:
            return hold.program
        defines = [f"#define BLOCK {BLOCK}", f"#define OCTANT_EPS {OCTANT_EPS:e}"]
        if linear:
            defines.append("#define LINEAR_PATH")
        if scene.use_shading():
            defines.append("#define SHADING")
        if kind == "none":
            defines.append("#define NO_SKIPPING")
        defines += layout_defines(layout)
        if kind == "cells":
            defines.append("#define CELL_SKIP")
        if coarse:  # straight-ray octant maps per COARSE_FACTOR³ cells
            defines += ["#define COARSE_CELLS", f"#define CELL_FACTOR {COARSE_FACTOR}"]
        per_check, chained = checks  # lattice samples per skip-map check
        if per_check > 1:  # straight rays and phases
            defines.append(f"#define SAMPLES_PER_CHECK {per_check}")
        if chained > 1:  # samples through the chain
            defines.append(f"#define CHAINED_PER_CHECK {chained}")
        if meshes:
            defines.append("#define MESH_DEPTH")
        if piecewise:
            defines.append("#define PIECEWISE")
        if piecewise == "map":
            defines.append("#define SEGMENT_MAP")
        if gradient_texture:
            defines.append("#define GRADIENT_TEXTURE")
        if scene.comparison is not None:
            defines.append("#define COMPARE")
        if uses_gradient_texture(scene):
            defines.append("#define FIXED_GRADIENT_TEXTURE")
        if self._detj_on(scene):
            defines.append("#define DETJ_OVERLAY")
        if support:
            defines.append("#define SUPPORT_MAP")
        frag = shaders.source(
            "raycast.frag.glsl",
            extra={
                "mode.glsl": shaders.read(f"mode_{scene.mode}.glsl"),
                "warps.glsl": compose_glsl(warps),
            },
        )
        frag = shaders.with_defines(frag, defines)

        try:  # compiled once per context, shared by its renderers (gl_programs)
            hold = gl_programs.program(
                self.ctx, vertex_shader=shaders.read("polygon.vert.glsl"), fragment_shader=frag
            )
        except Exception as exc:
            raise RenderError(f"raycast shader failed to compile/link for {key}: {exc}") from exc
        self._programs[key] = hold
        return hold.program

    # ------------------------------------------------------------------ drawing
    def draw(
        self,
        scene: Scene,
        framebuffer: Any,
        viewport: tuple[int, int, int, int] | None = None,
        camera: Camera | None = None,
    ) -> None:
        """Raycast ``scene`` into ``framebuffer`` (moderngl.Framebuffer) within ``viewport``.

        ``camera`` overrides the scene's (e.g. the GUI's interactive camera).
        """
        if self._released:
            raise RenderError("this Renderer was released")
        frame = self._begin_frame(scene, framebuffer, viewport, camera)
        values = self._set_uniforms(frame)
        # meshes of a mixed scene first: the pass binds its own textures and framebuffer
        mesh_inv_view_proj = self._draw_mesh_pass(frame)
        unit = self._bind_textures(frame)
        self._bind_mesh_target(frame, unit, mesh_inv_view_proj)
        self._draw_regions(frame, framebuffer, self._octant_regions(frame, values))

    def _begin_frame(
        self,
        scene: Scene,
        framebuffer: Any,
        viewport: tuple[int, int, int, int] | None,
        camera: Camera | None,
    ) -> _Frame:
        """Upload the volume, resolve viewport, camera and ray kind, pick the skipping
        (kept in :attr:`last_skip_kind`) and the program: the :class:`_Frame` of a draw."""
        gpu = self._volume_gpu(scene.volume)
        if viewport is None:
            viewport = (0, 0, *framebuffer.size)
        x, y, w, h = (int(v) for v in viewport)
        if w <= 0 or h <= 0:
            raise RenderError(f"viewport must have a positive size; got {viewport}")
        cam = camera or scene.resolved_camera()
        scene, plan = self._support_plan(scene)
        fold = fold_affine(scene.warps)
        linear = fold is not None
        skip_kind = self._skip_maps.kind(scene, linear, gpu.skip)
        if scene.comparison is not None:  # the skip maps know the moving volume only
            skip_kind = "none"
        self.last_skip_kind = skip_kind
        segment = 1
        if skip_kind == "cells" and not linear:
            segment = self._skip_maps.segments.fixed()
        self.last_ray_segment = segment
        shade_tex = self.last_gradient_texture = self._use_gradients(scene)
        support = plan == "map" and segment == 1 and not self._nearly_empty(scene, gpu, skip_kind)
        self.last_support = "map" if support else "none" if linear else "all"
        coarse = skip_kind == "cells" and linear and self._skip_maps.cell_factor(scene) > 1
        per_check, chained = self._checks(scene, gpu, skip_kind, linear, support, segment)
        self.last_samples_per_check, self.last_chained_per_check = per_check, chained
        prog = self._program(
            scene, linear, skip_kind, segment, shade_tex, gpu.layout, support, coarse,
            (per_check, chained),
        )  # fmt: skip
        bg = np.asarray(scene.background, float)
        bg_premul = (*(bg[:3] * bg[3]), bg[3])
        view = (x, y, w, h)
        return _Frame(
            scene, gpu, cam, view, fold, skip_kind, prog, bg_premul, shade_tex, segment, support
        )

    def _checks(
        self, scene: Scene, gpu: _VolumeGPU, skip_kind: str, linear: bool, support: bool,
        segment: int,
    ) -> tuple[int, int]:  # fmt: skip
        """Lattice samples per skip-map check (:mod:`voxwarp.render.skipping.checks`) of
        straight rays or a warped ray's straight phases, and of samples through the
        chain (the warped loop, a chained phase; not piecewise-linear rays)."""
        if skip_kind != "cells":
            return 1, 1
        maps, setting = self._skip_maps, self._samples_per_check
        if linear:
            visible = maps.visible_fraction(gpu.skip, scene)
            return samples_per_check(setting, scene, self._software, visible), 1
        visible = maps.warped_fraction(gpu.skip, scene)
        straight = samples_per_check(setting, scene, self._software, visible) if support else 1
        chained = chained_samples_per_check(setting, scene, self._software, visible)
        return straight, chained if segment == 1 else 1

    def _support_plan(self, scene: Scene, draw: bool = True) -> tuple[Scene, str]:
        """The scene a draw renders and how it uses the chain's support ("none": the
        chain moves nothing beyond the tolerance, so the scene without its warps; "map";
        "all"); ``draw`` False: asked outside a draw (builds nothing)."""
        if fold_affine(scene.warps) is not None:
            return scene, "all"
        plan = self._support.plan(scene, draw=draw)
        if plan == "none":
            return scene.copy(warps=[]), plan
        return scene, plan

    def _nearly_empty(self, scene: Scene, gpu: _VolumeGPU, skip_kind: str) -> bool:
        """Whether warped rays with deformed-space cell maps see fewer than
        MAP_MIN_VISIBLE of the cells: the map path costs more than it saves there."""
        if skip_kind != "cells":
            return False
        return self._skip_maps.warped_fraction(gpu.skip, scene) < MAP_MIN_VISIBLE

    def _detj_on(self, scene: Scene) -> bool:
        """Whether this draw tints by det J (an overlay is set and the mode shows it)."""
        return self.jacobian_overlay is not None and scene.mode in DETJ_MODES

    def _use_gradients(self, scene: Scene) -> bool:
        """Whether shading reads a gradient texture (see :attr:`gradient_texture`)."""
        if not scene.use_shading() or self.gradient_texture is False:
            return False
        if self.gradient_texture is True:
            return True
        return scene.volume.data.size <= gradients.MAX_VOXELS

    def _set_uniforms(self, frame: _Frame) -> dict[str, Any]:
        """Set the raycast program's uniforms for ``frame``; returns them by name."""
        values = self._frame_uniforms(frame)
        values.update(_mode_uniforms(frame.scene))
        if self.jacobian_overlay is not None and self._detj_on(frame.scene):
            values.update(self.jacobian_overlay.uniforms())
        values.update(self._texel_uniforms(frame))
        for name, value in values.items():
            set_uniform(frame.prog, name, value)
        return values

    def _frame_uniforms(self, frame: _Frame) -> dict[str, Any]:
        """The uniforms of every program variant: camera, ray bounds and steps, volume,
        value and colour mappings, light and texture units."""
        scene, gpu = frame.scene, frame.gpu
        vol, tf = scene.volume, scene.transfer_function
        x, y, w, h = frame.viewport
        lo, hi = scene.ray_bounds()
        level, width = scene.window
        step_mm = scene.sample_distance_mm
        diag = float(np.linalg.norm(np.asarray(hi) - np.asarray(lo)))
        tf_lo, tf_hi = tf.value_range
        tf_scale = (TABLE_SIZE - 1) / (tf_hi - tf_lo)
        return {
            "u_inv_view_proj": np.linalg.inv(frame.camera.view_projection(w / h)),
            "u_viewport": (x, y, w, h),
            "u_bounds_lo": tuple(lo),
            "u_bounds_hi": tuple(hi),
            "u_step": step_mm,
            "u_max_steps": int(min(diag / step_mm + 4, 1_000_000)),
            "u_jitter": int(scene.jitter),
            "u_seed": scene.seed & 0xFFFFFFFF,
            "u_background": frame.background,
            "u_value_limits": vol.value_range,
            "u_dims": tuple(float(s) for s in vol.shape),
            "u_inv_dims": tuple(1.0 / s for s in vol.shape),
            "u_value_map": gpu.value_map,
            "u_spacing": tuple(np.asarray(vol.spacing)),
            "u_origin": tuple(vol.origin),
            "u_direction": vol.direction,
            "u_tf_map": (tf_scale, 0.5 - tf_lo * tf_scale),
            "u_tf_size": float(TABLE_SIZE),
            "u_window": (level - width / 2, level + width / 2),
            "u_light": LIGHT,
            "u_blocks": tuple(int(b) for b in gpu.blocks),
            "u_volume": 0,
            "u_tf": 1,
            "u_block_info": 2,
            "u_cell_skip": 3,
        }

    def _texel_uniforms(self, frame: _Frame) -> dict[str, Any]:
        """World-to-texel maps: straight rays', through the folded chain; with cell
        skipping, warped rays' into the deformed-space skip map, and its size."""
        to_texel = frame.scene.volume.world_to_texel_matrix()
        if frame.fold is not None:
            return {"u_world_to_texel": to_texel @ frame.fold, "u_jacobian": frame.fold[:3, :3]}
        if frame.skip_kind != "cells":
            return {}
        # warped rays look up deformed-space cells: the volume's texel grid shifted by
        # the skip map's padding
        maps = frame.gpu.skip
        visible = self._skip_maps.warped_visibility(maps, frame.scene)
        to_texel[:3, 3] -= maps.warped_offset
        values = {
            "u_skip_world_to_texel": to_texel,
            "u_cell_dims": tuple(int(c) for c in visible.shape),
        }
        values["u_segment"] = max(frame.segment, 1)
        if frame.segment == 0:
            self._skip_maps.warped_segments(maps, frame.scene)
            values["u_segment_world_to_map"] = maps.warped_segments.world_to_map()
            values["u_segment_map_dims"] = maps.warped_segments.lengths.shape
            values["u_max_segment"] = MAX_SAMPLES
        return values

    def _draw_mesh_pass(self, frame: _Frame) -> np.ndarray | None:
        """Draw a mixed scene's meshes into the internal colour + depth target of the
        viewport's size, over the background; returns the mesh camera's inverse
        view-projection (None without meshes: nothing is drawn).

        The mesh camera is the frame's with its near/far range widened to hold every
        mesh, so meshes are not clipped by a camera fitted to the volume.
        """
        scene, cam = frame.scene, frame.camera
        if not scene.meshes:
            return None
        _, _, w, h = frame.viewport
        if self._mesh_renderer is None:
            self._mesh_renderer = MeshRenderer(self.ctx)
        fbo = self._mesh_framebuffer(w, h)
        bounds = mesh_instances_bounds(scene.meshes, scene.warps)
        assert bounds is not None
        lo, hi = bounds
        corners = box_corners(lo, hi)
        reach = float(np.max(np.linalg.norm(corners - cam.center, axis=1)))
        mesh_cam = dataclasses.replace(cam, radius=reach) if reach > cam.radius else cam
        self._mesh_renderer.draw(
            scene.meshes, fbo, mesh_cam, clear=frame.background, warps=scene.warps
        )
        return np.linalg.inv(mesh_cam.view_projection(w / h))

    def _mesh_framebuffer(self, w: int, h: int) -> Any:
        """The mesh pass's (w, h) framebuffer (colour + depth textures), remade on resize."""
        if self._mesh_target is None or self._mesh_target[0] != (w, h):
            self._release_mesh_target()
            color = self.ctx.texture((w, h), 4, dtype="f4")
            depth = self.ctx.depth_texture((w, h))
            depth.compare_func = ""  # read depth values, not comparisons
            for tex in (color, depth):
                tex.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
            fbo = self.ctx.framebuffer(color_attachments=[color], depth_attachment=depth)
            self._mesh_target = ((w, h), color, depth, fbo)
        return self._mesh_target[3]

    def _release_mesh_target(self) -> None:
        if self._mesh_target is not None:
            for obj in self._mesh_target[1:][::-1]:
                obj.release()
            self._mesh_target = None

    def _bind_textures(self, frame: _Frame) -> int:
        """Bind the volume (unit 0), transfer-function table (1), block info (2) and the
        warps' textures (4 on), and set the warps' uniforms; returns the next free unit."""
        scene, prog = frame.scene, frame.prog
        # the warps' textures first: making them may run GPU passes (an offset field
        # bakes its inverse) that bind texture units of their own
        textures = [] if frame.linear else warp_textures(self.ctx, scene.warps)
        frame.gpu.texture.use(0)
        ratio = scene.sample_distance_mm / scene.opacity_reference_mm
        self._tf_texture(scene.transfer_function, ratio).use(1)
        self._skip_maps.block_info(frame.gpu.skip, scene).use(2)
        unit = 4
        if not frame.linear:
            unit = bind_warps(prog, scene.warps, textures, unit)
        if frame.gradients:
            frame.gpu.gradient_texture(self.ctx, scene.volume).use(unit)
            set_uniform(prog, "u_gradient", unit)
            unit += 1
        if frame.support:
            support = self._support.uniforms(scene)
            for name, value in support.items():
                set_uniform(prog, name, value)
            self._support_ranges_texture(frame, support).use(unit)
            set_uniform(prog, "u_support_ranges", unit)
            unit += 1
        if frame.segment == 0 and frame.gpu.skip.segment_texture is not None:
            frame.gpu.skip.segment_texture.use(unit)
            set_uniform(prog, "u_segment_map", unit)
            unit += 1
        if scene.comparison is not None:
            self.check_volume(scene.comparison.fixed)  # too large: one line with advice
            texture, value_map = self._fixed.get(scene.comparison.fixed)
            texture.use(unit)
            for name, value in compare_uniforms(
                scene.volume, scene.comparison, unit, value_map
            ).items():
                set_uniform(prog, name, value)
            unit += 1
            if uses_gradient_texture(scene):
                self._fixed.gradient(scene.comparison.fixed).use(unit)
                set_uniform(prog, "u_fixed_gradient", unit)
                unit += 1
        return unit

    def _support_ranges_texture(self, frame: _Frame, support: dict[str, Any]) -> Any:
        """Each pixel's first and last crossing of the support's surface
        (:mod:`voxwarp.render.support_ranges`), drawn for this frame's camera."""
        _, _, w, h = frame.viewport
        inv_view_proj = np.linalg.inv(frame.camera.view_projection(w / h))
        box = (support["u_support_lo"], support["u_support_hi"])
        smap = self._support.support(frame.scene)
        return self._support_ranges.texture(
            smap, inv_view_proj, (w, h), box, bound=self.support_ranges
        )

    def _bind_mesh_target(
        self, frame: _Frame, unit: int, mesh_inv_view_proj: np.ndarray | None
    ) -> None:
        """Bind the mesh pass's colour and depth (units ``unit``, ``unit + 1``) and set
        its camera, for the raycaster to composite over (nothing without meshes)."""
        if mesh_inv_view_proj is None:
            return
        assert self._mesh_target is not None
        self._mesh_target[1].use(unit)
        self._mesh_target[2].use(unit + 1)
        set_uniform(frame.prog, "u_mesh_color", unit)
        set_uniform(frame.prog, "u_mesh_depth", unit + 1)
        set_uniform(frame.prog, "u_mesh_inv_view_proj", mesh_inv_view_proj)

    @staticmethod
    def _octant_regions(frame: _Frame, values: dict[str, Any]) -> list[_Region]:
        """The convex NDC polygons the image is drawn as: one covering the viewport, or,
        with octant skip maps, one per ray-direction octant present in the image (the
        shader discards the other octants' pixels along the shared borders)."""
        if frame.skip_kind != "cells":
            return [(None, [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)])]
        to_texel = values["u_world_to_texel" if frame.linear else "u_skip_world_to_texel"]
        coefficients = ray_direction_coefficients(values["u_inv_view_proj"], to_texel)
        _, _, w, h = frame.viewport
        return list(octant_regions(coefficients, (w, h)))

    def _draw_regions(self, frame: _Frame, framebuffer: Any, regions: list[_Region]) -> None:
        """Clear the viewport to the background (rays that miss the volume, or see
        nothing, discard), then draw each region with its octant's skip map."""
        prog = frame.prog
        framebuffer.use()
        framebuffer.viewport = frame.viewport
        framebuffer.clear(*frame.background, viewport=frame.viewport)
        self.ctx.disable(self.ctx.DEPTH_TEST | self.ctx.BLEND)
        vao = self._vao.get(id(prog))
        if vao is None:
            vao = self.ctx.vertex_array(prog, [])
            self._vao[id(prog)] = vao
        skip = self._skip_maps.cell_skip if frame.linear else self._skip_maps.warped_cell_skip
        for octant, polygon in regions:
            if octant is not None:
                skip(frame.gpu.skip, frame.scene, octant).use(3)
                set_uniform(prog, "u_octant", tuple(float(c) for c in octant))
            corners = [*polygon, *[(0.0, 0.0)] * (MAX_POLYGON - len(polygon))]
            prog["u_polygon"].value = corners
            vao.render(mode=self.ctx.TRIANGLE_FAN, vertices=len(polygon))

    def slice_values(
        self,
        scene: Scene,
        pixel_to_world: np.ndarray,
        size: tuple[int, int],
        *,
        slab_mm: float = 0.0,
        slab_mode: str = "mip",
        interpolation: str = "linear",
        detj: bool = False,
    ) -> np.ndarray:
        """One slice of ``scene`` through its warp chain, as data: (H, W, 4) float32,
        row 0 at the top, channels (deformed value, coverage, rest value, coverage);
        ``detj=True`` adds a fifth, det J of the chain at each pixel's point.

        Pixel ``(col, row)`` samples the world point ``pixel_to_world @ (col, row, 0, 1)``;
        a slab ``slab_mm`` thick runs along the matrix's third column, combined by
        ``slab_mode`` (``"mip"``, ``"minip"``, ``"average"``); ``interpolation`` is
        ``"linear"`` (trilinear) or ``"nearest"``. See :mod:`voxwarp.render.slices`.
        """
        if self._released:
            raise RenderError("this Renderer was released")
        gpu = self._volume_gpu(scene.volume)
        return self._slices().values(
            gpu,
            scene,
            pixel_to_world,
            size,
            slab_mm=slab_mm,
            slab_mode=slab_mode,
            interpolation=interpolation,
            detj=detj,
        )

    def _slices(self) -> SliceRenderer:
        """The slice renderer (made on first use, with this renderer's support_maps)."""
        if self._slice_renderer is None:
            self._slice_renderer = SliceRenderer(self.ctx)
            self._slice_renderer.support.build = self._support.build
        return self._slice_renderer

    def slice_detj(
        self, scene: Scene, pixel_to_world: np.ndarray, size: tuple[int, int]
    ) -> np.ndarray:
        """``det J`` of the scene's warp chain at the pixel centres of a slice, on the GPU
        (the warps' GLSL Jacobians): (H, W) float32, row 0 at the top; pixels as in
        :meth:`slice_values` (the CPU reference is
        :func:`voxwarp.render.jacobian_overlay.slice_detj`)."""
        if self._released:
            raise RenderError("this Renderer was released")
        gpu = self._volume_gpu(scene.volume)
        data = self._slices().values(gpu, scene, pixel_to_world, size, detj=True)
        return data[..., 4].copy()

    def draw_scaled(
        self,
        scene: Scene,
        framebuffer: Any,
        viewport: tuple[int, int, int, int] | None = None,
        camera: Camera | None = None,
        scale: float = 0.5,
    ) -> None:
        """Like :meth:`draw`, at ``scale`` times the resolution, upscaled bilinearly into
        ``viewport``: the interactive level of detail (``scale`` 0.5 costs about a
        quarter of the samples). ``scale`` >= 1 is a plain :meth:`draw`."""
        if viewport is None:
            viewport = (0, 0, *framebuffer.size)
        x, y, w, h = (int(v) for v in viewport)
        if not 0.0 < scale:
            raise RenderError(f"scale must be positive; got {scale}")
        if scale >= 1.0:
            self.draw(scene, framebuffer, viewport, camera)
            return
        size = (max(1, round(w * scale)), max(1, round(h * scale)))
        if self._lod_target is None or self._lod_target[0] != size:
            self._release_lod_target()
            tex = self.ctx.texture(size, 4, dtype="f1")
            tex.filter = (self.ctx.LINEAR, self.ctx.LINEAR)
            tex.repeat_x = tex.repeat_y = False
            self._lod_target = (size, tex, self.ctx.framebuffer(color_attachments=[tex]))
        _, tex, fbo = self._lod_target
        self.draw(scene, fbo, (0, 0, *size), camera)
        if self._upscale is None:
            hold = gl_programs.program(
                self.ctx,
                vertex_shader=shaders.source("upscale.vert.glsl"),
                fragment_shader=shaders.source("upscale.frag.glsl"),
            )
            self._upscale = (hold, self.ctx.vertex_array(hold.program, []))
        hold, vao = self._upscale
        prog = hold.program
        framebuffer.use()
        framebuffer.viewport = (x, y, w, h)
        with self.ctx.scope(framebuffer, enable_only=0):  # no blending, depth, culling: a copy
            tex.use(0)
            prog["u_frame"] = 0
            vao.render(self.ctx.TRIANGLES, vertices=3)

    def _release_lod_target(self) -> None:
        if self._lod_target is not None:
            _, tex, fbo = self._lod_target
            fbo.release()
            tex.release()
            self._lod_target = None

    def release(self) -> None:
        """Free every GPU resource this renderer made; idempotent."""
        if self._released:
            return
        for _, gpu in self._volumes.values():
            gpu.release()
        self._volumes.clear()
        for vao in self._vao.values():
            vao.release()
        self._vao.clear()
        for hold in self._programs.values():
            hold.release()  # the shared program stays for the context's other users
        self._programs.clear()
        self._release_lod_target()
        if self._upscale is not None:
            self._upscale[1].release()
            self._upscale[0].release()
            self._upscale = None
        if self._tf_tex is not None:
            self._tf_tex.release()
            self._tf_tex = None
        if self._mesh_renderer is not None:
            self._mesh_renderer.release()
            self._mesh_renderer = None
        if self._slice_renderer is not None:
            self._slice_renderer.release()
            self._slice_renderer = None
        self._fixed.release()
        self._support.release()
        self._support_ranges.release()
        self._release_mesh_target()
        self._released = True


def _mode_uniforms(scene: Scene) -> dict[str, Any]:
    """The mode's parameters, resolved only for the mode that reads them."""
    values: dict[str, Any] = {}
    if scene.mode == "flm":
        values["u_threshold"] = scene.resolved_flm_threshold()
    if scene.mode == "xray":
        values["u_xray_length"] = xray_reference_length(scene.volume)
    if scene.mode == "iso":
        iso = scene.resolved_iso_value()
        iso_rgb = scene.transfer_function(iso)[:3]
        if float(np.max(iso_rgb)) < 0.2:  # a dark TF colour: use a neutral surface
            iso_rgb = np.array([0.9, 0.85, 0.8])
        values["u_iso"] = iso
        values["u_iso_color"] = tuple(float(c) for c in iso_rgb)
    return values
