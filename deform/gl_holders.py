"""Who keeps GL objects cached on a moderngl context, so that whoever ends that context's
use can free them all.

A warp uploads its textures on first use per context and keeps them for the next draw.
On a context that lives on after its renderers (the pooled context of
:mod:`voxwarp.render.context_pool`), those textures would stay as long as the warp
does. So a warp that caches GL objects on ``ctx`` registers itself here:

>>> gl_holders.hold(ctx, self)  # doctest: +SKIP

and implements ``release_context(ctx)``: free what it keeps on ``ctx`` (the context is
current then) and forget it, so a later use uploads again instead of using a dead
object. :func:`release_context` calls that on every live holder of ``ctx``. Holders are
kept weakly (per context, itself a weak key): registering keeps nothing alive.
"""

from __future__ import annotations

import threading
import weakref
from typing import Any

_LOCK = threading.Lock()
_HOLDERS: weakref.WeakKeyDictionary[Any, weakref.WeakSet[Any]] = weakref.WeakKeyDictionary()


def hold(ctx: Any, owner: Any) -> None:
    """Record that ``owner`` keeps GL objects on ``ctx`` (it must have a
    ``release_context(ctx)`` method); idempotent."""
    with _LOCK:
        owners = _HOLDERS.get(ctx)
        if owners is None:
            owners = _HOLDERS[ctx] = weakref.WeakSet()
        owners.add(owner)


def release_context(ctx: Any) -> int:
    """Ask every live holder of ``ctx`` to free what it keeps there (``ctx`` must be
    current); returns how many holders were asked. Holders register again on their
    next upload."""
    with _LOCK:
        owners = list(_HOLDERS.pop(ctx, ()))
    for owner in owners:
        owner.release_context(ctx)
    return len(owners)


def holder_count(ctx: Any) -> int:
    """How many live holders keep GL objects on ``ctx`` (diagnostics and tests)."""
    with _LOCK:
        return len(_HOLDERS.get(ctx, ()))
