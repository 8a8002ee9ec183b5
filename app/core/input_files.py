"""The one rule for files voxwarp reads because a user or another file named them.

A named input must be a regular file (or, where a reader takes folders of slices, a
folder): never a FIFO, socket or device, nor a file under /proc or /sys, whose
read could block forever or never end.
Checked on the resolved path (symlinks followed) before anything opens it, by every
reader: volumes, detached NRRD/MetaImage data, fields, JSON inputs (scenes, transfer
functions, wires, lattices, cameras, animations, tours) and the paths scenes name.
Where the file lies (inside the folder of the file that names it) is checked by
:func:`voxwarp.io.volumes.data_file_outside` and :mod:`voxwarp.core.scene_paths`.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

#: Kernel trees: their "regular" files may block (/proc/kmsg) or never end.
_KERNEL_DIRS = ("/proc/", "/sys/")
_KINDS = (
    (stat.S_ISFIFO, "a pipe (FIFO)"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISDIR, "a folder"),
)


def not_regular(path: str | os.PathLike[str], *, folders: bool = False) -> str | None:
    """What ``path`` is when it is not a regular file (``"a pipe (FIFO)"``, ``"a
    folder"`` unless ``folders``...), else ``None``; a missing path is ``None`` too (the
    caller's own "no such file" applies)."""
    try:
        mode = os.stat(path).st_mode
        real = os.path.realpath(path)
    except (OSError, ValueError):
        return None
    if real.startswith(_KERNEL_DIRS):  # "regular" files that block or never end
        return "a file of the kernel's /proc or /sys"
    if stat.S_ISREG(mode) or (folders and stat.S_ISDIR(mode)):
        return None
    return next((what for test, what in _KINDS if test(mode)), "not a regular file")


def check_regular(
    path: str | os.PathLike[str], what: str, error: type[Exception], *, folders: bool = False
) -> Path:
    """``path`` when it is a regular file (or a folder, with ``folders``); otherwise raise
    ``error`` with one line: ``WHAT PATH is a pipe (FIFO), not a regular file; ...``."""
    kind = not_regular(path, folders=folders)
    if kind is not None:
        raise error(
            f"{what} {os.fspath(path)} is {kind}, not a regular file; voxwarp reads only"
            " regular files (a pipe or device could block forever): save the data to a file"
        )
    return Path(path)
