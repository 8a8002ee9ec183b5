"""The window's central area: the 3D viewport and three linked slice views (MPR).

:class:`SliceLayout` holds the main :class:`~voxwarp.ui.viewport.Viewport` and three
:class:`~voxwarp.ui.slice_view.SliceView` widgets in one grid: ``"2x2"`` as 3D Slicer's
four-up layout (axial top left, 3D top right, sagittal bottom left, coronal bottom
right), ``"1x3"`` (the 3D view large, the slices in a column on the right) or ``"3d"``
(the 3D view alone). The shared state is a Qt-free
:class:`voxwarp.editing.slice_views.SliceViews`; the 3D view draws its planes as
outlines (:meth:`SliceViews.outline_layers`, ``Display -> Slice planes``).

The slices follow the 3D view: after every frame the viewport draws (a drag, a running
simulation, an undo) one single-shot timer redraws the visible slices once (at half
resolution while the deformation changes, in full once it rests; the 3D view's adaptive
level counts their time in its frame budget, ``Viewport.companion_s``); their own
changes (crosshair, scrolling) redraw them at once and the 3D view (at its interactive
quality) for the outlines. :func:`install_slice_controls` adds the View menu's layout
actions and the "Slices" toolbar (layout, look, shown state, slab, interpolation).
"""

from __future__ import annotations

import time
from typing import Any

from PySide6.QtCore import Qt, QTimer
from PySide6.QtGui import QAction, QActionGroup, QKeySequence
from PySide6.QtWidgets import QComboBox, QDoubleSpinBox, QGridLayout, QLabel, QMenu, QWidget

from voxwarp.editing.slice_views import LAYOUTS, SliceViews
from voxwarp.errors import VoxwarpError
from voxwarp.render.slice_grid import slice_window
from voxwarp.render.slice_image import LOOKS, SHOWS
from voxwarp.render.slices import INTERPOLATIONS, SLAB_MODES
from voxwarp.ui.slice_view import SliceView
from voxwarp.ui.window_level import install_window_level

__all__ = ["LAYOUT_KEYS", "SliceLayout", "install_slice_controls"]

#: View menu text and shortcut of each layout
LAYOUT_KEYS: dict[str, tuple[str, str]] = {
    "2x2": ("Four-Up Layout (3D + Slices)", "Ctrl+1"),
    "1x3": ("3D Large, Slices in a Column", "Ctrl+2"),
    "3d": ("3D Only", "Ctrl+3"),
}
#: resolution of the slices (fraction of the view's) while the deformation changes
LIVE_SCALE = 0.5
#: the slices are drawn in full this long after the last change (ms)
REFINE_AFTER_MS = 250
#: smallest size of the 3D view alone and of each view in a grid (pixels)
VIEWPORT_MIN = (320, 240)
SLICE_MIN = (160, 120)
#: grid cells (row, column) of views 0..2 (axial/z, coronal/y, sagittal/x) and the 3D
#: view in the four-up layout
FOUR_UP = {0: (0, 0), "3d": (0, 1), 2: (1, 0), 1: (1, 1)}


class SliceLayout(QWidget):
    """The central widget: viewport plus three linked slice views (module docstring).

    Parameters
    ----------
    window
        The main window (its ``session`` and ``viewport`` are re-read every time).
    """

    def __init__(self, window: Any, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.window = window
        self.viewport = window.viewport
        self.state = self._new_state()
        self.grid = QGridLayout(self)
        self.grid.setContentsMargins(0, 0, 0, 0)
        self.grid.setSpacing(2)
        self.views = [SliceView(self, i, self) for i in range(3)]
        self._pending = QTimer(self)
        self._pending.setSingleShot(True)
        self._pending.setInterval(0)
        self._pending.timeout.connect(self.render_all)
        self._refine = QTimer(self)
        self._refine.setSingleShot(True)
        self._refine.setInterval(REFINE_AFTER_MS)
        self._refine.timeout.connect(self._refine_slices)
        self.viewport.frameDrawn.connect(lambda _ms: self._pending.start())
        self.viewport.extra_overlays.append(self._outlines)
        self.set_layout(self.state.layout)

    def _new_state(self) -> SliceViews:
        scene = self.window.session.scene
        return SliceViews(scene.volume, slice_window(scene))

    # ------------------------------------------------------------------ layout
    def set_layout(self, layout: str) -> None:
        """Arrange the views: ``"2x2"``, ``"1x3"`` or ``"3d"`` (see the module docstring)."""
        self.state.set_option("layout", layout)
        grid = self.grid
        for w in (self.viewport, *self.views):
            grid.removeWidget(w)
        for i in range(3):
            grid.setRowStretch(i, 0)
            grid.setColumnStretch(i, 0)
        if layout == "2x2":
            grid.addWidget(self.viewport, *FOUR_UP["3d"])
            for i, view in enumerate(self.views):
                grid.addWidget(view, *FOUR_UP[i])
            for i in range(2):
                grid.setRowStretch(i, 1)
                grid.setColumnStretch(i, 1)
        elif layout == "1x3":
            grid.addWidget(self.viewport, 0, 0, 3, 1)
            for i, view in enumerate(self.views):
                grid.addWidget(view, i, 1)
                grid.setRowStretch(i, 1)
            grid.setColumnStretch(0, 3)
            grid.setColumnStretch(1, 1)
        else:
            grid.addWidget(self.viewport, 0, 0)
            grid.setRowStretch(0, 1)
            grid.setColumnStretch(0, 1)
        for view in self.views:
            view.setVisible(layout != "3d")
        # a grid cell may be smaller than the 3D view alone likes to be
        self.viewport.setMinimumSize(*(VIEWPORT_MIN if layout == "3d" else SLICE_MIN))
        self._sync_controls()
        self.viewport.update()
        self._pending.start()

    def _sync_controls(self) -> None:
        """The View menu's layout actions and the toolbar follow the state."""
        actions = getattr(self.window, "layout_actions", {})
        if self.state.layout in actions:
            actions[self.state.layout].setChecked(True)
        for name, box in getattr(self.window, "slice_controls", {}).items():
            value = getattr(self.state, name)
            if isinstance(box, QComboBox):
                box.setCurrentText(str(value))
            elif box.value() != value:
                box.setValue(float(value))

    @property
    def slices_shown(self) -> bool:
        """Whether the slice views are on screen."""
        return self.state.layout != "3d" and self.isVisible()

    # ------------------------------------------------------------------ updates
    def set_session(self, session: Any) -> None:
        """A new session (a file was opened): fresh state for its volume, same layout."""
        layout = self.state.layout
        self.state = self._new_state()
        self.state.layout = layout
        for view in self.views:
            view.image = None
        self._sync_window_level()
        self.planes_changed()

    def render_all(self) -> None:
        """Draw every visible slice again (the scene or the planes changed): at
        :data:`LIVE_SCALE` of their resolution while a handle is dragged or the
        simulation moves, in full once that stops."""
        live = self.live()
        t = time.perf_counter()
        for view in self.views:
            view.render(LIVE_SCALE if live else 1.0)
        # the 3D view's adaptive level budgets the live slices with its own frame
        self.viewport.companion_s = time.perf_counter() - t if live else 0.0
        if live:
            self._refine.start()

    def live(self) -> bool:
        """Whether the deformation is changing right now (a drag, a running model)."""
        s = self.window.session
        return bool(s.dragging or (s.running and s.model is not None and not s.settled))

    def _refine_slices(self) -> None:
        if self.live():
            self._refine.start()
        else:
            self.render_all()

    def recolor_all(self) -> None:
        """Colour every slice again (window, look or shown state changed; no GPU)."""
        for view in self.views:
            view.recolor()
        self._sync_window_level()

    def _sync_window_level(self) -> None:
        """The Window/Level bar (:mod:`voxwarp.ui.window_level`) shows the window."""
        bar = getattr(self.window, "window_level", None)
        if bar is not None:
            bar.sync()

    def planes_changed(self) -> None:
        """The crosshair or a plane moved: redraw the slices now, the 3D view's
        outlines at its interactive quality."""
        self.render_all()
        if self.slices_shown and self.viewport.display.slice_planes:
            self.viewport.note_input()
            self.viewport.update()

    def set_option(self, name: str, value: Any) -> None:
        """Change a shared option (:meth:`SliceViews.set_option`) and redraw."""
        try:
            self.state.set_option(name, value)
        except VoxwarpError as exc:
            self.window.show_error(str(exc))
            return
        self._sync_controls()
        if name in ("look", "show"):
            self.recolor_all()
        else:
            self.render_all()

    def one_to_one(self) -> None:
        """Zoom every slice view so that one screen pixel is one voxel (1:1)."""
        for view in self.views:
            native = self.state.native_zoom(view.name, view.size_px())
            self.state.zoom(view.name, native / self.state.views[view.name].zoom)  # clipped
        self.planes_changed()

    def reset(self) -> None:
        """Crosshair to the centre, views unzoomed and untilted, default window."""
        self.state.reset()
        self._sync_window_level()
        self.planes_changed()

    def _outlines(self, display: Any) -> list[Any]:
        if not (display.slice_planes and self.state.layout != "3d"):
            return []
        return self.state.outline_layers()


def install_slice_controls(window: Any, menu: QMenu) -> None:
    """The layout actions (``window.layout_actions``) in ``menu`` and a "Slices"
    toolbar (``window.slice_bar``) with the shared slice options."""
    mpr: SliceLayout = window.mpr
    group = QActionGroup(window)
    window.layout_actions = {}
    for layout, (text, key) in LAYOUT_KEYS.items():
        a = QAction(text, window)
        a.setShortcut(QKeySequence(key))
        a.setShortcutContext(Qt.ShortcutContext.WindowShortcut)
        a.setCheckable(True)
        a.setChecked(layout == mpr.state.layout)
        a.triggered.connect(lambda *_, n=layout: mpr.set_layout(n))
        group.addAction(a)
        menu.addAction(a)
        window.addAction(a)
        window.layout_actions[layout] = a
    reset = QAction("Reset Slice Views (untilted, unzoomed)", window)
    reset.triggered.connect(lambda *_: mpr.reset())
    menu.addAction(reset)
    native = QAction("Slice Views 1:1 (a pixel per voxel)", window)
    native.triggered.connect(lambda *_: mpr.one_to_one())
    menu.addAction(native)

    bar = window.addToolBar("Slices")
    bar.setObjectName("Slices")
    window.addToolBarBreak()  # the toolbars after it go on the next row
    window.slice_bar = bar
    window.slice_controls = {}

    def combo(name: str, label: str, items: tuple[str, ...], tip: str) -> None:
        box = QComboBox()
        box.addItems(list(items))
        box.setCurrentText(str(getattr(mpr.state, name)))
        box.setToolTip(tip)
        if name == "layout":
            box.textActivated.connect(mpr.set_layout)
        else:
            box.textActivated.connect(lambda text, n=name: mpr.set_option(n, text))
        bar.addWidget(QLabel(f" {label} "))
        bar.addWidget(box)
        window.slice_controls[name] = box

    combo(
        "layout",
        "Layout",
        LAYOUTS,
        "3D and slices (Ctrl+1), slices in a column (Ctrl+2), 3D only (Ctrl+3)",
    )
    combo(
        "look", "Look", LOOKS, "grey window/level (right drag in a slice) or the transfer function"
    )
    combo(
        "show",
        "Show",
        SHOWS,
        "the deformed volume, its rest state, or both (checkerboard, difference)",
    )
    slab = QDoubleSpinBox()
    slab.setRange(0.0, 500.0)
    slab.setDecimals(1)
    slab.setSuffix(" mm")
    slab.setToolTip("thick slab through each plane (0: a thin slice)")
    slab.valueChanged.connect(lambda v: mpr.set_option("slab_mm", v))
    bar.addWidget(QLabel(" Slab "))
    bar.addWidget(slab)
    window.slice_controls["slab_mm"] = slab
    combo("slab_mode", "", tuple(SLAB_MODES), "how a slab's samples combine")
    combo("interpolation", "", INTERPOLATIONS, "sampling of the volume")
    install_window_level(window)  # typed window/level and presets: a toolbar of its own
