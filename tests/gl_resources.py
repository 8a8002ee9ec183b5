"""What a process holds, for the resource tests: resident memory, open descriptors and
the GL objects alive in a context, counted by the driver itself.

:func:`gl_objects` asks the current context with ``glIs*`` about every name up to the
highest one it could hand out now (found by generating a probe name per kind and
deleting it), so it counts what exists in the driver, whatever moderngl's wrappers say:
an object whose wrapper was dropped without ``release()`` still counts.
"""

from __future__ import annotations

import ctypes
import functools
import os
from typing import Any

# (glIs*, glGen*/glCreate*, glDelete*) per kind; programs and shaders share names
_KINDS = {
    "texture": ("glIsTexture", "glGenTextures", "glDeleteTextures"),
    "buffer": ("glIsBuffer", "glGenBuffers", "glDeleteBuffers"),
    "framebuffer": ("glIsFramebuffer", "glGenFramebuffers", "glDeleteFramebuffers"),
    "renderbuffer": ("glIsRenderbuffer", "glGenRenderbuffers", "glDeleteRenderbuffers"),
    "vertex_array": ("glIsVertexArray", "glGenVertexArrays", "glDeleteVertexArrays"),
    "sampler": ("glIsSampler", "glGenSamplers", "glDeleteSamplers"),
    "query": ("glIsQuery", "glGenQueries", "glDeleteQueries"),
}


def rss_kb() -> float:
    """Resident set size in KB (``/proc/self/statm``)."""
    with open("/proc/self/statm", encoding="ascii") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1024


def fds() -> int:
    """Open file descriptors (``/proc/self/fd``)."""
    return len(os.listdir("/proc/self/fd"))


@functools.cache
def _gl() -> Any:
    for name in ("libOpenGL.so.0", "libGL.so.1"):
        try:
            return ctypes.CDLL(name)
        except OSError:
            continue
    raise OSError("no libOpenGL.so.0 or libGL.so.1 to count GL objects with")


def _highest(lib: Any, gen: str, delete: str) -> int:
    name = ctypes.c_uint(0)
    getattr(lib, gen)(1, ctypes.byref(name))
    getattr(lib, delete)(1, ctypes.byref(name))
    return int(name.value)


def gl_objects(ctx: Any) -> dict[str, int]:
    """GL objects alive per kind in ``ctx`` (made current for the count), and
    ``programs`` (programs and shaders)."""
    from voxwarp.render.context import egl_current, egl_restore

    lib = _gl()
    out: dict[str, int] = {}
    saved = egl_current()
    ctx.mglo.__enter__()
    try:
        for kind, (is_, gen, delete) in _KINDS.items():
            test = getattr(lib, is_)
            test.restype = ctypes.c_ubyte
            out[kind] = sum(1 for n in range(1, _highest(lib, gen, delete) + 1) if test(n))
        lib.glCreateProgram.restype = ctypes.c_uint
        top = int(lib.glCreateProgram())
        lib.glDeleteProgram(top)
        lib.glIsProgram.restype = lib.glIsShader.restype = ctypes.c_ubyte
        out["programs"] = sum(1 for n in range(1, top) if lib.glIsProgram(n) or lib.glIsShader(n))
    finally:
        egl_restore(saved)
    return out
