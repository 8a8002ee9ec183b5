"""Typed window/level for the slice views: a preset combo and level and width fields.

:class:`WindowLevelBar` edits the slice views' shared window (``mpr.state.window``): the
presets of the volume's modality (:func:`voxwarp.core.window_presets.presets_for`: the
CT reading windows lung, mediastinum, bone and brain for a CT in HU, the percentile
window for every volume), or a level and a width typed in data units. A right drag in a
slice view changes the window too; :meth:`WindowLevelBar.sync` shows it (the slice
layout calls it after each re-colouring). :func:`install_window_level` adds the bar as
a toolbar of the main window (``window.window_level``).
"""

from __future__ import annotations

from typing import Any

from PySide6.QtCore import QSignalBlocker
from PySide6.QtWidgets import QComboBox, QDoubleSpinBox, QHBoxLayout, QLabel, QWidget

from voxwarp.core.window_presets import preset_of, preset_window, presets_for
from voxwarp.errors import VoxwarpError

#: the combo's entry while the window is none of the presets
CUSTOM = "custom"
#: largest |level| and width the fields accept (data units; float CT/MR fit easily)
FIELD_LIMIT = 1e9


class WindowLevelBar(QWidget):
    """Preset, level and width of the slice views' window (see the module docstring).

    Parameters
    ----------
    mpr
        The :class:`~voxwarp.ui.mpr.SliceLayout` whose ``state.window`` it edits.
    """

    def __init__(self, mpr: Any, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.mpr = mpr
        self.preset = QComboBox()
        self.preset.setToolTip("window presets of the volume's modality (CT: HU windows)")
        self.level = self._field("level: the value shown mid-grey (data units)")
        self.width = self._field("width: the value range from black to white (data units)")
        self.width.setMinimum(1e-6)
        layout = QHBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        for label, widget in (("W/L ", self.preset), (" L ", self.level), (" W ", self.width)):
            layout.addWidget(QLabel(label))
            layout.addWidget(widget)
        self.preset.textActivated.connect(self.apply_preset)
        self.level.editingFinished.connect(self.apply_typed)
        self.width.editingFinished.connect(self.apply_typed)
        self.sync()

    def _field(self, tip: str) -> QDoubleSpinBox:
        box = QDoubleSpinBox()
        box.setRange(-FIELD_LIMIT, FIELD_LIMIT)
        box.setDecimals(1)
        box.setKeyboardTracking(False)
        box.setToolTip(tip)
        box.setMinimumWidth(72)
        return box

    def apply_preset(self, name: str) -> None:
        """Set the window to preset ``name`` of the volume (``custom``: no change)."""
        if name == CUSTOM:
            return
        try:
            window = preset_window(name, self.mpr.state.volume)
        except VoxwarpError as exc:
            self.mpr.window.show_error(str(exc))
            return
        self.set_window(window)

    def apply_typed(self) -> None:
        """Set the window to the typed level and width."""
        self.set_window((self.level.value(), self.width.value()))

    def set_window(self, window: tuple[float, float]) -> None:
        """Make ``window`` the slice views' window, re-colour them and show it here."""
        self.mpr.state.window = (float(window[0]), float(window[1]))
        self.mpr.recolor_all()  # calls sync()

    def sync(self) -> None:
        """Show the slice views' current window (after a drag, a reset, a new volume)."""
        state = self.mpr.state
        names = [*presets_for(state.volume), CUSTOM]
        name = preset_of(state.window, state.volume) or CUSTOM
        with QSignalBlocker(self.preset), QSignalBlocker(self.level), QSignalBlocker(self.width):
            if [self.preset.itemText(i) for i in range(self.preset.count())] != names:
                self.preset.clear()
                self.preset.addItems(names)
            self.preset.setCurrentText(name)
            self.level.setValue(float(state.window[0]))
            self.width.setValue(float(state.window[1]))


def install_window_level(window: Any) -> WindowLevelBar:
    """Add a "Window/Level" toolbar holding a :class:`WindowLevelBar` for
    ``window.mpr`` to the main ``window``; also kept as ``window.window_level``."""
    bar = window.addToolBar("Window/Level")
    bar.setObjectName("WindowLevel")
    widget = WindowLevelBar(window.mpr)
    bar.addWidget(widget)
    window.window_level = widget
    return widget
