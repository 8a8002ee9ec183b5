"""Warped rays and slices pay for the chain only inside its support.

Oracles, in one process with the old path (``Renderer.support_skipping = False``, the
chain at every sample) as the reference:

* a warp that moves nothing draws exactly the undeformed image (and slice);
* a local drag (an offset field over the volume's box, one node moved): pixels whose rays
  miss every support brick (computed on the CPU from the camera), even where they cross
  the box around the bricks, equal the undeformed image exactly, every pixel is within
  1/255 of the old path, and the drag changes the image by more than that somewhere (so
  the test can fail);
* the same for a shaded mode (straight samples keep the identity Jacobian) and for the
  per-block loop of warped rays (mip), and for slices.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from voxwarp.core.camera import Camera
from voxwarp.core.volume import Volume
from voxwarp.deform.elements.offset_field import OffsetFieldWarp
from voxwarp.deform.support import SupportMap, chain_support
from voxwarp.io.samples import load_sample
from voxwarp.render.skipping.support import BRICK_VOXELS, MAP_MAX_FRACTION, TOLERANCE_VOXELS
from voxwarp.scene import Scene

SIZE = (96, 80)


@pytest.fixture(scope="module")
def head() -> Volume:
    return load_sample("colin27").downsample(2)


def offset_warp(vol: Volume, moved: bool) -> OffsetFieldWarp:
    """A 9³ offset field over the volume's box (so the ray box is the volume's): zero, or
    a node near the face dragged 10 mm sideways and its neighbours 5 mm."""
    lo, hi = vol.bounds
    u = np.zeros((9, 9, 9, 3))
    if moved:
        u[4, 7, 5] = (10.0, 0.0, -3.0)
        for d in ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)):
            u[4 + d[0], 7 + d[1], 5 + d[2]] = (5.0, 0.0, -1.5)
    return OffsetFieldWarp(lo, hi, u, inverse="baked")


def draw(offscreen: Any, scene: Scene, support: bool) -> np.ndarray:
    r = offscreen(*SIZE)
    r.renderer.support_skipping = support
    try:
        img = np.asarray(r.render(scene)).astype(int)
        r.render(scene)  # the second draw of a warp state uses its deformed-space maps
        img2 = np.asarray(r.render(scene)).astype(int)
        assert np.array_equal(img, img2) or np.abs(img - img2).max() <= 1
        return img2
    finally:
        r.renderer.support_skipping = True


def rays_missing(scene: Scene, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels whose ray misses the box [lo, hi] (row 0 at the top)."""
    w, h = SIZE
    inv = np.linalg.inv(scene.resolved_camera().view_projection(w / h))
    x, y = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    ndc = np.stack([x / w * 2 - 1, y / h * 2 - 1], axis=-1).reshape(-1, 2)
    ends = []
    for z in (-1.0, 1.0):
        c = np.concatenate([ndc, np.full((len(ndc), 1), z), np.ones((len(ndc), 1))], axis=1)
        p = c @ inv.T
        ends.append(p[:, :3] / p[:, 3:])
    ro, rd = ends[0], ends[1] - ends[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        ta, tb = (lo - ro) / rd, (hi - ro) / rd
    t_in = np.nanmax(np.minimum(ta, tb), axis=1)
    t_out = np.nanmin(np.maximum(ta, tb), axis=1)
    miss = (t_out < t_in) | (t_out < 0)
    return miss.reshape(h, w)[::-1]


def support_map(scene: Scene) -> SupportMap:
    voxel = float(np.min(scene.volume.spacing))
    lo, hi = scene.ray_bounds()
    return chain_support(scene.warps, lo, hi, BRICK_VOXELS * voxel, TOLERANCE_VOXELS * voxel)


def rays_missing_bricks(scene: Scene, margin: float) -> np.ndarray:
    """(H, W) bool: pixels whose ray misses every support brick grown by ``margin``."""
    smap = support_map(scene)
    miss = np.ones(SIZE[::-1], dtype=bool)
    for idx in np.argwhere(smap.moved):
        lo = smap.lo + idx * smap.size
        miss &= rays_missing(scene, lo - margin, lo + smap.size + margin)
    return miss


@pytest.mark.gl
@pytest.mark.parametrize("mode", ["dvr", "mip"])
def test_a_warp_that_moves_nothing_draws_the_undeformed_image(
    offscreen: Any, head: Volume, mode: str
) -> None:
    plain = Scene(head, mode=mode, view="left")
    still = plain.copy(warps=[offset_warp(head, moved=False)])
    image = draw(offscreen, still, True)
    assert offscreen(*SIZE).renderer.last_support == "none"
    assert np.array_equal(image, draw(offscreen, plain, True))
    draw(offscreen, still, False)
    assert offscreen(*SIZE).renderer.last_support == "all"


@pytest.mark.gl
@pytest.mark.parametrize(("mode", "shading"), [("dvr", False), ("dvr", True), ("mip", None)])
def test_a_local_drag_changes_only_the_rays_through_its_support(
    offscreen: Any, head: Volume, mode: str, shading: bool | None
) -> None:
    plain = Scene(head, mode=mode, view="anterior", shading=shading)
    scene = plain.copy(warps=[offset_warp(head, moved=True)])
    new = draw(offscreen, scene, True)
    assert offscreen(*SIZE).renderer.last_support == "map"
    old = draw(offscreen, scene, False)
    undeformed = draw(offscreen, plain, True)
    assert np.abs(new - old).max() <= 1, "within 1/255 of the chain at every sample"
    moved = np.abs(old - undeformed).max(axis=-1) > 1
    assert moved.mean() > 0.003, "the drag must show (else the test is empty)"
    miss = rays_missing_bricks(scene, margin=0.5)
    box = support_map(scene).moved_box()
    assert box is not None
    in_box = ~rays_missing(scene, box[0] - 0.5, box[1] + 0.5)
    assert 0.2 < miss.mean() < 0.98
    assert (miss & in_box).mean() > 0.01, "some rays cross the box but no brick"
    assert np.array_equal(new[miss], undeformed[miss]), "straight outside: the same texels"


def oblique(vol: Volume) -> Volume:
    """``vol`` with its index axes turned 25 degrees about z and 15 about x (an oblique
    acquisition: the volume's box is no longer the world box its rays march in)."""
    a, b = np.radians(25.0), np.radians(15.0)
    rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    return Volume(
        vol.data, vol.spacing, vol.origin, direction=rz @ rx, space=vol.space, name="oblique head"
    )


@pytest.mark.gl
def test_an_oblique_volume_keeps_its_straight_rays_exact(offscreen: Any, head: Volume) -> None:
    """The support is bricked in world space over the ray box and straight samples go
    through the volume's own world -> texel matrix: on an oblique scan too, rays that
    miss every support brick draw the undeformed image exactly, and the rest stay
    within 1/255 of the chain at every sample."""
    vol = oblique(head)
    assert vol.is_oblique
    plain = Scene(vol, view="anterior")
    scene = plain.copy(warps=[offset_warp(vol, moved=True)])
    new = draw(offscreen, scene, True)
    assert offscreen(*SIZE).renderer.last_support == "map"
    old = draw(offscreen, scene, False)
    undeformed = draw(offscreen, plain, True)
    assert np.abs(new - old).max() <= 1
    assert (np.abs(old - undeformed).max(axis=-1) > 1).mean() > 0.003, "the drag shows"
    miss = rays_missing_bricks(scene, margin=0.5)
    assert 0.2 < miss.mean() < 0.98
    assert np.array_equal(new[miss], undeformed[miss])


@pytest.mark.gl
def test_a_nearly_empty_view_draws_the_chain_everywhere(offscreen: Any, head: Volume) -> None:
    """Where the transfer function shows fewer than MAP_MIN_VISIBLE of the deformed-space
    cells, the same local drag is drawn with the chain at every sample (the map path's
    loops would cost more than the few chained samples they save): the old path's image
    exactly; a view that shows more keeps the map path."""
    from voxwarp.core.transfer_function import TransferFunction
    from voxwarp.render.skipping.support import MAP_MIN_VISIBLE

    top = float(np.percentile(np.asarray(head.data), 99.95))  # the brightest voxels only
    tf = TransferFunction([(0, 0, 0, 0, 0), (top, 1, 1, 1, 0), (top + 1, 1, 1, 1, 0.8)])
    sparse = Scene(head, view="anterior", transfer_function=tf)
    scene = sparse.copy(warps=[offset_warp(head, moved=True)])
    new = draw(offscreen, scene, True)
    r = offscreen(*SIZE).renderer
    gpu = r._volume_gpu(head)
    assert r._skip_maps.warped_fraction(gpu.skip, scene) < MAP_MIN_VISIBLE
    assert r.last_support == "all"
    assert np.array_equal(new, draw(offscreen, scene, False))
    assert new.any(), "the view shows something"
    dense = Scene(head, view="anterior").copy(warps=scene.warps)
    draw(offscreen, dense, True)
    assert r._skip_maps.warped_fraction(gpu.skip, dense) >= MAP_MIN_VISIBLE
    assert r.last_support == "map"


@pytest.mark.gl
def test_slices_pay_for_the_chain_only_inside_the_support(offscreen: Any, head: Volume) -> None:
    r = offscreen(*SIZE).renderer
    lo, hi = head.bounds
    node = lo + np.array([4, 7, 5]) / 8.0 * (hi - lo)  # the dragged node
    size, step = (90, 110), 0.7 * float(np.min(head.spacing))
    m = np.eye(4)  # an axial plane through the node, row 0 anterior
    m[:3, :3] = np.diag([step, -step, 1.0])
    m[:3, 3] = node - (45 * step, -55 * step, 0.0)
    out = {}
    for moved in (False, True):
        scene = Scene(head, warps=[offset_warp(head, moved)])
        for support in (True, False):
            r.slice_values(scene, m, (2, 2))  # makes the slice renderer
            r._slice_renderer.support.enabled = support
            out[moved, support] = r.slice_values(scene, m, size)
            r._slice_renderer.support.enabled = True
    rest = out[False, False][..., 2]
    np.testing.assert_array_equal(out[False, True][..., 0], rest)  # drawn without the warp
    deformed_new, deformed_old = out[True, True][..., 0], out[True, False][..., 0]
    value_range = float(np.ptp(np.asarray(head.data)))
    assert (np.abs(deformed_old - rest) > 0.01 * value_range).mean() > 0.01, "the drag shows"
    assert np.abs(deformed_new - deformed_old).max() <= 1e-3 * value_range
    still = np.abs(deformed_old - rest) == 0
    assert still.mean() > 0.3
    np.testing.assert_array_equal(deformed_new[still], rest[still])


@pytest.mark.gl
def test_a_warp_state_gets_its_map_when_drawn_a_second_time(offscreen: Any, head: Volume) -> None:
    """ "auto": a state that changes every frame (a drag) never builds a map, nor reads a
    GPU model's field back; asking needs_skip_maps is no draw."""
    r = offscreen(*SIZE)
    scene = Scene(head, view="anterior", warps=[offset_warp(head, moved=True)])
    r.renderer.needs_skip_maps(scene)
    r.render(scene)
    assert r.renderer.last_support == "all"
    r.renderer.needs_skip_maps(scene)
    r.render(scene)
    assert r.renderer.last_support == "map"
    r.renderer.support_maps = "always"
    try:
        other = scene.copy(warps=[offset_warp(head, moved=False)])
        r.render(other)
        assert r.renderer.last_support == "none"
    finally:
        r.renderer.support_maps = "auto"


@pytest.mark.gl
@pytest.mark.parametrize("projection", ["perspective", "orthographic"])
def test_a_camera_inside_the_support_draws_what_the_chain_draws(
    offscreen: Any, head: Volume, projection: str
) -> None:
    """An eye inside the support's box (rays start inside a support brick, where the
    per-pixel ranges cannot see an entry face): the box bounds those rays, and the image
    stays within 1/255 of the chain at every sample."""
    lo, hi = head.bounds
    node = lo + np.array([4, 7, 5]) / 8.0 * (hi - lo)  # the dragged node
    cam = Camera(center=tuple(node), distance=2.0, fov=60.0, projection=projection)
    cam.ortho_height = 60.0
    scene = Scene(head, mode="dvr", camera=cam, warps=[offset_warp(head, moved=True)])
    new = draw(offscreen, scene, True)
    assert offscreen(*SIZE).renderer.last_support == "map"
    old = draw(offscreen, scene, False)
    undeformed = draw(offscreen, scene.copy(warps=[]), True)
    assert np.abs(old - undeformed).max() > 1, "the drag must show"
    assert np.abs(new - old).max() <= 1


@pytest.fixture(scope="module")
def head_wire() -> tuple[Volume, Any]:
    """Colin27 and the cost table's head wire (rigid sides, bent and twisted top) at
    1:8: the swept part leaves vacated places behind, where nothing shows."""
    from benchmarks.wires import HEAD_WIRE
    from voxwarp.deform.wires.build import WireDeformer
    from voxwarp.deform.wires.wire import Wire

    vol = load_sample("colin27")
    deformer = WireDeformer(vol, [Wire(**HEAD_WIRE)], field_scale=2)
    deformer.build()
    return vol, deformer.warp()


@pytest.mark.gl
def test_a_wires_vacated_place_stays_empty_where_the_map_is_read(
    offscreen: Any, head_wire: tuple[Volume, Any]
) -> None:
    # oracle: the CPU's mapping (a vacated point shows nothing: NaN in a slice) and the
    # chain at every pixel / sample (a state's first draw, and the old path); before
    # vacated voxels counted as moved, the map path showed the moved part's old place
    vol, warp = head_wire
    scene = Scene(vol, view="anterior", warps=[warp])
    r = offscreen(*SIZE)
    first = r.render_slice(scene, "axial", at=60.0)
    support = r.renderer._slice_renderer.support
    support.map_max_fraction = 1.0  # read the map however much of the box it covers
    try:
        second = r.render_slice(scene, "axial", at=60.0)
        lo, hi = scene.deformed_bounds()
        box = (np.minimum(lo, vol.bounds[0]), np.maximum(hi, vol.bounds[1]))
        assert support.plan(scene, box, draw=False) == "map"  # the second draw read it
    finally:
        support.map_max_fraction = MAP_MAX_FRACTION
    h, w = first.values.shape
    rows, cols = np.mgrid[0:h, 0:w]
    pix = np.stack([cols.ravel(), rows.ravel(), 0 * rows.ravel(), 1 + 0 * rows.ravel()])
    far = warp.apply((first.pixel_to_world @ pix.astype(float))[:3].T)[:, 0] >= 1e19
    far = far.reshape(h, w)
    assert far.sum() >= 100  # the wire vacates part of this plane
    for img in (first, second):
        assert not np.isfinite(img.values[far]).any(), "content shows where the object left"
    np.testing.assert_array_equal(np.isfinite(second.values), np.isfinite(first.values))
    ok = np.isfinite(first.values)
    value_range = float(np.ptp(np.asarray(vol.data)))
    assert np.abs(second.values[ok] - first.values[ok]).max() <= 1e-3 * value_range
    # 3D: the map path against the chain at every sample
    r.renderer._support.map_max_fraction = 1.0
    try:
        with_map = draw(offscreen, scene, True)
        assert r.renderer.last_support == "map"
    finally:
        r.renderer._support.map_max_fraction = MAP_MAX_FRACTION
    everywhere = draw(offscreen, scene, False)
    assert np.abs(with_map - everywhere).max() <= 1
