"""File › Export…: the deformed volume, the displacement field or det J, written to a file.

The dialog picks what (deformed volume, displacement field, Jacobian determinant), the
file (its format by extension), the grid (``input``, ``volume``, ``deformed`` — the
last for the volume only) and the spacing (blank: the command's default), and shows the
size estimate of that choice. Export runs the same command as the CLI (``voxwarp
export-volume`` / ``export-field [--jacobian]``) on the scene saved to a temporary JSON,
in a fresh interpreter (its own GL context) on a worker thread (:mod:`voxwarp.ui.tasks`),
writing to a temporary name beside the file, renamed over it on success (atomic: a
failed or cancelled export leaves no file). Errors arrive as the command's one line.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from PySide6.QtWidgets import (
    QComboBox,
    QDialog,
    QDialogButtonBox,
    QFileDialog,
    QFormLayout,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QWidget,
)

from voxwarp.core.files import atomic_output, remove_stale_temps
from voxwarp.errors import VoxwarpError
from voxwarp.scene import Scene

#: what: (label, command line before the options, default file name, file filter)
KINDS: dict[str, tuple[str, list[str], str, str]] = {
    "volume": (
        "Deformed volume",
        ["export-volume"],
        "deformed.nii.gz",
        "Volume (*.nii.gz *.nii *.nrrd)",
    ),
    "field": (
        "Displacement field (ITK)",
        ["export-field"],
        "field.nii.gz",
        "Field (*.nii.gz *.nii *.nrrd *.mha *.h5 *.npz)",
    ),
    "jacobian": (
        "Jacobian determinant",
        ["export-field", "--jacobian"],
        "detj.nii.gz",
        "Scalar image (*.nii.gz *.nii *.nrrd)",
    ),
}
GRIDS = ("input", "volume", "deformed")


class ExportError(VoxwarpError):
    """An export the dialog could not run (one line: the command's own error)."""


def parse_spacing(text: str) -> list[float] | None:
    """Blank -> None (the default); one number or three (mm, > 0) -> a list."""
    parts = text.replace(",", " ").split()
    if not parts:
        return None
    try:
        vals = [float(v) for v in parts]
    except ValueError:
        vals = []
    if len(vals) not in (1, 3) or not all(np.isfinite(v) and v > 0 for v in vals):
        raise ExportError(f"spacing {text!r}: give one positive number or three (mm), or none")
    return vals


def export_argv(kind: str, scene_json: Path, out: Path, grid: str, spacing: Any) -> list[str]:
    """The ``voxwarp`` command line of an export (``spacing`` None: its default)."""
    argv = [*KINDS[kind][1], str(scene_json), "-o", str(out), "--grid", grid]
    if spacing is not None:
        s = [f"{v:g}" for v in spacing]
        argv += ["--spacing", ",".join(s)] if kind == "volume" else ["--spacing", *s]
    return argv


def estimate(scene: Scene, kind: str, grid: str, spacing: Any) -> str:
    """One line: the output's grid and its size before writing (uncompressed)."""
    from voxwarp.core.field_grid import field_grid
    from voxwarp.core.field_spacing import HEADER_BYTES, default_spacing
    from voxwarp.core.limits import format_bytes

    if kind == "volume":
        from voxwarp.cli.export_volume import export_grid

        s = None if spacing is None else tuple(np.resize(np.asarray(spacing, float), 3))
        _, shape = export_grid(scene, s, grid)  # type: ignore[arg-type]
        per, why = scene.volume.dtype.itemsize, ""
    else:
        choice = default_spacing(scene.volume, scene.warps)
        start = choice.spacing if spacing is None else spacing
        _, shape = field_grid(scene.volume, start, None, "volume" if grid == "deformed" else grid)
        per = 4 if kind == "jacobian" else 12
        why = f"; default spacing: {choice.reason}" if spacing is None else ""
    size = int(np.prod(shape)) * per + HEADER_BYTES
    dims = "x".join(str(int(n)) for n in shape)
    return f"{dims} nodes, about {format_bytes(size)} uncompressed{why}"


def run_export(
    scene: Scene,
    kind: str,
    out: Path,
    grid: str,
    spacing: Any,
    progress: Callable[[float, str], None] | None = None,
    cancelled: Callable[[], bool] | None = None,
) -> Path:
    """Write one export of ``scene`` to ``out`` atomically (see the module docstring):
    through :func:`voxwarp.core.files.atomic_output`, so a failed, cancelled or killed
    export leaves no file (the next one removes a killed one's temporary files) and a
    failed rename is one :class:`~voxwarp.errors.OutputError` line."""
    out = Path(out)
    if kind != "volume" and grid == "deformed":
        raise ExportError("the deformed grid is for the volume; use input or volume for a field")
    suffix = ".nii.gz" if out.name.lower().endswith(".nii.gz") else out.suffix
    with (
        tempfile.TemporaryDirectory(prefix="voxwarp-export-") as tmp,
        atomic_output(out, suffix) as tmp_out,
    ):
        scene_json = scene.save(Path(tmp) / "scene.json")
        argv = export_argv(kind, scene_json, tmp_out, grid, spacing)
        if progress:
            progress(0.1, f"voxwarp {' '.join(argv[:1])}")
        proc = subprocess.Popen(
            [sys.executable, "-m", "voxwarp", *argv],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            while proc.poll() is None:
                if cancelled and cancelled():
                    proc.kill()
                    break
                try:
                    proc.wait(timeout=0.2)
                except subprocess.TimeoutExpired:
                    pass
            _, err = proc.communicate()
        finally:
            if proc.returncode != 0:  # a killed command's temporary file: its pid is gone
                remove_stale_temps(out.parent, for_name=out.name)
        if proc.returncode != 0:
            lines = [ln for ln in err.splitlines() if "error:" in ln] or err.splitlines()[-1:]
            raise ExportError(lines[-1].split("error:", 1)[-1].strip() if lines else "failed")
    if progress:
        progress(1.0, f"wrote {out.name}")
    return out


class ExportDialog(QDialog):
    """File › Export…: what, file, grid, spacing and the size estimate."""

    def __init__(self, scene: Scene, folder: str = "", parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setWindowTitle("Export")
        self.scene = scene
        self.kind = QComboBox()
        for key, (label, *_rest) in KINDS.items():
            self.kind.addItem(label, key)
        self.path = QLineEdit(str(Path(folder or ".") / KINDS["volume"][2]))
        browse = QPushButton("…")
        browse.clicked.connect(self._browse)
        row = QHBoxLayout()
        row.addWidget(self.path)
        row.addWidget(browse)
        self.grid = QComboBox()
        self.grid.addItems(list(GRIDS))
        self.spacing = QLineEdit()
        self.spacing.setPlaceholderText("default (mm: one number or three)")
        self.estimate = QLabel()
        self.estimate.setWordWrap(True)
        form = QFormLayout(self)
        form.addRow("Export", self.kind)
        form.addRow("File", row)
        form.addRow("Grid", self.grid)
        form.addRow("Spacing", self.spacing)
        form.addRow("Size", self.estimate)
        buttons = QDialogButtonBox(
            QDialogButtonBox.StandardButton.Ok | QDialogButtonBox.StandardButton.Cancel
        )
        buttons.accepted.connect(self.accept)
        buttons.rejected.connect(self.reject)
        form.addRow(buttons)
        for w in (self.kind, self.grid):
            w.currentIndexChanged.connect(self._changed)
        self.spacing.textChanged.connect(self.update_estimate)
        self.update_estimate()

    def choice(self) -> tuple[str, Path, str, list[float] | None]:
        """``(kind, path, grid, spacing)`` as chosen (:class:`ExportError` if bad)."""
        return (
            str(self.kind.currentData()),
            Path(self.path.text()),
            self.grid.currentText(),
            parse_spacing(self.spacing.text()),
        )

    def update_estimate(self) -> None:
        """Show the estimate of the current choice (or why there is none)."""
        try:
            kind, _, grid, spacing = self.choice()
            self.estimate.setText(estimate(self.scene, kind, grid, spacing))
        except VoxwarpError as exc:
            self.estimate.setText(str(exc))

    def _changed(self) -> None:
        kind = str(self.kind.currentData())
        path = Path(self.path.text())
        self.path.setText(str(path.with_name(KINDS[kind][2])))
        self.update_estimate()

    def _browse(self) -> None:
        kind = str(self.kind.currentData())
        path, _ = QFileDialog.getSaveFileName(self, "Export", self.path.text(), KINDS[kind][3])
        if path:
            self.path.setText(path)


def open_export_dialog(window: Any) -> None:
    """File › Export… on the main window ``window`` (its session's scene, its
    ``show_error`` for the one-line errors, :func:`voxwarp.ui.tasks.run_with_progress`)."""
    from voxwarp.ui.tasks import run_with_progress

    dialog = ExportDialog(window.session.scene, window._last_dir(), window)
    if dialog.exec() != QDialog.DialogCode.Accepted:
        return
    try:
        kind, out, grid, spacing = dialog.choice()
    except VoxwarpError as exc:
        window.show_error(str(exc))
        return
    scene = window.session.scene

    def job(progress: Callable[[float, str], None], cancelled: Callable[[], bool]) -> Path:
        return run_export(scene, kind, out, grid, spacing, progress, cancelled)

    def done(path: Any) -> None:
        window.statusBar().showMessage(f"exported {path}", 8000)

    window._export_task = run_with_progress(window, "Exporting", job, done, window.show_error)
