"""The wire field's ``layout="paper"`` (deform/wires/layouts.py; wire paper section 7.2) and the
plane-mask memory of section 7.1.

Oracles: the 16-bit code of a voxel decoded by hand against the curve's own segment
of the voxel's closest point (the float layout's u for the same voxel, through the
curve parameter and :meth:`Curve.segment_of`); paper vs float mapping within a bound
derived from the 7-bit t (below); the mask memory against a count of planes and pixels
by hand. The GLSL decode against the CPU one, and the rendered image against the float
layout's, are parametrized with the other layouts in tests/deform/wires/test_wire_gpu_sampling.py
and tests/deform/wires/test_wires.py.

Tolerance of paper vs float: where all 8 neighbours of a sample are swept by the same
wire, both layouts interpolate t with the same trilinear weights, so the paper
layout's t differs from the float one by at most the largest rounding of a neighbour's
per-segment t: half a step, ``(u_{s+1} - u_s) / (2 * 127)`` in table units. The mapping
``A(t) p + b(t)`` is piecewise linear in t, so the point moves by at most that times
``max_i |(A_{i+1} - A_i) p + (b_{i+1} - b_i)|`` (per table entry).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.deform.wires.test_wires import (
    AXIS_Y,
    AXIS_Z,
    axis_points,
    build,
    cylinder,
    voxel_centres,
    wire,
)
from voxwarp.deform.warp import WarpError, warp_from_dict
from voxwarp.deform.wires.build import WireDeformer
from voxwarp.deform.wires.constants import FAR, LUT_SIZE, PAPER_VACATED
from voxwarp.deform.wires.warp import WireFieldWarp
from voxwarp.deform.wires.wire import Wire


def _twisted(layout: str) -> WireFieldWarp:
    """The cylinder with a bent wire twisted by half a turn (3 Catmull-Rom segments)."""
    ws = [wire(modified=axis_points(dy=3.0, dz=-3.0), twist=[(0, 0), (1, math.pi)])]
    return build(cylinder(), ws, layout=layout, field_scale=2)


def test_paper_code_bits_decoded_by_hand() -> None:
    f, pp = _twisted("float"), _twisted("paper")
    assert pp.field.nbytes == 2 * int(np.prod(pp.field.shape))
    code = pp.field.code.astype(np.int64)
    state = f.field.state
    swept = state >= 2
    assert np.array_equal(swept, (code & 0x8000) != 0)
    assert np.array_equal(state == 1, code == PAPER_VACATED)
    w = f.wires[0]
    tab = f.field.tables[0]
    seg_len = [w.modified.arc_length(t0=s / 3, t1=(s + 1) / 3) for s in range(3)]
    starts = np.concatenate([[0.0], np.cumsum(seg_len)]) / sum(seg_len) * (LUT_SIZE - 1)
    for sel in (swept, (state == 0) & (code != 0)):  # swept, and unswept in the region
        c = code[sel]
        u = f.field.t[sel] / (LUT_SIZE - 1)  # the same propagation: the same u
        assert np.all((c >> 11) & 0xF == 0)  # wire 0
        seg = w.modified.segment_of(np.interp(u, tab.u, tab.t_modified))[0]
        got_seg = (c >> 7) & 0xF
        # the segment of the closest point (a voxel on a boundary may fall either way)
        at_edge = np.min(np.abs(u[:, None] * (LUT_SIZE - 1) - starts[None, 1:-1]), 1) < 1e-3
        assert np.all((got_seg == seg) | at_edge)
        tu = u * (LUT_SIZE - 1)
        frac = (tu - starts[got_seg]) / (starts[got_seg + 1] - starts[got_seg])
        # t within the segment in 128 steps (±1 for the table's arc-length rounding)
        assert np.all(np.abs((c & 0x7F) - frac * 127) <= 1.0)
    assert set(np.unique((code[swept] >> 7) & 0xF)) == {0, 1, 2}


def test_paper_layout_maps_like_float_within_the_t_step() -> None:
    f, pp = _twisted("float"), _twisted("paper")
    p = voxel_centres(cylinder()) + 0.3  # off the voxel centres: t is interpolated
    p = p[f.swept(p)]
    # samples whose 8 field neighbours are all swept by wire 0 in both layouts
    fld = pp.field
    g = np.clip((p - fld.lo) / fld.spacing - 0.5, 0, np.asarray(fld.shape) - 1.0)
    i0 = np.floor(g).astype(np.int64)
    corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    idx = np.minimum(i0[:, None, :] + corners[None], np.asarray(fld.shape) - 1)
    codes = fld.code[idx[..., 0], idx[..., 1], idx[..., 2]].astype(np.int64)
    inner = np.all(codes & 0x8000 != 0, axis=1)
    p, codes = p[inner], codes[inner]
    mixed = np.ptp((codes >> 7) & 0xF, axis=1) > 0  # neighbours in two segments
    assert mixed.sum() > 50  # segment boundaries are tested
    tab = fld.tables[0]
    d_a = np.diff(tab.matrices, axis=0)
    d_b = np.diff(tab.offsets, axis=0)
    lip = np.linalg.norm(np.einsum("nij,mj->mni", d_a, p) + d_b[None], axis=2).max(1)
    half_step = np.diff(fld.segments[0, :4]).max() / (2 * 127)
    err = np.linalg.norm(pp.apply(p) - f.apply(p), axis=1)
    assert np.all(err <= half_step * lip + 1e-6)
    assert err.max() > 1e-3  # the quantisation shows: the comparison is not vacuous
    # mixing per-segment t across a boundary (not the table coordinate) would be far off
    assert np.all(err[mixed] <= half_step * lip[mixed] + 1e-6)


def test_paper_layout_limits_are_one_line_errors() -> None:
    vol = cylinder()
    many = [wire() for _ in range(17)]
    with pytest.raises(WarpError, match=r"at most 16 wires.*layout='packed'"):
        WireDeformer(vol, many, layout="paper")
    WireDeformer(vol, many, layout="packed")  # the suggested layout holds them
    long = [[4.0 + 56.0 * i / 17, AXIS_Y, AXIS_Z] for i in range(18)]  # 17 segments
    with pytest.raises(WarpError, match=r"at most 16 segments.*wire 0.*17.*layout='packed'"):
        WireDeformer(vol, [wire(base=long)], layout="paper")
    ok = [[4.0 + 56.0 * i / 16, AXIS_Y, AXIS_Z] for i in range(17)]  # 16 segments fit
    WireDeformer(vol, [wire(base=ok)], layout="paper")
    spec = {"type": "wires", "layout": "paper", "wires": [w.to_dict() for w in many]}
    with pytest.raises(WarpError, match="at most 16 wires") as err:
        warp_from_dict(spec)
    assert "\n" not in str(err.value)


def test_paper_layout_round_trips_through_json() -> None:
    w = _twisted("paper")
    d = w.to_dict()
    assert d["layout"] == "paper"
    back = warp_from_dict(d)
    back.bind_volume(cylinder())
    assert back.field.layout == "paper"
    np.testing.assert_array_equal(back.field.code, w.field.code)


@pytest.mark.filterwarnings("ignore:wire .* end lies inside")
def test_mask_memory_is_kept_planes_times_pixels_over_8() -> None:
    # a straight wire inside the cylinder (x 10..50 mm, every plane meets the object):
    # 1 mm pixels and planes -> 41 planes of (2 * 9 + 1)^2 pixels, one bit each
    vol = cylinder()
    straight = [[x, AXIS_Y, AXIS_Z] for x in (10.0, 30.0, 50.0)]
    rigid = Wire(
        straight, radius=9.0, beta=(50.0, 2000.0), ends="rigid", sides="rigid"
    )  # no radial fade
    wd = WireDeformer(vol, [rigid], mask_resolution=1.0)
    stats = wd.build()
    assert stats.planes == 41
    assert stats.planes_dropped == 0
    assert stats.mask_bytes == (math.ceil(41 * 19 * 19 / 8),)
    assert stats.mask_bytes_total == 1851
    assert stats.as_dict()["mask_bytes_total"] == 1851
    # a wire running out of the object (x 4..60): planes beyond its ends are dropped and
    # cost nothing; two wires add up
    two = [wire(), rigid]
    st2 = WireDeformer(vol, two, mask_resolution=1.0).build()
    kept0 = 57 - st2.planes_dropped
    assert st2.mask_bytes == (math.ceil(kept0 * 19 * 19 / 8), 1851)
    assert st2.mask_bytes_total == sum(st2.mask_bytes)


# ---------------------------------------------------------------------- propagation domain
def test_flagged_propagation_gives_the_region_field() -> None:
    region, flagged = _twisted("float"), None
    ws = [wire(modified=axis_points(dy=3.0, dz=-3.0), twist=[(0, 0), (1, math.pi)])]
    flagged = build(cylinder(), ws, field_scale=2, propagate="flagged")
    assert flagged.deformer.stats.propagate == "flagged"
    a, b = region.field, flagged.field
    np.testing.assert_array_equal(a.state, b.state)  # same swept and vacated voxels
    assert (a.state >= 2).sum() > 1000
    assert (a.state == 1).sum() > 100
    # t agrees wherever a swept sample can read it (the swept voxels and their
    # neighbours); nearest-seed ties may pick another seed, refined to the same point
    near = np.zeros(a.shape, dtype=bool)
    sw = np.argwhere(a.state >= 2)
    for d in np.ndindex(3, 3, 3):
        idx = np.clip(sw + np.array(d) - 1, 0, np.asarray(a.shape) - 1)
        near[idx[:, 0], idx[:, 1], idx[:, 2]] = True
    assert np.abs(a.t[near] - b.t[near]).max() < 0.05
    # and the propagation skipped much of the rest of the region: away from the swept
    # voxels (beyond the masks' touched voxels and two voxels around them) the flagged
    # field holds no propagated u, the region field does
    far = ~near & (a.state == 0) & (a.t > 1.0)
    assert far.sum() > 1000
    assert np.mean(b.t[far] == 0.0) > 0.5


def test_flagged_propagation_keeps_smooth_ends() -> None:
    ws = [wire(modified=axis_points(dy=3.0), radius=9.0, ends="smooth")]
    region = build(cylinder(), ws, field_scale=2)
    flagged = build(cylinder(), ws, field_scale=2, propagate="flagged")
    np.testing.assert_array_equal(region.field.state, flagged.field.state)


def test_propagate_option_is_checked_and_saved() -> None:
    with pytest.raises(WarpError, match=r"propagate must be one of \('region', 'flagged'\)"):
        WireDeformer(cylinder(), [wire()], propagate="all")
    ws = [wire(modified=axis_points(dy=3.0))]
    w = build(cylinder(), ws, field_scale=2, propagate="flagged")
    d = w.to_dict()
    assert d["propagate"] == "flagged"
    assert "propagate" not in build(cylinder(), ws, field_scale=2).to_dict()  # the default
    back = warp_from_dict(d)
    back.bind_volume(cylinder())
    assert back.deformer.propagate == "flagged"
    with pytest.raises(WarpError, match="propagate"):
        warp_from_dict({**d, "propagate": "everywhere"})


def test_paper_layout_displacement_range_holds_every_displacement() -> None:
    # the skip maps' bounds come from the decoded table coordinates (as the packed test)
    w = _twisted("paper")
    rng = np.random.default_rng(5)
    lo = rng.uniform([0, 0, 0], [60, 36, 36], size=(200, 3))
    hi = lo + rng.uniform(0.5, 6.0, size=(200, 3))
    a, b = w.displacement_range(lo, hi)
    moved = 0
    for i in range(len(lo)):
        pts = rng.uniform(lo[i], hi[i], size=(200, 3))
        q = w.apply(pts)
        keep = q[:, 0] < FAR / 2  # vacated samples show nothing
        d = q[keep] - pts[keep]
        assert np.all(d >= a[i] - 1e-6), i
        assert np.all(d <= b[i] + 1e-6), i
        moved += int(np.any(np.abs(d) > 0.5))
    assert moved > 20  # boxes in the swept region were tested
