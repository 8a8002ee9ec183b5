"""The det J overlay in the GUI: View › Jacobian (det J) Overlay (J) and the status line.

:class:`DetJOverlay` (``window.detj``) holds the switch. On, the 3D view colours the
volume by ``det J`` of the warp chain (dvr, mip, minip, iso; the renderer's
:attr:`~voxwarp.render.raycaster.Renderer.jacobian_overlay`) and the slice views draw
the colour map with its legend (:mod:`voxwarp.render.jacobian_overlay`) and add
``det J`` to the cursor readout. Whenever the scene has warps, the status bar shows
min/max ``det J`` and the folded (``det J <= 0``) nodes and their volume, from
:meth:`voxwarp.scene.Scene.jacobian_determinant` on a coarse grid (at most
:data:`STATUS_NODES` nodes a side), computed :data:`THROTTLE_MS` after the last edit so
a drag stays interactive.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from PySide6.QtCore import QObject, Qt, QTimer
from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import QLabel, QMenu

from voxwarp.core.jacobian import JacobianStats
from voxwarp.errors import VoxwarpError
from voxwarp.render.jacobian_overlay import DETJ_MODES, JacobianOverlay

#: nodes along the longest side of the status line's det J grid
STATUS_NODES = 32
#: the status line is recomputed this long after the last change
THROTTLE_MS = 300


def status_spacing(volume: Any) -> float:
    """Grid spacing (mm) of the status line's det J: :data:`STATUS_NODES` nodes along the
    volume's longest side, never finer than its voxels."""
    extent = np.asarray(volume.shape, float) * np.asarray(volume.spacing, float)
    return max(float(extent.max()) / STATUS_NODES, float(min(volume.spacing)))


def status_text(stats: JacobianStats) -> str:
    """The status line: ``det J 0.81..1.3 · 2 folded (16 mm³)``."""
    if stats.nodes == 0:
        return "det J: —"
    mm3 = stats.folded * stats.voxel_mm3
    return f"det J {stats.min:.3g}..{stats.max:.3g} · {stats.folded} folded ({mm3:.4g} mm³)"


class DetJOverlay(QObject):
    """The det J switch, the slice views' det J and the status line of one window."""

    def __init__(self, window: Any) -> None:
        super().__init__(window)
        self.window = window
        #: the overlay is drawn (View › Jacobian (det J) Overlay)
        self.enabled = False
        #: how it is drawn
        self.overlay = JacobianOverlay()
        #: the last status line's numbers (None without warps)
        self.stats: JacobianStats | None = None
        self.label = QLabel("")
        self.label.setToolTip(
            "det J of the warp chain on a coarse grid: min..max and the folded nodes"
            " (det J <= 0). Overlay colours: blue > 1 (shown shrunk), orange < 1 (shown"
            " enlarged), green folds; 3D in dvr, mip, minip and iso"
        )
        self.label.hide()
        self._timer = QTimer(self)
        self._timer.setSingleShot(True)
        self._timer.setInterval(THROTTLE_MS)
        self._timer.timeout.connect(self.update_stats)

    def set_enabled(self, on: bool) -> None:
        """Switch the overlay in the 3D and slice views."""
        self.enabled = bool(on)
        self.apply_to_renderer()
        self.window.mpr.render_all()
        self.window.viewport.update()

    def apply_to_renderer(self) -> None:
        """Give the viewport's renderer the overlay (or none)."""
        renderer = self.window.viewport.renderer
        if renderer is not None:
            renderer.jacobian_overlay = self.overlay if self.enabled else None

    def jacobian(self) -> JacobianOverlay | None:
        """The overlay the slice views colour with (None when off)."""
        return self.overlay if self.enabled else None

    def schedule(self) -> None:
        """Recompute the status line soon (after the last of a burst of changes)."""
        self.apply_to_renderer()
        self._timer.start()

    def update_stats(self) -> None:
        """Recompute min/max det J and the folds now (on the coarse grid)."""
        scene = self.window.session.scene
        if not scene.warps:
            self.stats = None
            self.label.hide()
            return
        spacing = status_spacing(scene.volume)
        try:
            jm = self.window.viewport.with_context(
                lambda: scene.jacobian_determinant(spacing=spacing)
            )
        except VoxwarpError as exc:
            self.label.setText(f"det J: {exc}")
            self.label.show()
            return
        self.stats = jm.stats
        text = status_text(self.stats)
        if self.enabled and scene.mode not in DETJ_MODES:
            text += f" (3D overlay in {', '.join(DETJ_MODES)})"
        self.label.setText(text)
        self.label.show()


def masked_detj(data: np.ndarray, image: Any) -> np.ndarray:
    """The det J channel of ``slice_values(..., detj=True)`` data, NaN where the slice
    image shows no volume."""
    return np.where(np.isfinite(image.values), data[..., 4], np.nan).astype(np.float32)


def readout_suffix(window: Any, image: Any, xy: tuple[float, float]) -> str:
    """``   det J 0.93`` for the slice readout at image pixel ``xy`` (empty when off)."""
    detj = getattr(image, "detj", None)
    control = getattr(window, "detj", None)
    if detj is None or control is None or not control.enabled:
        return ""
    c, r = math.floor(xy[0]), math.floor(xy[1])
    h, w = detj.shape
    v = float(detj[r, c]) if 0 <= c < w and 0 <= r < h else float("nan")
    return f"   det J {v:.4g}" if math.isfinite(v) else "   det J —"


def install_detj_controls(window: Any, menu: QMenu) -> None:
    """``window.detj`` (:class:`DetJOverlay`), its checkable action in ``menu``
    (``window.detj_action``, shortcut J) and its label in the status bar."""
    window.detj = DetJOverlay(window)
    a = QAction("&Jacobian (det J) Overlay", window)
    a.setCheckable(True)
    a.setShortcut(QKeySequence("J"))
    a.setShortcutContext(Qt.ShortcutContext.WindowShortcut)
    a.setToolTip("colour the 3D and slice views by det J of the warp chain")
    a.toggled.connect(window.detj.set_enabled)
    menu.addAction(a)
    window.addAction(a)
    window.detj_action = a
    window.statusBar().addPermanentWidget(window.detj.label)
    window.undo_stack.indexChanged.connect(lambda *_: window.detj.schedule())
    window.viewport.dragged.connect(window.detj.schedule)
    window.detj.schedule()
