"""GPU programs shared per moderngl context: each shader text is compiled once per
context, not once per warp, solver or renderer that uses it.

Compiling and freeing a program for every new warp costs a compile each time and, on
Mesa's llvmpipe, native memory that is not all given back. So the wrappers in
:mod:`voxwarp.deform` and :mod:`voxwarp.render` take their programs from here:

>>> hold = program(ctx, vertex_shader=vert, fragment_shader=frag)  # doctest: +SKIP
>>> hold.program["u_scale"].value = 2.0  # doctest: +SKIP
>>> hold.release()  # this user is done; the program itself stays  # doctest: +SKIP

Each call returns a :class:`SharedProgram`, one user's hold on the program. Programs are
keyed by their full shader text (defines included) and kept per context object (a
weak-key dictionary, so a new context never meets a dead context's programs, even when
it reuses the old one's ``id``); they die with their context. A program nobody holds any
more is kept for the next user, up to :data:`IDLE_LIMIT` of them per context; beyond that
the least recently used idle one is freed when a new program is compiled (the context is
current then), so many grid sizes or render variants over a long session stay bounded.

A shared program's uniforms are shared too: every user sets the uniforms it relies on
before each draw or dispatch, as all of voxwarp's wrappers do.
"""

from __future__ import annotations

import threading
import weakref
from collections import OrderedDict
from collections.abc import Callable, Sequence
from typing import Any

#: idle programs (held by nobody) kept per context for their next user
IDLE_LIMIT = 32

_LOCK = threading.Lock()


class _Entry:
    __slots__ = ("key", "program", "users")

    def __init__(self, key: tuple, program: Any) -> None:
        self.key = key
        self.program = program
        self.users = 0


class _ContextPrograms:
    """The programs of one context, most recently used last."""

    def __init__(self) -> None:
        self.entries: OrderedDict[tuple, _Entry] = OrderedDict()

    def evict(self) -> None:
        idle = [e for e in self.entries.values() if e.users == 0]
        for e in idle[: max(0, len(idle) - IDLE_LIMIT)]:
            del self.entries[e.key]
            try:
                e.program.release()
            except Exception:  # context already gone: nothing left to free
                pass


_CACHES: weakref.WeakKeyDictionary[Any, _ContextPrograms] = weakref.WeakKeyDictionary()


class SharedProgram:
    """One user's hold on a program shared by every user of the same shader text on a
    context.

    Attributes
    ----------
    program
        The ``moderngl.Program`` or ``moderngl.ComputeShader``; never release it
        directly.
    """

    __slots__ = ("_entry", "program")

    def __init__(self, entry: _Entry) -> None:
        self._entry: _Entry | None = entry
        self.program = entry.program

    def release(self) -> None:
        """Give up this hold (idempotent). The program stays for other and later users;
        it is freed with its context or when too many programs sit idle."""
        with _LOCK:
            if self._entry is not None:
                self._entry.users = max(0, self._entry.users - 1)
                self._entry = None


def _context_gone(ctx: Any) -> bool:
    return type(getattr(ctx, "mglo", None)).__name__ == "InvalidObject"


def _acquire(ctx: Any, key: tuple, make: Any) -> SharedProgram:
    with _LOCK:
        cache = _CACHES.get(ctx)
        if cache is None or _context_gone(ctx):
            cache = _CACHES[ctx] = _ContextPrograms()
        entry = cache.entries.get(key)
        if entry is None:
            entry = _Entry(key, make())  # compile errors propagate, nothing is kept
            cache.entries[key] = entry
            entry.users += 1
            cache.evict()  # a new program: the context is current, free surplus idle ones
        else:
            entry.users += 1
            cache.entries.move_to_end(key)
        return SharedProgram(entry)


def program(
    ctx: Any,
    *,
    vertex_shader: str,
    fragment_shader: str | None = None,
    geometry_shader: str | None = None,
    varyings: Sequence[str] = (),
) -> SharedProgram:
    """A hold on the program of these shader texts on ``ctx``, compiled on first use
    (``ctx`` must be current then); ``ctx.program``'s errors propagate."""
    key = ("program", vertex_shader, fragment_shader, geometry_shader, tuple(varyings))

    def make() -> Any:
        kwargs: dict[str, Any] = {"vertex_shader": vertex_shader}
        if fragment_shader is not None:
            kwargs["fragment_shader"] = fragment_shader
        if geometry_shader is not None:
            kwargs["geometry_shader"] = geometry_shader
        if varyings:
            kwargs["varyings"] = list(varyings)
        return ctx.program(**kwargs)

    return _acquire(ctx, key, make)


class KeyedPrograms:
    """A renderer's holds on shared full-screen programs, one per key of its own (the
    warp chain's signatures, defines...): :meth:`get` compiles a key's program on first
    use, :meth:`release` gives every hold back."""

    def __init__(self, ctx: Any, vertex_shader: str) -> None:
        self.ctx = ctx
        self.vertex_shader = vertex_shader
        self._holds: dict[Any, SharedProgram] = {}

    def get(self, key: Any, fragment_shader: Callable[[], str]) -> Any:
        """The program of ``key``; ``fragment_shader()`` builds its source the first
        time (``ctx.program``'s errors propagate, nothing is kept)."""
        hold = self._holds.get(key)
        if hold is None:
            hold = program(
                self.ctx, vertex_shader=self.vertex_shader, fragment_shader=fragment_shader()
            )
            self._holds[key] = hold
        return hold.program

    def release(self) -> None:
        """Give up every hold (idempotent)."""
        for hold in self._holds.values():
            hold.release()
        self._holds.clear()


def compute_shader(ctx: Any, source: str) -> SharedProgram:
    """A hold on the compute shader of ``source`` on ``ctx``, compiled on first use."""
    return _acquire(ctx, ("compute", source), lambda: ctx.compute_shader(source))


def program_count(ctx: Any) -> tuple[int, int]:
    """``(held, idle)``: how many of ``ctx``'s shared programs have users, and how many
    sit idle (diagnostics and tests)."""
    with _LOCK:
        cache = _CACHES.get(ctx)
        if cache is None:
            return (0, 0)
        held = sum(1 for e in cache.entries.values() if e.users > 0)
        return (held, len(cache.entries) - held)
