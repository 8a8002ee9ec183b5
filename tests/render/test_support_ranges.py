"""Per-pixel ray ranges through the chain's support (voxwarp.render.support_ranges).

Oracle: the first and last ray parameter at which each pixel's ray lies in a support
brick, by slab tests against every brick on the CPU (the ray built as the raycaster
builds it). The pass widens the surface's rectangles by GROW of a brick (against
rasterisation cracks at T-junctions), so a range must hold every brick the ray crosses
and may reach as far as the bricks grown by that much, no farther.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from voxwarp.core.camera import Camera
from voxwarp.deform.support import SupportMap
from voxwarp.render.support_ranges import FAR, GROW, MAX_TRIANGLES, SupportRanges

SIZE = (64, 48)


def blob_map() -> SupportMap:
    """A 6³ brick map over [0, 60]³ mm holding an L-shaped blob and a lone brick."""
    moved = np.zeros((6, 6, 6), dtype=bool)
    moved[1:3, 1:4, 2:4] = True
    moved[1:3, 3, 4] = True
    moved[4, 4, 1] = True
    return SupportMap(np.zeros(3), np.full(3, 60.0), moved)


def camera(distance: float = 160.0) -> Camera:
    angle = np.radians(35.0)  # a view oblique to every axis
    rot = np.array(
        [
            [np.cos(angle), 0.0, np.sin(angle)],
            [0.0, 1.0, 0.0],
            [-np.sin(angle), 0.0, np.cos(angle)],
        ]
    )
    tilt = np.radians(-20.0)
    rot = (
        np.array(
            [[1.0, 0.0, 0.0], [0.0, np.cos(tilt), -np.sin(tilt)], [0.0, np.sin(tilt), np.cos(tilt)]]
        )
        @ rot
    )
    return Camera(center=(30.0, 30.0, 30.0), rotation=rot, distance=distance, fov=30.0)


def rays(inv_view_proj: np.ndarray, size: tuple[int, int] = SIZE) -> tuple[np.ndarray, np.ndarray]:
    """Origins and unit directions (H, W, 3) of the pixels' rays, row 0 at the bottom."""
    w, h = size
    x, y = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    ndc = np.stack([x / w * 2 - 1, y / h * 2 - 1], axis=-1)
    ends = []
    for z in (-1.0, 1.0):
        c = np.concatenate([ndc, np.full((h, w, 1), z), np.ones((h, w, 1))], axis=-1)
        p = c @ inv_view_proj.T
        ends.append(p[..., :3] / p[..., 3:])
    d = ends[1] - ends[0]
    return ends[0], d / np.linalg.norm(d, axis=-1, keepdims=True)


def brick_range(smap: SupportMap, ro: np.ndarray, rd: np.ndarray, grow: float) -> np.ndarray:
    """(H, W, 2): first entry and last exit of the rays into the support bricks, each
    grown by ``grow`` mm (negative: shrunk); (inf, -inf) where a ray meets none."""
    first = np.full(ro.shape[:2], np.inf)
    last = np.full(ro.shape[:2], -np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for idx in np.argwhere(smap.moved):
            lo = smap.lo + idx * smap.size - grow
            hi = lo + smap.size + 2 * grow
            ta, tb = (lo - ro) / rd, (hi - ro) / rd
            t_in = np.max(np.minimum(ta, tb), axis=-1)
            t_out = np.min(np.maximum(ta, tb), axis=-1)
            hit = (t_out >= t_in) & (t_out >= 0)
            first = np.where(hit, np.minimum(first, t_in), first)
            last = np.where(hit, np.maximum(last, t_out), last)
    return np.stack([first, last], axis=-1)


def read_ranges(
    ctx: Any, smap: SupportMap, inv: np.ndarray, size: tuple[int, int] = SIZE
) -> np.ndarray:
    """(H, W, 2) first and last crossing per pixel from a fresh pass (row 0 at the bottom)."""
    box = smap.moved_box()
    assert box is not None
    ranges = SupportRanges(ctx)
    try:
        tex = ranges.texture(smap, inv, size, box)
        tw, th = tex.size
        data = np.frombuffer(tex.read(), dtype=np.float32).reshape(th, tw, 4)
    finally:
        ranges.release()
    return data[: size[1], : size[0]][..., [0, 3]]


def check_ranges(got: np.ndarray, smap: SupportMap, ro: np.ndarray, rd: np.ndarray) -> None:
    """Every ray's range holds the bricks it crosses (shrunk by 0.05 mm: a ray grazing
    an edge may count the brick or not) and lies within the bricks grown by GROW of a
    brick (and 0.05 mm), to float32 rounding of the interpolated face point; a ray that
    misses the grown bricks has none."""
    inner = brick_range(smap, ro, rd, -0.05)
    outer = brick_range(smap, ro, rd, GROW * float(smap.size.max()) + 0.05)
    hit = np.isfinite(inner[..., 0])
    miss = ~np.isfinite(outer[..., 0])
    tol = 0.02
    g, a, b = got[hit], inner[hit], outer[hit]
    missed = ~((g[:, 0] <= a[:, 0] + tol) & (g[:, 1] >= a[:, 1] - tol))
    assert not missed.any(), f"{missed.sum()} rays through the support without its range"
    assert np.all((g[:, 0] >= b[:, 0] - tol) & (g[:, 1] <= b[:, 1] + tol))
    assert np.all(got[miss][:, 0] >= FAR * 0.5)
    assert np.all(got[miss][:, 1] <= -FAR * 0.5)


@pytest.mark.gl
@pytest.mark.parametrize("projection", ["perspective", "orthographic"])
def test_each_ray_gets_its_first_and_last_crossing_of_the_support(
    gl_ctx: Any, projection: str
) -> None:
    smap = blob_map()
    cam = camera()
    cam.projection = projection  # type: ignore[assignment]
    cam.ortho_height = 70.0
    inv = np.linalg.inv(cam.view_projection(SIZE[0] / SIZE[1]))
    got = read_ranges(gl_ctx, smap, inv)
    ro, rd = rays(inv)
    inner = brick_range(smap, ro, rd, -0.05)
    hit = np.isfinite(inner[..., 0])
    assert hit.mean() > 0.05, "the view must show the blob"
    assert (~np.isfinite(brick_range(smap, ro, rd, 1.0)[..., 0])).mean() > 0.3, "and beside it"
    check_ranges(got, smap, ro, rd)
    # rays through both of the blob's parts: the range spans the gap between them
    a = inner[hit]
    assert np.any(a[:, 1] - a[:, 0] > 2.5 * smap.size[0])


@pytest.mark.gl
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_merged_rows_leave_no_ray_without_its_range(gl_ctx: Any, seed: int) -> None:
    """A ragged blob (rows of every length: T-junctions everywhere between merged
    rectangles) seen from oblique angles at 256x192: every ray through a support brick
    gets its range. Without the widening, rasterisation left such rays uncovered (seen
    on the bundled scans: 1-2 pixels a frame drawn straight through the support)."""
    rng = np.random.default_rng(seed)
    moved = np.zeros((12, 12, 12), dtype=bool)
    centre = rng.uniform(4.0, 8.0, 3)
    idx = np.indices(moved.shape).transpose(1, 2, 3, 0) + 0.5
    moved[np.linalg.norm((idx - centre) / rng.uniform(2.5, 4.5, 3), axis=-1) < 1.0] = True
    moved &= rng.random(moved.shape) < 0.85  # a ragged surface
    smap = SupportMap(np.zeros(3), np.full(3, 60.0), moved)
    size = (256, 192)
    for yaw in (23.0, 67.0, 141.0):
        cam = camera()
        c, s_ = np.cos(np.radians(yaw)), np.sin(np.radians(yaw))
        cam.rotation = cam.rotation @ np.array([[c, 0.0, s_], [0.0, 1.0, 0.0], [-s_, 0.0, c]])
        inv = np.linalg.inv(cam.view_projection(size[0] / size[1]))
        got = read_ranges(gl_ctx, smap, inv, size)
        ro, rd = rays(inv, size)
        assert np.isfinite(brick_range(smap, ro, rd, -0.05)[..., 0]).mean() > 0.05
        check_ranges(got, smap, ro, rd)


@pytest.mark.gl
def test_a_camera_whose_near_plane_reaches_the_support_falls_back_to_the_box(
    gl_ctx: Any,
) -> None:
    """A ray starting inside a support brick crosses no face before it: the pass then
    leaves every range open, so the box alone bounds the chained phase."""
    smap = blob_map()
    cam = camera()
    cam.distance = 1.0  # the eye at the box's centre, inside the blob's box
    got = read_ranges(gl_ctx, smap, np.linalg.inv(cam.view_projection(SIZE[0] / SIZE[1])))
    assert np.all(got[..., 0] <= -FAR * 0.5)
    assert np.all(got[..., 1] >= FAR * 0.5)


@pytest.mark.gl
def test_a_scattered_support_leaves_the_ranges_open(gl_ctx: Any) -> None:
    """A surface of more than MAX_TRIANGLES triangles would cost more to rasterise than it
    saves: the box bounds the rays instead (every range open)."""
    moved = np.random.default_rng(5).random((32, 32, 32)) < 0.3
    smap = SupportMap(np.zeros(3), np.full(3, 60.0), moved)
    assert len(smap.boundary_triangles()) > MAX_TRIANGLES
    got = read_ranges(gl_ctx, smap, np.linalg.inv(camera().view_projection(SIZE[0] / SIZE[1])))
    assert np.all(got[..., 0] <= -FAR * 0.5)
    assert np.all(got[..., 1] >= FAR * 0.5)


@pytest.mark.gl
def test_the_same_camera_reads_the_ranges_drawn_last_a_new_one_draws_them(gl_ctx: Any) -> None:
    """A draw that asks again for the map, camera and size the target holds skips the
    pass; any change (camera, map) draws it anew, with that view's ranges."""
    smap = blob_map()
    box = smap.moved_box()
    assert box is not None
    views = []
    for distance in (160.0, 120.0):
        views.append(np.linalg.inv(camera(distance).view_projection(SIZE[0] / SIZE[1])))
    ranges = SupportRanges(gl_ctx)
    drawn: list[int] = []
    vao_of = ranges._vao
    ranges._vao = lambda m: drawn.append(1) or vao_of(m)  # type: ignore[method-assign]

    def read(inv: np.ndarray, m: SupportMap = smap) -> np.ndarray:
        tex = ranges.texture(m, inv, SIZE, box)
        tw, th = tex.size
        data = np.frombuffer(tex.read(), dtype=np.float32).reshape(th, tw, 4)
        return data[: SIZE[1], : SIZE[0]][..., [0, 3]]

    try:
        for inv in (views[0], views[0], views[1], views[0]):
            check_ranges(read(inv), smap, *rays(inv))
        assert len(drawn) == 3  # the repeated first view read what was there
        other = SupportMap(smap.lo, smap.hi, smap.moved.copy())  # the same bricks, anew
        check_ranges(read(views[0], other), other, *rays(views[0]))
        assert len(drawn) == 4
    finally:
        ranges.release()
