"""The interface of a deformation family's panel; the base class is the family "none".

A family panel holds the widgets only its family uses (the element model's simulation,
the wires, ...) and tells :class:`~voxwarp.ui.panels.DeformationPanel` what to show of
the common parts: which rows of the Model group (:mod:`voxwarp.ui.family_panels.options`)
and whether Apply, Reset and the placement are offered. It may also give the window
actions of its own (:meth:`FamilyPanel.window_actions`: menu entries with shortcuts, such
as the wire family's "Lay a New Wire"). One panel may serve several families (mass-spring
and ChainMail share :class:`ElementsPanel`); its :attr:`labels` name them. Register a new
panel in :data:`voxwarp.ui.family_panels.FAMILY_PANELS`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar, NamedTuple

from PySide6.QtWidgets import QGroupBox, QVBoxLayout, QWidget

from voxwarp.editing.session import EditSession
from voxwarp.ui.panel_base import Panel

__all__ = ["FamilyPanel", "PanelAction"]


class PanelAction(NamedTuple):
    """An action a family panel adds to the window's Deformation menu."""

    #: menu text (``&`` marks the mnemonic)
    text: str
    #: what it does (called without arguments)
    slot: Callable[[], Any]
    #: its shortcut (a ``QKeySequence`` string such as ``"W"``), or None
    shortcut: str | None = None
    #: its row of the keyboard help: (keys, what they do), or None
    help: tuple[str, str] | None = None


class FamilyPanel(Panel):
    """The panel of the family ``"none"`` (nothing to edit) and the base of the others.

    Built as ``Cls(window, refresh_host)`` by the deformation panel, which shows it while
    one of its families is current; ``refresh_host()`` refreshes the whole deformation
    panel. Subclasses add their group boxes in :meth:`_build` with :meth:`add_group`.
    """

    #: family name -> human name (model combo box, edit names, scene tree)
    labels: ClassVar[dict[str, str]] = {"none": "none"}
    #: family name -> the Model group's option rows it shows (``ModelOptions`` names)
    options: ClassVar[dict[str, tuple[str, ...]]] = {"none": ()}
    #: whether the family has a model to apply, reset and place
    editable: ClassVar[bool] = False
    #: attributes the deformation panel offers as its own (tests, the main window)
    exposed: ClassVar[tuple[str, ...]] = ()

    def __init__(
        self, window: Any, refresh_host: Callable[[], None], parent: QWidget | None = None
    ) -> None:
        super().__init__(window, parent)
        self._refresh_host = refresh_host
        self._layout = QVBoxLayout(self)
        self._layout.setContentsMargins(0, 0, 0, 0)
        self._build()

    def _build(self) -> None:
        """Build the family's widgets (none here)."""

    def add_group(self, box: QGroupBox) -> None:
        """Put a group box of the family below the Model group."""
        self._layout.addWidget(box)

    @property
    def has_groups(self) -> bool:
        """Whether the panel shows anything (an empty one stays hidden)."""
        return self._layout.count() > 0

    # ---------------------------------------------------------------- per family
    @classmethod
    def edit_name(cls, kind: str) -> str:
        """Undo text of choosing family ``kind``."""
        return f"New {cls.labels[kind]} model" if cls.editable else "No deformation"

    @classmethod
    def summary(cls, s: EditSession) -> str:
        """One line on the session's deformation (the scene tree's details)."""
        return cls.labels.get(s.kind, s.kind)

    @classmethod
    def sized(cls, s: EditSession, shape: Any, what: str) -> str:
        """:meth:`summary` of the family plus a grid size, e.g. "mass-spring, 8×8×8
        elements" (just the family when ``shape`` is None)."""
        text = cls.labels.get(s.kind, s.kind)
        if shape is None:
            return text
        return f"{text}, {'×'.join(str(n) for n in shape)} {what}"

    def window_actions(self) -> list[PanelAction]:
        """The panel's actions for the window's Deformation menu (none here). The window
        asks every panel once, when it builds its menus, so the actions and their
        shortcuts are there whatever family is current."""
        return []

    def show_family(self, kind: str) -> None:
        """Show the rows of family ``kind`` (for panels serving several families)."""

    # ---------------------------------------------------------------- refresh
    def refresh(self, s: EditSession) -> None:
        """Show the session's state of the family in the widgets (no edit)."""

    def timing_parts(self, timings: dict[str, float]) -> list[str]:
        """Texts of the family's timings (``session.timings``) for the timings label."""
        return []

    def model_edited(self) -> None:
        """After a new model or a reset of the family (a wire field is rebuilt)."""
