"""Tests of voxwarp.deform.elements.offset_field: the offset-field warp, CPU reference and GPU path.

CPU oracles: the forward map ``X + u(X)`` (the inverse must undo it), finite
differences (Jacobian); the error study behind the default iteration count is the lab's
(tests/benchmarks/test_offset_inverse.py). GPU
oracles: the warp's GLSL evaluated at single points against :meth:`apply`, a zero field
against no warp, and a volume resampled on the CPU through the warp (scipy, order 1)
rendered without warp against the original volume rendered with the warp.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from scipy import ndimage

from tests.render.test_render import aligned_camera, grey_scene, phantom
from tests.warp_gpu import gpu_warp
from voxwarp.core.volume import Volume
from voxwarp.deform.elements.offset_field import (
    DEFAULT_BAKED_ITERATIONS,
    DEFAULT_ITERATIONS,
    OffsetFieldWarp,
)
from voxwarp.deform.warp import (
    AffineWarp,
    ForwardMapError,
    WarpError,
    compose_glsl,
    warp_from_dict,
)
from voxwarp.scene import Scene

SAVE_IMAGES = os.environ.get("VOXWARP_SAVE_IMAGES")  # folder for the comparison PNGs


# ---------------------------------------------------------------------- fields
def node_positions(lo: Any, hi: Any, shape: tuple[int, int, int]) -> np.ndarray:
    """(nx, ny, nz, 3) rest positions of the nodes."""
    axes = [np.linspace(lo[a], hi[a], shape[a]) for a in range(3)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)


def wavy_field(lo: Any, hi: Any, shape: tuple[int, int, int], amplitude: float) -> np.ndarray:
    """Smooth field, all three components non-zero, scaled to max |u| = ``amplitude``.

    Zero on the faces of the grid box, so the forward map takes the box onto itself.
    """
    x = node_positions(lo, hi, shape)
    s = (x - np.asarray(lo, float)) / (np.asarray(hi, float) - np.asarray(lo, float))
    taper = np.prod(np.sin(np.pi * s), axis=-1)[..., None]
    u = taper * np.stack(
        [
            np.sin(np.pi * s[..., 1] + 0.4) * np.cos(0.8 * np.pi * s[..., 2]),
            np.cos(np.pi * s[..., 0] - 0.3) * np.sin(np.pi * s[..., 2] + 0.2),
            0.7 * np.sin(np.pi * s[..., 0] + 0.1) * np.sin(np.pi * s[..., 1]),
        ],
        axis=-1,
    )
    return u * (amplitude / np.max(np.linalg.norm(u, axis=-1)))


def bump_field(lo: Any, hi: Any, shape: tuple[int, int, int], amplitude: Any) -> np.ndarray:
    """``amplitude * sin(pi sx) sin(pi sy) sin(pi sz)``: zero on the faces of the grid box."""
    x = node_positions(lo, hi, shape)
    s = (x - np.asarray(lo, float)) / (np.asarray(hi, float) - np.asarray(lo, float))
    b = np.prod(np.sin(np.pi * s), axis=-1)
    return b[..., None] * np.asarray(amplitude, float)


LO, HI, SHAPE = np.array([-10.0, 0.0, 5.0]), np.array([38.0, 40.0, 61.0]), (13, 11, 15)
H = (HI - LO) / (np.asarray(SHAPE) - 1)  # (4, 4, 4) mm


def wavy_warp(**kw: Any) -> OffsetFieldWarp:
    """The wavy field with max |u| = 1.5 node spacings (6 mm); max |du/dX| 0.41."""
    return OffsetFieldWarp(LO, HI, wavy_field(LO, HI, SHAPE, 1.5 * H[0]), **kw)


def points_in(lo: Any, hi: Any, n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(lo, hi, (n, 3))


# ---------------------------------------------------------------------- CPU reference
def test_zero_field_is_the_identity() -> None:
    w = OffsetFieldWarp(LO, HI, np.zeros((*SHAPE, 3)))
    p = points_in(LO - 5, HI + 5, 500, 0)
    np.testing.assert_array_equal(w.apply(p), p)
    np.testing.assert_array_equal(w.forward(p), p)
    np.testing.assert_array_equal(w.jacobian(p), np.broadcast_to(np.eye(3), (500, 3, 3)))
    assert w.max_displacement() == 0.0
    lo, hi = w.deformed_bounds(LO + 1, HI - 1)
    np.testing.assert_array_equal(lo, LO + 1)
    np.testing.assert_array_equal(hi, HI - 1)
    assert not w.is_affine


def test_nodes_move_by_their_displacement_and_outside_is_identity() -> None:
    u = wavy_field(LO, HI, SHAPE, 6.0)
    w = OffsetFieldWarp(LO, HI, u)
    x = node_positions(LO, HI, SHAPE).reshape(-1, 3)
    np.testing.assert_allclose(w.field_forward(x), x + u.reshape(-1, 3), atol=1e-12)
    # forward follows the inverse the volume is drawn with (6 fixed-point steps), which
    # is within a fraction of a mm of the field's own map here
    p = w.forward(x)
    np.testing.assert_allclose(w.apply(p), x, atol=2 * w.forward_tolerance)
    np.testing.assert_allclose(p, x + u.reshape(-1, 3), atol=0.05)
    # trilinear between nodes: the midpoint of an edge gets the mean of its two nodes
    mid = 0.5 * (x[0] + x[1])  # nodes (0, 0, 0) and (0, 0, 1)
    np.testing.assert_allclose(w.offset(mid)[0], 0.5 * (u[0, 0, 0] + u[0, 0, 1]), atol=1e-12)
    node = node_positions(LO, HI, SHAPE)[5, 4, 6]
    centre = node + 0.5 * H
    cube = u[5:7, 4:6, 6:8].reshape(-1, 3).mean(axis=0)
    np.testing.assert_allclose(w.offset(centre)[0], cube, atol=1e-12)
    outside = np.array([[LO[0] - 0.01, 10.0, 20.0], [0.0, HI[1] + 1e-6, 20.0], [50, 50, 50]])
    np.testing.assert_array_equal(w.apply(outside), outside)
    np.testing.assert_array_equal(w.offset(outside), np.zeros((3, 3)))


def test_exact_inverse_undoes_the_forward_map() -> None:
    w = wavy_warp()
    assert w.inverse == "exact"
    assert w.iterations == DEFAULT_ITERATIONS
    assert w.max_displacement() == pytest.approx(1.5 * H[0])
    p = points_in(LO, HI, 4000, 1)
    err = np.linalg.norm(w.forward(w.apply(p)) - p, axis=1)
    # measured (k = 6): max 0.0081 mm = 0.002 node spacings, mean 1.8e-4 mm
    assert err.max() < 0.01 * H[0], err.max()
    x = points_in(LO, HI, 4000, 2)
    np.testing.assert_allclose(w.apply(w.forward(x)), x, atol=0.01 * H[0])
    # and with many iterations the inverse is exact to round-off
    w64 = wavy_warp(iterations=64)
    np.testing.assert_allclose(w64.forward(w64.apply(p)), p, atol=1e-9)


def test_approx_error_is_larger_than_exact_error() -> None:
    p = points_in(LO, HI, 4000, 3)
    errors = {}
    for mode in ("approx", "exact"):
        w = wavy_warp(inverse=mode)
        errors[mode] = np.linalg.norm(w.field_forward(w.apply(p)) - p, axis=1)
    # measured (mm, node spacing 4 mm): approx max 1.58 (0.40 spacings), mean 0.22;
    # exact (k = 6) max 0.0081, mean 1.8e-4
    assert errors["approx"].max() > 0.25 * H[0]
    assert errors["exact"].max() < 0.01 * H[0]
    assert errors["approx"].mean() > 100 * errors["exact"].mean()
    # the baked seed alone (iterations=0: one trilinear lookup): measured max 0.0144
    # spacings, mean 8e-4; one correction shrinks it ~4x (max 0.0037)
    seed = wavy_warp(inverse="baked", iterations=0)
    assert seed.steps == 0
    assert seed.glsl_constants()["ITERATE"] == ""
    e0 = np.linalg.norm(seed.field_forward(seed.apply(p)) - p, axis=1)
    one_fix = wavy_warp(inverse="baked", iterations=1)
    e1 = np.linalg.norm(one_fix.field_forward(one_fix.apply(p)) - p, axis=1)
    assert e0.max() < 0.02 * H[0]
    assert e0.max() > 2 * e1.max()
    # "exact" takes at least one step
    assert wavy_warp(inverse="exact", iterations=0).steps == 1
    # approx is exactly one fixed-point step
    one = wavy_warp(iterations=1)
    np.testing.assert_array_equal(one.apply(p), wavy_warp(inverse="approx").apply(p))


def test_jacobian_matches_finite_differences_of_apply() -> None:
    w = wavy_warp(iterations=64)  # converged, so apply is the true inverse
    p = points_in(LO + 2, HI - 2, 300, 4)
    eps = 1e-6
    fd = np.empty((len(p), 3, 3))
    for a in range(3):
        e = np.zeros(3)
        e[a] = eps
        fd[:, :, a] = (w.apply(p + e) - w.apply(p - e)) / (2 * eps)
    j = w.jacobian(p)
    err = np.abs(j - fd).max(axis=(1, 2))
    # the trilinear gradient jumps across cell faces; a difference straddling one may
    # differ there (none did in the measured run: max 6e-9)
    assert np.mean(err < 1e-5) >= 0.99
    # default iterations: apply is not the exact inverse, its derivative differs a bit
    wd = wavy_warp()
    fd_d = np.stack(
        [(wd.apply(p + e) - wd.apply(p - e)) / (2 * eps) for e in np.eye(3) * eps], axis=-1
    )
    # measured: median 8e-6, max 0.003
    assert np.abs(wd.jacobian(p) - fd_d).max() < 1e-2


def test_deformed_bounds_hold_the_deformed_volume_box() -> None:
    w = wavy_warp()
    vlo, vhi = LO + np.array([3.0, -4.0, 6.0]), HI + np.array([-5.0, 2.0, 8.0])
    dlo, dhi = w.deformed_bounds(vlo, vhi)
    x = points_in(vlo, vhi, 20000, 5)
    f = w.forward(x)
    assert np.all(f >= dlo - 1e-9)
    assert np.all(f <= dhi + 1e-9)
    # points p that the (finitely iterated) warp maps into the box lie inside too
    p = points_in(dlo - 10, dhi + 10, 20000, 6)
    q = w.apply(p)
    into = np.all((q >= vlo) & (q <= vhi), axis=1)
    assert np.all(p[into] >= dlo - 1e-9)
    assert np.all(p[into] <= dhi + 1e-9)
    # no further than max |u| per axis, and only within the grid box
    m = np.abs(w.displacements).max(axis=(0, 1, 2))
    assert np.all(dlo >= np.minimum(vlo, np.maximum(vlo - m, LO)) - 1e-12)
    assert np.all(dhi <= np.maximum(vhi, np.minimum(vhi + m, HI)) + 1e-12)
    # a box far from the grid is not moved
    far_lo, far_hi = w.deformed_bounds(HI + 10, HI + 20)
    np.testing.assert_array_equal(far_lo, HI + 10)
    np.testing.assert_array_equal(far_hi, HI + 20)


def test_content_cannot_leave_the_grid_box() -> None:
    # every node moves 3 mm along +x, the boundary nodes too: material near the +x face
    # is pushed out of the grid box, where the warp is the identity, so it is cut off
    u = np.zeros((*SHAPE, 3))
    u[..., 0] = 3.0
    w = OffsetFieldWarp(LO, HI, u)
    x = np.array([[HI[0] - 1.0, 20.0, 30.0], [HI[0] - 5.0, 20.0, 30.0]])
    p = w.field_forward(x)
    assert p[0, 0] > HI[0]  # the field sends it outside the grid box...
    np.testing.assert_array_equal(w.apply(p[:1]), p[:1])  # ...but there the original is shown
    # so the forward map of the drawn volume has no point for it (meshes are told)
    with pytest.raises(ForwardMapError, match="no forward map at 1 of 2 points") as info:
        w.forward(x)
    assert info.value.failed.tolist() == [True, False]
    inside = np.array([[HI[0] - 5.0, 20.0, 30.0]])
    np.testing.assert_allclose(w.apply(inside), inside - [3.0, 0, 0], atol=1e-12)
    # and the deformed bounds of the grid box itself do not grow
    lo, hi = w.deformed_bounds(LO, HI)
    np.testing.assert_array_equal(lo, LO)
    np.testing.assert_array_equal(hi, HI)


def test_update_replaces_the_field() -> None:
    w = wavy_warp()
    p = points_in(LO, HI, 100, 7)
    before = w.apply(p)
    w.update(np.zeros((*SHAPE, 3)))
    np.testing.assert_array_equal(w.apply(p), p)
    w.update(wavy_field(LO, HI, SHAPE, 6.0))
    np.testing.assert_allclose(w.apply(p), before, atol=1e-12)
    w.update(np.zeros((3, 4, 5, 3)))  # new node count
    assert w.shape == (3, 4, 5)
    with pytest.raises(WarpError, match=r"\(nx, ny, nz, 3\)"):
        w.update(np.zeros((3, 4, 5)))


def test_signature_uniforms_and_constants() -> None:
    exact, approx = wavy_warp(), wavy_warp(inverse="approx", iterations=9)
    baked = wavy_warp(inverse="baked")
    assert len({exact.signature(), approx.signature(), baked.signature()}) == 3
    # iterations are compile-time constants (the loop unrolls): part of the signature
    assert exact.signature() != wavy_warp(iterations=3).signature()
    un = exact.uniforms()
    np.testing.assert_array_equal(un["lo"], LO)
    np.testing.assert_array_equal(un["size"], HI - LO)
    np.testing.assert_array_equal(un["shape"], SHAPE)
    step, last = "q = p - WARP_offset(q);", "q = p - WARP_offset_last(q);"
    assert exact.glsl_constants() == {
        "ITERATIONS": DEFAULT_ITERATIONS,
        "SEEDED": False,
        "ITERATE": " ".join([step] * (DEFAULT_ITERATIONS - 1) + [last]),
    }
    assert approx.glsl_constants() == {"ITERATIONS": 1, "SEEDED": False, "ITERATE": last}
    assert baked.bake_factor >= 3  # small grid: baked 3-4x finer, one correction
    assert baked.glsl_constants()["ITERATIONS"] == DEFAULT_BAKED_ITERATIONS
    assert baked.glsl_constants()["SEEDED"] is True
    assert approx.iterations == 9  # kept for a switch back to "exact"
    src = compose_glsl([exact, approx, baked])
    for i in (0, 1, 2):
        for name in ("lo", "size", "shape", "ITERATIONS", "SEEDED", "displacement", "offset"):
            assert f"w{i}_{name}" in src
    assert f"const int w0_ITERATIONS = {DEFAULT_ITERATIONS};" in src
    assert "const bool w2_SEEDED = true;" in src
    assert "WARP_" not in src


# ---------------------------------------------------------------------- serialisation
def test_round_trip_through_warp_from_dict() -> None:
    material = np.random.default_rng(8).uniform(0, 1, SHAPE)
    w = OffsetFieldWarp(
        LO, HI, wavy_field(LO, HI, SHAPE, 5.0), inverse="approx", iterations=7, material=material
    )
    d = json.loads(json.dumps(w.to_dict()))  # plain JSON, no pickle
    assert d["type"] == "offset_field"
    assert d["shape"] == list(SHAPE)
    back = warp_from_dict(d)
    assert isinstance(back, OffsetFieldWarp)
    assert (back.inverse, back.iterations, back.shape) == ("approx", 7, SHAPE)
    np.testing.assert_array_equal(back.displacements, w.displacements)
    np.testing.assert_array_equal(back.lo, LO)
    np.testing.assert_array_equal(back.hi, HI)
    np.testing.assert_array_equal(back.texture_data(), w.texture_data())
    p = points_in(LO, HI, 50, 9)
    np.testing.assert_array_equal(back.apply(p), w.apply(p))


def test_a_gpu_owned_field_is_not_saved_by_the_warp() -> None:
    w = OffsetFieldWarp(LO, HI, shape=SHAPE, texture_source=lambda ctx: None)
    assert w.gpu_owned
    d = json.loads(json.dumps(w.to_dict()))
    assert d["displacements"] is None
    with pytest.raises(WarpError, match="MassSpring"):
        warp_from_dict(d)
    with pytest.raises(WarpError, match="owned by a GPU texture"):
        w.apply(np.zeros((1, 3)))
    with pytest.raises(WarpError, match="texture_source"):
        w.update(np.zeros((*SHAPE, 3)))
    # without a known maximum the deformed bounds take in the whole grid box
    lo, hi = w.deformed_bounds(LO + 5, HI - 5)
    np.testing.assert_array_equal(lo, LO)
    np.testing.assert_array_equal(hi, HI)


Z = np.zeros((*SHAPE, 3))


@pytest.mark.parametrize(
    ("args", "kw", "pattern"),
    [
        ((LO, HI, np.zeros((9, 7, 3))), {}, r"shape \(nx, ny, nz, 3\)"),
        ((LO, HI, np.zeros((9, 7, 11, 2))), {}, r"shape \(nx, ny, nz, 3\)"),
        ((LO, HI, np.zeros((1, 7, 11, 3))), {}, "at least 2 nodes"),
        ((LO, HI, Z), {"shape": (9, 7, 10)}, "shape=.* was given"),
        ((HI, LO, Z), {}, "lo < hi"),
        ((LO, LO + np.array([1, 0, 1]), Z), {}, "lo < hi"),
        ((LO[:2], HI, Z), {}, "three numbers"),
        ((LO, [0, np.nan, 1], Z), {}, "NaN"),
        ((LO, HI, np.where(np.arange(Z.size).reshape(Z.shape) == 5, np.inf, Z)), {}, "NaN/Inf"),
        ((LO, HI, Z + 1e5), {}, "half-float"),
        ((LO, HI, "field"), {}, "numeric"),
        ((LO, HI, Z), {"inverse": "newton"}, "inverse must be one of"),
        ((LO, HI, Z), {"iterations": -1}, "0..64"),
        ((LO, HI, Z), {"iterations": 65}, "0..64"),
        ((LO, HI, Z), {"iterations": 2.5}, "integer"),
        ((LO, HI, Z), {"iterations": True}, "integer"),
        ((LO, HI), {}, "displacements .* or a texture_source"),
        ((LO, HI), {"texture_source": lambda c: None}, "needs shape"),
        ((LO, HI), {"texture_source": 3, "shape": SHAPE}, "callable"),
        ((LO, HI, Z), {"texture_source": lambda c: None}, "not both"),
        ((LO, HI), {"texture_source": lambda c: None, "shape": (4, 4)}, "three integer"),
        ((LO, HI, Z), {"material": np.zeros((2, 2, 2))}, "one value per node"),
    ],
)
def test_bad_inputs_raise_clear_errors(args: tuple, kw: dict, pattern: str) -> None:
    with pytest.raises(WarpError, match=pattern):
        OffsetFieldWarp(*args, **kw)


@pytest.mark.parametrize(
    ("d", "pattern"),
    [
        ({"type": "offset_field", "lo": [0, 0, 0], "hi": [1, 1, 1]}, r"needs \['shape'\]"),
        (
            {"type": "offset_field", "lo": [0, 0, 0], "hi": [1, 1, 1], "shape": [2, 2, 2]},
            "GPU simulation",
        ),
        (
            {
                "type": "offset_field",
                "lo": [0, 0, 0],
                "hi": [1, 1, 1],
                "shape": [2, 2, 2],
                "displacements": [[1, 2], [3]],
            },
            "numeric",
        ),
    ],
)
def test_bad_dicts_raise_clear_errors(d: dict, pattern: str) -> None:
    with pytest.raises(WarpError, match=pattern):
        warp_from_dict(d)


# ---------------------------------------------------------------------- GLSL at points
@pytest.mark.parametrize(
    ("inverse", "iterations"), [("approx", None), ("exact", None), ("baked", None), ("baked", 0)]
)
def test_glsl_warp_matches_the_cpu_reference(
    gl_ctx: Any, inverse: str, iterations: int | None
) -> None:
    w = wavy_warp(inverse=inverse, iterations=iterations)
    # the CPU twin of what the texture holds: the field rounded to half floats
    half = OffsetFieldWarp(
        LO, HI, w.displacements.astype(np.float16), inverse=inverse, iterations=iterations
    )
    try:
        p = np.vstack([points_in(LO, HI, 250, 10), points_in(LO - 6, HI + 6, 50, 11)])
        q, jac = gpu_warp(gl_ctx, w, p)
        # float32 arithmetic and filtering against the half-float field: measured max
        # 4e-6 mm on llvmpipe (float filter weights); GPUs with 8-bit filter weights
        # may be off by |du| / 512 per fetch (~0.003 mm here, x2 through the iteration).
        # Against the unrounded field: measured 0.0014 mm.
        # baked: the GPU stores the baked inverse in half floats (|v| * 2**-11, 3e-3 mm
        # here), which the correction shrinks by ~|du| (0.41): measured max 5e-5 mm
        llvmpipe = "llvmpipe" in gl_ctx.info.get("GL_RENDERER", "")
        # the seed alone (iterations 0) keeps the half-float rounding of v: up to 3e-3 mm
        tol = 5e-5 if inverse != "baked" else 1e-3 if iterations is None else 5e-3
        np.testing.assert_allclose(q, half.apply(p), atol=tol if llvmpipe else 2e-2)
        np.testing.assert_allclose(q, w.apply(p), atol=2e-2)
        # the GLSL's Jacobian is the CPU's: the analytic gradient of the trilinear cell
        # of q (8 unfiltered nodes); measured max 3e-7 (baked: 7e-6, seed alone 3e-5)
        jtol = 2e-5 if inverse != "baked" else 1e-4 if iterations is None else 1e-3
        np.testing.assert_allclose(jac, half.jacobian(p), atol=jtol if llvmpipe else 5e-3)
        # vs the unrounded field: the half-float rounding of u only, measured median
        # 4e-5, max 6e-4 (central differences, which mix neighbouring cells' slopes,
        # were median 0.018, max 0.11)
        err = np.abs(jac - w.jacobian(p)).max(axis=(1, 2))
        assert np.median(err) < 2e-4
        assert err.max() < 3e-3
    finally:
        w.release()


def test_glsl_kept_jacobian_is_the_jacobian_warped_anew(gl_ctx: Any) -> None:
    """The raycaster's Jacobian (from the points ``warp_chain`` kept: no second warp)
    is bit for bit the one that warps again, through a chain around the field."""
    w = wavy_warp(inverse="baked")
    chain = [AffineWarp.rotation((0, 0, 1), 20.0), w, AffineWarp.translation((3.0, -2.0, 1.0))]
    try:
        p = np.vstack([points_in(LO, HI, 120, 12), points_in(LO - 6, HI + 6, 30, 13)])
        q, jac = gpu_warp(gl_ctx, chain, p)
        q_kept, jac_kept = gpu_warp(gl_ctx, chain, p, kept=True)
        np.testing.assert_array_equal(q_kept, q)
        np.testing.assert_array_equal(jac_kept, jac)
        assert np.abs(jac - np.eye(3)).max() > 0.1  # the field's gradient is in it
    finally:
        w.release()


@pytest.mark.parametrize("inverse", ["exact", "baked"])
def test_glsl_shaded_jacobian_from_the_last_step_is_the_cpu_one(gl_ctx: Any, inverse: str) -> None:
    """Compiled for shading, the last fixed-point step keeps grad u from its own 8 nodes:
    the warped points stay those of the plain program, and the Jacobian is the CPU's at
    q up to the last correction's move (grad u is continuous inside a cell; points
    whose last step crosses a cell face take the face's other cell)."""
    w = wavy_warp(inverse=inverse)
    half = OffsetFieldWarp(LO, HI, w.displacements.astype(np.float16), inverse=inverse)
    try:
        p = np.vstack([points_in(LO, HI, 250, 14), points_in(LO - 6, HI + 6, 50, 15)])
        q, _ = gpu_warp(gl_ctx, w, p)
        q_shaded, jac = gpu_warp(gl_ctx, w, p, kept=True, shading=True)
        # the 8 nodes' trilinear value against the filtered fetch: float rounding on
        # llvmpipe; GPUs with 8-bit filter weights: up to |du| / 256 per fetch
        llvmpipe = "llvmpipe" in gl_ctx.info.get("GL_RENDERER", "")
        np.testing.assert_allclose(q_shaded, q, atol=1e-4 if llvmpipe else 2e-2)
        err = np.abs(jac - half.jacobian(p)).max(axis=(1, 2))
        # measured (llvmpipe): exact median 2e-7, max 2e-4; baked (one correction after
        # the seed) median 1e-5, max 0.017, 99.7 % below 1e-2; q within 4e-6 mm
        assert np.median(err) < 1e-3
        assert np.mean(err < 1e-2) > 0.95
        assert np.abs(jac - np.eye(3)).max() > 0.1  # the field's gradient is in it
        _, jac_anew = gpu_warp(gl_ctx, w, p, shading=True)
        np.testing.assert_array_equal(jac_anew, jac)  # warping again keeps the same
    finally:
        w.release()


def test_compose_glsl_gives_every_warp_a_jacobian_given_its_output() -> None:
    src = compose_glsl([AffineWarp.translation((1.0, 0.0, 0.0)), wavy_warp()])
    # the affine file has none: the chain defines it from warp_jacobian
    assert "mat3 w0_warp_jacobian_at(vec3 p, vec3 q) { return w0_warp_jacobian(p); }" in src
    assert src.count("mat3 w1_warp_jacobian_at(") == 1  # the offset field's own
    kept = src[src.index("mat3 warp_chain_kept_jacobian()") :]
    assert "w0_warp_jacobian_at(warp_chain_p0, warp_chain_p1)" in kept
    assert "w1_warp_jacobian_at(warp_chain_p1, warp_chain_p2)" in kept


# ---------------------------------------------------------------------- rendering
def render(offscreen: Callable[..., Any], scene: Scene, size: tuple[int, int]) -> np.ndarray:
    return offscreen(*size, dtype="f4").render(scene)


def mip_scene(vol: Volume, window: tuple[float, float], warps: list | None = None) -> Scene:
    cam, _ = aligned_camera(vol, "+z")
    return grey_scene(vol, "mip", "+z", cam, window=window, warps=warps or [])


def blobs(n: int = 32) -> Volume:
    """n³ float32: a few Gaussian blobs of different sizes and heights (asymmetric)."""
    i, j, k = np.meshgrid(*(np.arange(n, dtype=float),) * 3, indexing="ij")
    f = np.zeros((n, n, n))
    for (ci, cj, ck), r, a in (
        ((10, 12, 15), 3.0, 1000.0),
        ((21, 20, 12), 2.5, 800.0),
        ((16, 8, 20), 2.0, 600.0),
        ((8, 24, 10), 3.5, 500.0),
        ((24, 10, 18), 1.8, 900.0),
    ):
        f += a * np.exp(-((i - ci) ** 2 + (j - cj) ** 2 + (k - ck) ** 2) / (2 * r**2))
    return Volume(f.astype(np.float32), name="blobs")


def resample(vol: Volume, warp: OffsetFieldWarp) -> Volume:
    """The deformed volume on the CPU: value at voxel centre p = original at warp(p)."""
    idx = np.stack(np.meshgrid(*(np.arange(n) for n in vol.shape), indexing="ij"), axis=-1)
    p = vol.index_to_world(idx.reshape(-1, 3))
    q = vol.world_to_index(warp.apply(p))
    data = np.asarray(vol.data, np.float64)
    out = ndimage.map_coordinates(data, q.T, order=1, mode="nearest")
    return Volume(out.reshape(vol.shape).astype(np.float32), name="resampled")


def save_png(name: str, *images: np.ndarray) -> None:
    if not SAVE_IMAGES:
        return
    from tests.conftest import _write_png

    row = np.concatenate([np.asarray(im[..., :3], np.float64) for im in images], axis=1)
    big = np.kron(row, np.ones((8, 8, 1)))  # 8x nearest upscale for viewing
    _write_png(__import__("pathlib").Path(SAVE_IMAGES) / f"{name}.png", big)


def test_zero_field_renders_like_no_warp(offscreen: Callable[..., Any]) -> None:
    vol = phantom()
    lo, hi = vol.bounds
    window = (100.0, 2200.0)
    _, size = aligned_camera(vol, "+z")
    plain = render(offscreen, mip_scene(vol, window), size)
    w = OffsetFieldWarp(lo - 4, hi + 4, np.zeros((6, 5, 7, 3)))
    try:
        warped = render(offscreen, mip_scene(vol, window, [w]), size)
    finally:
        w.release()
    # measured max 0.0 (the generic path computes q = p - 0 exactly)
    assert float(np.max(np.abs(warped - plain))) <= 1 / 255


def oracle_setup() -> tuple[Volume, OffsetFieldWarp, tuple[float, float]]:
    vol = blobs()
    lo, hi = vol.bounds  # 9³ nodes on the volume box, spacing 4 mm
    # in-plane displacement (u_z = 0, so the +z rays keep their sample lattice), zero on
    # the grid faces: max 1 node spacing, |du/dX| <= 0.39
    u = bump_field(lo, hi, (9, 9, 9), (4.0, -2.5, 0.0))
    w = OffsetFieldWarp(lo, hi, u)
    lo_v, hi_v = vol.value_range
    return vol, w, (0.5 * (lo_v + hi_v), hi_v - lo_v)


def test_gpu_warp_matches_cpu_resampling(offscreen: Callable[..., Any]) -> None:
    vol, w, window = oracle_setup()
    approx = OffsetFieldWarp(w.lo, w.hi, w.displacements, inverse="approx")
    baked = OffsetFieldWarp(w.lo, w.hi, w.displacements, inverse="baked")
    exact_ref = OffsetFieldWarp(w.lo, w.hi, w.displacements, iterations=64)  # converged
    _, size = aligned_camera(vol, "+z")
    try:
        reference = render(offscreen, mip_scene(resample(vol, exact_ref), window), size)
        gpu_exact = render(offscreen, mip_scene(vol, window, [w]), size)
        gpu_approx = render(offscreen, mip_scene(vol, window, [approx]), size)
        gpu_baked = render(offscreen, mip_scene(vol, window, [baked]), size)
        original = render(offscreen, mip_scene(vol, window), size)
    finally:
        w.release()
        approx.release()
        baked.release()
    d_exact = np.abs(gpu_exact[..., 0] - reference[..., 0])
    d_approx = np.abs(gpu_approx[..., 0] - reference[..., 0])
    d_baked = np.abs(gpu_baked[..., 0] - reference[..., 0])
    # panels: original, exact warp, CPU-resampled reference, approx warp, then
    # |approx - reference| and |exact - reference| amplified 4x
    grey = [np.repeat(4 * d[..., None], 3, axis=-1) for d in (d_approx, d_exact)]
    save_png("offset_field_oracle", original, gpu_exact, reference, gpu_approx, *grey)
    # measured (llvmpipe): exact mean 2.9e-5, p99 3.4e-4, max 1.0e-3 (0.26/255);
    # approx mean 0.016, p99 0.13, max 0.28
    assert float(d_exact.mean()) < 2e-4
    assert float(np.percentile(d_exact, 99)) < 1 / 255
    assert float(d_exact.max()) < 2 / 255
    assert float(d_approx.mean()) > max(0.005, 20 * float(d_exact.mean()))
    # baked (2 fetches instead of 6): about as close to the reference as exact
    assert float(d_baked.mean()) < max(2e-4, 2 * float(d_exact.mean()))
    assert float(d_baked.max()) < 2 / 255
    # and the warp did move things: measured mean change 0.065
    assert float(np.abs(gpu_exact - original).mean()) > 0.02


def test_update_changes_the_rendered_image(offscreen: Callable[..., Any], gl_ctx: Any) -> None:
    vol, w, window = oracle_setup()
    _, size = aligned_camera(vol, "+z")
    try:
        a = render(offscreen, mip_scene(vol, window, [w]), size)
        tex = w.textures(gl_ctx)["displacement"]
        u = w.displacements
        w.update(-u)  # the opposite drag
        b = render(offscreen, mip_scene(vol, window, [w]), size)
        assert w.textures(gl_ctx)["displacement"] is tex  # same node counts: reused
        assert float(np.abs(a - b).mean()) > 0.01
        w.update(u)
        np.testing.assert_array_equal(render(offscreen, mip_scene(vol, window, [w]), size), a)
        # new node counts: a new texture of the new size
        w.update(bump_field(w.lo, w.hi, (5, 6, 7), (4.0, -2.5, 0.0)))
        c = render(offscreen, mip_scene(vol, window, [w]), size)
        new_tex = w.textures(gl_ctx)["displacement"]
        assert tuple(new_tex.size) == (5, 6, 7)
        assert float(np.abs(a - c).mean()) > 1e-3  # coarser field, same drag: close to a
        assert float(np.abs(a - c).mean()) < float(np.abs(a - b).mean())
    finally:
        w.release()


def test_texture_source_renders_like_the_cpu_field(
    offscreen: Callable[..., Any], gl_ctx: Any
) -> None:
    vol, cpu, window = oracle_setup()
    tex = gl_ctx.texture_array(cpu.shape, 4, cpu.texture_data().tobytes(), dtype="f2")
    tex.filter = (gl_ctx.LINEAR, gl_ctx.LINEAR)
    tex.repeat_x = tex.repeat_y = False
    calls: list[Any] = []

    def source(ctx: Any) -> Any:
        calls.append(ctx)
        return tex

    gpu = OffsetFieldWarp(cpu.lo, cpu.hi, shape=cpu.shape, texture_source=source)
    _, size = aligned_camera(vol, "+z")
    try:
        a = render(offscreen, mip_scene(vol, window, [cpu]), size)
        b = render(offscreen, mip_scene(vol, window, [gpu]), size)
        np.testing.assert_array_equal(a, b)
        assert calls
        assert calls[-1] is offscreen(*size, dtype="f4").ctx
        gpu.release()  # must not free the source's texture
        assert len(tex.read()) == int(np.prod(cpu.shape)) * 8
    finally:
        cpu.release()
        tex.release()


def test_bake_factor_and_default_corrections_follow_the_grid_size() -> None:
    small = OffsetFieldWarp(LO, HI, np.zeros((16, 16, 16, 3)), inverse="baked")
    assert small.bake_factor == 4
    assert small.bake_shape == (61, 61, 61)
    assert small.iterations == DEFAULT_BAKED_ITERATIONS
    mid = OffsetFieldWarp(LO, HI, np.zeros((64, 40, 8, 3)), inverse="baked")
    assert mid.bake_factor == 2  # 127 // 63: at most 128 baked nodes per axis
    assert mid.iterations == DEFAULT_BAKED_ITERATIONS + 1
    big = OffsetFieldWarp(LO, HI, np.zeros((128, 4, 4, 3)), inverse="baked")
    assert big.bake_factor == 1
    assert big.bake_shape == (128, 4, 4)
    assert big.baked_inverse().shape == (128, 4, 4, 3)


def test_update_region_rewrites_only_its_block(gl_ctx: Any) -> None:
    rng = np.random.default_rng(4)
    u = rng.normal(0.0, 1.0, (*SHAPE, 3))
    w = OffsetFieldWarp(LO, HI, u)
    try:
        tex = w.textures(gl_ctx)["displacement"]
        block = rng.normal(0.0, 1.0, (3, 4, 2, 3))
        w.update_region((2, 5, 7), block)
        u[2:5, 5:9, 7:9] = block
        np.testing.assert_array_equal(w.displacements, u)
        w.update_region((0, 0, 0), u[:1, :1, :1] * 2.0)
        u[:1, :1, :1] *= 2.0
        assert w.textures(gl_ctx)["displacement"] is tex  # rewritten in place
        got = np.frombuffer(tex.read(), np.float16).reshape(SHAPE[2], SHAPE[1], SHAPE[0], 4)
        np.testing.assert_array_equal(got, w.texture_data())  # the whole field is current
        with pytest.raises(WarpError, match="leaves"):
            w.update_region((12, 0, 0), np.zeros((2, 1, 1, 3)))
        with pytest.raises(WarpError, match="NaN"):
            w.update_region((0, 0, 0), np.full((1, 1, 1, 3), np.nan))
    finally:
        w.release()


@pytest.mark.parametrize("width", [(1, 1, 1), (2, 4, 1), (3, 5, 2), (8, 2, 16)])
def test_window_reduce_matches_brute_force(width: tuple[int, int, int]) -> None:
    from voxwarp.deform.node_grid import window_reduce

    a = np.random.default_rng(9).normal(size=(9, 7, 6, 3))
    cache: dict = {}
    for op, red in ((np.maximum, np.max), (np.minimum, np.min)):
        got = window_reduce(a, width, op, cache if op is np.maximum else None)
        want = np.empty_like(a)
        for i, j, k in np.ndindex(a.shape[:3]):
            block = a[i : i + width[0], j : j + width[1], k : k + width[2]]
            want[i, j, k] = red(block.reshape(-1, 3), axis=0)
        np.testing.assert_array_equal(got, want)
    assert cache  # prefixes kept for the next window
