"""The support cache keys each warp by a token that no later warp reuses.

Oracle: the chain itself. A warp that moves nothing plans "none"; a new warp that moves a
node plans "map", even when CPython gives it the freed address (``id()``) of the still
one at the same revision and uniforms (the stale key drew a drag as the undeformed
image, found by ``test_support_render`` on CI).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from voxwarp.core.volume import Volume
from voxwarp.deform.elements.offset_field import OffsetFieldWarp
from voxwarp.deform.identity import token
from voxwarp.errors import RenderError
from voxwarp.render.skipping.support import MAP_MAX_FRACTION, SupportCache, uniforms_key
from voxwarp.scene import Scene


def volume() -> Volume:
    return Volume(np.zeros((16, 16, 16), np.uint8), spacing=(2.0, 2.0, 2.0))


def displacements(moved: bool) -> np.ndarray:
    """A 9³ grid over the volume, still or with one node off-centre moved 1 mm: a local
    support (well under MAP_MAX_FRACTION of the bricks)."""
    u = np.zeros((9, 9, 9, 3))
    if moved:
        u[2, 2, 2] = (1.0, 0.0, 0.0)
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


def test_never_builds_no_map_and_a_state_seen_then_gets_one_at_rest() -> None:
    vol, cache = volume(), SupportCache(None)
    lo, hi = vol.bounds
    scene = Scene(vol, warps=[OffsetFieldWarp(lo, hi, displacements(True), inverse="approx")])
    cache.build = "never"  # the window while the user drags: three slices per state
    assert [cache.plan(scene) for _ in range(3)] == ["all"] * 3
    assert cache._map is None
    cache.build = "auto"  # at rest: the state was drawn before, so its map is built now
    assert cache.plan(scene) == "map"


@pytest.mark.gl
def test_the_renderer_gives_its_support_maps_setting_to_the_slices(offscreen: Any) -> None:
    r = offscreen(16, 16).renderer
    vol = volume()
    lo, hi = vol.bounds
    scene = Scene(vol, warps=[OffsetFieldWarp(lo, hi, displacements(True), inverse="approx")])
    m = np.eye(4)
    try:
        r.support_maps = "never"
        r.slice_values(scene, m, (8, 8))
        cache = r._slice_renderer.support
        before = cache._map  # a map of an earlier test's state, or None
        for _ in range(3):
            r.slice_values(scene, m, (8, 8))
        assert cache._map is before, "no map built while 'never'"
        r.support_maps = "auto"
        r.slice_values(scene, m, (8, 8))
        assert cache._map is not before
        assert cache._map is not None
        with pytest.raises(RenderError, match="support_maps must be"):
            r.support_maps = "sometimes"
    finally:
        r.support_maps = "auto"


def test_a_support_over_most_of_the_bricks_draws_the_chain_everywhere() -> None:
    """The map path's loops cost more than they save when most rays chain most samples:
    above ``map_max_fraction`` of the bricks the plan is "all", at or below it "map"."""
    vol = volume()
    lo, hi = vol.bounds
    u = np.zeros((5, 5, 5, 3))
    u[2, 2, 2] = (3.0, 0.0, 0.0)  # the middle node of a coarse grid: a wide support
    cache = SupportCache(None)
    cache.build = "always"
    scene = Scene(vol, warps=[OffsetFieldWarp(lo, hi, u, inverse="approx")])
    fraction = cache.support(scene).fraction
    assert MAP_MAX_FRACTION < fraction < 1.0
    assert cache.plan(scene) == "all"
    cache.map_max_fraction = fraction
    assert cache.plan(scene) == "map"
