"""A compact view of the deformation's internal fields as a 2D slice (Display dock).

Shows :func:`voxwarp.render.field_views.field_slice` of the session's model warp
(:meth:`voxwarp.editing.session.EditSession.model_warp`: the model in its grid frame, without a
placement's affine warps) or of an imported warp (a displacement field read with File ->
Add Displacement Field; :meth:`~voxwarp.editing.session.EditSession.field_view_warps`): a
view combo (the views of those warps, an imported one's named by its file), the slice normal,
a position slider and the image scaled to fit, with a title and a legend. The whole
thing folds away behind a "Show field slice" check box (folded, nothing is computed).

The widget talks to the window only through ``window.session`` (re-read every time:
opening a file replaces it). :meth:`FieldSliceView.refresh` recomputes only when the
warp (its ``id`` and ``revision``), the view, the axis or the position changed; while
shown, a timer calls it a few times a second, so the view follows a running simulation
and wire fields built off the GUI thread.
"""

from __future__ import annotations

import contextlib
from typing import Any

import numpy as np
from PySide6.QtCore import Qt, QTimer
from PySide6.QtGui import QImage, QPixmap, QResizeEvent
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QHBoxLayout,
    QLabel,
    QSizePolicy,
    QSlider,
    QVBoxLayout,
    QWidget,
)

from voxwarp.deform.warp import WarpError
from voxwarp.errors import VoxwarpError
from voxwarp.render import field_views

__all__ = ["FieldSliceView"]

#: pixels across the longer side of the computed image
IMAGE_PIXELS = 256
#: milliseconds between the refreshes of a shown view (cheap when nothing changed)
POLL_MS = 400
#: between a view and the file of an imported warp in the view combo
SEP = " · "
#: most height of the image on screen (px)
MAX_IMAGE_HEIGHT = 260


class _ImageLabel(QLabel):
    """A label that rescales its image when its width changes."""

    def __init__(self, owner: FieldSliceView) -> None:
        super().__init__()
        self._owner = owner

    def resizeEvent(self, event: QResizeEvent) -> None:
        """Fit the image to the new width."""
        super().resizeEvent(event)
        if event.size().width() != event.oldSize().width():
            self._owner._fit()


class FieldSliceView(QWidget):
    """The field slice view (see the module docstring).

    Parameters
    ----------
    window
        The main window (``window.session``: an :class:`~voxwarp.editing.session.EditSession`).
    parent
        Optional parent widget.

    Attributes
    ----------
    show_check : QCheckBox
        "Show field slice": unfolds the view.
    view_combo, axis_combo : QComboBox
        The view (:func:`voxwarp.render.field_views.views_for`) and the slice normal (x, y, z).
    slider : QSlider
        Position of the slice across the volume, 0..100 %.
    image_label, title_label, legend_label : QLabel
        The image and its texts.
    computations : int
        How many slices were computed (refreshes that changed something).
    """

    def __init__(self, window: Any, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._window = window
        self._key: tuple[Any, ...] | None = None
        self._warp: Any = None  # the keyed warp, held so that its id is not reused
        self._pixmap: QPixmap | None = None
        self.slice: field_views.FieldSlice | None = None
        self.computations = 0

        outer = QVBoxLayout(self)
        outer.setContentsMargins(0, 0, 0, 0)
        outer.setSpacing(2)
        self.show_check = QCheckBox("Show field slice")
        self.show_check.setToolTip(
            "Show the deformation's internal fields (attribute field, masks, offsets,"
            " displacement) on a slice through the volume"
        )
        outer.addWidget(self.show_check)

        self.body = QWidget()
        lay = QVBoxLayout(self.body)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.setSpacing(2)
        row = QHBoxLayout()
        self.view_combo = QComboBox()
        self.view_combo.setToolTip("Which field to show")
        self.view_combo.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Fixed)
        self.view_combo.setMinimumContentsLength(8)
        self.view_combo.setSizeAdjustPolicy(
            QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon
        )
        self.axis_combo = QComboBox()
        self.axis_combo.addItems(list(field_views.AXES))
        self.axis_combo.setCurrentIndex(2)
        self.axis_combo.setToolTip("Slice normal")
        row.addWidget(self.view_combo, 1)
        row.addWidget(QLabel("normal"))
        row.addWidget(self.axis_combo)
        lay.addLayout(row)

        row = QHBoxLayout()
        self.slider = QSlider(Qt.Orientation.Horizontal)
        self.slider.setRange(0, 100)
        self.slider.setValue(50)
        self.slider.setToolTip("Position of the slice across the volume")
        self.position_label = QLabel("50 %")
        self.position_label.setMinimumWidth(
            self.position_label.fontMetrics().horizontalAdvance("100 %")
        )
        row.addWidget(self.slider, 1)
        row.addWidget(self.position_label)
        lay.addLayout(row)

        top_left = Qt.AlignmentFlag.AlignLeft | Qt.AlignmentFlag.AlignTop
        self.title_label = QLabel()
        self.title_label.setWordWrap(True)
        self.title_label.setAlignment(top_left)
        lay.addWidget(self.title_label)
        self.image_label = _ImageLabel(self)
        self.image_label.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.image_label.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Fixed)
        self.image_label.setMinimumHeight(60)
        lay.addWidget(self.image_label)
        self.legend_label = QLabel()
        self.legend_label.setWordWrap(True)
        self.legend_label.setAlignment(top_left)
        small = self.legend_label.font()
        small.setPointSizeF(max(small.pointSizeF() * 0.9, 6.0))
        self.legend_label.setFont(small)
        lay.addWidget(self.legend_label)
        outer.addWidget(self.body)
        self.body.setVisible(False)

        self._timer = QTimer(self)
        self._timer.setInterval(POLL_MS)
        self._timer.timeout.connect(self._poll)

        self.show_check.toggled.connect(self._show_toggled)
        self.view_combo.currentIndexChanged.connect(lambda _i: self.refresh())
        self.axis_combo.currentIndexChanged.connect(lambda _i: self.refresh())
        self.slider.valueChanged.connect(self._slider_moved)

    # ------------------------------------------------------------------ state
    @property
    def fraction(self) -> float:
        """The slider's position as a fraction of the volume (0..1)."""
        return self.slider.value() / 100.0

    def _show_toggled(self, on: bool) -> None:
        self.body.setVisible(on)
        if on:
            self._timer.start()
            self.refresh()
        else:
            self._timer.stop()

    def _slider_moved(self, value: int) -> None:
        self.position_label.setText(f"{value} %")
        self.refresh()

    def _poll(self) -> None:
        # not during a drag: a GPU model's field would be read back while interacting
        if self.isVisible() and not self._window.session.dragging:
            self.refresh()

    def _entries(self, session: Any) -> list[tuple[str, Any, str]]:
        """``(combo text, warp, view)`` of every view of the session's warps."""
        out = []
        for label, warp in session.field_view_warps():
            for view in field_views.views_for(warp):
                out.append((view if label == "model" else f"{view}{SEP}{label}", warp, view))
        return out

    def select(self, text: str) -> bool:
        """Show the combo entry ``text`` (e.g. ``"field |u| · u.nii.gz"``); False if absent."""
        self._set_views(tuple(t for t, _, _ in self._entries(self._window.session)))
        index = self.view_combo.findText(text)
        if index >= 0:
            self.view_combo.setCurrentIndex(index)
        return index >= 0

    def _set_views(self, views: tuple[str, ...]) -> None:
        """Fill the view combo with ``views`` when they changed (another kind of
        deformation: its first, most specific view is selected; only imported warps
        changed: the current view stays selected if still offered)."""
        current = [self.view_combo.itemText(i) for i in range(self.view_combo.count())]
        if tuple(current) == views and self.view_combo.isEnabled() == bool(views):
            return
        model_views = [v for v in views if SEP not in v]
        same_model = model_views == [v for v in current if SEP not in v]
        selected = self.view_combo.currentText() if same_model else ""
        self.view_combo.blockSignals(True)
        try:
            self.view_combo.clear()
            if views:
                self.view_combo.addItems(list(views))
                self.view_combo.setCurrentIndex(max(0, self.view_combo.findText(selected)))
            else:
                self.view_combo.addItem("no deformation")
            self.view_combo.setEnabled(bool(views))
        finally:
            self.view_combo.blockSignals(False)

    # ------------------------------------------------------------------ refresh
    def refresh(self) -> None:
        """Recompute the slice if the warp, view, axis or position changed (folded:
        nothing)."""
        if not self.show_check.isChecked():
            return
        session = self._window.session
        entries = self._entries(session)
        self._set_views(tuple(text for text, _, _ in entries))
        if not entries:
            self._key, self._warp, self.slice = None, None, None
            kind = getattr(session, "kind", "none")
            # a wire field is built off the GUI thread: the session has no warp meanwhile
            self._show(None, "no deformation" if kind == "none" else f"no {kind} field yet", "")
            return
        _, warp, view = entries[max(0, self.view_combo.currentIndex())]
        axis = self.axis_combo.currentIndex()
        fraction = self.fraction
        key = (
            id(warp),
            getattr(warp, "revision", None),
            id(session.volume),
            view,
            axis,
            fraction,
        )
        if key == self._key and warp is self._warp:
            return
        self._key, self._warp = key, warp
        self.computations += 1
        gpu = bool(getattr(warp, "gpu_owned", False))
        scope = session.gl_scope() if gpu else contextlib.nullcontext()
        try:
            with scope:
                fs = field_views.field_slice(
                    warp, session.volume, view, axis, fraction, IMAGE_PIXELS, ctx=session.ctx
                )
        except (VoxwarpError, WarpError) as exc:
            self.slice = None
            self._show(None, str(exc), "")
            return
        self.slice = fs
        self._show(fs.image, fs.title, fs.legend)

    def _show(self, image: np.ndarray | None, title: str, legend: str) -> None:
        self.title_label.setText(title)
        self.legend_label.setText(legend)
        if image is None:
            self._pixmap = None
            self.image_label.clear()
            self.image_label.setFixedHeight(60)
            return
        h, w = image.shape[:2]
        data = np.ascontiguousarray(image, dtype=np.uint8)
        qimage = QImage(data.data, w, h, 3 * w, QImage.Format.Format_RGB888).copy()
        self._pixmap = QPixmap.fromImage(qimage)
        self._fit()

    def _fit(self) -> None:
        """Scale the image to the label's width (aspect kept, nearest neighbour)."""
        if self._pixmap is None or self._pixmap.isNull():
            return
        width = max(self.image_label.width(), 40)
        scaled = self._pixmap.scaled(
            width,
            MAX_IMAGE_HEIGHT,
            Qt.AspectRatioMode.KeepAspectRatio,
            Qt.TransformationMode.FastTransformation,
        )
        self.image_label.setFixedHeight(max(scaled.height(), 1))
        self.image_label.setPixmap(scaled)
