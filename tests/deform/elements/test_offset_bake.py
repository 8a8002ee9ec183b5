"""The GPU bake of an offset field's inverse stops where the fixed point stops changing.

Oracle: the same compute shader without the early exit (all ``BAKE_ITERATIONS`` steps
at every node), run on the same field: the baked textures must be bit-identical, for a
local drag (most nodes never move) and for a smooth field that moves every node.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from tests.deform.elements.test_offset_field import wavy_field
from voxwarp import shaders
from voxwarp.deform.elements.offset_field import BAKE_ITERATIONS, OffsetFieldWarp

LO, HI = np.array([-60.0, -50.0, -40.0]), np.array([60.0, 70.0, 50.0])
EARLY_EXIT = "if (next == q) break;"


def local_drag() -> np.ndarray:
    u = np.zeros((9, 9, 9, 3))
    u[4, 5, 3] = (9.0, -3.0, 2.0)
    u[3:6, 4:7, 2:5] += (2.0, -0.5, 0.5)
    return u


def bake_all_steps(ctx: Any, warp: OffsetFieldWarp) -> bytes:
    """The inverse baked by the shader with the early exit removed."""
    src = shaders.source("offset_field_bake.comp.glsl")
    assert EARLY_EXIT in src
    prog = ctx.compute_shader(src.replace(EARLY_EXIT, ""))
    tex = ctx.texture3d(warp.bake_shape, 4, dtype="f2")
    try:
        warp.textures(ctx)["displacement"].use(0)
        warp.run_bake(ctx, prog, tex)
        return tex.read()
    finally:
        tex.release()
        prog.release()


@pytest.mark.gl
@pytest.mark.parametrize("field", ["local drag", "wavy"])
def test_early_exit_bakes_bit_identical_inverse(gl_ctx: Any, field: str) -> None:
    u = local_drag() if field == "local drag" else wavy_field(LO, HI, (9, 9, 9), 12.0)
    warp = OffsetFieldWarp(LO, HI, u, inverse="baked")
    try:
        baked = warp.textures(gl_ctx)["inverse"].read()
        reference = bake_all_steps(gl_ctx, warp)
        assert baked == reference
        v = np.frombuffer(baked, np.float16).reshape(*warp.bake_shape[::-1], 4)
        assert np.abs(v[..., :3]).max() > 1.0, "the field must move something"
        assert np.allclose(v[..., :3].transpose(2, 1, 0, 3), warp.baked_inverse(), atol=2e-2), (
            "and agree with the CPU bake (half floats)"
        )
    finally:
        warp.release_context(gl_ctx)


@pytest.mark.parametrize("field", ["local drag", "wavy"])
def test_cpu_bake_stops_early_bit_identically(field: str) -> None:
    u = local_drag() if field == "local drag" else wavy_field(LO, HI, (9, 9, 9), 12.0)
    warp = OffsetFieldWarp(LO, HI, u, inverse="baked")
    axes = [np.linspace(a, b, n) for a, b, n in zip(warp.lo, warp.hi, warp.bake_shape, strict=True)]
    x = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    q = x.copy()
    for _ in range(BAKE_ITERATIONS):  # every step at every node: the reference
        q = x - warp._interpolate(q, field=u)
    expected = (x - q).reshape(*warp.bake_shape, 3)
    assert np.array_equal(warp.baked_inverse(), expected)
    assert np.abs(expected).max() > 1.0
