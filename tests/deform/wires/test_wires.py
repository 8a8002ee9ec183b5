"""Wire field (deform/wires/): the mapping, the attribute field, the GPU warp.

Oracles: the identity wire maps every point to itself; a translated wire translates the
object (CPU exactly, GPU as an image shift); a twist of θ turns a cross-section's
off-axis marker by θ and a scale s moves it to s times its radius; the GPU render equals
the CPU resample through :meth:`WireFieldWarp.apply`; OpenCL and scipy fields agree;
plane masks keep a nearby second object still.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from scipy import ndimage

from tests.render.test_render import aligned_camera, grey_scene, projected
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import WarpError, warp_from_dict
from voxwarp.deform.wires.build import WireDeformer
from voxwarp.deform.wires.constants import FAR, LUT_SIZE, MAX_WIRES
from voxwarp.deform.wires.propagation import opencl_available
from voxwarp.deform.wires.warp import WireFieldWarp
from voxwarp.deform.wires.wire import Wire
from voxwarp.scene import Scene

N = (64, 40, 40)  # voxels, 1 mm
AXIS_Y, AXIS_Z = 19.5, 19.5  # the cylinder's axis (mm)
R_CYL = 6.0
MARKER = 4.0  # the marker rod's distance from the axis, along +y (mm)


def cylinder(second: bool = False) -> Volume:
    """A cylinder along x (value 100, radius 6 mm) with a marker rod (1000) 4 mm off its
    axis along +y, from x = 8 to 56 mm; ``second`` adds a parallel cylinder (value 100)
    3 mm beside it (the delineation problem)."""
    x, y, z = np.meshgrid(*(np.arange(n, dtype=np.float32) for n in N), indexing="ij")
    along = (x >= 8) & (x <= 56)
    r = np.hypot(y - AXIS_Y, z - AXIS_Z)
    data = np.where(along & (r <= R_CYL), 100.0, 0.0)
    data[along & (np.hypot(y - AXIS_Y - MARKER, z - AXIS_Z) <= 1.6)] = 1000.0
    if second:
        # its axis 2 R + 3 mm away along z (not inside the first's region of influence
        # by distance alone: the wire's radius below reaches it)
        r2 = np.hypot(y - AXIS_Y, z - AXIS_Z - (2 * R_CYL + 3.0))
        data[along & (r2 <= R_CYL)] = 100.0
    vol = Volume(np.asfortranarray(data.astype(np.float32)), name="cylinder")
    return vol


def axis_points(dx: float = 0.0, dy: float = 0.0, dz: float = 0.0) -> list[list[float]]:
    """Control points along the cylinder's axis (x from 4 to 60 mm), shifted."""
    return [[x + dx, AXIS_Y + dy, AXIS_Z + dz] for x in (4.0, 20.0, 36.0, 60.0)]


def wire(**kw: Any) -> Wire:
    kw.setdefault("ends", "rigid")  # the paper's sweep (test_wire_ends.py: the smooth one)
    kw.setdefault("sides", "rigid")  # (test_wire_sides.py: the smooth sides)
    kw.setdefault("radius", 9.0)
    kw.setdefault("beta", (50.0, 2000.0))
    base = kw.pop("base", axis_points())
    return Wire(base, kw.pop("modified", None), **kw)


def build(vol: Volume, wires: list[Wire], **kw: Any) -> WireFieldWarp:
    kw.setdefault("field_scale", 1)
    wd = WireDeformer(vol, wires, **kw)
    wd.build()
    return wd.warp()


def voxel_centres(vol: Volume) -> np.ndarray:
    idx = np.stack(np.meshgrid(*(np.arange(n) for n in vol.shape), indexing="ij"), -1)
    return vol.index_to_world(idx.reshape(-1, 3).astype(float))


def resample(vol: Volume, warp: WireFieldWarp) -> Volume:
    """The deformed volume on the CPU: value at voxel centre p = original at warp(p)."""
    q = warp.apply(voxel_centres(vol))
    far = q[:, 0] >= FAR / 2
    idx = vol.world_to_index(np.where(far[:, None], -1e6, q))
    out = ndimage.map_coordinates(
        np.asarray(vol.data, np.float64), idx.T, order=1, mode="constant", cval=0.0
    )
    out[far] = 0.0
    return Volume(np.asfortranarray(out.reshape(vol.shape).astype(np.float32)), name="res")


def marker_angle(section: np.ndarray) -> tuple[float, float]:
    """Angle (radians, from +y towards +z) and radius (mm) of the bright marker's centroid
    in a (y, z) cross-section of the 1 mm grid."""
    m = section > 300
    assert m.sum() > 3, "the marker is not in the section"
    j, k = np.nonzero(m)
    w = section[m]
    cy, cz = np.average(j, weights=w) - AXIS_Y, np.average(k, weights=w) - AXIS_Z
    return math.atan2(cz, cy), math.hypot(cy, cz)


def angle_diff(a: float, b: float) -> float:
    return abs((a - b + math.pi) % (2 * math.pi) - math.pi)


# ---------------------------------------------------------------------- the mapping (CPU)
def test_identity_wire_maps_every_point_to_itself() -> None:
    vol = cylinder()
    w = build(vol, [wire()])
    p = voxel_centres(vol)
    swept = w.swept(p)
    assert swept.sum() > 2000  # the cylinder (~5400 voxels) is swept
    q = w.apply(p)
    far = q[:, 0] >= FAR / 2
    np.testing.assert_allclose(q[~far], p[~far], atol=1e-6)
    # nothing visible is vacated: the swept set covers the object's own place
    assert not np.any(far & (vol.data.ravel(order="F")[...] > 0)[_c_to_f(vol)])


def _c_to_f(vol: Volume) -> np.ndarray:
    """Index map from C-order voxel enumeration (voxel_centres) to F-order ravel."""
    return np.ravel_multi_index(
        np.unravel_index(np.arange(np.prod(vol.shape)), vol.shape), vol.shape, order="F"
    )


def test_translated_wire_translates_the_object() -> None:
    vol = cylinder()
    d = np.array([0.0, 3.0, -2.0])
    w = build(vol, [wire(modified=axis_points(*d))])
    p = voxel_centres(vol)
    q = w.apply(p)
    swept = w.swept(p)
    np.testing.assert_allclose(q[swept], p[swept] - d, atol=1e-6)
    res = resample(vol, w).data
    # the cylinder's voxels (integer shift) are exactly where they moved to
    orig = np.asarray(vol.data)
    inner = (slice(12, 52), slice(None), slice(None))  # away from the wire's ends
    shifted = np.roll(np.roll(orig, 3, axis=1), -2, axis=2)
    np.testing.assert_allclose(res[inner], shifted[inner], atol=1e-3)


@pytest.mark.parametrize("theta", [math.pi / 2, 2.0])
def test_twist_rotates_a_cross_section_by_theta(theta: float) -> None:
    vol = cylinder()
    w = build(vol, [wire(twist=theta)])
    res = resample(vol, w).data
    before, r0 = marker_angle(np.asarray(vol.data)[32])
    after, r1 = marker_angle(res[32])
    assert angle_diff(after - before, theta) < math.radians(2)
    assert abs(r1 - r0) < 0.15


def test_twist_keys_interpolate_along_the_wire() -> None:
    vol = cylinder()
    # 0 at the start, pi at the end: the marker turns linearly with the length
    w = build(vol, [wire(twist=[(0.0, 0.0), (1.0, math.pi)])])
    res = resample(vol, w).data
    length = 56.0  # the wire runs x = 4 .. 60
    for x in (16, 32, 48):
        expected = math.pi * (x - 4.0) / length
        got = marker_angle(res[x])[0] - marker_angle(np.asarray(vol.data)[x])[0]
        assert angle_diff(got, expected) < math.radians(3), x


@pytest.mark.parametrize("s", [0.6, 1.4])
def test_scale_scales_a_cross_section(s: float) -> None:
    vol = cylinder()
    w = build(vol, [wire(scale=s, radius=9.0)])
    res = resample(vol, w).data
    _, r0 = marker_angle(np.asarray(vol.data)[32])
    _, r1 = marker_angle(res[32])
    assert abs(r1 - s * r0) < 0.2
    # the cylinder's cross-section area scales by s² (integrated, marker clipped out)
    a0 = np.minimum(np.asarray(vol.data)[32], 100.0).sum()
    a1 = np.minimum(res[32], 100.0).sum()
    assert abs(a1 / a0 - s * s) < 0.05 * s * s


def test_jacobian_is_the_local_linear_map() -> None:
    vol = cylinder()
    w = build(vol, [wire(modified=axis_points(dz=2.0), twist=0.7, scale=1.2)])
    p = voxel_centres(vol)
    p = p[w.swept(p)]
    p = p[(p[:, 0] > 16) & (p[:, 0] < 48)][::7]
    jac = w.jacobian(p)
    num = WireFieldWarp.__mro__[1].jacobian(w, p, eps=0.05)  # central differences
    err = np.abs(jac - num).max(axis=(1, 2))
    assert np.median(err) < 0.02
    # a rotation by the twist divided by the scale across the wire
    np.testing.assert_allclose(np.abs(np.linalg.det(jac)), 1 / 1.2**2, rtol=0.02)


# ---------------------------------------------------------------------- the field
def test_field_counts_are_consistent() -> None:
    vol = cylinder()
    wd = WireDeformer(vol, [wire(modified=axis_points(dy=3.0))], field_scale=2)
    st = wd.build()
    assert st.voxels == int(np.prod(st.field_shape))
    assert st.swept + st.vacated + st.ignored == st.voxels
    assert 0 < st.swept < st.voxels
    assert st.vacated > 0  # the object left part of its place
    assert st.percent_ignored == pytest.approx(100 * st.ignored / st.voxels)
    # the wire runs 4 mm beyond each end of the cylinder: those planes hold no object
    assert st.planes_dropped >= 4
    assert set(st.timings) >= {"masks", "seeds", "propagate", "flags", "total"}


@pytest.mark.parametrize("scale", [1, 2, 4, 8, 16])
def test_field_scales(scale: int) -> None:
    vol = cylinder()
    wd = WireDeformer(vol, [wire(modified=axis_points(dy=3.0))], field_scale=scale)
    st = wd.build()
    assert st.field_shape[1] == math.ceil(vol.shape[1] / scale)
    assert np.allclose(wd.field.spacing, scale)
    # the translation is exact wherever a point is swept, at every scale
    p = voxel_centres(vol)
    w = wd.warp()
    sw = w.swept(p)
    assert sw.any()
    np.testing.assert_allclose(w.apply(p[sw]), p[sw] - [0, 3, 0], atol=1e-6)


@pytest.mark.skipif(not opencl_available(), reason="no OpenCL platform")
def test_opencl_field_equals_the_scipy_reference() -> None:
    vol = cylinder(second=True)
    kw = {"field_scale": 1}
    ws = [wire(modified=axis_points(dz=-2.0), twist=[(0, 0), (1, 1.0)])]
    a = WireDeformer(vol, ws, backend="opencl", **kw)
    b = WireDeformer(vol, ws, backend="scipy", **kw)
    a.build()
    b.build()
    sa, wa, ta = a.field.decode()
    sb, wb, tb = b.field.decode()
    # equidistant seeds may resolve differently: the refined t of such voxels still
    # agrees (both are refined to the closest point), so states and t match closely
    assert (sa != sb).mean() < 0.002
    assert np.array_equal(wa, wb)
    both = (sa == 2) & (sb == 2)
    dt = np.abs(ta[both] - tb[both])
    assert np.quantile(dt, 0.99) < 0.05  # table units (1 = length / 255)
    assert dt.max() < 1.0


def test_without_opencl_the_build_warns_and_uses_scipy(monkeypatch: pytest.MonkeyPatch) -> None:
    from voxwarp.deform.wires import propagation

    vol = cylinder()
    ws = [wire(modified=axis_points(dz=-2.0))]
    reference = WireDeformer(vol, ws, backend="scipy")
    reference.build()
    monkeypatch.setenv(propagation.ENV_VAR, "0")
    propagation._reset_opencl_cache()
    try:
        wd = WireDeformer(vol, ws)  # backend "auto"
        with pytest.warns(propagation.OpenCLUnavailableWarning, match="pocl"):
            stats = wd.build()
        assert stats.backend == "scipy"
        for a, b in zip(wd.field.decode(), reference.field.decode(), strict=True):
            np.testing.assert_array_equal(a, b)
    finally:
        propagation._reset_opencl_cache()


def test_masks_solve_the_delineation_problem() -> None:
    vol = cylinder(second=True)
    # the wire in the first cylinder; its radius reaches well into the second
    ws = [wire(modified=axis_points(dy=4.0), radius=14.0)]
    p = voxel_centres(vol)
    data = np.asarray(vol.data)
    second = np.zeros(vol.shape, dtype=bool)
    second[..., 32:] = data[..., 32:] > 50  # the second cylinder (z >= 27 + 3 mm)
    second_pts = p[second.ravel()]
    masked = build(vol, ws, masks=True)
    unmasked = build(vol, ws, masks=False)
    # with masks the second cylinder stays where it is, and stays visible
    np.testing.assert_allclose(masked.apply(second_pts), second_pts, atol=1e-9)
    res = resample(vol, masked).data
    assert np.array_equal(res[second], data[second])
    # without masks the wire drags it along
    moved = np.any(np.abs(unmasked.apply(second_pts) - second_pts) > 1.0, axis=1)
    assert moved.mean() > 0.15  # the part of it inside the wire's radius


def test_masks_fill_cavities_and_keep_forks() -> None:
    """A hollow tube whose wall forks into two prongs: the lumen moves with the wall
    (holes are filled) and both prongs are swept (the 2.5D fill follows the object
    through neighbouring planes), though on a prong's planes the two are apart."""
    x, y, z = np.meshgrid(*(np.arange(n, dtype=np.float32) for n in N), indexing="ij")
    r = np.hypot(y - AXIS_Y, z - AXIS_Z)
    data = np.zeros(N, dtype=np.float32)
    tube = (x >= 8) & (x < 34) & (r >= 3.5) & (r <= 6.0)
    data[tube] = 100.0  # the wall; the lumen (r < 3.5) is 0, as the outside
    for dz in (-4.5, 4.5):  # two prongs from x = 30 on, 9 mm apart (a 6 mm gap)
        prong = (x >= 30) & (x <= 56) & (np.hypot(y - AXIS_Y, z - AXIS_Z - dz) <= 1.5)
        data[prong] = 100.0
    vol = Volume(np.asfortranarray(data), name="fork")
    w = build(vol, [wire(modified=axis_points(dy=3.0), radius=9.0)])
    swept = w.swept(voxel_centres(vol)).reshape(N)
    lumen = (x >= 12) & (x < 30) & (r < 2.5)
    assert swept[lumen].all()
    for dz in (-4.5, 4.5):
        prong = (x >= 40) & (x <= 52) & (np.hypot(y - AXIS_Y, z - AXIS_Z - dz) <= 1.0)
        assert swept[prong].all(), dz


def test_packed_layout_agrees_with_float() -> None:
    vol = cylinder()
    ws = [wire(modified=axis_points(dz=3.0), twist=[(0, 0), (1, math.pi / 2)])]
    f = build(vol, ws, layout="float")
    pk = build(vol, ws, layout="packed")
    assert pk.field.nbytes == 2 * int(np.prod(pk.field.shape))
    p = voxel_centres(vol)
    sf, sp = f.swept(p), pk.swept(p)
    assert np.array_equal(sf, sp)
    d = np.linalg.norm(f.apply(p[sf]) - pk.apply(p[sf]), axis=1)
    # integer t: 1/255 of the length; along straight parts the mapping ignores t errors
    assert np.quantile(d, 0.99) < 0.3
    assert d.max() < 1.0


def test_displacement_range_holds_every_displacement() -> None:
    vol = cylinder()
    w = build(vol, [wire(modified=axis_points(dy=3.0, dz=-2.0), twist=1.0)], field_scale=2)
    rng = np.random.default_rng(1)
    lo = rng.uniform([0, 0, 0], [60, 36, 36], size=(300, 3))
    hi = lo + rng.uniform(0.5, 6.0, size=(300, 3))
    a, b = w.displacement_range(lo, hi)
    for i in range(len(lo)):
        pts = rng.uniform(lo[i], hi[i], size=(200, 3))
        q = w.apply(pts)
        keep = q[:, 0] < FAR / 2  # vacated samples show nothing
        d = q[keep] - pts[keep]
        assert np.all(d >= a[i] - 1e-6), i
        assert np.all(d <= b[i] + 1e-6), i
    # and the intervals are tight enough to skip: untouched boxes get exactly 0
    far_lo = np.array([[0.0, 0.0, 0.0]])
    fa, fb = w.displacement_range(far_lo, far_lo + 2.0)
    assert np.all(fa == 0)
    assert np.all(fb == 0)


def test_object_may_leave_the_volume_box() -> None:
    vol = cylinder()
    # bend the far end 12 mm beyond the top of the box (z: 0 .. 40 mm)
    mod = [[4.0, AXIS_Y, AXIS_Z], [20.0, AXIS_Y, AXIS_Z], [36.0, AXIS_Y, 30.0], [60.0, 19.5, 52]]
    w = build(vol, [wire(modified=mod)], field_scale=2)
    _, hi = w.deformed_bounds(*vol.bounds)
    assert hi[2] > vol.bounds[1][2] + 10
    tip = np.array([[54.0, AXIS_Y, 48.0]])
    assert w.swept(tip).all()
    assert np.asarray(vol.data)[tuple(np.rint(vol.world_to_index(w.apply(tip))[0]).astype(int))] > 0


# ---------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    ("kwargs", "fragment"),
    [
        ({"base": [[1.0, 2.0, 3.0]]}, "2"),
        ({"base": [[0, 0, 0]] * 5, "kind": "bezier"}, "3k"),
        ({"base": [[10.0, 10, 10], [10.0, 10, 10]]}, "length"),
        ({"base": [[0, 0, 0], [np.nan, 1, 1]]}, "NaN"),
        ({"kind": "nurbs"}, "catmull-rom"),
        ({"radius": 0.0}, "radius"),
        ({"radius": "wide"}, "radius"),
        ({"twist": [(1.5, 1.0)]}, "[0, 1]"),
        ({"twist": [(0.5, np.inf)]}, "NaN"),
        ({"scale": [(0.5, 0.0)]}, "> 0"),
        ({"beta": (10, 5)}, "lo <= hi"),
        ({"beta": "bone"}, "value range"),
        ({"initial_normal": (0, 0, 0)}, "non-zero"),
    ],
)
def test_bad_wires_raise_clear_errors(kwargs: dict[str, Any], fragment: str) -> None:
    with pytest.raises(WarpError, match=None) as exc:
        wire(**kwargs)
    assert fragment.lower() in str(exc.value).lower()


def test_bad_deformer_arguments_raise_clear_errors() -> None:
    vol = cylinder()
    w = wire()
    outside = wire(base=[[500.0, 500, 500], [600.0, 500, 500]])
    with pytest.raises(WarpError, match="outside the volume"):
        WireDeformer(vol, [outside])
    with pytest.raises(WarpError, match=f"at most {MAX_WIRES}"):
        WireDeformer(vol, [w] * (MAX_WIRES + 1))
    with pytest.raises(WarpError, match="field_scale"):
        WireDeformer(vol, [w], field_scale=3)
    with pytest.raises(WarpError, match="layout"):
        WireDeformer(vol, [w], layout="half")
    with pytest.raises(WarpError, match="at least one"):
        WireDeformer(vol, [])
    with pytest.raises(WarpError, match=r"not a voxwarp\.deform\.Wire"):
        WireDeformer(vol, [{"base": []}])  # type: ignore[list-item]
    flat = type("V", (), {"data": np.zeros(4), "spacing": (1, 1, 1), "origin": (0, 0, 0)})
    with pytest.raises(WarpError, match="3D volume"):
        WireDeformer(flat(), [w])
    with pytest.raises(WarpError, match="data, spacing and origin"):
        WireDeformer(np.zeros((4, 4, 4)), [w])


def test_many_wires_get_their_own_ids() -> None:
    vol = cylinder(second=True)
    a = wire(modified=axis_points(dy=2.0), radius=7.0)
    b = wire(
        base=axis_points(dz=2 * R_CYL + 3.0),
        modified=axis_points(dy=-2.0, dz=2 * R_CYL + 3.0),
        radius=7.0,
    )
    w = build(vol, [a, b])
    _, wires, _ = w.field.decode()
    state = w.field.decode()[0]
    assert set(np.unique(wires[state == 2])) == {0, 1}
    p1 = np.array([[32.0, AXIS_Y + 2.0, AXIS_Z]])
    p2 = np.array([[32.0, AXIS_Y - 2.0, AXIS_Z + 2 * R_CYL + 3.0]])
    np.testing.assert_allclose(w.apply(p1), [[32.0, AXIS_Y, AXIS_Z]], atol=1e-6)
    np.testing.assert_allclose(w.apply(p2), [[32.0, AXIS_Y, AXIS_Z + 2 * R_CYL + 3]], atol=1e-6)


# ---------------------------------------------------------------------- serialisation
def test_round_trip_through_scene_json(tmp_path: Any) -> None:
    vol = cylinder()
    ws = [wire(modified=axis_points(dz=2.0), twist=[(0, 0), (1, 1.0)], scale=[(0.5, 1.2)])]
    w = build(vol, ws, field_scale=2, layout="packed")
    d = json.loads(json.dumps(w.to_dict()))
    assert d["type"] == "wires"
    assert set(d) == {
        "type",
        "wires",
        "field_scale",
        "layout",
        "masks",
        "mask_resolution",
        "dilation",
    }
    assert len(json.dumps(d)) < 2000  # the field is rebuilt from the volume, never stored
    loaded = warp_from_dict(d)
    with pytest.raises(WarpError, match="no volume yet"):
        loaded.apply(np.zeros((1, 3)))
    loaded.bind_volume(vol)
    p = voxel_centres(vol)[::5]
    np.testing.assert_array_equal(loaded.apply(p), w.apply(p))
    # through a whole scene file
    scene = Scene(vol, transfer_function="grayscale", warps=[w])
    vol_path = tmp_path / "cyl.npy"
    np.save(vol_path, np.asarray(vol.data))
    d = scene.to_dict()
    d["volume"] = {"path": str(vol_path), "spacing": [1, 1, 1]}
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(d))
    again = Scene.load(path)
    np.testing.assert_array_equal(again.warps[0].apply(p), w.apply(p))


def test_callable_beta_works_but_cannot_be_saved() -> None:
    vol = cylinder()
    w = build(vol, [wire(beta=lambda v: v > 500)])  # only the marker rod
    p = voxel_centres(vol)
    data = np.asarray(vol.data)
    swept = w.swept(p).reshape(vol.shape)
    assert swept[data > 500].mean() > 0.9
    assert swept[(data > 50) & (data < 500)].mean() < 0.3
    with pytest.raises(WarpError, match="callable beta"):
        w.to_dict()


@pytest.mark.parametrize(
    ("entry", "fragment"),
    [
        ({"type": "wires"}, "non-empty list"),
        ({"type": "wires", "wires": [{"base": [[0, 0, 0], [1, 1, 1]]}]}, "radius"),
        ({"type": "wires", "wires": [{"radius": 3}]}, "base"),
        ({"type": "wires", "wires": [{"base": [[0, 0, 0], [1, 1, 1]], "radius": 2, "x": 1}]}, "x"),
        (
            {
                "type": "wires",
                "wires": [{"base": [[0, 0, 0], [1, 1, 1]], "radius": 2}],
                "field_scale": 5,
            },
            "field_scale",
        ),
        (
            {
                "type": "wires",
                "wires": [{"base": [[0, 0, 0], [1, 1, 1]], "radius": 2}],
                "colour": 1,
            },
            "colour",
        ),
    ],
)
def test_bad_wire_json_raises_clear_errors(entry: dict[str, Any], fragment: str) -> None:
    with pytest.raises(WarpError) as exc:
        warp_from_dict(entry)
    assert fragment in str(exc.value)


# ---------------------------------------------------------------------- GPU
def _mip(offscreen: Callable[..., Any], vol: Volume, warps: list, view: str = "+z") -> np.ndarray:
    cam, size = aligned_camera(vol, view)
    scene = grey_scene(vol, "mip", view, cam, window=(500.0, 1000.0), warps=warps)
    return offscreen(*size, dtype="f4").render(scene)[..., 0].astype(np.float64)


def _cpu_mip(vol: Volume, view: str = "+z") -> np.ndarray:
    return np.clip(projected(vol, view, np.max) / 1000.0, 0.0, 1.0)


@pytest.mark.parametrize("layout", ["float", "packed"])
def test_gpu_render_equals_cpu_resample(offscreen: Callable[..., Any], layout: str) -> None:
    vol = cylinder()
    ws = [wire(modified=axis_points(dy=4.0, dz=-3.0), twist=[(0, 0), (1, math.pi / 2)])]
    w = build(vol, ws, layout=layout, field_scale=2)
    try:
        for view in ("+z", "+x"):
            gpu = _mip(offscreen, vol, [w], view)
            cpu = _cpu_mip(resample(vol, w), view)
            diff = np.abs(gpu - cpu)
            # samples at voxel centres: equal but where t (float32 on the GPU) makes a
            # sample fall on the other side of the marker's edge
            assert np.mean(diff > 0.05) < 0.01, view
            assert np.mean(diff) < 0.005, view
    finally:
        w.release()


def test_gpu_identity_and_translation(offscreen: Callable[..., Any]) -> None:
    vol = cylinder()
    plain = _mip(offscreen, vol, [])
    ident = build(vol, [wire()])
    moved = build(vol, [wire(modified=axis_points(dy=3.0))])
    try:
        same = _mip(offscreen, vol, [ident])
        assert np.abs(same - plain).max() < 1e-3
        shifted = _mip(offscreen, vol, [moved])
        # +z view: image right = +x, up = +y; 3 mm = 3 pixels up (rows decrease)
        expected = np.roll(plain, -3, axis=0)
        cols = slice(14, 50)  # away from the wire's ends
        assert np.abs(shifted[:, cols] - expected[:, cols]).max() < 1e-3
    finally:
        ident.release()
        moved.release()


def test_gpu_twist_turns_the_marker(offscreen: Callable[..., Any]) -> None:
    vol = cylinder()
    w = build(vol, [wire(twist=math.pi / 2)])
    try:
        # looking along +x at the cross-sections: MIP of the marker
        img = _mip(offscreen, vol, [w], "+x")
        plain = _mip(offscreen, vol, [], "+x")

        # +x view: right = +y, up = +z; the marker moves from +y (right of the axis)
        # to +z (above it)
        def centroid(im: np.ndarray) -> tuple[float, float]:
            rows, cols = np.nonzero(im > 0.5)
            return float(np.mean(cols)), float(np.mean(rows))

        c0, r0 = centroid(plain)
        c1, r1 = centroid(img)
        h = img.shape[0]
        y0, z0 = c0 - AXIS_Y, (h - 1 - r0) - AXIS_Z
        y1, z1 = c1 - AXIS_Y, (h - 1 - r1) - AXIS_Z
        assert angle_diff(math.atan2(z1, y1) - math.atan2(z0, y0), math.pi / 2) < math.radians(3)
    finally:
        w.release()


def test_gpu_skip_maps_do_not_change_the_image(offscreen: Callable[..., Any]) -> None:
    vol = cylinder()
    w = build(vol, [wire(modified=axis_points(dy=3.0, dz=-2.0), twist=1.2)], field_scale=2)
    cam, size = aligned_camera(vol, "+z")
    scene = Scene(
        vol,
        mode="dvr",
        transfer_function="grayscale",
        view="+z",
        projection="orthographic",
        window=(500.0, 1000.0),
        jitter=False,
        camera=cam,
        warps=[w],
    )
    r = offscreen(*size, dtype="f4")
    try:
        r.renderer.warped_skip_maps = "never"
        blocks = r.render(scene)
        assert r.renderer.last_skip_kind == "blocks"
        r.renderer.warped_skip_maps = "always"
        cells = r.render(scene)
        assert r.renderer.last_skip_kind == "cells"
        assert np.abs(cells - blocks).max() < 1e-5
        assert blocks[..., 3].max() > 0.5  # something was drawn
    finally:
        r.renderer.warped_skip_maps = "auto"
        w.release()


def test_lookup_table_size_matches_the_packed_t() -> None:
    # the packed layout's 8-bit t indexes the tables directly
    assert LUT_SIZE == 256


@pytest.mark.parametrize("layout", ["packed", "paper"])
def test_gpu_code_layouts_render_like_float(offscreen: Callable[..., Any], layout: str) -> None:
    vol = cylinder()
    ws = [wire(modified=axis_points(dy=3.0, dz=-3.0), twist=[(0, 0), (1, math.pi)])]
    f = build(vol, ws, layout="float", field_scale=2)
    pk = build(vol, ws, layout=layout, field_scale=2)
    try:
        for view in ("+z", "+x"):
            a = _mip(offscreen, vol, [f], view)
            b = _mip(offscreen, vol, [pk], view)
            diff = np.abs(a - b)
            # the packed t is an integer (1/255 of the wire; the paper's 1/127 of a
            # segment): where the twist turns fast, the marker's edge moves by a fraction
            # of a voxel
            assert np.mean(diff) < 0.005, view
            assert np.mean(diff > 0.1) < 0.01, view
    finally:
        f.release()
        pk.release()
