"""Files named inside a scene JSON (its volume, its meshes, its fields): where they are,
and whether voxwarp may read them.

A relative path in scene JSON is relative to the folder of the scene file. Whatever the
form (relative, ``..``, absolute, a link), the file must lie in the scene's folder or a
subfolder, or in an allowed folder (:mod:`voxwarp.core.allowed_folders`: ``--allow-dir``,
``VOXWARP_ALLOW_DATA_DIRS``, the bundled samples): a scene never makes voxwarp read
outside where the user pointed it. A refusal is one line naming the file and the folder to
allow; the error carries that folder as ``outside_folder`` (the GUI offers to allow it).
Scenes voxwarp writes name a file under their folder relatively and any other absolutely
(:func:`path_entry`), sealed with the user's key so that they reopen from anywhere
(:mod:`voxwarp.core.scene_seal`). A missing file is one error line naming the path it resolved to. A
FIFO, socket or device is refused (:mod:`voxwarp.core.input_files`). A scene built in
memory (no folder) reads any path.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from voxwarp.core.allowed_folders import allow_hint, outside_allowed
from voxwarp.core.input_files import check_regular
from voxwarp.errors import VoxwarpError


def scene_file(
    value: Any,
    base_dir: str | os.PathLike[str] | None,
    what: str,
    error: type[VoxwarpError],
    *,
    noun: str = "file",
    must_exist: bool = True,
    owner: str = "scene",
) -> Path:
    """The file a scene entry's ``path`` names (``what``: the entry, e.g. ``"volume"``;
    ``noun``: what the file is, in the error; ``owner``: the naming file's kind, e.g.
    ``"tour"``), resolved against the scene's folder
    ``base_dir`` (made absolute, symlinks kept). Raises ``error`` for a value that is not
    a path string, for a file outside that folder and the allowed folders, or, with
    ``must_exist``, for a file or folder that is not there."""
    if not isinstance(value, str | os.PathLike) or not os.fspath(value):
        raise error(f"{owner} {what} path must be a file path (a string); got {value!r:.60}")
    p = Path(os.path.expanduser(os.fspath(value)))
    relative = not p.is_absolute()
    if relative and base_dir is not None:
        p = Path(base_dir) / p
    try:
        resolved = p.resolve()
    except (OSError, RuntimeError) as exc:  # a symlink loop
        raise error(f"{owner} {what} path {os.fspath(value)}: cannot resolve it ({exc})") from exc
    if must_exist and not resolved.exists():
        where = "" if base_dir is None else f" (relative paths start at the {owner}'s folder)"
        raise error(
            f"{owner} {what} path {os.fspath(value)}: no such {noun} {resolved}{where}; fix"
            f" the path in the {owner} JSON or put the file there"
        )
    check_regular(resolved, f"{owner} {what} path", error, folders=True)
    if base_dir is not None and outside_allowed(resolved, base_dir):
        folder = Path(base_dir).resolve()
        shown = "" if str(resolved) == os.fspath(value) else f" reads {resolved}"
        exc = error(
            f"{owner} {what} path {os.fspath(value)}{shown}, outside the {owner}'s"
            f" folder {folder}; a {owner} reads files only in its folder or an allowed folder:"
            f" {allow_hint(resolved)}"
        )
        exc.outside_folder = resolved.parent  # type: ignore[attr-defined]
        raise exc
    return Path(os.path.abspath(p))


def path_entry(path: str | os.PathLike[str], base_dir: str | os.PathLike[str] | None) -> str:
    """How a scene JSON written to ``base_dir`` names the existing file ``path``: relative
    to that folder when the file lies under it (the inverse of :func:`scene_file`), else
    absolute (also without a folder; the saved scene's seal lets it reopen,
    :mod:`voxwarp.core.scene_seal`)."""
    p = Path(path).resolve()
    if base_dir is None or not p.is_relative_to(Path(base_dir).resolve()):
        return str(p)
    return os.path.relpath(p, Path(base_dir).resolve())
