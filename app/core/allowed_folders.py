"""Where voxwarp reads a file that another file names (a scene's volume, meshes and
fields; a detached NRRD or MetaImage header's data file): the naming file's own folder
and its subfolders, the bundled samples, and the folders the user allows.

A file must not make voxwarp read outside where the user pointed it, so a scene saved
elsewhere, or a header naming ``/etc/passwd`` or ``../../secret``, is refused unless its
target lies in an allowed folder. Folders are allowed by:

* ``--allow-dir DIR`` on the command line (:func:`set_allowed_folders`, process-wide);
* ``with allowed_folders([DIR]):`` around API calls (``load_volume(allow_data_dirs=)``);
* the environment variable ``VOXWARP_ALLOW_DATA_DIRS`` (``os.pathsep``-separated);
* a scene voxwarp saved, for exactly the files it names (:mod:`voxwarp.core.scene_seal`).

Use :func:`outside_allowed` to test a target and :func:`allow_hint` for the fix the
error line names.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path

#: Environment variable naming more allowed folders (``os.pathsep``-separated).
ALLOW_DIRS_ENV = "VOXWARP_ALLOW_DATA_DIRS"

#: Folders allowed while a ``with allowed_folders(...)`` block runs.
_SCOPED: ContextVar[tuple[Path, ...]] = ContextVar("voxwarp_allowed_folders", default=())
#: Folders allowed for the whole process (``--allow-dir``), seen by every thread.
_PROCESS: list[Path] = []
#: Files (or slice folders) allowed for the whole process by name: a sealed scene's
#: (:mod:`voxwarp.core.scene_seal`).
_FILES: set[Path] = set()

FolderList = Sequence[str | os.PathLike[str]] | str | os.PathLike[str] | None


def _resolved(dirs: FolderList) -> tuple[Path, ...]:
    if not dirs:
        return ()
    if isinstance(dirs, str | os.PathLike):
        dirs = [dirs]
    return tuple(Path(os.path.expanduser(os.fspath(d))).resolve() for d in dirs)


@contextmanager
def allowed_folders(dirs: FolderList) -> Iterator[None]:
    """Allow reading named files under ``dirs`` while the block runs (``None`` or empty
    changes nothing)."""
    extra = _resolved(dirs)
    if not extra:
        yield
        return
    token = _SCOPED.set(_SCOPED.get() + extra)
    try:
        yield
    finally:
        _SCOPED.reset(token)


def set_allowed_folders(dirs: FolderList) -> None:
    """Allow ``dirs`` for the rest of the process, replacing what the last call allowed
    (the CLI's ``--allow-dir``; ``None`` clears it)."""
    _PROCESS[:] = _resolved(dirs)


def allow_folder(folder: str | os.PathLike[str]) -> None:
    """Allow ``folder`` for the rest of the process, besides the folders allowed so far
    (the GUI's "allow this folder")."""
    _PROCESS.extend(_resolved(folder))


def allow_files(paths: Sequence[str | os.PathLike[str]]) -> None:
    """Allow exactly ``paths`` (files, or folders of slices: their files, not below) for
    the rest of the process."""
    _FILES.update(Path(os.path.expanduser(os.fspath(p))).resolve() for p in paths)


def _bundled_samples() -> Path | None:
    try:
        import voxwarp.sample_volumes as samples
    except ImportError:  # pragma: no cover - always installed with voxwarp
        return None
    return Path(samples.__file__).resolve().parent


def current_folders() -> list[Path]:
    """Every folder allowed now, besides the naming file's own folder."""
    env = os.environ.get(ALLOW_DIRS_ENV, "")
    found = [*_SCOPED.get(), *_PROCESS]
    found += [Path(os.path.expanduser(d)).resolve() for d in env.split(os.pathsep) if d]
    samples = _bundled_samples()
    return found if samples is None else [*found, samples]


def outside_allowed(target: str | os.PathLike[str], home: str | os.PathLike[str]) -> bool:
    """Whether ``target`` (resolved, symlinks followed) lies outside ``home`` (the naming
    file's folder) and every allowed folder."""
    real = Path(target).resolve()
    if real in _FILES or real.parent in _FILES:
        return False
    folders = [Path(home).resolve(), *current_folders()]
    return not any(real.is_relative_to(f) for f in folders)


def allow_hint(target: str | os.PathLike[str]) -> str:
    """The fix an error line names for ``target``: the option and variable that allow its
    folder."""
    folder = Path(target).resolve().parent
    return f"pass --allow-dir {folder} or set {ALLOW_DIRS_ENV}={folder}"
