"""SlicePlane geometry (no GL): radiological layout, pixel <-> world, moving, oblique
planes, the command line's plane syntax, orientation letters, pixel fitting, and the
plane's camera, which ties a slice view's pixels to picking and dragging."""

from __future__ import annotations

import numpy as np
import pytest

from voxwarp.core.slice_plane import (
    PLANE_AXIS,
    PLANE_NAMES,
    SlicePlane,
    fit_pixels,
    parse_plane,
    plane_names,
)
from voxwarp.errors import SceneError

BOUNDS = (np.array([-80.0, -100.0, -60.0]), np.array([80.0, 120.0, 90.0]))

#: (right, up) in world RAS of each named plane, radiological: patient left on the right
LAYOUT = {
    "axial": ((-1, 0, 0), (0, 1, 0)),  # right = L (-x), top = A (+y)
    "coronal": ((-1, 0, 0), (0, 0, 1)),  # right = L, top = S
    "sagittal": ((0, -1, 0), (0, 0, 1)),  # right = P (-y), top = S
    "x": ((0, 1, 0), (0, 0, 1)),
    "y": ((1, 0, 0), (0, 0, 1)),
    "z": ((1, 0, 0), (0, 1, 0)),
}


@pytest.mark.parametrize("name", PLANE_NAMES)
def test_named_plane_axes(name: str) -> None:
    plane = SlicePlane.named(name, BOUNDS)
    right, up = LAYOUT[name]
    np.testing.assert_allclose(plane.right, right, atol=1e-12)
    np.testing.assert_allclose(plane.up, up, atol=1e-12)
    np.testing.assert_allclose(plane.normal, np.cross(right, up), atol=1e-12)
    assert plane.name == name
    np.testing.assert_allclose(plane.center, (BOUNDS[0] + BOUNDS[1]) / 2)


def test_plane_names_by_space() -> None:
    assert plane_names("RAS") == ("axial", "coronal", "sagittal")
    assert plane_names("") == ("z", "y", "x")


@pytest.mark.parametrize("name", PLANE_NAMES)
def test_framing_shows_the_whole_box(name: str) -> None:
    size = (300, 200)
    plane = SlicePlane.named(name, BOUNDS, aspect=size[0] / size[1])
    lo, hi = BOUNDS
    corners = np.array(np.meshgrid(*zip(lo, hi, strict=True))).reshape(3, -1).T
    px, dist = plane.world_to_pixel(corners, size)
    assert np.all(px >= -0.5)
    assert np.all(px[:, 0] <= size[0] - 0.5)
    assert np.all(px[:, 1] <= size[1] - 0.5)
    # snug: the box fills one image dimension up to the 5 % margin
    span = np.ptp(px, axis=0) / np.array(size)
    assert max(span) == pytest.approx(1 / 1.05, rel=1e-6)
    assert np.ptp(dist) > 0  # corners on both sides of the plane


@pytest.mark.parametrize("name", [*PLANE_NAMES, "oblique"])
def test_pixel_to_world_and_back(name: str) -> None:
    size = (64, 48)
    if name == "oblique":
        plane = SlicePlane.oblique((3.0, -4.0, 5.0), (0.3, -0.2, 1.0), BOUNDS, aspect=64 / 48)
    else:
        plane = SlicePlane.named(name, BOUNDS, at=7.5, aspect=64 / 48)
    m = plane.pixel_to_world(size)
    px_mm = plane.pixel_mm(size)
    assert px_mm == pytest.approx(plane.height_mm / 48)
    # column steps along right, rows downwards (along -up), square pixels
    np.testing.assert_allclose(m[:3, 0], plane.right * px_mm, atol=1e-12)
    np.testing.assert_allclose(m[:3, 1], -plane.up * px_mm, atol=1e-12)
    np.testing.assert_allclose(m[:3, 2], plane.normal, atol=1e-12)
    # the image centre (between the middle pixels) is the plane's centre
    np.testing.assert_allclose(m @ [31.5, 23.5, 0, 1], [*plane.center, 1], atol=1e-9)
    rng = np.random.default_rng(1)
    pix = rng.uniform(0, 64, (20, 2))
    off = rng.uniform(-5, 5, 20)
    world = (np.c_[pix, off, np.ones(20)] @ m.T)[:, :3]
    back, dist = plane.world_to_pixel(world, size)
    np.testing.assert_allclose(back, pix, atol=1e-9)
    np.testing.assert_allclose(dist, off, atol=1e-9)


@pytest.mark.parametrize("name", PLANE_NAMES)
def test_at_moved_through_position(name: str) -> None:
    axis = PLANE_AXIS[name]
    plane = SlicePlane.named(name, BOUNDS, at=12.0)
    assert plane.center[axis] == 12.0
    assert plane.position == 12.0
    moved = plane.moved(-5.0)
    assert moved.position == 7.0
    np.testing.assert_allclose(np.delete(moved.center, axis), np.delete(plane.center, axis))
    assert plane.at(-33.0).position == -33.0
    point = np.array([1.0, 2.0, 3.0])
    through = plane.through(point)
    assert through.position == pytest.approx(point[axis])
    assert through.world_to_pixel(point, (10, 10))[1][0] == pytest.approx(0.0, abs=1e-12)
    assert through.height_mm == plane.height_mm
    assert through.name == name


@pytest.mark.parametrize(
    ("normal", "nearest"),
    [
        ((0.1, 0.2, 1.0), "axial"),
        ((0.05, -1.0, 0.3), "coronal"),
        ((1.0, 0.2, -0.4), "sagittal"),
        ((-1.0, 0.1, 0.1), "sagittal"),  # the opposite normal: the same, unmirrored image
    ],
)
def test_oblique_tilts_the_nearest_named_plane(
    normal: tuple[float, float, float], nearest: str
) -> None:
    point = np.array([10.0, -20.0, 30.0])
    plane = SlicePlane.oblique(point, normal, BOUNDS)
    n = np.asarray(normal) / np.linalg.norm(normal)
    assert plane.name == "oblique"
    assert abs(plane.normal @ n) == pytest.approx(1.0, abs=1e-12)
    assert abs(plane.world_to_pixel(point, (9, 9))[1][0]) < 1e-9  # the point stays on it
    named = SlicePlane.named(nearest, BOUNDS)
    assert plane.normal @ named.normal > 0  # named plane's side kept
    # the smallest rotation: the in-plane axes turn by no more than the normal does
    tilt = np.degrees(np.arccos(np.clip(plane.normal @ named.normal, -1, 1)))
    for a, b in ((plane.right, named.right), (plane.up, named.up)):
        assert np.degrees(np.arccos(np.clip(a @ b, -1, 1))) <= tilt + 1e-6
    assert tilt < 45


def test_oblique_along_an_axis_is_the_named_plane() -> None:
    plane = SlicePlane.oblique((0, 0, 4.0), (0, 0, -2.0), BOUNDS)
    assert plane.name == "axial"
    assert plane.position == 4.0
    np.testing.assert_allclose(plane.right, LAYOUT["axial"][0], atol=1e-12)


def test_rotated_turns_about_the_in_plane_axes() -> None:
    plane = SlicePlane.named("axial", BOUNDS)
    tilted = plane.rotated(about_right=30.0)
    assert tilted.name == "oblique"
    np.testing.assert_allclose(tilted.right, plane.right, atol=1e-12)
    assert tilted.normal @ plane.normal == pytest.approx(np.cos(np.radians(30)))
    np.testing.assert_allclose(tilted.center, plane.center)


def test_parse_plane_names_and_point_normal() -> None:
    assert parse_plane(" Coronal ", BOUNDS, at=4.0).position == 4.0
    assert parse_plane("z", BOUNDS).name == "z"
    plane = parse_plane("1,2,3:0,0.3,1", BOUNDS)
    n = np.array([0, 0.3, 1]) / np.linalg.norm([0, 0.3, 1])
    # the normal is the given one up to sign (the axial side: seen from below)
    np.testing.assert_allclose(plane.normal, -n, atol=1e-12)
    np.testing.assert_allclose(plane.scroll_axis, n, atol=1e-12)  # scrolls towards +S
    assert abs(plane.world_to_pixel([1, 2, 3], (4, 4))[1][0]) < 1e-9
    moved = parse_plane("1,2,3:0,0.3,1", BOUNDS, at=5.0)
    np.testing.assert_allclose(moved.center - plane.center, 5.0 * n, atol=1e-9)
    assert moved.position - plane.position == pytest.approx(5.0)


@pytest.mark.parametrize("name", ["axial", "coronal", "sagittal"])
def test_a_slight_tilt_keeps_the_scroll_direction(name: str) -> None:
    plane = SlicePlane.named(name, BOUNDS)
    for tilted in (plane.rotated(about_right=1.0), plane.rotated(about_up=-1.0)):
        assert tilted.scroll_axis @ plane.scroll_axis > 0.99
        assert tilted.moved(3.0).position - tilted.position == pytest.approx(3.0)
        point = np.array([4.0, -6.0, 8.0])
        assert tilted.through(point).world_to_pixel(point, (5, 5))[1][0] == pytest.approx(
            0.0, abs=1e-9
        )


@pytest.mark.parametrize(
    "text", ["transverse", "", "1,2:0,0,1", "1,2,3", "1,2,3:0,0", "a,b,c:0,0,1", "0,0,0:0,0,0"]
)
def test_parse_plane_rejects_junk_in_one_line(text: str) -> None:
    with pytest.raises(SceneError) as info:
        parse_plane(text, BOUNDS)
    message = str(info.value)
    assert "\n" not in message
    assert message


@pytest.mark.parametrize("at", [float("nan"), "left"])
def test_bad_position_is_one_line(at: object) -> None:
    with pytest.raises(SceneError, match="slice position") as info:
        SlicePlane.named("axial", BOUNDS, at=at)  # type: ignore[arg-type]
    assert "\n" not in str(info.value)


def test_letters_of_named_and_oblique_planes() -> None:
    expect = {
        "axial": {"right": "L", "left": "R", "top": "A", "bottom": "P"},
        "coronal": {"right": "L", "left": "R", "top": "S", "bottom": "I"},
        "sagittal": {"right": "P", "left": "A", "top": "S", "bottom": "I"},
    }
    for name, letters in expect.items():
        assert SlicePlane.named(name, BOUNDS).letters() == letters
    tilted = SlicePlane.named("axial", BOUNDS).rotated(about_up=35.0)
    letters = tilted.letters()
    assert letters["right"][0] == "L"
    assert len(letters["right"]) == 2
    assert letters["left"][0] == "R"
    assert letters["top"] == "A"


def test_fit_pixels() -> None:
    plane = SlicePlane.named("coronal", BOUNDS)
    framed, (w, h) = fit_pixels(plane, *BOUNDS, 2.0)
    # coronal shows x (160 mm) across and z (150 mm) up, 5 % margin, 2 mm pixels
    assert (w, h) == (int(np.ceil(160 * 1.05 / 2)), int(np.ceil(150 * 1.05 / 2)))
    assert framed.pixel_mm((w, h)) == pytest.approx(2.0)
    assert framed.position == plane.position
    coarse, size = fit_pixels(plane, *BOUNDS, 1e-3)  # capped at MAX_SLICE_PIXELS a side
    assert max(size) <= 4096
    assert coarse.pixel_mm(size) > 1e-3
    for anchor in ((0.3, 0.7, 0.1), (0.0, 0.0, 0.0), (1.234, -5.5, 7.77)):
        # a pixel grid laid out from a voxel centre grows by whole pixels: still capped
        _, size = fit_pixels(plane, *BOUNDS, 1e-3, anchor=anchor)
        assert max(size) <= 4096, (anchor, size)
        assert max(size) >= 4090
    with pytest.raises(SceneError, match="pixel size"):
        fit_pixels(plane, *BOUNDS, 0.0)


@pytest.mark.parametrize("name", ["axial", "sagittal", "oblique"])
def test_camera_projects_pixel_centres_to_their_pixels(name: str) -> None:
    size = (80, 60)
    if name == "oblique":
        plane = SlicePlane.oblique((5.0, 5.0, 5.0), (0.4, 0.3, 1.0), BOUNDS, aspect=80 / 60)
    else:
        plane = SlicePlane.named(name, BOUNDS, at=3.0, aspect=80 / 60)
    cam = plane.camera()
    m = plane.pixel_to_world(size)
    pix = np.array([[0, 0], [79, 0], [0, 59], [40, 30], [13, 47]], float)
    world = (np.c_[pix, np.zeros(5), np.ones(5)] @ m.T)[:, :3]
    # project's origin is the image's top-left corner: a pixel's centre is at +0.5
    np.testing.assert_allclose(cam.project(world, size), pix + 0.5, atol=1e-6)
    # and the camera looks at the plane from its front (the normal's side)
    origin, direction = cam.ray((40.5, 30.5), size)
    np.testing.assert_allclose(direction, -plane.normal, atol=1e-9)
    np.testing.assert_allclose(plane.world_to_pixel(origin, size)[0][0], (40, 30), atol=1e-6)
