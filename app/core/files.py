"""Atomic, checked file writes: a file appears complete or not at all, never half written.

Every writer in voxwarp (images, frames, volumes, scene JSON, manifests, meshes,
benchmark tables) goes through :func:`atomic_output`. It hands the writer a temporary
path in the destination's folder; once the writer returns, the temporary file is synced
to disk and renamed over the destination with ``os.replace``. On any failure (the
writer raising, a short write, the sync, the rename) the temporary file is removed, a
previous version of the destination stays intact, and an :class:`OSError` becomes an
:class:`~voxwarp.errors.OutputError` whose one-line message names the path and the
cause::

    from voxwarp.core.files import atomic_output, atomic_open

    with atomic_output(path, ".nii.gz") as tmp:   # a library writes a file by name
        nib.save(img, str(tmp))

    with atomic_open(path, "w") as fh:            # or write through a file object
        json.dump(doc, fh)

    # OutputError: cannot write /data/out.png: disk full (No space left on device); ...

A writer that reports failure by a return value instead of an exception (OpenImageIO)
raises :func:`output_error` itself. Temporary names are hidden and recognisable
(``.NAME.PID-XXXXXXXX.vwtmp[SUFFIX]``, see :func:`is_temp_name`), never stack
(``.tmp.tmp``), and :func:`remove_stale_temps` removes those a killed process left.
"""

from __future__ import annotations

import errno as _errno
import math
import os
import re
import secrets
import shutil
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

from voxwarp.core.limits import format_bytes
from voxwarp.errors import OutputError

#: Marks every temporary file voxwarp writes (before the format's own suffix).
TEMP_MARK = ".vwtmp"

# ".NAME.PID-8hex.vwtmp[.suffix]"; the legacy ".tmp" mark of earlier versions too
_TEMP_RE = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)-[0-9a-f]{8}\.(?:vwtmp|tmp)(?:\..*)?$")

#: errno -> (cause, fix) for the one-line message of :class:`OutputError`.
_CAUSES: dict[int, tuple[str, str]] = {
    _errno.ENOSPC: ("disk full", "free some space or write to another disk"),
    _errno.EDQUOT: ("disk quota exceeded", "free some space or write to another disk"),
    _errno.EFBIG: ("file too large for this file system", "write to another disk"),
    _errno.EROFS: ("read-only file system", "write to a writable folder"),
    _errno.EACCES: ("permission denied", "write to a folder you may write to"),
    _errno.EPERM: ("permission denied", "write to a folder you may write to"),
    _errno.ENOENT: ("folder does not exist", "create the folder or fix the path"),
    _errno.ENOTDIR: ("a part of the path is not a folder", "fix the path"),
    _errno.EISDIR: ("it is a folder", "name a file, not a folder"),
    _errno.EIO: ("input/output error", "check the disk"),
}

# texts of libraries that report no errno (OpenImageIO, ...) -> errno
_TEXT_ERRNO = (
    ("no space left", _errno.ENOSPC),
    ("disk quota", _errno.EDQUOT),
    ("read-only file system", _errno.EROFS),
    ("permission denied", _errno.EACCES),
    ("file too large", _errno.EFBIG),
)


def output_error(path: str | os.PathLike, cause: BaseException | str) -> OutputError:
    """The one-line :class:`OutputError` for a failed write of ``path``.

    ``cause`` is the :class:`OSError` raised (its errno picks the cause and the fix) or
    a library's error text (recognised phrases such as "No space left on device" map to
    the same causes).
    """
    code = getattr(cause, "errno", None) if isinstance(cause, BaseException) else None
    if isinstance(cause, OSError):
        detail = cause.strerror or str(cause) or type(cause).__name__
    else:
        detail = str(cause) or type(cause).__name__
    detail = " ".join(detail.split())  # one line whatever the library printed
    if code is None:
        low = detail.lower()
        code = next((c for text, c in _TEXT_ERRNO if text in low), None)
    if code is None:  # a short write with no errno (numpy's tofile, OpenImageIO)
        code = _probe_errno(Path(path).parent)
        if code is not None:
            detail = f"{os.strerror(code)}: {detail}"
    if code == _errno.EFBIG and math.isfinite(cap := file_size_limit()):
        what = f"file too large for this process's file-size limit of {format_bytes(int(cap))}"
        msg = f"cannot write {path}: {what} ({detail}); raise the limit (ulimit -f) or write less"
    elif code in _CAUSES:
        what, fix = _CAUSES[code]
        msg = f"cannot write {path}: {what} ({detail}); {fix}"
    else:
        msg = f"cannot write {path}: {detail}"
    return OutputError(msg, path=str(path), errno=code)


def _probe_errno(folder: Path) -> int | None:
    """Why writing in ``folder`` fails, for errors that carry no errno: the errno of
    creating a probe file there, else ``ENOSPC`` when no space is left, else None."""
    probe = folder / f".{os.getpid()}-{secrets.token_hex(4)}{TEMP_MARK}.probe"
    try:
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
    except OSError as exc:
        return exc.errno if exc.errno in _CAUSES else None
    _discard(probe)
    try:
        return _errno.ENOSPC if os.statvfs(folder).f_bavail == 0 else None
    except OSError:
        return None


def file_size_limit() -> float:
    """The process's file-size limit in bytes (``RLIMIT_FSIZE``, ``ulimit -f``); ``inf``
    when unlimited or unknown (no :mod:`resource` on Windows)."""
    try:
        import resource
    except ImportError:
        return math.inf
    soft = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    return math.inf if soft in (resource.RLIM_INFINITY, -1) or soft < 0 else float(soft)


def ensure_room(path: str | os.PathLike, nbytes: int) -> None:
    """Raise :class:`OutputError` before ``nbytes`` are written to ``path`` when they are
    over the process's file-size limit (``EFBIG``) or the free space of its disk
    (``ENOSPC``). For native writers that cannot survive running into either (HDF5
    returns an error, then crashes the process at exit): call it before they start."""
    need = f"the file needs about {format_bytes(nbytes)}"
    if nbytes >= file_size_limit():
        raise output_error(path, OSError(_errno.EFBIG, need))
    folder = Path(path).resolve().parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    try:
        free = shutil.disk_usage(folder).free
    except OSError:
        return  # cannot tell: the write itself reports
    if nbytes > free:
        raise output_error(path, OSError(_errno.ENOSPC, f"{need}, {format_bytes(free)} free"))


def _reached_limit(tmp: Path) -> bool:
    """Whether ``tmp`` is as large as the process's file-size limit (the write was cut
    there); ``False`` without a limit or a file."""
    cap = file_size_limit()
    try:
        return math.isfinite(cap) and tmp.stat().st_size >= cap
    except OSError:
        return False


def _check_not_cut(tmp: Path) -> None:
    """Raise ``EFBIG`` when the written file reached the file-size limit: the write was
    cut there (OpenImageIO, among others, reports no error for the part that did not
    fit and would leave a truncated image)."""
    if _reached_limit(tmp):
        raise OSError(_errno.EFBIG, os.strerror(_errno.EFBIG))


def _failure(exc: OSError, final: Path, tmp: Path, cut: bool) -> OSError:
    """The :class:`OutputError` to raise for ``exc``, a failed write of ``final`` through
    ``tmp``: worded by its errno (``EFBIG`` when ``cut``, the file having reached the
    file-size limit, and the library gave no errno), naming ``final``, never ``tmp``.
    Returns ``exc`` itself when it is already that error."""
    error: OSError = exc
    if cut and exc.errno is None:  # a library's short write (OpenImageIO's text)
        prefix = f"cannot write {final}: "
        text = str(exc).removeprefix(prefix) if isinstance(exc, OutputError) else str(exc)
        error = output_error(final, OSError(_errno.EFBIG, text or os.strerror(_errno.EFBIG)))
    elif not isinstance(exc, OutputError):
        error = output_error(final, exc)
    text = str(error)
    if str(tmp) in text or tmp.name in text:  # HDF5 names the file it could not open
        text = text.replace(str(tmp), str(final)).replace(tmp.name, final.name)
        error = OutputError(text, path=str(final), errno=error.errno)
    return error


def temp_name(final: Path, suffix: str = "") -> Path:
    """A hidden, unique temporary path beside ``final``: ``.NAME.PID-HEX.vwtmp`` + ``suffix``.

    ``suffix`` (e.g. ``".png"``, ``".nii.gz"``) is kept so that libraries choosing the
    format by extension write the right format. The name of a temporary file is never
    nested into another (a ``final`` that is itself a temporary name is used by its
    real name).
    """
    final = Path(final)
    m = _TEMP_RE.match(final.name)
    name = m.group("name") if m else final.name
    if suffix == TEMP_MARK or suffix == ".tmp":  # no ".vwtmp.tmp"
        suffix = ""
    return final.with_name(f".{name}.{os.getpid()}-{secrets.token_hex(4)}{TEMP_MARK}{suffix}")


def is_temp_name(name: str | os.PathLike) -> bool:
    """Whether ``name`` (a file name or path) is a temporary file of :func:`temp_name`
    (or of an earlier voxwarp, ``.NAME.PID-HEX.tmp...``)."""
    return _TEMP_RE.match(Path(name).name) is not None


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True  # exists (another user's), or cannot tell: keep its files
    return True


def remove_stale_temps(
    folder: str | os.PathLike, *, for_name: str | None = None, min_age_s: float = 0.0
) -> list[Path]:
    """Remove the temporary files that writers killed before finishing left in ``folder``.

    A temporary file is stale when the process that wrote it (its name holds the pid)
    no longer runs on this machine and it is at least ``min_age_s`` seconds old (give a
    margin when other machines write into a shared folder: their pids mean nothing
    here). ``for_name`` limits the cleaning to the temporaries of that one destination
    name. Files that cannot be removed are left. Returns the paths removed.
    """
    removed: list[Path] = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    now = time.time()
    for entry in entries:
        m = _TEMP_RE.match(entry.name)
        if m is None or (for_name is not None and m.group("name") != for_name):
            continue
        try:
            if not entry.is_file(follow_symlinks=False) or _pid_alive(int(m.group("pid"))):
                continue
            if now - entry.stat(follow_symlinks=False).st_mtime < min_age_s:
                continue
            os.unlink(entry.path)
        except OSError:
            continue
        removed.append(Path(entry.path))
    return removed


def _discard(tmp: Path) -> None:
    """Remove ``tmp`` if it is there; a failing removal (read-only disk) never hides the
    error that made the write fail."""
    try:
        os.unlink(tmp)
    except OSError:
        pass


def _sync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _sync_folder(folder: Path) -> None:
    """Make the rename durable; file systems that cannot sync a folder are passed over."""
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextmanager
def atomic_output(
    path: str | os.PathLike, suffix: str | None = None, *, mkdir: bool = True
) -> Iterator[Path]:
    """Yield a temporary path to write; on success it replaces ``path`` atomically. The
    temporaries of ``path`` that killed writers left (:func:`remove_stale_temps`) are
    removed first (every writer cleans up after a kill on its next run, as ``animate``
    does) and again after the rename.

    Parameters
    ----------
    path
        The destination.
    suffix
        Ending of the temporary name, for libraries that pick the format from the
        extension (``".nii.gz"``); default the destination's last suffix.
    mkdir
        Create the destination's folder first.

    Raises
    ------
    OutputError
        For any :class:`OSError` of the write, the sync or the rename (and when the
        writer left no file); the temporary file is removed first. Other exceptions of
        the writer pass through unchanged, after the same clean-up.

    Examples
    --------
    >>> with atomic_output(out, ".png") as tmp:  # doctest: +SKIP
    ...     library_write(str(tmp))
    """
    final = Path(path)
    if suffix is None:
        suffix = final.suffix
    if mkdir:
        try:
            final.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise output_error(final, exc) from exc
    # first the temporaries of this destination a killed writer left (its pid is gone):
    # a rerun frees their space before it writes, and even when it fails
    remove_stale_temps(final.parent, for_name=final.name)
    tmp = temp_name(final, suffix)
    try:
        yield tmp
        if not tmp.is_file():
            raise OutputError(f"cannot write {final}: the writer produced no file", path=str(final))
        _check_not_cut(tmp)
        _sync_file(tmp)
        os.replace(tmp, final)
    except OSError as exc:  # OutputError too
        cut = _reached_limit(tmp)
        _discard(tmp)
        error = _failure(exc, final, tmp, cut)
        if error is exc:
            raise
        raise error from exc
    except BaseException:
        _discard(tmp)
        raise
    _sync_folder(final.parent)
    # temporaries of this destination that a killed writer left (its pid is gone)
    remove_stale_temps(final.parent, for_name=final.name)


@contextmanager
def atomic_open(
    path: str | os.PathLike,
    mode: str = "w",
    *,
    encoding: str | None = "utf-8",
    suffix: str | None = None,
    mkdir: bool = True,
) -> Iterator[IO[Any]]:
    """Yield a new file object (``mode`` ``"w"`` or ``"wb"``) whose content replaces
    ``path`` atomically once the block ends; every write, the flush, the sync and the
    close are checked (see :func:`atomic_output` for the errors)."""
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open mode must be 'w' or 'wb'; got {mode!r}")
    binary = mode == "wb"
    with atomic_output(path, suffix, mkdir=mkdir) as tmp:
        fh = open(tmp, "xb" if binary else "x", encoding=None if binary else encoding)
        try:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        except BaseException:
            try:
                fh.close()
            except OSError:
                pass  # the first error is the one to report
            raise
        fh.close()  # a failing close (buffered data) raises here, inside the guard


def atomic_write(final: Path, suffix: str, write: Callable[[Path], None]) -> None:
    """Write through ``write(tmp)`` to a temporary file, then rename it to ``final``
    (:func:`atomic_output` as a call)."""
    with atomic_output(final, suffix) as tmp:
        write(tmp)


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically, synced to disk, creating folders."""
    with atomic_open(path, "w", suffix="") as fh:
        fh.write(text)
