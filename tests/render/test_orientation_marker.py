"""The orientation marker (voxwarp.render.orientation_marker): directions, letters, pixels.

Oracles: the camera's own projection (``Camera.project`` of a world axis through an
orthographic camera) gives where each half-axis must point on the image; the font's
glyph bitmaps give which letter sits where. A mirrored image must fail the same checks.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from voxwarp.core.camera import Camera, view_rotation
from voxwarp.core.orientation import ANATOMICAL_VIEWS
from voxwarp.core.volume import Volume
from voxwarp.errors import RenderError
from voxwarp.render.orientation_marker import (
    AXIS_COLORS,
    draw_orientation_marker,
    draw_scene_marker,
    glyph_mask,
    marker_axes,
    marker_layout,
)
from voxwarp.scene import Scene

SIZE = (200, 160)  # width, height
GREY = 90


def camera(view: Any) -> Camera:
    return Camera.fit((-10, -10, -10), (10, 10, 10), view, projection="orthographic")


def drawn(view: Any, oriented: bool = True, channels: int = 3, **kw: Any) -> np.ndarray:
    img = np.full((SIZE[1], SIZE[0], channels), GREY, np.uint8)
    return draw_orientation_marker(img, camera(view), oriented, **kw)


def letter_box(img: np.ndarray, at: tuple[float, float], letter: str, scale: int) -> np.ndarray:
    """The pixels of the letter cell centred at ``at`` (as the drawing places it)."""
    h, w = glyph_mask(letter, scale).shape
    x0, y0 = round(at[0] - w / 2), round(at[1] - h / 2)
    return img[y0 : y0 + h, x0 : x0 + w]


def letter_color(letter: str) -> np.ndarray:
    if letter in "xyz":
        return np.array(AXIS_COLORS["xyz".index(letter)], dtype=float)
    axis = "RAS".index(letter) if letter in "RAS" else "LPI".index(letter)
    color = np.array(AXIS_COLORS[axis], dtype=float)
    return np.round(color * 0.5) if letter in "LPI" else color


def painted(img: np.ndarray, color: np.ndarray) -> np.ndarray:
    """Pixels of exactly ``color`` (within 1/255)."""
    return np.all(np.abs(img[..., :3].astype(int) - color) <= 1, axis=-1)


def shows_letter(img: np.ndarray, at: tuple[float, float], letter: str, scale: int) -> bool:
    """Whether the pixels of exactly the letter's colour at ``at`` form its glyph."""
    box = letter_box(img, at, letter, scale)
    mask = glyph_mask(letter, scale)
    return box.shape[:2] == mask.shape and bool(
        np.array_equal(painted(box, letter_color(letter)), mask)
    )


def find_letter(img: np.ndarray, letter: str, scale: int) -> tuple[float, float] | None:
    """Where the glyph of ``letter`` is drawn in ``img`` (its centre), by search."""
    mask = glyph_mask(letter, scale)
    windows = np.lib.stride_tricks.sliding_window_view(
        painted(img, letter_color(letter)), mask.shape
    )
    hits = np.argwhere(np.all(windows == mask, axis=(2, 3)))
    if len(hits) != 1:
        return None
    y, x = hits[0]
    return (x + mask.shape[1] / 2, y + mask.shape[0] / 2)


def screen_direction(cam: Camera, axis: int) -> np.ndarray:
    """Where the world axis points on the image (x right, y down), by projection."""
    e = np.zeros(3)
    e[axis] = 5.0
    p = cam.project(np.array([cam.center, cam.center + e]), (100, 100))
    return p[1] - p[0]


# ---------------------------------------------------------------------- geometry
@pytest.mark.parametrize("view", [*ANATOMICAL_VIEWS.values(), (30, 20), (-120, -45)])
def test_axes_point_where_the_camera_projects_the_world_axes(view: Any) -> None:
    cam = camera(view)
    for a in marker_axes(cam, oriented=True):
        expected = a.sign * screen_direction(cam, a.axis)
        got = np.array([a.direction[0], -a.direction[1]])  # (right, up) -> (x, y down)
        n = np.linalg.norm(expected)
        if n < 1e-9:
            assert np.linalg.norm(got) < 1e-9
        else:
            np.testing.assert_allclose(got / np.linalg.norm(got), expected / n, atol=1e-9)


def test_letters_are_patient_letters_or_axis_names() -> None:
    oriented = {(a.axis, a.sign): a.label for a in marker_axes(camera("+y"), True)}
    assert oriented == {
        (0, 1): "R",
        (0, -1): "L",
        (1, 1): "A",
        (1, -1): "P",
        (2, 1): "S",
        (2, -1): "I",
    }
    plain = {(a.axis, a.sign): a.label for a in marker_axes(camera("+y"), False)}
    assert plain == {(0, 1): "x", (1, 1): "y", (2, 1): "z", (0, -1): "", (1, -1): "", (2, -1): ""}


def test_axes_are_drawn_back_to_front() -> None:
    depths = [a.depth for a in marker_axes(camera((30, 20)), True)]
    assert depths == sorted(depths)


# ---------------------------------------------------------------------- anatomical views
def letters_at(view: str, **kw: Any) -> tuple[Any, np.ndarray]:
    lay = marker_layout(camera(ANATOMICAL_VIEWS[view]), True, SIZE, **kw)
    return lay, drawn(ANATOMICAL_VIEWS[view], **kw)


def check_anterior(img: np.ndarray, scale: int) -> bool:
    """As drawn in ``img``: R left of S's column and S above R's row (the anterior view
    of a RAS volume: the patient's right on the image's left, head up)."""
    r, s = find_letter(img, "R", scale), find_letter(img, "S", scale)
    return r is not None and s is not None and r[0] < s[0] - 5 and s[1] < r[1] - 5


def test_anterior_view_puts_r_left_and_s_up() -> None:
    lay, img = letters_at("anterior")
    cx, cy = lay.center
    r, s = lay.label_position("R"), lay.label_position("S")
    assert r is not None
    assert s is not None
    assert r[0] < cx - lay.length
    assert abs(r[1] - cy) < 1
    assert s[1] < cy - lay.length
    assert abs(s[0] - cx) < 1
    # the drawn pixels: the glyphs R, L, S, I where the layout puts them
    for letter in "RLSI":
        assert shows_letter(img, lay.label_position(letter), letter, lay.scale), letter
    assert lay.label_position("A") is None  # points at the viewer: no letter on the centre
    assert check_anterior(img, lay.scale)


def test_a_mirrored_marker_fails_the_anterior_check() -> None:
    lay, img = letters_at("anterior")
    assert check_anterior(img, lay.scale)
    # the image mirrored left-right (glyphs mirrored too)
    assert not check_anterior(np.ascontiguousarray(img[:, ::-1]), lay.scale)
    # a mirrored convention (the patient's right on the image's right, upright letters)
    mirror = np.diag([-1.0, 1.0, 1.0]) @ view_rotation("+y")
    wrong = np.full((SIZE[1], SIZE[0], 3), GREY, np.uint8)
    draw_orientation_marker(wrong, mirror, True)
    assert find_letter(wrong, "R", lay.scale) is not None
    assert not check_anterior(wrong, lay.scale)


def test_inferior_view_is_radiological_a_up_r_left() -> None:
    lay, img = letters_at("inferior")
    cx, cy = lay.center
    a, r = lay.label_position("A"), lay.label_position("R")
    assert a[1] < cy - lay.length
    assert r[0] < cx - lay.length
    assert shows_letter(img, a, "A", lay.scale)
    assert shows_letter(img, r, "R", lay.scale)
    assert find_letter(img, "R", lay.scale)[0] < cx


def test_superior_view_puts_r_right_and_a_up() -> None:
    lay, img = letters_at("superior")
    cx, cy = lay.center
    a, r = lay.label_position("A"), lay.label_position("R")
    assert a[1] < cy - lay.length
    assert r[0] > cx + lay.length
    assert find_letter(img, "R", lay.scale)[0] > cx
    assert find_letter(img, "A", lay.scale)[1] < cy


def test_left_and_right_views() -> None:
    # from the patient's left: anterior on the image's left (head up)
    lay, img = letters_at("left")
    assert lay.label_position("A")[0] < lay.center[0]
    assert find_letter(img, "A", lay.scale)[0] < lay.center[0]
    assert lay.label_position("S")[1] < lay.center[1]
    lay, _img = letters_at("right")
    assert lay.label_position("A")[0] > lay.center[0]


# ---------------------------------------------------------------------- pixels
def test_drawn_colours_lie_along_the_axes() -> None:
    lay, img = letters_at("anterior")
    cx, cy = (int(v) for v in lay.center)
    red, blue = AXIS_COLORS[0], AXIS_COLORS[2]
    # anterior: +x (R) runs left from the centre, +z (S) up
    half = int(lay.length // 2)
    np.testing.assert_array_equal(img[cy, cx - half], red)
    np.testing.assert_array_equal(img[cy - half, cx], blue)
    # the negative halves are dimmer
    dim_red = img[cy, cx + half].astype(int)
    assert dim_red[0] > dim_red[1]
    assert dim_red[0] < red[0] - 50
    # far from the marker nothing changed
    assert np.all(img[:20, -40:] == GREY)


def test_corners_and_alpha_channel() -> None:
    img = drawn("+y", channels=4, corner="top-right")
    changed = np.any(img != GREY, axis=-1)
    ys, xs = np.nonzero(changed)
    # inside the 96-pixel square 6 pixels from the top-right corner, letters included
    assert ys.min() >= 6
    assert ys.max() < 6 + 96
    assert xs.min() >= SIZE[0] - 6 - 96
    assert xs.max() < SIZE[0] - 6
    # the triad is opaque: alpha goes to 255 under a line
    lay = marker_layout(camera("+y"), True, SIZE, corner="top-right")
    cx, cy = (int(v) for v in lay.center)
    assert img[cy, cx - int(lay.length // 2), 3] == 255


def test_float_images() -> None:
    img = np.zeros((SIZE[1], SIZE[0], 4), np.float32)
    draw_orientation_marker(img, camera("+y"), True)
    assert img.max() <= 1.0
    assert img.max() > 0.9
    assert img.dtype == np.float32


def test_unoriented_volume_gets_xyz() -> None:
    lay = marker_layout(camera("+y"), False, SIZE)
    img = drawn("+y", oriented=False)
    x_at = lay.label_position("x")
    assert x_at is not None
    mask = glyph_mask("x", lay.scale)
    box = letter_box(img, x_at, "x", lay.scale)
    np.testing.assert_array_equal(painted(box, np.array(AXIS_COLORS[0])), mask)
    assert lay.label_position("R") is None


def test_scene_marker_reads_the_volume_space() -> None:
    data = np.zeros((8, 8, 8), np.float32)
    for space, letter in (("RAS", "R"), ("", "x")):
        vol = Volume(data, spacing=(1, 1, 1), origin=(0, 0, 0), space=space)
        scene = Scene(vol, view="+y", projection="orthographic")
        img = np.full((SIZE[1], SIZE[0], 3), GREY, np.uint8)
        draw_scene_marker(img, scene)
        lay = marker_layout(scene.resolved_camera(), space == "RAS", SIZE)
        at = lay.label_position(letter)
        assert at is not None
        box = letter_box(img, at, letter, lay.scale)
        np.testing.assert_array_equal(
            painted(box, np.array(AXIS_COLORS[0])), glyph_mask(letter, lay.scale)
        )


def test_cli_render_marker(tmp_path: Path) -> None:
    """``voxwarp render --marker`` changes only the bottom-left square: there it draws
    the triad (x y z letters: an array has no patient orientation)."""
    from voxwarp.cli.main import main
    from voxwarp.io.images import read_image
    from voxwarp.io.volumes import save_volume

    z, y, x = np.mgrid[:24, :24, :24]
    data = ((x - 12) ** 2 + (y - 12) ** 2 + (z - 12) ** 2 < 64).astype(np.float32)
    src = save_volume(Volume(data, spacing=(1, 1, 1), name="ball"), tmp_path / "ball.npz")
    args = ["render", str(src), "--size", "160x128", "--tf", "grayscale", "--no-jitter"]
    assert main([*args, "-o", str(tmp_path / "plain.png")]) == 0
    assert main([*args, "-o", str(tmp_path / "marked.png"), "--marker"]) == 0
    plain, marked = (read_image(tmp_path / f"{n}.png") for n in ("plain", "marked"))
    changed = np.any(plain != marked, axis=-1)
    ys, xs = np.nonzero(changed)
    assert len(ys) > 100
    assert ys.min() >= 128 - 6 - 96
    assert xs.max() < 6 + 96
    scale = marker_layout(np.eye(3), False, (160, 128)).scale
    at = find_letter(marked, "z", scale)
    assert at is not None
    assert find_letter(plain, "z", scale) is None


def test_small_images_and_bad_input() -> None:
    img = np.full((30, 40, 3), GREY, np.uint8)
    draw_orientation_marker(img, camera("+y"), True)  # shrinks to fit
    assert np.any(img != GREY)
    with pytest.raises(RenderError, match="corner must be one of"):
        draw_orientation_marker(img, camera("+y"), True, corner="middle")
    with pytest.raises(RenderError, match=r"\(H, W, 3\) or \(H, W, 4\)"):
        draw_orientation_marker(np.zeros((10, 10)), camera("+y"), True)
    with pytest.raises(RenderError, match="uint8 or float"):
        draw_orientation_marker(np.zeros((10, 10, 3), np.int32), camera("+y"), True)
