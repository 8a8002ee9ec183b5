"""GPU programs shared per context (voxwarp.deform.gl_programs): one compiled program per
shader text and context, whatever number of warps, solvers and renderers use it;
releasing one user leaves the others working."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from voxwarp.core.volume import Volume
from voxwarp.deform import gl_programs
from voxwarp.deform.elements.offset_field import OffsetFieldWarp, texture_field
from voxwarp.deform.elements.spring_model import SpringModel
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.scene import Scene

FILL = """#version 430
#define K {k}
layout(local_size_x = 1) in;
layout(rgba32f, binding = 0) uniform writeonly image2D u_out;
uniform float u_value;
void main() {{
    imageStore(u_out, ivec2(gl_GlobalInvocationID.xy), vec4(u_value + K));
}}
"""


def _dead(prog: Any) -> bool:
    return type(prog.mglo).__name__ == "InvalidObject"


def _fill(ctx: Any, prog: Any, value: float) -> np.ndarray:
    """Run a FILL shader over a 2x2 float image; returns its red channel."""
    tex = ctx.texture((2, 2), 4, dtype="f4")
    try:
        tex.bind_to_image(0, read=False, write=True)
        prog["u_value"].value = value
        prog.run(2, 2, 1)
        ctx.memory_barrier()
        return np.frombuffer(tex.read(), np.float32).reshape(2, 2, 4)[..., 0].copy()
    finally:
        tex.release()


def test_same_text_gives_one_program_and_a_release_keeps_it(gl_ctx: Any) -> None:
    a = gl_programs.compute_shader(gl_ctx, FILL.format(k=1.0))
    b = gl_programs.compute_shader(gl_ctx, FILL.format(k=1.0))
    c = gl_programs.compute_shader(gl_ctx, FILL.format(k=2.0))
    try:
        assert a.program is b.program
        assert c.program is not a.program
        a.release()
        a.release()  # idempotent
        assert not _dead(b.program)
        assert np.all(_fill(gl_ctx, b.program, 3.0) == 4.0)
        assert np.all(_fill(gl_ctx, c.program, 3.0) == 5.0)
        # a later user gets the same program back, not a recompiled one
        d = gl_programs.compute_shader(gl_ctx, FILL.format(k=1.0))
        assert d.program is b.program
        d.release()
    finally:
        for hold in (a, b, c):
            hold.release()


def test_idle_programs_beyond_the_limit_are_freed_held_ones_never(
    gl_ctx: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(gl_programs, "IDLE_LIMIT", 2)
    held = gl_programs.compute_shader(gl_ctx, FILL.format(k=10.0))
    idle = []
    for k in (11.0, 12.0, 13.0):
        hold = gl_programs.compute_shader(gl_ctx, FILL.format(k=k))
        idle.append(hold.program)
        hold.release()
    # compiling one more program frees the least recently used idle one
    extra = gl_programs.compute_shader(gl_ctx, FILL.format(k=14.0))
    try:
        assert _dead(idle[0])
        assert not _dead(idle[1])
        assert not _dead(idle[2])
        assert gl_programs.program_count(gl_ctx)[1] <= 2
        assert not _dead(held.program)
        assert np.all(_fill(gl_ctx, held.program, 0.0) == 10.0)
    finally:
        held.release()
        extra.release()


def test_offset_warps_share_one_bake_shader_and_outlive_each_other(gl_ctx: Any) -> None:
    rng = np.random.default_rng(3)
    lo, hi = (0.0, 0.0, 0.0), (10.0, 12.0, 8.0)
    w1 = OffsetFieldWarp(lo, hi, rng.normal(0, 0.4, (4, 4, 3, 3)), inverse="baked")
    w2 = OffsetFieldWarp(lo, hi, rng.normal(0, 0.4, (4, 4, 3, 3)), inverse="baked")
    w3 = None
    try:
        w1.textures(gl_ctx)
        w2.textures(gl_ctx)
        prog = w1._baked[id(gl_ctx)][1].program
        assert w2._baked[id(gl_ctx)][1].program is prog
        w1.release()
        assert not _dead(prog)
        # w2 bakes a new field with the shared shader after w1 is gone
        w2.update(rng.normal(0, 0.4, (4, 4, 3, 3)))
        baked = texture_field(w2.textures(gl_ctx)["inverse"], w2.bake_shape)
        assert baked is not None
        reference = w2.baked_inverse()
        assert float(np.abs(reference).max()) > 0.1
        # half floats: |v| * 2**-11 plus float32 arithmetic
        np.testing.assert_allclose(baked, reference, atol=2e-3)
        w3 = OffsetFieldWarp(lo, hi, np.zeros((4, 4, 3, 3)), inverse="baked")
        w3.textures(gl_ctx)
        assert w3._baked[id(gl_ctx)][1].program is prog  # not compiled again
    finally:
        for w in (w1, w2, w3):
            if w is not None:
                w.release()


def test_renderers_on_one_context_share_programs(gl_ctx: Any) -> None:
    rng = np.random.default_rng(5)
    volume = Volume(rng.random((9, 8, 7)).astype(np.float32) * 100, spacing=(1.0, 1.0, 1.0))
    lo, hi = volume.bounds
    warp = OffsetFieldWarp(lo, hi, rng.normal(0, 0.3, (3, 3, 3, 3)), inverse="exact")
    scene = Scene(volume, warps=[warp])
    r1 = OffscreenRenderer(12, 10, ctx=gl_ctx)
    r2 = OffscreenRenderer(12, 10, ctx=gl_ctx)
    try:
        first = r1.render(scene)
        before = sum(gl_programs.program_count(gl_ctx))
        second = r2.render(scene)
        assert sum(gl_programs.program_count(gl_ctx)) == before  # nothing compiled
        np.testing.assert_array_equal(second, first)
        assert first[..., 3].max() > 0  # something was drawn
        r1.release()
        np.testing.assert_array_equal(r2.render(scene), first)
    finally:
        r1.release()
        r2.release()
        warp.release()


def test_spring_solvers_share_programs_and_outlive_each_other(gl_ctx: Any) -> None:
    from voxwarp.deform.elements.massspring_gpu import GpuSpringSolver

    shape = (4, 3, 5)
    rng = np.random.default_rng(7)
    rest = np.stack(np.meshgrid(*(np.arange(n) * 1.5 for n in shape), indexing="ij"), axis=-1)
    model = SpringModel(
        rest=rest,
        spacing=np.full(3, 1.5),
        stiffness=rng.uniform(0.2, 0.9, shape),
        damping=rng.uniform(0.0, 1.0, shape),
        mass=rng.uniform(0.5, 2.0, shape),
    )
    pinned = np.zeros(shape, bool)
    pinned[0, 0, 0] = True
    targets = rest.copy()
    targets[0, 0, 0] += (0.7, -0.4, 0.5)
    solvers = [GpuSpringSolver(model, gl_ctx) for _ in range(3)]
    try:
        a, b, c = solvers
        assert a._prog is b._prog
        assert a._comp is b._comp
        a.release()
        for s in (b, c):
            s.set_constraints(pinned, targets)
            s.step(4)
        moved = b.positions()
        assert np.abs(moved - rest).max() > 0.1
        np.testing.assert_array_equal(moved, c.positions())
    finally:
        for s in solvers:
            s.release()
