"""The GUI's fixed image: a registration's fixed volume beside the moving one.

File › Open Fixed Image… loads a second volume (any grid; :mod:`voxwarp.core.comparison`).
The slice views then sample it on each plane (:meth:`FixedImage.fixed_values`) and the Show
choices ``rest`` (the fixed image), ``checkerboard`` (world cells of the checker size),
``difference`` and ``blend`` compare with it; the Compare toolbar's slider sets the
blend (0 = moving, 1 = fixed) and its 3D choice turns the raycaster's comparison on
(``scene.comparison``: checkerboard, difference or blend) or off; the toolbar sits at
the bottom of the window while a fixed image is open. File › Close Fixed Image drops
it. :func:`install_fixed_image` wires this into the main window.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtGui import QAction
from PySide6.QtWidgets import (
    QComboBox,
    QDoubleSpinBox,
    QFileDialog,
    QLabel,
    QSlider,
    QToolBar,
)

from voxwarp.core.comparison import COMPARE_SHOWS, Comparison, default_checker_mm
from voxwarp.core.volume import Volume
from voxwarp.errors import VoxwarpError
from voxwarp.render.slice_image import SliceImage
from voxwarp.scene import Scene

#: the 3D choice that leaves the raycaster on the moving image alone
OFF = "off"


class FixedImage:
    """The window's fixed image and its comparison settings (slices and 3D)."""

    def __init__(self, window: Any) -> None:
        self.window = window
        self.volume: Volume | None = None
        #: "off" or one of COMPARE_SHOWS: what the 3D view shows
        self.show_3d = OFF
        self.blend = 0.5
        self.checker_mm: float | None = None
        self._scene: Scene | None = None  # the fixed volume's own scene, for slices

    def open(self, path: str | Path) -> bool:
        """Load ``path`` as the fixed image; a one-line error dialog when it fails."""
        # loaded when used: the window opens without the readers
        from voxwarp.io.volumes import load_volume

        try:
            volume = load_volume(path)
        except (VoxwarpError, OSError) as exc:
            self.window.show_error(f"could not open the fixed image {Path(path).name}: {exc}")
            return False
        self.set_volume(volume)
        self.window.statusBar().showMessage(f"Fixed image: {Path(path).name}", 10000)
        return True

    def set_volume(self, volume: Volume | None) -> None:
        """Use ``volume`` as the fixed image (None: close it); redraw the views."""
        self.volume = volume
        self._scene = None
        if volume is not None and self.checker_mm is None:
            self.checker_mm = default_checker_mm(volume)
        if volume is None:
            self.show_3d = OFF
        self.apply()

    def set_option(self, name: str, value: Any) -> None:
        """Change ``show_3d``, ``blend`` or ``checker_mm`` and redraw."""
        setattr(self, name, value)
        self.apply()

    def comparison(self) -> Comparison | None:
        """The 3D comparison to draw (None: off or no fixed image)."""
        if self.volume is None or self.show_3d == OFF:
            return None
        return Comparison(self.volume, self.show_3d, self.blend, self.checker_mm)

    def apply(self) -> None:
        """Put the settings on the scene (3D) and redraw the slices and the 3D view."""
        self.window.session.scene.comparison = self.comparison()
        self.window.mpr.render_all()
        self.window.viewport.update()
        _sync(self.window)

    def fixed_values(self, renderer: Any, p2w: np.ndarray, size: Any, state: Any) -> Any:
        """(H, W) fixed values on a slice's pixels (None without a fixed image)."""
        if self.volume is None:
            return None
        if self._scene is None:
            tf = self.window.session.scene.transfer_function
            self._scene = Scene(self.volume, transfer_function=tf)
        data = renderer.slice_values(
            self._scene,
            p2w,
            size,
            slab_mm=state.slab_mm,
            slab_mode=state.slab_mode,
            interpolation=state.interpolation,
        )
        return SliceImage.from_data(data, p2w).values

    def colour_options(self) -> dict[str, Any]:
        """``colorize`` options of the slices: the blend, and world checker cells with
        a fixed image (32-pixel tiles against the rest state without one)."""
        checker = self.checker_mm if self.volume is not None else None
        return {"blend": self.blend, "checker_mm": checker}


def open_fixed_dialog(window: Any) -> None:
    """Choose a volume file to open as the fixed image."""
    path, _ = QFileDialog.getOpenFileName(window, "Open fixed image", window._last_dir())
    if path:
        window.fixed_image.open(path)


def install_fixed_image(window: Any, file_menu: Any) -> FixedImage:
    """Add File › Open Fixed Image… / Close Fixed Image and the Compare toolbar to
    ``window``; returns the :class:`FixedImage` (also ``window.fixed_image``)."""
    fixed = FixedImage(window)
    window.fixed_image = fixed
    for text, slot in (
        ("Open &Fixed Image…", lambda: open_fixed_dialog(window)),
        ("Close Fixed Image", lambda: fixed.set_volume(None)),
    ):
        action = QAction(text, window)
        action.triggered.connect(lambda *_, s=slot: s())
        file_menu.addAction(action)
        window.addAction(action)
    bar = QToolBar("Compare")
    bar.setObjectName("Compare")
    # at the bottom, shown while a fixed image is open: the top rows keep their room
    window.addToolBar(Qt.ToolBarArea.BottomToolBarArea, bar)
    bar.setVisible(False)
    window.compare_bar = bar
    controls: dict[str, Any] = {}
    box = QComboBox()
    box.addItems([OFF, *COMPARE_SHOWS])
    box.setToolTip("3D view: the moving image alone, or compared with the fixed image")
    box.textActivated.connect(lambda text: fixed.set_option("show_3d", text))
    bar.addWidget(QLabel(" 3D compare "))
    bar.addWidget(box)
    controls["show_3d"] = box
    slider = QSlider(Qt.Orientation.Horizontal)
    slider.setRange(0, 100)
    slider.setValue(50)
    slider.setFixedWidth(120)
    slider.setToolTip("blend: 0 = moving, 1 = fixed (Show blend in the slices, 3D blend)")
    slider.valueChanged.connect(lambda v: fixed.set_option("blend", v / 100.0))
    bar.addWidget(QLabel(" Blend "))
    bar.addWidget(slider)
    controls["blend"] = slider
    cell = QDoubleSpinBox()
    cell.setRange(0.5, 500.0)
    cell.setDecimals(1)
    cell.setSuffix(" mm")
    cell.setToolTip("checkerboard cell size (world cubes, the same in 3D and the slices)")
    cell.valueChanged.connect(lambda v: fixed.set_option("checker_mm", float(v)))
    bar.addWidget(QLabel(" Cell "))
    bar.addWidget(cell)
    controls["checker_mm"] = cell
    window.compare_controls = controls
    _sync(window)
    return fixed


def _sync(window: Any) -> None:
    """Show the settings in the toolbar (signals blocked); enabled with a fixed image."""
    controls = getattr(window, "compare_controls", None)
    if not controls:
        return
    fixed = window.fixed_image
    window.compare_bar.setVisible(fixed.volume is not None)
    values = {
        "show_3d": fixed.show_3d,
        "blend": round(fixed.blend * 100),
        "checker_mm": fixed.checker_mm or 0.5,
    }
    for name, widget in controls.items():
        widget.blockSignals(True)
        if isinstance(widget, QComboBox):
            widget.setCurrentText(values[name])
        else:
            widget.setValue(values[name])
        widget.setEnabled(fixed.volume is not None or name == "blend")
        widget.blockSignals(False)


def slice_extras(window: Any) -> FixedImage | None:
    """The window's :class:`FixedImage` (None before it is installed)."""
    return getattr(window, "fixed_image", None)
