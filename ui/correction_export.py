"""Deformation -> Export Corrected Field…: the session's whole chain (the correction drawn
in the views, then the imported registration fields) written as ONE ITK displacement
field (``.h5``, ``.nii.gz``, ``.nrrd``, ``.mha``) that SimpleITK, ANTs and Slicer apply
to reproduce what the window shows (:meth:`voxwarp.scene.Scene.export_field`).

:func:`install_correction_export` adds the action to a menu of the main window;
:func:`export_corrected_field` does the work (tests call it with a path).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from PySide6.QtGui import QAction
from PySide6.QtWidgets import QFileDialog, QMenu

from voxwarp.errors import VoxwarpError

__all__ = ["export_corrected_field", "install_correction_export"]

#: the file dialog's filter: the formats :func:`voxwarp.io.fields.save_displacement_field`
#: writes that ITK tools read
FILTER = "ITK displacement field (*.h5 *.nii.gz *.nii *.nrrd *.mha)"


def install_correction_export(window: Any, menu: QMenu) -> QAction:
    """Add "Export Corrected Field…" to ``menu`` (enabled when the chain has warps)."""
    action = QAction("Export Corrected &Field…", window)
    action.setToolTip(
        "write the correction and the imported fields, composed, as one ITK displacement field"
    )
    action.triggered.connect(lambda *_: _export_dialog(window))
    menu.addAction(action)
    window.addAction(action)
    return action


def _export_dialog(window: Any) -> None:
    if not window.session.scene.warps:
        window.statusBar().showMessage("Nothing to export: the scene has no deformation", 4000)
        return
    path, _ = QFileDialog.getSaveFileName(
        window, "Export corrected field", str(Path.home() / "corrected.h5"), FILTER
    )
    if not path:
        return
    try:
        out = export_corrected_field(window, path)
    except (VoxwarpError, OSError) as exc:
        window.show_error(f"could not export the field: {exc}")
        return
    window.statusBar().showMessage(f"Exported the composed field to {out}", 10000)


def export_corrected_field(window: Any, path: str | Path) -> Path:
    """Write the window's scene chain as one displacement field at ``path`` (its spacing
    refined until ITK's trilinear field is within tolerance of the chain; see
    :meth:`~voxwarp.scene.Scene.export_field`); returns the path written."""
    # loaded when used: keeps the window's start light
    from voxwarp.io.fields import save_displacement_field

    def write() -> Path:
        export = window.session.scene.export_field()
        return save_displacement_field(export.field, path, export.metadata())

    return Path(window.viewport.with_context(write))
