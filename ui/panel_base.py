"""The base of the dock panels and the small widget helpers they share.

:class:`Panel` is the plumbing of every panel of :mod:`voxwarp.ui.panels` and of the
family panels of :mod:`voxwarp.ui.family_panels`: the window, its session, the refresh
guard and edits (see the module docstring of :mod:`voxwarp.ui.panels` for the window's
contract). The helpers build compact spin and combo boxes.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
from PySide6.QtCore import QSize, Qt
from PySide6.QtGui import QValidator
from PySide6.QtWidgets import (
    QComboBox,
    QDoubleSpinBox,
    QFrame,
    QScrollArea,
    QSizePolicy,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from voxwarp.editing.session import EditSession

__all__ = [
    "AXIS_LETTERS",
    "AxisSpinBox",
    "Panel",
    "axis_names",
    "axis_spin",
    "combo",
    "double_spin",
    "int_spin",
    "is_oriented",
    "set_combo_data",
    "value_decimals",
]

#: Patient letters of the RAS world axes: (positive end, negative end) per axis.
AXIS_LETTERS: tuple[tuple[str, str], ...] = (("R", "L"), ("A", "P"), ("S", "I"))


def is_oriented(volume: Any) -> bool:
    """Whether ``volume``'s world is patient RAS (its coordinates get letters)."""
    return getattr(volume, "space", "") == "RAS"


def axis_names(volume: Any) -> list[tuple[str, tuple[str, str] | None]]:
    """Per world axis: its row/column label and its (positive, negative) letters.

    An oriented volume gets ``"L–R"``, ``"P–A"``, ``"I–S"`` (from low to high values)
    and letters; others ``"x"``, ``"y"``, ``"z"`` and None.
    """
    if not is_oriented(volume):
        return [(a, None) for a in ("x", "y", "z")]
    return [(f"{neg}–{pos}", (pos, neg)) for pos, neg in AXIS_LETTERS]


# ---------------------------------------------------------------------------- helpers
def double_spin(
    lo: float,
    hi: float,
    step: float,
    decimals: int = 2,
    suffix: str = "",
    tooltip: str = "",
    spin: QDoubleSpinBox | None = None,
) -> QDoubleSpinBox:
    """A compact double spin box that reports a value only when typing is finished
    (``spin``: set up this one, e.g. an :class:`AxisSpinBox`, instead of a new one)."""
    spin = QDoubleSpinBox() if spin is None else spin
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


class AxisSpinBox(QDoubleSpinBox):
    """A spin box of a world coordinate along one axis (mm); with patient letters it
    shows the value as a distance towards an anatomical side, as radiology viewers do:
    ``R 12.0`` for x = +12, ``L 80.0`` for x = -80 (RAS world). The value stays the
    signed world coordinate; typing ``L 80``, ``-80`` or ``R 12`` all work.
    """

    _NUMBER = re.compile(r"^\s*([A-Za-z])?\s*([+-]?(?:\d+\.?\d*|\.\d+)?)\s*$")

    def __init__(self) -> None:
        super().__init__()
        self._letters: tuple[str, str] | None = None

    @property
    def letters(self) -> tuple[str, str] | None:
        """(positive, negative) letters, or None (plain signed numbers)."""
        return self._letters

    def set_letters(self, letters: tuple[str, str] | None) -> None:
        """Show values with these (positive, negative) letters, or plain (None)."""
        if letters != self._letters:
            self._letters = letters
            # the shown text follows the new letters
            blocked = self.blockSignals(True)
            self.lineEdit().setText(
                self.prefix() + self.textFromValue(self.value()) + self.suffix()
            )
            self.blockSignals(blocked)

    def textFromValue(self, value: float) -> str:
        """``"R 12.00"`` / ``"L 80.00"`` with letters, else the plain number."""
        if self._letters is None:
            return super().textFromValue(value)
        d = self.decimals()
        if abs(value) < 0.5 * 10.0**-d:
            return f"{0.0:.{d}f}"
        letter = self._letters[0] if value > 0 else self._letters[1]
        return f"{letter} {abs(value):.{d}f}"

    def _parse(self, text: str) -> float | str | None:
        """The value of ``text`` (prefix/suffix allowed), None when it cannot become
        one, ``"partial"`` when it may after more typing."""
        t = text
        if self.suffix() and t.endswith(self.suffix()):
            t = t[: -len(self.suffix())]
        elif self.suffix().strip() and t.rstrip().endswith(self.suffix().strip()):
            t = t.rstrip()[: -len(self.suffix().strip())]
        m = self._NUMBER.match(t)
        if m is None:
            return None
        letter, number = m.group(1), m.group(2)
        sign = 1.0
        if letter is not None:
            letter = letter.upper()
            if self._letters is None or letter not in self._letters:
                return None
            sign = 1.0 if letter == self._letters[0] else -1.0
            if number.startswith(("+", "-")):
                return None
        if number in ("", "+", "-", "."):
            return "partial"
        return sign * float(number)

    def valueFromText(self, text: str) -> float:
        """The signed world coordinate of ``text`` (``"L 80"`` -> -80)."""
        v = self._parse(text)
        return float(v) if isinstance(v, float) else self.value()

    def validate(self, text: str, pos: int) -> Any:
        """Acceptable: a value in range; intermediate: on the way to one."""
        v = self._parse(text)
        if v is None:
            return (QValidator.State.Invalid, text, pos)
        if v == "partial" or not (self.minimum() <= float(v) <= self.maximum()):
            return (QValidator.State.Intermediate, text, pos)
        return (QValidator.State.Acceptable, text, pos)


def axis_spin(
    lo: float, hi: float, step: float, decimals: int = 2, suffix: str = "", tooltip: str = ""
) -> AxisSpinBox:
    """A compact :class:`AxisSpinBox` (see :func:`double_spin`)."""
    spin = AxisSpinBox()
    double_spin(lo, hi, step, decimals, suffix, tooltip, spin=spin)
    return spin


def int_spin(lo: int, hi: int, tooltip: str = "") -> QSpinBox:
    """An integer spin box that reports a value only when typing is finished."""
    spin = QSpinBox()
    spin.setRange(lo, hi)
    spin.setKeyboardTracking(False)
    if tooltip:
        spin.setToolTip(tooltip)
    return spin


def combo(items: tuple[str, ...] | list[str], tooltip: str = "") -> QComboBox:
    """A combo box offering ``items`` (read with ``currentText()``)."""
    box = QComboBox()
    box.addItems(list(items))
    if tooltip:
        box.setToolTip(tooltip)
    return box


def set_combo_data(box: QComboBox, value: Any) -> None:
    """Select the entry whose item data equals ``value`` (no change when none does)."""
    for i in range(box.count()):
        if box.itemData(i) == value:
            box.setCurrentIndex(i)
            return


def value_decimals(span: float) -> int:
    """Decimals that show about three significant digits of a value range ``span``."""
    if not math.isfinite(span) or span <= 0:
        return 3
    return int(np.clip(3 - math.floor(math.log10(span)), 0, 6))


# ---------------------------------------------------------------------------- panel
class Panel(QWidget):
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
