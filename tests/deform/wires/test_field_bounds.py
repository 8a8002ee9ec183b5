"""The wire field's per-box bounds (``deform/wires/field_bounds.py``): boxes of one
wire use the info pyramid alone; the per-voxel displacement pyramid is built only for
boxes holding several wires' swept voxels, and both answers hold every displacement."""

from __future__ import annotations

import numpy as np

from tests.deform.wires.test_wires import AXIS_Y, AXIS_Z, R_CYL, axis_points, build, cylinder, wire
from voxwarp.deform.wires.constants import FAR
from voxwarp.deform.wires.field_bounds import FieldBounds


def _holds(w: object, lo: np.ndarray, hi: np.ndarray, rng: np.random.Generator) -> None:
    """Every sampled displacement of each box lies in its interval."""
    a, b = w.displacement_range(lo, hi)  # type: ignore[attr-defined]
    for i in range(len(lo)):
        pts = rng.uniform(lo[i], hi[i], size=(200, 3))
        q = w.apply(pts)  # type: ignore[attr-defined]
        keep = q[:, 0] < FAR / 2  # vacated samples show nothing
        d = q[keep] - pts[keep]
        assert np.all(d >= a[i] - 1e-6), i
        assert np.all(d <= b[i] + 1e-6), i


def two_wire_warp() -> object:
    """The cylinder and the one beside it, each moved by its own wire."""
    vol = cylinder(second=True)
    dz2 = 2 * R_CYL + 3.0
    first = wire(modified=axis_points(dy=3.0), radius=7.0)
    second = wire(
        base=axis_points(dz=dz2), modified=axis_points(dy=-2.0, dz=dz2), radius=7.0, twist=0.5
    )
    return build(vol, [first, second], field_scale=1)


def test_one_wire_never_builds_the_voxel_intervals() -> None:
    w = build(cylinder(), [wire(modified=axis_points(dy=3.0, dz=-2.0), twist=1.0)])
    rng = np.random.default_rng(2)
    lo = rng.uniform([0, 0, 0], [60, 36, 36], size=(200, 3))
    hi = lo + rng.uniform(0.5, 30.0, size=(200, 3))
    _holds(w, lo, hi, rng)
    w.support_bricks(lo, hi, 1e-3)
    bounds = w._field_bounds()
    assert isinstance(bounds, FieldBounds)
    assert bounds._info is not None
    assert bounds._displacement is None


def test_boxes_of_two_wires_hold_every_displacement() -> None:
    w = two_wire_warp()
    rng = np.random.default_rng(3)
    # boxes across both cylinders (mixed) and within each (one wire)
    lo = rng.uniform([0, AXIS_Y - 12, AXIS_Z - 10], [56, AXIS_Y + 4, AXIS_Z + 18], size=(150, 3))
    hi = lo + rng.uniform(0.5, 16.0, size=(150, 3))
    _holds(w, lo, hi, rng)
    bounds = w._field_bounds()
    assert bounds._displacement is not None  # some box held both wires' swept voxels


def test_a_box_of_both_wires_is_their_voxels_union() -> None:
    """A mixed box's interval is the union of its voxels' own intervals: it holds the
    intervals of the boxes of each wire's part."""
    w = two_wire_warp()
    mid = np.array([30.0, AXIS_Y, AXIS_Z + R_CYL + 1.5])
    extent = np.array([4.0, 4.0, 9.0])
    lo, hi = mid - extent, mid + extent
    (a,), (b,) = w.displacement_range(lo[None], hi[None])
    half = np.array([mid[2], mid[2]])
    parts_lo = np.array([lo, [lo[0], lo[1], half[0] + 0.5]])
    parts_hi = np.array([[hi[0], hi[1], half[1] - 0.5], hi])
    pa, pb = w.displacement_range(parts_lo, parts_hi)
    assert np.all(a <= pa.min(axis=0))
    assert np.all(b >= pb.max(axis=0))
    assert np.any(b - a > 1.0)  # the wires move it: not the empty interval


def test_two_threads_build_the_bounds_once(monkeypatch: object) -> None:
    """The GUI asks for a new field's bounds from its skip-map worker and, for the
    support, from the GUI thread at once: one of them builds the pyramids, the other
    waits and reads the same answers."""
    import threading
    import time

    w = build(cylinder(), [wire(modified=axis_points(dy=3.0), twist=1.0)])
    builds = []
    real = FieldBounds._build_info

    def slow_build(self: FieldBounds) -> object:
        builds.append(threading.get_ident())
        time.sleep(0.2)  # long enough for the other thread to arrive meanwhile
        return real(self)

    monkeypatch.setattr(FieldBounds, "_build_info", slow_build)  # type: ignore[attr-defined]
    lo = np.array([[10.0, 10.0, 10.0], [0.0, 0.0, 0.0]])
    hi = lo + 12.0
    out: dict[str, object] = {}

    def ask(name: str) -> None:
        out[name] = w.displacement_range(lo, hi)

    threads = [threading.Thread(target=ask, args=(n,)) for n in ("worker", "gui")]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(builds) == 1
    for a, b in zip(out["worker"], out["gui"], strict=True):  # type: ignore[call-overload]
        np.testing.assert_array_equal(a, b)
