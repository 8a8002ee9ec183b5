"""The support cache keys each warp by a token that no later warp reuses.

Oracle: the chain itself. A warp that moves nothing plans "none"; a new warp that moves a
node plans "map", even when CPython gives it the freed address (``id()``) of the still
one at the same revision and uniforms (the stale key drew a drag as the undeformed
image, found by ``test_support_render`` on CI).
"""

from __future__ import annotations

import numpy as np

from voxwarp.core.volume import Volume
from voxwarp.deform.elements.offset_field import OffsetFieldWarp
from voxwarp.deform.identity import token
from voxwarp.render.skipping.support import SupportCache, uniforms_key
from voxwarp.scene import Scene


def volume() -> Volume:
    return Volume(np.zeros((16, 16, 16), np.uint8), spacing=(2.0, 2.0, 2.0))


def displacements(moved: bool) -> np.ndarray:
    u = np.zeros((5, 5, 5, 3))
    if moved:
        u[2, 2, 2] = (3.0, 0.0, 0.0)
    return u


def planned(cache: SupportCache, vol: Volume, warp: OffsetFieldWarp) -> str:
    scene = Scene(vol, warps=[warp])
    cache.plan(scene)  # the first draw of a state builds nothing ("auto")
    return cache.plan(scene)


def test_a_new_warp_at_a_freed_address_gets_its_own_map() -> None:
    vol, cache = volume(), SupportCache(None)
    lo, hi = vol.bounds
    still_u, moved_u = displacements(False), displacements(True)
    reused = 0
    for _ in range(20):
        warp = OffsetFieldWarp(lo, hi, still_u, inverse="approx")
        assert planned(cache, vol, warp) == "none"
        old = id(warp)
        del warp  # nothing allocated until the next warp: CPython hands out the address
        warp = OffsetFieldWarp(lo, hi, moved_u, inverse="approx")
        reused += id(warp) == old
        assert planned(cache, vol, warp) == "map"
        del warp
    assert reused, "CPython reused no address: the case this test is for did not occur"


class Thing:
    """A weakly referenceable object."""


def test_tokens_are_never_reused_and_stay_with_their_object() -> None:
    seen: dict[int, int] = {}
    for _ in range(50):
        thing = Thing()
        t = token(thing)
        assert token(thing) == t
        assert t not in seen.values()
        seen[id(thing)] = t
        del thing
    assert len(seen) < 50, "no address was reused: the case this test is for did not occur"


def test_uniform_keys_tell_long_arrays_apart_in_the_middle() -> None:
    a = np.zeros(5000, np.float32)
    b = a.copy()
    b[2500] = 1.0  # repr() prints both as "array([0., 0., 0., ..., 0., 0., 0.])"
    assert repr(a) == repr(b)
    assert uniforms_key({"u": a}) != uniforms_key({"u": b})
    assert uniforms_key({"u": a, "v": 1.0}) == uniforms_key({"v": 1.0, "u": a.copy()})
    assert uniforms_key({"u": (1.0, 2.0)}) != uniforms_key({"u": (1.0, 2.5)})
