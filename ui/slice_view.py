"""One slice view of the linked multi-planar layout (``voxwarp.ui.mpr``).

A :class:`SliceView` shows one plane of :class:`voxwarp.editing.slice_views.SliceViews`:
the main viewport's :class:`~voxwarp.render.raycaster.Renderer` samples it through the
warp chain (:meth:`~voxwarp.render.raycaster.Renderer.slice_values`, on the viewport's
GL context: the window has one context), :func:`voxwarp.render.slice_image.colorize`
colours it on the CPU (a window/level drag only re-colours), and a ``QPainter`` draws
the image, the other planes' lines through the crosshair, the handles near the plane,
the orientation letters, a scale bar and the position readout.

Mouse: left click sets the crosshair in all views (left press on a handle picks it and
a drag moves it in the slice plane, one undoable edit); wheel scrolls through slices
(Ctrl + wheel zooms, Shift + wheel and Alt + wheel tilt the plane about its vertical and
horizontal axes through the crosshair: an oblique plane); right drag changes the window
(horizontal: width, vertical: level); middle drag pans.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from PySide6.QtCore import QPointF, QRectF, QSize, Qt, Signal
from PySide6.QtGui import (
    QColor,
    QFont,
    QImage,
    QMouseEvent,
    QPainter,
    QPaintEvent,
    QPen,
    QWheelEvent,
)
from PySide6.QtWidgets import QWidget

from voxwarp.core.slice_plane import SlicePlane
from voxwarp.editing.common import COLORS
from voxwarp.editing.reading import split_readout, window_text
from voxwarp.editing.slice_views import (
    PLANE_COLORS,
    edge_labels,
    handles_near,
    near_plane_mm,
    readout,
    scale_bar_mm,
)
from voxwarp.errors import VoxwarpError
from voxwarp.render.slice_image import SliceImage, colorize
from voxwarp.ui.detj_overlay import masked_detj, readout_suffix
from voxwarp.ui.fixed_image import slice_extras

__all__ = ["SliceView"]

#: pixels the mouse may move before a press becomes a drag
CLICK_SLOP_PX = 3
#: zoom per wheel notch with Ctrl
ZOOM_PER_STEP = 1.15
#: degrees a plane tilts per wheel notch with Shift (about its up axis) or Alt (right)
TILT_PER_STEP = 5.0
#: smallest size of a slice view (pixels)
SLICE_MIN_PX = (160, 120)
#: diameter of a handle's dot (pixels)
HANDLE_PX = 7.0


def qcolor(rgb: Any, alpha: float = 1.0) -> QColor:
    """A ``QColor`` from float RGB(A) in [0, 1]."""
    c = [float(v) for v in rgb]
    return QColor.fromRgbF(c[0], c[1], c[2], c[3] if len(c) > 3 else alpha)


class SliceView(QWidget):
    """One plane of the linked slice views (see the module docstring).

    Parameters
    ----------
    mpr
        The :class:`voxwarp.ui.mpr.SliceLayout` that owns the shared state (re-read
        every time: opening a file replaces it).
    index
        Which of the state's three planes (0: axial/z, 1: coronal/y, 2: sagittal/x).

    Signals
    -------
    editStarted(str), editFinished(str), dragged(), failed(str)
        As :class:`voxwarp.ui.viewport.Viewport`'s (the window snapshots for undo).
    """

    editStarted = Signal(str)
    editFinished = Signal(str)
    dragged = Signal()
    failed = Signal(str)

    def __init__(self, mpr: Any, index: int, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.mpr = mpr
        self.index = int(index)
        #: the last slice drawn (values and colours), or None
        self.image: SliceImage | None = None
        self._qimage: QImage | None = None
        self._press: dict[str, Any] | None = None
        self._hover: tuple[float, float] | None = None
        self._error = ""
        #: slices drawn (tests wait for it)
        self.renders = 0
        self.last_render_ms = 0.0
        self.setMinimumSize(*SLICE_MIN_PX)
        self.setMouseTracking(True)
        self.setFocusPolicy(Qt.FocusPolicy.ClickFocus)
        self.setAttribute(Qt.WidgetAttribute.WA_OpaquePaintEvent)

    # ------------------------------------------------------------------ geometry
    @property
    def name(self) -> str:
        """The plane's name (``axial`` ... or ``z`` ...)."""
        return self.mpr.state.names[self.index]

    def size_px(self) -> tuple[int, int]:
        """The view's size in (logical) pixels: the geometry of the plane's image."""
        return max(1, self.width()), max(1, self.height())

    def plane(self) -> SlicePlane:
        """The plane this view shows at its current size."""
        w, h = self.size_px()
        return self.mpr.state.plane(self.name, w / h, size=(w, h))  # on the voxel grid

    def world_at(self, x: float, y: float) -> np.ndarray:
        """The world point (mm) under widget position ``(x, y)``."""
        m = self.plane().pixel_to_world(self.size_px())
        return (m @ np.array([x - 0.5, y - 0.5, 0.0, 1.0]))[:3]

    def to_widget(self, points: np.ndarray, plane: SlicePlane | None = None) -> np.ndarray:
        """World points (N, 3) -> widget positions (N, 2) on this view's plane."""
        px, _ = (plane or self.plane()).world_to_pixel(points, self.size_px())
        return px + 0.5

    def handle_tolerance(self, plane: SlicePlane) -> float:
        """How far from the plane (mm) a handle may be and still show and be picked."""
        pts = self.mpr.window.session.handles()
        return near_plane_mm(pts, plane, self.size_px(), self.mpr.state.slab_mm)

    # ------------------------------------------------------------------ drawing
    def render(self, scale: float = 1.0) -> bool:
        """Sample the plane on the GPU (at ``scale`` of the view's resolution) and
        colour it; False when the viewport has no renderer yet or the view is hidden."""
        vp = self.mpr.viewport
        if vp.renderer is None or not self.isVisible():
            return False
        import time

        t0 = time.perf_counter()
        state, scene = self.mpr.state, self.mpr.window.session.scene
        w, h = self.size_px()
        r = self.devicePixelRatioF() * float(scale)
        size = (max(1, round(w * r)), max(1, round(h * r)))
        plane = self.plane()
        p2w = plane.pixel_to_world(size)
        detj = getattr(self.mpr.window, "detj", None)  # the det J overlay
        want_detj = detj is not None and detj.enabled
        try:
            data = vp.with_context(
                lambda: vp.renderer.slice_values(
                    scene,
                    p2w,
                    size,
                    slab_mm=state.slab_mm,
                    slab_mode=state.slab_mode,
                    interpolation=state.interpolation,
                    detj=want_detj,
                )
            )
            self.image = SliceImage.from_data(data[..., :4], p2w, plane)
            fixed = slice_extras(self.mpr.window)
            if fixed is not None:  # the fixed image on the same pixels (ui/fixed_image.py)
                self.image.fixed = vp.with_context(
                    lambda: fixed.fixed_values(vp.renderer, p2w, size, state)
                )
            self.image.detj = masked_detj(data, self.image) if want_detj else None
            self._error = ""
            self.recolor()
        except VoxwarpError as exc:
            self._show_error(str(exc))
        self.renders += 1
        self.last_render_ms = (time.perf_counter() - t0) * 1000
        return True

    def recolor(self) -> None:
        """Colour the last slice with the shared look, window and shown state (no GPU)."""
        if self.image is None:
            return
        state = self.mpr.state
        try:
            rgba = colorize(
                self.image,
                look=state.look,
                window=state.window,
                tf=self.mpr.window.session.scene.transfer_function,
                show=state.show,
                **(fixed.colour_options() if (fixed := slice_extras(self.mpr.window)) else {}),
                jacobian=getattr(self.mpr.window, "detj", None) and self.mpr.window.detj.jacobian(),
                legend="top-right",  # the readout and scale bar are at the bottom
            )
        except VoxwarpError as exc:
            self._show_error(str(exc))
            return
        if getattr(self.mpr.window, "warp_overlays", None) is not None:  # grid, glyphs
            rgba = self.mpr.window.warp_overlays.slice_rgba(self.image, rgba)
        h, w = rgba.shape[:2]
        self._qimage = QImage(rgba.data, w, h, 4 * w, QImage.Format.Format_RGBA8888).copy()
        self.update()

    def _show_error(self, message: str) -> None:
        if message != self._error:
            self._error = message
            self.failed.emit(message)
        self.update()

    def paintEvent(self, event: QPaintEvent) -> None:
        """The slice image and what lies over it."""
        p = QPainter(self)
        try:
            p.fillRect(self.rect(), Qt.GlobalColor.black)
            if self._qimage is not None:
                p.setRenderHint(QPainter.RenderHint.SmoothPixmapTransform, True)
                p.drawImage(QRectF(self.rect()), self._qimage)
            plane = self.plane()
            p.setRenderHint(QPainter.RenderHint.Antialiasing, True)
            self._paint_crosshair(p, plane)
            self._paint_handles(p, plane)
            self._paint_labels(p, plane)
        finally:
            p.end()

    def _paint_crosshair(self, p: QPainter, plane: SlicePlane) -> None:
        """Where the other two planes cut this one: lines in their colours through the
        crosshair."""
        state = self.mpr.state
        c = self.to_widget(state.crosshair[None], plane)[0]
        reach = float(np.hypot(self.width(), self.height()))
        for other in state.names:
            if other == self.name:
                continue
            n = state.plane(other).normal
            line = np.cross(plane.normal, n)
            d2 = np.array([line @ plane.right, -(line @ plane.up)])
            if np.linalg.norm(d2) < 1e-9:
                continue
            d2 = d2 / np.linalg.norm(d2) * reach
            p.setPen(QPen(qcolor(PLANE_COLORS[other], 0.85), 1.0))
            p.drawLine(QPointF(*(c - d2)), QPointF(*(c + d2)))

    def _paint_handles(self, p: QPainter, plane: SlicePlane) -> None:
        """The handles near the plane as dots (selected yellow, reference white, fixed
        red, anchored by a drag's region violet)."""
        session = self.mpr.window.session
        pts = session.handles()
        if not self.mpr.window.viewport.display.elements or len(pts) == 0:
            return
        near = handles_near(pts, plane, self.size_px(), self.mpr.state.slab_mm)
        if len(near) == 0:
            return
        xy = self.to_widget(pts[near], plane)
        fixed = session.fixed_handles()
        anchored = session.anchored_handles()
        selected = set(session.selection)
        p.setPen(QPen(QColor(15, 15, 15), 1.0))
        for i, (x, y) in zip(near, xy, strict=True):
            if i == session.reference:
                colour, size = COLORS["reference"], HANDLE_PX + 3
            elif i in selected:
                colour, size = COLORS["selected"], HANDLE_PX + 2
            elif len(fixed) > i and fixed[i]:
                colour, size = COLORS["fixed"], HANDLE_PX
            elif len(anchored) > i and anchored[i]:
                colour, size = COLORS["anchored"], HANDLE_PX
            else:
                colour, size = COLORS["element"], HANDLE_PX
            p.setBrush(qcolor(colour))
            p.drawEllipse(QPointF(x, y), size / 2, size / 2)

    def _paint_labels(self, p: QPainter, plane: SlicePlane) -> None:
        """Title, orientation letters, scale bar and readout."""
        state = self.mpr.state
        space = getattr(self.mpr.window.session.volume, "space", "")
        w, h = self.width(), self.height()
        font = QFont(p.font())
        font.setPointSizeF(9.0)
        p.setFont(font)
        fm = p.fontMetrics()
        colour = qcolor(PLANE_COLORS.get(self.name, (0.8, 0.8, 0.8)))
        p.setPen(QPen(colour, 2.0))
        p.setBrush(Qt.BrushStyle.NoBrush)
        p.drawRect(QRectF(1, 1, w - 2, h - 2))
        p.setPen(colour)
        pos = state.crosshair @ plane.scroll_axis
        title = f"{plane.name}  {pos:+.1f} mm" + (
            f"  slab {state.slab_mm:g} mm" if state.slab_mm else ""
        )
        p.drawText(QPointF(6, 4 + fm.ascent()), title)
        p.setPen(QColor(230, 230, 120))
        top = 4 + fm.ascent() + fm.height()  # below the title line
        bottom = h - 14 - 3 * fm.height()  # above the scale bar and the readout's 2 lines
        for side, text in edge_labels(plane, space).items():
            tw = fm.horizontalAdvance(text)
            x = {"left": 6.0, "right": w - 6.0 - tw}.get(side, (w - tw) / 2)
            y = {"top": top, "bottom": bottom}.get(side, (h + fm.ascent()) / 2)
            p.drawText(QPointF(x, y), text)
        self._paint_scale_bar(p, plane, fm)
        p.setPen(QColor(220, 220, 220))
        if state.look == "window":  # the window, top right (below, if the title is long)
            corner = self.window_text()
            cw = fm.horizontalAdvance(corner)
            row = 0 if fm.horizontalAdvance(title) + cw + 18 <= w else 1
            p.drawText(QPointF(w - 6 - cw, 4 + fm.ascent() + row * fm.height()), corner)
        for i, line in enumerate(reversed(self.readout_lines())):  # values last
            text = fm.elidedText(line, Qt.TextElideMode.ElideRight, w - 12)
            p.drawText(QPointF(6, h - 6 - fm.descent() - i * fm.height()), text)
        if self._error:
            p.setPen(QColor(255, 110, 110))
            p.drawText(QRectF(6, 24, w - 12, h - 48), Qt.TextFlag.TextWordWrap, self._error)

    def _paint_scale_bar(self, p: QPainter, plane: SlicePlane, fm: Any) -> None:
        w, h = self.width(), self.height()
        px_mm = plane.pixel_mm(self.size_px())
        mm = scale_bar_mm(px_mm, 0.25 * w)
        length = mm / px_mm
        x1 = w - 10
        y = h - 14 - 2 * fm.height()  # above the readout's two lines
        p.setPen(QPen(QColor(240, 240, 240), 2.0))
        p.drawLine(QPointF(x1 - length, y), QPointF(x1, y))
        for x in (x1 - length, x1):
            p.drawLine(QPointF(x, y - 4), QPointF(x, y + 4))
        text = f"{mm:g} mm"
        p.drawText(QPointF(x1 - (length + fm.horizontalAdvance(text)) / 2, y - 6), text)

    def window_text(self) -> str:
        """The corner label of the shared window: ``"W 400 L 40"`` (the toolbar's
        combo names its preset)."""
        return window_text(self.mpr.state.window)

    def readout_lines(self) -> tuple[str, str]:
        """:meth:`readout_text` as a position line and a value line (fits narrow views)."""
        return split_readout(self.readout_text())

    def readout_text(self) -> str:
        """The position line: the point under the cursor (else the crosshair) in patient
        mm and the deformed and rest values of the slice there."""
        space = getattr(self.mpr.window.session.volume, "space", "")
        if self._hover is not None:
            point = self.world_at(*self._hover)
        else:
            point = self.mpr.state.crosshair
        values = (float("nan"), float("nan"))
        suffix = ""
        if self.image is not None:
            _, h = self.size_px()
            ih = self.image.size[1]
            xy = self.to_widget(point[None])[0] * (ih / h)  # image pixels (a scaled image)
            values = self.image.value_at(xy[0], xy[1])
            suffix = readout_suffix(self.mpr.window, self.image, xy)
        fixed = self.image is not None and self.image.fixed is not None
        return readout(point, space, *values, "fixed" if fixed else "rest") + suffix

    # ------------------------------------------------------------------ mouse
    def mousePressEvent(self, event: QMouseEvent) -> None:
        """Pick a handle or set the crosshair (left), pan (middle), window (right)."""
        self.mpr.viewport.with_context(lambda: self._press_event(event))

    def _press_event(self, event: QMouseEvent) -> None:
        pos = event.position()
        xy = (float(pos.x()), float(pos.y()))
        button = event.button()
        self._press = {"pos": xy, "last": xy, "mode": None, "moved": False}
        if button == Qt.MouseButton.LeftButton:
            session = self.mpr.window.session
            plane = self.plane()
            size = self.size_px()
            hit = session.pick_near_plane(plane.camera(), size, xy, self.handle_tolerance(plane))
            if hit is not None:
                self.editStarted.emit("Drag")
                if hit not in session.selection:
                    session.select([hit], "replace")
                else:
                    session.set_reference(hit)
                ok = session.begin_drag(plane.camera(), size, xy)
                self._press["mode"] = "drag" if ok else "select"
                self.mpr.viewport.update()
                self.update()
                return
            self._press["mode"] = "crosshair"
            self._set_crosshair(xy)
        elif button == Qt.MouseButton.MiddleButton:
            self._press["mode"] = "pan"
        elif button == Qt.MouseButton.RightButton:
            self._press["mode"] = "window"

    def _set_crosshair(self, xy: tuple[float, float]) -> None:
        self.mpr.state.set_crosshair(self.world_at(*xy))
        self.mpr.planes_changed()

    def mouseMoveEvent(self, event: QMouseEvent) -> None:
        """Drag, move the crosshair, pan, change the window, or update the readout."""
        self.mpr.viewport.with_context(lambda: self._move_event(event))

    def _move_event(self, event: QMouseEvent) -> None:
        pos = event.position()
        xy = (float(pos.x()), float(pos.y()))
        self._hover = xy
        p = self._press
        if p is None:
            self.update()
            return
        if not p["moved"]:
            if abs(xy[0] - p["pos"][0]) + abs(xy[1] - p["pos"][1]) < CLICK_SLOP_PX:
                return
            p["moved"] = True
        dx, dy = xy[0] - p["last"][0], xy[1] - p["last"][1]
        p["last"] = xy
        mode = p["mode"]
        state = self.mpr.state
        try:
            if mode == "drag":
                self.mpr.window.session.drag_to(xy)
                self.dragged.emit()
                self.mpr.viewport.note_input()
                self.mpr.viewport.update()
            elif mode == "crosshair":
                self._set_crosshair(xy)
            elif mode == "pan":
                px_mm = self.plane().pixel_mm(self.size_px())
                state.pan(self.name, -dx * px_mm, dy * px_mm)
                self.render()
            elif mode == "window":
                state.window_drag(dx, dy)
                self.mpr.recolor_all()
        except VoxwarpError as exc:
            self.failed.emit(str(exc))
        self.update()

    def mouseReleaseEvent(self, event: QMouseEvent) -> None:
        """Finish a drag (one undoable edit)."""
        self.mpr.viewport.with_context(lambda: self._release_event(event))

    def _release_event(self, event: QMouseEvent) -> None:
        p, self._press = self._press, None
        if p is None:
            return
        if p["mode"] in ("drag", "select"):
            self.mpr.window.session.end_drag()
            self.editFinished.emit("Drag" if p["moved"] else "Select")
            self.mpr.viewport.update()
        self.update()

    def leaveEvent(self, event: Any) -> None:
        """The readout goes back to the crosshair."""
        self._hover = None
        self.update()
        super().leaveEvent(event)

    def wheelEvent(self, event: QWheelEvent) -> None:
        """Scroll through slices (one voxel spacing a notch); Ctrl: zoom; Shift / Alt:
        tilt the plane (:data:`TILT_PER_STEP` a notch)."""
        delta = event.angleDelta()
        # (with Alt or Shift some platforms turn the wheel into a horizontal one)
        steps = (delta.y() or delta.x()) / 120.0
        if not steps:
            return
        mods = event.modifiers()
        if mods & Qt.KeyboardModifier.ControlModifier:
            self.mpr.state.zoom(self.name, ZOOM_PER_STEP**steps)
            self.render()
            return
        if mods & (Qt.KeyboardModifier.ShiftModifier | Qt.KeyboardModifier.AltModifier):
            about = "up" if mods & Qt.KeyboardModifier.ShiftModifier else "right"
            self.mpr.state.rotate(self.name, TILT_PER_STEP * steps, about=about)
            self.mpr.planes_changed()
            return
        self.mpr.state.scroll(self.name, steps)
        self.mpr.planes_changed()

    def sizeHint(self) -> QSize:
        """Preferred size."""
        return QSize(400, 300)
