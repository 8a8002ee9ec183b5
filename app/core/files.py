"""Atomic file writes: a file appears complete or not at all, never half written.

Every writer in voxwarp (volumes, scene JSON, images, benchmark tables) goes through
:func:`atomic_write`: it writes a temporary file in the target's folder, then renames
it over the target with ``os.replace``; on any failure the temporary file is removed
and a previous version of the target stays intact.
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Callable
from pathlib import Path


def temp_name(final: Path, suffix: str) -> Path:
    """A hidden, unique temporary path beside ``final`` ending in ``suffix``.

    The suffix is kept so that libraries choosing the format by extension (NIfTI,
    OpenImageIO) write the right format.
    """
    return final.with_name(f".{final.name}.{os.getpid()}-{secrets.token_hex(4)}.tmp{suffix}")


def atomic_write(final: Path, suffix: str, write: Callable[[Path], None]) -> None:
    """Write through ``write(tmp)`` to a temporary file, then rename it to ``final``."""
    tmp = temp_name(final, suffix)
    try:
        write(tmp)
        os.replace(tmp, final)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically, synced to disk, creating folders."""
    path.parent.mkdir(parents=True, exist_ok=True)

    def write(tmp: Path) -> None:
        with open(tmp, "x", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())

    atomic_write(path, ".tmp", write)
