"""Oracle tests of the ``xray`` render mode (shaders/mode_xray.glsl) against ``average``.

``xray`` is a radiograph: the line integral of ``max(v - w_lo, 0)`` along the ray (mm),
divided by the fixed reference length ``L`` (the longest edge of the volume box,
:func:`voxwarp.render.raycaster.xray_reference_length`) and by the window's width. So
with the window ``w_lo = 0, width = V`` a ray crossing ``c`` mm of value ``V`` shows
``c / L``. ``average`` is the thesis's mean along the ray (Knoche 2008, section 2.3.2):
the same uniform material shows the same grey whatever its thickness, and rays that
cross the box near its faces (a few samples) give bright caps.

Oracles: the analytic chord of a sphere and the analytic path through a box, and a
numpy raycaster (trilinear samples every 0.1 mm along the same rays) for a cylinder that
touches the box's faces. Images are float32 (no 8-bit rounding); ``jitter=False``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from scipy import ndimage

from tests.render.test_render import (
    GenericAffine,
    GenericIdentity,
    aligned_camera,
    grey_scene,
    phantom,
    render,
)
from voxwarp.core.camera import Camera, view_rotation
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import AffineWarp
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.render.raycaster import xray_reference_length
from voxwarp.render.skipping.maps import BLOCK, block_min_max, static_block_visibility
from voxwarp.scene import Scene

BLUE = (0.0, 0.0, 1.0, 1.0)
V = 1000.0  # value of the uniform objects


# ---------------------------------------------------------------------- volumes
def pv_sphere(n: int, radius: float, spacing: float) -> Volume:
    """n³ float32 zeros with a centred sphere of value V and ``radius`` voxels; the rim
    is partial-volume antialiased (one voxel ramp centred on the radius), so a line
    integral through the trilinear field is close to V x the analytic chord."""
    c = (n - 1) / 2
    i, j, k = np.meshgrid(*(np.arange(n, dtype=float) - c,) * 3, indexing="ij")
    d = np.sqrt(i * i + j * j + k * k)
    a = V * np.clip(radius - d + 0.5, 0.0, 1.0)
    return Volume(a.astype(np.float32), spacing=(spacing,) * 3, name="sphere")


def uniform_box(shape: tuple[int, int, int], spacing: tuple[float, float, float]) -> Volume:
    return Volume(np.full(shape, V, np.float32), spacing=spacing, name="box")


def cylinder_through_faces() -> Volume:
    """40x40x48 zeros with a z-axis cylinder (radius 12 voxels, value V) from the bottom
    face to the top face (partial-volume rim): an object touching the box's faces, as a
    body runs out of a CT's field of view."""
    shape = (40, 40, 48)
    i, j = np.meshgrid(np.arange(40.0) - 19.5, np.arange(40.0) - 19.5, indexing="ij")
    disc = V * np.clip(12.0 - np.sqrt(i * i + j * j) + 0.5, 0.0, 1.0)
    a = np.repeat(disc[:, :, None], shape[2], axis=2)
    return Volume(a.astype(np.float32), name="cylinder")


# ---------------------------------------------------------------------- rays
def oblique_camera(vol: Volume, view: tuple[float, float], size: int) -> Camera:
    """Orthographic camera from ``view`` (azimuth, elevation) showing the whole box."""
    radius = float(np.linalg.norm(vol.size_mm)) / 2
    return Camera(
        center=vol.center,
        rotation=view_rotation(view),
        distance=4 * radius,
        projection="orthographic",
        ortho_height=2.1 * radius,
        radius=radius,
    )


def pixel_rays(cam: Camera, w: int, h: int) -> tuple[np.ndarray, np.ndarray]:
    """World ray origins and unit directions (h, w, 3) of the pixel centres, image row 0
    at the top, unprojected as raycast.frag.glsl does (near -> far plane)."""
    inv = np.linalg.inv(cam.view_projection(w / h))
    x = (np.arange(w) + 0.5) / w * 2 - 1
    y = 1 - (np.arange(h) + 0.5) / h * 2
    nx, ny = np.meshgrid(x, y)
    ends = []
    for z in (-1.0, 1.0):
        p = np.stack([nx, ny, np.full_like(nx, z), np.ones_like(nx)], axis=-1) @ inv.T
        ends.append(p[..., :3] / p[..., 3:])
    d = ends[1] - ends[0]
    return ends[0], d / np.linalg.norm(d, axis=-1, keepdims=True)


def box_interval(vol: Volume, ro: np.ndarray, rd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Entry and exit ray parameters (mm) through the volume box (exit <= entry: miss)."""
    lo, hi = vol.bounds
    with np.errstate(divide="ignore", invalid="ignore"):
        ta, tb = (lo - ro) / rd, (hi - ro) / rd
    t0 = np.nanmax(np.minimum(ta, tb), axis=-1)
    t1 = np.nanmin(np.maximum(ta, tb), axis=-1)
    return np.maximum(t0, 0.0), t1


def numpy_ray_integrals(vol: Volume, cam: Camera, w: int, h: int, ds: float = 0.1) -> tuple:
    """Per pixel: the path (mm) through the box, the integral of the trilinear field
    along it (value x mm) and its mean, from samples every ``ds`` mm (clamp to edge)."""
    ro, rd = pixel_rays(cam, w, h)
    t0, t1 = box_interval(vol, ro, rd)
    path = np.maximum(t1 - t0, 0.0)
    integral = np.zeros(path.shape)
    hit = path > 0
    n = int(np.ceil(path.max() / ds))
    frac = (np.arange(n) + 0.5) / n  # midpoints of n equal pieces of each ray's path
    pts = ro[hit][:, None] + rd[hit][:, None] * (
        t0[hit][:, None, None] + frac[None, :, None] * path[hit][:, None, None]
    )
    idx = vol.world_to_index(pts.reshape(-1, 3)).T
    vals = ndimage.map_coordinates(vol.data.astype(np.float64), idx, order=1, mode="nearest")
    integral[hit] = vals.reshape(-1, n).mean(axis=1) * path[hit]
    with np.errstate(invalid="ignore"):
        mean = np.where(hit, integral / np.where(hit, path, 1.0), 0.0)
    return path, integral, mean


def scene_at(vol: Volume, mode: str, cam: Camera, window: tuple, **kw: Any) -> Scene:
    return Scene(
        vol,
        mode=mode,
        transfer_function="grayscale",
        projection="orthographic",
        window=window,
        jitter=False,
        camera=cam,
        background=BLUE,
        **kw,
    )


def lo_width(lo: float, width: float) -> tuple[float, float]:
    """(level, width) of the window ``lo .. lo + width``."""
    return (lo + width / 2, width)


# ---------------------------------------------------------------------- reference length
def test_reference_length_is_the_longest_box_edge() -> None:
    vol = Volume(np.zeros((10, 20, 30), np.uint8), spacing=(3.0, 1.0, 0.5))
    assert xray_reference_length(vol) == 30.0  # 10 x 3 mm beats 20 x 1 and 30 x 0.5
    assert xray_reference_length(vol.with_geometry(origin=(5.0, -7.0, 2.0))) == 30.0


# ---------------------------------------------------------------------- oracle 1: chords
@pytest.mark.parametrize(("view", "spacing"), [("+z", 1.0), ("-x", 0.5)])
def test_sphere_is_proportional_to_its_chord(offscreen: Any, view: str, spacing: float) -> None:
    """Orthographic xray of a sphere of value V in zeros: grey = chord / L.

    Window 0 .. V, so the grey of a pixel is the chord (mm) through the sphere divided
    by L = 64 voxels x spacing. Pixels whose chord is at least 30 % of the diameter
    (the partial-volume rim and the sample lattice matter less there) are within 2 % of
    the analytic value (measured: 1.1 %); over every pixel of the centre row and column
    the correlation with the chord is >= 0.999 (measured 0.99998) and the error <= 0.015
    grey (measured 0.009, at the antialiased rim).
    """
    n, radius = 64, 22.0
    vol = pv_sphere(n, radius, spacing)
    cam, size = aligned_camera(vol, view, pixel=spacing)  # one pixel per voxel
    scene = grey_scene(vol, "xray", view, cam, window=lo_width(0.0, V), step=0.25)
    img = render(offscreen, scene, size)[..., 0].astype(np.float64)
    L = xray_reference_length(vol)
    assert L == pytest.approx(n * spacing)
    # pixel centres sit on voxel centres: offset (voxels) from the sphere's axis
    c = (n - 1) / 2
    rows, cols = np.meshgrid(np.arange(size[1]), np.arange(size[0]), indexing="ij")
    d = np.hypot(cols - c, rows - c)
    chord = 2 * np.sqrt(np.maximum(radius**2 - d**2, 0.0)) * spacing  # mm
    expected = chord / L
    mid = n // 2
    line = np.concatenate([img[mid, :], img[:, mid]])
    line_expected = np.concatenate([expected[mid, :], expected[:, mid]])
    assert np.corrcoef(line, line_expected)[0, 1] >= 0.999
    assert np.max(np.abs(line - line_expected)) <= 0.015
    inner = chord >= 0.3 * 2 * radius * spacing
    ratio = img[inner] / expected[inner]
    assert np.max(np.abs(ratio - 1.0)) <= 0.02, (ratio.min(), ratio.max())
    # whole image: proportional to the chord (correlation) and dark outside the sphere
    assert np.corrcoef(img.ravel(), expected.ravel())[0, 1] >= 0.999
    assert np.max(img[d > radius + 1.5]) <= 1e-6
    # the brightest pixel is the longest chord: the diameter over L
    assert img.max() == pytest.approx(2 * radius / n, rel=0.01)


# ---------------------------------------------------------------------- oracle 2: no caps
def test_uniform_box_grows_with_path_where_average_is_constant(offscreen: Any) -> None:
    """An oblique orthographic view of a uniform box (value V): each pixel's ray crosses
    the box over a different length (short near the silhouette, long through the
    middle). xray = V x path / L / width (window 0 .. 2V: nothing clips), within the
    sample lattice's error: the samples (step s = 0.25 mm, one at the middle of each
    step) cover the path to within s / 2, so |error| <= s / 2 x V / L / width (+ 1e-4
    round-off) on every pixel, and <= 1 % where the path exceeds 20 mm. It grows
    monotonically with the path. average is V through the window (0.5) on every pixel
    the box covers, short paths included: it does not see thickness."""
    vol = uniform_box((40, 30, 20), (1.0, 1.0, 1.5))
    cam = oblique_camera(vol, (35.0, 25.0), 96)
    w = h = 96
    window = lo_width(0.0, 2 * V)
    L = xray_reference_length(vol)
    path, _, _ = numpy_ray_integrals(vol, cam, w, h)
    img = render(offscreen, scene_at(vol, "xray", cam, window, step=0.25), (w, h))[..., 0]
    avg = render(offscreen, scene_at(vol, "average", cam, window, step=0.25), (w, h))[..., 0]
    expected = path * V / L / (2 * V)
    step = 0.25  # mm: 0.25 x the smallest spacing
    hit = path > 0
    assert hit.sum() > 0.3 * w * h  # the box fills a good part of the image
    err = np.abs(img - expected)[hit]
    assert err.max() <= step / 2 / L / 2 + 1e-4, err.max()
    long = path > 20.0
    rel = np.abs(img[long] / expected[long] - 1.0)
    assert rel.max() <= 0.01, rel.max()
    assert np.corrcoef(img[hit], expected[hit])[0, 1] >= 0.999
    long = path > 4.0
    # monotonic: sorted by path length, the grey never drops by more than the lattice
    # error of one sample (step 0.25 mm x V / L / 2V)
    order = np.argsort(path[long])
    g = img[long][order]
    assert np.min(np.diff(g)) >= -step / L / 2 - 1e-4
    assert g[-1] > 5 * g[0]  # and it spans a real range (thin corner vs. thick middle)
    # average: constant 0.5 (V through the window 0 .. 2V) wherever the ray meets the box
    covered = path > 0.5
    np.testing.assert_allclose(avg[covered], 0.5, atol=2e-3)
    # nothing outside the box: background for both
    outside = path == 0
    assert outside.sum() > 0.1 * w * h
    assert np.all(img[outside] == 0.0)
    assert np.all(avg[outside] == 0.0)


def test_box_faces_give_average_caps_but_not_xray(offscreen: Any) -> None:
    """A cylinder running through the box's top and bottom faces (as a body through a
    CT's field of view), seen obliquely (elevation 30°). Rays that leave the box through
    its top or bottom face while inside the cylinder skip the air behind it: their path
    is shorter, but a larger share of it lies in the cylinder. average (the mean over the
    box path) makes them brighter than the rays through the middle: caps (numpy: 0.75
    against 0.6). xray (the integral) counts the material crossed, the same cylinder
    chord: no brighter than the middle. Both match a numpy raycaster of
    the same rays (trilinear samples every 0.1 mm): xray within 0.005 grey and average
    within 0.02 where the path exceeds 4 mm (measured: 0.0016 and 0.005)."""
    vol = cylinder_through_faces()
    cam = oblique_camera(vol, (0.0, 30.0), 96)
    w = h = 96
    window = lo_width(0.0, V)
    L = xray_reference_length(vol)
    path, integral, mean = numpy_ray_integrals(vol, cam, w, h)
    img = render(offscreen, scene_at(vol, "xray", cam, window, step=0.25), (w, h))[..., 0]
    avg = render(offscreen, scene_at(vol, "average", cam, window, step=0.25), (w, h))[..., 0]
    long = path > 4.0
    assert np.abs(img - integral / L / V)[long].max() <= 0.005
    assert np.abs(avg - mean / V)[long].max() <= 0.02
    # the centre column: the rays through the cylinder's axis
    col = w // 2
    rows = np.flatnonzero(path[:, col] > 0)
    middle = rows[len(rows) // 2]
    assert path[middle, col] == pytest.approx(path[:, col].max(), rel=0.01)
    for half in (rows[rows < middle], rows[rows > middle]):  # top and bottom
        cap = half[np.argmax(avg[half, col])]
        assert path[cap, col] < 0.9 * path[middle, col]  # a shorter ray
        assert avg[cap, col] > avg[middle, col] + 0.1, "average has a bright cap"
        # xray counts the cylinder crossed (the same chord here): no cap
        assert img[cap, col] <= img[middle, col] + 0.005, "xray has a bright cap"
    # xray's brightest pixels of the column are the longest cylinder chords
    assert img[middle, col] >= img[:, col].max() - 0.005


# ---------------------------------------------------------------------- oracle 3: window
def test_window_changes_the_image_as_stated(offscreen: Any) -> None:
    """The window's low end is zero attenuation and its width the grey scale: doubling
    the width (same low end) halves every unclipped grey; raising the low end to the
    sphere's value V makes the sphere vanish (values at or below it add nothing)."""
    vol = pv_sphere(40, 14.0, 1.0)
    cam, size = aligned_camera(vol, "+z")
    a = render(offscreen, grey_scene(vol, "xray", "+z", cam, window=lo_width(0.0, V)), size)
    b = render(offscreen, grey_scene(vol, "xray", "+z", cam, window=lo_width(0.0, 2 * V)), size)
    c = render(offscreen, grey_scene(vol, "xray", "+z", cam, window=lo_width(V, V)), size)
    a, b, c = (x[..., 0].astype(float) for x in (a, b, c))
    assert a.max() > 0.5  # not clipped (2 x 14 / 40 = 0.7) and not empty
    assert np.abs(a - b).mean() > 0.05  # the window change changes the image
    np.testing.assert_allclose(b, a / 2, atol=1e-4)
    assert c.max() == 0.0


# ---------------------------------------------------------------------- warps
@pytest.mark.parametrize("warp_cls", [AffineWarp, GenericAffine])
def test_translation_shifts_and_stretch_brightens_xray(offscreen: Any, warp_cls: type) -> None:
    """Through a warp (folded affine and the generic warp-chain path): a translation of
    3 mm along +x moves the image 3 columns right; stretching the object 1.5x along the
    ray (about its centre) makes it 1.5x brighter, since the line integral is taken in
    deformed space (L stays the undeformed box's)."""
    vol = pv_sphere(32, 10.0, 1.0)
    cam, size = aligned_camera(vol, "+z")
    window = lo_width(0.0, V)
    base = render(offscreen, grey_scene(vol, "xray", "+z", cam, window=window), size)
    k = 3
    moved = render(
        offscreen,
        grey_scene(vol, "xray", "+z", cam, window=window, warps=[warp_cls.translation((k, 0, 0))]),
        size,
    )
    np.testing.assert_allclose(moved[:, k:, 0], base[:, :-k, 0], atol=1e-4)
    assert np.all(moved[:, :k, 0] < 1e-6)
    stretch = warp_cls(AffineWarp.scaling((1.0, 1.0, 1.5), center=vol.center).forward_matrix)
    scene = grey_scene(vol, "xray", "+z", cam, window=window, warps=[stretch], step=0.25)
    tall = render(offscreen, scene, size)[..., 0].astype(float)
    ref = render(offscreen, grey_scene(vol, "xray", "+z", cam, window=window, step=0.25), size)
    inner = ref[..., 0] > 0.2
    np.testing.assert_allclose(tall[inner] / ref[..., 0][inner], 1.5, rtol=0.02)


# ---------------------------------------------------------------------- skipping
def test_block_skipping_leaves_the_xray_unchanged(gl_ctx: Any) -> None:
    """Blocks whose values all lie at or below the window's low end add nothing, so
    warped xray rays skip them (block checks); the image equals the one without any
    skipping. Straight rays march plainly (skip checks cost more than they save)."""
    vol = phantom()
    kw = {"mode": "xray", "view": (30, 20), "window": (0.0, 2000.0), "zoom": 1.25}
    visible = static_block_visibility(Scene(vol, **kw), *block_min_max(vol.data, BLOCK))
    assert 0.05 < visible.mean() < 0.95  # air blocks (-1000 HU = the window's low end)
    images = {}
    for skipping in (True, False):
        with OffscreenRenderer(64, 64, ctx=gl_ctx, dtype="f4") as r:
            r.renderer.empty_space_skipping = skipping
            images[skipping] = r.render(Scene(vol, warps=[GenericIdentity()], **kw))
            assert r.renderer.last_skip_kind == ("blocks" if skipping else "none")
            straight = r.render(Scene(vol, **kw))
            assert r.renderer.last_skip_kind == "none"
    assert np.abs(images[True] - images[False]).max() <= 1 / 255
    assert np.abs(images[True] - straight).max() <= 1 / 255
    assert images[True][..., 0].max() > 0.1  # the body shows
