"""View › Warped Grid / Displacement Glyphs: the chain's grid and glyphs in the GUI.

:class:`WarpOverlays` (``window.warp_overlays``) holds the two switches and the grid
spacing (0: automatic, as the CLI's default) and draws:

* on the slice views, over each slice's colours (:meth:`WarpOverlays.slice_rgba`,
  called by :meth:`voxwarp.ui.slice_view.SliceView.recolor`), the rest-space grid and
  the displacement arrows of :func:`voxwarp.render.warp_overlays.draw_slice_overlays`;
  each slice's pull-back points are computed once per drawn slice (a window/level
  drag does not recompute them);
* in the 3D view, 1-pixel lines on top of the volume (an ``extra_overlays`` entry of
  the viewport): the grid plane facing the camera moved by the chain's forward map,
  and arrows of ``u`` on that plane (:func:`~voxwarp.render.warp_meshes.grid_segments`,
  :func:`~voxwarp.render.warp_meshes.glyph_segments`), cached per warp revision.

:func:`install_warp_overlays` adds the menu entries and the spacing box.
"""

from __future__ import annotations

import weakref
from typing import Any

import numpy as np
from PySide6.QtGui import QAction
from PySide6.QtWidgets import QDoubleSpinBox, QHBoxLayout, QLabel, QMenu, QWidget, QWidgetAction

from voxwarp.core.warp_grid import (
    MIN_CELL_PX,
    nice_spacing,
    pixel_points,
    pull_back,
)
from voxwarp.errors import VoxwarpError
from voxwarp.render.overlay import OverlayLayer
from voxwarp.render.warp_meshes import WarpLines
from voxwarp.render.warp_overlays import composite, slice_overlay_layer


class WarpOverlays:
    """The grid/glyph switches of one window and their drawing (see the module)."""

    def __init__(self, window: Any) -> None:
        self.window = window
        self.grid = False
        self.glyphs = False
        #: grid spacing in mm; 0 picks it from the volume's box
        self.spacing_mm = 0.0
        #: pull-back points per drawn slice image: id -> (weak reference, points)
        self._rest: dict[int, tuple[weakref.ref, np.ndarray]] = {}
        #: overlay layers per drawn slice image: id -> (weak reference, settings, layer)
        self._layers: dict[int, tuple[weakref.ref, Any, np.ndarray]] = {}
        self._lines = WarpLines()

    @property
    def active(self) -> bool:
        """True when the grid or the glyphs are shown."""
        return self.grid or self.glyphs

    def spacing(self, pixel_mm: float = 0.0) -> float:
        """The grid spacing in mm (the automatic one when ``spacing_mm`` is 0)."""
        if self.spacing_mm > 0:
            return float(self.spacing_mm)
        volume = self.window.session.scene.volume
        return nice_spacing(*volume.bounds, at_least_mm=MIN_CELL_PX * pixel_mm)

    def set(self, grid: bool | None = None, glyphs: bool | None = None) -> None:
        """Switch the grid and/or glyphs and redraw."""
        if grid is not None:
            self.grid = bool(grid)
        if glyphs is not None:
            self.glyphs = bool(glyphs)
        self.changed()

    def set_spacing(self, mm: float) -> None:
        """Grid spacing in mm (0: automatic) and redraw."""
        self.spacing_mm = max(float(mm), 0.0)
        self.changed()

    def changed(self) -> None:
        """Recolour the slices and redraw the 3D view."""
        self.window.mpr.recolor_all()
        self.window.viewport.update()

    # ---------------------------------------------------------------- slices
    def slice_rgba(self, image: Any, rgba: np.ndarray) -> np.ndarray:
        """``rgba`` of a slice ``image`` with the switched-on overlays drawn over it
        (the overlay layer is kept per image: a window/level drag only composites)."""
        if not self.active:
            return rgba
        m = np.asarray(image.pixel_to_world, dtype=np.float64)
        rest_shown = self.window.mpr.state.show == "rest"  # the rest state: a straight grid
        warps = [] if rest_shown else self.window.session.scene.warps
        spacing = self.spacing(float(np.linalg.norm(m[:3, 0])))
        key = (self.grid, self.glyphs, spacing, rest_shown)
        hit = self._layers.get(id(image))
        if hit is not None and hit[0]() is image and hit[1] == key:
            return composite(rgba, hit[2])
        wanted = [name for name, on in (("grid", self.grid), ("glyphs", self.glyphs)) if on]
        try:
            rest = self._rest_points(image, warps) if self.grid else None
            layer, _ = slice_overlay_layer(warps, m, image.size, wanted, spacing, rest=rest)
        except VoxwarpError:
            return rgba
        self._layers = {k: v for k, v in self._layers.items() if v[0]() is not None}
        self._layers[id(image)] = (weakref.ref(image), key, layer)
        return composite(rgba, layer)

    def _rest_points(self, image: Any, warps: list) -> np.ndarray:
        """The pull-back points of a slice's pixels, computed once per slice image."""
        if not warps:
            return pixel_points(np.asarray(image.pixel_to_world, float), image.size)
        hit = self._rest.get(id(image))
        if hit is not None and hit[0]() is image:
            return hit[1]
        self._rest = {k: v for k, v in self._rest.items() if v[0]() is not None}
        m = np.asarray(image.pixel_to_world, dtype=np.float64)
        rest = pull_back(warps, pixel_points(m, image.size))
        self._rest[id(image)] = (weakref.ref(image), rest)
        return rest

    # ---------------------------------------------------------------- 3D
    def layers_3d(self, display: Any = None) -> list[OverlayLayer]:
        """The 3D view's line layers (:class:`~voxwarp.render.warp_meshes.WarpLines`)."""
        lines = self._lines
        lines.grid, lines.glyphs, lines.spacing_mm = self.grid, self.glyphs, self.spacing_mm
        try:
            return lines.layers(self.window.session.scene, self.window.viewport.camera)
        except VoxwarpError:
            return []


def install_warp_overlays(window: Any, menu: QMenu) -> WarpOverlays:
    """Add "Warped Grid" (G), "Displacement Glyphs" and a grid spacing box to ``menu``;
    the state is ``window.warp_overlays``, its actions ``window.warp_overlay_actions``."""
    overlays = WarpOverlays(window)
    window.warp_overlays = overlays
    window.viewport.extra_overlays.append(overlays.layers_3d)
    grid = QAction("Warped &Grid", window)
    grid.setCheckable(True)
    grid.setShortcut("G")
    grid.setToolTip("the rest-space grid carried by the warp chain, in 3D and on the slices")
    grid.toggled.connect(lambda on: overlays.set(grid=on))
    glyphs = QAction("Displacement Gl&yphs", window)
    glyphs.setCheckable(True)
    glyphs.setToolTip("arrows of u = chain(x) - x (the exported field's vectors)")
    glyphs.toggled.connect(lambda on: overlays.set(glyphs=on))
    for action in (grid, glyphs):
        menu.addAction(action)
        window.addAction(action)
    box = QDoubleSpinBox()
    box.setRange(0.0, 1000.0)
    box.setDecimals(1)
    box.setSuffix(" mm")
    box.setSpecialValueText("auto")
    box.setToolTip("grid spacing (auto: about 1/16 of the volume)")
    box.valueChanged.connect(overlays.set_spacing)
    holder = QWidget()
    row = QHBoxLayout(holder)
    row.setContentsMargins(24, 2, 8, 2)
    row.addWidget(QLabel("Grid spacing"))
    row.addWidget(box)
    spacing = QWidgetAction(window)
    spacing.setDefaultWidget(holder)
    menu.addAction(spacing)
    window.warp_overlay_actions = {"grid": grid, "glyphs": glyphs, "spacing": box}
    return overlays


__all__ = ["WarpOverlays", "install_warp_overlays"]
