"""GL tests of voxwarp.render.overlay: editing handles drawn over a frame (llvmpipe through EGL).

Oracles: :meth:`voxwarp.core.camera.Camera.project` (independent of the shader's matrix path
only in that it is the CPU reference the GUI picks with) gives where each handle must
land; a point must fill exactly the pixels whose centres lie within its disc, with the
outline ring around it; a 1-px line must light one pixel per column (x-major) within
half a pixel of the projected segment; over a raycast frame, pixels away from handles
must keep their bits and translucent handles must follow premultiplied "over".

Images are read with row 0 at the top; pixel (col, row) has its centre at
``(col + 0.5, row + 0.5)`` in ``Camera.project``'s coordinates.
"""

from __future__ import annotations

import ctypes
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from voxwarp.core.camera import Camera
from voxwarp.core.volume import Volume
from voxwarp.errors import RenderError
from voxwarp.io.images import read_image, write_image
from voxwarp.render.overlay import (
    OUTLINE_COLOR,
    OverlayLayer,
    OverlayRenderer,
    box_edges,
    grid_edges,
    polyline_segments,
)
from voxwarp.scene import Scene

W, H = 96, 64
BG = (0.2, 0.3, 0.4, 1.0)
#: margin (px) around disc / ring borders and lines for float and rasteriser snapping
EDGE = 0.15


@pytest.fixture(scope="module")
def overlay(gl_ctx: Any) -> Iterator[OverlayRenderer]:
    r = OverlayRenderer(gl_ctx)
    yield r
    r.release()


@pytest.fixture(scope="module")
def target(gl_ctx: Any) -> Iterator[Any]:
    color = gl_ctx.renderbuffer((W, H), 4, dtype="f4")
    fbo = gl_ctx.framebuffer(color_attachments=[color])
    yield fbo
    gl_ctx.detect_framebuffer(0).use()  # never delete the bound framebuffer
    fbo.release()
    color.release()


def read(fbo: Any, dtype: str = "f4") -> np.ndarray:
    """The (H, W, 4) image of ``fbo``, row 0 at the top: float32 (``"f4"``) or uint8."""
    w, h = fbo.size
    raw = fbo.read(components=4, dtype="f4" if dtype == "f4" else "f1", alignment=1)
    img = np.frombuffer(raw, dtype=np.float32 if dtype == "f4" else np.uint8)
    return img.reshape(h, w, 4)[::-1].copy()


def draw_on_background(
    overlay: OverlayRenderer, fbo: Any, layers: list, cam: Camera, viewport: Any = None
) -> np.ndarray:
    fbo.use()
    fbo.clear(*BG)
    overlay.draw(layers, fbo, cam, viewport)
    return read(fbo)


def camera(projection: str) -> Camera:
    from voxwarp.core.camera import view_rotation

    return Camera(
        center=np.array([1.0, 2.0, 3.0]),
        rotation=view_rotation((30.0, 20.0)),
        distance=60.0,
        fov=40.0,
        projection=projection,
        ortho_height=30.0,
        radius=20.0,
    )


def pixel_centres(w: int = W, h: int = H) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) x and y of the pixel centres in Camera.project coordinates."""
    return np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)


def premultiplied(rgba: Any) -> np.ndarray:
    c = np.asarray(rgba, float)
    return np.r_[c[:3] * c[3], c[3]]


def segment_distance(px: np.ndarray, py: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of points (px, py) to the 2D segment a-b."""
    d = b - a
    t = np.clip(((px - a[0]) * d[0] + (py - a[1]) * d[1]) / max(float(d @ d), 1e-12), 0, 1)
    return np.hypot(px - (a[0] + t * d[0]), py - (a[1] + t * d[1]))


# ---------------------------------------------------------------------- points
POINTS = np.array([[0.0, 0.0, 0.0], [6.0, -4.0, 3.0], [-5.0, 5.0, -2.0], [3.0, 7.0, 8.0]])
COLORS = np.array([[1, 0, 0, 1], [0, 1, 0, 1], [0, 0, 1, 1], [1, 1, 0, 1]], float)


def test_cameras_project_test_points_differently() -> None:
    # the point tests would not tell the projections apart otherwise
    a = camera("perspective").project(POINTS, (W, H))
    b = camera("orthographic").project(POINTS, (W, H))
    assert np.abs(a - b).max() > 3.0
    for p in (a, b):  # all well inside the image
        assert np.all((p > 8) & (p < [W - 8, H - 8]))


@pytest.mark.parametrize("projection", ["perspective", "orthographic"])
def test_points_are_discs_at_projected_pixels(
    overlay: OverlayRenderer, target: Any, projection: str
) -> None:
    cam = camera(projection)
    size = 5.0
    img = draw_on_background(overlay, target, [OverlayLayer("points", POINTS, COLORS, size)], cam)
    expected = cam.project(POINTS, (W, H))
    x, y = pixel_centres()
    far = np.ones((H, W), bool)
    for p, color in zip(expected, COLORS, strict=True):
        r = np.hypot(x - p[0], y - p[1])
        # the pixel holding the projected point, and its whole disc, have the colour
        col, row = int(p[0]), int(p[1])
        np.testing.assert_allclose(img[row, col], premultiplied(color), atol=1e-6)
        disc = r <= size / 2 - EDGE
        assert disc.sum() >= 9
        np.testing.assert_allclose(img[disc], np.broadcast_to(color, (disc.sum(), 4)), atol=1e-6)
        ring = (r > size / 2 + EDGE) & (r <= size / 2 + 1 - EDGE)
        assert ring.sum() >= 8
        np.testing.assert_allclose(
            img[ring], np.broadcast_to(premultiplied(OUTLINE_COLOR), (ring.sum(), 4)), atol=1e-6
        )
        far &= r > size / 2 + 1 + EDGE
    np.testing.assert_allclose(img[far], np.broadcast_to(BG, (far.sum(), 4)), atol=1e-6)


def test_point_scale_scales_the_disc_not_the_ring(overlay: OverlayRenderer, target: Any) -> None:
    """``point_scale`` (a frame drawn at another resolution than shown): a 4 px point at
    scale 2 is an 8 px disc inside the same 1 px ring."""
    cam = camera("orthographic")
    layer = OverlayLayer("points", POINTS[:1], COLORS[:1], 4.0)
    target.use()
    target.clear(*BG)
    overlay.draw([layer], target, cam, point_scale=2.0)
    img = read(target)
    p = cam.project(POINTS[:1], (W, H))[0]
    x, y = pixel_centres()
    r = np.hypot(x - p[0], y - p[1])
    disc = r <= 4.0 - EDGE
    np.testing.assert_allclose(img[disc], np.broadcast_to(COLORS[0], (disc.sum(), 4)), atol=1e-6)
    ring = (r > 4.0 + EDGE) & (r <= 5.0 - EDGE)
    assert ring.sum() >= 8
    np.testing.assert_allclose(
        img[ring], np.broadcast_to(premultiplied(OUTLINE_COLOR), (ring.sum(), 4)), atol=1e-6
    )
    assert np.allclose(img[r > 5.0 + EDGE], BG, atol=1e-6)


def test_points_in_a_viewport(overlay: OverlayRenderer, target: Any) -> None:
    cam = camera("perspective")
    vx, vy, vw, vh = 30, 10, 50, 40  # origin bottom-left, as the raycaster's viewport
    layer = OverlayLayer("points", POINTS[:2], (1.0, 0.5, 0.0, 1.0), size=3.0)
    img = draw_on_background(overlay, target, [layer], cam, (vx, vy, vw, vh))
    expected = cam.project(POINTS[:2], (vw, vh)) + np.array([vx, H - vy - vh])  # top-left origin
    for p in expected:  # colours travel as 8 bits per channel
        np.testing.assert_allclose(img[int(p[1]), int(p[0])], (1.0, 0.5, 0.0, 1.0), atol=1 / 255)
    touched = np.any(np.abs(img - BG) > 1e-6, axis=-1)
    rows, cols = np.nonzero(touched)
    assert touched.sum() > 0
    assert cols.min() >= vx
    assert cols.max() < vx + vw
    assert rows.min() >= H - vy - vh
    assert rows.max() < H - vy
    assert target.viewport == (0, 0, W, H)  # the framebuffer's viewport is left as it was


# ---------------------------------------------------------------------- lines
@pytest.mark.parametrize(
    ("projection", "ends"),
    [
        ("perspective", [[7.0, -12.0, 1.0], [-6.0, 11.0, -3.0]]),  # x-major on screen
        ("orthographic", [[-2.0, -6.0, 9.0], [3.0, 9.0, -8.0]]),  # y-major on screen
    ],
)
def test_line_covers_the_projected_segment(
    overlay: OverlayRenderer, target: Any, projection: str, ends: list
) -> None:
    cam = camera(projection)
    green = (0.0, 1.0, 0.0, 1.0)
    ends_a = np.array(ends)
    img = draw_on_background(overlay, target, [OverlayLayer("lines", ends_a, green)], cam)
    a, b = cam.project(ends_a, (W, H))
    x, y = pixel_centres()
    lit = np.all(np.abs(img - green) < 1e-6, axis=-1)
    # the midpoint of the projected segment is on the line (within one pixel)
    mid = (a + b) / 2
    assert lit[int(mid[1]) - 1 : int(mid[1]) + 2, int(mid[0]) - 1 : int(mid[0]) + 2].any()
    # along the major axis: exactly one lit pixel per column (row), within half a pixel
    major = int(np.argmax(np.abs(b - a)))
    assert abs(b[major] - a[major]) > 20
    lit_major = lit if major == 0 else lit.T
    lo, hi = sorted((a[major], b[major]))
    for i in range(int(np.ceil(lo)) + 2, int(hi) - 2):
        hits = np.flatnonzero(lit_major[:, i])
        assert len(hits) == 1, f"{len(hits)} lit pixels at major coordinate {i}"
        t = (i + 0.5 - a[major]) / (b[major] - a[major])
        minor = a[1 - major] + t * (b[1 - major] - a[1 - major])
        assert abs(hits[0] + 0.5 - minor) <= 0.5 + 1e-3
    # nothing off the segment
    d = segment_distance(x, y, a, b)
    assert not np.any(np.abs(img[d > 1.5] - BG) > 1e-6)
    assert lit[d <= 1.5].sum() >= int(abs(hi - lo)) - 1


def test_handles_outside_the_camera_depth_range_are_drawn(
    overlay: OverlayRenderer, target: Any
) -> None:
    # radius 1: near/far planes enclose only |p - center| < 2 mm; the handles lie beyond
    cam = Camera(center=np.zeros(3), distance=40.0, fov=40.0, radius=1.0)
    near, far = cam.near_far()
    pts = np.array([[2.0, 1.0, 40.0 - near / 2], [-3.0, -1.0, 40.0 - far - 10.0]])
    assert cam.view_matrix()[2] @ np.r_[pts[0], 1] > -near  # in front of the near plane
    img = draw_on_background(overlay, target, [OverlayLayer("points", pts, (1, 0, 1, 1))], cam)
    for p in cam.project(pts, (W, H)):
        np.testing.assert_allclose(img[int(p[1]), int(p[0])], (1, 0, 1, 1), atol=1e-6)
    # behind the eye: nothing drawn
    behind = OverlayLayer("points", [[0.0, 0.0, 60.0]], (1, 0, 1, 1))
    img = draw_on_background(overlay, target, [behind], cam)
    np.testing.assert_allclose(img, np.broadcast_to(BG, img.shape), atol=1e-6)


def test_empty_layers_are_skipped(overlay: OverlayRenderer, target: Any) -> None:
    cam = camera("perspective")
    empty = [
        OverlayLayer("points", np.zeros((0, 3)), (1, 0, 0, 1)),
        OverlayLayer("lines", [], (1, 0, 0, 1)),
        OverlayLayer("points", np.zeros((0, 3)), np.zeros((0, 4))),
    ]
    img = draw_on_background(overlay, target, empty, cam)
    np.testing.assert_allclose(img, np.broadcast_to(BG, img.shape), atol=1e-6)
    # an empty layer between two others changes nothing
    dot = OverlayLayer("points", POINTS[:1], (1, 0, 0, 1))
    line = OverlayLayer("lines", POINTS[1:3], (0, 1, 0, 1))
    a = draw_on_background(overlay, target, [dot, line], cam)
    b = draw_on_background(overlay, target, [dot, *empty, line], cam)
    np.testing.assert_array_equal(a, b)
    assert np.any(np.abs(a - BG) > 1e-6)


# ---------------------------------------------------------------------- over a volume
def blob(n: int = 32) -> Volume:
    c = (n - 1) / 2
    i, j, k = np.meshgrid(*(np.arange(n, dtype=float) - c,) * 3, indexing="ij")
    f = np.exp(-((i / 9.0) ** 2 + (j / 5.5) ** 2 + (k / 7.0) ** 2))
    f += 0.8 * np.exp(-(((i - 6.0) / 3.0) ** 2 + ((j - 4.0) / 3.0) ** 2 + (k / 3.0) ** 2))
    return Volume((1000.0 * f).astype(np.float32), spacing=(1.0, 1.0, 1.0), name="blob")


def gl_is_enabled() -> Any:
    """glIsEnabled of the current context through libGL (GLVND), or None."""
    for name in ("libOpenGL.so.0", "libGL.so.1"):
        try:
            lib = ctypes.CDLL(name)
        except OSError:
            continue
        fn = lib.glIsEnabled
        fn.restype = ctypes.c_ubyte
        fn.argtypes = [ctypes.c_uint]
        return fn
    return None


def test_overlay_on_a_volume_frame(
    gl_ctx: Any, offscreen: Any, overlay: OverlayRenderer, tmp_path: Any
) -> None:
    size = (128, 96)
    vol = blob()
    scene = Scene(vol, mode="mip", transfer_function="grayscale", view=(35.0, 25.0), jitter=False)
    cam = scene.resolved_camera()
    off = offscreen(*size)
    before = off.render(scene, cam)
    assert before[..., :3].max() > 200  # a bright volume under the handles

    lo, hi = (np.asarray(b, float) for b in vol.bounds)
    axes = [np.linspace(lo[a], hi[a], 3) for a in range(3)]
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)  # (3, 3, 3, 3) lattice
    wire = np.c_[
        np.linspace(lo[0], hi[0], 12),
        np.full(12, 0.5 * (lo[1] + hi[1])),
        8 * np.sin(np.linspace(0, np.pi, 12)) + 0.5 * (lo[2] + hi[2]),
    ]
    edge_color = (0.2, 0.8, 1.0, 0.5)  # translucent: blended over the volume
    layers = [
        OverlayLayer("lines", box_edges(lo - 2, hi + 2), (1.0, 0.6, 0.0, 1.0), name="clip box"),
        OverlayLayer("lines", grid_edges(nodes), edge_color, name="lattice"),
        OverlayLayer("lines", polyline_segments(wire), (1.0, 0.2, 0.8, 1.0), name="wire"),
        OverlayLayer("points", nodes.reshape(-1, 3), (1.0, 0.9, 0.1, 1.0), 7.0, "nodes"),
    ]
    overlay.draw(layers, off.framebuffer, cam)
    after = read(off.framebuffer, "u1")
    path = write_image(tmp_path / "overlay_on_volume.png", after)
    np.testing.assert_array_equal(read_image(path)[..., :3], after[..., :3])

    x, y = pixel_centres(*size)
    near = np.zeros(size[::-1], bool)
    for layer in layers:
        p2 = cam.project(np.asarray(layer.positions), size)
        if layer.kind == "points":
            for p in p2:
                near |= np.hypot(x - p[0], y - p[1]) <= layer.size / 2 + 1 + 1
        else:
            for a, b in zip(p2[0::2], p2[1::2], strict=True):
                near |= segment_distance(x, y, a, b) <= 1.5
    assert 0.02 < near.mean() < 0.6
    # pixels away from the handles keep their bits
    np.testing.assert_array_equal(after[~near], before[~near])
    # opaque node points at their projected pixels (drawn last, on top)
    for p in cam.project(nodes.reshape(-1, 3), size):
        np.testing.assert_array_equal(after[int(p[1]), int(p[0])], (255, 230, 26, 255))
    # translucent lattice edges: premultiplied "over" the frame, on pixels right on one
    # edge and away from other edges (crossings blend twice) and other handles
    on_edge = np.zeros(size[::-1], bool)
    edges_near = np.zeros(size[::-1], int)
    p2 = cam.project(layers[1].positions, size)
    for a, b in zip(p2[0::2], p2[1::2], strict=True):
        d = segment_distance(x, y, a, b)
        on_edge |= d <= 0.3
        edges_near += d <= 1.5
    lattice_only = on_edge & (edges_near == 1)
    others = np.zeros_like(near)
    for layer in (layers[0], layers[2], layers[3]):
        q = cam.project(np.asarray(layer.positions), size)
        if layer.kind == "points":
            for p in q:
                others |= np.hypot(x - p[0], y - p[1]) <= layer.size / 2 + 2
        else:
            for a, b in zip(q[0::2], q[1::2], strict=True):
                others |= segment_distance(x, y, a, b) <= 1.5
    lattice_only &= ~others
    changed = np.any(after != before, axis=-1)
    blended = lattice_only & changed
    assert blended.sum() > 50
    alpha = edge_color[3]
    expected = premultiplied(edge_color) * 255 + (1 - alpha) * before[blended].astype(float)
    assert np.abs(after[blended].astype(float) - expected).max() <= 2.0

    # the raycaster's next frame is unaffected by the overlay's GL state
    again = off.render(scene, cam)
    np.testing.assert_array_equal(again, before)


def test_gl_state_is_restored(gl_ctx: Any, overlay: OverlayRenderer, target: Any) -> None:
    is_enabled = gl_is_enabled()
    if is_enabled is None:
        pytest.skip("no libGL/libOpenGL to query glIsEnabled")
    flags = {"depth": 0x0B71, "blend": 0x0BE2, "cull": 0x0B44, "point_size": 0x8642}

    def state() -> dict[str, int]:
        return {k: int(is_enabled(v)) for k, v in flags.items()}

    # calibrate: the queries must read this context's flags
    gl_ctx.enable(gl_ctx.DEPTH_TEST)
    on = state()
    gl_ctx.disable(gl_ctx.DEPTH_TEST)
    if on["depth"] != 1 or state()["depth"] != 0:
        pytest.skip("glIsEnabled does not read the test context")
    layers = [
        OverlayLayer("points", POINTS, (1, 0, 0, 1)),
        OverlayLayer("lines", POINTS, (0, 1, 0, 1)),
    ]
    cam = camera("perspective")
    try:
        for enabled in (0, gl_ctx.DEPTH_TEST | gl_ctx.CULL_FACE):
            gl_ctx.enable_only(enabled)
            expect = state()
            draw_on_background(overlay, target, layers, cam)
            assert state() == expect
    finally:
        gl_ctx.enable_only(0)


# ---------------------------------------------------------------------- buffers, size
def test_many_handles_reuse_the_buffer(overlay: OverlayRenderer, target: Any) -> None:
    rng = np.random.default_rng(3)
    cam = camera("orthographic")
    pts = rng.uniform(-7, 7, (40_000, 3)) + cam.center
    segs = rng.uniform(-7, 7, (400_000, 3)) + cam.center  # 200k segments
    layers = [
        OverlayLayer("lines", segs, (0.0, 1.0, 0.0, 0.3)),
        OverlayLayer("points", pts, rng.uniform(0, 1, (len(pts), 4)), size=2.0),
    ]
    img = draw_on_background(overlay, target, layers, cam)
    vbo = overlay._vbo
    assert vbo.size >= 440_000 * 16
    # the handles' projected bounding box (less a border) is covered densely
    p = cam.project(np.r_[pts, segs], (W, H))
    (x0, y0), (x1, y1) = np.ceil(p.min(axis=0)) + 2, np.floor(p.max(axis=0)) - 2
    assert (x1 - x0) * (y1 - y0) > 0.15 * W * H
    assert y0 > 6
    assert y1 < H - 6
    inside = img[int(y0) : int(y1), int(x0) : int(x1)]
    assert np.mean(np.any(np.abs(inside - BG) > 1e-6, axis=-1)) > 0.95
    # nothing above or below them (points reach 2 px beyond their centres)
    assert not np.any(np.abs(img[: int(p[:, 1].min()) - 3] - BG) > 1e-6)
    assert not np.any(np.abs(img[int(p[:, 1].max()) + 4 :] - BG) > 1e-6)
    again = draw_on_background(overlay, target, layers, cam)
    assert overlay._vbo is vbo  # kept across frames
    np.testing.assert_array_equal(again, img)
    draw_on_background(overlay, target, layers[1:], cam)
    assert overlay._vbo is vbo  # a smaller frame reuses it too


def test_release_is_idempotent(gl_ctx: Any, target: Any) -> None:
    r = OverlayRenderer(gl_ctx)
    r.draw([OverlayLayer("points", POINTS, (1, 0, 0, 1))], target, camera("perspective"))
    r.release()
    r.release()
    with pytest.raises(RenderError, match="released"):
        r.draw([], target, camera("perspective"))


# ---------------------------------------------------------------------- segment builders
def test_grid_edges_join_neighbours() -> None:
    shape = (2, 3, 4)
    idx = np.stack(np.meshgrid(*(np.arange(n) for n in shape), indexing="ij"), axis=-1)
    scale = np.array([1.0, 10.0, 100.0])
    edges = grid_edges(idx * scale + 0.25)
    expected_count = 1 * 3 * 4 + 2 * 2 * 4 + 2 * 3 * 3
    assert edges.shape == (2 * expected_count, 3)
    a = np.rint((edges[0::2] - 0.25) / scale).astype(int)
    b = np.rint((edges[1::2] - 0.25) / scale).astype(int)
    np.testing.assert_allclose(edges[0::2], a * scale + 0.25)  # endpoints are nodes
    step = b - a
    assert np.all(np.sum(np.abs(step), axis=1) == 1)  # neighbours
    assert np.all(step >= 0)
    assert np.all((a >= 0) & (b < shape))
    pairs = {(tuple(p), tuple(q)) for p, q in zip(a, b, strict=True)}
    assert len(pairs) == expected_count  # each link once
    # every neighbour pair of the grid is there
    for axis in range(3):
        n = np.sum(step[:, axis] == 1)
        assert n == np.prod(shape) // shape[axis] * (shape[axis] - 1)
    # a single node: no edges; a line of nodes: a polyline
    assert grid_edges(np.zeros((1, 1, 1, 3))).shape == (0, 3)
    line = np.arange(12.0).reshape(1, 4, 1, 3)
    np.testing.assert_array_equal(grid_edges(line), polyline_segments(line.reshape(-1, 3)))


def test_box_edges() -> None:
    lo, hi = np.array([-1.0, 2.0, 3.0]), np.array([4.0, 5.0, 9.0])
    e = box_edges(lo, hi)
    assert e.shape == (24, 3)
    corners = {tuple(c) for c in e}
    assert len(corners) == 8
    assert all(np.all((c == lo) | (c == hi)) for c in e)
    d = np.abs(e[1::2] - e[0::2])
    assert np.all(np.count_nonzero(d, axis=1) == 1)  # each edge along one axis
    np.testing.assert_allclose(d.sum(axis=1), np.repeat(hi - lo, 4))
    edges = {frozenset((tuple(p), tuple(q))) for p, q in zip(e[0::2], e[1::2], strict=True)}
    assert len(edges) == 12
    counts = {c: sum(c in edge for edge in edges) for c in corners}
    assert set(counts.values()) == {3}


def test_polyline_segments() -> None:
    p = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 2.0, 0.0], [1.0, 2.0, 3.0]])
    s = polyline_segments(p)
    assert s.shape == (6, 3)
    np.testing.assert_array_equal(s[0::2], p[:-1])
    np.testing.assert_array_equal(s[1::2], p[1:])
    assert polyline_segments(p[:1]).shape == (0, 3)
    assert polyline_segments(np.zeros((0, 3))).shape == (0, 3)


# ---------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"kind": "triangles"}, "kind must be one of 'points', 'lines'"),
        ({"positions": np.zeros((4, 2))}, r"\(N, 3\) array .* got shape \(4, 2\)"),
        ({"positions": np.zeros((2, 2, 2, 3))}, "grid_edges"),
        ({"positions": [[0, 0, 0], [1, np.nan, 0]]}, "1 non-finite point.*index 1"),
        ({"positions": [["a", "b", "c"]]}, "real"),
        ({"colors": np.ones((3, 4))}, "colors has 3 rows but positions has 2 points"),
        ({"colors": (1, 0, 0)}, r"got shape \(3,\) \(add alpha: RGBA\)"),
        ({"colors": (255, 0, 0, 255)}, r"in \[0, 1\].*255"),
        ({"colors": (1, 0, np.nan, 1)}, "finite"),
        ({"size": 0.0}, "size must be a positive number of pixels"),
        ({"kind": "lines", "positions": np.zeros((3, 3))}, "even count; got 3"),
    ],
)
def test_bad_layers_raise_helpful_errors(kwargs: dict, message: str) -> None:
    fields = {"kind": "points", "positions": np.zeros((2, 3)), "colors": (1, 0, 0, 1)}
    fields.update(kwargs)
    with pytest.raises(RenderError, match=message):
        OverlayLayer(**fields, name="handles")


def test_bad_draw_arguments(overlay: OverlayRenderer, target: Any) -> None:
    cam = camera("perspective")
    good = OverlayLayer("points", POINTS, (1, 0, 0, 1), name="nodes")
    with pytest.raises(RenderError, match="OverlayLayer objects; layer 1 is a ndarray"):
        overlay.draw([good, POINTS], target, cam)
    # fields replaced after construction are checked when drawn, naming the layer
    good.positions = np.zeros((3, 4))
    with pytest.raises(RenderError, match=r"overlay layer 0 \('nodes'\): positions"):
        overlay.draw([good], target, cam)
    good.positions = POINTS
    with pytest.raises(RenderError, match="viewport must have a positive size"):
        overlay.draw([good], target, cam, (0, 0, 0, 10))
    with pytest.raises(RenderError, match=r"takes a voxwarp\.Camera"):
        overlay.draw([good], target, "perspective")  # type: ignore[arg-type]


def test_bad_builder_input() -> None:
    with pytest.raises(RenderError, match=r"\(nx, ny, nz, 3\).*got shape \(4, 3\)"):
        grid_edges(np.zeros((4, 3)))
    with pytest.raises(RenderError, match="hi must be 3 finite numbers"):
        box_edges((0, 0, 0), (1, np.inf, 1))
    with pytest.raises(RenderError, match=r"got shape \(2, 2\)"):
        polyline_segments(np.zeros((2, 2)))
