"""Tests of voxwarp.editing.session: picking, selecting, dragging, wires, lattice, placement, undo,
files.

Pure CPU (no GL context): a 48³ ``fish`` sample and small deformation grids. Oracles:
the camera's own projection (a dragged handle must land under the cursor, in the plane
parallel to the image through it), handle positions computed here from the grid and
the placement matrix, the lattice's forward map, arc-length fractions of straight
wires, exact equality of snapshots, and the scene JSON read back by ``Scene.load``.

"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from voxwarp.core.camera import PROJECTIONS, VIEWS, Camera
from voxwarp.core.transfer_function import TransferFunction
from voxwarp.core.volume import Volume
from voxwarp.deform.elements.massspring import MassSpring
from voxwarp.deform.elements.offset_field import OffsetFieldWarp
from voxwarp.deform.lattice.warp import LatticeWarp
from voxwarp.deform.warp import AffineWarp, chain_apply
from voxwarp.deform.wires.field import WireFieldWarp
from voxwarp.editing.families.wires import WiresFamily
from voxwarp.editing.session import (
    PICK_RADIUS_PX,
    DisplayOptions,
    EditorError,
    EditSession,
    Placement,
)
from voxwarp.errors import SceneError
from voxwarp.io.samples import load_sample
from voxwarp.scene import Scene

SIZE = (320, 240)
ELEMENT_KINDS = ("massspring", "chainmail")
FAMILIES = ("massspring", "chainmail", "wires", "lattice")
#: (view, projection) pairs the geometric tests run under
VIEWS_UNDER_TEST: list[tuple[Any, str]] = [
    ("+z", "perspective"),
    ((35.0, 25.0), "perspective"),
    ((-120.0, -40.0), "orthographic"),
    ("-x", "orthographic"),
]
PLACEMENT = Placement(translate=(6.0, -4.0, 3.0), rotate=(20.0, -10.0, 35.0), scale=(1.2, 0.8, 1.1))


# ---------------------------------------------------------------------- helpers
@pytest.fixture(scope="module")
def volume() -> Volume:
    """The fish phantom, small: box (-1, -0.5, -0.42) .. (95, 47.5, 39.6) mm."""
    return load_sample("fish", shape=(48, 48, 48))


@pytest.fixture
def session(volume: Volume) -> EditSession:
    """A fresh session without a deformation."""
    return EditSession(Scene(volume))


def camera_for(points: np.ndarray, view: Any, projection: str) -> Camera:
    """A camera framing ``points`` (world mm)."""
    return Camera.fit(points.min(axis=0), points.max(axis=0), view, projection)


def flat(shape: tuple[int, int, int], *ijk: int) -> int:
    """Handle index of grid element / lattice node ``ijk``."""
    return int(np.ravel_multi_index(ijk, shape))


def drag(session: EditSession, camera: Camera, offset: tuple[float, float]) -> dict[str, Any]:
    """Drag the selection from the reference's pixel by ``offset`` pixels; what happened."""
    before = session.handles().copy()
    pixel = camera.project(before[session.reference], SIZE)[0]
    assert session.begin_drag(camera, SIZE, pixel)
    cursor = pixel + np.asarray(offset, dtype=np.float64)
    delta = session.drag_to(cursor)
    session.end_drag()
    return {"before": before, "after": session.handles().copy(), "cursor": cursor, "delta": delta}


def layer_names(session: EditSession, **display: bool) -> list[str]:
    """Names of the overlay layers with some DisplayOptions changed."""
    return [layer.name for layer in session.overlay_layers(DisplayOptions(**display))]


def build_wires(session: EditSession) -> WireFieldWarp:
    """Rebuild the wire field and install it (as the GUI's worker does)."""
    job = session.family.build_job()
    warp = job.run()
    assert warp is not None
    assert session.family.install(job)
    return warp


def deform_family(session: EditSession, kind: str) -> None:
    """Set up ``kind`` and make one edit that moves a handle."""
    if kind == "wires":
        session.set_deformation("wires")
        session.select([1])
    elif kind == "lattice":
        session.set_deformation("lattice", resolution=4)
        session.select([flat((4, 4, 4), 1, 2, 1)])
    else:
        session.set_deformation(kind, resolution=5, anchor="corners")
        session.select([flat((5, 5, 5), 2, 2, 2), flat((5, 5, 5), 2, 3, 2)])
    cam = camera_for(session.handles(), (30.0, 20.0), "perspective")
    drag(session, cam, (12.0, -7.0))
    if kind == "wires":
        build_wires(session)


# ---------------------------------------------------------------------- camera
@settings(max_examples=80, deadline=None, derandomize=True)
@given(
    view=st.one_of(
        st.sampled_from(VIEWS),
        st.tuples(st.floats(-180.0, 180.0), st.floats(-90.0, 90.0)),
    ),
    projection=st.sampled_from(PROJECTIONS),
    zoom=st.floats(0.5, 3.0),
    u=st.tuples(*(st.floats(0.0, 1.0),) * 3),
)
def test_point_on_view_plane_inverts_project(
    view: Any, projection: str, zoom: float, u: tuple[float, float, float]
) -> None:
    """The point where the ray through p's pixel meets p's view plane is p itself."""
    lo, hi = np.array([-10.0, -20.0, 0.0]), np.array([30.0, 10.0, 25.0])
    cam = Camera.fit(lo, hi, view, projection, zoom=zoom)
    p = lo + np.asarray(u) * (hi - lo)
    pixel = cam.project(p, SIZE)[0]
    np.testing.assert_allclose(cam.point_on_view_plane(pixel, SIZE, p), p, atol=1e-8)


@pytest.mark.parametrize(("view", "projection"), VIEWS_UNDER_TEST)
def test_ray_is_unit_and_passes_through_its_pixel(view: Any, projection: str) -> None:
    """Camera.ray: unit direction; its points project to the pixel; through p for p's pixel."""
    cam = Camera.fit((-10, -20, 0), (30, 10, 25), view, projection)
    back = cam.rotation[:, 2]
    rng = np.random.default_rng(1)
    for p in rng.uniform((-10, -20, 0), (30, 10, 25), size=(6, 3)):
        pixel = cam.project(p, SIZE)[0]
        origin, d = cam.ray(pixel, SIZE)
        assert np.linalg.norm(d) == pytest.approx(1.0, abs=1e-12)
        assert d @ back < 0  # it looks away from the eye side
        if projection == "orthographic":
            np.testing.assert_allclose(d, -back, atol=1e-12)
        # p lies on the ray, in front of its origin
        s = (p - origin) @ d
        assert s > 0
        np.testing.assert_allclose(origin + s * d, p, atol=1e-8)
        for t in (0.5 * cam.distance, cam.distance, 1.5 * cam.distance):
            np.testing.assert_allclose(cam.project(origin + t * d, SIZE)[0], pixel, atol=1e-7)


# ---------------------------------------------------------------------- picking
@pytest.mark.parametrize(("view", "projection"), VIEWS_UNDER_TEST[1:3])
def test_pick_returns_the_nearest_handle_within_the_radius(
    session: EditSession, view: Any, projection: str
) -> None:
    """pick == argmin of the projected distance over the handles within the radius."""
    session.set_deformation("massspring", resolution=4)
    pts = session.handles()
    cam = camera_for(pts, view, projection)
    xy = cam.project(pts, SIZE)
    rng = np.random.default_rng(2)
    checked = 0
    for i in rng.choice(len(pts), size=12, replace=False):
        pixel = xy[i] + rng.uniform(-4.0, 4.0, size=2)
        dist = np.hypot(*(xy - pixel).T)
        order = np.argsort(dist)
        if dist[order[1]] - dist[order[0]] < 1e-3:
            continue  # a tie on screen: not what this test is about
        expected = int(order[0]) if dist[order[0]] <= PICK_RADIUS_PX else None
        assert session.pick(cam, SIZE, pixel) == expected
        checked += 1
    assert checked >= 8


def test_pick_returns_none_beyond_the_radius(session: EditSession) -> None:
    """A pixel farther than the radius from every handle picks nothing; a larger radius does."""
    session.set_deformation("lattice", resolution=3)
    pts = session.handles()
    cam = camera_for(pts, (35.0, 25.0), "perspective")
    xy = cam.project(pts, SIZE)
    i = int(np.argmax(xy[:, 0]))
    pixel = xy[i] + (PICK_RADIUS_PX + 1.0, 0.0)  # right of the rightmost handle
    dist = np.hypot(*(xy - pixel).T)
    assert dist.min() > PICK_RADIUS_PX
    assert session.pick(cam, SIZE, pixel) is None
    assert session.pick(cam, SIZE, pixel, radius=float(dist.min()) + 0.01) == int(np.argmin(dist))
    assert session.pick(cam, SIZE, pixel, radius=float(dist.min()) - 0.01) is None


@pytest.mark.parametrize("projection", PROJECTIONS)
@pytest.mark.parametrize(("view", "near_k"), [("+z", 2), ("-z", 0)])
def test_pick_prefers_the_handle_nearer_the_eye(
    session: EditSession, projection: str, view: str, near_k: int
) -> None:
    """Three lattice nodes on the optical axis share a pixel: the one nearest the eye wins."""
    session.set_deformation("lattice", resolution=3)  # 3 nodes per axis
    pts = session.handles()
    cam = camera_for(pts, view, projection)
    column = [flat((3, 3, 3), 1, 1, k) for k in range(3)]
    xy = cam.project(pts[column], SIZE)
    np.testing.assert_allclose(xy, np.repeat(xy[:1], 3, axis=0), atol=1e-9)
    assert session.pick(cam, SIZE, xy[0]) == column[near_k]


@pytest.mark.parametrize(("view", "projection"), VIEWS_UNDER_TEST)
def test_pick_rect_returns_exactly_the_handles_inside(
    session: EditSession, view: Any, projection: str
) -> None:
    """The rubber band holds the handles whose projection lies in it (corners in any order)."""
    session.set_deformation("chainmail", resolution=5)
    pts = session.handles()
    cam = camera_for(pts, view, projection)
    xy = cam.project(pts, SIZE)
    rng = np.random.default_rng(3)
    for _ in range(6):
        a, b = rng.uniform((0, 0), SIZE, size=(2, 2))
        inside = np.all((xy >= np.minimum(a, b)) & (xy <= np.maximum(a, b)), axis=1)
        assert session.pick_rect(cam, SIZE, a, b) == np.flatnonzero(inside).tolist()
        assert session.pick_rect(cam, SIZE, b, a) == np.flatnonzero(inside).tolist()
    assert session.pick_rect(cam, SIZE, (0, 0), SIZE) == list(range(len(pts)))


# ---------------------------------------------------------------------- selection
def test_select_modes_and_the_reference(session: EditSession) -> None:
    """replace/add/remove/toggle change the selection; the reference is the last added."""
    session.set_deformation("lattice", resolution=3)
    session.select([4, 2, 7])
    assert (session.selection, session.reference) == ([4, 2, 7], 7)
    session.select([1, 2], "add")
    assert (session.selection, session.reference) == ([4, 2, 7, 1], 2)
    session.select([4], "remove")
    assert (session.selection, session.reference) == ([2, 7, 1], 2)
    session.select([7, 9], "toggle")  # 7 goes, 9 comes and is the last added
    assert (session.selection, session.reference) == ([2, 1, 9], 9)
    session.select([5], "replace")
    assert (session.selection, session.reference) == ([5], 5)
    session.select([], "replace")
    assert (session.selection, session.reference) == ([], None)


def test_reference_falls_back_to_the_last_selected_when_removed(session: EditSession) -> None:
    """Removing or toggling off the reference makes the last selected handle the reference."""
    session.set_deformation("lattice", resolution=3)
    session.select([3, 8, 5, 1])
    session.set_reference(8)
    session.select([8], "remove")
    assert (session.selection, session.reference) == ([3, 5, 1], 1)
    session.set_reference(3)
    session.select([3], "toggle")
    assert (session.selection, session.reference) == ([5, 1], 1)
    session.select([5, 1], "remove")
    assert (session.selection, session.reference) == ([], None)
    with pytest.raises(EditorError, match="not selected"):
        session.set_reference(5)


@pytest.mark.parametrize("bad", [27, -1, 1000])
def test_select_bad_index_names_the_handle_count(session: EditSession, bad: int) -> None:
    """An index outside 0..N-1 raises EditorError with N; the selection stays."""
    session.set_deformation("lattice", resolution=3)  # 27 nodes
    session.select([2])
    with pytest.raises(EditorError, match=rf"no handle {bad}: there are 27 handles"):
        session.select([1, bad], "add")
    assert (session.selection, session.reference) == ([2], 2)


# ---------------------------------------------------------------------- dragging
@pytest.mark.parametrize(("view", "projection"), VIEWS_UNDER_TEST)
@pytest.mark.parametrize("kind", ELEMENT_KINDS)
def test_drag_moves_the_reference_in_the_view_plane_under_the_cursor(
    session: EditSession, kind: str, view: Any, projection: str
) -> None:
    """The reference's target offset is parallel to the image and it lands under the cursor."""
    session.set_deformation(kind, resolution=5, anchor="corners")
    ref = flat((5, 5, 5), 2, 2, 2)
    session.select([ref])
    cam = camera_for(session.handles(), view, projection)
    d = drag(session, cam, (14.0, 0.0))
    offset = d["after"][ref] - d["before"][ref]
    assert np.linalg.norm(offset) > 1.0
    assert offset @ cam.rotation[:, 2] == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(cam.project(d["after"][ref], SIZE)[0], d["cursor"], atol=1e-6)
    np.testing.assert_allclose(d["delta"], offset, atol=1e-9)
    # the model holds the element at exactly that offset from rest
    assert session.model is not None
    held = {tuple(h["index"]): np.array(h["offset"]) for h in session.model.to_dict()["held"]}
    rest = session.model.grid.rest_positions[2, 2, 2]
    np.testing.assert_allclose(held[(2, 2, 2)], d["after"][ref] - rest, atol=1e-12)


@pytest.mark.parametrize("kind", ELEMENT_KINDS)
def test_drag_keeps_the_shape_of_the_selection(session: EditSession, kind: str) -> None:
    """Every selected element moves by the reference's offset: pairwise differences stay."""
    session.set_deformation(kind, resolution=5, anchor="corners")
    sel = [flat((5, 5, 5), *ijk) for ijk in [(1, 2, 2), (2, 2, 2), (2, 3, 1), (3, 1, 3)]]
    session.select(sel)
    session.set_reference(sel[1])
    cam = camera_for(session.handles(), (35.0, 25.0), "perspective")
    first = drag(session, cam, (-10.0, 6.0))
    second = drag(session, cam, (4.0, 9.0))  # a second drag starts from the held state
    for d in (first, second):
        b, a = d["before"][sel], d["after"][sel]
        assert np.linalg.norm(a - b, axis=1).min() > 1.0
        np.testing.assert_allclose(a - a[1], b - b[1], atol=1e-9)
        np.testing.assert_allclose(a - b, np.broadcast_to(d["delta"], b.shape), atol=1e-9)


@pytest.mark.parametrize("kind", ELEMENT_KINDS)
def test_drag_leaves_fixed_elements_in_the_selection_where_they_are(
    session: EditSession, kind: str
) -> None:
    """A fixed element (a corner, or one fixed by set_fixed) in the selection does not move."""
    session.set_deformation(kind, resolution=5, anchor="corners")
    corner, fixed, free = (flat((5, 5, 5), *ijk) for ijk in [(0, 0, 0), (1, 3, 3), (2, 2, 2)])
    session.set_fixed([fixed], True)
    assert session.fixed_handles()[[corner, fixed, free]].tolist() == [True, True, False]
    session.select([corner, fixed, free])
    cam = camera_for(session.handles(), (35.0, 25.0), "perspective")
    d = drag(session, cam, (8.0, 5.0))
    np.testing.assert_array_equal(d["after"][[corner, fixed]], d["before"][[corner, fixed]])
    np.testing.assert_allclose(d["after"][free] - d["before"][free], d["delta"], atol=1e-9)
    assert np.linalg.norm(d["delta"]) > 1.0
    np.testing.assert_array_equal(
        d["after"][session.fixed_handles()], d["before"][session.fixed_handles()]
    )


def test_begin_drag_without_a_selection_does_nothing(session: EditSession) -> None:
    """No selection: begin_drag returns False and drag_to None; nothing moves."""
    session.set_deformation("massspring", resolution=4)
    cam = camera_for(session.handles(), "+z", "perspective")
    before = session.handles().copy()
    assert session.begin_drag(cam, SIZE, (160, 120)) is False
    assert session.drag_to((200, 100)) is None
    np.testing.assert_array_equal(session.handles(), before)


# ---------------------------------------------------------------------- wires
def wire_session(session: EditSession) -> tuple[EditSession, Camera]:
    session.set_deformation("wires")
    return session, camera_for(session.handles(), "+z", "perspective")


def test_dragging_a_wire_point_moves_only_that_point_and_stales_the_field(
    session: EditSession,
) -> None:
    """Only the dragged control point of the modified wire moves; base stays; field stale."""
    session, cam = wire_session(session)
    assert not session.family.field_stale
    base = session.adapter(WiresFamily).wires[0].base.control_points.copy()
    drawn = session.scene.warps[0]
    session.select([1])
    d = drag(session, cam, (0.0, -25.0))
    moved = np.linalg.norm(d["after"] - d["before"], axis=1)
    assert moved[1] > 1.0
    np.testing.assert_array_equal(np.delete(d["after"], 1, 0), np.delete(d["before"], 1, 0))
    np.testing.assert_allclose(cam.project(d["after"][1], SIZE)[0], d["cursor"], atol=1e-6)
    np.testing.assert_array_equal(
        session.adapter(WiresFamily).wires[0].modified.control_points, d["after"]
    )
    np.testing.assert_array_equal(session.adapter(WiresFamily).wires[0].base.control_points, base)
    assert session.family.field_stale
    assert session.scene.warps == [drawn]  # the old field is drawn until a rebuild


def test_rebuild_wire_field_builds_a_stale_field_here_and_only_then(
    session: EditSession,
) -> None:
    """The same-thread rebuild (scripts, the notebook viewer): a stale field is replaced
    by one of the current wires; a fresh one is left alone."""
    session, cam = wire_session(session)
    fresh = session.scene.warps[0]
    session.family.rebuild_if_stale()
    assert session.scene.warps == [fresh]  # nothing was stale
    session.select([2])
    drag(session, cam, (10.0, 20.0))
    assert session.family.field_stale
    session.family.rebuild_if_stale()
    assert not session.family.field_stale
    (warp,) = session.scene.warps
    assert warp is not fresh
    np.testing.assert_array_equal(
        warp.wires[0].modified.control_points,
        session.adapter(WiresFamily).wires[0].modified.control_points,
    )


def test_wire_build_clears_the_stale_field_and_changes_the_warp(session: EditSession) -> None:
    """A WireBuild after the drag installs a field of the dragged wires in the scene."""
    session, cam = wire_session(session)
    old = session.scene.warps[0]
    session.select([2])
    drag(session, cam, (10.0, 20.0))
    job = session.family.build_job()
    fractions: list[float] = []
    warp = job.run(lambda f, _msg: fractions.append(f))
    assert isinstance(warp, WireFieldWarp)
    assert fractions[-1] == 1.0
    assert session.family.install(job) is True
    assert not session.family.field_stale
    assert session.scene.warps == [warp]
    assert warp is not old
    assert old in session.take_released_warps()
    np.testing.assert_array_equal(
        warp.wires[0].modified.control_points,
        session.adapter(WiresFamily).wires[0].modified.control_points,
    )
    # the new field maps differently from the old one somewhere near the wire
    lo, hi = session.box
    grid = np.stack(np.meshgrid(*(np.linspace(lo[a], hi[a], 24) for a in range(3))), -1)
    pts = grid.reshape(-1, 3)
    assert np.abs(warp.apply(pts) - old.apply(pts)).max() > 1.0


def test_a_build_started_before_a_later_edit_reports_false(session: EditSession) -> None:
    """A build of outdated wires installs (progress while dragging) but returns False and
    leaves the field stale, so another build is due."""
    session, cam = wire_session(session)
    session.select([1])
    drag(session, cam, (0.0, -15.0))
    job = session.family.build_job()
    session.adapter(WiresFamily).set_wire_key(2, twist=0.5)  # an edit after the job was made
    assert job.run() is not None
    assert session.family.install(job) is False
    assert session.family.field_stale
    assert session.scene.warps == [job.warp]
    build_wires(session)
    assert not session.family.field_stale


def test_a_cancelled_build_returns_none_and_is_not_installed(session: EditSession) -> None:
    """cancel() before (or during) run(): run returns None, install returns False, nothing
    changes."""
    session, cam = wire_session(session)
    session.select([1])
    drag(session, cam, (0.0, -15.0))
    drawn = session.scene.warps[0]
    job = session.family.build_job()
    job.cancel()
    assert job.cancelled
    assert job.run() is None
    assert session.family.install(job) is False
    assert session.family.field_stale
    assert session.scene.warps == [drawn]
    # cancelled while it runs (here: from its progress report), the result is dropped too
    late = session.family.build_job()
    assert late.run(lambda f, _msg: late.cancel() if f >= 0.2 else None) is None
    assert session.family.install(late) is False
    assert session.scene.warps == [drawn]


def test_set_wire_key_keys_the_twist_at_the_points_length_fraction(session: EditSession) -> None:
    """The default wire is straight through points at 0.1, 0.37, 0.63, 0.9 of the box:
    point 1 sits at (0.37 - 0.1) / 0.8 of its length; a second key there replaces it."""
    session, _ = wire_session(session)
    session.adapter(WiresFamily).set_wire_key(1, twist=0.7)
    twist = session.adapter(WiresFamily).wires[0].twist
    assert twist.shape == (2, 2)
    np.testing.assert_allclose(twist[0], (0.0, 0.0))
    assert twist[1, 0] == pytest.approx(0.27 / 0.8, abs=1e-3)
    assert twist[1, 1] == 0.7
    assert session.family.field_stale
    session.adapter(WiresFamily).set_wire_key(1, twist=-0.2, scale=1.5)
    wire = session.adapter(WiresFamily).wires[0]
    assert wire.twist.shape == (2, 2)
    assert wire.twist[1, 1] == -0.2
    assert wire.scale[-1, 0] == pytest.approx(0.27 / 0.8, abs=1e-3)
    assert wire.scale[-1, 1] == 1.5
    assert wire.twist_at(0.27 / 0.8) == pytest.approx(-0.2, abs=1e-3)


def test_bad_wire_handle_is_named_in_the_error(session: EditSession) -> None:
    """A handle that is no control point is named in the error."""
    session, _ = wire_session(session)
    with pytest.raises(EditorError, match=r"handle 99 is not a wire control point"):
        session.adapter(WiresFamily).set_wire_key(99, twist=1.0)


def test_laid_points_become_a_wire_in_the_view_plane(session: EditSession) -> None:
    """add_wire_point lays points under the cursor in the plane through the box centre;
    finish_wire makes them a wire whose control points are new handles."""
    session, cam = wire_session(session)
    pixels = np.array([[80.0, 90.0], [160.0, 140.0], [240.0, 100.0]])
    for px in pixels:
        session.adapter(WiresFamily).add_wire_point(cam, SIZE, px)
    assert session.adapter(WiresFamily).finish_wire() == 1
    pts = session.adapter(WiresFamily).wires[1].base.control_points
    np.testing.assert_allclose(cam.project(pts, SIZE), pixels, atol=1e-6)
    centre = 0.5 * (session.box[0] + session.box[1])
    np.testing.assert_allclose((pts - centre) @ cam.rotation[:, 2], 0.0, atol=1e-9)
    assert len(session.handles()) == 4 + 3
    np.testing.assert_array_equal(session.handles()[4:], pts)
    assert session.adapter(WiresFamily).pending_wire == []
    assert session.family.field_stale


@pytest.mark.parametrize(("kind", "laid", "need"), [("catmull-rom", 1, 2), ("bezier", 3, 4)])
def test_finish_wire_with_too_few_points_names_the_count(
    session: EditSession, kind: str, laid: int, need: int
) -> None:
    """Too few laid points: EditorError naming the need and the count; nothing is added."""
    session, cam = wire_session(session)
    for i in range(laid):
        session.adapter(WiresFamily).add_wire_point(cam, SIZE, (100.0 + 30 * i, 120.0))
    with pytest.raises(EditorError, match=rf"at least {need} control points; {laid} laid"):
        session.adapter(WiresFamily).finish_wire(kind)
    assert len(session.adapter(WiresFamily).wires) == 1
    assert len(session.adapter(WiresFamily).pending_wire) == laid


def test_set_wire_settings_rejects_bad_values(session: EditSession) -> None:
    """field_scale outside 1, 2, 4, 8, 16 and unknown settings raise; settings stay."""
    session, _ = wire_session(session)
    with pytest.raises(EditorError, match=r"field_scale must be 1, 2, 4, 8 or 16; got 3"):
        session.adapter(WiresFamily).set_wire_settings(field_scale=3)
    with pytest.raises(EditorError, match=r"unknown wire settings \['resolution'\]"):
        session.adapter(WiresFamily).set_wire_settings(resolution=3)
    assert session.options.wire_settings == {"field_scale": 2}
    assert not session.family.field_stale
    session.adapter(WiresFamily).set_wire_settings(field_scale=4, layout="packed")
    assert session.family.field_stale
    warp = build_wires(session)
    assert (warp.deformer.field_scale, warp.deformer.layout) == (4, "packed")


def test_set_wire_settings_rejects_a_bad_layout(session: EditSession) -> None:
    """layout must be 'float' or 'packed' (the docstring's values), checked at once."""
    session, _ = wire_session(session)
    with pytest.raises(EditorError, match="layout"):
        session.adapter(WiresFamily).set_wire_settings(layout="bogus")


# ---------------------------------------------------------------------- lattice
def test_dragging_a_lattice_node_moves_only_it_and_the_warp_maps_its_rest_there(
    session: EditSession,
) -> None:
    """Only the dragged node moves; the LatticeWarp's forward map takes the node's rest
    position to its new position (and its inverse takes it back)."""
    session.set_deformation("lattice", resolution=4)  # 3 cells, 4 nodes per axis
    node = flat((4, 4, 4), 1, 2, 1)
    rest = session.handles().copy()
    session.select([node])
    cam = camera_for(rest, (35.0, 25.0), "perspective")
    d = drag(session, cam, (6.0, -4.0))  # small enough not to fold the lattice
    assert np.linalg.norm(d["after"][node] - rest[node]) > 3.0
    np.testing.assert_array_equal(np.delete(d["after"], node, 0), np.delete(rest, node, 0))
    (warp,) = session.scene.warps
    assert isinstance(warp, LatticeWarp)
    assert not warp.is_affine
    np.testing.assert_allclose(warp.forward(rest[node]), d["after"][[node]], atol=1e-9)
    np.testing.assert_allclose(warp.forward(rest[:5]), rest[:5], atol=1e-9)  # others: rest
    # unfolded, the inverse takes the node back to its rest place
    assert not warp.grid.folds()
    np.testing.assert_allclose(warp.apply(d["after"][[node]]), rest[[node]], atol=1e-3)


# ---------------------------------------------------------------------- placement
def test_placed_handles_are_the_placement_matrix_times_the_grid(session: EditSession) -> None:
    """With a Placement the handles are M @ grid positions and the chain has 3 warps."""
    session.set_deformation("massspring", resolution=4)
    grid = session.handles().copy()
    session.set_placement(PLACEMENT)
    lo, hi = session.box
    m = PLACEMENT.matrix(0.5 * (lo + hi))
    np.testing.assert_allclose(session.placement_matrix, m)
    np.testing.assert_allclose(session.handles(), grid @ m[:3, :3].T + m[:3, 3], atol=1e-12)
    warps = session.scene.warps
    assert len(warps) == 3
    assert isinstance(warps[0], AffineWarp)
    assert isinstance(warps[1], OffsetFieldWarp)
    assert isinstance(warps[2], AffineWarp)
    np.testing.assert_allclose(warps[0].forward_matrix, m)
    # the placement is rotation and scale about the box centre, then the translation
    np.testing.assert_allclose(
        m[:3, :3] @ (0.5 * (lo + hi)) + m[:3, 3], 0.5 * (lo + hi) + PLACEMENT.translate
    )
    np.testing.assert_allclose(
        np.linalg.svd(m[:3, :3], compute_uv=False), sorted(PLACEMENT.scale, reverse=True)
    )


def test_placed_chain_is_the_identity_outside_the_placed_grid(session: EditSession) -> None:
    """[placement^-1, lattice, placement] maps points outside the placed grid to themselves
    and moves points inside it."""
    session.set_deformation("lattice", resolution=4)
    session.set_placement(PLACEMENT)
    node = flat((4, 4, 4), 2, 1, 2)
    session.select([node])
    cam = camera_for(session.handles(), (35.0, 25.0), "perspective")
    d = drag(session, cam, (-5.0, 3.0))
    assert not session.scene.warps[1].grid.folds()
    lo, hi = session.box
    m = session.placement_matrix
    rng = np.random.default_rng(4)
    u = rng.uniform(-0.5, 1.5, size=(400, 3))
    u = u[np.any((u < -0.02) | (u > 1.02), axis=1)]  # outside the grid's box
    outside = (lo + u * (hi - lo)) @ m[:3, :3].T + m[:3, 3]
    np.testing.assert_allclose(chain_apply(session.scene.warps, outside), outside, atol=1e-9)
    # inside, the chain deforms: the dragged node shows the content of its rest place
    assert np.linalg.norm(d["after"][node] - d["before"][node]) > 3.0
    seen = chain_apply(session.scene.warps, d["after"][[node]])
    np.testing.assert_allclose(seen, d["before"][[node]], atol=1e-3)


@pytest.mark.parametrize("kind", ["massspring", "lattice"])
def test_placed_drag_moves_the_handle_by_the_world_delta(session: EditSession, kind: str) -> None:
    """Under a rotated, scaled placement the reference still follows the cursor in world."""
    session.set_deformation(kind, resolution=4)
    session.set_placement(PLACEMENT)
    ref = flat((4, 4, 4), 1, 2, 2)
    session.select([ref])
    cam = camera_for(session.handles(), (-60.0, 30.0), "perspective")
    d = drag(session, cam, (11.0, 7.0))
    np.testing.assert_allclose(d["after"][ref] - d["before"][ref], d["delta"], atol=1e-9)
    assert d["delta"] @ cam.rotation[:, 2] == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(cam.project(d["after"][ref], SIZE)[0], d["cursor"], atol=1e-6)


# ---------------------------------------------------------------------- snapshots
def scene_edit(session: EditSession) -> None:
    """Change the scene's look."""
    session.scene.mode = "mip"
    session.scene.transfer_function = TransferFunction.preset("hot", session.volume)
    session.scene.step = 0.5


@pytest.mark.parametrize("kind", FAMILIES)
def test_restore_returns_to_the_snapshot_exactly(session: EditSession, kind: str) -> None:
    """restore(snapshot()) after further edits gives back the same state and handles."""
    deform_family(session, kind)
    session.set_placement(Placement(rotate=(0.0, 0.0, 10.0)))
    snap = session.snapshot()
    handles = session.handles().copy()
    warps = len(session.scene.warps)
    # further edits of every kind
    cam = camera_for(session.handles(), "-y", "orthographic")
    session.select([0, 3])
    session.set_reference(3)
    drag(session, cam, (6.0, 9.0))
    session.set_placement(Placement(translate=(2.0, 0.0, 0.0)))
    session.set_option("steps_per_frame", 3)
    session.advance()
    if kind == "wires":
        session.adapter(WiresFamily).set_wire_key(2, twist=0.3)
    scene_edit(session)
    assert not session.snapshot().same_as(snap)
    session.restore(snap)
    assert session.snapshot().same_as(snap)
    np.testing.assert_array_equal(session.handles(), handles)
    assert len(session.scene.warps) == warps
    assert (session.selection, session.kind) == (list(snap.selection), kind)
    if kind == "wires":
        assert not session.family.field_stale
        np.testing.assert_array_equal(
            session.scene.warps[1].wires[0].modified.control_points,
            session.adapter(WiresFamily).wires[0].modified.control_points,
        )


def test_restore_brings_back_mass_spring_velocities_exactly(session: EditSession) -> None:
    """Step the model, snapshot, step more, restore: positions and velocities as before."""
    session.set_deformation("massspring", resolution=5)
    session.select([flat((5, 5, 5), 2, 2, 3)])
    drag(session, camera_for(session.handles(), "+x", "perspective"), (20.0, -10.0))
    assert isinstance(session.model, MassSpring)
    session.model.step(7)
    snap = session.snapshot()
    v, x = session.model.velocities(), session.model.positions()
    assert np.abs(v).max() > 0
    session.model.step(9)
    assert not np.array_equal(session.model.velocities(), v)
    session.restore(snap)
    assert isinstance(session.model, MassSpring)
    np.testing.assert_array_equal(session.model.velocities(), v)
    np.testing.assert_array_equal(session.model.positions(), x)
    # and the dynamics continue the same way from there
    session.model.step(5)
    v5 = session.model.velocities()
    session.restore(snap)
    session.model.step(5)
    np.testing.assert_array_equal(session.model.velocities(), v5)


def test_the_scene_look_is_part_of_the_snapshot(session: EditSession) -> None:
    """Mode, transfer function, sample distance, window and clip box come back on restore."""
    session.set_deformation("lattice", resolution=3)
    tf = session.scene.transfer_function
    snap = session.snapshot()
    scene_edit(session)
    session.scene.window = (100.0, 50.0)
    session.scene.clip_box = ((0, 0, 0), (10, 10, 10))
    assert not session.snapshot().same_as(snap)
    session.restore(snap)
    assert session.scene.mode == "dvr"
    assert session.scene.transfer_function is tf
    assert session.scene.step == 1.0
    assert session.scene._window is None
    assert session.scene.clip_box is None
    assert session.snapshot().same_as(snap)


def test_restore_rebuilds_the_wire_field_with_the_restored_settings(
    session: EditSession,
) -> None:
    """Undoing a change of field_scale draws a field of the restored field_scale."""
    session.set_deformation("wires")
    snap = session.snapshot()
    session.adapter(WiresFamily).set_wire_settings(field_scale=4)
    build_wires(session)
    session.restore(snap)
    assert session.options.wire_settings["field_scale"] == 2
    assert session.scene.warps[0].deformer.field_scale == 2


# ---------------------------------------------------------------------- files
@pytest.mark.parametrize("placed", [False, True])
@pytest.mark.parametrize("kind", FAMILIES)
def test_save_and_load_round_trip(
    session: EditSession, tmp_path: Path, kind: str, placed: bool
) -> None:
    """save then load: kind, placement, wire settings and handles come back; the file is
    scene JSON that Scene.load reads (so `voxwarp render` renders it)."""
    if kind == "wires":
        session.options.wire_settings = {"field_scale": 4}  # set before the first build
    deform_family(session, kind)
    if placed:
        session.set_placement(PLACEMENT)
    path = session.save(tmp_path / "edit.json")
    raw = json.loads(path.read_text(encoding="utf-8"))
    assert raw["format"] == "voxwarp-scene"
    assert raw["editor"]["deformation"] == kind
    assert raw["editor"]["placement"] == session.placement.to_dict()
    assert raw["volume"]["sample"] == "fish"
    scene = Scene.load(path)
    assert len(scene.warps) == (3 if placed else 1)
    loaded = EditSession.load(path)
    assert loaded.kind == kind
    assert loaded.placement == session.placement
    assert (
        loaded.options.wire_settings["field_scale"] == session.options.wire_settings["field_scale"]
    )
    assert loaded.handles().shape == session.handles().shape
    np.testing.assert_allclose(loaded.handles(), session.handles(), atol=1e-6)
    np.testing.assert_array_equal(loaded.fixed_handles(), session.fixed_handles())
    assert [type(w) for w in loaded.scene.warps] == [type(w) for w in session.scene.warps]
    assert not loaded.family.field_stale


def test_saving_with_a_stale_wire_field_keeps_the_edit(
    session: EditSession, tmp_path: Path
) -> None:
    """A wire dragged but not yet rebuilt is saved where it was dragged."""
    session, cam = wire_session(session)
    session.select([1])
    drag(session, cam, (0.0, -25.0))
    assert session.family.field_stale
    loaded = EditSession.load(session.save(tmp_path / "w.json"))
    np.testing.assert_allclose(loaded.handles(), session.handles(), atol=1e-6)


def test_loading_keeps_the_lattice_resolution(session: EditSession, tmp_path: Path) -> None:
    """A lattice of resolution 4 saved and loaded resets to the same 4x4x4 nodes."""
    session.set_deformation("lattice", resolution=4)
    loaded = EditSession.load(session.save(tmp_path / "l.json"))
    assert loaded.resolution == (4, 4, 4)
    loaded.reset_model()
    assert loaded.handles().shape == (64, 3)


def test_loading_keeps_the_placement_without_a_deformation(
    session: EditSession, tmp_path: Path
) -> None:
    """A session without deformation keeps its saved placement and model settings."""
    session.set_deformation("none", resolution=6, stiffness=0.8)
    session.set_placement(PLACEMENT)
    loaded = EditSession.load(session.save(tmp_path / "n.json"))
    assert loaded.kind == "none"
    assert loaded.placement == PLACEMENT
    assert (loaded.resolution, loaded.options.stiffness) == ((6, 6, 6), 0.8)


def test_save_creates_missing_folders_and_a_failed_save_keeps_the_old_file(
    session: EditSession, tmp_path: Path
) -> None:
    """Missing folders are created (as Scene.save does); a save that fails raises, leaves
    no temporary file and keeps the previous file; a folder in the way raises OSError."""
    session.set_deformation("lattice", resolution=3)
    path = session.save(tmp_path / "new" / "dir" / "s.json")
    assert EditSession.load(path).kind == "lattice"
    old = path.read_text(encoding="utf-8")
    # an in-memory volume too large to embed cannot be saved
    big = EditSession(
        Scene(Volume(np.zeros((210, 210, 210), np.uint8)), transfer_function="grayscale")
    )
    with pytest.raises(SceneError, match="too large to embed"):
        big.save(path)
    assert path.read_text(encoding="utf-8") == old
    assert sorted(p.name for p in path.parent.iterdir()) == ["s.json"]
    # a file where a folder should be, and a folder where the file should be
    blocker = tmp_path / "blocker"
    blocker.write_text("x", encoding="utf-8")
    with pytest.raises(OSError, match="blocker"):
        session.save(blocker / "s.json")
    (tmp_path / "taken.json").mkdir()
    with pytest.raises(OSError, match=r"taken\.json"):
        session.save(tmp_path / "taken.json")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["blocker", "new", "taken.json"]
    assert list((tmp_path / "taken.json").iterdir()) == []


def test_a_scene_with_an_unsupported_warp_is_refused(volume: Volume, tmp_path: Path) -> None:
    """An AffineWarp alone is no model: EditSession and EditSession.load name it."""
    scene = Scene(volume, warps=[AffineWarp.translation((1.0, 2.0, 3.0))])
    with pytest.raises(EditorError, match=r"'affine' warp is not editable"):
        EditSession(scene)
    path = scene.save(tmp_path / "affine.json")
    with pytest.raises(EditorError, match=r"'affine' warp is not editable"):
        EditSession.load(path)
    two = Scene(volume, warps=[AffineWarp.translation((1.0, 0, 0))] * 2)
    with pytest.raises(EditorError, match="the scene has 2 warps"):
        EditSession(two)


# ---------------------------------------------------------------------- set_deformation
@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"kind": "springs"}, "deformation must be one of none, massspring, chainmail, wires, la"),
        ({"backend": "cuda"}, "backend must be one of cpu, gpu; got 'cuda'"),
        ({"resolution": 1}, r"2\.\.64 elements per axis here; got \(1, 1, 1\)"),
        ({"resolution": (4, 65, 4)}, r"2\.\.64 elements per axis here; got \(4, 65, 4\)"),
        ({"resolution": "big"}, "grid resolution must be 1 or 3 integers"),
        ({"integrator": "rk4"}, "integrator must be one of semi-implicit, explicit"),
        ({"variant": "fast"}, "variant must be one of enhanced, gibson"),
        ({"stiffness": 0.0}, r"stiffness must be in \(0, 1\]"),
        ({"colour": "red"}, "unknown deformation settings: colour"),
        ({"backend": "gpu"}, "GPU backend needs the viewport's OpenGL context"),
    ],
)
def test_refused_settings_name_the_allowed_values_and_keep_the_model(
    session: EditSession, settings: dict[str, Any], message: str
) -> None:
    """A bad setting raises EditorError naming what is allowed; the model stays."""
    session.set_deformation("massspring", resolution=4)
    model, warps = session.model, list(session.scene.warps)
    state = (session.kind, session.backend, session.resolution, session.options.stiffness)
    kind = settings.pop("kind", "chainmail")
    with pytest.raises(EditorError, match=message):
        session.set_deformation(kind, **settings)
    assert session.model is model
    assert session.scene.warps == warps
    assert (session.kind, session.backend, session.resolution, session.options.stiffness) == state


class OldContext:
    """Stands for an OpenGL 4.1 context (macOS): too old for the GPU solvers."""

    version_code = 410


@pytest.mark.parametrize("kind", ELEMENT_KINDS)
def test_a_gpu_model_the_context_cannot_run_is_refused(volume: Volume, kind: str) -> None:
    """The GPU solver refuses the context: EditorError; kind, backend, model unchanged."""
    session = EditSession(Scene(volume), ctx=OldContext())
    session.set_deformation("massspring", resolution=4)
    model = session.model
    with pytest.raises(EditorError, match=r"OpenGL 4\.3"):
        session.set_deformation(kind, backend="gpu", resolution=6)
    assert session.model is model
    assert (session.kind, session.backend, session.resolution) == ("massspring", "cpu", (4,) * 3)
    assert session.scene.warps == [model.warp()]


def test_a_refused_gpu_model_keeps_the_stiffness(volume: Volume) -> None:
    """The stiffness of the refused model is not taken over either."""
    session = EditSession(Scene(volume), ctx=OldContext())
    session.set_deformation("massspring", resolution=4, stiffness=0.5)
    with pytest.raises(EditorError):
        session.set_deformation("chainmail", backend="gpu", stiffness=0.9)
    assert session.options.stiffness == 0.5


def test_a_non_numeric_stiffness_is_an_editor_error(session: EditSession) -> None:
    """stiffness='soft' raises EditorError naming stiffness."""
    with pytest.raises(EditorError, match="stiffness"):
        session.set_deformation("massspring", stiffness="soft")


# ---------------------------------------------------------------------- overlay
@pytest.mark.parametrize(
    ("kind", "expected", "toggles"),
    [
        (
            "massspring",
            ["grid box", "links", "elements", "fixed"],
            {"links": ["links"], "elements": ["elements"], "fixed": ["fixed"]},
        ),
        (
            "chainmail",
            ["grid box", "links", "elements", "fixed"],
            {"links": ["links"], "elements": ["elements"], "fixed": ["fixed"]},
        ),
        (
            "wires",
            ["grid box", "base", "wire", "points"],
            {"wires_base": ["base"], "wires_modified": ["wire", "points"]},
        ),
        ("lattice", ["grid box", "cells", "nodes"], {"lattice_cells": ["cells", "nodes"]}),
    ],
)
def test_overlay_layers_per_family_and_their_toggles(
    session: EditSession, kind: str, expected: list[str], toggles: dict[str, list[str]]
) -> None:
    """Each family draws its layers; each DisplayOptions field removes exactly its layers."""
    session.set_deformation(kind, resolution=4, anchor="corners")
    assert layer_names(session) == expected
    for option, gone in {**toggles, "grid_box": ["grid box"]}.items():
        assert layer_names(session, **{option: False}) == [n for n in expected if n not in gone]
    layers = {layer.name: layer for layer in session.overlay_layers()}
    pts = session.handles()
    if kind in ELEMENT_KINDS:
        fixed = session.fixed_handles()
        assert fixed.sum() == 8  # the corners
        np.testing.assert_array_equal(layers["elements"].positions, pts[~fixed])
        np.testing.assert_array_equal(layers["fixed"].positions, pts[fixed])
    elif kind == "wires":
        np.testing.assert_array_equal(layers["points"].positions, pts)
    else:
        np.testing.assert_array_equal(layers["nodes"].positions, pts)


def test_no_deformation_draws_nothing(session: EditSession) -> None:
    """Without a deformation there is no handle, no grid box and no layer."""
    assert session.kind == "none"
    assert session.overlay_layers() == []
    assert session.handles().shape == (0, 3)


@pytest.mark.parametrize("kind", FAMILIES)
def test_selected_handles_are_drawn_at_their_positions(session: EditSession, kind: str) -> None:
    """The 'selected' layer holds the selected handles, 'ref' the reference; both toggle."""
    session.set_deformation(kind, resolution=4)
    session.set_placement(PLACEMENT)
    session.select([3, 1])
    session.select([2], "add")
    session.set_reference(1)
    layers = {layer.name: layer for layer in session.overlay_layers()}
    pts = session.handles()
    np.testing.assert_array_equal(layers["selected"].positions, pts[[3, 1, 2]])
    np.testing.assert_array_equal(layers["ref"].positions, pts[[1]])
    names = layer_names(session, selection=False)
    assert "selected" not in names
    assert "ref" not in names
    session.select([], "replace")
    assert "selected" not in layer_names(session)
