"""The interactive notebook viewer: voxwarp's renderer in a ``jupyter_rfb`` widget.

:class:`Viewer` is a :class:`jupyter_rfb.RemoteFrameBuffer`: the browser sends pointer,
wheel, key and resize events to :meth:`Viewer.handle_event`, which turns them into
camera moves and edits of an :class:`~voxwarp.editing.session.EditSession` (the desktop
GUI's Qt-free session; the controls are those of
:mod:`voxwarp.notebook.interaction`) and asks for a frame; :meth:`Viewer.get_frame`
renders the scene headless (:class:`~voxwarp.render.offscreen.OffscreenRenderer`) with
the editing handles drawn on top by the desktop viewport's pass
(:class:`~voxwarp.render.overlay.OverlayRenderer`, point sizes scaled to the frame's
resolution) and returns it.

While the view is being changed (a drag, an orbit, a running mass-spring or ChainMail
model that has not come to rest) frames are drawn at the level of detail the desktop
GUI uses (:class:`~voxwarp.render.adaptive_quality.AdaptiveQuality`: a fraction of the
resolution, which the browser scales up, and a longer sample distance), and the model
advances one frame (``steps_per_frame`` steps) before each; once it rests, the full
frame follows. The same actions are methods for scripts and tests: :meth:`orbit`,
:meth:`zoom`, :meth:`pan`, :meth:`pick`, :meth:`drag`, :meth:`undo`, :meth:`snapshot`;
:meth:`show_overlays` switches the warped grid and the displacement glyphs.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.core.comparison import Comparison
from voxwarp.core.volume import Volume
from voxwarp.editing.common import DisplayOptions
from voxwarp.editing.session import EditorError, EditSession
from voxwarp.errors import MissingExtraError, VoxwarpError
from voxwarp.inputs import load_input
from voxwarp.io.image_objects import image_kind
from voxwarp.io.samples import suggested_transfer_function
from voxwarp.io.volumes import load_volume
from voxwarp.notebook.gl_thread import GLThread, SameThread
from voxwarp.notebook.interaction import SETTLE_S, Interaction, view_size
from voxwarp.render.adaptive_quality import FULL, AdaptiveQuality, Quality, scene_at
from voxwarp.render.inline_image import RenderedImage, png_bytes
from voxwarp.render.interaction_volume import InteractionVolumes
from voxwarp.render.jacobian_overlay import (
    DEFAULT_OPACITY,
    DETJ_MODES,
    JacobianOverlay,
    draw_legend,
)
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.render.overlay import OverlayRenderer
from voxwarp.render.overlay_options import OVERLAYS, check_overlays
from voxwarp.render.warp_meshes import WarpLines
from voxwarp.scene import Scene, as_fixed_volume

try:
    from jupyter_rfb import RemoteFrameBuffer
except ImportError as exc:  # pragma: no cover - the notebook extra is missing
    raise MissingExtraError(
        "voxwarp.notebook.Viewer needs the notebook extra (missing: jupyter_rfb):"
        " pip install 'voxwarp[notebook]'"
    ) from exc

#: default view size in CSS pixels
DEFAULT_SIZE = (480, 360)
#: the longest side rendered (device pixels): larger views are scaled up by the browser
MAX_RENDER_PX = 1024
#: least seconds between frames of a running simulation
SIM_FRAME_S = 1 / 30


def session_for(source: Any, deformation: str | None = None, **settings: Any) -> EditSession:
    """An edit session for ``source``: a :class:`~voxwarp.scene.Scene` (a copy of it is
    edited; its warps resume as the session's deformation), an
    :class:`~voxwarp.editing.session.EditSession`, a :class:`~voxwarp.core.volume.Volume`,
    a 3D array or a SimpleITK/nibabel image (as :func:`~voxwarp.io.volumes.load_volume`
    takes them), or INPUT as
    ``voxwarp gui`` takes it (a scene JSON, resuming its deformation; a volume file;
    ``sample:NAME``). ``deformation`` (``"massspring"``, ``"chainmail"``,
    ``"wires"``, ``"lattice"``) starts that family with ``settings`` (``resolution``,
    ``stiffness``, ``integrator``, ``variant``, ``backend``). One time point or channel
    of a 4-D file: pass ``load_volume(path, frame_index=..., channel=...)``."""
    if isinstance(source, EditSession):
        session = source
    elif isinstance(source, Scene):
        session = EditSession(source.copy())  # the caller's scene keeps its warps
    elif isinstance(source, Volume):
        session = EditSession(Scene(source))
    elif isinstance(source, np.ndarray) or image_kind(source):  # as load_volume takes them
        session = EditSession(Scene(load_volume(source)))
    elif isinstance(source, str | Path):
        session = _session_from_input(str(source))
    else:
        raise EditorError(
            "Viewer takes a Scene, an EditSession, a Volume, a 3D array, a SimpleITK or"
            " nibabel image, a scene JSON path,"
            f" a volume path or 'sample:NAME'; got {type(source).__name__}"
        )
    session.sync_builds = False  # wire fields are rebuilt when a drag ends
    start_deformation(session, deformation, settings)
    return session


def start_deformation(session: EditSession, deformation: str | None, settings: dict) -> None:
    """Start ``deformation`` (None: keep the session's) with ``settings``."""
    if deformation is not None:
        session.set_deformation(deformation, **settings)
    elif settings:
        raise EditorError(f"deformation settings {', '.join(sorted(settings))} need a deformation")


def _session_from_input(spec: str) -> EditSession:
    if spec.lower().endswith(".json") and Path(spec).is_file():
        return EditSession.load(spec)
    obj = load_input(spec)
    if isinstance(obj, Scene):
        return EditSession(obj)
    tf = suggested_transfer_function(obj.name) if spec.startswith("sample:") else None
    return EditSession(Scene(obj, transfer_function=tf))


class Viewer(RemoteFrameBuffer):
    """An interactive view of a scene in Jupyter: orbit, zoom, pick and drag handles.

    Use it as the last expression of a cell (or ``viewer.display()``); the viewer's
    :attr:`session` is the full editing API (``viewer.session.model``, ``.selection``,
    ``.set_option(...)``; ``viewer.session.scene`` is the scene being edited, a copy of
    a scene passed in), :attr:`camera` its camera.

    Parameters
    ----------
    source
        What to show and edit (see :func:`session_for`): a Scene, an EditSession, a
        Volume, a scene JSON path, a volume path or ``"sample:NAME"``.
    deformation
        Start a deformation family on it: ``"massspring"``, ``"chainmail"``, ``"wires"``
        or ``"lattice"`` (a scene JSON saved with one resumes it without this).
    size
        (width, height) of the view in CSS pixels.
    running
        Whether a mass-spring or ChainMail model runs between frames.
    ctx
        A moderngl context to render with (its owner makes it current); default: a
        headless EGL context of the viewer's own.
    fixed
        A registration's fixed image (a Volume, a path or ``"sample:NAME"``): the view
        compares the moving image seen through the warps with it (checkerboard; see
        :meth:`set_fixed` and :mod:`voxwarp.core.comparison`). None: a scene's own.
    settings
        Deformation settings: ``resolution``, ``stiffness``, ``integrator``,
        ``variant``, ``backend``, and the element grid's boundary conditions ``anchor``
        (``"shell"``, ``"corners"``, ``"none"``) and ``fix_outside`` (mm, ``"auto"``).
    """

    def __init__(
        self,
        source: Any,
        deformation: str | None = None,
        *,
        size: tuple[int, int] = DEFAULT_SIZE,
        running: bool = True,
        ctx: Any = None,
        fixed: Any = None,
        **settings: Any,
    ) -> None:
        w, h = view_size(size)  # one-line EditorError for a string, three numbers, ...
        super().__init__(css_width=f"{w}px", css_height=f"{h}px")
        # an own context lives on a thread of its own (Jupyter calls from several)
        self._gl: GLThread | SameThread = GLThread() if ctx is None else SameThread()
        self._released = False
        self._overlay: OverlayRenderer | None = None  # the handles' pass, made on first draw
        try:
            self._renderer = self._gl.run(OffscreenRenderer, w, h, ctx=ctx)
        except BaseException:
            self._released = True  # the widget's __del__ closes it again: nothing left
            self._gl.shutdown()
            raise
        try:
            self.session = self._on_gl(session_for, source)
            self.session.ctx = self._renderer.ctx  # GPU models step on the viewer's context
            self.session.gl_scope = self._renderer.current
            self._on_gl(start_deformation, self.session, deformation, settings)
        except BaseException:
            self._released = True
            self._gl.run(self._renderer.release)
            self._gl.shutdown()
            raise
        self.session.running = bool(running)
        if fixed is not None:
            self.session.scene.comparison = Comparison(as_fixed_volume(fixed))
        self.pixel_ratio = 1.0
        self.interaction = Interaction(self.session, (w, h))
        self.display_options = DisplayOptions()
        self.adaptive = AdaptiveQuality()
        self.last_quality: Quality = FULL
        #: the volume at the scene's ``interactive_downsample``, for interactive frames
        self.interaction_volumes = InteractionVolumes()
        self.frames_drawn = 0
        self.last_frame_ms = 0.0
        self._refine: Any = None
        #: the warped grid / glyph switches (:meth:`show_overlays`)
        self.warp_lines = WarpLines()

    # ------------------------------------------------------------------ properties
    @property
    def camera(self) -> Any:
        """The view's :class:`~voxwarp.core.camera.Camera` (orbit, pan and zoom move it)."""
        return self.interaction.camera

    @property
    def size(self) -> tuple[int, int]:
        """The view's (width, height) in CSS pixels."""
        return self.interaction.size

    @property
    def running(self) -> bool:
        """Whether a mass-spring or ChainMail model runs between frames (settable)."""
        return bool(self.session.running)

    @running.setter
    def running(self, value: bool) -> None:
        self._on_gl(self.session.set_option, "running", bool(value))
        self.request_draw()

    @property
    def overlays(self) -> tuple[str, ...]:
        """Overlays drawn over the view (settable: a name, a comma list or names of
        :data:`~voxwarp.render.overlay_options.OVERLAYS`): ``"jacobian"`` colours the
        volume by det J of the warp chain, with a legend (dvr, mip, minip, iso; see
        :mod:`voxwarp.render.jacobian_overlay`, strength :attr:`overlay_opacity`);
        ``"grid"`` and ``"glyphs"`` as :meth:`show_overlays`."""
        lines = self.warp_lines
        on = {
            "jacobian": self._renderer.renderer.jacobian_overlay is not None,
            "grid": lines.grid,
            "glyphs": lines.glyphs,
        }
        return tuple(name for name in OVERLAYS if on[name])

    @overlays.setter
    def overlays(self, names: Any) -> None:
        wanted = check_overlays(names)
        opacity = getattr(self, "_overlay_opacity", DEFAULT_OPACITY)
        overlay = JacobianOverlay(opacity=opacity) if "jacobian" in wanted else None
        self._renderer.renderer.jacobian_overlay = overlay
        self.show_overlays(grid="grid" in wanted, glyphs="glyphs" in wanted)

    @property
    def overlay_opacity(self) -> float:
        """Strength (0..1) of the overlay colours (settable)."""
        return float(getattr(self, "_overlay_opacity", DEFAULT_OPACITY))

    @overlay_opacity.setter
    def overlay_opacity(self, value: float) -> None:
        self._overlay_opacity = JacobianOverlay(opacity=float(value)).opacity
        self.overlays = self.overlays

    def _on_gl(self, fn: Any, *args: Any, **kwargs: Any) -> Any:
        """``fn(*args, **kwargs)`` on the viewer's GL thread with its context current
        (every use of the session and the renderer goes through here, one at a time)."""

        def call() -> Any:
            with self._renderer.current():
                return fn(*args, **kwargs)

        return self._gl.run(call)

    def _redrawn(self, result: Any) -> Any:
        """``result``, after asking for a frame (from the caller's thread: jupyter_rfb
        schedules it on that thread's event loop)."""
        self.request_draw()
        return result

    # ------------------------------------------------------------------ scripting API
    def orbit(self, d_azimuth: float, d_elevation: float = 0.0) -> None:
        """Turn the camera (degrees about its up axis, then its right axis)."""
        self._redrawn(self._on_gl(self.interaction.orbit, d_azimuth, d_elevation))

    def zoom(self, factor: float) -> None:
        """Magnify by ``factor`` (> 1 zooms in)."""
        self._redrawn(self._on_gl(self.interaction.zoom, factor))

    def pan(self, dx: float, dy: float) -> None:
        """Move the view by fractions of its height (right, up)."""
        self._redrawn(self._on_gl(self.interaction.pan, dx, dy))

    def reset_camera(self) -> None:
        """Refit the camera to the scene."""
        self._redrawn(self._on_gl(self.interaction.reset_camera))

    def set_fixed(
        self,
        fixed: Any,
        compare: str = "checkerboard",
        blend: float = 0.5,
        checker_mm: float | None = None,
    ) -> None:
        """Compare with a fixed image (a Volume, a path or ``"sample:NAME"``) as
        ``compare`` says (``"checkerboard"``, ``"difference"``, ``"blend"``); None
        stops comparing. See ``Scene(fixed=...)``."""
        cmp = None
        if fixed is not None:
            cmp = Comparison(as_fixed_volume(fixed), compare, blend, checker_mm)
        self.session.scene.comparison = cmp
        self.request_draw()

    def show_overlays(
        self,
        grid: bool | None = None,
        glyphs: bool | None = None,
        spacing_mm: float | None = None,
    ) -> None:
        """Switch the warped grid and the displacement glyphs (lines over the view on
        the plane facing the camera, carried by the scene's warp chain; see
        :class:`~voxwarp.render.warp_meshes.WarpLines`); ``spacing_mm`` 0: about 1/16
        of the volume. ``None`` leaves a setting as it is."""
        lines = self.warp_lines
        if grid is not None:
            lines.grid = bool(grid)
        if glyphs is not None:
            lines.glyphs = bool(glyphs)
        if spacing_mm is not None:
            lines.spacing_mm = max(float(spacing_mm), 0.0)
        self._redrawn(None)

    def handle_pixels(self) -> np.ndarray:
        """(N, 2) CSS pixel positions of the handles (to pick or drag them by script)."""
        return self._on_gl(self.interaction.handle_pixels)

    def pick(self, x: float, y: float, mode: str = "replace") -> int | None:
        """Select the handle under CSS pixel ``(x, y)``; its index, or None."""
        return self._redrawn(self._on_gl(self.interaction.pick, x, y, mode))

    def drag(self, start: Sequence[float], end: Sequence[float], steps: int = 8) -> int | None:
        """Drag the handle at CSS pixel ``start`` to ``end`` (one undo step); the model
        advances a frame per step. Returns the handle, or None when none is at ``start``."""
        return self._redrawn(self._on_gl(self.interaction.drag, start, end, steps))

    def step(self, frames: int = 1) -> None:
        """Advance the running model by ``frames`` frames (``steps_per_frame`` steps each)."""

        def run() -> None:
            for _ in range(max(0, int(frames))):
                self.session.advance()

        self._redrawn(self._on_gl(run))

    def undo(self) -> bool:
        """Undo the last edit (a drag, a selection); False when there is none."""
        return self._redrawn(self._on_gl(self.interaction.undo))

    def redo(self) -> bool:
        """Redo the last undone edit; False when there is none."""
        return self._redrawn(self._on_gl(self.interaction.redo))

    def snapshot(self, pixel_ratio: float | None = None) -> RenderedImage:  # type: ignore[override]
        """The view at full quality now: (H, W, 4) uint8 at the view's device pixels
        (shows inline; ``pixel_ratio`` overrides the browser's)."""
        ratio = self.pixel_ratio if pixel_ratio is None else float(pixel_ratio)
        return self._on_gl(self._draw, FULL, ratio)

    # ------------------------------------------------------------------ jupyter_rfb
    def handle_event(self, event: dict) -> bool:  # type: ignore[override]
        """Act on one ``jupyter_rfb`` event (pointer_down/move/up, wheel, key_down,
        resize, ...); returns whether it was used. A malformed or unknown event is
        ignored; an error of the edit is printed in the widget's output, in one line."""
        if not isinstance(event, dict):
            return False
        kind = event.get("type", event.get("event_type"))
        handler = _HANDLERS.get(kind) if isinstance(kind, str) else None
        if handler is None:
            return False
        try:
            used = bool(self._on_gl(handler, self, event))
        except (KeyError, TypeError, ValueError):
            return False  # a malformed event (missing or non-numeric fields)
        except VoxwarpError as exc:
            self.print(f"voxwarp: {exc}")
            return False
        if used:
            self.request_draw()
        return used

    def get_frame(self) -> np.ndarray | None:  # type: ignore[override]
        """The next frame (called by ``jupyter_rfb`` when the browser is ready): the
        model advances one frame if it runs, then the scene is drawn, at the
        interactive level of detail while anything moves."""
        try:
            frame, interacting = self._on_gl(self._next_frame)
        except VoxwarpError as exc:
            self.print(f"voxwarp: {exc}")
            return None
        if interacting:
            self._schedule_next()
        return frame

    def _next_frame(self) -> tuple[RenderedImage, bool]:
        """Advance a running model, draw; (frame, whether it was an interactive one)."""
        interacting = self.interaction.interacting()
        if self.interaction.simulating():
            self.session.advance()
        quality = self.adaptive.quality if interacting else FULL
        frame = self._draw(quality, self.pixel_ratio, interacting)
        if interacting:
            self.adaptive.frame_drawn(self.last_frame_ms / 1000)
        return frame, interacting

    def _repr_mimebundle_(self, **kwargs: Any) -> Any:
        """The widget, plus a PNG of the view for front ends without widgets (a
        notebook on GitHub, nbconvert)."""
        self._rfb_pending_display = None  # jupyter_rfb's HTML snapshot: the PNG below instead
        result = super()._repr_mimebundle_(**kwargs)
        data = result[0] if isinstance(result, tuple) else result
        if isinstance(data, dict):
            try:
                data["image/png"] = png_bytes(self.snapshot())
            except VoxwarpError:
                pass
        return result

    # ------------------------------------------------------------------ drawing
    def _draw(self, quality: Quality, ratio: float, interacting: bool = False) -> RenderedImage:
        """Render the scene and the handles at ``quality`` (device pixels: CSS size x
        ``ratio`` x the quality's scale, at most :data:`MAX_RENDER_PX` a side); an
        ``interacting`` frame draws the volume at the scene's ``interactive_downsample``."""
        t0 = time.perf_counter()
        w, h = self.size
        scale = ratio * quality.scale * min(1.0, MAX_RENDER_PX / (max(w, h) * ratio))
        size = (max(1, round(w * scale)), max(1, round(h * scale)))
        r = self._renderer
        with r.current():
            for warp in self.session.take_released_warps():
                warp.release()
            if r.size != size:
                r.resize(*size)
            scene = scene_at(self.session.scene, quality)
            if interacting:
                scene = self.interaction_volumes.scene(scene)
            r.renderer.draw(scene, r.framebuffer, camera=self.camera)
            if self._overlay is None:
                self._overlay = OverlayRenderer(r.ctx)
            layers = self.session.overlay_layers(self.display_options)
            layers += self.warp_lines.layers(self.session.scene, self.camera)
            self._overlay.draw(layers, r.framebuffer, self.camera, point_scale=scale)
            img = r.read()
        overlay = r.renderer.jacobian_overlay
        if overlay is not None and self.session.scene.mode in DETJ_MODES:
            draw_legend(img, overlay)
        self.last_quality = quality
        self.last_frame_ms = (time.perf_counter() - t0) * 1000
        self.frames_drawn += 1
        return img

    def _schedule_next(self) -> None:
        """Another frame soon: the next simulation frame, or the full-quality one once
        the interaction has settled."""
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:
            return  # no event loop (a script or a test): frames are drawn on request
        if self.interaction.simulating():
            loop.call_later(SIM_FRAME_S, self.request_draw)
        else:
            if self._refine is not None:
                self._refine.cancel()
            self._refine = loop.call_later(SETTLE_S + 0.05, self.request_draw)

    def close(self, *args: Any, **kwargs: Any) -> None:
        """Close the widget and free its GPU resources."""
        if "_released" not in vars(self):  # __init__ refused its size: no widget was made
            return
        super().close(*args, **kwargs)
        self.release()

    def release(self) -> None:
        """Free the renderer (and its context, if the viewer made it); idempotent."""
        if self._released:
            return
        self._released = True

        def free() -> None:
            with self._renderer.current():
                for warp in self.session.take_released_warps():
                    warp.release()
                if self._overlay is not None:
                    self._overlay.release()
            self._renderer.release()

        try:
            self._gl.run(free)
        except RuntimeError:  # Python is exiting: no new work, the driver frees it all
            return
        self._gl.shutdown()


# ---------------------------------------------------------------------- event handlers
def _xy(event: dict) -> tuple[float, float]:
    x, y = float(event["x"]), float(event["y"])
    if not (np.isfinite(x) and np.isfinite(y)):
        raise ValueError("non-finite pointer position")
    return x, y


def _on_resize(v: Viewer, e: dict) -> bool:
    w, h = float(e["width"]), float(e["height"])
    if not (np.isfinite(w) and np.isfinite(h) and w >= 1 and h >= 1):
        raise ValueError("bad size")
    ratio = float(e.get("ratio", e.get("pixel_ratio", 1.0)))
    v.pixel_ratio = ratio if np.isfinite(ratio) and 0.25 <= ratio <= 8 else 1.0
    v.interaction.resize((round(w), round(h)))
    return True


def _on_down(v: Viewer, e: dict) -> bool:
    v.interaction.press(*_xy(e), int(e.get("button", 1)), tuple(e.get("modifiers", ())))
    return True


def _on_move(v: Viewer, e: dict) -> bool:
    if not v.interaction.pressed:
        return False
    v.interaction.move(*_xy(e))
    return True


def _on_up(v: Viewer, e: dict) -> bool:
    x, y = _xy(e) if "x" in e and "y" in e else (None, None)
    v.interaction.release(x, y)
    return True


def _on_wheel(v: Viewer, e: dict) -> bool:
    v.interaction.wheel(float(e["dy"]))
    return True


def _on_key(v: Viewer, e: dict) -> bool:
    return v.interaction.key(str(e["key"]), tuple(e.get("modifiers", ())))


_HANDLERS = {
    "resize": _on_resize,
    "pointer_down": _on_down,
    "pointer_move": _on_move,
    "pointer_up": _on_up,
    "wheel": _on_wheel,
    "key_down": _on_key,
}
