"""Wire ends (deform/wires/wire.py ``Wire.ends``): the smooth falloff and the rigid warning.

Oracles: with ``ends="smooth"`` the warp has no jump across the end plane or the radius
(neighbouring samples on a line across them move apart by at most the sample spacing
times a bound on the warp's slope), it still sweeps the wire's middle rigidly, and it is
the identity beyond the falloff; the rigid sweep cuts there (the same line jumps by the
end's displacement) and warns when its wire ends inside the object; the GLSL agrees with
the CPU reference in smooth mode; a scene round trip keeps the option.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import pytest

from tests.deform.wires.test_wires import AXIS_Y, AXIS_Z, build, cylinder, resample, wire
from tests.warp_gpu import gpu_warp
from voxwarp.deform.warp import WarpError, warp_from_dict
from voxwarp.deform.wires.constants import FAR
from voxwarp.deform.wires.wire import Wire

SHIFT = 4.0  # the modified wire's end moves this far along +y (mm)
FALLOFF = 10.0  # mm


def short_wire(ends: str, **kw: Any) -> Wire:
    """A wire from x = 4 to 36 mm: it ends inside the cylinder (x 8..56), its modified
    copy leans to +y, reaching SHIFT mm at the end."""
    xs = (4.0, 16.0, 28.0, 36.0)
    base = [[x, AXIS_Y, AXIS_Z] for x in xs]
    mod = [[x, AXIS_Y + SHIFT * (x - 4.0) / 32.0, AXIS_Z] for x in xs]
    kw.setdefault("falloff", FALLOFF)
    return wire(base=base, modified=mod, ends=ends, **kw)


def quiet_build(ends: str, **kw: Any) -> Any:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return build(cylinder(), [short_wire(ends)], **kw)


def max_step(q: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(q, axis=0), axis=1).max())


@pytest.mark.parametrize("scale", [1, 2])
def test_smooth_end_has_no_jump_and_rigid_end_cuts(scale: int) -> None:
    # a line along the wire 3 mm off its axis, across the end plane (x = 36) and beyond
    xs = np.linspace(20.0, 60.0, 801)
    spacing = xs[1] - xs[0]
    p = np.stack([xs, np.full_like(xs, AXIS_Y + 3.0), np.full_like(xs, AXIS_Z)], -1)
    smooth = quiet_build("smooth", field_scale=scale).apply(p)
    rigid = quiet_build("rigid", field_scale=scale).apply(p)
    assert not np.any(smooth >= FAR / 2)
    assert not np.any(rigid >= FAR / 2)
    # the slope of the displacement: SHIFT / 32 along the wire, 1.5 SHIFT / FALLOFF over
    # the smoothstep beyond it (plus the field's interpolation)
    bound = spacing * (1.0 + 2.0 * SHIFT / FALLOFF)
    assert max_step(smooth) <= bound, max_step(smooth)
    assert max_step(rigid) > 0.8 * SHIFT  # the rigid sweep jumps at its end
    before = xs < 34.0
    np.testing.assert_allclose(smooth[before], rigid[before], atol=1e-9)  # same sweep
    beyond = xs > 36.0 + FALLOFF + 1.0
    np.testing.assert_allclose(smooth[beyond], p[beyond], atol=1e-9)  # untouched


def test_smooth_radius_boundary_has_no_jump() -> None:
    # a wire along the whole cylinder whose radius (5 mm) is less than the cylinder's
    # (6 mm): the rigid sweep cuts the cylinder's rim, the smooth one fades out across it
    xs = (4.0, 20.0, 36.0, 60.0)
    base = [[x, AXIS_Y, AXIS_Z] for x in xs]
    mod = [[x, AXIS_Y, AXIS_Z + 3.0] for x in xs]
    ys = np.linspace(AXIS_Y - 9.0, AXIS_Y + 9.0, 721)
    p = np.stack([np.full_like(ys, 30.0), ys, np.full_like(ys, AXIS_Z + 3.0)], -1)
    out = {}
    for ends in ("smooth", "rigid"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            w = build(cylinder(), [wire(base=base, modified=mod, radius=5.0, ends=ends)])
        q = w.apply(p)
        out[ends] = q
    spacing = ys[1] - ys[0]
    # the fade: 3 mm over the outer quarter (1.25 mm) of the radius, a smoothstep
    bound = spacing * (1.0 + 1.5 * 3.0 / 1.25 + 0.5)
    smooth = out["smooth"]
    assert not np.any(smooth >= FAR / 2)
    assert max_step(smooth) <= bound, max_step(smooth)
    rigid = out["rigid"]
    shown = rigid[:, 0] < FAR / 2
    assert max_step(rigid[shown]) > 2.0 or not shown.all()  # the rigid sweep cuts
    # the core still moves rigidly by the full 3 mm
    core = np.abs(ys - AXIS_Y) < 3.0
    np.testing.assert_allclose(smooth[core, 2] - p[core, 2], -3.0, atol=1e-6)


def test_rigid_end_inside_the_object_warns_and_outside_does_not() -> None:
    vol = cylinder()
    with pytest.warns(UserWarning, match=r"wire 'inner': its end lies inside .* ends='smooth'"):
        build(vol, [short_wire("rigid", name="inner")])
    # the same wire running past both ends of the cylinder (x 8..56): no warning
    xs = (2.0, 20.0, 40.0, 62.0)
    through = wire(base=[[x, AXIS_Y, AXIS_Z] for x in xs], ends="rigid")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        build(vol, [through])
        build(vol, [short_wire("smooth")])  # smooth ends bend instead of cutting: no warning


@pytest.mark.parametrize("layout", ["float", "packed", "paper"])
def test_smooth_mode_gpu_equals_cpu(gl_ctx: Any, layout: str) -> None:
    w = quiet_build("smooth", field_scale=2, layout=layout)
    try:
        rng = np.random.default_rng(7)
        lo = np.array([2.0, AXIS_Y - 10.0, AXIS_Z - 10.0])
        hi = np.array([62.0, AXIS_Y + 12.0, AXIS_Z + 10.0])
        p = rng.uniform(lo, hi, (4096, 3))
        weight = w._weight(p, w._lookup(p)[0])
        q_gpu, jac_gpu = gpu_warp(gl_ctx, w, p)
    finally:
        w.release()
    q_cpu = w.apply(p)
    state = w._lookup(p)[0]
    fading = (weight > 0.05) & (weight < 0.95)
    assert fading.sum() > 100  # the sample really tests the falloff
    np.testing.assert_array_equal(q_gpu[:, 0] >= FAR / 2, q_cpu[:, 0] >= FAR / 2)
    swept = state == 2
    err = np.linalg.norm(q_gpu[swept] - q_cpu[swept], axis=1)
    assert err.max() <= 5e-3, err.max()
    jac_cpu = w.jacobian(p)
    assert np.abs(jac_gpu[swept] - jac_cpu[swept]).max() <= 5e-3


def test_ends_round_trip_and_bad_values() -> None:
    w = short_wire("smooth", falloff=7.5)
    d = w.to_dict()
    assert d["ends"] == "smooth"
    assert d["falloff"] == 7.5
    back = Wire.from_dict(d)
    assert (back.ends, back.falloff) == ("smooth", 7.5)
    assert Wire.from_dict({**d, "falloff": None}).falloff == back.radius  # default: radius
    spec = {"type": "wires", "wires": [d]}
    assert warp_from_dict(spec).to_dict()["wires"][0]["ends"] == "smooth"
    with pytest.raises(WarpError, match="ends must be one of"):
        short_wire("soft")
    with pytest.raises(WarpError, match="falloff must be a finite number"):
        short_wire("smooth", falloff=-1.0)


def test_smooth_forward_map_inverts_the_warp_across_the_falloff() -> None:
    # meshes follow the smooth sweep too: original points around the end (x 30..50)
    w = quiet_build("smooth", field_scale=2)
    rng = np.random.default_rng(1)
    n = 400
    x = np.stack(
        [
            rng.uniform(30.0, 50.0, n),
            AXIS_Y + rng.uniform(-4.0, 4.0, n),
            AXIS_Z + rng.uniform(-4.0, 4.0, n),
        ],
        -1,
    )
    p = w.forward(x)
    np.testing.assert_allclose(w.apply(p), x, atol=1e-3)
    assert np.linalg.norm(p - x, axis=1).max() > 0.5 * SHIFT  # they do move


def test_smooth_sweep_of_an_object_inside_its_radius_leaves_no_copy() -> None:
    # a wire past both ends of the cylinder, translated: its core moves rigidly and its
    # old place is vacated, as with the rigid sweep (the fades hold only background)
    vol = cylinder()
    d = np.array([0.0, 3.0, -2.0])
    xs = (2.0, 20.0, 40.0, 62.0)
    base = [[x, AXIS_Y, AXIS_Z] for x in xs]
    res = {}
    for ends in ("smooth", "rigid"):
        w = build(vol, [wire(base=base, modified=[list(np.add(b, d)) for b in base], ends=ends)])
        res[ends] = resample(vol, w).data
    inner = (slice(12, 52), slice(None), slice(None))
    shifted = np.roll(np.roll(np.asarray(vol.data), 3, axis=1), -2, axis=2)
    np.testing.assert_allclose(res["smooth"][inner], shifted[inner], atol=1e-3)
    np.testing.assert_allclose(res["smooth"], res["rigid"], atol=1e-3)


def test_displacement_range_holds_the_faded_displacements() -> None:
    # the skip maps' intervals must hold every displacement the fades scale down
    w = quiet_build("smooth", field_scale=2)
    rng = np.random.default_rng(5)
    lo = rng.uniform(
        [20.0, AXIS_Y - 10.0, AXIS_Z - 10.0], [56.0, AXIS_Y + 6.0, AXIS_Z + 6.0], (200, 3)
    )
    hi = lo + rng.uniform(0.5, 6.0, size=(200, 3))
    a, b = w.displacement_range(lo, hi)
    for i in range(len(lo)):
        pts = rng.uniform(lo[i], hi[i], size=(200, 3))
        q = w.apply(pts)
        keep = q[:, 0] < FAR / 2
        d = q[keep] - pts[keep]
        assert np.all(d >= a[i] - 1e-6), i
        assert np.all(d <= b[i] + 1e-6), i


def _straight(shift: float, twist: float = 0.0, radius: float = 5.0) -> Wire:
    base = [[x, 0.0, 0.0] for x in (0.0, 10.0, 20.0, 30.0)]
    mod = [[x, shift, 0.0] for x in (0.0, 10.0, 20.0, 30.0)]
    return Wire(
        base, mod, twist=[(0.0, 0.0), (1.0, twist)], radius=radius, ends="smooth", sides="rigid"
    )


def test_end_moves_are_the_sweeps_largest_move_of_each_end() -> None:
    # a translated wire moves both ends' cross-sections by the translation
    assert _straight(12.0).end_moves() == pytest.approx((12.0, 12.0), abs=1e-6)
    # a twist of theta at the far end moves its rim by 2 r sin(theta / 2)
    start, end = _straight(0.0, twist=np.pi / 2).end_moves()
    assert start == pytest.approx(0.0, abs=1e-6)
    assert end == pytest.approx(2 * 5.0 * np.sin(np.pi / 4), rel=1e-3)


def test_default_falloff_grows_with_the_end_move() -> None:
    assert _straight(1.0).falloff == 5.0  # the radius
    assert _straight(12.0).falloff == pytest.approx(24.0, abs=1e-5)
    assert Wire.from_dict({**_straight(12.0).to_dict(), "falloff": 7.0}).falloff == 7.0
    w = _straight(12.0)
    w.modified = _straight(3.0).modified  # edited: the cached moves follow the shape
    assert w.falloff == pytest.approx(6.0, abs=1e-5)
