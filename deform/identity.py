"""Identity tokens for cache keys: a number no other live or dead object of this process
had, unlike ``id()``, which a new object reuses once the old one is collected.

Caches of derived data (support and skip maps, baked meshes, overlay lines) key on
``(token(warp), warp.revision, ...)``; with ``id()`` a new warp at a freed address, at
the same revision, found the old warp's map and was drawn as it (a flaky render test
caught it). Use :func:`token` for any object that can be weakly referenced.
"""

from __future__ import annotations

import itertools
import weakref
from typing import Any

_SERIALS = itertools.count(1)
#: id(obj) -> (weak reference to obj, its token); an entry goes when its object dies
_TOKENS: dict[int, tuple[weakref.ref, int]] = {}


def token(obj: Any) -> int:
    """The object's token: the same number for the object's lifetime, never given to
    another object of this process (raises TypeError for objects without weak
    references)."""
    key = id(obj)
    hit = _TOKENS.get(key)
    if hit is not None and hit[0]() is obj:
        return hit[1]
    serial = next(_SERIALS)

    def forget(_ref: weakref.ref, key: int = key, serial: int = serial) -> None:
        entry = _TOKENS.get(key)
        if entry is not None and entry[1] == serial:
            del _TOKENS[key]

    _TOKENS[key] = (weakref.ref(obj, forget), serial)
    return serial
