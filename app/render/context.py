"""The headless OpenGL context: a standalone EGL context and saving/restoring whichever
EGL context is current (a thread may hold Qt's or another renderer's).

:func:`create_context` makes one (its caller owns it and releases it; renderers lease
one from :mod:`voxwarp.render.context_pool` instead); :func:`egl_current` and
:func:`egl_restore` bracket work on another context so the caller's stays current, and
:func:`egl_uncurrent` lets go of one so that another thread can use it.
"""

from __future__ import annotations

import functools
from typing import Any

from voxwarp.errors import RenderError


@functools.cache
def _egl_library() -> Any:
    """libEGL through ctypes with the few entry points used here typed, or None."""
    import ctypes

    try:
        lib = ctypes.CDLL("libEGL.so.1")
    except OSError:
        return None
    for name in ("eglGetCurrentContext", "eglGetCurrentDisplay", "eglGetCurrentSurface"):
        getattr(lib, name).restype = ctypes.c_void_p
    lib.eglGetCurrentSurface.argtypes = [ctypes.c_int]
    lib.eglMakeCurrent.argtypes = [ctypes.c_void_p] * 4
    return lib


def egl_current() -> tuple | None:
    """The current EGL (display, draw, read, context), or None (no EGL or none current)."""
    lib = _egl_library()
    if lib is None:
        return None
    context = lib.eglGetCurrentContext()
    if not context:
        return None
    return (
        lib.eglGetCurrentDisplay(),
        lib.eglGetCurrentSurface(0x3059),  # EGL_DRAW
        lib.eglGetCurrentSurface(0x305A),  # EGL_READ
        context,
    )


def egl_restore(saved: tuple | None) -> None:
    """Make ``saved`` (from :func:`egl_current`) current again; nothing for None."""
    if saved is not None:
        _egl_library().eglMakeCurrent(*saved)


def egl_uncurrent(context: int | None) -> None:
    """Leave no EGL context current on this thread if ``context`` (an EGL handle, as
    :func:`egl_current` gives) is the current one, so another thread may take it."""
    saved = egl_current()
    if context and saved is not None and saved[3] == context:
        _egl_library().eglMakeCurrent(saved[0], None, None, None)


def create_context() -> Any:
    """A standalone headless OpenGL 4.3+ context through EGL (the caller owns it).

    Whatever EGL context was current before stays current (a new context is left
    current only when none was).
    """
    import moderngl

    saved = egl_current()
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=430)
    except Exception as exc:
        raise RenderError(
            "could not create a headless OpenGL 4.3 context through EGL"
            f" ({exc}). Install Mesa's EGL and GL libraries (Debian: libegl1 libgl1"
            " libegl-mesa0 libgl1-mesa-dri; run `sudo scripts/install-system-deps.sh`)."
        ) from exc
    finally:
        egl_restore(saved)
    return ctx
