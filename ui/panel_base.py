"""The base of the dock panels and the small widget helpers they share.

:class:`Panel` is the plumbing of every panel of :mod:`voxwarp.ui.panels` and of the
family panels of :mod:`voxwarp.ui.family_panels`: the window, its session, the refresh
guard and edits (see the module docstring of :mod:`voxwarp.ui.panels` for the window's
contract). The helpers build compact spin and combo boxes.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
from PySide6.QtCore import QSize, Qt
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

__all__ = ["Panel", "combo", "double_spin", "int_spin", "set_combo_data", "value_decimals"]


# ---------------------------------------------------------------------------- helpers
def double_spin(
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
