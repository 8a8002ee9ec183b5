"""Headless rendering: :class:`OffscreenRenderer` draws scenes and slices into an
offscreen framebuffer on the pooled EGL context (or one it is given) and reads them back
as arrays (row 0 at the top) that Jupyter shows inline."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from voxwarp.core.camera import Camera
from voxwarp.core.slice_plane import SlicePlane
from voxwarp.core.warp_grid import MIN_CELL_PX, nice_spacing
from voxwarp.errors import RenderError
from voxwarp.render import context_pool
from voxwarp.render.context import egl_current, egl_restore
from voxwarp.render.inline_image import RenderedImage, rendered
from voxwarp.render.jacobian_overlay import (
    DEFAULT_OPACITY,
    DETJ_MODES,
    JacobianOverlay,
    draw_legend,
)
from voxwarp.render.overlay_options import check_overlays
from voxwarp.render.raycaster import Renderer
from voxwarp.render.slice_grid import named_slice_grid, slice_window
from voxwarp.render.slice_image import SliceImage, colorize
from voxwarp.render.warp_overlays import WARP_OVERLAYS, draw_slice_overlays
from voxwarp.scene import Scene


class OffscreenRenderer:
    """Headless rendering into an offscreen framebuffer.

    Parameters
    ----------
    width, height
        Image size in pixels.
    ctx
        Optional existing context (the caller's: made current by the caller, never
        released here); by default the renderer leases this thread's pooled EGL
        context (:mod:`voxwarp.render.context_pool`), shared with the thread's other
        renderers and given back on :meth:`release`.
    dtype
        ``"u1"`` for (H, W, 4) uint8 images, ``"f4"`` for float32 (tests, HDR/EXR output).

    Use as a context manager; :meth:`render` returns the image with row 0 at the top.
    """

    def __init__(
        self, width: int = 512, height: int = 512, *, ctx: Any = None, dtype: str = "u1"
    ) -> None:
        if int(width) < 1 or int(height) < 1 or int(width) > 16384 or int(height) > 16384:
            raise RenderError(f"image size must be 1..16384 pixels per side; got {width}x{height}")
        if dtype not in ("u1", "f4"):
            raise RenderError(f"dtype must be 'u1' or 'f4'; got {dtype!r}")
        self._pooled = ctx is None
        self.ctx = context_pool.acquire() if ctx is None else ctx
        self.size = (int(width), int(height))
        self.dtype = dtype
        self._gl_dtype = "f1" if dtype == "u1" else "f4"
        self._fbo: Any = None
        self._color: Any = None
        try:
            with self.current():
                self.renderer = Renderer(self.ctx)
                self._make_fbo()
        except BaseException:
            if self._pooled:
                context_pool.give_back(self.ctx)
            raise
        self._released = False

    @contextlib.contextmanager
    def current(self) -> Iterator[None]:
        """A block with this renderer's context current and the previous one restored
        after (a context passed in too: several renderers may share one, and another
        context may be current when they draw): for GPU work beside :meth:`render`, such
        as an edit session's ``gl_scope``."""
        if getattr(self, "_released", False):
            raise RenderError(
                "this OffscreenRenderer is closed (released, or its with block has ended):"
                " use it inside the block, or make a new one"
            )
        saved = egl_current()
        self.ctx.mglo.__enter__()  # eglMakeCurrent(this context)
        if self._pooled:
            context_pool.collect(self.ctx)  # what was dropped unreleased since
        try:
            yield
        finally:
            if saved is not None:
                egl_restore(saved)

    def _unbind_fbo(self) -> None:
        # never delete the bound framebuffer: moderngl would re-bind the dead name later
        try:
            self.ctx.detect_framebuffer(0).use()
        except Exception:
            pass

    def _make_fbo(self) -> None:
        if self._fbo is not None:
            self._unbind_fbo()
            self._fbo.release()
            self._color.release()
        # moderngl "f1" is normalised RGBA8 ("u1" would be an integer format)
        self._color = self.ctx.renderbuffer(self.size, 4, dtype=self._gl_dtype)
        self._fbo = self.ctx.framebuffer(color_attachments=[self._color])

    def resize(self, width: int, height: int) -> None:
        """Change the image size."""
        self.size = (int(width), int(height))
        with self.current():
            self._make_fbo()

    @property
    def framebuffer(self) -> Any:
        """The moderngl framebuffer images are drawn into."""
        return self._fbo

    def render(self, scene: Scene, camera: Camera | None = None) -> RenderedImage:
        """Render ``scene``; returns (H, W, 4) uint8 or float32, row 0 = image top (a
        :class:`~voxwarp.render.inline_image.RenderedImage`: an array Jupyter shows)."""
        with self.current():
            self.renderer.draw(scene, self._fbo, camera=camera)
            img = self.read()
        overlay = self.renderer.jacobian_overlay
        if overlay is not None and scene.mode in DETJ_MODES:  # the det J colour bar
            draw_legend(img, overlay)
        return img

    def read(self) -> RenderedImage:
        """What :attr:`framebuffer` holds, as :meth:`render` returns it: after drawing
        more into it (e.g. an :class:`~voxwarp.render.overlay.OverlayRenderer` pass)."""
        with self.current():
            raw = self._fbo.read(components=4, dtype=self._gl_dtype, alignment=1)
        w, h = self.size
        img = np.frombuffer(raw, dtype=np.uint8 if self.dtype == "u1" else np.float32)
        return rendered(img.reshape(h, w, 4)[::-1].copy())

    def render_slice(
        self,
        scene: Scene,
        plane: SlicePlane | str,
        *,
        size: tuple[int, int] | None = None,
        at: float | None = None,
        slab_mm: float = 0.0,
        slab_mode: str = "mip",
        interpolation: str = "linear",
        look: str = "window",
        window: tuple[float, float] | None = None,
        show: str = "deformed",
        checker_mm: float | None = None,
        blend: float | None = None,
        pixel_mm: float | None = None,
        overlay: str | Sequence[str] = (),
        overlay_opacity: float = DEFAULT_OPACITY,
        grid_spacing_mm: float | None = None,
        glyph_spacing_mm: float | None = None,
    ) -> SliceImage:
        """One slice of ``scene`` through its warp chain (multi-planar reformatting).

        ``plane`` is a :class:`~voxwarp.core.slice_plane.SlicePlane` (``size``
        defaults to this renderer's) or a name (``"axial"``, ``"coronal"``,
        ``"sagittal"``, ``"x"``, ``"y"``, ``"z"``) at ``at`` mm along its axis (default:
        the voxel centre nearest the deformed box's centre) on the pixel grid of
        :func:`~voxwarp.render.slice_grid.named_slice_grid`: without ``size``, pixels of
        ``pixel_mm`` (default the smallest voxel side) whose centres are voxel centres,
        as many as hold the deformed box, so the default slice of an unwarped volume is
        the array's own slice. Returns a :class:`~voxwarp.render.slice_image.SliceImage`: its
        ``rgba`` (coloured by ``look`` ``"window"`` with ``window = (level, width)``,
        default the scene's own, else
        :func:`~voxwarp.core.window_presets.default_slice_window`: mediastinum for a CT
        in HU, the percentile window otherwise; or ``"tf"``; ``show`` one of
        ``"deformed"``, ``"rest"``, ``"checkerboard"``, ``"difference"``, ``"blend"``),
        the deformed and rest ``values`` and ``pixel_to_world``, the 4x4 map of pixel
        ``(col, row, 0, 1)`` to world mm. A scene with a fixed image
        (``Scene(fixed=...)``) samples it at the same world points (``image.fixed``) and
        compares with it instead of the rest state; ``checker_mm`` (world cells instead of
        32-pixel tiles) and ``blend`` default to the scene's comparison settings.
        ``overlay``: names of :data:`~voxwarp.render.overlay_options.OVERLAYS`;
        ``"jacobian"`` draws ``det J`` of the chain at every pixel centre (kept as
        ``detj``) as a colour map with a legend, ``overlay_opacity`` (0..1) strong
        (:mod:`voxwarp.render.jacobian_overlay`); ``grid`` and ``glyphs`` are drawn by
        :func:`voxwarp.render.warp_overlays.draw_slice_overlays` on the result, lines
        every ``grid_spacing_mm`` (default about 1/16 of the volume, at least 12 pixels)
        and arrows every ``glyph_spacing_mm`` (what was drawn: ``image.notes``).
        """
        overlays = check_overlays(overlay)
        jacobian = JacobianOverlay(opacity=overlay_opacity) if "jacobian" in overlays else None
        lines = [name for name in overlays if name in WARP_OVERLAYS]  # grid, glyphs
        if isinstance(plane, str):
            plane, size = named_slice_grid(scene, plane, at=at, size=size, pixel_mm=pixel_mm)
        else:
            size = self.size if size is None else (int(size[0]), int(size[1]))
            plane = plane if at is None else plane.at(at)
        sampling = {"slab_mm": slab_mm, "slab_mode": slab_mode, "interpolation": interpolation}
        image = self._sample_slice(scene, plane, size, sampling, detj=jacobian is not None)
        cmp = scene.comparison
        if cmp is not None:
            checker_mm = cmp.cell_mm if checker_mm is None else checker_mm
            blend = cmp.blend if blend is None else blend
        colorize(
            image,
            look=look,
            window=slice_window(scene) if window is None else window,
            tf=scene.transfer_function,
            show=show,
            checker_mm=checker_mm,
            blend=0.5 if blend is None else blend,
            jacobian=jacobian,
            legend=None if lines else "bottom-right",  # the legend goes over the lines
        )
        if lines:
            warps = [] if show == "rest" else scene.warps  # the rest state: a straight grid
            _draw_lines(image, warps, scene.volume, lines, grid_spacing_mm, glyph_spacing_mm)
            if jacobian is not None:
                draw_legend(image.rgba, jacobian)
        image.rgba = rendered(image.rgba)  # shows inline in Jupyter
        return image

    def _sample_slice(
        self,
        scene: Scene,
        plane: SlicePlane,
        size: tuple[int, int],
        sampling: dict[str, Any],
        detj: bool,
    ) -> SliceImage:
        """The deformed and rest values of ``plane`` (and det J, and the fixed image's
        values when the scene compares with one) on ``size`` pixels, not yet coloured."""
        matrix = plane.pixel_to_world(size)
        with self.current():
            data = self.renderer.slice_values(scene, matrix, size, detj=detj, **sampling)
        image = SliceImage.from_data(data[..., :4], matrix, plane)
        if detj:  # det J per pixel (same draw), where the volume shows
            det = data[..., 4]
            image.detj = np.where(np.isfinite(image.values), det, np.nan).astype(np.float32)
        if scene.comparison is not None:
            fixed_scene = Scene(scene.comparison.fixed, transfer_function=scene.transfer_function)
            with self.current():
                fixed = self.renderer.slice_values(fixed_scene, matrix, size, **sampling)
            image.fixed = SliceImage.from_data(fixed, matrix).values
        return image

    def time_frames(
        self, scene: Scene, frames: int = 10, warmup: int = 2, camera: Camera | None = None
    ) -> list[float]:
        """Milliseconds per frame (``ctx.finish()`` bound) after ``warmup`` frames."""
        with self.current():
            return self._time_frames(scene, frames, warmup, camera)

    def _time_frames(
        self, scene: Scene, frames: int, warmup: int, camera: Camera | None
    ) -> list[float]:
        for _ in range(warmup):
            self.renderer.draw(scene, self._fbo, camera=camera)
        self.ctx.finish()
        times = []
        for _ in range(frames):
            t = time.perf_counter()
            self.renderer.draw(scene, self._fbo, camera=camera)
            self.ctx.finish()
            times.append((time.perf_counter() - t) * 1000)
        return times

    def release(self) -> None:
        """Free every GL object this renderer made and give the pooled context back (the
        last renderer of a context also frees what warps cached on it); idempotent."""
        if getattr(self, "_released", True):
            return
        try:
            with self.current():
                self.renderer.release()
                self._unbind_fbo()
                self._fbo.release()
                self._color.release()
        finally:
            self._released = True
            if self._pooled:
                context_pool.give_back(self.ctx)

    def __enter__(self) -> OffscreenRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def _draw_lines(
    image: SliceImage,
    warps: Sequence[Any],
    volume: Any,
    lines: Sequence[str],
    grid_spacing_mm: float | None,
    glyph_spacing_mm: float | None,
) -> None:
    """Draw the ``grid``/``glyphs`` of ``lines`` over ``image.rgba`` (what was drawn in
    ``image.notes``); the grid spacing defaults to about 1/16 of the volume, at least 12
    pixels."""
    matrix = image.pixel_to_world
    if grid_spacing_mm is None:
        pixel = float(np.linalg.norm(matrix[:3, 0]))
        grid_spacing_mm = nice_spacing(*volume.bounds, MIN_CELL_PX * pixel)
    assert image.rgba is not None
    image.rgba, image.notes = draw_slice_overlays(
        image.rgba, warps, matrix, lines, grid_spacing_mm, glyph_spacing_mm=glyph_spacing_mm
    )
