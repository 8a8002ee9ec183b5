"""The panel of the element families, mass-spring and ChainMail: the simulation group
(run or pause, single step, steps per frame or relaxation steps, fix or free elements;
ChainMail: cut the links around the selection, join cut links where they touch, or
pull the sides together and join them all).
"""

from __future__ import annotations

from typing import ClassVar

from PySide6.QtWidgets import (
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QSpinBox,
    QWidget,
)

from voxwarp.editing.session import EditorError, EditSession
from voxwarp.ui.family_panels.base import FamilyPanel
from voxwarp.ui.panel_base import int_spin

__all__ = ["ElementsPanel"]

#: options of the Model group, shared by both element families
_SHARED = ("backend", "resolution", "stiffness", "margin", "anchor", "fix_outside")


class ElementsPanel(FamilyPanel):
    """Simulation of a mass-spring or ChainMail model (one panel for both families)."""

    labels: ClassVar[dict[str, str]] = {"massspring": "mass-spring", "chainmail": "ChainMail"}
    options: ClassVar[dict[str, tuple[str, ...]]] = {
        "massspring": (*_SHARED, "integrator"),
        "chainmail": (*_SHARED, "variant"),
    }
    #: family name -> the run-time option (session) of the simulation group it shows
    run_options: ClassVar[dict[str, str]] = {
        "massspring": "steps_per_frame",
        "chainmail": "relax_steps",
    }
    editable = True
    exposed = (
        "simulation_group",
        "simulation_form",
        "run_button",
        "step_button",
        "steps_spin",
        "relax_spin",
        "fix_button",
        "free_button",
        "cut_button",
        "join_button",
        "pull_button",
        "boundary_label",
    )

    def _build(self) -> None:
        self.simulation_group = QGroupBox("Simulation")
        form = QFormLayout(self.simulation_group)
        form.setFieldGrowthPolicy(QFormLayout.FieldGrowthPolicy.AllNonFixedFieldsGrow)
        self.simulation_form = form
        form.addRow(self._run_row())
        self.steps_spin = self._option_spin(
            "steps_per_frame", 1000, "Mass-spring steps per frame while running"
        )
        form.addRow("Steps per frame", self.steps_spin)
        self.relax_spin = self._option_spin(
            "relax_steps", 16, "ChainMail relaxation steps per frame while running"
        )
        form.addRow("Relax steps", self.relax_spin)
        form.addRow(self._fix_row())
        self.cut_row = self._cut_row()
        form.addRow(self.cut_row)
        self.boundary_label = QLabel()
        self.boundary_label.setWordWrap(True)
        self.boundary_label.setToolTip(
            "Boundary conditions: fixed elements (red) and elements anchored by the region"
            " of influence of the drag (violet); Free selected frees either kind"
        )
        form.addRow("Boundary", self.boundary_label)
        self.add_group(self.simulation_group)

    def _run_row(self) -> QHBoxLayout:
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
        return row

    def _option_spin(self, name: str, most: int, tooltip: str) -> QSpinBox:
        """A spin box of the session's run-time option ``name`` (0..``most``)."""
        spin = int_spin(0, most, tooltip)
        spin.valueChanged.connect(lambda v: self._option_changed(name, v))
        return spin

    def _fix_row(self) -> QHBoxLayout:
        row = QHBoxLayout()
        self.fix_button = QPushButton("Fix selected")
        self.fix_button.setToolTip("The selected elements stay where they are")
        self.fix_button.clicked.connect(lambda: self._set_fixed(True))
        self.free_button = QPushButton("Free selected")
        self.free_button.setToolTip("The selected elements move again")
        self.free_button.clicked.connect(lambda: self._set_fixed(False))
        row.addWidget(self.fix_button)
        row.addWidget(self.free_button)
        return row

    def _cut_row(self) -> QWidget:
        row = QWidget()
        layout = QHBoxLayout(row)
        layout.setContentsMargins(0, 0, 0, 0)
        self.cut_button = QPushButton("Cut selected")
        self.cut_button.setToolTip(
            "Cut the links between the selected elements and the others: the selection"
            " comes loose and moves independently (links drawn no more)"
        )
        self.cut_button.clicked.connect(self._cut)
        self.join_button = QPushButton("Join selected")
        self.join_button.setToolTip(
            "Join the cut links at the selected elements where the two sides touch"
            " (within the link limits); links a drag pulled apart stay cut: drag the"
            " sides together first"
        )
        self.join_button.clicked.connect(lambda: self._join(False))
        self.pull_button = QPushButton("Pull and join")
        self.pull_button.setToolTip(
            "Join every cut link at the selected elements, dragging free elements until"
            " the two sides meet (a suture; held and fixed elements stay)"
        )
        self.pull_button.clicked.connect(lambda: self._join(True))
        for button in (self.cut_button, self.join_button, self.pull_button):
            layout.addWidget(button)
        return row

    # ---------------------------------------------------------------- per family
    @classmethod
    def summary(cls, s: EditSession) -> str:
        """The family and its element grid."""
        return cls.sized(s, s.model.grid.shape if s.model is not None else None, "elements")

    def show_family(self, kind: str) -> None:
        """Show the run-time option row of family ``kind`` only."""
        shown = self.run_options.get(kind)
        for name, spin in (("steps_per_frame", self.steps_spin), ("relax_steps", self.relax_spin)):
            self.simulation_form.setRowVisible(spin, name == shown)

    def refresh(self, s: EditSession) -> None:
        """Show whether the model runs, its run-time options and what the buttons can do."""
        with self._refreshing():
            self.run_button.setChecked(bool(s.running))
            self.run_button.setText("Pause" if s.running else "Run")
            self.steps_spin.setValue(s.options.steps_per_frame)
            self.relax_spin.setValue(s.options.relax_steps)
            for button in (self.fix_button, self.free_button, self.step_button):
                button.setEnabled(s.model is not None)
            self.simulation_form.setRowVisible(self.cut_row, s.family.can_cut)
            text = getattr(s.family, "boundary_text", None)
            self.boundary_label.setText(text() if callable(text) else "")

    def timing_parts(self, timings: dict[str, float]) -> list[str]:
        """The last model step."""
        step = timings.get("step")
        return [] if step is None else [f"step {step:.2f} ms"]

    # ---------------------------------------------------------------- handlers
    def _run_toggled(self, running: bool) -> None:
        self.run_button.setText("Pause" if running else "Run")
        if self._updating:
            return
        self._window.set_running(bool(running))

    def _single_step(self) -> None:
        self._edit("Single step", lambda: self.session.single_step())

    def _option_changed(self, name: str, value: int) -> None:
        """A run-time option of the session (one undo step per spin box drag)."""
        if self._updating:
            return
        label, merge = _OPTION_EDITS[name]
        self._edit(label, lambda: self.session.set_option(name, int(value)), merge=merge)

    def _set_fixed(self, fixed: bool) -> None:
        def fn() -> None:
            s = self.session
            if not s.selection:
                raise EditorError("select elements first (click or drag a rectangle)")
            s.set_fixed(s.selection, fixed)

        self._edit("Fix selected" if fixed else "Free selected", fn)

    def _cut(self) -> None:
        n = self._edit("Cut selected", lambda: self.session.cut_links(self.session.selection))
        if n is not None:
            self._window.statusBar().showMessage(f"Cut {n} link(s)", 6000)

    def _join(self, pull: bool) -> None:
        s = self.session
        text = "Pull and join" if pull else "Join selected"
        done = self._edit(text, lambda: s.join_links(s.selection, pull))
        if done is not None:
            joined, left = done
            more = f"; {left} stay cut (stretched apart: drag them together)" if left else ""
            self._window.statusBar().showMessage(f"Joined {joined} link(s){more}", 8000)


#: run-time option -> (undo text, merge key) of its edits
_OPTION_EDITS = {
    "steps_per_frame": ("Steps per frame", "steps per frame"),
    "relax_steps": ("Relaxation steps", "relax steps"),
}
