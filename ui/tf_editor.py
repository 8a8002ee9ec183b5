"""Transfer-function editor: histogram, opacity curve, control points, presets, files.

:class:`TransferFunctionEditor` edits an :class:`voxwarp.core.transfer_function.TransferFunction`
interactively and emits ``transferFunctionChanged`` with the new transfer function after
every user edit (also while a point is being dragged, so a live renderer follows).

The painted :class:`TransferFunctionCanvas` shows, over the *view range* (the union of
the transfer function's value range and the volume's data range):

* the histogram of the volume's values (log counts, grey; at most
  :data:`HISTOGRAM_MAX_SAMPLES` voxels, :data:`HISTOGRAM_BINS` bins),
* the opacity curve through the control points (x = value, y = opacity), the area
  under it tinted with the transfer function's colours, and each control point as a disc
  filled with its colour (the selected one ringed),
* below the plot, a colour bar of the transfer function over the same value axis.

Mouse and keys on the canvas
----------------------------
* left click on empty space: add a point there (colour interpolated from the transfer
  function at that value), which can be dragged right away;
* left drag on a point: move it; its value stays between its neighbours' values (and
  within the view range), its opacity within [0, 1];
* double click on a point: choose its colour (``QColorDialog``);
* right click on a point, or Delete/Backspace with a point selected: remove it, unless
  only two points are left.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
from PySide6.QtCore import QPointF, QRectF, QSize, Qt, Signal
from PySide6.QtGui import (
    QBrush,
    QColor,
    QImage,
    QKeyEvent,
    QLinearGradient,
    QMouseEvent,
    QPainter,
    QPainterPath,
    QPaintEvent,
    QPen,
    QPolygonF,
)
from PySide6.QtWidgets import (
    QColorDialog,
    QComboBox,
    QFileDialog,
    QHBoxLayout,
    QInputDialog,
    QLabel,
    QMessageBox,
    QPushButton,
    QSizePolicy,
    QVBoxLayout,
    QWidget,
)

from voxwarp.core.files import atomic_write_text
from voxwarp.core.transfer_function import (
    PRESETS,
    ControlPoint,
    TransferFunction,
    colormaps_available,
)
from voxwarp.core.volume import Volume
from voxwarp.errors import VoxwarpError

__all__ = [
    "HISTOGRAM_BINS",
    "HISTOGRAM_MAX_SAMPLES",
    "TransferFunctionCanvas",
    "TransferFunctionEditor",
    "value_histogram",
]

#: Number of histogram bins over the view range.
HISTOGRAM_BINS = 256
#: At most this many voxels (a regular stride through the array) feed the histogram.
HISTOGRAM_MAX_SAMPLES = 2_000_000
#: Entry of the preset combo box shown when the transfer function is not a preset.
CUSTOM_ENTRY = "custom"

_JSON_FILTER = "Transfer function JSON (*.json);;All files (*)"
#: Load accepts voxwarp's JSON, ParaView colour maps and Slicer volume properties.
_LOAD_FILTER = (
    "Transfer functions (*.json *.xml *.vp);;voxwarp or ParaView colour map JSON (*.json)"
    ";;3D Slicer presets.xml, .vp or .vp.json (*.xml *.vp *.json);;All files (*)"
)
#: matplotlib colour maps the preset combo offers after the presets (with matplotlib).
COLORMAP_ENTRIES = ("viridis", "magma", "inferno", "plasma", "cividis", "gray")


def preset_entries() -> list[str]:
    """The preset combo's names after ``custom``: the presets, then, when matplotlib is
    installed, :data:`COLORMAP_ENTRIES`."""
    return [*PRESETS, *(COLORMAP_ENTRIES if colormaps_available() else ())]


def value_histogram(
    volume: Volume,
    lo: float,
    hi: float,
    bins: int = HISTOGRAM_BINS,
    max_samples: int = HISTOGRAM_MAX_SAMPLES,
) -> tuple[np.ndarray, np.ndarray]:
    """Histogram of a volume's values over ``[lo, hi]`` from at most ``max_samples`` voxels.

    Parameters
    ----------
    volume
        The volume; its data is read in memory order with a regular stride (no copy).
    lo, hi
        Range of the bins, ``lo < hi``; values outside it (and NaN) are not counted.
    bins
        Number of bins.
    max_samples
        Upper bound on the number of voxels counted.

    Returns
    -------
    counts : numpy.ndarray
        ``(bins,)`` int64 counts.
    edges : numpy.ndarray
        ``(bins + 1,)`` bin edges from ``lo`` to ``hi``.
    """
    flat = volume.data.ravel(order="K")  # a view for the Fortran-ordered data
    step = max(1, -(-flat.size // max_samples))  # ceil division
    counts, edges = np.histogram(flat[::step], bins=bins, range=(float(lo), float(hi)))
    return counts.astype(np.int64), edges


def _view_range(tf: TransferFunction, volume: Volume | None) -> tuple[float, float]:
    """Union of the transfer function's value range and the volume's data range."""
    lo, hi = tf.value_range
    if volume is not None:
        dlo, dhi = volume.value_range
        lo, hi = min(lo, dlo), max(hi, dhi)
    if not hi > lo:
        hi = lo + 1.0
    return float(lo), float(hi)


def _qcolor(rgb: tuple[float, float, float] | np.ndarray, alpha: float = 1.0) -> QColor:
    r, g, b = (float(np.clip(c, 0.0, 1.0)) for c in rgb)
    return QColor.fromRgbF(r, g, b, float(np.clip(alpha, 0.0, 1.0)))


def _format_value(v: float) -> str:
    return f"{v:.4g}"


class TransferFunctionCanvas(QWidget):
    """The painted part of the editor: histogram, opacity curve, points, colour bar.

    It holds the transfer function being edited and emits :attr:`edited` with the new
    :class:`TransferFunction` after each mouse or key edit. Programmatic changes
    (:meth:`set_transfer_function`, :meth:`set_volume`) do not emit.

    Parameters
    ----------
    tf
        The initial transfer function.
    volume
        Volume whose histogram is drawn, or ``None`` for none.
    parent
        Parent widget.
    """

    #: The new transfer function after a user edit.
    edited = Signal(object)
    #: Index of the newly selected control point, or ``None``.
    selectionChanged = Signal(object)

    MARGIN_LEFT = 12
    MARGIN_RIGHT = 12
    MARGIN_TOP = 10
    BAR_GAP = 6
    BAR_HEIGHT = 16
    LABEL_HEIGHT = 18
    POINT_RADIUS = 5.0
    PICK_RADIUS = 8.0

    def __init__(
        self, tf: TransferFunction, volume: Volume | None = None, parent: QWidget | None = None
    ) -> None:
        super().__init__(parent)
        self._tf = tf
        self._volume = volume
        self._view = _view_range(tf, volume)
        self._hist: tuple[np.ndarray, np.ndarray] | None = None
        self._selected: int | None = None
        self._drag: int | None = None
        self._drag_offset = QPointF(0.0, 0.0)
        self.setMouseTracking(True)
        self.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
        self.setMinimumSize(260, 160)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self._update_histogram()

    # ------------------------------------------------------------------ state
    @property
    def transfer_function(self) -> TransferFunction:
        """The current transfer function."""
        return self._tf

    @property
    def volume(self) -> Volume | None:
        """The volume whose histogram is drawn."""
        return self._volume

    @property
    def view_range(self) -> tuple[float, float]:
        """``(lo, hi)`` data values at the left and right edges of the plot."""
        return self._view

    @property
    def histogram(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``(counts, edges)`` of the drawn histogram, or ``None`` without a volume."""
        return self._hist

    @property
    def selected(self) -> int | None:
        """Index of the selected control point, or ``None``."""
        return self._selected

    def set_transfer_function(self, tf: TransferFunction) -> None:
        """Show ``tf`` (recomputing the view range) without emitting :attr:`edited`."""
        self._tf = tf
        self._drag = None
        if self._selected is not None and self._selected >= len(tf.points):
            self._set_selected(None)
        self._refresh_view()

    def set_volume(self, volume: Volume | None) -> None:
        """Show the histogram of ``volume`` (``None``: no histogram); does not emit."""
        self._volume = volume
        self._refresh_view(force=True)

    def _refresh_view(self, force: bool = False) -> None:
        view = _view_range(self._tf, self._volume)
        if force or view != self._view:
            self._view = view
            self._update_histogram()
        self.update()

    def _update_histogram(self) -> None:
        if self._volume is None:
            self._hist = None
        else:
            self._hist = value_histogram(self._volume, *self._view)

    def _set_selected(self, index: int | None) -> None:
        if index != self._selected:
            self._selected = index
            self.selectionChanged.emit(index)
        self.update()

    def _commit(self, points: list[ControlPoint]) -> None:
        """Replace the points by an edit of the user: new transfer function, emit."""
        self._tf = TransferFunction(points, name=CUSTOM_ENTRY)
        self.update()
        self.edited.emit(self._tf)

    # ------------------------------------------------------------------ geometry
    def sizeHint(self) -> QSize:
        """Preferred size."""
        return QSize(520, 240)

    def plot_rect(self) -> QRectF:
        """Pixel rectangle of the opacity plot (opacity 1 at the top, 0 at the bottom)."""
        w = max(1.0, self.width() - self.MARGIN_LEFT - self.MARGIN_RIGHT)
        below = self.BAR_GAP + self.BAR_HEIGHT + self.LABEL_HEIGHT
        h = max(1.0, self.height() - self.MARGIN_TOP - below)
        return QRectF(self.MARGIN_LEFT, self.MARGIN_TOP, w, h)

    def bar_rect(self) -> QRectF:
        """Pixel rectangle of the colour bar below the plot."""
        plot = self.plot_rect()
        return QRectF(plot.left(), plot.bottom() + self.BAR_GAP, plot.width(), self.BAR_HEIGHT)

    def value_to_x(self, value: float) -> float:
        """Canvas x pixel of a data value."""
        lo, hi = self._view
        plot = self.plot_rect()
        return plot.left() + (value - lo) / (hi - lo) * plot.width()

    def x_to_value(self, x: float) -> float:
        """Data value at canvas x pixel (not clamped)."""
        lo, hi = self._view
        plot = self.plot_rect()
        return lo + (x - plot.left()) / plot.width() * (hi - lo)

    def opacity_to_y(self, opacity: float) -> float:
        """Canvas y pixel of an opacity."""
        plot = self.plot_rect()
        return plot.bottom() - opacity * plot.height()

    def y_to_opacity(self, y: float) -> float:
        """Opacity at canvas y pixel (not clamped)."""
        plot = self.plot_rect()
        return (plot.bottom() - y) / plot.height()

    def point_position(self, i: int) -> QPointF:
        """Canvas pixel of control point ``i``."""
        v, _r, _g, _b, a = self._tf.points[i]
        return QPointF(self.value_to_x(v), self.opacity_to_y(a))

    def point_at(self, pos: QPointF) -> int | None:
        """Index of the control point nearest to ``pos`` within the pick radius, or None."""
        best, best_d2 = None, self.PICK_RADIUS**2
        for i in range(len(self._tf.points)):
            d = self.point_position(i) - pos
            d2 = d.x() ** 2 + d.y() ** 2
            if d2 <= best_d2:
                best, best_d2 = i, d2
        return best

    # ------------------------------------------------------------------ editing
    def _move_point(self, i: int, pos: QPointF) -> None:
        points = list(self._tf.points)
        lo, hi = self._view
        vmin = points[i - 1][0] if i > 0 else lo
        vmax = points[i + 1][0] if i + 1 < len(points) else hi
        value = float(np.clip(self.x_to_value(pos.x()), vmin, vmax))
        opacity = float(np.clip(self.y_to_opacity(pos.y()), 0.0, 1.0))
        _v, r, g, b, _a = points[i]
        if (value, opacity) == (points[i][0], points[i][4]):
            return
        points[i] = (value, r, g, b, opacity)
        self._commit(points)

    def _add_point(self, pos: QPointF) -> int:
        lo, hi = self._view
        value = float(np.clip(self.x_to_value(pos.x()), lo, hi))
        opacity = float(np.clip(self.y_to_opacity(pos.y()), 0.0, 1.0))
        r, g, b, _a = (float(c) for c in np.clip(self._tf(value), 0.0, 1.0))
        points = list(self._tf.points)
        index = int(np.searchsorted([p[0] for p in points], value, side="right"))
        points.insert(index, (value, r, g, b, opacity))
        self._commit(points)
        return index

    def remove_point(self, i: int) -> bool:
        """Remove control point ``i`` as a user edit (emits); refused at two points.

        Returns
        -------
        bool
            Whether the point was removed.
        """
        points = list(self._tf.points)
        if len(points) <= 2 or not 0 <= i < len(points):
            return False
        del points[i]
        if self._selected is not None:
            if self._selected == i:
                self._set_selected(None)
            elif self._selected > i:
                self._set_selected(self._selected - 1)
        self._drag = None
        self._commit(points)
        return True

    def set_point_color(self, i: int, color: QColor) -> None:
        """Set the colour of control point ``i`` as a user edit (emits)."""
        points = list(self._tf.points)
        v, *_rgb, a = points[i]
        points[i] = (v, color.redF(), color.greenF(), color.blueF(), a)
        self._commit(points)

    # ------------------------------------------------------------------ events
    def mousePressEvent(self, event: QMouseEvent) -> None:
        """Select/drag a point, add a point (left) or remove one (right)."""
        pos = event.position()
        hit = self.point_at(pos)
        if event.button() == Qt.MouseButton.LeftButton:
            if hit is None:
                if not self.plot_rect().adjusted(-2, -2, 2, 2).contains(pos):
                    return
                hit = self._add_point(pos)
            self._set_selected(hit)
            self._drag = hit
            self._drag_offset = self.point_position(hit) - pos
        elif event.button() == Qt.MouseButton.RightButton and hit is not None:
            self.remove_point(hit)

    def mouseMoveEvent(self, event: QMouseEvent) -> None:
        """Drag the pressed point; otherwise show which point the mouse is over."""
        pos = event.position()
        if self._drag is not None:
            self._move_point(self._drag, pos + self._drag_offset)
            return
        over = self.point_at(pos) is not None
        self.setCursor(Qt.CursorShape.PointingHandCursor if over else Qt.CursorShape.CrossCursor)

    def mouseReleaseEvent(self, event: QMouseEvent) -> None:
        """End a drag."""
        if event.button() == Qt.MouseButton.LeftButton:
            self._drag = None

    def mouseDoubleClickEvent(self, event: QMouseEvent) -> None:
        """Choose the colour of the point under the mouse."""
        if event.button() != Qt.MouseButton.LeftButton:
            return
        hit = self.point_at(event.position())
        if hit is None:
            return
        self._drag = None
        self._set_selected(hit)
        _v, r, g, b, _a = self._tf.points[hit]
        color = QColorDialog.getColor(_qcolor((r, g, b)), self, "Control point colour")
        if color.isValid():
            self.set_point_color(hit, color)

    def keyPressEvent(self, event: QKeyEvent) -> None:
        """Delete/Backspace removes the selected point."""
        if event.key() in (Qt.Key.Key_Delete, Qt.Key.Key_Backspace):
            if self._selected is not None:
                self.remove_point(self._selected)
            event.accept()
            return
        super().keyPressEvent(event)

    # ------------------------------------------------------------------ painting
    def paintEvent(self, event: QPaintEvent) -> None:
        """Draw histogram, opacity curve, points, colour bar and value labels."""
        p = QPainter(self)
        p.setRenderHint(QPainter.RenderHint.Antialiasing)
        plot = self.plot_rect()
        p.fillRect(plot, QColor(30, 30, 30))
        self._paint_grid(p, plot)
        self._paint_histogram(p, plot)
        self._paint_curve(p, plot)
        self._paint_points(p)
        p.setPen(QPen(QColor(90, 90, 90), 1))
        p.setBrush(Qt.BrushStyle.NoBrush)
        p.drawRect(plot)
        self._paint_bar(p)
        self._paint_labels(p)
        p.end()

    def _paint_grid(self, p: QPainter, plot: QRectF) -> None:
        p.setPen(QPen(QColor(60, 60, 60), 1, Qt.PenStyle.DotLine))
        for a in (0.25, 0.5, 0.75):
            y = self.opacity_to_y(a)
            p.drawLine(QPointF(plot.left(), y), QPointF(plot.right(), y))

    def _paint_histogram(self, p: QPainter, plot: QRectF) -> None:
        if self._hist is None:
            return
        counts, edges = self._hist
        logc = np.log1p(counts.astype(np.float64))
        top = float(logc.max())
        if top <= 0:
            return
        heights = logc / top * plot.height()
        xs = [self.value_to_x(float(e)) for e in edges]
        poly = QPolygonF()
        poly.append(QPointF(xs[0], plot.bottom()))
        for i, h in enumerate(heights):
            y = plot.bottom() - float(h)
            poly.append(QPointF(xs[i], y))
            poly.append(QPointF(xs[i + 1], y))
        poly.append(QPointF(xs[-1], plot.bottom()))
        p.setPen(Qt.PenStyle.NoPen)
        p.setBrush(QColor(105, 105, 105))
        p.drawPolygon(poly)

    def _paint_curve(self, p: QPainter, plot: QRectF) -> None:
        pts = [self.point_position(i) for i in range(len(self._tf.points))]
        # tint the area under the curve with the transfer function's colours
        grad = QLinearGradient(plot.left(), 0.0, plot.right(), 0.0)
        for v, r, g, b, _a in self._tf.points:
            t = (self.value_to_x(v) - plot.left()) / plot.width()
            grad.setColorAt(float(np.clip(t, 0.0, 1.0)), _qcolor((r, g, b), 0.32))
        area = QPainterPath(QPointF(plot.left(), plot.bottom()))
        area.lineTo(QPointF(plot.left(), pts[0].y()))
        for q in pts:
            area.lineTo(q)
        area.lineTo(QPointF(plot.right(), pts[-1].y()))
        area.lineTo(QPointF(plot.right(), plot.bottom()))
        area.closeSubpath()
        p.setPen(Qt.PenStyle.NoPen)
        p.setBrush(QBrush(grad))
        p.drawPath(area)
        # the transfer function is constant outside its points: dotted extensions
        p.setBrush(Qt.BrushStyle.NoBrush)
        p.setPen(QPen(QColor(200, 200, 200), 1, Qt.PenStyle.DotLine))
        p.drawLine(QPointF(plot.left(), pts[0].y()), pts[0])
        p.drawLine(pts[-1], QPointF(plot.right(), pts[-1].y()))
        p.setPen(QPen(QColor(235, 235, 235), 1.5))
        p.drawPolyline(QPolygonF(pts))

    def _paint_points(self, p: QPainter) -> None:
        for i, (_v, r, g, b, _a) in enumerate(self._tf.points):
            c = self.point_position(i)
            if i == self._selected:
                p.setPen(QPen(QColor(255, 210, 0), 2.5))
                radius = self.POINT_RADIUS + 2
            else:
                p.setPen(QPen(QColor(240, 240, 240), 1.2))
                radius = self.POINT_RADIUS
            p.setBrush(_qcolor((r, g, b)))
            p.drawEllipse(c, radius, radius)

    def _paint_bar(self, p: QPainter) -> None:
        bar = self.bar_rect()
        n = max(2, int(bar.width()))
        xs = bar.left() + (np.arange(n) + 0.5) * bar.width() / n
        rgba = self._tf(np.array([self.x_to_value(float(x)) for x in xs]))
        img = np.empty((1, n, 4), dtype=np.uint8)
        img[0, :, :3] = np.round(np.clip(rgba[:, :3], 0.0, 1.0) * 255)
        img[0, :, 3] = 255
        buf = img.tobytes()  # kept alive while QImage refers to it
        qimg = QImage(buf, n, 1, 4 * n, QImage.Format.Format_RGBA8888)
        p.drawImage(bar, qimg)
        del qimg, buf
        p.setPen(QPen(QColor(90, 90, 90), 1))
        p.setBrush(Qt.BrushStyle.NoBrush)
        p.drawRect(bar)

    def _paint_labels(self, p: QPainter) -> None:
        bar = self.bar_rect()
        lo, hi = self._view
        p.setPen(self.palette().windowText().color())
        y0 = bar.bottom() + 1
        h = float(self.LABEL_HEIGHT)
        count = 5
        for k in range(count):
            v = lo + (hi - lo) * k / (count - 1)
            x = self.value_to_x(v)
            text = _format_value(v)
            if k == 0:
                rect = QRectF(x, y0, 120, h)
                align = Qt.AlignmentFlag.AlignLeft
            elif k == count - 1:
                rect = QRectF(x - 120, y0, 120, h)
                align = Qt.AlignmentFlag.AlignRight
            else:
                rect = QRectF(x - 60, y0, 120, h)
                align = Qt.AlignmentFlag.AlignHCenter
            p.drawText(rect, int(align | Qt.AlignmentFlag.AlignVCenter), text)


class TransferFunctionEditor(QWidget):
    """Interactive editor of a :class:`TransferFunction` (see the module docstring).

    Parameters
    ----------
    tf
        The initial transfer function.
    volume
        Volume whose value histogram is shown behind the curve (and against which
        presets are resolved), or ``None``.
    parent
        Parent widget.

    Attributes
    ----------
    canvas : TransferFunctionCanvas
        The painted plot that receives the mouse and key edits.
    preset_combo : QComboBox
        ``"custom"`` followed by :func:`preset_entries` (the presets, then a few
        matplotlib colour maps when matplotlib is installed).
    save_button, load_button : QPushButton
        Open a file dialog, then call :meth:`save_to` / :meth:`load_from`.
    """

    #: The new :class:`TransferFunction` after every user edit (also during drags).
    transferFunctionChanged = Signal(object)

    def __init__(
        self, tf: TransferFunction, volume: Volume | None = None, parent: QWidget | None = None
    ) -> None:
        super().__init__(parent)
        self._volume = volume
        self._last_dir = ""
        self.canvas = TransferFunctionCanvas(tf, volume, self)
        self.canvas.edited.connect(self._on_canvas_edited)
        self.canvas.selectionChanged.connect(lambda _i: self._update_readout())

        self.preset_combo = QComboBox(self)
        self.preset_combo.addItem(CUSTOM_ENTRY)
        self.preset_combo.addItems(preset_entries())
        self.preset_combo.setToolTip("Replace the transfer function by a preset")
        self.preset_combo.currentIndexChanged.connect(self._on_preset_index)
        self.save_button = QPushButton("Save…", self)
        self.save_button.setToolTip("Save the transfer function as JSON")
        self.save_button.clicked.connect(self._on_save_clicked)
        self.load_button = QPushButton("Load…", self)
        self.load_button.setToolTip(
            "Load a transfer function: voxwarp or ParaView JSON, Slicer presets.xml or .vp"
        )
        self.load_button.clicked.connect(self._on_load_clicked)
        self.readout = QLabel(self)
        self.message = QLabel(self)
        self.message.setWordWrap(True)
        self.message.setVisible(False)
        self.setToolTip(
            "Click: add point · drag: move · double click: colour · right click / Delete: remove"
        )

        row = QHBoxLayout()
        row.addWidget(QLabel("Preset:", self))
        row.addWidget(self.preset_combo, 1)
        row.addWidget(self.save_button)
        row.addWidget(self.load_button)
        layout = QVBoxLayout(self)
        layout.addWidget(self.canvas, 1)
        layout.addWidget(self.readout)
        layout.addLayout(row)
        layout.addWidget(self.message)
        self._sync_combo()
        self._update_readout()

    # ------------------------------------------------------------------ public API
    @property
    def transfer_function(self) -> TransferFunction:
        """The current transfer function."""
        return self.canvas.transfer_function

    def set_transfer_function(self, tf: TransferFunction) -> None:
        """Show ``tf`` without emitting :attr:`transferFunctionChanged`."""
        self.canvas.set_transfer_function(tf)
        self._sync_combo()
        self._update_readout()

    def set_volume(self, volume: Volume | None) -> None:
        """Use ``volume`` for the histogram and for resolving presets (does not emit)."""
        self._volume = volume
        self.canvas.set_volume(volume)

    def point_position(self, i: int) -> QPointF:
        """Canvas pixel (in :attr:`canvas` coordinates) of control point ``i``."""
        return self.canvas.point_position(i)

    def apply_preset(self, name: str) -> None:
        """Replace the transfer function by preset ``name`` resolved against the volume.

        This is a user edit: :attr:`transferFunctionChanged` is emitted. A warning of the
        preset (a Hounsfield preset rescaled onto a non-HU volume) is shown below the plot.
        """
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            tf = TransferFunction.preset(name, self._volume)
        self._show_message(" ".join(str(w.message) for w in caught))
        self._user_set(tf)

    def save_to(self, path: str | Path) -> bool:
        """Write the transfer function as JSON (``to_dict`` form) to ``path``, atomically.

        Errors are shown in a warning box, not raised.

        Returns
        -------
        bool
            Whether the file was written.
        """
        path = Path(path)
        text = json.dumps(self.transfer_function.to_dict(), indent=2) + "\n"
        try:
            atomic_write_text(path, text)
        except (OSError, VoxwarpError) as exc:
            message = f"Cannot save the transfer function to {path}:\n{exc}"
            QMessageBox.warning(self, "Save transfer function", message)
            return False
        return True

    def load_from(self, path: str | Path, name: str | None = None) -> bool:
        """Read a transfer function file and make it current (a user edit: emits).

        voxwarp JSON, ParaView colour-map JSON or a Slicer ``presets.xml`` / ``.vp`` (see
        :meth:`TransferFunction.load`), resolved against the editor's volume. A file with
        several maps asks which one (a list dialog) unless ``name`` is given. Errors
        (missing file, bad content, unknown name) are shown in a warning box, not raised,
        and leave the current transfer function unchanged; conversion notes are shown
        below the plot.

        Returns
        -------
        bool
            Whether a transfer function was loaded (False also when the choice is cancelled).
        """
        try:
            if name is None:
                names = TransferFunction.map_names(str(path))
                if len(names) > 1:
                    name, ok = QInputDialog.getItem(
                        self,
                        "Load transfer function",
                        f"{Path(path).name} holds several maps:",
                        names,
                        0,
                        False,
                    )
                    if not ok:
                        return False
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                tf = TransferFunction.load(str(path), self._volume, name=name)
        except (OSError, VoxwarpError) as exc:
            QMessageBox.warning(self, "Load transfer function", str(exc))
            return False
        self._show_message(" ".join(str(w.message) for w in caught))
        self._user_set(tf)
        return True

    # ------------------------------------------------------------------ internals
    def _user_set(self, tf: TransferFunction) -> None:
        self.canvas.set_transfer_function(tf)
        self._sync_combo()
        self._update_readout()
        self.transferFunctionChanged.emit(tf)

    def _on_canvas_edited(self, tf: TransferFunction) -> None:
        self._sync_combo()
        self._update_readout()
        self.transferFunctionChanged.emit(tf)

    def _on_preset_index(self, index: int) -> None:
        if index > 0:  # every entry after "custom" is a preset or colour-map name
            self.apply_preset(self.preset_combo.itemText(index))

    def _sync_combo(self) -> None:
        name = self.transfer_function.name
        index = self.preset_combo.findText(name)  # -1 (shown as custom) when not offered
        was = self.preset_combo.blockSignals(True)
        self.preset_combo.setCurrentIndex(max(0, index))
        self.preset_combo.blockSignals(was)

    def _update_readout(self) -> None:
        i = self.canvas.selected
        if i is None or i >= len(self.transfer_function.points):
            n = len(self.transfer_function.points)
            self.readout.setText(f"{n} points")
            return
        v, *_rgb, a = self.transfer_function.points[i]
        self.readout.setText(f"point {i + 1}: value {_format_value(v)}, opacity {a:.3f}")

    def _show_message(self, text: str) -> None:
        self.message.setText(text)
        self.message.setVisible(bool(text))

    def _on_save_clicked(self) -> None:
        path, _filter = QFileDialog.getSaveFileName(
            self, "Save transfer function", self._last_dir, _JSON_FILTER
        )
        if not path:
            return
        p = Path(path)
        if not p.suffix:
            p = p.with_suffix(".json")
        self._last_dir = str(p.parent)
        self.save_to(p)

    def _on_load_clicked(self) -> None:
        path, _filter = QFileDialog.getOpenFileName(
            self, "Load transfer function", self._last_dir, _LOAD_FILTER
        )
        if not path:
            return
        self._last_dir = str(Path(path).parent)
        self.load_from(path)
