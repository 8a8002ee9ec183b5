"""Hand memory the allocator keeps after big temporaries back to the system.

glibc serves arrays below its (self-raising, up to 32 MiB) mmap threshold from its heap
and keeps freed pages resident; after building a skip map of a 256³ volume those freed
temporaries were about as large as the map itself. :func:`return_freed_memory` asks it
to give them back (``malloc_trim(0)``, milliseconds); elsewhere it does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys
from functools import cache
from typing import Any


@cache
def _libc() -> Any:
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        return libc if hasattr(libc, "malloc_trim") else None
    except OSError:
        return None


def return_freed_memory() -> bool:
    """Return freed heap pages to the system (glibc); True when the call was made."""
    libc = _libc()
    if libc is None:
        return False
    libc.malloc_trim(0)
    return True
