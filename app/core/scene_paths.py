"""Files named inside a scene JSON (its volume, its meshes): where they are, and whether
they stay in the scene's folder.

A relative path in scene JSON is relative to the folder of the scene file. An absolute
path names its file outright (a shared scan): it loads without a word. A relative path
that climbs out of that folder (``..``, or a link inside it pointing elsewhere) still
loads but is reported in one warning line naming what it reads, so a relative name never
makes voxwarp read outside the scene's folder unnoticed. Scenes voxwarp writes name a
file under their folder relatively and any other absolutely (:func:`path_entry`), so they
reopen from anywhere without a warning. A missing file is one error line naming the path
it resolved to. A FIFO, socket or device is refused (:mod:`voxwarp.core.input_files`).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any

from voxwarp.core.input_files import check_regular
from voxwarp.errors import VoxwarpError


class OutsideSceneFolderWarning(UserWarning):
    """A scene JSON names a file outside the scene's own folder."""


def scene_file(
    value: Any,
    base_dir: str | os.PathLike[str] | None,
    what: str,
    error: type[VoxwarpError],
    *,
    noun: str = "file",
    must_exist: bool = True,
) -> Path:
    """The file a scene entry's ``path`` names (``what``: the entry, e.g. ``"volume"``;
    ``noun``: what the file is, in the error), resolved against the scene's folder
    ``base_dir`` (made absolute, symlinks kept); warns
    (:class:`OutsideSceneFolderWarning`) when a relative path leads outside that folder. Raises
    ``error`` for a value that is not a path string or, with ``must_exist``, for a file
    or folder that is not there."""
    if not isinstance(value, str | os.PathLike) or not os.fspath(value):
        raise error(f"scene {what} path must be a file path (a string); got {value!r:.60}")
    p = Path(os.path.expanduser(os.fspath(value)))
    relative = not p.is_absolute()
    if relative and base_dir is not None:
        p = Path(base_dir) / p
    try:
        resolved = p.resolve()
    except (OSError, RuntimeError) as exc:  # a symlink loop
        raise error(f"scene {what} path {os.fspath(value)}: cannot resolve it ({exc})") from exc
    if must_exist and not resolved.exists():
        where = "" if base_dir is None else " (relative paths start at the scene's folder)"
        raise error(
            f"scene {what} path {os.fspath(value)}: no such {noun} {resolved}{where}; fix the path"
            " in the scene JSON or put the file there"
        )
    check_regular(resolved, f"scene {what} path", error, folders=True)
    if relative and base_dir is not None:
        folder = Path(base_dir).resolve()
        if not resolved.is_relative_to(folder):
            warnings.warn(
                f"scene {what} path {os.fspath(value)} is outside the scene's folder {folder}:"
                f" reading {resolved}",
                OutsideSceneFolderWarning,
                stacklevel=3,
            )
    return Path(os.path.abspath(p))


def path_entry(path: str | os.PathLike[str], base_dir: str | os.PathLike[str] | None) -> str:
    """How a scene JSON written to ``base_dir`` names the existing file ``path``: relative
    to that folder when the file lies under it (the inverse of :func:`scene_file`), else
    absolute (also without a folder), so the scene reopens from anywhere without a
    warning."""
    p = Path(path).resolve()
    if base_dir is None or not p.is_relative_to(Path(base_dir).resolve()):
        return str(p)
    return os.path.relpath(p, Path(base_dir).resolve())
