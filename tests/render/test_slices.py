"""Slice views through the warp chain (``render_slice`` / ``Renderer.slice_values``)
against CPU oracles.

Oracles:

* the array itself: a named plane through voxel centres with pixel = spacing is the
  array slice, flipped the radiological way (axial: ``data[::-1, ::-1, k].T``, patient
  left on the image right, anterior up; coronal ``data[::-1, j, ::-1].T``; sagittal
  ``data[i, ::-1, ::-1].T``, nose left), with nearest and linear interpolation, exact;
* ``scipy.ndimage.map_coordinates`` of the volume at ``volume.world_to_index`` of each
  pixel's world point (``chain_apply(warps, p)`` when the scene deforms: the CPU warp
  gives the same pull-back point as the shader), ``mode="nearest"`` (the texture's
  clamp inside the half-voxel border), NaN where the point is outside that border.
  Nearest must match exactly away from ties. Linear: GPU texture units (llvmpipe too)
  weigh the 8 texels with 8-bit fractions, an error of at most 1/512 of the local texel
  difference per axis, so the tolerance is ``3 * range / 512`` (range: the volume's value
  range, the largest possible texel difference);
* thick slabs over N voxel planes (sample distance = spacing, slab = N spacings, so the
  samples land on voxel centres) against ``max``/``min``/``mean`` of the array's planes;
* a mass-spring and a wire scene against the CPU oracle at ``chain_apply``: the warp
  the shader evaluates reads its own field textures with the same 8-bit filter weights,
  so its sample point differs from the CPU's by a small fraction of a voxel; the
  tolerance is twice the volume filter's (``2 * 3 * range / 512``, the second half for
  that point's error) on pixels whose point lies at least 3 voxels inside the volume,
  the mean error must stay under a tenth of it, and the deformation must change the
  slice by more than the tolerance on a good share of those pixels.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from scipy import ndimage

from tests.model_scenes import massspring_push, padded_colin, wire_bend
from voxwarp.core.slice_plane import SlicePlane
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import AffineWarp, Warp, chain_apply, rotation_matrix
from voxwarp.errors import RenderError
from voxwarp.render.slice_image import SliceImage, colorize
from voxwarp.scene import Scene

SHAPE = (14, 12, 10)
#: "exact": integer voxel values come back through the texture's value map
#: (normalized integers times a scale, plus an offset, in float32) within its rounding,
#: far below the 1 between neighbouring integers
EXACT = 1e-2
SPACING = 2.0


def _volume(dtype: Any = np.uint8, direction: np.ndarray | None = None, **kw: Any) -> Volume:
    rng = np.random.default_rng(3)
    if dtype == np.int16:
        data = rng.integers(-1024, 3000, SHAPE).astype(np.int16)
    else:
        data = rng.integers(0, 256, SHAPE).astype(np.uint8)
    spacing = kw.pop("spacing", (SPACING,) * 3)
    return Volume(data, spacing, (-11.0, 7.0, 3.0), direction=direction, space="RAS", **kw)


@pytest.fixture(scope="module")
def renderer(offscreen: Any) -> Any:
    return offscreen(16, 16)


def _values(renderer: Any, scene: Scene, m: np.ndarray, size: tuple[int, int], **kw: Any):
    data = renderer.renderer.slice_values(scene, m, size, **kw)
    return SliceImage.from_data(data, m)


def _points(m: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """World centres of every pixel, (H*W, 3), row-major from the top row."""
    cols, rows = np.meshgrid(np.arange(size[0]), np.arange(size[1]))
    pix = np.c_[cols.ravel(), rows.ravel(), np.zeros(cols.size), np.ones(cols.size)]
    return (pix @ m.T)[:, :3]


def _oracle(vol: Volume, points: np.ndarray, size: tuple[int, int], order: int) -> np.ndarray:
    """CPU sampling of ``vol`` at world ``points``; NaN outside the half-voxel border."""
    idx = vol.world_to_index(points)
    data = np.asarray(vol.data, np.float64)
    if order == 0:  # the texel holding the point (numpy rounds halves to even: avoid ties)
        near = np.clip(np.floor(idx + 0.5).astype(int), 0, np.array(vol.shape) - 1)
        vals = data[tuple(near.T)]
    else:
        vals = ndimage.map_coordinates(data, idx.T, order=1, mode="nearest")
    inside = np.all((idx >= -0.5) & (idx <= np.array(vol.shape) - 0.5), axis=1)
    return np.where(inside, vals, np.nan).reshape(size[1], size[0])


def _linear_tol(vol: Volume) -> float:
    data = np.asarray(vol.data, np.float64)
    return 3 * float(np.ptp(data)) / 512


def _voxel_plane(vol: Volume, name: str, index: int) -> tuple[SlicePlane, tuple[int, int]]:
    """The named plane through voxel plane ``index`` with one pixel per voxel."""
    axis = {"axial": 2, "coronal": 1, "sagittal": 0}[name]
    in_plane = [a for a in range(3) if a != axis]
    size = tuple(SHAPE[a] for a in in_plane)
    if name == "sagittal":
        size = (SHAPE[1], SHAPE[2])
    lo, hi = vol.index_to_world(np.array([[0, 0, 0], np.array(SHAPE) - 1.0]))
    centre = (lo + hi) / 2
    centre[axis] = vol.index_to_world(np.array([[index] * 3]))[0][axis]
    right, up = SlicePlane.named(name, (lo, hi)).right, SlicePlane.named(name, (lo, hi)).up
    plane = SlicePlane(centre, right, up, height_mm=size[1] * SPACING, name=name)
    return plane, size  # type: ignore[return-value]


ARRAY_SLICES = {
    "axial": lambda d, k: d[::-1, ::-1, k].T,
    "coronal": lambda d, k: d[::-1, k, ::-1].T,
    "sagittal": lambda d, k: d[k, ::-1, ::-1].T,
}


# ---------------------------------------------------------------------- (a) undeformed
@pytest.mark.parametrize("name", ["axial", "coronal", "sagittal"])
@pytest.mark.parametrize("interpolation", ["nearest", "linear"])
def test_named_plane_is_the_array_slice(renderer: Any, name: str, interpolation: str) -> None:
    vol = _volume()
    scene = Scene(vol)
    for index in (0, 4):
        plane, size = _voxel_plane(vol, name, index)
        image = renderer.render_slice(scene, plane, size=size, interpolation=interpolation)
        expect = ARRAY_SLICES[name](np.asarray(vol.data), index)
        np.testing.assert_allclose(image.values, expect, rtol=0, atol=EXACT)
        np.testing.assert_array_equal(image.rest, image.values)
        assert image.rgba is not None
        assert image.rgba.shape == (*expect.shape, 4)


def test_int16_ct_values_are_exact(renderer: Any) -> None:
    vol = _volume(np.int16)
    plane, size = _voxel_plane(vol, "coronal", 5)
    for interpolation in ("nearest", "linear"):
        image = renderer.render_slice(Scene(vol), plane, size=size, interpolation=interpolation)
        expect = ARRAY_SLICES["coronal"](np.asarray(vol.data), 5)
        np.testing.assert_allclose(image.values, expect, rtol=0, atol=EXACT)


def _oblique_volume() -> Volume:
    direction = rotation_matrix((0.2, 1.0, 0.4), 25.0)
    return _volume(direction=direction, spacing=(1.5, 2.0, 2.5))


@pytest.mark.parametrize("interpolation", ["nearest", "linear"])
@pytest.mark.parametrize("plane_text", ["axial", "sagittal", "tilted"])
def test_oblique_volume_matches_map_coordinates(
    renderer: Any, interpolation: str, plane_text: str
) -> None:
    vol = _oblique_volume()
    scene = Scene(vol)
    size = (40, 36)
    bounds = scene.deformed_bounds()
    if plane_text == "tilted":
        plane = SlicePlane.oblique(vol.center + 1.3, (0.3, -0.5, 1.0), bounds, aspect=40 / 36)
    else:
        plane = SlicePlane.named(plane_text, bounds, aspect=40 / 36).moved(0.7)
    m = plane.pixel_to_world(size)
    image = _values(renderer, scene, m, size, interpolation=interpolation)
    expect = _oracle(vol, _points(m, size), size, 0 if interpolation == "nearest" else 1)
    np.testing.assert_array_equal(np.isnan(image.values), np.isnan(expect))
    assert np.isnan(expect).any()
    assert (~np.isnan(expect)).sum() > 300
    inside = ~np.isnan(expect)
    if interpolation == "nearest":
        np.testing.assert_allclose(image.values[inside], expect[inside], rtol=0, atol=EXACT)
    else:
        err = np.abs(image.values[inside] - expect[inside])
        assert err.max() <= _linear_tol(vol)


def test_outside_is_nan_everywhere(renderer: Any) -> None:
    vol = _volume()
    plane = SlicePlane.named("axial", vol.bounds, at=vol.bounds[1][2] + 5.0)
    image = renderer.render_slice(Scene(vol), plane, size=(20, 20))
    assert np.isnan(image.values).all()
    assert np.isnan(image.rest).all()
    assert (image.rgba[..., :3] == 0).all()


@pytest.mark.parametrize(
    ("anatomical", "axis"), [("axial", "z"), ("coronal", "y"), ("sagittal", "x")]
)
def test_anatomical_names_on_a_volume_without_orientation_mean_its_axes(
    renderer: Any, anatomical: str, axis: str
) -> None:
    vol = _volume()
    plain = Scene(Volume(vol.data, vol.spacing, vol.origin))  # space "": no orientation
    named = renderer.render_slice(plain, anatomical, size=(24, 20))
    assert named.plane.name == axis
    np.testing.assert_array_equal(
        named.values, renderer.render_slice(plain, axis, size=(24, 20)).values
    )
    oriented = renderer.render_slice(Scene(vol), anatomical, size=(24, 20))
    assert oriented.plane.name == anatomical


def test_linear_halfway_between_voxel_planes_is_their_mean(renderer: Any) -> None:
    vol = _volume()
    plane, size = _voxel_plane(vol, "axial", 3)
    half = plane.moved(SPACING / 2)
    image = renderer.render_slice(Scene(vol), half, size=size, interpolation="linear")
    d = np.asarray(vol.data, np.float64)
    expect = (ARRAY_SLICES["axial"](d, 3) + ARRAY_SLICES["axial"](d, 4)) / 2
    np.testing.assert_allclose(image.values, expect, atol=255 / 512)
    assert np.abs(image.values - ARRAY_SLICES["axial"](d, 3)).max() > 20


# ---------------------------------------------------------------------- (c) affine warps
def test_translation_is_the_shifted_array_slice(renderer: Any) -> None:
    vol = _volume()
    shift = np.array([2, -1, 3])  # voxels
    warp = AffineWarp.translation(shift * SPACING)  # the object moves by +shift
    scene = Scene(vol, warps=[warp])
    plane, size = _voxel_plane(vol, "axial", 6)  # shows original plane 6 - 3 = 3
    image = renderer.render_slice(scene, plane, size=size, interpolation="nearest")
    expect = np.full(size[::-1], np.nan, np.float32)
    moved = ARRAY_SLICES["axial"](np.asarray(vol.data, np.float32), 3)
    # radiological: +x (i) runs right to left, +y (j) bottom to top, so pixel (r, c)
    # shows the original voxel of pixel (r - 1, c + 2) of that plane
    rows, cols = size[1], size[0]
    expect[1:, : cols - 2] = moved[: rows - 1, 2:]
    np.testing.assert_allclose(image.values, expect, rtol=0, atol=EXACT)
    rest = ARRAY_SLICES["axial"](np.asarray(vol.data, np.float32), 6)
    np.testing.assert_allclose(image.rest, rest, rtol=0, atol=EXACT)


@pytest.mark.parametrize("interpolation", ["nearest", "linear"])
def test_rotation_warp_matches_the_cpu_pull_back(renderer: Any, interpolation: str) -> None:
    vol = _volume(spacing=(1.5, 2.0, 2.5))
    warp = AffineWarp.rotation((0.3, 0.2, 1.0), 17.0, center=vol.center + 2.0)
    scene = Scene(vol, warps=[warp])
    size = (44, 40)
    plane = SlicePlane.named("coronal", scene.deformed_bounds(), aspect=44 / 40).moved(0.9)
    m = plane.pixel_to_world(size)
    image = _values(renderer, scene, m, size, interpolation=interpolation)
    pulled = chain_apply(scene.warps, _points(m, size))
    expect = _oracle(vol, pulled, size, 0 if interpolation == "nearest" else 1)
    np.testing.assert_array_equal(np.isnan(image.values), np.isnan(expect))
    inside = ~np.isnan(expect)
    err = np.abs(image.values[inside] - expect[inside])
    if interpolation == "nearest":  # a tie can flip one texel: allow a handful
        assert (err > EXACT).mean() < 0.01
    else:
        assert err.max() <= _linear_tol(vol)
    rest = _oracle(vol, _points(m, size), size, 1)
    assert np.nanmax(np.abs(image.values - rest)) > 50  # the warp shows


# ---------------------------------------------------------------------- (d) slabs
@pytest.mark.parametrize(
    ("mode", "reduce"), [("mip", np.max), ("minip", np.min), ("average", np.mean)]
)
def test_slab_over_voxel_planes(renderer: Any, mode: str, reduce: Any) -> None:
    vol = _volume()
    scene = Scene(vol, step=1.0)  # samples one spacing apart
    assert scene.sample_distance_mm == SPACING
    plane, size = _voxel_plane(vol, "axial", 5)
    n = 5  # voxel planes 3..7
    image = renderer.render_slice(
        scene, plane, size=size, slab_mm=n * SPACING, slab_mode=mode, interpolation="linear"
    )
    stack = np.asarray(vol.data, np.float64)[..., 3:8]
    expect = ARRAY_SLICES["axial"](reduce(stack, axis=2)[..., None], 0)
    np.testing.assert_allclose(image.values, expect, rtol=0, atol=1e-3)
    thin = renderer.render_slice(scene, plane, size=size)
    assert np.abs(image.values - thin.values).max() > 10


def test_slab_half_outside_averages_the_inside_samples(renderer: Any) -> None:
    vol = _volume()
    plane, size = _voxel_plane(vol, "axial", 0)  # planes -2..2: two are outside
    image = renderer.render_slice(
        Scene(vol), plane, size=size, slab_mm=5 * SPACING, slab_mode="average"
    )
    expect = ARRAY_SLICES["axial"](np.asarray(vol.data, float)[..., :3].mean(2)[..., None], 0)
    np.testing.assert_allclose(image.values, expect, atol=1e-3)


# ---------------------------------------------------------------------- (e) models


@pytest.fixture(scope="module")
def colin() -> Volume:
    return padded_colin()


def _massspring(vol: Volume) -> list[Warp]:
    return massspring_push(vol, 5, 1000)


def _wires(vol: Volume) -> list[Warp]:
    return wire_bend(vol, 25.0, 40.0)


@pytest.mark.parametrize("model", ["massspring", "wires"])
def test_model_scene_matches_the_cpu_chain(renderer: Any, colin: Volume, model: str) -> None:
    warps = _massspring(colin) if model == "massspring" else _wires(colin)
    scene = Scene(colin, warps=warps)
    size = (64, 64)
    tol = 2 * _linear_tol(colin)
    lo, hi = colin.bounds
    for name in ("axial", "coronal"):
        at = 0.4 * lo[2] + 0.6 * hi[2] if name == "axial" else colin.center[1]
        plane = SlicePlane.named(name, colin.bounds, at=at)
        m = plane.pixel_to_world(size)
        image = _values(renderer, scene, m, size, interpolation="linear")
        pulled = chain_apply(scene.warps, _points(m, size))
        expect = _oracle(colin, pulled, size, 1)
        idx = colin.world_to_index(pulled).reshape(size[1], size[0], 3)
        deep = np.all((idx >= 3) & (idx <= np.array(colin.shape) - 4), axis=2)
        assert deep.sum() > 1000
        err = np.abs(image.values[deep] - expect[deep])
        moved = np.abs(image.values[deep] - image.rest[deep])
        assert err.max() <= tol, (name, err.max(), tol)
        assert err.mean() <= tol / 10
        assert (moved > tol).mean() > 0.1  # the deformation shows


# ---------------------------------------------------------------------- (f) overlays
def test_rest_checkerboard_and_difference(renderer: Any) -> None:
    vol = _volume()
    plane, size = _voxel_plane(vol, "axial", 4)
    window = (128.0, 256.0)
    still = Scene(vol)
    warped = Scene(vol, warps=[AffineWarp.translation((4.0, 2.0, 2.0))])
    base = renderer.render_slice(still, plane, size=size, window=window)
    rest = renderer.render_slice(warped, plane, size=size, window=window, show="rest")
    np.testing.assert_array_equal(rest.rgba, base.rgba)
    deformed = renderer.render_slice(warped, plane, size=size, window=window)
    assert (deformed.rgba != base.rgba).any()
    board = colorize(deformed, window=window, show="checkerboard", checker_px=4)
    tiles = (np.arange(size[1])[:, None] // 4 + np.arange(size[0])[None, :] // 4) % 2 == 1
    np.testing.assert_array_equal(board[tiles], base.rgba[tiles])
    colorize(deformed, window=window)
    np.testing.assert_array_equal(board[~tiles], deformed.rgba[~tiles])
    same = renderer.render_slice(still, plane, size=size, window=window, show="difference")
    assert (same.rgba[..., 0] == same.rgba[..., 1]).all()  # grey: no red, no blue
    assert (same.rgba[..., 2] == same.rgba[..., 1]).all()
    diff = colorize(deformed, window=window, show="difference")
    assert (diff[..., 0] > diff[..., 1] + 50).any()
    assert (diff[..., 2] > diff[..., 1] + 50).any()


# ---------------------------------------------------------------------- (g) bad options
@pytest.mark.parametrize(
    ("option", "match"),
    [
        ({"slab_mode": "max"}, "slab mode"),
        ({"interpolation": "cubic"}, "interpolation"),
        ({"slab_mm": -1.0}, "slab thickness"),
        ({"slab_mm": float("nan")}, "slab thickness"),
        ({"size": (0, 10)}, "slice size"),
        ({"show": "overlay"}, "show"),
        ({"look": "hot"}, "look"),
        ({"window": (10.0, 0.0)}, "window width"),
    ],
)
def test_bad_options_are_one_line(renderer: Any, option: dict, match: str) -> None:
    vol = _volume()
    with pytest.raises(RenderError, match=match) as info:
        renderer.render_slice(Scene(vol), "axial", **{"size": (8, 8), **option})
    assert "\n" not in str(info.value)
