"""Dock panels of the main window: volume look, deformation, display toggles, scene tree.

Every panel is a plain :class:`QWidget` built as ``Panel(window)`` and placed by the
window in a :class:`QDockWidget`. The panels talk to the window only through this
contract (see ``ui/main_window.py``)::

    window.session: EditSession            # replaced when a file is opened
    window.viewport.display: DisplayOptions
    window.viewport.update() -> None       # redraw
    window.edit(text, fn, merge=None)      # fn() as one undoable edit
    window.scene_changed() -> None         # the scene's look changed
    window.request_wire_build() -> None    # rebuild the wire field off the GUI thread
    window.set_running(running) -> None
    window.open_file_dialog() -> None

Edits
-----
Every change of the session or of the scene runs inside ``window.edit`` (one undo step;
spin boxes pass a ``merge`` key so that a run of changes of one value is one undo step).
The window shows errors of an edit in a dialog and returns ``None``; the panels never
catch them. Only :class:`DisplayPanel` changes things directly: what the viewport draws
over the volume is not part of the document.

Refresh
-------
``panel.refresh()`` re-reads ``window.session`` (which may be a new object after a file
was opened) into the widgets. It never makes an edit: the widgets' signal handlers return
at once while a refresh runs (the panel's ``_updating`` flag). The window calls it after
every edit, undo, redo and open.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
from PySide6.QtCore import QSize, Qt, QTimer
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QDoubleSpinBox,
    QFormLayout,
    QFrame,
    QGridLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QScrollArea,
    QSizePolicy,
    QSpinBox,
    QTreeWidget,
    QTreeWidgetItem,
    QVBoxLayout,
    QWidget,
)

from voxwarp.core.camera import PROJECTIONS
from voxwarp.editing.session import (
    BACKENDS,
    CHAINMAIL_VARIANTS,
    DEFORMATIONS,
    INTEGRATORS,
    WIRE_KINDS,
    DisplayOptions,
    EditorError,
    EditSession,
    Placement,
)
from voxwarp.scene import MODES

__all__ = [
    "DISPLAY_LABELS",
    "FIELD_SCALES",
    "SHADING_CHOICES",
    "DeformationPanel",
    "DisplayPanel",
    "ScenePanel",
    "VolumePanel",
    "wire_of_handle",
]

#: Entries of the shading combo box and the ``Scene.shading`` value of each.
SHADING_CHOICES: tuple[tuple[str, bool | None], ...] = (
    ("auto", None),
    ("on", True),
    ("off", False),
)
#: Per-axis reductions of the wire attribute field offered (``wire_settings["field_scale"]``).
FIELD_SCALES: tuple[int, ...] = (1, 2, 4, 8, 16)
#: Check box labels of the :class:`~voxwarp.editing.session.DisplayOptions` fields (others: field
#: name).
DISPLAY_LABELS: dict[str, str] = {
    "volume": "Volume",
    "elements": "Elements",
    "links": "Links between elements",
    "fixed": "Fixed elements",
    "wires_base": "Base wires",
    "wires_modified": "Modified wires",
    "lattice_cells": "Lattice cells",
    "grid_box": "Deformation grid box",
    "clip_box": "Clipping box",
}
#: Human names of the deformation families (model combo box and edit names).
DEFORMATION_LABELS: dict[str, str] = {
    "none": "none",
    "massspring": "mass-spring",
    "chainmail": "ChainMail",
    "wires": "wires",
    "lattice": "lattice",
}
AXES = ("x", "y", "z")


# ---------------------------------------------------------------------------- helpers
def _double_spin(
    lo: float,
    hi: float,
    step: float,
    decimals: int = 2,
    suffix: str = "",
    tooltip: str = "",
) -> QDoubleSpinBox:
    """A compact double spin box that reports a value only when typing is finished."""
    spin = QDoubleSpinBox()
    spin.setRange(lo, hi)
    spin.setDecimals(decimals)
    spin.setSingleStep(step)
    spin.setSuffix(suffix)
    spin.setKeyboardTracking(False)
    spin.setAccelerated(True)
    spin.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Fixed)
    spin.setMinimumWidth(40)
    if tooltip:
        spin.setToolTip(tooltip)
    return spin


def _int_spin(lo: int, hi: int, tooltip: str = "") -> QSpinBox:
    spin = QSpinBox()
    spin.setRange(lo, hi)
    spin.setKeyboardTracking(False)
    if tooltip:
        spin.setToolTip(tooltip)
    return spin


def _combo(items: tuple[str, ...] | list[str], tooltip: str = "") -> QComboBox:
    combo = QComboBox()
    combo.addItems(list(items))
    if tooltip:
        combo.setToolTip(tooltip)
    return combo


def _set_combo_data(combo: QComboBox, value: Any) -> None:
    """Select the entry whose item data equals ``value`` (no change when none does)."""
    for i in range(combo.count()):
        if combo.itemData(i) == value:
            combo.setCurrentIndex(i)
            return


def _value_decimals(span: float) -> int:
    """Decimals that show about three significant digits of a value range ``span``."""
    if not math.isfinite(span) or span <= 0:
        return 3
    return int(np.clip(3 - math.floor(math.log10(span)), 0, 6))


def wire_of_handle(session: EditSession, handle: int | None) -> tuple[int, int] | None:
    """``(wire, control point)`` of a handle index of the wires deformation, or None.

    Parameters
    ----------
    session
        The session (its ``wires``; handles are the modified wires' control points in
        order).
    handle
        A handle index (e.g. ``session.reference``) or None.

    Returns
    -------
    tuple of int or None
        The wire's index and the control point's index in it; None when ``handle`` is
        None or not a wire control point.
    """
    if handle is None or handle < 0:
        return None
    index = int(handle)
    for w, wire in enumerate(session.wires):
        n = len(wire.modified.control_points)
        if index < n:
            return w, index
        index -= n
    return None


class _Panel(QWidget):
    """Common plumbing: the window, the session, the refresh guard, edits."""

    def __init__(self, window: Any, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._window = window
        self._updating = False
        self._body: QWidget | None = None
        self._scroll: QScrollArea | None = None

    def _scrolling_body(self) -> QWidget:
        """The widget to put the panel's content in: it scrolls vertically, so that a
        dock can be shorter than the content (the main window's height stays free)."""
        outer = QVBoxLayout(self)
        outer.setContentsMargins(0, 0, 0, 0)
        self._scroll = QScrollArea()
        self._scroll.setWidgetResizable(True)
        self._scroll.setFrameShape(QFrame.Shape.NoFrame)
        self._scroll.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        self._body = QWidget()
        self._scroll.setWidget(self._body)
        outer.addWidget(self._scroll)
        return self._body

    def _scrollbar_width(self) -> int:
        assert self._scroll is not None
        return self._scroll.verticalScrollBar().sizeHint().width()

    def sizeHint(self) -> QSize:
        """The content's size (plus room for the scroll bar)."""
        if self._body is None:
            return super().sizeHint()
        hint = self._body.sizeHint()
        return QSize(hint.width() + self._scrollbar_width(), hint.height())

    def minimumSizeHint(self) -> QSize:
        """The content's width (never cut off sideways), a short height (it scrolls)."""
        if self._body is None:
            return super().minimumSizeHint()
        hint = self._body.minimumSizeHint()
        return QSize(hint.width() + self._scrollbar_width(), min(hint.height(), 120))

    @property
    def session(self) -> EditSession:
        """The window's current session (re-read every time: opening a file replaces it)."""
        return self._window.session

    @contextmanager
    def _refreshing(self) -> Iterator[None]:
        """Widget changes made inside do not trigger edits."""
        previous, self._updating = self._updating, True
        try:
            yield
        finally:
            self._updating = previous

    def _edit(self, text: str, fn: Callable[[], Any], merge: str | None = None) -> Any:
        return self._window.edit(text, fn, merge=merge)

    def _edit_look(self, text: str, name: str, value: Any, merge: str | None = None) -> None:
        """Set ``session.scene.<name>`` as an edit, then tell the window the look changed."""
        if self._updating:
            return

        def fn() -> bool:
            setattr(self.session.scene, name, value)
            return True

        if self._edit(text, fn, merge) is not None:
            self._window.scene_changed()


# ---------------------------------------------------------------------------- volume
class VolumePanel(_Panel):
    """The volume and how it is rendered: mode, projection, sampling, window, clipping.

    Parameters
    ----------
    window
        The main window (see the module docstring for what the panel uses of it).
    parent
        Optional parent widget.
    """

    def __init__(self, window: Any, parent: QWidget | None = None) -> None:
        super().__init__(window, parent)
        layout = QVBoxLayout(self._scrolling_body())
        layout.setContentsMargins(4, 4, 4, 4)

        # volume info + open
        top = QHBoxLayout()
        self.info_label = QLabel()
        self.info_label.setWordWrap(True)
        self.info_label.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.open_button = QPushButton("Open…")
        self.open_button.setToolTip("Open a volume or a scene file")
        self.open_button.clicked.connect(self._open)
        top.addWidget(self.info_label, 1)
        top.addWidget(self.open_button, 0, Qt.AlignmentFlag.AlignTop)
        layout.addLayout(top)

        # rendering
        render_box = QGroupBox("Rendering")
        form = QFormLayout(render_box)
        form.setFieldGrowthPolicy(QFormLayout.FieldGrowthPolicy.AllNonFixedFieldsGrow)
        self.mode_combo = _combo(
            MODES,
            "dvr: emission-absorption; mip/minip: maximum/minimum intensity; average:"
            " X-ray like; flm: first local maximum; iso: shaded isosurface",
        )
        self.mode_combo.currentTextChanged.connect(self._mode_changed)
        form.addRow("Mode", self.mode_combo)
        self.projection_combo = _combo(PROJECTIONS)
        self.projection_combo.currentTextChanged.connect(self._projection_changed)
        form.addRow("Projection", self.projection_combo)
        self.step_spin = _double_spin(
            0.1,
            8.0,
            0.1,
            2,
            " vx",
            "Sample distance along the rays, in voxels of the"
            " smallest spacing (smaller: finer and slower)",
        )
        self.step_spin.valueChanged.connect(self._step_changed)
        form.addRow("Sample distance", self.step_spin)
        self.level_spin = _double_spin(-1e9, 1e9, 1.0, 3, tooltip="Window centre (data units)")
        self.level_spin.valueChanged.connect(self._window_changed)
        form.addRow("Window level", self.level_spin)
        self.width_spin = _double_spin(1e-6, 1e9, 1.0, 3, tooltip="Window width (data units)")
        self.width_spin.valueChanged.connect(self._window_changed)
        form.addRow("Window width", self.width_spin)
        self.shading_combo = QComboBox()
        for label, value in SHADING_CHOICES:
            self.shading_combo.addItem(label, value)
        self.shading_combo.setToolTip(
            "Blinn-Phong shading from gradients; auto: on for iso and flm, off otherwise"
        )
        self.shading_combo.currentIndexChanged.connect(self._shading_changed)
        form.addRow("Shading", self.shading_combo)
        self.jitter_check = QCheckBox("Jitter ray starts")
        self.jitter_check.setToolTip("Jitter the ray starts per pixel against wood-grain rings")
        self.jitter_check.toggled.connect(self._jitter_changed)
        form.addRow(self.jitter_check)
        layout.addWidget(render_box)

        # clipping box
        clip_box = QGroupBox("Clipping")
        grid = QGridLayout(clip_box)
        grid.setColumnStretch(1, 1)
        grid.setColumnStretch(2, 1)
        self.clip_check = QCheckBox("Clip")
        self.clip_check.setToolTip("Cut the rays to a box (deformed world, mm)")
        self.clip_check.toggled.connect(self._clip_toggled)
        grid.addWidget(self.clip_check, 0, 0, 1, 3)
        self.clip_spins: list[tuple[QDoubleSpinBox, QDoubleSpinBox]] = []
        for a, axis in enumerate(AXES):
            lo = _double_spin(-1e6, 1e6, 1.0, 2, " mm", f"Low {axis} of the clipping box")
            hi = _double_spin(-1e6, 1e6, 1.0, 2, " mm", f"High {axis} of the clipping box")
            lo.valueChanged.connect(lambda _v, a=a: self._clip_changed(a, 0))
            hi.valueChanged.connect(lambda _v, a=a: self._clip_changed(a, 1))
            grid.addWidget(QLabel(axis), a + 1, 0)
            grid.addWidget(lo, a + 1, 1)
            grid.addWidget(hi, a + 1, 2)
            self.clip_spins.append((lo, hi))
        layout.addWidget(clip_box)
        layout.addStretch(1)
        self.refresh()

    # ------------------------------------------------------------------ refresh
    def refresh(self) -> None:
        """Show the current session's volume and scene look (makes no edit)."""
        scene = self.session.scene
        vol = scene.volume
        with self._refreshing():
            shape = " × ".join(str(n) for n in vol.shape)
            spacing = " × ".join(f"{s:g}" for s in vol.spacing)
            self.info_label.setText(f"<b>{vol.name}</b><br>{shape} voxels<br>{spacing} mm")
            self.info_label.setToolTip(str(vol.source or "in memory"))
            self.mode_combo.setCurrentText(scene.mode)
            self.projection_combo.setCurrentText(scene.projection)
            self.step_spin.setValue(scene.step)
            vlo, vhi = vol.value_range
            span = max(vhi - vlo, scene.window[1], 1e-6)
            decimals = _value_decimals(span)
            step = max(span / 100.0, 10.0**-decimals)
            for spin in (self.level_spin, self.width_spin):
                spin.setDecimals(decimals)
                spin.setSingleStep(step)
            level, width = scene.window
            # ranges around the data (compact spin boxes), wide enough for the window
            reach = 10.0 * span
            self.level_spin.setRange(min(vlo - reach, level), max(vhi + reach, level))
            self.width_spin.setRange(10.0**-decimals, max(2.0 * reach, width))
            self.level_spin.setValue(level)
            self.width_spin.setValue(width)
            _set_combo_data(self.shading_combo, scene.shading)
            self.jitter_check.setChecked(scene.jitter)
            lo, hi = (np.asarray(b, dtype=np.float64) for b in vol.bounds)
            box = scene.clip_box
            self.clip_check.setChecked(box is not None)
            for a, (lo_spin, hi_spin) in enumerate(self.clip_spins):
                r0, r1 = float(lo[a]), float(hi[a])
                if box is not None:
                    r0, r1 = min(r0, box[0][a]), max(r1, box[1][a])
                step = max((r1 - r0) / 50.0, 0.01)
                for spin in (lo_spin, hi_spin):
                    spin.setRange(r0, r1)
                    spin.setSingleStep(step)
                    spin.setEnabled(box is not None)
                lo_spin.setValue(box[0][a] if box is not None else r0)
                hi_spin.setValue(box[1][a] if box is not None else r1)

    # ------------------------------------------------------------------ handlers
    def _open(self) -> None:
        self._window.open_file_dialog()

    def _mode_changed(self, mode: str) -> None:
        self._edit_look(f"Mode {mode}", "mode", mode)

    def _projection_changed(self, projection: str) -> None:
        self._edit_look(f"Projection {projection}", "projection", projection)

    def _step_changed(self, value: float) -> None:
        self._edit_look("Sample distance", "step", float(value), merge="sample distance")

    def _window_changed(self, _value: float) -> None:
        window = (float(self.level_spin.value()), float(self.width_spin.value()))
        self._edit_look("Window", "window", window, merge="window")

    def _shading_changed(self, _index: int) -> None:
        value = self.shading_combo.currentData()
        self._edit_look(f"Shading {self.shading_combo.currentText()}", "shading", value)

    def _jitter_changed(self, on: bool) -> None:
        self._edit_look("Jitter on" if on else "Jitter off", "jitter", bool(on))

    def _spin_box(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        lo = tuple(float(s[0].value()) for s in self.clip_spins)
        hi = tuple(float(s[1].value()) for s in self.clip_spins)
        return lo, hi

    def _clip_toggled(self, on: bool) -> None:
        if self._updating:
            return
        for pair in self.clip_spins:
            for spin in pair:
                spin.setEnabled(on)
        self._edit_look(
            "Clip on" if on else "Clip off", "clip_box", self._spin_box() if on else None
        )

    def _clip_changed(self, axis: int, side: int) -> None:
        if self._updating or not self.clip_check.isChecked():
            return
        lo_spin, hi_spin = self.clip_spins[axis]
        if lo_spin.value() >= hi_spin.value():
            # keep the box non-empty: the other side wins, this one stops just short of it
            with self._refreshing():
                gap = lo_spin.singleStep()
                if side == 0:
                    lo_spin.setValue(hi_spin.value() - gap)
                else:
                    hi_spin.setValue(lo_spin.value() + gap)
            if lo_spin.value() >= hi_spin.value():
                return
        self._edit_look("Clipping box", "clip_box", self._spin_box(), merge="clip box")


# ---------------------------------------------------------------------------- deformation
class DeformationPanel(_Panel):
    """The deformation model, its simulation, wires and placement, and timings.

    Parameters
    ----------
    window
        The main window (see the module docstring for what the panel uses of it; the
        wire toggle also sets ``window.viewport.laying_wire``).
    parent
        Optional parent widget.
    """

    def __init__(self, window: Any, parent: QWidget | None = None) -> None:
        super().__init__(window, parent)
        self._fraction_cache: tuple[Any, ...] | None = None
        self._fraction: float | None = None
        self._timings_text = ""
        self._beta_volume: Any = None
        layout = QVBoxLayout(self._scrolling_body())
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addWidget(self._build_model_group())
        layout.addWidget(self._build_simulation_group())
        layout.addWidget(self._build_wire_group())
        layout.addWidget(self._build_placement_group())
        self.timings_label = QLabel()
        self.timings_label.setWordWrap(True)
        self.timings_label.setToolTip(
            "step: one model step (mass-spring) or relaxation step (ChainMail); field: the"
            " last wire-field build; frame: the last frame drawn"
        )
        layout.addWidget(self.timings_label)
        layout.addStretch(1)
        self.refresh()
        self.refresh_timings(None)

    # ------------------------------------------------------------------ building
    def _build_model_group(self) -> QGroupBox:
        box = QGroupBox("Model")
        form = QFormLayout(box)
        form.setFieldGrowthPolicy(QFormLayout.FieldGrowthPolicy.AllNonFixedFieldsGrow)
        self.model_form = form
        self.model_combo = QComboBox()
        for kind in DEFORMATIONS:
            self.model_combo.addItem(DEFORMATION_LABELS.get(kind, kind), kind)
        self.model_combo.setToolTip("Deformation family (choosing one builds it at rest)")
        self.model_combo.currentIndexChanged.connect(self._model_changed)
        form.addRow("Model", self.model_combo)
        self.backend_combo = _combo(BACKENDS, "Where mass-spring and ChainMail run")
        form.addRow("Backend", self.backend_combo)
        self.resolution_spin = _int_spin(
            2,
            32,
            "Elements per axis (mass-spring, ChainMail); lattice: cells + 1 per axis"
            " (at most 8 cells)",
        )
        form.addRow("Resolution", self.resolution_spin)
        self.integrator_combo = _combo(INTEGRATORS, "Mass-spring time integration")
        form.addRow("Integrator", self.integrator_combo)
        self.variant_combo = _combo(CHAINMAIL_VARIANTS, "ChainMail variant")
        form.addRow("Variant", self.variant_combo)
        self.stiffness_spin = _double_spin(
            0.01, 1.0, 0.05, 2, tooltip="Element stiffness of new models (0..1]"
        )
        form.addRow("Stiffness", self.stiffness_spin)
        row = QHBoxLayout()
        self.apply_button = QPushButton("Apply")
        self.apply_button.setToolTip("Build a new model at rest with these settings")
        self.apply_button.clicked.connect(self._apply)
        self.reset_button = QPushButton("Reset")
        self.reset_button.setToolTip(
            "Back to rest: elements released, wires straightened, lattice undeformed"
        )
        self.reset_button.clicked.connect(self._reset)
        row.addWidget(self.apply_button)
        row.addWidget(self.reset_button)
        form.addRow(row)
        return box

    def _build_simulation_group(self) -> QGroupBox:
        self.simulation_group = QGroupBox("Simulation")
        form = QFormLayout(self.simulation_group)
        form.setFieldGrowthPolicy(QFormLayout.FieldGrowthPolicy.AllNonFixedFieldsGrow)
        self.simulation_form = form
        row = QHBoxLayout()
        self.run_button = QPushButton("Pause")
        self.run_button.setCheckable(True)
        self.run_button.setToolTip("Run or pause the simulation")
        self.run_button.toggled.connect(self._run_toggled)
        self.step_button = QPushButton("Step")
        self.step_button.setToolTip("One step of the model, also while paused")
        self.step_button.clicked.connect(self._single_step)
        row.addWidget(self.run_button)
        row.addWidget(self.step_button)
        form.addRow(row)
        self.steps_spin = _int_spin(0, 1000, "Mass-spring steps per frame while running")
        self.steps_spin.valueChanged.connect(
            lambda v: self._option_changed(
                "steps_per_frame", "Steps per frame", "steps per frame", v
            )
        )
        form.addRow("Steps per frame", self.steps_spin)
        self.relax_spin = _int_spin(0, 16, "ChainMail relaxation steps per frame while running")
        self.relax_spin.valueChanged.connect(
            lambda v: self._option_changed("relax_steps", "Relaxation steps", "relax steps", v)
        )
        form.addRow("Relax steps", self.relax_spin)
        row = QHBoxLayout()
        self.fix_button = QPushButton("Fix selected")
        self.fix_button.setToolTip("The selected elements stay where they are")
        self.fix_button.clicked.connect(lambda: self._set_fixed(True))
        self.free_button = QPushButton("Free selected")
        self.free_button.setToolTip("The selected elements move again")
        self.free_button.clicked.connect(lambda: self._set_fixed(False))
        row.addWidget(self.fix_button)
        row.addWidget(self.free_button)
        form.addRow(row)
        return self.simulation_group

    def _build_wire_group(self) -> QGroupBox:
        self.wire_group = QGroupBox("Wires")
        form = QFormLayout(self.wire_group)
        form.setFieldGrowthPolicy(QFormLayout.FieldGrowthPolicy.AllNonFixedFieldsGrow)
        self.wire_label = QLabel()
        self.wire_label.setWordWrap(True)
        form.addRow(self.wire_label)
        self.wire_kind_combo = _combo(
            WIRE_KINDS, "Curve of the selected wire (and of the next wire laid)"
        )
        self.wire_kind_combo.currentTextChanged.connect(self._wire_kind_changed)
        form.addRow("Curve", self.wire_kind_combo)
        self.radius_spin = _double_spin(
            0.01,
            1e5,
            1.0,
            2,
            " mm",
            "Region of influence of the selected wire (and of the next wire laid)",
        )
        self.radius_spin.valueChanged.connect(self._radius_changed)
        form.addRow("Radius", self.radius_spin)
        self.beta_check = QCheckBox("Object classification")
        self.beta_check.setToolTip(
            "β: only voxels with values in [low, high] follow the selected wire;"
            " unchecked: everything within the radius"
        )
        self.beta_check.toggled.connect(self._beta_toggled)
        form.addRow(self.beta_check)
        row = QHBoxLayout()
        self.beta_lo_spin = _double_spin(-1e9, 1e9, 1.0, 3, tooltip="Lowest value of the object")
        self.beta_hi_spin = _double_spin(-1e9, 1e9, 1.0, 3, tooltip="Highest value of the object")
        self.beta_lo_spin.valueChanged.connect(self._beta_range_changed)
        self.beta_hi_spin.valueChanged.connect(self._beta_range_changed)
        row.addWidget(self.beta_lo_spin)
        row.addWidget(QLabel("–"))
        row.addWidget(self.beta_hi_spin)
        form.addRow("β range", row)
        self.twist_spin = _double_spin(
            -720.0, 720.0, 5.0, 1, "°", "Twist about the wire at the reference control point"
        )
        form.addRow("Twist", self.twist_spin)
        self.scale_spin = _double_spin(
            0.05, 20.0, 0.05, 2, tooltip="Cross-section scale at the reference control point"
        )
        form.addRow("Scale", self.scale_spin)
        self.set_key_button = QPushButton("Set at point")
        self.set_key_button.setToolTip(
            "Key this twist and scale at the reference control point (select one first)"
        )
        self.set_key_button.clicked.connect(self._set_wire_key)
        form.addRow(self.set_key_button)
        self.field_scale_combo = QComboBox()
        for s in FIELD_SCALES:
            self.field_scale_combo.addItem(f"1/{s}" if s > 1 else "full", s)
        self.field_scale_combo.setToolTip(
            "Resolution of the wire attribute field per axis (coarser builds faster)"
        )
        self.field_scale_combo.currentIndexChanged.connect(self._field_scale_changed)
        form.addRow("Field resolution", self.field_scale_combo)
        row = QHBoxLayout()
        self.lay_button = QPushButton("New wire: click points")
        self.lay_button.setCheckable(True)
        self.lay_button.setToolTip(
            "Click control points of a new wire in the viewport (on the plane through the"
            " volume's centre, parallel to the image), then Finish wire"
        )
        self.lay_button.toggled.connect(self._lay_toggled)
        self.finish_button = QPushButton("Finish wire")
        self.finish_button.setToolTip("Make the clicked points a wire (curve and radius above)")
        self.finish_button.clicked.connect(self._finish_wire)
        row.addWidget(self.lay_button)
        row.addWidget(self.finish_button)
        form.addRow(row)
        self.remove_wire_button = QPushButton("Remove wire")
        self.remove_wire_button.setToolTip("Delete the selected wire (not the last one)")
        self.remove_wire_button.clicked.connect(self._remove_wire)
        form.addRow(self.remove_wire_button)
        return self.wire_group

    def _build_placement_group(self) -> QGroupBox:
        self.placement_group = QGroupBox("Placement of the grid")
        self.placement_group.setToolTip(
            "Move, rotate (about the volume's centre) and scale the deformation grid"
            " relative to the volume; outside it nothing moves"
        )
        grid = QGridLayout(self.placement_group)
        for c, axis in enumerate(AXES):
            label = QLabel(axis)
            label.setAlignment(Qt.AlignmentFlag.AlignCenter)
            grid.addWidget(label, 0, c + 1)
            grid.setColumnStretch(c + 1, 1)
        self.translate_spins = [_double_spin(-1e5, 1e5, 1.0, 1) for _ in AXES]
        self.rotate_spins = [_double_spin(-360.0, 360.0, 5.0, 1) for _ in AXES]
        self.scale_spins = [_double_spin(0.05, 20.0, 0.05, 2) for _ in AXES]
        rows = (
            ("Move mm", self.translate_spins),
            ("Rotate °", self.rotate_spins),
            ("Scale", self.scale_spins),
        )
        for r, (name, spins) in enumerate(rows):
            grid.addWidget(QLabel(name), r + 1, 0)
            for c, spin in enumerate(spins):
                spin.setButtonSymbols(QDoubleSpinBox.ButtonSymbols.NoButtons)
                spin.valueChanged.connect(self._placement_changed)
                grid.addWidget(spin, r + 1, c + 1)
        self.place_reset_button = QPushButton("Reset placement")
        self.place_reset_button.clicked.connect(self._reset_placement)
        grid.addWidget(self.place_reset_button, 4, 0, 1, 4)
        return self.placement_group

    # ------------------------------------------------------------------ refresh
    def refresh(self) -> None:
        """Show the current session's model, settings, wires and placement (no edit)."""
        s = self.session
        with self._refreshing():
            _set_combo_data(self.model_combo, s.kind)
            self.backend_combo.setCurrentText(s.backend)
            self.resolution_spin.setValue(int(max(s.resolution)))
            self.integrator_combo.setCurrentText(s.integrator)
            self.variant_combo.setCurrentText(s.variant)
            self.stiffness_spin.setValue(s.stiffness)
            self.run_button.setChecked(bool(s.running))
            self.run_button.setText("Pause" if s.running else "Run")
            self.steps_spin.setValue(s.steps_per_frame)
            self.relax_spin.setValue(s.relax_steps)
            has_elements = s.kind in ("massspring", "chainmail") and s.model is not None
            for button in (self.fix_button, self.free_button, self.step_button):
                button.setEnabled(has_elements)
            self.reset_button.setEnabled(s.kind != "none")
            self._refresh_wires(s)
            self._refresh_placement(s)
            self._update_visibility(s.kind)

    def _current_wire(self, s: EditSession) -> tuple[int, int | None] | None:
        """(wire, control point or None) the wire widgets edit: that of the reference or
        the last selected handle, else wire 0; None without wires."""
        if s.kind != "wires" or not s.wires:
            return None
        for handle in (s.reference, s.selection[-1] if s.selection else None):
            hit = wire_of_handle(s, handle)
            if hit is not None:
                return hit
        return 0, None

    def _reference_fraction(self, s: EditSession) -> float | None:
        """Fraction of its wire's length at the reference control point (cached)."""
        hit = wire_of_handle(s, s.reference) if s.kind == "wires" else None
        if hit is None:
            return None
        key = (id(s), s.reference, s.wire_generation, len(s.wires))
        if key != self._fraction_cache:
            curve = s.wires[hit[0]].modified
            t, _ = curve.closest_point(curve.control_points[hit[1]])
            t = float(np.asarray(t).reshape(-1)[0])
            total = curve.arc_length()
            self._fraction = (
                0.0 if total <= 0 else float(np.clip(curve.arc_length(t1=t) / total, 0.0, 1.0))
            )
            self._fraction_cache = key
        return self._fraction

    def _refresh_wires(self, s: EditSession) -> None:
        current = self._current_wire(s)
        pending = len(s.pending_wire)
        laying = bool(getattr(self._window.viewport, "laying_wire", False))
        self.lay_button.setChecked(laying)
        self.finish_button.setEnabled(pending > 0)
        self.field_scale_combo.setCurrentIndex(
            max(0, self.field_scale_combo.findData(int(s.wire_settings.get("field_scale", 2))))
        )
        lo, hi = s.volume.value_range
        span = max(hi - lo, 1e-6)
        decimals = _value_decimals(span)
        for spin in (self.beta_lo_spin, self.beta_hi_spin):
            spin.setDecimals(decimals)
            spin.setSingleStep(max(span / 100.0, 10.0**-decimals))
            spin.setRange(lo - span, hi + span)
        extent = float(np.max(s.box[1] - s.box[0]))
        self.radius_spin.setSingleStep(max(extent / 100.0, 0.01))
        self.radius_spin.setMaximum(max(10.0 * extent, 1.0))
        self.remove_wire_button.setEnabled(current is not None and len(s.wires) > 1)
        self.set_key_button.setEnabled(current is not None and current[1] is not None)
        if current is None:
            self.wire_label.setText("No wires." if s.kind == "wires" else "")
            return
        w, point = current
        wire = s.wires[w]
        where = f", point {point + 1}" if point is not None else " (click a point to pick)"
        text = f"Wire {w + 1} of {len(s.wires)}{where}"
        if laying or pending:
            text += (
                f"<br>New wire: {pending} point{'s' if pending != 1 else ''} laid;"
                " curve and radius are those of the new wire"
            )
        self.wire_label.setText(text)
        if not laying:
            self.wire_kind_combo.setCurrentText(wire.kind)
            self.radius_spin.setMaximum(max(self.radius_spin.maximum(), wire.radius))
            self.radius_spin.setValue(wire.radius)
        beta = wire.beta if isinstance(wire.beta, tuple) else None
        self.beta_check.setChecked(beta is not None)
        if beta is not None:
            for spin in (self.beta_lo_spin, self.beta_hi_spin):
                spin.setRange(min(spin.minimum(), beta[0]), max(spin.maximum(), beta[1]))
            self.beta_lo_spin.setValue(beta[0])
            self.beta_hi_spin.setValue(beta[1])
        elif self._beta_volume is not s.volume:
            # without classification the spins keep what was typed, for switching it on;
            # a new volume starts them at its value range
            self.beta_lo_spin.setValue(lo)
            self.beta_hi_spin.setValue(hi)
        self._beta_volume = s.volume
        self.beta_lo_spin.setEnabled(beta is not None)
        self.beta_hi_spin.setEnabled(beta is not None)
        fraction = self._reference_fraction(s) if point is not None else None
        if fraction is not None:
            self.twist_spin.setValue(math.degrees(float(wire.twist_at(fraction))))
            self.scale_spin.setValue(float(wire.scale_at(fraction)))

    def _refresh_placement(self, s: EditSession) -> None:
        p = s.placement
        extent = float(np.max(s.box[1] - s.box[0]))
        for spin in self.translate_spins:
            spin.setSingleStep(max(extent / 100.0, 0.1))
        for spins, values in (
            (self.translate_spins, p.translate),
            (self.rotate_spins, p.rotate),
            (self.scale_spins, p.scale),
        ):
            for spin, v in zip(spins, values, strict=True):
                spin.setValue(v)
        self.place_reset_button.setEnabled(not p.is_identity)

    def _update_visibility(self, kind: str) -> None:
        """Show only the widgets of deformation family ``kind``."""
        elements = kind in ("massspring", "chainmail")
        rows = {
            self.backend_combo: elements,
            self.resolution_spin: elements or kind == "lattice",
            self.integrator_combo: kind == "massspring",
            self.variant_combo: kind == "chainmail",
            self.stiffness_spin: elements,
        }
        for widget, visible in rows.items():
            self.model_form.setRowVisible(widget, visible)
        self.apply_button.setVisible(kind != "none")
        self.simulation_group.setVisible(elements)
        self.simulation_form.setRowVisible(self.steps_spin, kind == "massspring")
        self.simulation_form.setRowVisible(self.relax_spin, kind == "chainmail")
        self.wire_group.setVisible(kind == "wires")
        self.placement_group.setVisible(kind != "none")
        self.updateGeometry()

    # ------------------------------------------------------------------ new wires
    def wire_kind(self) -> str:
        """Curve kind chosen in the wire group (for :meth:`EditSession.finish_wire`)."""
        return self.wire_kind_combo.currentText()

    def wire_radius(self) -> float:
        """Radius (mm) chosen in the wire group (for :meth:`EditSession.finish_wire`)."""
        return float(self.radius_spin.value())

    # ------------------------------------------------------------------ timings
    def refresh_timings(self, frame_ms: float | None) -> None:
        """Show the last step and field-build times and the frame time (cheap: call
        every frame).

        Parameters
        ----------
        frame_ms
            Duration of the last frame in ms, or None when unknown.
        """
        timings = self.session.timings
        parts = []
        step = timings.get("step")
        if step is not None and self.session.kind in ("massspring", "chainmail"):
            parts.append(f"step {step:.2f} ms")
        field = timings.get("field")
        if field is not None and self.session.kind == "wires":
            parts.append(f"field {field:.0f} ms")
        if frame_ms is not None and frame_ms > 0:
            parts.append(f"frame {frame_ms:.1f} ms ({1000.0 / frame_ms:.0f} fps)")
        text = " · ".join(parts)
        if text != self._timings_text:
            self._timings_text = text
            self.timings_label.setText(text)

    # ------------------------------------------------------------------ model handlers
    def _settings(self) -> dict[str, Any]:
        return {
            "backend": self.backend_combo.currentText(),
            "resolution": int(self.resolution_spin.value()),
            "integrator": self.integrator_combo.currentText(),
            "variant": self.variant_combo.currentText(),
            "stiffness": float(self.stiffness_spin.value()),
        }

    def _model_changed(self, _index: int) -> None:
        if self._updating:
            return
        self._apply()

    def _apply(self) -> None:
        kind = str(self.model_combo.currentData())
        settings = self._settings()
        text = "No deformation" if kind == "none" else f"New {DEFORMATION_LABELS[kind]} model"
        self._edit(text, lambda: self.session.set_deformation(kind, **settings))
        if kind == "wires":
            self._window.request_wire_build()
        # also after a failed edit: the widgets must show the session again
        self.refresh()

    def _reset(self) -> None:
        wires = self.session.kind == "wires"
        self._edit("Reset model", lambda: self.session.reset_model())
        if wires:
            self._window.request_wire_build()

    # ------------------------------------------------------------------ simulation
    def _run_toggled(self, running: bool) -> None:
        self.run_button.setText("Pause" if running else "Run")
        if self._updating:
            return
        self._window.set_running(bool(running))

    def _single_step(self) -> None:
        self._edit("Single step", lambda: self.session.single_step())

    def _option_changed(self, name: str, label: str, merge: str, value: int) -> None:
        """A run-time option of the session (one undo step per spin box drag)."""
        if self._updating:
            return
        self._edit(label, lambda: self.session.set_option(name, int(value)), merge=merge)

    def _set_fixed(self, fixed: bool) -> None:
        def fn() -> None:
            s = self.session
            if not s.selection:
                raise EditorError("select elements first (click or drag a rectangle)")
            s.set_fixed(s.selection, fixed)

        self._edit("Fix selected" if fixed else "Free selected", fn)

    # ------------------------------------------------------------------ wire handlers
    def _wire_edit(self, text: str, fn: Callable[[], Any], merge: str | None = None) -> Any:
        """An edit of the wires, then a rebuild of their field off the GUI thread."""
        result = self._edit(text, fn, merge)
        self._window.request_wire_build()
        return result

    def _wire_index(self) -> int | None:
        current = self._current_wire(self.session)
        return None if current is None else current[0]

    def _wire_kind_changed(self, kind: str) -> None:
        w = self._wire_index()
        if (
            self._updating
            or self.lay_button.isChecked()
            or w is None
            or self.session.wires[w].kind == kind
        ):
            return
        self._wire_edit(
            f"Wire curve {kind}", lambda: self.session.set_wire_parameters(w, kind=kind)
        )

    def _radius_changed(self, radius: float) -> None:
        w = self._wire_index()
        if self._updating or self.lay_button.isChecked() or w is None:
            return
        self._wire_edit(
            "Wire radius",
            lambda: self.session.set_wire_parameters(w, radius=float(radius)),
            merge=f"wire radius {w}",
        )

    def _beta_toggled(self, on: bool) -> None:
        if self._updating:
            return
        self.beta_lo_spin.setEnabled(on)
        self.beta_hi_spin.setEnabled(on)
        self._beta_changed()

    def _beta_range_changed(self, _value: float) -> None:
        if self._updating or not self.beta_check.isChecked():
            return  # the range is kept for when classification is switched on
        self._beta_changed()

    def _beta_changed(self) -> None:
        w = self._wire_index()
        if self._updating or w is None:
            return
        on = self.beta_check.isChecked()
        beta = (float(self.beta_lo_spin.value()), float(self.beta_hi_spin.value())) if on else None
        self._wire_edit(
            "Wire object classification",
            lambda: self.session.set_wire_parameters(w, beta=beta),
            merge=f"wire beta {w}" if on else None,
        )

    def _set_wire_key(self) -> None:
        twist = math.radians(float(self.twist_spin.value()))
        scale = float(self.scale_spin.value())

        def fn() -> None:
            s = self.session
            if s.kind != "wires" or wire_of_handle(s, s.reference) is None:
                raise EditorError("select a control point of a wire first (click it)")
            s.set_wire_key(s.reference, twist=twist, scale=scale)

        self._wire_edit("Wire twist and scale", fn)

    def _field_scale_changed(self, _index: int) -> None:
        if self._updating:
            return
        scale = int(self.field_scale_combo.currentData())

        def fn() -> None:
            self.session.set_wire_settings(field_scale=scale)

        self._wire_edit(f"Wire field 1/{scale}", fn)

    def _lay_toggled(self, on: bool) -> None:
        if self._updating:
            return
        self._window.viewport.laying_wire = bool(on)
        self.refresh()

    def _finish_wire(self) -> None:
        kind, radius = self.wire_kind(), self.wire_radius()
        result = self._wire_edit("New wire", lambda: self.session.finish_wire(kind, radius))
        if result is not None:
            self._window.viewport.laying_wire = False
            self.refresh()

    def _remove_wire(self) -> None:
        w = self._wire_index()
        if w is None:
            return
        self._wire_edit(f"Remove wire {w + 1}", lambda: self.session.remove_wire(w))

    # ------------------------------------------------------------------ placement
    def _placement_changed(self, _value: float) -> None:
        if self._updating:
            return
        translate = tuple(float(s.value()) for s in self.translate_spins)
        rotate = tuple(float(s.value()) for s in self.rotate_spins)
        scale = tuple(float(s.value()) for s in self.scale_spins)
        self._edit(
            "Place grid",
            lambda: self.session.set_placement(Placement(translate, rotate, scale)),
            merge="placement",
        )

    def _reset_placement(self) -> None:
        self._edit("Reset placement", lambda: self.session.set_placement(Placement()))


# ---------------------------------------------------------------------------- display
class DisplayPanel(_Panel):
    """Check boxes toggling what the viewport draws
    (:class:`~voxwarp.editing.session.DisplayOptions`),
    and below them the field slice view (:class:`voxwarp.ui.field_view.FieldSliceView`).

    Display toggles are not part of the document: they change
    ``window.viewport.display`` directly (no undo step) and redraw.

    Parameters
    ----------
    window
        The main window.
    parent
        Optional parent widget.
    """

    def __init__(self, window: Any, parent: QWidget | None = None) -> None:
        super().__init__(window, parent)
        layout = QVBoxLayout(self._scrolling_body())
        layout.setContentsMargins(4, 4, 4, 4)
        self.checks: dict[str, QCheckBox] = {}
        for f in dataclasses.fields(DisplayOptions):
            check = QCheckBox(DISPLAY_LABELS.get(f.name, f.name.replace("_", " ").capitalize()))
            check.toggled.connect(lambda on, name=f.name: self._toggled(name, on))
            layout.addWidget(check)
            self.checks[f.name] = check
        from voxwarp.ui.field_view import FieldSliceView

        #: the deformation's internal fields on a slice (folded until asked for)
        self.field_view = FieldSliceView(window)
        layout.addSpacing(4)
        layout.addWidget(self.field_view)
        layout.addStretch(1)
        self.refresh()

    def refresh(self) -> None:
        """Show the viewport's current display options (and the field slice of the
        current deformation, recomputed only when something changed)."""
        display = self._window.viewport.display
        with self._refreshing():
            for name, check in self.checks.items():
                check.setChecked(bool(getattr(display, name)))
        self.field_view.refresh()

    def _toggled(self, name: str, on: bool) -> None:
        if self._updating:
            return
        setattr(self._window.viewport.display, name, bool(on))
        self._window.viewport.update()


# ---------------------------------------------------------------------------- scene tree
class ScenePanel(_Panel):
    """A tree of the scene: the volume, the deformation and its warps, the meshes.

    Meshes whose instance has a ``visible`` attribute get a check box that shows or hides
    them (an undoable edit).

    Parameters
    ----------
    window
        The main window.
    parent
        Optional parent widget.
    """

    def __init__(self, window: Any, parent: QWidget | None = None) -> None:
        super().__init__(window, parent)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        self.tree = QTreeWidget()
        self.tree.setColumnCount(2)
        self.tree.setHeaderLabels(["Item", "Details"])
        self.tree.setRootIsDecorated(True)
        self.tree.setUniformRowHeights(True)
        self.tree.itemChanged.connect(self._item_changed)
        self._in_item_signal = False
        self._rebuild_pending = False
        layout.addWidget(self.tree)
        self.refresh()

    def refresh(self) -> None:
        """Rebuild the tree from the current session."""
        if self._in_item_signal:
            if not self._rebuild_pending:
                self._rebuild_pending = True
                QTimer.singleShot(0, self, self._deferred_refresh)
            return
        s = self.session
        scene = s.scene
        with self._refreshing():
            self.tree.clear()
            vol = scene.volume
            shape = "×".join(str(n) for n in vol.shape)
            spacing = "×".join(f"{x:g}" for x in vol.spacing)
            volume_item = QTreeWidgetItem(["Volume", f"{vol.name}, {shape}"])
            volume_item.setToolTip(1, f"{shape} voxels of {spacing} mm, {vol.dtype}")
            self.tree.addTopLevelItem(volume_item)
            label = DEFORMATION_LABELS.get(s.kind, s.kind)
            detail = label
            if s.kind in ("massspring", "chainmail") and s.model is not None:
                detail += f", {'×'.join(str(n) for n in s.model.grid.shape)} elements"
            elif s.kind == "wires":
                detail += f", {len(s.wires)} wire{'s' if len(s.wires) != 1 else ''}"
            elif s.kind == "lattice" and s.lattice_nodes is not None:
                cells = "×".join(str(n - 1) for n in s.lattice_nodes.shape[:3])
                detail += f", {cells} cells"
            deform_item = QTreeWidgetItem(["Deformation", detail])
            for warp in scene.warps:
                deform_item.addChild(QTreeWidgetItem([type(warp).__name__, ""]))
            self.tree.addTopLevelItem(deform_item)
            meshes = scene.meshes
            meshes_item = QTreeWidgetItem(["Meshes", str(len(meshes))])
            for i, inst in enumerate(meshes):
                how = "lattice" if inst.is_lattice else "matrix"
                item = QTreeWidgetItem([inst.name, f"{inst.mesh.n_faces} faces, {how}"])
                item.setData(0, Qt.ItemDataRole.UserRole, i)
                if hasattr(inst, "visible"):
                    item.setFlags(item.flags() | Qt.ItemFlag.ItemIsUserCheckable)
                    state = Qt.CheckState.Checked if inst.visible else Qt.CheckState.Unchecked
                    item.setCheckState(0, state)
                meshes_item.addChild(item)
            self.tree.addTopLevelItem(meshes_item)
            self.tree.expandAll()
            self.tree.resizeColumnToContents(0)

    def _item_changed(self, item: QTreeWidgetItem, column: int) -> None:
        if self._updating or column != 0:
            return
        index = item.data(0, Qt.ItemDataRole.UserRole)
        if index is None:
            return
        visible = item.checkState(0) == Qt.CheckState.Checked

        def fn() -> bool:
            setattr(self.session.scene.meshes[int(index)], "visible", visible)  # noqa: B010
            return True

        # the edit refreshes the panels; rebuilding the tree now would delete the item
        # inside its own signal, so refresh() defers the rebuild meanwhile
        self._in_item_signal = True
        try:
            done = self._edit("Show mesh" if visible else "Hide mesh", fn) is not None
        finally:
            self._in_item_signal = False
        if done:
            self._window.scene_changed()

    def _deferred_refresh(self) -> None:
        self._rebuild_pending = False
        self.refresh()
