"""Dock panels of the main window: volume look, deformation, display toggles, scene tree.

Every panel is a plain :class:`QWidget` built as ``Panel(window)`` and placed by the
window in a :class:`QDockWidget`. The widgets of each deformation family are in its panel
of :mod:`voxwarp.ui.family_panels`, shown by :class:`DeformationPanel`. The panels talk
to the window only through this contract (see ``ui/main_window.py``)::

    window.session: EditSession            # replaced when a file is opened
    window.viewport.display: DisplayOptions
    window.viewport.update() -> None       # redraw
    window.edit(text, fn, merge=None)      # fn() as one undoable edit
    window.scene_changed() -> None         # the scene's look changed
    window.request_field_build() -> None    # rebuild the wire field off the GUI thread
    window.set_running(running) -> None
    window.open_file_dialog() -> None
    window.refresh_panels() -> None        # after an edit outside window.edit
    window.statusBar()                     # messages of the family panels' actions

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
import functools
from typing import Any

import numpy as np
from PySide6.QtCore import Qt, QTimer
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QDoubleSpinBox,
    QFormLayout,
    QGridLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QSpinBox,
    QTreeWidget,
    QTreeWidgetItem,
    QVBoxLayout,
    QWidget,
)

from voxwarp import shaders
from voxwarp.core.camera import PROJECTIONS
from voxwarp.core.levels import LEVEL_ATTRIBUTES
from voxwarp.editing.session import DEFORMATIONS, DisplayOptions, EditSession, Placement
from voxwarp.scene import MAX_INTERACTIVE_DOWNSAMPLE, MODES
from voxwarp.ui.family_panels import (
    FAMILY_PANELS,
    FamilyPanel,
    ModelOptions,
    PanelAction,
    family_label,
)
from voxwarp.ui.field_view import FieldSliceView
from voxwarp.ui.panel_base import (
    AxisSpinBox,
    Panel,
    axis_names,
    axis_spin,
    combo,
    double_spin,
    int_spin,
    set_combo_data,
    value_decimals,
)

__all__ = [
    "DISPLAY_LABELS",
    "SHADING_CHOICES",
    "DeformationPanel",
    "DisplayPanel",
    "ScenePanel",
    "VolumePanel",
    "window_acts",
]

#: Entries of the shading combo box and the ``Scene.shading`` value of each.
SHADING_CHOICES: tuple[tuple[str, bool | None], ...] = (
    ("auto", None),
    ("on", True),
    ("off", False),
)
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
    "slice_planes": "Slice planes",
}
AXES = ("x", "y", "z")


@functools.cache
def window_acts(mode: str) -> bool:
    """Whether render ``mode`` reads the grey-value window (level, width).

    Asked of the mode's own shader (``shaders/mode_<mode>.glsl`` uses ``u_window`` or
    ``window_gray``), so a new mode is right without a list to keep in step: today mip,
    minip, average and xray; dvr, flm and iso map values through the transfer function.
    """
    try:
        text = shaders.read(f"mode_{mode}.glsl")
    except FileNotFoundError:
        return False
    return "u_window" in text or "window_gray" in text


def _compact_form(form: QFormLayout) -> None:
    form.setFieldGrowthPolicy(QFormLayout.FieldGrowthPolicy.AllNonFixedFieldsGrow)
    form.setContentsMargins(6, 4, 6, 4)
    form.setVerticalSpacing(3)
    form.setHorizontalSpacing(6)


def _orientation_text(vol: Any) -> str:
    """`` · RAS (file LAS)`` for an oriented volume, `` · no orientation`` else."""
    if getattr(vol, "space", "") != "RAS":
        return " · no patient orientation"
    file_axes = getattr(vol, "file_axes", "")
    was = f", file {file_axes}" if file_axes and file_axes != "RAS" else ""
    oblique = ", oblique" if getattr(vol, "is_oblique", False) else ""
    return f" · patient RAS{was}{oblique}"


def _axis_tooltip(name: str, letters: tuple[str, str] | None) -> str:
    if letters is None:
        return f"world {name} (mm; the volume has no patient orientation)"
    pos, neg = letters
    return (
        f"patient axis {name} in RAS world mm: {pos} 12 = 12 mm towards {pos},"
        f" {neg} 12 = 12 mm towards {neg} (type either, or a signed number)"
    )


# ---------------------------------------------------------------------------- volume
class VolumePanel(Panel):
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

        # rendering (compact: two values per row where they belong together, so that
        # the clipping group stays in view in a 1280x800 window)
        render_box = QGroupBox("Rendering")
        form = QFormLayout(render_box)
        _compact_form(form)
        self.mode_combo = combo(
            MODES,
            "dvr: emission-absorption; mip/minip: maximum/minimum intensity; average:"
            " mean along the ray; xray: radiograph (line integral, brighter where thicker);"
            " flm: first local maximum; iso: shaded isosurface",
        )
        self.mode_combo.currentTextChanged.connect(self._mode_changed)
        form.addRow("Mode", self.mode_combo)
        self.projection_combo = combo(PROJECTIONS)
        self.projection_combo.currentTextChanged.connect(self._projection_changed)
        form.addRow("Projection", self.projection_combo)
        self.step_spin = double_spin(
            0.1,
            8.0,
            0.1,
            2,
            " vx",
            "Sample distance along the rays, in voxels of the"
            " smallest spacing (smaller: finer and slower)",
        )
        self.step_spin.valueChanged.connect(self._step_changed)
        form.addRow("Sample dist.", self.step_spin)
        self.level_spin = double_spin(-1e9, 1e9, 1.0, 3, tooltip="Window centre (data units)")
        self.level_spin.valueChanged.connect(self._window_changed)
        self.width_spin = double_spin(1e-6, 1e9, 1.0, 3, tooltip="Window width (data units)")
        self.width_spin.valueChanged.connect(self._window_changed)
        self.level_spin.setPrefix("L ")
        self.width_spin.setPrefix("W ")
        window_row = QHBoxLayout()
        window_row.setSpacing(4)
        window_row.addWidget(self.level_spin)
        window_row.addWidget(self.width_spin)
        self.window_label = QLabel("Window")
        form.addRow(self.window_label, window_row)
        form.addRow(*self._build_threshold_row())
        self.shading_combo = QComboBox()
        for label, value in SHADING_CHOICES:
            self.shading_combo.addItem(label, value)
        self.shading_combo.setToolTip(
            "Blinn-Phong shading from gradients; auto: on for iso and flm, off otherwise"
        )
        self.shading_combo.currentIndexChanged.connect(self._shading_changed)
        self.jitter_check = QCheckBox("Jitter")
        self.jitter_check.setToolTip("Jitter the ray starts per pixel against wood-grain rings")
        self.jitter_check.toggled.connect(self._jitter_changed)
        shading_row = QHBoxLayout()
        shading_row.setSpacing(6)
        shading_row.addWidget(self.shading_combo, 1)
        shading_row.addWidget(self.jitter_check)
        form.addRow("Shading", shading_row)
        form.addRow("Interaction", self._build_resolution_spin())
        layout.addWidget(render_box)

        # clipping box: the group's own check box turns it on
        clip_box = QGroupBox("Clipping (world mm)")
        clip_box.setCheckable(True)
        clip_box.setToolTip(
            "Cut the rays to a box in world coordinates (mm; for a volume with a patient"
            " orientation, R/L A/P S/I of RAS patient space)"
        )
        #: the clipping group's check box (on: the scene has a clip box)
        self.clip_group = clip_box
        self.clip_check = clip_box
        clip_box.toggled.connect(self._clip_toggled)
        grid = QGridLayout(clip_box)
        grid.setContentsMargins(6, 4, 6, 4)
        grid.setVerticalSpacing(3)
        grid.setColumnStretch(1, 1)
        grid.setColumnStretch(2, 1)
        self.clip_spins: list[tuple[AxisSpinBox, AxisSpinBox]] = []
        self.clip_labels: list[QLabel] = []
        for a, axis in enumerate(AXES):
            lo = axis_spin(-1e6, 1e6, 1.0, 2, " mm", f"Low {axis} of the clipping box")
            hi = axis_spin(-1e6, 1e6, 1.0, 2, " mm", f"High {axis} of the clipping box")
            lo.valueChanged.connect(lambda _v, a=a: self._clip_changed(a, 0))
            hi.valueChanged.connect(lambda _v, a=a: self._clip_changed(a, 1))
            label = QLabel(axis)
            grid.addWidget(label, a, 0)
            grid.addWidget(lo, a, 1)
            grid.addWidget(hi, a, 2)
            self.clip_spins.append((lo, hi))
            self.clip_labels.append(label)
        layout.addWidget(clip_box)
        layout.addStretch(1)
        self.refresh()

    def _build_threshold_row(self) -> tuple[QLabel, QHBoxLayout]:
        """The level of the threshold modes (iso value, FLM threshold) and its Auto box."""
        self.threshold_spin = double_spin(-1e9, 1e9, 1.0, 3)
        self.threshold_spin.valueChanged.connect(self._threshold_changed)
        self.threshold_auto = QCheckBox("Auto")
        self.threshold_auto.setToolTip(
            "From the histogram: the split of object and background (on a CT the transfer"
            " function's level above it); off: the value typed here"
        )
        self.threshold_auto.toggled.connect(self._threshold_auto_toggled)
        row = QHBoxLayout()
        row.setSpacing(6)
        row.addWidget(self.threshold_spin, 1)
        row.addWidget(self.threshold_auto)
        self.threshold_label = QLabel("Level")
        return self.threshold_label, row

    def _build_resolution_spin(self) -> QSpinBox:
        """The volume resolution of interactive frames (the scene's
        ``interactive_downsample``): 1/N per axis while dragging or orbiting."""
        spin = int_spin(
            1,
            MAX_INTERACTIVE_DOWNSAMPLE,
            "Volume resolution while you drag or orbit: the volume reduced to 1/N per axis"
            " (over the same box) for faster interactive frames; the view at rest,"
            " screenshots, exports and voxwarp render use the full volume",
        )
        spin.setPrefix("volume 1/")
        spin.setSpecialValueText("full volume")
        spin.valueChanged.connect(self._resolution_changed)
        self.resolution_spin = spin
        return spin

    # ------------------------------------------------------------------ refresh
    def refresh(self) -> None:
        """Show the current session's volume and scene look (makes no edit)."""
        scene = self.session.scene
        vol = scene.volume
        with self._refreshing():
            shape = "×".join(str(n) for n in vol.shape)
            spacing = "×".join(f"{s:g}" for s in vol.spacing)
            where = _orientation_text(vol)
            self.info_label.setText(f"<b>{vol.name}</b>{where}<br>{shape} voxels · {spacing} mm")
            self.info_label.setToolTip(str(vol.source or "in memory"))
            self.mode_combo.setCurrentText(scene.mode)
            self.projection_combo.setCurrentText(scene.projection)
            self.step_spin.setValue(scene.step)
            vlo, vhi = vol.value_range
            span = max(vhi - vlo, scene.window[1], 1e-6)
            decimals = value_decimals(span)
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
            self._show_window_controls(scene.mode)
            self._show_threshold(scene, decimals, step)
            set_combo_data(self.shading_combo, scene.shading)
            self.jitter_check.setChecked(scene.jitter)
            self.resolution_spin.setValue(scene.interactive_downsample)
            lo, hi = (np.asarray(b, dtype=np.float64) for b in vol.bounds)
            box = scene.clip_box
            self.clip_check.setChecked(box is not None)
            names = axis_names(vol)
            for a, (lo_spin, hi_spin) in enumerate(self.clip_spins):
                name, letters = names[a]
                self.clip_labels[a].setText(name)
                self.clip_labels[a].setToolTip(_axis_tooltip(name, letters))
                lo_spin.set_letters(letters)
                hi_spin.set_letters(letters)
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

    def _show_window_controls(self, mode: str) -> None:
        """Window level and width act only in the modes that read them: enabled there,
        disabled (with a tooltip saying where they act) elsewhere."""
        acts = window_acts(mode)
        where = ", ".join(m for m in MODES if window_acts(m))
        for w in (self.window_label, self.level_spin, self.width_spin):
            w.setEnabled(acts)
        self.window_label.setToolTip(
            "Grey-value window (level, width) of this mode"
            if acts
            else f"The window acts in {where} only; {mode} maps values through the"
            " transfer function"
        )

    def _show_threshold(self, scene: Any, decimals: int, step: float) -> None:
        """The threshold row: the mode's level (given or chosen) where the mode has one,
        disabled elsewhere."""
        attr = LEVEL_ATTRIBUTES.get(scene.mode)
        self.threshold_label.setText("Iso value" if scene.mode == "iso" else "Threshold")
        for w in (self.threshold_label, self.threshold_spin, self.threshold_auto):
            w.setEnabled(attr is not None)
        if attr is None:
            self.threshold_label.setText("Level")
            self.threshold_label.setToolTip("The iso value of iso and the threshold of flm")
            return
        level = scene.resolved_level()
        self.threshold_spin.setDecimals(decimals)
        self.threshold_spin.setSingleStep(step)
        self.threshold_spin.setValue(level.value)
        self.threshold_auto.setChecked(getattr(scene, attr) is None)
        self.threshold_spin.setEnabled(getattr(scene, attr) is not None)
        self.threshold_label.setToolTip(level.text(scene.mode))

    def _threshold_changed(self, value: float) -> None:
        attr = LEVEL_ATTRIBUTES.get(self.session.scene.mode)
        if attr is None or self.threshold_auto.isChecked():
            return
        self._edit_look(self.threshold_label.text(), attr, float(value), merge=attr)

    def _threshold_auto_toggled(self, on: bool) -> None:
        attr = LEVEL_ATTRIBUTES.get(self.session.scene.mode)
        if attr is None:
            return
        self.threshold_spin.setEnabled(not on)
        value = None if on else float(self.threshold_spin.value())
        self._edit_look(f"{self.threshold_label.text()} {'auto' if on else 'set'}", attr, value)

    def _window_changed(self, _value: float) -> None:
        window = (float(self.level_spin.value()), float(self.width_spin.value()))
        self._edit_look("Window", "window", window, merge="window")

    def _shading_changed(self, _index: int) -> None:
        value = self.shading_combo.currentData()
        self._edit_look(f"Shading {self.shading_combo.currentText()}", "shading", value)

    def _resolution_changed(self, value: int) -> None:
        self._edit_look("Interaction resolution", "interactive_downsample", int(value))

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
class DeformationPanel(Panel):
    """The deformation model, the current family's panel, placement and timings.

    The family's own widgets live in its panel (:data:`FAMILY_PANELS`); the panel shows
    that of ``session.kind`` and offers the family panels' ``exposed`` widgets as its own
    attributes (``steps_spin``, ``wire_group``, ``wire_kind()``, ...).

    Parameters
    ----------
    window
        The main window (see the module docstring for what the panel uses of it).
    parent
        Optional parent widget.
    """

    def __init__(self, window: Any, parent: QWidget | None = None) -> None:
        super().__init__(window, parent)
        self._timings_text = ""
        layout = QVBoxLayout(self._scrolling_body())
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addWidget(self._build_model_group())
        self._family_panels = self._build_family_panels(layout)
        layout.addWidget(self._build_placement_group())
        self.timings_label = QLabel()
        self.timings_label.setWordWrap(True)
        self.timings_label.setToolTip(
            "step: one model step (mass-spring) or relaxation step (ChainMail); field: the"
            " last wire-field build (the frame rate is in the status bar)"
        )
        layout.addWidget(self.timings_label)
        layout.addStretch(1)
        self.refresh()
        self.refresh_timings()

    # ------------------------------------------------------------------ building
    def _build_model_group(self) -> QGroupBox:
        box = QGroupBox("Model")
        form = QFormLayout(box)
        form.setFieldGrowthPolicy(QFormLayout.FieldGrowthPolicy.AllNonFixedFieldsGrow)
        self.model_form = form
        self.model_combo = QComboBox()
        for kind in DEFORMATIONS:
            self.model_combo.addItem(family_label(kind), kind)
        self.model_combo.setToolTip(
            "Deformation family (choosing one builds it at rest; mass-spring and ChainMail"
            " switch into each other keeping the deformation)"
        )
        self.model_combo.currentIndexChanged.connect(self._model_changed)
        form.addRow("Model", self.model_combo)
        self.options = ModelOptions(form)
        self.backend_combo = self.options.backend_combo
        self.resolution_spin = self.options.resolution_spin
        self.integrator_combo = self.options.integrator_combo
        self.variant_combo = self.options.variant_combo
        self.stiffness_spin = self.options.stiffness_spin
        self.margin_spin = self.options.margin_spin
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

    def _build_family_panels(self, layout: QVBoxLayout) -> dict[str, FamilyPanel]:
        """One panel per panel class of :data:`FAMILY_PANELS` (shared by its families),
        added to ``layout``; their ``exposed`` attributes become this panel's."""
        built: dict[type[FamilyPanel], FamilyPanel] = {}
        for cls in FAMILY_PANELS.values():
            if cls not in built:
                built[cls] = cls(self._window, self.refresh)
                layout.addWidget(built[cls])
                self._expose(built[cls])
        return {kind: built[cls] for kind, cls in FAMILY_PANELS.items()}

    def _expose(self, panel: FamilyPanel) -> None:
        for name in panel.exposed:
            assert not hasattr(self, name), f"two family panels expose {name}"
            setattr(self, name, getattr(panel, name))

    def window_actions(self) -> list[PanelAction]:
        """The family panels' actions for the window's Deformation menu, in the order of
        :data:`FAMILY_PANELS` (see :meth:`FamilyPanel.window_actions`)."""
        return [a for p in dict.fromkeys(self._family_panels.values()) for a in p.window_actions()]

    def _build_placement_group(self) -> QGroupBox:
        self.placement_group = QGroupBox("Placement of the grid")
        self.placement_group.setToolTip(
            "Move, rotate (about the volume's centre) and scale the deformation grid"
            " relative to the volume; outside it nothing moves"
        )
        grid = QGridLayout(self.placement_group)
        #: column headers: x y z, or L–R P–A I–S for a volume with a patient orientation
        self.placement_labels: list[QLabel] = []
        for c, axis in enumerate(AXES):
            label = QLabel(axis)
            label.setAlignment(Qt.AlignmentFlag.AlignCenter)
            grid.addWidget(label, 0, c + 1)
            grid.setColumnStretch(c + 1, 1)
            self.placement_labels.append(label)
        # moves in world mm: shown towards a patient side (R 5.0) when oriented
        self.translate_spins = [axis_spin(-1e5, 1e5, 1.0, 1) for _ in AXES]
        self.rotate_spins = [double_spin(-360.0, 360.0, 5.0, 1) for _ in AXES]
        self.scale_spins = [double_spin(0.05, 20.0, 0.05, 2) for _ in AXES]
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
    @property
    def family_panel(self) -> FamilyPanel:
        """The panel of the session's current family."""
        return self._family_panels[self.session.kind]

    def refresh(self) -> None:
        """Show the current session's model, settings, family and placement (no edit)."""
        s = self.session
        with self._refreshing():
            set_combo_data(self.model_combo, s.kind)
            self.options.refresh(s)
            self.reset_button.setEnabled(self.family_panel.editable)
            self.family_panel.refresh(s)
            self._refresh_placement(s)
            self._show_family(s.kind)

    def _refresh_placement(self, s: EditSession) -> None:
        p = s.placement
        for label, spin, (name, letters) in zip(
            self.placement_labels, self.translate_spins, axis_names(s.volume), strict=True
        ):
            label.setText(name)
            label.setToolTip(_axis_tooltip(name, letters))
            spin.set_letters(letters)
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

    def _show_family(self, kind: str) -> None:
        """Show only the widgets of deformation family ``kind``."""
        current = self._family_panels[kind]
        self.options.show_only(current.options[kind])
        self.apply_button.setVisible(current.editable)
        self.placement_group.setVisible(current.editable)
        for panel in dict.fromkeys(self._family_panels.values()):
            panel.setVisible(panel is current and panel.has_groups)
        current.show_family(kind)
        self.updateGeometry()

    # ------------------------------------------------------------------ timings
    def refresh_timings(self) -> None:
        """Show the last step and field-build times (cheap: call every frame). The frame
        rate has one readout only, in the window's status bar."""
        parts = self.family_panel.timing_parts(self.session.timings)
        text = " · ".join(parts)
        if text != self._timings_text:
            self._timings_text = text
            self.timings_label.setText(text)

    # ------------------------------------------------------------------ model handlers
    def _model_changed(self, _index: int) -> None:
        if self._updating:
            return
        self._apply()

    def _apply(self) -> None:
        kind = str(self.model_combo.currentData())
        settings = self.options.settings()
        panel = self._family_panels[kind]

        def switch() -> bool:
            self.session.set_deformation(kind, **settings)
            return True

        if self._edit(panel.edit_name(kind), switch):
            # mass-spring <-> ChainMail keeps the deformation: how far that moved elements
            note = self.session.family.switch_note
            if note:
                self._window.statusBar().showMessage(note, 15000)
        panel.model_edited()
        # also after a failed edit: the widgets must show the session again
        self.refresh()

    def _reset(self) -> None:
        panel = self.family_panel
        self._edit("Reset model", lambda: self.session.reset_model())
        panel.model_edited()

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
class DisplayPanel(Panel):
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
class ScenePanel(Panel):
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
            detail = FAMILY_PANELS[s.kind].summary(s)
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
