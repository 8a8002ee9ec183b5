"""The settings of new models in the Model group: backend, resolution, integrator,
variant, stiffness and the element grid's margin and boundary conditions (anchor,
region).

They are the session's settings (shared by the families: the resolution is that of the
elements and of the lattice), so there is one widget each; a family panel names the rows
its families show (:attr:`FamilyPanel.options`). Usage: ``ModelOptions(form)`` adds the
rows to the Model group's form; ``settings()`` is the keywords of
:meth:`EditSession.set_deformation`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from PySide6.QtWidgets import QFormLayout, QWidget

from voxwarp.deform.elements.anchors import ANCHOR_CHOICES, AUTO, DEFAULT, MODEL_DEFAULT
from voxwarp.deform.elements.margin import AUTO_MARGIN, AUTO_MARGIN_FRACTION, auto_margin
from voxwarp.editing.session import BACKENDS, CHAINMAIL_VARIANTS, INTEGRATORS, EditSession
from voxwarp.ui.panel_base import combo, double_spin, int_spin

__all__ = ["ModelOptions"]


class ModelOptions:
    """The option rows of the Model group (``form``), all built, shown as asked."""

    def __init__(self, form: QFormLayout) -> None:
        self._form = form
        self.backend_combo = combo(BACKENDS, "Where mass-spring and ChainMail run")
        self.resolution_spin = int_spin(
            2,
            32,
            "Elements per axis (mass-spring, ChainMail); lattice: cells + 1 per axis"
            " (at most 8 cells)",
        )
        self.integrator_combo = combo(INTEGRATORS, "Mass-spring time integration")
        self.variant_combo = combo(CHAINMAIL_VARIANTS, "ChainMail variant")
        self.stiffness_spin = double_spin(
            0.01, 1.0, 0.05, 2, tooltip="Element stiffness of new models (0..1]"
        )
        self.margin_spin = double_spin(-1.0, 1000.0, 5.0, 1, suffix=" mm")
        self.margin_spin.setSpecialValueText(AUTO_MARGIN)  # -1
        self.margin_spin.setToolTip(_margin_tooltip(None))
        self.anchor_combo = combo(
            ANCHOR_CHOICES,
            "Elements fixed at rest: default (the model's: shell for mass-spring, corners for"
            " ChainMail, whose drags stay local by themselves), shell (the grid's outer faces,"
            " so a springy drag stays local), corners (the thesis's 8: a mass-spring drag"
            " moves everything) or none",
        )
        self.region_spin = double_spin(
            -1.0,
            1000.0,
            5.0,
            0,
            " mm",
            "Region of influence: elements farther than this from every dragged element"
            " are anchored at rest (drawn in their own colour); auto: the larger of 30 mm,"
            " 4 element spacings and 3 x the drag; 0: off",
        )
        self.region_spin.setSpecialValueText(AUTO)
        #: option name -> its widget, in the order of the rows
        self.widgets: dict[str, QWidget] = {
            "backend": self.backend_combo,
            "resolution": self.resolution_spin,
            "integrator": self.integrator_combo,
            "variant": self.variant_combo,
            "stiffness": self.stiffness_spin,
            "margin": self.margin_spin,
            "anchor": self.anchor_combo,
            "fix_outside": self.region_spin,
        }
        for name, widget in self.widgets.items():
            form.addRow(_ROW_LABELS.get(name, name.capitalize()), widget)

    def settings(self) -> dict[str, Any]:
        """The chosen settings (keywords of :meth:`EditSession.set_deformation`)."""
        return {
            "backend": self.backend_combo.currentText(),
            "resolution": int(self.resolution_spin.value()),
            "integrator": self.integrator_combo.currentText(),
            "variant": self.variant_combo.currentText(),
            "stiffness": float(self.stiffness_spin.value()),
            "margin": _margin_setting(self.margin_spin.value()),
            "anchor": self.anchor_combo.currentText(),
            "fix_outside": AUTO if self.region_spin.value() < 0 else self.region_spin.value(),
        }

    def refresh(self, s: EditSession) -> None:
        """Show the session's settings (call inside the panel's refresh guard)."""
        self.backend_combo.setCurrentText(s.backend)
        self.resolution_spin.setValue(int(max(s.resolution)))
        self.integrator_combo.setCurrentText(s.options.integrator)
        self.variant_combo.setCurrentText(s.options.variant)
        self.stiffness_spin.setValue(s.options.stiffness)
        margin = s.options.margin
        self.margin_spin.setValue(-1.0 if margin == AUTO_MARGIN else float(margin))
        self.margin_spin.setToolTip(_margin_tooltip(_margin_in_use(s)))
        self.anchor_combo.setCurrentText(s.options.anchor)
        self.region_spin.setValue(_region_value(s.options.anchor, s.options.fix_outside))

    def show_only(self, names: tuple[str, ...]) -> None:
        """Show the rows of the options ``names``, hide the others."""
        for name, widget in self.widgets.items():
            self._form.setRowVisible(widget, name in names)


#: row labels that are not the option's name capitalised
_ROW_LABELS = {"anchor": "Anchor", "fix_outside": "Fix outside"}


def _margin_setting(value: float) -> float | str:
    """The margin setting of the spin box's value: -1 (shown ``auto``) is ``"auto"``."""
    return AUTO_MARGIN if value < 0 else float(value)


def _margin_in_use(s: EditSession) -> float:
    """The margin (mm) of the running element model's grid, else the one the session's
    setting gives a new model over its volume's box."""
    grid = getattr(getattr(s.family, "model", None), "grid", None)
    if grid is not None:
        return float(grid.margin)
    if s.options.margin != AUTO_MARGIN:
        return float(s.options.margin)
    lo, hi = (np.asarray(b, dtype=np.float64) for b in s.volume.bounds)
    return auto_margin(hi - lo)


def _margin_tooltip(in_use: float | None) -> str:
    """The Margin row's tooltip, naming the margin in mm in use (when known)."""
    now = "" if in_use is None else f"In use: {in_use:.1f} mm. "
    return (
        f"{now}Grid margin (mm): the element grid reaches this far beyond the volume's box,"
        " so content dragged across a face is carried out and drawn there. auto (the"
        f" default): {AUTO_MARGIN_FRACTION:.0%} of the volume box's largest side; 0: the"
        " volume's box. A margin as large as the largest drag keeps everything"
    )


def _region_value(anchor: str, fix_outside: float | str | None) -> float:
    """The region spin box's value of a setting: -1 shows ``auto``, 0 off."""
    if fix_outside == DEFAULT:
        fix_outside = AUTO if anchor in ("shell", MODEL_DEFAULT) else None
    if fix_outside == AUTO:
        return -1.0
    return 0.0 if fix_outside is None else float(fix_outside)
