"""Asking to read a folder that an opened scene names outside its own folder.

A scene (or a detached header) may name files only in its folder and the allowed folders
(:mod:`voxwarp.core.allowed_folders`). When opening one is refused for that, the window
shows the refusal and asks whether to allow the folder for this session; yes allows it
(as ``--allow-dir`` would) and opens the file again.
"""

from __future__ import annotations

from pathlib import Path

from PySide6.QtWidgets import QMessageBox, QWidget

from voxwarp.core.allowed_folders import allow_folder


def outside_folder(error: BaseException) -> Path | None:
    """The folder a refusal asks to allow (set by the scene path check), else ``None``."""
    folder = getattr(error, "outside_folder", None)
    return Path(folder) if folder is not None else None


def ask_allow_folder(parent: QWidget | None, error: BaseException) -> bool:
    """Show ``error`` and ask whether to allow its folder for this session; ``True`` (and
    the folder allowed) on yes."""
    folder = outside_folder(error)
    if folder is None:
        return False
    answer = QMessageBox.question(
        parent,
        "Read a file outside the scene's folder?",
        f"{error}\n\nAllow reading files in {folder} for this session?",
        QMessageBox.Yes | QMessageBox.No,
        QMessageBox.No,
    )
    if answer != QMessageBox.Yes:
        return False
    allow_folder(folder)
    return True
