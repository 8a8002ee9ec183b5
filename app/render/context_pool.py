"""The pooled headless context: one standalone EGL context per rendering thread, lent
to every :class:`~voxwarp.render.offscreen.OffscreenRenderer` made without ``ctx=``
and taken back when it closes.

Creating and releasing a standalone EGL context grows the process by 100-270 KB that
moderngl and the driver never give back (bare
``moderngl.create_standalone_context(backend="egl").release()`` does it without
voxwarp), so a process that makes renderers in a loop (a notebook, napari, a batch
export) would grow without bound. So contexts are made once and reused:

>>> ctx = acquire()  # this thread's context (made on first use)  # doctest: +SKIP
>>> give_back(ctx)  # doctest: +SKIP

Every renderer of one thread shares that thread's context (they may be open at the
same time); another thread gets another context. When a thread's last lease comes
back, the context is cleaned and put on a free list for any thread: what warps cached
on it is freed (:func:`voxwarp.deform.gl_holders.release_context`; a warp used again
uploads again), so are the GL objects whose moderngl wrappers were dropped without
``release()`` (the pooled contexts run in moderngl's ``context_gc`` mode; :func:`collect`
frees that queue), and the context is made not current on this thread (a context whose
last lease comes back on another thread leaves the pool: its own thread may still hold
it current). What stays is
bounded: the shared programs of :mod:`voxwarp.deform.gl_programs`, kept to compile
nothing twice. Contexts live until the process ends (a forked child starts with an
empty pool). The GUI's Qt context is not pooled.
"""

from __future__ import annotations

import os
import threading
from typing import Any

from voxwarp.deform import gl_holders
from voxwarp.render.context import create_context, egl_current, egl_restore, egl_uncurrent

_LOCK = threading.Lock()


class _Pooled:
    """One pooled context, its EGL handle and how many leases it has out."""

    __slots__ = ("ctx", "egl", "leases")

    def __init__(self, ctx: Any, egl: int | None) -> None:
        self.ctx, self.egl, self.leases = ctx, egl, 0


_LEASED: dict[int, _Pooled] = {}  # thread ident -> the context its renderers share
_FREE: list[_Pooled] = []
_MADE = [0]


def _forget_after_fork() -> None:
    """A forked child starts with an empty pool: its parent's contexts are not its own."""
    global _LOCK
    _LOCK = threading.Lock()
    _LEASED.clear()
    _FREE.clear()


os.register_at_fork(after_in_child=_forget_after_fork)


def acquire() -> Any:
    """This thread's pooled context, with one more lease: the one its open renderers
    share, else a free one, else a new one (:func:`create_context`'s error if none can
    be made). Give it back with :func:`give_back`."""
    tid = threading.get_ident()
    with _LOCK:
        entry = _LEASED.get(tid)
        if entry is None and _FREE:
            entry = _LEASED[tid] = _FREE.pop()
        if entry is not None:
            entry.leases += 1
            return entry.ctx
    entry = _make()  # slow, outside the lock; only this thread adds its own entry
    with _LOCK:
        _LEASED[tid] = entry
        entry.leases += 1
        _MADE[0] += 1
    return entry.ctx


def _make() -> _Pooled:
    saved = egl_current()  # before: creating a context makes it current
    ctx = create_context()
    ctx.gc_mode = "context_gc"  # wrappers dropped unreleased are queued for collect()
    ctx.mglo.__enter__()
    mine = egl_current()
    if saved is not None:
        egl_restore(saved)
    elif mine is not None:
        egl_uncurrent(mine[3])
    return _Pooled(ctx, None if mine is None else mine[3])


def give_back(ctx: Any) -> None:
    """Return one lease of ``ctx``; the last one cleans it (see the module) and frees
    it for any thread. A context not from the pool is ignored."""
    with _LOCK:
        found = [(tid, e) for tid, e in _LEASED.items() if e.ctx is ctx]
        if not found:
            return
        tid, entry = found[0]
        entry.leases -= 1
        if entry.leases > 0:
            return
        del _LEASED[tid]
        if tid != threading.get_ident():
            return  # its thread may still hold it current: it cannot be lent again
    try:
        _clean(entry)
    finally:
        with _LOCK:
            _FREE.append(entry)


def _clean(entry: _Pooled) -> None:
    saved = egl_current()
    entry.ctx.mglo.__enter__()
    try:
        gl_holders.release_context(entry.ctx)
        collect(entry.ctx)
    finally:
        if saved is not None and saved[3] != entry.egl:
            egl_restore(saved)
        else:
            egl_uncurrent(entry.egl)


def collect(ctx: Any) -> int:
    """Free the GL objects whose wrappers were dropped unreleased on ``ctx`` (it must be
    current); returns how many. Cheap when there are none.

    Not ``ctx.gc()``: moderngl queues the wrappers released properly too (as an
    ``InvalidObject`` without ``release``), which that call fails on."""
    queue = ctx.objects
    freed = 0
    while queue:
        mglo = queue.popleft()
        if type(mglo).__name__ != "InvalidObject":
            mglo.release()
            freed += 1
    return freed


def is_pooled(ctx: Any) -> bool:
    """Whether ``ctx`` is one of the pool's contexts."""
    with _LOCK:
        return any(e.ctx is ctx for e in (*_LEASED.values(), *_FREE))


def pool_stats() -> dict[str, int]:
    """``made`` (contexts created so far), ``leased`` (contexts lent out now), ``free``
    and ``leases`` (renderers holding one): diagnostics and tests."""
    with _LOCK:
        return {
            "made": _MADE[0],
            "leased": len(_LEASED),
            "free": len(_FREE),
            "leases": sum(e.leases for e in _LEASED.values()),
        }
