"""One thread for a notebook object's OpenGL work.

An OpenGL (EGL) context is current in one thread at a time, but Jupyter calls a widget
from more than one: cells run on the kernel's main thread, while JupyterLab's widget
messages (pointer events, frame requests) can arrive on a subshell thread (ipykernel 7).
:class:`GLThread` runs every call it is given on a single thread of its own, which
creates the context and keeps it current; callers wait for the result (exceptions are
raised in the caller). That also serialises the edits coming from both sides.
:class:`SameThread` is the stand-in for a context the caller owns and makes current
itself: calls run where they are made.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any


class GLThread:
    """Runs calls on one worker thread (see the module docstring)."""

    def __init__(self, name: str = "voxwarp-gl") -> None:
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix=name)
        self._ident: int | None = None

    def run(self, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        """``fn(*args, **kwargs)`` on the worker thread (directly when called from it)."""
        if threading.get_ident() == self._ident:
            return fn(*args, **kwargs)
        return self._pool.submit(self._call, fn, args, kwargs).result()

    def _call(self, fn: Callable[..., Any], args: tuple, kwargs: dict) -> Any:
        self._ident = threading.get_ident()
        return fn(*args, **kwargs)

    def shutdown(self) -> None:
        """Stop the worker (after the calls queued so far; from the worker itself, as
        a widget collected there may ask, without waiting for itself)."""
        self._pool.shutdown(wait=threading.get_ident() != self._ident)


class SameThread:
    """Runs calls where they are made (a context the caller makes current)."""

    def run(self, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        """``fn(*args, **kwargs)``."""
        return fn(*args, **kwargs)

    def shutdown(self) -> None:
        """Nothing to stop."""
