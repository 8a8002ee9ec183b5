"""The pooled headless context (voxwarp.render.context_pool, issue 33): renderers made
without ``ctx=`` reuse one EGL context per thread, free every GL object they and the
warps they drew left on it when the last one closes, and a warp drawn again uploads
again. The GL objects are counted by the driver (``glIs*``, tests/gl_resources.py), not
by moderngl's wrappers.

Measured (llvmpipe, 2 cores): a context per renderer grew RSS by 106 KB per
create/render/close cycle (300 cycles, 31 MiB) and left 330 contexts alive; the pool
grows it by 1-6 KB per cycle (0.9 KB over 1000) with one context.
"""

from __future__ import annotations

import gc
import threading
from typing import Any

import numpy as np
import pytest

from tests.gl_resources import fds, gl_objects
from voxwarp.core.volume import Volume
from voxwarp.deform import gl_holders
from voxwarp.deform.elements.offset_field import OffsetFieldWarp
from voxwarp.render import context_pool
from voxwarp.render.context import egl_current
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.scene import Scene

CYCLES = 100


def _volume() -> Volume:
    rng = np.random.default_rng(3)
    return Volume((rng.random((12, 10, 8)) * 100).astype(np.float32), spacing=(1.0, 1.0, 1.0))


def _warp(volume: Volume, seed: int = 1) -> OffsetFieldWarp:
    lo, hi = volume.bounds
    u = np.random.default_rng(seed).normal(0.0, 0.8, (3, 3, 3, 3))
    return OffsetFieldWarp(lo, hi, u, inverse="baked")


def _draw(scene: Scene) -> tuple[Any, np.ndarray]:
    """A renderer's context and its image of ``scene`` (the renderer closed after)."""
    with OffscreenRenderer(24, 24) as r:
        return r.ctx, np.asarray(r.render(scene))


@pytest.mark.timeout(60)
def test_create_close_cycles_reuse_the_context_and_leave_nothing() -> None:
    vol = _volume()
    scenes = [
        Scene(vol, transfer_function="grayscale"),
        Scene(vol, warps=[_warp(vol)], mode="mip", transfer_function="grayscale"),
    ]
    with OffscreenRenderer(16, 16) as r:  # every program variant compiled once
        ctx = r.ctx
        for scene in scenes:
            r.render(scene)
        r.render_slice(scenes[1], "axial", overlay="jacobian")
    made, before, files = context_pool.pool_stats()["made"], gl_objects(ctx), fds()
    with OffscreenRenderer(24, 24) as r:
        r.render(scenes[1])
        during = gl_objects(ctx)
    assert during["texture"] > before["texture"]  # the count sees a renderer's objects
    assert during["framebuffer"] > before["framebuffer"]
    for i in range(CYCLES):
        with OffscreenRenderer(16, 16) as r:
            assert r.ctx is ctx
            r.render(scenes[i % 2])
            if i % 10 == 0:
                r.render_slice(scenes[1], "axial", overlay="jacobian")
    gc.collect()
    assert context_pool.pool_stats()["made"] == made
    assert gl_objects(ctx) == before
    assert fds() == files


def test_a_warp_drawn_again_uploads_again() -> None:
    vol = _volume()
    warp = _warp(vol)
    scene = Scene(vol, warps=[warp], mode="mip", transfer_function="grayscale")
    ctx, first = _draw(scene)
    assert gl_holders.holder_count(ctx) == 0  # freed when the renderer closed
    _, plain = _draw(Scene(vol, mode="mip", transfer_function="grayscale"))
    _, again = _draw(scene)  # a dead texture would draw something else
    assert not np.array_equal(first, plain)
    np.testing.assert_array_equal(again, first)


def test_nested_renderers_share_the_context_and_keep_its_textures() -> None:
    vol = _volume()
    scene = Scene(vol, warps=[_warp(vol)], mode="mip", transfer_function="grayscale")
    with OffscreenRenderer(24, 24) as outer:
        first = np.asarray(outer.render(scene))
        leases = context_pool.pool_stats()["leases"]
        with OffscreenRenderer(8, 8) as inner:
            assert inner.ctx is outer.ctx
            assert context_pool.pool_stats()["leases"] == leases + 1
            inner.render(scene)
        assert gl_holders.holder_count(outer.ctx) == 1  # the outer one still draws it
        np.testing.assert_array_equal(outer.render(scene), first)


def test_a_warp_dropped_unreleased_is_freed_with_the_context() -> None:
    vol = _volume()
    ctx, _ = _draw(Scene(vol, mode="mip"))
    before = gl_objects(ctx)["texture"]
    with OffscreenRenderer(16, 16) as r:
        scene = Scene(vol, warps=[_warp(vol)], mode="mip")
        r.render(scene)
        del scene  # the warp and its two textures' wrappers die unreleased
        gc.collect()
    assert gl_objects(ctx)["texture"] == before


def test_threads_get_a_context_of_their_own_and_hand_it_on() -> None:
    vol = _volume()
    scene = Scene(vol, warps=[_warp(vol)], mode="mip", transfer_function="grayscale")
    out: dict[str, Any] = {}

    def worker(key: str) -> None:
        try:
            out[key] = _draw(scene)
        except Exception as exc:  # reported in the test's thread
            out["error"] = exc

    with OffscreenRenderer(24, 24) as main:
        image = np.asarray(main.render(scene))
        made = context_pool.pool_stats()["made"]
        for key in ("a", "b", "c"):  # one after another: each takes the one freed
            t = threading.Thread(target=worker, args=(key,))
            t.start()
            t.join(30)
        assert "error" not in out, out.get("error")
        assert out["a"][0] is not main.ctx  # a context is current in one thread only
        assert out["a"][0] is out["b"][0] is out["c"][0]
        assert context_pool.pool_stats()["made"] <= made + 1
        for key in "abc":
            np.testing.assert_array_equal(out[key][1], image)


def test_the_callers_context_stays_current(gl_ctx: Any) -> None:
    saved = egl_current()
    assert saved is not None  # the session context (conftest makes it current)
    with OffscreenRenderer(16, 16) as r:
        r.render(Scene(_volume(), mode="mip"))
        assert egl_current() == saved
    assert egl_current() == saved


@pytest.mark.timeout(60)
def test_a_renderer_given_a_context_draws_on_it_whatever_is_current(gl_ctx: Any) -> None:
    """Renderers sharing one context (``ctx=``) make it current to draw, so another
    context being current (here the session's) changes nothing. Before: the sharing
    renderer drew on whatever context was current, black frames and GL errors there."""
    vol = _volume()
    scene = Scene(vol, mode="mip", warps=[_warp(vol)])
    with OffscreenRenderer(24, 24) as owner:
        expected = np.asarray(owner.render(scene))
        sharing = OffscreenRenderer(24, 24, ctx=owner.ctx)
        try:
            gl_ctx.mglo.__enter__()  # another context current between the draws
            first = np.asarray(sharing.render(scene))
            gl_ctx.mglo.__enter__()
            second = np.asarray(sharing.render(scene))
        finally:
            sharing.release()
    assert expected[..., :3].max() > 0
    np.testing.assert_array_equal(first, expected)
    np.testing.assert_array_equal(second, expected)
    assert gl_ctx.error == "GL_NO_ERROR"


def _lattice(volume: Volume) -> Any:
    from benchmarks.lattice_inverse import bent_grid
    from voxwarp.deform.lattice.warp import LatticeWarp

    lo, hi = volume.bounds
    return LatticeWarp(bent_grid(2, lo, hi, bend=0.3), (lo, hi))


def _field(volume: Volume) -> Any:
    from voxwarp.deform.fields.displacement import DisplacementFieldWarp

    u = np.random.default_rng(4).normal(0.0, 1.0, (5, 5, 5, 3))
    return DisplacementFieldWarp(u, np.diag([3.0, 3.0, 2.0, 1.0]))


def _wires(volume: Volume) -> Any:
    from voxwarp.deform.wires.field import Wire, WireDeformer

    base = np.array([[4, 4, 1], [4, 4, 3], [4, 4, 5], [4, 4, 7]], dtype=float)
    moved = base.copy()
    moved[1:, 1] += 1.5
    wire = Wire(base, moved, radius=3.0, beta=(50.0, 200.0), name="pool")
    deformer = WireDeformer(volume, [wire], field_scale=1)
    deformer.build()
    return deformer.warp()


@pytest.mark.parametrize(
    "make", [_lattice, _field, _wires], ids=["lattice", "displacement_field", "wires"]
)
def test_each_family_frees_its_textures_and_uploads_again(make: Any) -> None:
    vol = _volume()
    warp = make(vol)
    ctx, plain = _draw(Scene(vol, mode="mip", transfer_function="grayscale"))
    before = gl_objects(ctx)["texture"]
    scene = Scene(vol, warps=[warp], mode="mip", transfer_function="grayscale")
    with OffscreenRenderer(24, 24) as r:
        first = np.asarray(r.render(scene))
        assert gl_holders.holder_count(ctx) == 1
    assert gl_holders.holder_count(ctx) == 0
    assert gl_objects(ctx)["texture"] == before
    _, again = _draw(scene)
    assert not np.array_equal(first, plain)
    np.testing.assert_array_equal(again, first)
