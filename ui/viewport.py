"""The 3D viewport: a ``QOpenGLWidget`` drawing the scene with voxwarp's own renderer.

moderngl is attached to Qt's current context (the GUI draws with exactly the renderer
of headless rendering, into Qt's framebuffer object), then the editing handles are
drawn over the frame by :class:`voxwarp.render.overlay.OverlayRenderer`, and the
orientation marker (:mod:`voxwarp.render.orientation_marker`: the world axes with the
patient's R/L A/P S/I letters, or x y z for volumes without an orientation) in the
bottom-left corner (:attr:`Viewport.show_marker`): drawn with numpy, as headless renders
draw it, and blended into the frame as a texture (a ``QPainter`` on the widget would miss
grabs of the whole window, which redirect the widget's painting).

Mouse (see also the help dialog of the main window):

* left button on a handle: pick it (Shift adds, Ctrl toggles) and drag the selection
  in the plane parallel to the image through the reference handle;
* left button elsewhere: orbit; Shift + left elsewhere: rubber-band selection;
  while the family places a new object (its adapter's ``placing``: a new wire), each
  click places a point (``place_point``);
* middle button, or right button dragged: pan; right click: context menu;
* wheel: zoom.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Iterator
from typing import Any

import moderngl
import numpy as np
from PySide6.QtCore import QPoint, QRect, QSize, Qt, QTimer, Signal
from PySide6.QtGui import QImage, QKeyEvent, QMouseEvent, QOpenGLContext, QWheelEvent
from PySide6.QtOpenGLWidgets import QOpenGLWidget
from PySide6.QtWidgets import QRubberBand, QWidget

from voxwarp import shaders
from voxwarp.core.camera import Camera
from voxwarp.editing.session import DisplayOptions, EditSession
from voxwarp.errors import VoxwarpError
from voxwarp.render.adaptive_quality import FULL, AdaptiveQuality, scene_at
from voxwarp.render.interaction_volume import InteractionVolumes, reduced_volume
from voxwarp.render.orientation_marker import draw_orientation_marker
from voxwarp.render.overlay import OverlayRenderer
from voxwarp.render.raycaster import Renderer
from voxwarp.ui.tasks import Task

#: pixels the mouse may move before a press becomes a drag (orbit, pan, band)
CLICK_SLOP_PX = 3
#: frames are drawn at full resolution again this long after the last input (ms)
REFINE_AFTER_MS = 250
#: a warp state drawn again after this long gets its skip maps built (ms)
SKIP_MAP_SETTLE_MS = 150
#: degrees of orbit per arrow key press, and fraction of the view height per Shift+arrow
KEY_ORBIT_DEG = 5.0
KEY_PAN = 0.05
#: degrees of orbit per pixel of mouse motion
ORBIT_DEG_PER_PX = 0.4
#: side of the orientation marker's square and its distance from the corner (pixels)
MARKER_PX = 96
MARKER_MARGIN_PX = 6


class _QtLoader:
    """moderngl's loader for an external context: Qt's ``getProcAddress``."""

    def load_opengl_function(self, name: str) -> int:
        ctx = QOpenGLContext.currentContext()
        if ctx is None:
            return 0
        return int(ctx.getProcAddress(name.encode()) or 0)

    def release(self) -> None:
        """Nothing to release: Qt owns the context."""


class Viewport(QOpenGLWidget):
    """Draws an :class:`~voxwarp.editing.session.EditSession`'s scene and edits it with the mouse.

    Signals
    -------
    editStarted(str)
        Before an edit by mouse (a drag, a fix): the window snapshots for undo.
    editFinished(str)
        After it; the argument is the undo text.
    dragged()
        After every move of a drag (the window may rebuild a wire field).
    frameDrawn(float)
        After each frame, with its time in ms.
    failed(str)
        A drawing or editing error, with the message for the user.
    contextMenuAt(QPoint, object)
        Right click (global position, picked handle or None).
    pointPlaced()
        A click placed a point of the family's new object (a wire's control point).
    """

    editStarted = Signal(str)
    editFinished = Signal(str)
    dragged = Signal()
    frameDrawn = Signal(float)
    failed = Signal(str)
    contextMenuAt = Signal(QPoint, object)
    pointPlaced = Signal()

    def __init__(self, session: EditSession, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.session = session
        self.display = DisplayOptions()
        self.camera: Camera = session.scene.resolved_camera()
        #: draw the orientation marker (View -> Orientation Marker)
        self.show_marker = True
        self._marker: tuple[Any, np.ndarray] | None = None
        self._marker_gl: dict[str, Any] = {}
        #: more overlay layers to draw, ``(display) -> layers`` (the slice planes)
        self.extra_overlays: list[Callable[[DisplayOptions], list[Any]]] = []
        self.ctx: Any = None
        self.renderer: Renderer | None = None
        self.overlay: OverlayRenderer | None = None
        self.frames_drawn = 0
        self.last_frame_ms = 0.0
        self._press: dict[str, Any] | None = None
        self._band = QRubberBand(QRubberBand.Shape.Rectangle, self)
        #: the user moved the camera: a resize keeps it (else it is refitted)
        self.camera_moved = False
        self._skip_task: Task | None = None
        self._skip_key: Any = None
        #: the level of detail of frames drawn while interacting (dragging, orbiting, a
        #: running simulation): resolution and sample distance, adapted to the frame
        #: times so that the view stays responsive (full quality once it rests)
        self.adaptive = AdaptiveQuality()
        #: the level the last frame was drawn at
        self.last_quality = FULL
        #: the volume at the scene's interactive resolution (``interactive_downsample``),
        #: drawn while interacting; frames at rest draw the full volume
        self.interaction_volumes = InteractionVolumes()
        #: the volume the last frame drew (the scene's, or its reduced copy)
        self.last_volume: Any = None
        #: a still is being taken (:meth:`drawing_still`): full quality, full volume
        self._still = False
        #: the worker making the reduced volume, and the (volume id, level) that failed
        self._reduce_task: Task | None = None
        self._reduce_failed: tuple[int, int] | None = None
        #: seconds the views redrawn after each interactive frame took last time (the
        #: live slice views): the adaptive level budgets them with the 3D frame, so that
        #: the window, not only this view, holds the frame rate
        self.companion_s = 0.0
        self._last_input = 0.0
        self._refine = QTimer(self)
        self._refine.setSingleShot(True)
        self._refine.setInterval(REFINE_AFTER_MS)
        self._refine.timeout.connect(self._refine_frame)
        self.setMinimumSize(320, 240)
        self.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
        self.setMouseTracking(False)

    # ------------------------------------------------------------------ GL
    def initializeGL(self) -> None:
        """Attach moderngl to Qt's context and make the renderers."""
        try:
            self.ctx = moderngl.create_context(context=_QtLoader(), require=430)
        except Exception as exc:  # no 4.3 context: say so instead of crashing
            self.failed.emit(f"voxwarp needs OpenGL 4.3; this display offers less: {exc}")
            return
        self.session.gl_scope = self.gl_scope
        self.renderer = Renderer(self.ctx)
        # deformed-space skip maps take 0.5-3 s of CPU: never in a frame, but on a
        # worker thread once a warp state holds still (see _start_skip_map_job)
        self.renderer.warped_skip_maps = "background"
        self.renderer.cell_skip_maps = "background"  # a big volume's cell maps too
        self.overlay = OverlayRenderer(self.ctx)
        self.session.ctx = self.ctx

    def size_px(self) -> tuple[int, int]:
        """The framebuffer size in device pixels."""
        r = self.devicePixelRatio()
        return max(1, round(self.width() * r)), max(1, round(self.height() * r))

    def resizeGL(self, w: int, h: int) -> None:
        """Refit the camera to the new shape until the user moves it."""
        if not self.camera_moved:
            self.set_view(self.session.scene.view)

    def paintGL(self) -> None:
        """Raycast the scene, then the handles on top."""
        if self.renderer is None or self.overlay is None:
            return
        t0 = time.perf_counter()
        start_now = interactive = False
        w, h = self.size_px()
        fbo = self.ctx.detect_framebuffer(self.defaultFramebufferObject())
        try:
            self.session.poll_model()  # the newest state the model worker finished
            for warp in self.session.take_released_warps():
                warp.release()
            scene = self.session.scene
            if not self.display.volume:
                fbo.use()
                fbo.clear(*scene.background)
            else:
                # a new warp state waits for its skip maps at the interactive scale
                # (built on a worker: _start_skip_map_job) instead of marching every block
                waiting = self._waiting_for_skip_maps() and not self._still
                interactive = self.interacting() and not self._still
                start_now = waiting and not interactive
                quality = self.adaptive.quality if interactive or waiting else FULL
                self.last_quality = quality
                drawn = scene_at(scene, quality)
                if interactive:
                    drawn = self._interaction_scene(drawn)
                self.last_volume = drawn.volume
                # no support maps of states that change every frame (the slice views
                # draw each three times); the state at rest gets its map
                self.renderer.support_maps = "never" if interactive else "auto"
                self.renderer.draw_scaled(drawn, fbo, (0, 0, w, h), self.camera, quality.scale)
                if quality != FULL:
                    self._refine.start()  # full quality once the interaction stops
            layers = self.session.overlay_layers(self.display)
            layers += [layer for extra in self.extra_overlays for layer in extra(self.display)]
            self.overlay.draw(layers, fbo, self.camera, (0, 0, w, h))
            if self.show_marker:
                self._draw_marker(fbo)
            self.ctx.finish()  # honest frame times: wait for the GPU, not just the submission
        except VoxwarpError as exc:
            fbo.use()
            fbo.clear(0.15, 0.0, 0.0, 1.0)
            self.failed.emit(str(exc))
        self.last_frame_ms = (time.perf_counter() - t0) * 1000
        if interactive:
            self.adaptive.frame_drawn(self.last_frame_ms / 1000 + self.companion_s)
        self.frames_drawn += 1
        self._start_skip_map_job(start_now)
        self.frameDrawn.emit(self.last_frame_ms)

    def _interaction_scene(self, scene: Any) -> Any:
        """``scene`` at its ``interactive_downsample``: with the reduced volume once a
        worker thread has made it (seconds for a large CT), the full volume until then."""
        f = scene.interactive_downsample
        if f == 1:
            return scene
        if self.interaction_volumes.cached(scene.volume, f) is None:
            self._start_reduction(scene.volume, f)
            return scene
        return self.interaction_volumes.scene(scene)

    def _start_reduction(self, volume: Any, factor: int) -> None:
        """Make the reduced copy of ``volume`` on a worker thread (one at a time)."""
        running = self._reduce_task is not None and self._reduce_task.running
        if running or self._reduce_failed == (id(volume), factor):
            return  # a failed copy is not tried again for this volume and level
        cache = self.interaction_volumes

        def done(small: Any) -> None:
            cache.put(volume, factor, small)
            self.update()

        def failed(message: str) -> None:
            self._reduce_failed = (id(volume), factor)
            self.failed.emit(f"could not reduce the volume for interaction: {message}")

        task = Task(lambda _progress, _cancelled: reduced_volume(volume, factor), self)
        task.succeeded.connect(done)
        task.failed.connect(failed)
        self._reduce_task = task.start()

    def oriented(self) -> bool:
        """Whether the volume's world is patient RAS (the marker shows R/L A/P S/I)."""
        return getattr(self.session.volume, "space", "") == "RAS"

    def marker_image(self) -> np.ndarray:
        """The orientation marker for the current camera: premultiplied RGBA (uint8,
        row 0 at the top) of its square plus margin in device pixels, drawn by
        :func:`~voxwarp.render.orientation_marker.draw_orientation_marker` (kept until
        the view direction, the volume's orientation or the pixel ratio change)."""
        r = self.devicePixelRatio()
        side = round((MARKER_PX + 2 * MARKER_MARGIN_PX) * r)
        key = (np.round(self.camera.rotation, 6).tobytes(), self.oriented(), side)
        if self._marker is None or self._marker[0] != key:
            arr = np.zeros((side, side, 4), np.uint8)  # transparent: "over" gives premultiplied
            draw_orientation_marker(
                arr,
                self.camera,
                self.oriented(),
                size_px=round(MARKER_PX * r),
                margin_px=round(MARKER_MARGIN_PX * r),
            )
            self._marker = (key, arr)
        return self._marker[1]

    def _draw_marker(self, fbo: Any) -> None:
        """Blend the marker into the bottom-left corner of ``fbo`` (premultiplied over)."""
        img = self.marker_image()
        side = img.shape[0]
        gl = self._marker_gl
        ctx = self.ctx
        if gl.get("side") != side:
            if "tex" in gl:
                gl.pop("tex").release()
            tex = ctx.texture((side, side), 4, dtype="f1")
            tex.filter = (ctx.NEAREST, ctx.NEAREST)
            gl.update(tex=tex, side=side, shown=None)
        if gl.get("shown") is not img:
            gl["tex"].write(np.ascontiguousarray(img[::-1]).tobytes())  # GL rows: bottom up
            gl["shown"] = img
        if "prog" not in gl:
            # a textured square through the full-screen triangle of the raycaster's upscaler
            prog = ctx.program(
                vertex_shader=shaders.source("upscale.vert.glsl"),
                fragment_shader=shaders.source("upscale.frag.glsl"),
            )
            gl.update(prog=prog, vao=ctx.vertex_array(prog, []))
        previous_viewport = fbo.viewport
        fbo.use()
        fbo.viewport = (0, 0, side, side)  # GL's origin is the bottom-left corner
        scope = ctx.scope(fbo, enable_only=ctx.BLEND)
        try:
            with scope:
                ctx.blend_func = (ctx.ONE, ctx.ONE_MINUS_SRC_ALPHA)
                gl["tex"].use(0)
                gl["prog"]["u_frame"] = 0
                gl["vao"].render(ctx.TRIANGLES, vertices=3)
        finally:
            ctx.blend_func = ctx.DEFAULT_BLENDING
            scope.release()
            fbo.viewport = previous_viewport

    def _start_skip_map_job(self, now: bool) -> None:
        """Build the skip maps of a warp state drawn twice in a row (``now``: at once,
        the view rests) on a worker thread (CPU models only: a GPU model's field would
        be read back off its thread)."""
        assert self.renderer is not None
        wanted = self.renderer.skip_map_job()
        if wanted is None:
            self._skip_key = None
            return
        key, job = wanted
        gpu_model = not self._can_build_skip_maps()
        busy = self._skip_task is not None and self._skip_task.running
        if (key != self._skip_key and not now) or gpu_model or busy:
            if key != self._skip_key and not gpu_model:
                QTimer.singleShot(SKIP_MAP_SETTLE_MS, self.update)  # is it still there?
            self._skip_key = key
            return
        self._skip_key = None
        renderer = self.renderer
        task = Task(lambda _progress, _cancelled: job(), self)
        task.succeeded.connect(lambda result: self._skip_map_ready(renderer, key, result))
        self._skip_task = task.start()

    def _waiting_for_skip_maps(self) -> bool:
        """Whether the scene's warp state has no skip maps yet that a worker can build."""
        return (
            self.renderer is not None
            and self._can_build_skip_maps()
            and self.renderer.needs_skip_maps(self.session.scene)
        )

    def _can_build_skip_maps(self) -> bool:
        """Skip maps are built off the GUI thread for CPU models only (a GPU model's
        field would be read back off its context's thread)."""
        m = self.session.model
        return m is None or m.backend != "gpu"

    def _skip_map_ready(self, renderer: Renderer, key: Any, result: Any) -> None:
        if renderer is self.renderer:
            renderer.install_skip_map(key, result)
            self.update()

    def interacting(self) -> bool:
        """Whether the view is being changed right now: a mouse drag, a wheel turn or a
        key in the last moments, or a simulation that has not come to rest."""
        if self._press is not None and self._press.get("moved"):
            return True
        if (time.perf_counter() - self._last_input) * 1000 < REFINE_AFTER_MS:
            return True
        s = self.session
        return bool(s.running and s.model is not None and not s.settled)

    def at_rest(self) -> bool:
        """Whether the next frame is the final one: no interaction and no skip maps
        being built for it (tests and scripts wait for this before reading frames)."""
        if self.interacting() or (self._skip_task is not None and self._skip_task.running):
            return False
        if self.session.model_busy:
            return False
        return not self._waiting_for_skip_maps()

    def showing_final_frame(self) -> bool:
        """Whether the last frame drawn is the final one: at full quality, at rest, with
        no skip maps still being built for it (scripts wait for this before a picture)."""
        return self.last_quality == FULL and self.at_rest()

    def note_input(self) -> None:
        """Something changed the view (the next frames are interactive ones)."""
        self._last_input = time.perf_counter()

    def _refine_frame(self) -> None:
        if self.interacting():
            self._refine.start()
        elif self._skip_task is not None and self._skip_task.running:
            # the skip maps of this state are being built: its full-resolution frame
            # waits for them (_skip_map_ready redraws) instead of marching every block
            return
        else:
            self.update()

    def with_context(self, fn: Callable[[], Any]) -> Any:
        """Run ``fn`` with the viewport's GL context current (GPU models, releases);
        before the context exists, just run it."""
        with self.gl_scope():
            return fn()

    @contextlib.contextmanager
    def gl_scope(self) -> Iterator[None]:
        """Make the viewport's context current for a block (re-entrant: inside
        ``paintGL`` or another scope it is current already and stays so)."""
        if self.ctx is None or QOpenGLContext.currentContext() is self.context():
            yield
            return
        self.makeCurrent()
        try:
            yield
        finally:
            self.doneCurrent()

    def set_session(self, session: EditSession, keep_camera: bool = False) -> None:
        """Show another session (a file was opened)."""
        self.session = session
        session.ctx = self.ctx
        session.gl_scope = self.gl_scope
        self.interaction_volumes.clear()
        self.camera_moved = keep_camera
        if not keep_camera:
            self.reset_camera()
        self.update()

    def release_gl(self) -> None:
        """Release the renderers and the session's GPU resources (idempotent)."""
        if self.ctx is None:
            return

        def release() -> None:
            for warp in self.session.take_released_warps():
                warp.release()
            for name in ("vao", "prog", "tex"):
                if name in self._marker_gl:
                    self._marker_gl.pop(name).release()
            self._marker_gl.clear()
            if self.overlay is not None:
                self.overlay.release()
            if self.renderer is not None:
                self.renderer.release()

        self.with_context(release)
        self.renderer = self.overlay = None
        self.ctx = None

    # ------------------------------------------------------------------ camera
    def reset_camera(self) -> None:
        """Fit the camera to the scene from its standard view."""
        self.set_view(self.session.scene.view)

    def set_view(self, view: Any) -> None:
        """Look from a standard view (``"+x"`` ... ``"-z"``) or (azimuth, elevation),
        framing the scene in this viewport (also when it is taller than wide)."""
        scene = self.session.scene
        cam = scene.copy(camera=None, view=view).resolved_camera()
        w, h = self.size_px()
        if w < h:  # the fit frames the height; a tall viewport needs the width framed
            cam.zoom(w / h)
        self.camera = cam
        self.update()

    def set_projection(self, projection: str) -> None:
        """Perspective or orthographic, keeping the framing."""
        cam = self.camera
        if projection == cam.projection:
            return
        h = 2 * cam.distance * math.tan(math.radians(cam.fov) / 2)
        self.camera = Camera(
            cam.center, cam.rotation, cam.distance, cam.fov, projection, h, cam.radius
        )
        self.session.scene.projection = projection
        self.update()

    # ------------------------------------------------------------------ mouse
    def _xy(self, pos: Any) -> tuple[float, float]:
        r = self.devicePixelRatio()
        return float(pos.x()) * r, float(pos.y()) * r

    def mousePressEvent(self, event: QMouseEvent) -> None:
        """See :meth:`_mousePressEvent` (run with the GL context current: a GPU model moves
        its elements through GL)."""
        self.with_context(lambda: self._mousePressEvent(event))

    def _mousePressEvent(self, event: QMouseEvent) -> None:
        """Pick, start a drag, an orbit, a pan or a rubber band."""
        pos = event.position()
        mods = event.modifiers()
        shift = bool(mods & Qt.KeyboardModifier.ShiftModifier)
        ctrl = bool(mods & Qt.KeyboardModifier.ControlModifier)
        button = event.button()
        self._press = {"pos": pos, "last": pos, "button": button, "mode": None, "moved": False}
        xy = self._xy(pos)
        size = self.size_px()
        if button == Qt.MouseButton.LeftButton:
            family = self.session.family
            if family.placing:  # a click places a point of a new object, no picking
                family.place_point(self.camera, size, xy)
                self._press["mode"] = "placed"
                self.pointPlaced.emit()
                self.update()
                return
            hit = self.session.pick(self.camera, size, xy)
            if hit is not None:
                self.editStarted.emit("Drag")
                if ctrl:
                    self.session.select([hit], "toggle")
                elif shift:
                    self.session.select([hit], "add")
                elif hit not in self.session.selection:
                    self.session.select([hit], "replace")
                else:
                    self.session.set_reference(hit)
                if self.session.begin_drag(self.camera, size, xy):
                    self._press["mode"] = "drag"
                else:
                    self._press["mode"] = "select"
                self.update()
                return
            self._press["mode"] = "band" if shift or ctrl else "orbit"
        elif button == Qt.MouseButton.MiddleButton:
            self._press["mode"] = "pan"
        elif button == Qt.MouseButton.RightButton:
            self._press["mode"] = "pan-or-menu"

    def mouseMoveEvent(self, event: QMouseEvent) -> None:
        """See :meth:`_mouseMoveEvent` (run with the GL context current: a GPU model moves
        its elements through GL)."""
        self.with_context(lambda: self._mouseMoveEvent(event))

    def _mouseMoveEvent(self, event: QMouseEvent) -> None:
        """Drag the selection, orbit, pan or stretch the band."""
        if self._press is None:
            return
        pos = event.position()
        p = self._press
        if not p["moved"]:
            d = pos - p["pos"]
            if abs(d.x()) + abs(d.y()) < CLICK_SLOP_PX:
                return
            p["moved"] = True
        dx, dy = pos.x() - p["last"].x(), pos.y() - p["last"].y()
        p["last"] = pos
        self.note_input()
        mode = p["mode"]
        try:
            if mode == "drag":
                self.session.drag_to(self._xy(pos))
                self.dragged.emit()
            elif mode == "orbit":
                self.camera_moved = True
                self.camera.orbit(-dx * ORBIT_DEG_PER_PX, -dy * ORBIT_DEG_PER_PX)
            elif mode in ("pan", "pan-or-menu"):
                self.camera_moved = True
                self.camera.pan(-dx / max(1, self.height()), dy / max(1, self.height()))
            elif mode == "band":
                self._band.setGeometry(QRect(p["pos"].toPoint(), pos.toPoint()).normalized())
                self._band.show()
        except VoxwarpError as exc:
            self.failed.emit(str(exc))
        self.update()

    def mouseReleaseEvent(self, event: QMouseEvent) -> None:
        """See :meth:`_mouseReleaseEvent` (run with the GL context current: a GPU model moves
        its elements through GL)."""
        self.with_context(lambda: self._mouseReleaseEvent(event))

    def _mouseReleaseEvent(self, event: QMouseEvent) -> None:
        """Finish what the press started."""
        p, self._press = self._press, None
        if p is None:
            return
        mode = p["mode"]
        if mode in ("drag", "select"):
            self.session.end_drag()
            self.editFinished.emit("Drag" if p["moved"] else "Select")
        elif mode == "band":
            self._band.hide()
            mods = event.modifiers()
            how = "remove" if mods & Qt.KeyboardModifier.ControlModifier else "add"
            if p["moved"]:
                hits = self.session.pick_rect(
                    self.camera, self.size_px(), self._xy(p["pos"]), self._xy(event.position())
                )
                self.session.select(hits, how)
        elif mode == "orbit" and not p["moved"]:
            self.session.select([], "replace")  # a click on nothing clears the selection
        elif mode == "pan-or-menu" and not p["moved"]:
            hit = self.session.pick(self.camera, self.size_px(), self._xy(event.position()))
            self.contextMenuAt.emit(event.globalPosition().toPoint(), hit)
        self.update()

    def wheelEvent(self, event: QWheelEvent) -> None:
        """Zoom about the centre."""
        steps = event.angleDelta().y() / 120.0
        if steps:
            self.note_input()
            self.camera_moved = True
            self.camera.zoom(1.15**steps)
            self.update()

    def keyPressEvent(self, event: QKeyEvent) -> None:
        """Arrow keys orbit (Shift+arrows pan), + and - zoom."""
        key = event.key()
        shift = bool(event.modifiers() & Qt.KeyboardModifier.ShiftModifier)
        arrows = {
            Qt.Key.Key_Left: (-1, 0),
            Qt.Key.Key_Right: (1, 0),
            Qt.Key.Key_Up: (0, 1),
            Qt.Key.Key_Down: (0, -1),
        }
        if key in arrows:
            dx, dy = arrows[key]
            if shift:
                self.camera.pan(-dx * KEY_PAN, -dy * KEY_PAN)
            else:
                self.camera.orbit(dx * KEY_ORBIT_DEG, dy * KEY_ORBIT_DEG)
        elif key in (Qt.Key.Key_Plus, Qt.Key.Key_Equal):
            self.camera.zoom(1.15)
        elif key == Qt.Key.Key_Minus:
            self.camera.zoom(1 / 1.15)
        else:
            super().keyPressEvent(event)
            return
        self.camera_moved = True
        self.note_input()
        self.update()

    # ------------------------------------------------------------------ pictures
    @contextlib.contextmanager
    def drawing_still(self) -> Iterator[None]:
        """Frames drawn inside are stills: full quality and the full volume, even while
        the user interacts (screenshots: ``with viewport.drawing_still(): grab``)."""
        self._still = True
        try:
            yield
        finally:
            self._still = False
            self.update()  # the next frame is the interactive one again

    def screenshot(self) -> np.ndarray:
        """The current frame, (H, W, 4) uint8, row 0 at the top."""
        img = self.grabFramebuffer().convertToFormat(QImage.Format.Format_RGBA8888)
        return qimage_to_array(img)

    def sizeHint(self) -> QSize:
        """Preferred size."""
        return QSize(800, 600)


def qimage_to_array(img: QImage) -> np.ndarray:
    """An RGBA8888 ``QImage`` as an (H, W, 4) uint8 array (copied)."""
    img = img.convertToFormat(QImage.Format.Format_RGBA8888)
    w, h = img.width(), img.height()
    buf = np.frombuffer(img.constBits(), dtype=np.uint8, count=img.sizeInBytes())
    return buf.reshape(h, img.bytesPerLine())[:, : 4 * w].reshape(h, w, 4).copy()
