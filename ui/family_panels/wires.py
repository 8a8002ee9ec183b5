"""The panel of the wires family: the selected wire's curve, radius, object
classification, twist and scale keys, the field resolution, laying and removing wires,
and the window's "Lay a New Wire" (W) and "Finish Wire" (Return) actions.

A new wire is laid through the adapter's generic placing (``Family.start_placing``; the
viewport hands clicks to ``place_point``) and finished with this panel's curve and
radius. The wire edits rebuild the wire field off the GUI thread
(``window.request_field_build``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QPushButton,
)

from voxwarp.deform.wires.field import ENDS, SIDES, VACATED
from voxwarp.editing.families.wires import WiresFamily
from voxwarp.editing.session import WIRE_KINDS, EditorError, EditSession
from voxwarp.ui.family_panels.base import FamilyPanel, PanelAction
from voxwarp.ui.panel_base import combo, double_spin, value_decimals

__all__ = ["FIELD_SCALES", "WiresPanel", "wire_of_handle"]

#: Per-axis reductions of the wire attribute field offered (``wire_settings["field_scale"]``).
FIELD_SCALES: tuple[int, ...] = (1, 2, 4, 8, 16)


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
    for w, wire in enumerate(session.adapter(WiresFamily).wires):
        n = len(wire.modified.control_points)
        if index < n:
            return w, index
        index -= n
    return None


class WiresPanel(FamilyPanel):
    """The wire group: edits the wire of the reference (or last selected) control point."""

    labels: ClassVar[dict[str, str]] = {"wires": "wires"}
    options: ClassVar[dict[str, tuple[str, ...]]] = {"wires": ()}
    editable = True
    exposed = (
        "wire_group",
        "wire_label",
        "wire_kind_combo",
        "radius_spin",
        "wire_ends_combo",
        "wire_sides_combo",
        "side_falloff_spin",
        "wire_vacated_combo",
        "beta_check",
        "beta_lo_spin",
        "beta_hi_spin",
        "twist_spin",
        "scale_spin",
        "set_key_button",
        "field_scale_combo",
        "lay_button",
        "finish_button",
        "remove_wire_button",
        "wire_kind",
        "wire_radius",
        "_set_wire_key",
    )

    def _build(self) -> None:
        self._fraction_cache: tuple[Any, ...] | None = None
        self._fraction: float | None = None
        self._beta_volume: Any = None
        self.wire_group = QGroupBox("Wires")
        form = QFormLayout(self.wire_group)
        form.setFieldGrowthPolicy(QFormLayout.FieldGrowthPolicy.AllNonFixedFieldsGrow)
        self.wire_label = QLabel()
        self.wire_label.setWordWrap(True)
        form.addRow(self.wire_label)
        self._build_curve_rows(form)
        self._build_key_rows(form)
        self._build_field_row(form)
        self._build_new_wire_rows(form)
        self.add_group(self.wire_group)

    def _build_side_rows(self, form: QFormLayout) -> None:
        """Sides, side falloff and vacated place of the selected wire."""
        self.wire_sides_combo = combo(
            SIDES,
            "Around the selected wire's radius: smooth moves everything within radius +"
            " falloff (the surroundings stretch, nothing is left empty); rigid is the"
            " paper's sweep of the masked object (its old place is vacated)",
        )
        self.wire_sides_combo.currentTextChanged.connect(self._sides_changed)
        form.addRow("Sides", self.wire_sides_combo)
        self.side_falloff_spin = double_spin(
            0.0,
            1e5,
            1.0,
            2,
            " mm",
            "Width of the smooth sides' fade beyond the radius; 0: the default (the radius,"
            " or twice the wire's largest move if longer: narrower fades fold)",
        )
        self.side_falloff_spin.setSpecialValueText("default")
        self.side_falloff_spin.valueChanged.connect(self._side_falloff_changed)
        form.addRow("Side falloff", self.side_falloff_spin)
        self.wire_vacated_combo = combo(
            VACATED,
            "With rigid sides: what the swept object's old place shows: empty (the"
            " paper) or rest (its unmoved content)",
        )
        self.wire_vacated_combo.currentTextChanged.connect(self._vacated_changed)
        form.addRow("Vacated", self.wire_vacated_combo)

    def _build_curve_rows(self, form: QFormLayout) -> None:
        """Curve kind, radius and object classification of the selected wire."""
        self.wire_kind_combo = combo(
            WIRE_KINDS, "Curve of the selected wire (and of the next wire laid)"
        )
        self.wire_kind_combo.currentTextChanged.connect(self._wire_kind_changed)
        form.addRow("Curve", self.wire_kind_combo)
        self.radius_spin = double_spin(
            0.01,
            1e5,
            1.0,
            2,
            " mm",
            "Region of influence of the selected wire (and of the next wire laid)",
        )
        self.radius_spin.valueChanged.connect(self._radius_changed)
        form.addRow("Radius", self.radius_spin)
        self.wire_ends_combo = combo(
            ENDS,
            "Past the selected wire's ends and radius: smooth fades the sweep out (an object"
            " the wire ends in bends); rigid is the paper's sweep (it cuts there)",
        )
        self.wire_ends_combo.currentTextChanged.connect(self._ends_changed)
        form.addRow("Ends", self.wire_ends_combo)
        self._build_side_rows(form)
        self.beta_check = QCheckBox("Object classification")
        self.beta_check.setToolTip(
            "β: only voxels with values in [low, high] follow the selected wire;"
            " unchecked: everything within the radius"
        )
        self.beta_check.toggled.connect(self._beta_toggled)
        form.addRow(self.beta_check)
        row = QHBoxLayout()
        self.beta_lo_spin = double_spin(-1e9, 1e9, 1.0, 3, tooltip="Lowest value of the object")
        self.beta_hi_spin = double_spin(-1e9, 1e9, 1.0, 3, tooltip="Highest value of the object")
        self.beta_lo_spin.valueChanged.connect(self._beta_range_changed)
        self.beta_hi_spin.valueChanged.connect(self._beta_range_changed)
        row.addWidget(self.beta_lo_spin)
        row.addWidget(QLabel("–"))
        row.addWidget(self.beta_hi_spin)
        form.addRow("β range", row)

    def _build_key_rows(self, form: QFormLayout) -> None:
        """Twist and scale keyed at the reference control point."""
        self.twist_spin = double_spin(
            -720.0, 720.0, 5.0, 1, "°", "Twist about the wire at the reference control point"
        )
        form.addRow("Twist", self.twist_spin)
        self.scale_spin = double_spin(
            0.05, 20.0, 0.05, 2, tooltip="Cross-section scale at the reference control point"
        )
        form.addRow("Scale", self.scale_spin)
        self.set_key_button = QPushButton("Set at point")
        self.set_key_button.setToolTip(
            "Key this twist and scale at the reference control point (select one first)"
        )
        self.set_key_button.clicked.connect(self._set_wire_key)
        form.addRow(self.set_key_button)

    def _build_field_row(self, form: QFormLayout) -> None:
        self.field_scale_combo = QComboBox()
        for s in FIELD_SCALES:
            self.field_scale_combo.addItem(f"1/{s}" if s > 1 else "full", s)
        self.field_scale_combo.setToolTip(
            "Resolution of the wire attribute field per axis (coarser builds faster)"
        )
        self.field_scale_combo.currentIndexChanged.connect(self._field_scale_changed)
        form.addRow("Field resolution", self.field_scale_combo)

    def _build_new_wire_rows(self, form: QFormLayout) -> None:
        """Lay a new wire, finish it, remove the selected wire."""
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

    # ---------------------------------------------------------------- per family
    @classmethod
    def summary(cls, s: EditSession) -> str:
        """The family and its number of wires."""
        n = len(s.adapter(WiresFamily).wires)
        return f"{super().summary(s)}, {n} wire{'s' if n != 1 else ''}"

    def timing_parts(self, timings: dict[str, float]) -> list[str]:
        """The last wire-field build."""
        field = timings.get("field")
        return [] if field is None else [f"field {field:.0f} ms"]

    def model_edited(self) -> None:
        """New or reset wires: rebuild their field."""
        self._window.request_field_build()

    # ---------------------------------------------------------------- new wires
    def window_actions(self) -> list[PanelAction]:
        """Lay a New Wire (W) and Finish Wire (Return) in the Deformation menu."""
        return [
            PanelAction(
                "Lay a New &Wire",
                self.start_wire,
                "W",
                ("W", "lay a new wire (click points; Enter finishes, Esc cancels)"),
            ),
            PanelAction("&Finish Wire", self.finish_wire, "Return"),
        ]

    def start_wire(self) -> None:
        """Lay a new wire (switching to the wire family first): the next clicks in the
        viewport lay its control points."""
        if self.session.kind != "wires":
            self._edit("Wire field", lambda: self.session.set_deformation("wires"))
        self.session.family.start_placing()
        self._window.statusBar().showMessage(
            "Click control points of the new wire; Enter finishes", 5000
        )
        self._window.refresh_panels()

    def finish_wire(self) -> None:
        """Make the laid points a wire with the curve and radius of the wire group (one
        undo step, "New wire"); nothing unless a wire is being laid."""
        if not self._laying():
            return
        kind, radius = self.wire_kind(), self.wire_radius()
        self._edit("New wire", lambda: self.session.family.finish_placing(kind=kind, radius=radius))

    def wire_kind(self) -> str:
        """Curve kind chosen in the wire group (for :meth:`WiresFamily.finish_wire`)."""
        return self.wire_kind_combo.currentText()

    def wire_radius(self) -> float:
        """Radius (mm) chosen in the wire group (for :meth:`WiresFamily.finish_wire`)."""
        return float(self.radius_spin.value())

    # ---------------------------------------------------------------- refresh
    def _current_wire(self, s: EditSession) -> tuple[int, int | None] | None:
        """(wire, control point or None) the wire widgets edit: that of the reference or
        the last selected handle, else wire 0; None without wires."""
        if not s.adapter(WiresFamily).wires:
            return None
        for handle in (s.reference, s.selection[-1] if s.selection else None):
            hit = wire_of_handle(s, handle)
            if hit is not None:
                return hit
        return 0, None

    def _reference_fraction(self, s: EditSession) -> float | None:
        """Fraction of its wire's length at the reference control point (cached)."""
        hit = wire_of_handle(s, s.reference)
        if hit is None:
            return None
        key = (
            id(s),
            s.reference,
            s.adapter(WiresFamily).generation,
            len(s.adapter(WiresFamily).wires),
        )
        if key != self._fraction_cache:
            curve = s.adapter(WiresFamily).wires[hit[0]].modified
            t, _ = curve.closest_point(curve.control_points[hit[1]])
            t = float(np.asarray(t).reshape(-1)[0])
            total = curve.arc_length()
            self._fraction = (
                0.0 if total <= 0 else float(np.clip(curve.arc_length(t1=t) / total, 0.0, 1.0))
            )
            self._fraction_cache = key
        return self._fraction

    def refresh(self, s: EditSession) -> None:
        """Show the current wire, the new wire being laid and the field resolution."""
        with self._refreshing():
            current = self._current_wire(s)
            self._refresh_common(s, current)
            if current is None:
                self.wire_label.setText("No wires.")
                return
            self._refresh_wire(s, *current)

    def _refresh_common(self, s: EditSession, current: tuple[int, int | None] | None) -> None:
        """Buttons, field resolution and the ranges of the spins."""
        self.lay_button.setChecked(self._laying())
        self.finish_button.setEnabled(len(s.adapter(WiresFamily).pending_wire) > 0)
        self.field_scale_combo.setCurrentIndex(
            max(
                0,
                self.field_scale_combo.findData(int(s.options.wire_settings.get("field_scale", 2))),
            )
        )
        lo, hi = s.volume.value_range
        span = max(hi - lo, 1e-6)
        decimals = value_decimals(span)
        for spin in (self.beta_lo_spin, self.beta_hi_spin):
            spin.setDecimals(decimals)
            spin.setSingleStep(max(span / 100.0, 10.0**-decimals))
            spin.setRange(lo - span, hi + span)
        extent = float(np.max(s.box[1] - s.box[0]))
        self.radius_spin.setSingleStep(max(extent / 100.0, 0.01))
        self.radius_spin.setMaximum(max(10.0 * extent, 1.0))
        self.remove_wire_button.setEnabled(
            current is not None and len(s.adapter(WiresFamily).wires) > 1
        )
        self.set_key_button.setEnabled(current is not None and current[1] is not None)

    def _laying(self) -> bool:
        """Whether a new wire is being laid (the adapter's generic placing)."""
        return self.session.kind == "wires" and self.session.family.placing

    def _refresh_wire(self, s: EditSession, w: int, point: int | None) -> None:
        """The label, curve, radius, classification and keys of wire ``w``."""
        wire = s.adapter(WiresFamily).wires[w]
        laying, pending = self._laying(), len(s.adapter(WiresFamily).pending_wire)
        where = f", point {point + 1}" if point is not None else " (click a point to pick)"
        text = f"Wire {w + 1} of {len(s.adapter(WiresFamily).wires)}{where}"
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
        self.wire_ends_combo.setCurrentText(wire.ends)
        self.wire_sides_combo.setCurrentText(wire.sides)
        self.side_falloff_spin.setValue(wire.side_falloff_mm or 0.0)
        self.side_falloff_spin.setEnabled(wire.smooth_sides)
        self.wire_vacated_combo.setCurrentText(wire.vacated)
        self.wire_vacated_combo.setEnabled(not wire.smooth_sides)
        self._refresh_beta(s, wire)
        fraction = self._reference_fraction(s) if point is not None else None
        if fraction is not None:
            self.twist_spin.setValue(math.degrees(float(wire.twist_at(fraction))))
            self.scale_spin.setValue(float(wire.scale_at(fraction)))

    def _refresh_beta(self, s: EditSession, wire: Any) -> None:
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
            lo, hi = s.volume.value_range
            self.beta_lo_spin.setValue(lo)
            self.beta_hi_spin.setValue(hi)
        self._beta_volume = s.volume
        self.beta_lo_spin.setEnabled(beta is not None)
        self.beta_hi_spin.setEnabled(beta is not None)

    # ---------------------------------------------------------------- handlers
    def _wire_edit(self, text: str, fn: Callable[[], Any], merge: str | None = None) -> Any:
        """An edit of the wires, then a rebuild of their field off the GUI thread."""
        result = self._edit(text, fn, merge)
        self._window.request_field_build()
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
            or self.session.adapter(WiresFamily).wires[w].kind == kind
        ):
            return
        self._wire_edit(
            f"Wire curve {kind}",
            lambda: self.session.adapter(WiresFamily).set_wire_parameters(w, kind=kind),
        )

    def _radius_changed(self, radius: float) -> None:
        w = self._wire_index()
        if self._updating or self.lay_button.isChecked() or w is None:
            return
        self._wire_edit(
            "Wire radius",
            lambda: self.session.adapter(WiresFamily).set_wire_parameters(w, radius=float(radius)),
            merge=f"wire radius {w}",
        )

    def _ends_changed(self, ends: str) -> None:
        w = self._wire_index()
        if self._updating or w is None or self.session.adapter(WiresFamily).wires[w].ends == ends:
            return
        self._wire_edit(
            f"Wire ends {ends}",
            lambda: self.session.adapter(WiresFamily).set_wire_parameters(w, ends=ends),
        )

    def _sides_changed(self, sides: str) -> None:
        w = self._wire_index()
        if self._updating or w is None or self.session.adapter(WiresFamily).wires[w].sides == sides:
            return
        self._wire_edit(
            f"Wire sides {sides}",
            lambda: self.session.adapter(WiresFamily).set_wire_parameters(w, sides=sides),
        )

    def _side_falloff_changed(self, mm: float) -> None:
        w = self._wire_index()
        if self._updating or w is None:
            return
        value = float(mm) if mm > 0 else None
        self._wire_edit(
            "Wire side falloff",
            lambda: self.session.adapter(WiresFamily).set_wire_parameters(w, side_falloff=value),
            merge=f"wire side falloff {w}",
        )

    def _vacated_changed(self, vacated: str) -> None:
        w = self._wire_index()
        wires = self.session.adapter(WiresFamily).wires
        if self._updating or w is None or wires[w].vacated == vacated:
            return
        self._wire_edit(
            f"Wire vacated {vacated}",
            lambda: self.session.adapter(WiresFamily).set_wire_parameters(w, vacated=vacated),
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
            lambda: self.session.adapter(WiresFamily).set_wire_parameters(w, beta=beta),
            merge=f"wire beta {w}" if on else None,
        )

    def _set_wire_key(self) -> None:
        twist = math.radians(float(self.twist_spin.value()))
        scale = float(self.scale_spin.value())

        def fn() -> None:
            s = self.session
            if wire_of_handle(s, s.reference) is None:
                raise EditorError("select a control point of a wire first (click it)")
            s.adapter(WiresFamily).set_wire_key(s.reference, twist=twist, scale=scale)

        self._wire_edit("Wire twist and scale", fn)

    def _field_scale_changed(self, _index: int) -> None:
        if self._updating:
            return
        scale = int(self.field_scale_combo.currentData())

        def fn() -> None:
            self.session.adapter(WiresFamily).set_wire_settings(field_scale=scale)

        self._wire_edit(f"Wire field 1/{scale}", fn)

    def _lay_toggled(self, on: bool) -> None:
        if self._updating:
            return
        if on:
            self.session.adapter(WiresFamily).start_placing()
        else:  # paused: the laid points stay (Finish wire makes them a wire)
            self.session.adapter(WiresFamily).placing = False
        self._refresh_host()

    def _finish_wire(self) -> None:
        kind, radius = self.wire_kind(), self.wire_radius()
        result = self._wire_edit(
            "New wire", lambda: self.session.adapter(WiresFamily).finish_wire(kind, radius)
        )
        if result is not None:
            self.session.adapter(WiresFamily).placing = False
            self._refresh_host()

    def _remove_wire(self) -> None:
        w = self._wire_index()
        if w is None:
            return
        self._wire_edit(
            f"Remove wire {w + 1}", lambda: self.session.adapter(WiresFamily).remove_wire(w)
        )
