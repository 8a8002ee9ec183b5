"""Per-pixel ray ranges through the chain's support (voxwarp.render.support_ranges).

Oracle: the first and last ray parameter at which each pixel's ray lies in a support
brick, by slab tests against every brick on the CPU (the ray built as the raycaster
builds it). Pixels whose ray passes within a hair of a brick's edge are left out (either
answer is right there).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from voxwarp.core.camera import Camera
from voxwarp.deform.support import SupportMap
from voxwarp.render.support_ranges import FAR, MAX_TRIANGLES, SupportRanges

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


def rays(inv_view_proj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Origins and unit directions (H, W, 3) of the pixels' rays, row 0 at the bottom."""
    w, h = SIZE
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


def read_ranges(ctx: Any, smap: SupportMap, inv: np.ndarray) -> np.ndarray:
    """(H, W, 2) first and last crossing per pixel from a fresh pass (row 0 at the bottom)."""
    box = smap.moved_box()
    assert box is not None
    ranges = SupportRanges(ctx)
    try:
        tex = ranges.texture(smap, inv, SIZE, box)
        tw, th = tex.size
        data = np.frombuffer(tex.read(), dtype=np.float32).reshape(th, tw, 4)
    finally:
        ranges.release()
    return data[: SIZE[1], : SIZE[0]][..., [0, 3]]


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
    outer = brick_range(smap, ro, rd, 0.05)
    hit = np.isfinite(inner[..., 0])
    miss = ~np.isfinite(outer[..., 0])
    assert hit.mean() > 0.05, "the view must show the blob"
    assert miss.mean() > 0.3, "and rays beside it"
    # between the ranges of the bricks shrunk and grown by 0.05 mm (a ray grazing a
    # brick may count it or not), to float32 rounding of the interpolated face point
    tol = 0.02
    g, a, b = got[hit], inner[hit], outer[hit]
    assert np.all((g[:, 0] >= b[:, 0] - tol) & (g[:, 0] <= a[:, 0] + tol))
    assert np.all((g[:, 1] >= a[:, 1] - tol) & (g[:, 1] <= b[:, 1] + tol))
    assert np.all(got[miss][:, 0] >= FAR * 0.5)
    assert np.all(got[miss][:, 1] <= -FAR * 0.5)
    # rays through both of the blob's parts: the range spans the gap between them
    assert np.any(a[:, 1] - a[:, 0] > 2.5 * smap.size[0])


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
