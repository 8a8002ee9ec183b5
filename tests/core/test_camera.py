"""Tests of voxwarp.core.camera: standard views, fitting, projection, orbit / zoom / pan, JSON.

Pure CPU. Oracles: geometric facts (a standard view's back axis points to its side,
right x up = back, rotations are proper), the pixel mapping of the documented
conventions (origin top-left, y down) and closed-form pan offsets.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

from voxwarp.core.camera import PROJECTIONS, VIEWS, Camera, view_rotation
from voxwarp.errors import SceneError

SIDES = {
    "+x": (1, 0, 0),
    "-x": (-1, 0, 0),
    "+y": (0, 1, 0),
    "-y": (0, -1, 0),
    "+z": (0, 0, 1),
    "-z": (0, 0, -1),
}


def assert_proper_rotation(r: np.ndarray, atol: float = 1e-12) -> None:
    np.testing.assert_allclose(r.T @ r, np.eye(3), atol=atol)
    assert np.linalg.det(r) == pytest.approx(1.0, abs=atol)


# ---------------------------------------------------------------------- standard views
def test_views_are_the_six_sides() -> None:
    assert set(VIEWS) == set(SIDES)


@pytest.mark.parametrize("view", list(SIDES))
def test_standard_view_back_axis_points_to_its_side(view: str) -> None:
    r = view_rotation(view)
    right, up, back = r[:, 0], r[:, 1], r[:, 2]
    np.testing.assert_array_equal(back, SIDES[view])
    np.testing.assert_allclose(np.cross(right, up), back, atol=1e-15)
    assert_proper_rotation(r)
    # the eye of a camera with this view sits on that side of the centre
    cam = Camera(center=(1, 2, 3), rotation=r, distance=10)
    np.testing.assert_allclose(cam.eye, np.array([1, 2, 3]) + 10 * np.array(SIDES[view]))


@pytest.mark.parametrize("view", ["+x", "-x", "+y", "-y"])
def test_side_views_keep_z_up(view: str) -> None:
    np.testing.assert_array_equal(view_rotation(view)[:, 1], (0, 0, 1))


def test_z_views_have_y_up_and_documented_right_axis() -> None:
    np.testing.assert_array_equal(view_rotation("+z")[:, :2], [[1, 0], [0, 1], [0, 0]])
    np.testing.assert_array_equal(view_rotation("-z")[:, :2], [[-1, 0], [0, 1], [0, 0]])


@pytest.mark.parametrize(
    ("angles", "view"),
    [((0, 0), "+x"), ((90, 0), "+y"), ((180, 0), "-x"), ((-90, 0), "-y"), ((270, 0), "-y")],
)
def test_azimuth_elevation_matches_standard_views(angles: tuple[float, float], view: str) -> None:
    np.testing.assert_allclose(view_rotation(angles), view_rotation(view), atol=1e-12)


@pytest.mark.parametrize("az", [0.0, 37.0, 123.0, -80.0])
@pytest.mark.parametrize("el", [-89.9, -45.0, 0.0, 20.0, 60.0, 89.99, 90.0, -90.0])
def test_azimuth_elevation_rotation_is_proper_with_the_right_back_axis(
    az: float, el: float
) -> None:
    r = view_rotation((az, el))
    assert_proper_rotation(r)
    a, e = np.radians(az), np.radians(el)
    expected_back = [np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)]
    np.testing.assert_allclose(r[:, 2], expected_back, atol=1e-12)
    np.testing.assert_allclose(np.cross(r[:, 0], r[:, 1]), r[:, 2], atol=1e-12)
    if abs(el) < 89:
        assert abs(r[2, 0]) < 1e-12, "the right axis stays horizontal"
        assert r[2, 1] > 0, "world +z points up on screen"


@pytest.mark.parametrize(
    ("view", "pattern"),
    [
        ("top", "unknown view"),
        ("x", "unknown view"),
        ((1.0, 2.0, 3.0), "azimuth, elevation"),
        (("a", "b"), "azimuth, elevation"),
        (5, "azimuth, elevation"),
        ((float("nan"), 0.0), "finite"),
        ((0.0, float("inf")), "finite"),
    ],
)
def test_bad_views_raise_scene_error(view: Any, pattern: str) -> None:
    with pytest.raises(SceneError, match=pattern) as info:
        view_rotation(view)
    if isinstance(view, str):
        for name in VIEWS:
            assert name in str(info.value)


# ---------------------------------------------------------------------- fitting
BOXES = [
    ((0, 0, 0), (10, 10, 10)),
    ((-5, 2, 100), (45, 8, 130)),  # flat, off-centre
    ((0, 0, 0), (1, 1, 300)),  # a needle
    ((-3.5, -1e-3, -7), (2.25, 1e-3, 9)),  # a sheet
]
VIEW_CHOICES = [*SIDES, (30.0, 20.0), (-135.0, 70.0), (10.0, -89.0)]


def box_corners(lo: Any, hi: Any) -> np.ndarray:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return np.array(
        [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    )


@pytest.mark.parametrize("projection", PROJECTIONS)
@pytest.mark.parametrize("view", VIEW_CHOICES)
@pytest.mark.parametrize("box", BOXES)
@pytest.mark.parametrize("size", [(64, 64), (320, 200)])
def test_fit_keeps_all_box_corners_inside_the_image(
    projection: str, view: Any, box: Any, size: tuple[int, int]
) -> None:
    lo, hi = box
    cam = Camera.fit(lo, hi, view=view, projection=projection, fov=35.0)
    px = cam.project(box_corners(lo, hi), size)
    w, h = size
    assert np.all(np.isfinite(px))
    assert np.all((px[:, 0] >= 0) & (px[:, 0] <= w)), px
    assert np.all((px[:, 1] >= 0) & (px[:, 1] <= h)), px
    # corners lie in front of the camera and between the near and far planes
    depth = (cam.eye - box_corners(lo, hi)) @ cam.rotation[:, 2]
    near, far = cam.near_far()
    assert np.all(depth > near)
    assert np.all(depth < far)


@pytest.mark.parametrize("projection", PROJECTIONS)
def test_fit_fills_a_good_part_of_the_image(projection: str) -> None:
    lo, hi = (0, 0, 0), (20, 20, 20)
    cam = Camera.fit(lo, hi, view="+z", projection=projection)
    px = cam.project(box_corners(lo, hi), (100, 100))
    extent = px.max(axis=0) - px.min(axis=0)
    assert extent.min() > 40, "the fitted box should not be a speck"


@pytest.mark.parametrize("projection", PROJECTIONS)
def test_fit_zoom_magnifies(projection: str) -> None:
    lo, hi = (0, 0, 0), (20, 10, 5)
    c1 = Camera.fit(lo, hi, view="-y", projection=projection)
    c2 = Camera.fit(lo, hi, view="-y", projection=projection, zoom=2.0)
    assert c2.distance == pytest.approx(c1.distance / 2)
    assert c2.ortho_height == pytest.approx(c1.ortho_height / 2)
    np.testing.assert_allclose(c1.center, [10, 5, 2.5])


@pytest.mark.parametrize("projection", PROJECTIONS)
@pytest.mark.parametrize("size", [(64, 64), (101, 37)])
def test_project_of_the_centre_is_the_image_centre(projection: str, size: tuple) -> None:
    cam = Camera.fit((-4, 0, 3), (10, 7, 9), view=(40.0, 25.0), projection=projection)
    px = cam.project(cam.center, size)
    np.testing.assert_allclose(px, [[size[0] / 2, size[1] / 2]], atol=1e-9)


def test_project_screen_orientation_for_plus_z() -> None:
    """+z view: +x is right and +y up, so y grows upward = smaller pixel rows."""
    cam = Camera.fit((-1, -1, -1), (1, 1, 1), view="+z", projection="orthographic")
    c, right, up = cam.project(np.array([[0, 0, 0], [0.5, 0, 0], [0, 0.5, 0]]), (100, 100))
    assert right[0] > c[0]
    assert right[1] == pytest.approx(c[1])
    assert up[1] < c[1]
    assert up[0] == pytest.approx(c[0])


def test_view_projection_maps_to_clip_space_consistently() -> None:
    cam = Camera.fit((0, 0, 0), (10, 20, 30), view=(15.0, 35.0))
    vp = cam.view_projection(1.5)
    pts = np.random.default_rng(0).uniform(0, 10, (20, 3))
    clip = np.c_[pts, np.ones(20)] @ vp.T
    ndc = clip[:, :3] / clip[:, 3:]
    assert np.all(np.abs(ndc) <= 1 + 1e-9), "points inside the fitted box are inside the frustum"
    # the view matrix is a rigid transform taking the eye to the origin
    v = cam.view_matrix()
    np.testing.assert_allclose(v @ np.r_[cam.eye, 1], [0, 0, 0, 1], atol=1e-9)
    np.testing.assert_allclose(v[:3, :3] @ v[:3, :3].T, np.eye(3), atol=1e-12)


# ---------------------------------------------------------------------- interaction
@pytest.mark.parametrize("steps", [1, 4, 12, 360])
def test_orbit_full_turn_in_azimuth_returns(steps: int) -> None:
    cam = Camera.fit((0, 0, 0), (10, 10, 10), view=(20.0, 30.0))
    start = cam.rotation.copy()
    for _ in range(steps):
        cam.orbit(360.0 / steps, 0.0)
    np.testing.assert_allclose(cam.rotation, start, atol=1e-9)


@pytest.mark.parametrize("steps", [1, 3, 24])
def test_orbit_full_turn_in_elevation_returns(steps: int) -> None:
    cam = Camera.fit((0, 0, 0), (10, 10, 10), view="-y")
    start = cam.rotation.copy()
    for _ in range(steps):
        cam.orbit(0.0, 360.0 / steps)
    np.testing.assert_allclose(cam.rotation, start, atol=1e-9)


def test_orbit_keeps_orthonormality_and_the_centre() -> None:
    cam = Camera.fit((0, 0, 0), (10, 20, 30), view="+x")
    center = cam.center.copy()
    distance = cam.distance
    rng = np.random.default_rng(5)
    for _ in range(2000):
        cam.orbit(*rng.uniform(-40, 40, 2))
    assert_proper_rotation(cam.rotation, atol=1e-12)
    np.testing.assert_array_equal(cam.center, center)
    assert cam.distance == distance
    assert np.linalg.norm(cam.eye - center) == pytest.approx(distance)


def test_orbit_azimuth_turns_about_the_up_axis() -> None:
    cam = Camera(rotation=view_rotation("-y"))
    cam.orbit(90.0, 0.0)
    up = cam.rotation[:, 1]
    np.testing.assert_allclose(up, [0, 0, 1], atol=1e-12)  # up is unchanged
    # a quarter turn moves the camera from the -y side to a +-x side
    assert abs(abs(cam.rotation[0, 2]) - 1) < 1e-12
    cam.orbit(-90.0, 0.0)
    np.testing.assert_allclose(cam.rotation, view_rotation("-y"), atol=1e-12)


def test_orbit_elevation_tilts_the_back_axis_upward() -> None:
    cam = Camera(rotation=view_rotation("-y"))
    cam.orbit(0.0, 30.0)
    back = cam.rotation[:, 2]
    assert abs(back[2]) == pytest.approx(np.sin(np.radians(30)), abs=1e-12)
    np.testing.assert_allclose(cam.rotation[:, 0], [1, 0, 0], atol=1e-12)  # right unchanged


@pytest.mark.parametrize("projection", PROJECTIONS)
def test_zoom_halves_distance_and_ortho_height(projection: str) -> None:
    cam = Camera.fit((0, 0, 0), (10, 10, 10), projection=projection)
    d, h = cam.distance, cam.ortho_height
    cam.zoom(2.0)
    assert cam.distance == pytest.approx(d / 2)
    assert cam.ortho_height == pytest.approx(h / 2)
    cam.zoom(0.5)
    assert cam.distance == pytest.approx(d)
    assert cam.ortho_height == pytest.approx(h)


@pytest.mark.parametrize("factor", [0.0, -1.0])
def test_zoom_rejects_non_positive_factors(factor: float) -> None:
    cam = Camera()
    with pytest.raises(SceneError, match="positive"):
        cam.zoom(factor)
    assert cam.distance == 100.0


@pytest.mark.parametrize("projection", PROJECTIONS)
@pytest.mark.parametrize(("dx", "dy"), [(0.1, 0.0), (0.0, -0.25), (0.2, 0.3)])
def test_pan_moves_the_centre_along_screen_axes(projection: str, dx: float, dy: float) -> None:
    cam = Camera.fit((0, 0, 0), (10, 20, 30), view=(50.0, 10.0), projection=projection)
    old_center = cam.center.copy()
    rot = cam.rotation.copy()
    cam.pan(dx, dy)
    move = cam.center - old_center
    # along right and up only, never along the view direction
    assert move @ rot[:, 2] == pytest.approx(0.0, abs=1e-12)
    if projection == "perspective":
        visible = 2 * cam.distance * np.tan(np.radians(cam.fov) / 2)
    else:
        visible = cam.ortho_height
    assert move @ rot[:, 0] == pytest.approx(dx * visible, abs=1e-12)
    assert move @ rot[:, 1] == pytest.approx(dy * visible, abs=1e-12)
    np.testing.assert_array_equal(cam.rotation, rot)
    # the old centre now appears shifted by (dx, dy) image heights against the pan
    w, h = 300, 200
    px = cam.project(old_center, (w, h))[0]
    np.testing.assert_allclose(px, [w / 2 - dx * h, h / 2 + dy * h], atol=1e-6)


# ---------------------------------------------------------------------- validation, JSON
@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"projection": "fisheye"}, "perspective, orthographic"),
        ({"fov": 0.0}, "fov"),
        ({"fov": -10.0}, "fov"),
        ({"fov": 179.0}, "fov"),
        ({"fov": 250.0}, "fov"),
        ({"distance": 0.0}, "positive"),
        ({"ortho_height": -1.0}, "positive"),
        ({"radius": 0.0}, "positive"),
    ],
)
def test_invalid_camera_raises_scene_error(kwargs: dict[str, Any], pattern: str) -> None:
    with pytest.raises(SceneError, match=pattern):
        Camera(**kwargs)


def test_fit_with_bad_arguments_raises_scene_error() -> None:
    with pytest.raises(SceneError, match="projection"):
        Camera.fit((0, 0, 0), (1, 1, 1), projection="fisheye")
    with pytest.raises(SceneError, match="view"):
        Camera.fit((0, 0, 0), (1, 1, 1), view="top")


@pytest.mark.parametrize("projection", PROJECTIONS)
def test_to_dict_from_dict_round_trip(projection: str) -> None:
    cam = Camera.fit((-1, 2, -3), (4, 9, 6), view=(12.0, 34.0), projection=projection, fov=25.0)
    cam.orbit(17.0, -8.0)
    cam.pan(0.1, 0.05)
    cam.zoom(1.3)
    d = json.loads(json.dumps(cam.to_dict()))
    back = Camera.from_dict(d)
    np.testing.assert_array_equal(back.center, cam.center)
    np.testing.assert_array_equal(back.rotation, cam.rotation)
    for key in ("distance", "fov", "projection", "ortho_height", "radius"):
        assert getattr(back, key) == getattr(cam, key)
    np.testing.assert_array_equal(back.view_projection(1.25), cam.view_projection(1.25))


def test_from_dict_rejects_unknown_keys_and_bad_values() -> None:
    assert Camera.from_dict({"distance": 5.0}).distance == 5.0
    with pytest.raises(SceneError, match=r"unknown camera key 'comment'.*center, rotation"):
        Camera.from_dict({"distance": 5.0, "comment": "hello"})
    for bad in ({"center": "here"}, {"rotation": [1, 2]}, {"fov": "wide"}, {"distance": None}):
        with pytest.raises(SceneError, match=r"camera|fov|positive"):
            Camera.from_dict(bad)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"distance": float("nan")},
        {"ortho_height": float("nan")},
        {"rotation": np.diag([2.0, 1.0, 1.0])},
        {"rotation": np.zeros((3, 3))},
    ],
)
def test_camera_rejects_nan_lengths_and_non_rotations(kwargs: dict[str, Any]) -> None:
    with pytest.raises(SceneError):
        Camera(**kwargs)


@pytest.mark.parametrize("size", [(400, 200), (200, 400), (300, 300)])
def test_framing_fills_the_image_width_or_height(size: tuple[int, int]) -> None:
    """Camera.framing: the box's projected extent reaches ``fill`` of the image in one
    direction (the tighter one) and stays inside it in the other."""
    lo, hi = np.array([0.0, 0.0, 0.0]), np.array([120.0, 40.0, 60.0])
    cam = Camera.framing(lo, hi, (-60.0, 20.0), size, fill=0.9)
    corners = np.array([[x, y, z] for x in (0, 120) for y in (0, 40) for z in (0, 60)], float)
    xy = cam.project(corners, size)
    centre = np.array(size) / 2
    reach = np.abs(xy - centre).max(axis=0) / (np.array(size) / 2)
    assert reach.max() == pytest.approx(0.9, abs=1e-3)
    assert np.all(reach <= 0.9 + 1e-3)
