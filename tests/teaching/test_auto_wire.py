"""The automatic wire of ``voxwarp demo INPUT`` (voxwarp.teaching.auto_wire).

Oracles: on two objects it runs along the larger one's long axis, both ends beyond the
object's extent and its radius covering it; on the bundled MRI and CT, the same wire
built with the rigid sweep raises no "end inside the object" warning (so its ends lie
outside what it sweeps); data with no object stands out is skipped with a reason.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from voxwarp.core.volume import Volume
from voxwarp.deform.wires.field import Wire, WireDeformer
from voxwarp.io.samples import load_sample
from voxwarp.teaching.auto_wire import auto_wire, otsu_threshold


def two_objects() -> Volume:
    """A long ellipsoid along x (value 100; x 10..70 mm) and a small ball (value 120)."""
    x, y, z = np.meshgrid(*(np.arange(n, dtype=np.float32) for n in (80, 48, 48)), indexing="ij")
    data = np.where(((x - 40) / 30) ** 2 + ((y - 24) / 12) ** 2 + ((z - 24) / 10) ** 2 <= 1, 100, 0)
    data = data.astype(np.float32)
    data[np.hypot(np.hypot(x - 10, y - 40), z - 40) <= 5] = 120.0
    data += np.random.default_rng(3).normal(0.0, 3.0, data.shape).astype(np.float32)
    return Volume(np.asfortranarray(data), name="two")


def rigid_copy(wire: Wire) -> Wire:
    return Wire(
        wire.base.control_points,
        wire.modified.control_points,
        radius=wire.radius,
        beta=wire.beta,
        ends="rigid",
    )


def assert_ends_outside(vol: Volume, wire: Wire, field_scale: int) -> None:
    """The rigid sweep of ``wire`` warns of no end inside the object."""
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        WireDeformer(vol, [rigid_copy(wire)], field_scale=field_scale).build()
    inside = [str(w.message) for w in rec if "lies inside" in str(w.message)]
    assert not inside, inside


def test_otsu_splits_two_levels() -> None:
    values = np.concatenate([np.full(500, 10.0), np.full(300, 90.0)])
    assert 10.0 < otsu_threshold(values) < 90.0


def test_it_picks_the_largest_object_with_ends_outside() -> None:
    vol = two_objects()
    auto = auto_wire(vol)
    wire = auto.wire
    assert wire is not None, auto.message
    base = wire.base.control_points
    axis = base[-1] - base[0]
    assert abs(axis[0]) / np.linalg.norm(axis) > 0.99  # along the ellipsoid's long axis
    assert min(base[0, 0], base[-1, 0]) < 10.0 - 2.0  # both ends beyond the object
    assert max(base[0, 0], base[-1, 0]) > 70.0 + 2.0
    np.testing.assert_allclose(base[:, 1:], [[24.0, 24.0]] * 4, atol=1.0)  # through it
    assert wire.radius >= 12.0  # covers the cross-section
    assert wire.ends == "smooth"
    lo, hi = wire.beta
    assert 10.0 < lo < 90.0
    assert hi >= 100.0
    assert "largest object" in auto.message
    assert "both ends outside it" in auto.message
    assert_ends_outside(vol, wire, field_scale=2)
    # the view picks the bend: across it, never along it
    bent = auto_wire(vol, view=(0.0, 0.0, 1.0)).wire
    assert bent is not None
    lean = bent.modified.control_points[-1] - bent.base.control_points[-1]
    assert abs(lean[2]) < 1e-6 < abs(lean[1])


def test_a_principal_axis_along_the_view_gives_way_to_the_second() -> None:
    # a flat ellipsoid, 60 mm along x, 50 along y: seen along x, the wire runs along y
    x, y, z = np.meshgrid(*(np.arange(n, dtype=np.float32) for n in (72, 64, 32)), indexing="ij")
    inside = ((x - 36) / 30) ** 2 + ((y - 32) / 25) ** 2 + ((z - 16) / 8) ** 2 <= 1
    vol = Volume(np.asfortranarray(np.where(inside, 100.0, 0.0).astype(np.float32)))
    for view, along in (((0.0, 0.0, 1.0), 0), ((1.0, 0.0, 0.0), 1)):
        wire = auto_wire(vol, view=view).wire
        assert wire is not None
        base = wire.base.control_points
        axis = (base[-1] - base[0]) / np.linalg.norm(base[-1] - base[0])
        assert abs(axis[along]) > 0.99, (view, axis)
        lean = wire.modified.control_points[-1] - base[-1]
        assert abs(lean @ np.asarray(view)) < 1e-6  # bent across the view


@pytest.mark.parametrize("data", ["constant", "speck"])
def test_no_object_is_skipped_with_a_reason(data: str) -> None:
    arr = np.zeros((32, 32, 32), np.float32)
    if data == "speck":
        arr[16, 16, 16] = 100.0
    auto = auto_wire(Volume(arr))
    assert auto.wire is None
    assert auto.message.startswith("skipped the wire:")


@pytest.mark.parametrize(("name", "scale"), [("colin27", 2), ("stent", 4)])
def test_bundled_scans_get_a_wire_whose_ends_lie_outside(name: str, scale: int) -> None:
    vol = load_sample(name)
    auto = auto_wire(vol)
    assert auto.wire is not None, auto.message
    assert_ends_outside(vol, auto.wire, field_scale=scale)
