"""Tests of the directional (octant) empty-space-skipping maps and of the split of the
image into ray-direction octants (voxwarp.render.skipping.maps), plus their use by the renderer.

Oracles: a brute-force search for the largest invisible cube ahead of each cell; the
isotropic chessboard distance (a cube centred on the cell is never larger than the best
one starting at it); a per-pixel classification of the shader's ray directions; and
renders with skipping off, which must be identical (skipping only jumps over samples
that cannot contribute, on the same sample lattice).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from voxwarp.core.camera import Camera
from voxwarp.core.transfer_function import TransferFunction
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import AffineWarp
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.render.skipping.maps import (
    OCTANT_EPS,
    Octant,
    block_skip_distances,
    octant_regions,
    octant_skip_distances,
    ray_direction_coefficients,
)
from voxwarp.scene import Scene

OCTANTS = list(itertools.product((1, -1), repeat=3))


def octant_of(direction: np.ndarray) -> Octant:
    """The octant of a direction as the raycaster classifies it (see ``OCTANT_EPS``): the
    CPU oracle of the shader's rule."""
    d = np.asarray(direction, dtype=np.float64)[:3]
    limit = -OCTANT_EPS * float(np.max(np.abs(d)))
    return tuple(-1 if c < limit else 1 for c in d)  # type: ignore[return-value]


def brute_force_octant(
    visible: np.ndarray, signs: tuple[int, int, int], cap: int = 255
) -> np.ndarray:
    """Edge of the largest invisible cube starting at each cell towards ``signs``."""
    out = np.zeros(visible.shape, dtype=np.int64)
    pts = np.argwhere(visible)
    s = np.asarray(signs)
    for c in np.ndindex(visible.shape):
        if visible[c]:
            continue
        delta = (pts - np.asarray(c)) * s
        ahead = delta[(delta >= 0).all(axis=1)]
        out[c] = min(cap, int(ahead.max(axis=1).min())) if len(ahead) else cap
    return out


def cube_is_invisible(visible: np.ndarray, c: tuple, signs: tuple, edge: int) -> bool:
    sl = []
    for ci, si, n in zip(c, signs, visible.shape, strict=True):
        lo, hi = (ci, ci + edge) if si > 0 else (ci - edge + 1, ci + 1)
        sl.append(slice(max(lo, 0), min(hi, n)))
    return not visible[tuple(sl)].any()


@pytest.mark.parametrize("signs", OCTANTS)
def test_octant_distances_are_exact_without_cap(signs: tuple[int, int, int]) -> None:
    rng = np.random.default_rng(abs(hash(signs)) % 1000)
    visible = rng.random((11, 9, 13)) < 0.03
    d = octant_skip_distances(visible, signs, cell_cap=255)
    assert d.dtype == np.uint8
    assert d.shape == visible.shape
    np.testing.assert_array_equal(d, brute_force_octant(visible, signs))


@pytest.mark.parametrize(("cell_cap", "block"), [(2, 2), (3, 4), (8, 4), (4, 3)])
@pytest.mark.parametrize("signs", [(1, 1, 1), (-1, 1, -1), (1, -1, -1)])
def test_capped_octant_distances_are_safe_and_exact_up_to_the_cap(
    cell_cap: int, block: int, signs: tuple[int, int, int]
) -> None:
    rng = np.random.default_rng(cell_cap * 10 + block)
    visible = rng.random((17, 12, 10)) < 0.01
    d = octant_skip_distances(visible, signs, cell_cap=cell_cap, block=block).astype(int)
    exact = brute_force_octant(visible, signs)
    assert (d <= exact).all(), "a jump would leave the invisible cube"
    assert (d >= np.minimum(exact, cell_cap)).all(), "exact below the cap"
    assert ((d == 0) == visible).all()
    # beyond the cap the block level still lets rays jump further than the cap
    assert (d > cell_cap).any()
    for c in zip(*np.nonzero(d), strict=True):
        assert cube_is_invisible(visible, c, signs, int(d[c]))


def test_octant_cube_is_at_least_the_centred_cube() -> None:
    # The isotropic map lets a ray leave the cube of edge 2d - 1 centred on its cell;
    # the directional cube of edge d starting at the cell lies inside it, so the best
    # directional cube is never smaller than d.
    rng = np.random.default_rng(5)
    visible = rng.random((20, 20, 20)) < 0.004
    iso = block_skip_distances(visible).astype(int)
    for signs in OCTANTS:
        d = octant_skip_distances(visible, signs, cell_cap=255).astype(int)
        assert (d >= np.minimum(iso, 255)).all()
        assert d.mean() > 1.2 * iso.mean()  # and usually much larger


def test_octant_distances_reject_bad_input() -> None:
    with pytest.raises(ValueError, match="3D"):
        octant_skip_distances(np.zeros((3, 3), bool), (1, 1, 1))
    with pytest.raises(ValueError, match="signs"):
        octant_skip_distances(np.zeros((3, 3, 3), bool), (1, 0, 1))


def test_octant_of_treats_rounding_noise_as_positive() -> None:
    assert octant_of(np.array([-1.0, 2.0, -3.0])) == (-1, 1, -1)
    assert octant_of(np.array([0.0, -1e-12, -1.0])) == (1, 1, -1)


# ---------------------------------------------------------------------- image regions
def _cameras() -> list[tuple[str, Camera, tuple[int, int]]]:
    lo, hi = np.zeros(3), np.array([40.0, 30.0, 20.0])
    cams = []
    for view in ["+z", "-x", "+y", (30.0, 20.0), (135.0, -60.0)]:
        for projection in ("perspective", "orthographic"):
            cam = Camera.fit(lo, hi, view=view, projection=projection, fov=60.0)
            cams.append((f"{view}-{projection}", cam, (48, 32)))
    inside = Camera.fit(lo, hi, view=(20.0, 10.0), projection="perspective", fov=90.0, zoom=8)
    cams.append(("inside", inside, (40, 40)))
    return cams


def _pixel_directions(cam: Camera, size: tuple[int, int], to_texel: np.ndarray) -> np.ndarray:
    """Texel-space ray direction per pixel centre, in float32 like the shader."""
    w, h = size
    inv = np.linalg.inv(cam.view_projection(w / h)).astype(np.float32)
    xs = (np.arange(w, dtype=np.float32) + 0.5) / w * 2 - 1
    ys = (np.arange(h, dtype=np.float32) + 0.5) / h * 2 - 1
    x, y = np.meshgrid(xs, ys)
    one = np.ones_like(x)
    a = np.stack([x, y, -one, one], -1) @ inv.T
    b = np.stack([x, y, one, one], -1) @ inv.T
    rd = b[..., :3] / b[..., 3:] - a[..., :3] / a[..., 3:]
    return rd @ to_texel[:3, :3].astype(np.float32).T


def _inside(poly: list[tuple[float, float]], p: tuple[float, float]) -> bool:
    sign = 0.0
    for (x0, y0), (x1, y1) in zip(poly, poly[1:] + poly[:1], strict=True):
        cross = (x1 - x0) * (p[1] - y0) - (y1 - y0) * (p[0] - x0)
        if cross != 0:
            if sign and np.sign(cross) != sign:
                return False
            sign = np.sign(cross)
    return True


@pytest.mark.parametrize(("name", "cam", "size"), _cameras(), ids=lambda v: str(v))
def test_octant_regions_cover_every_pixel_of_its_octant(
    name: str, cam: Camera, size: tuple[int, int]
) -> None:
    to_texel = np.diag([1 / 0.5, 1 / 1.0, 1 / 2.0, 1.0])  # anisotropic voxels
    coeff = ray_direction_coefficients(
        np.linalg.inv(cam.view_projection(size[0] / size[1])), to_texel
    )
    regions = dict(octant_regions(coeff, size))
    dirs = _pixel_directions(cam, size, to_texel)
    w, h = size
    for j, i in itertools.product(range(h), range(w)):
        octant = octant_of(dirs[j, i])
        assert octant in regions, f"{name}: pixel ({i}, {j}) in octant {octant} is never drawn"
        ndc = ((i + 0.5) / w * 2 - 1, (j + 0.5) / h * 2 - 1)
        assert _inside(regions[octant], ndc), f"{name}: pixel ({i}, {j}) outside its polygon"
    if name.startswith("+z-persp") or name == "inside":
        assert len(regions) >= 4  # the image really is split


# ---------------------------------------------------------------------- rendering
def _volume() -> Volume:
    rng = np.random.default_rng(7)
    data = np.zeros((24, 20, 16), np.float32)
    for _ in range(12):  # scattered blobs: fragmented empty space in every direction
        c = rng.uniform((2, 2, 2), (22, 18, 14))
        r = rng.uniform(1.5, 3.5)
        g = np.indices(data.shape).transpose(1, 2, 3, 0)
        data += 100.0 * np.exp(-np.sum((g - c) ** 2, axis=-1) / r**2)
    return Volume(data.astype(np.uint8), spacing=(1.0, 0.8, 1.3))


TF = TransferFunction(
    [(0, 0, 0, 0, 0), (30, 1, 0.5, 0.2, 0), (60, 1, 1, 0.8, 0.6), (255, 1, 1, 1, 0.9)]
)


@pytest.mark.parametrize("mode", ["dvr", "iso", "flm"])
@pytest.mark.parametrize(
    "where", ["+z", "inside", "rotated"], ids=["axis-view", "camera-inside", "rotated-warp"]
)
def test_octant_skipping_matches_no_skipping(gl_ctx: Any, mode: str, where: str) -> None:
    vol = _volume()
    lo, hi = vol.bounds
    warps: list = []
    if where == "inside":
        cam = Camera.fit(lo, hi, view=(20.0, 10.0), projection="perspective", fov=90.0, zoom=6)
    else:
        cam = Camera.fit(lo, hi, view="+z", projection="perspective", fov=60.0)
    if where == "rotated":
        warps = [AffineWarp.rotation((1, 1, 0), 35.0, center=vol.center)]
    scene = Scene(
        vol, mode=mode, transfer_function=TF, camera=cam, warps=warps, iso_value=60.0, seed=3
    )
    images = {}
    for skipping in (True, False):
        with OffscreenRenderer(48, 40, ctx=gl_ctx, dtype="f4") as r:
            r.renderer.empty_space_skipping = skipping
            images[skipping] = r.render(scene)
    assert np.abs(images[True] - images[False]).max() <= 1 / 255
    background = np.asarray(scene.background, np.float32)
    assert np.abs(images[False] - background).max(axis=-1).mean() > 0.02  # not empty


def test_draw_touches_only_its_viewport(gl_ctx: Any) -> None:
    vol = _volume()
    scene = Scene(vol, mode="dvr", transfer_function=TF, view="+z", background=(0, 0, 1, 1))
    with OffscreenRenderer(40, 40, ctx=gl_ctx, dtype="f4") as r:
        fbo = r.framebuffer
        fbo.use()
        fbo.clear(1.0, 0.0, 0.0, 1.0)
        r.renderer.draw(scene, fbo, viewport=(8, 4, 24, 30))
        img = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(40, 40, 4)
    inside = img[4:34, 8:32]
    outside = np.ones((40, 40), bool)
    outside[4:34, 8:32] = False
    np.testing.assert_array_equal(img[outside], np.tile([1.0, 0, 0, 1], (outside.sum(), 1)))
    assert (inside[..., 2] > 0.5).mean() > 0.3  # the background of the scene ...
    assert (np.abs(inside - [0, 0, 1, 1]).max(axis=-1) > 0.05).any()  # ... and the volume


@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.uint16])
def test_visible_ranges_integer_path_equals_float_path(dtype: Any) -> None:
    rng = np.random.default_rng(1)
    info = np.iinfo(dtype)
    lo_v, hi_v = max(info.min, -1000), min(info.max, 3000)
    a = rng.integers(lo_v, hi_v, size=(30, 20, 10)).astype(dtype)
    b = rng.integers(lo_v, hi_v, size=(30, 20, 10)).astype(dtype)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    span = hi_v - lo_v
    # opacity only in a narrow band in the middle: many ranges miss it, many include it
    b0, b1, b2 = (lo_v + f * span for f in (0.45, 0.5, 0.55))
    tf = TransferFunction(
        [
            (lo_v, 0, 0, 0, 0),
            (b0, 1, 1, 1, 0),
            (b1, 1, 1, 1, 0.5),
            (b2, 1, 1, 1, 0),
            (hi_v, 1, 1, 1, 0),
        ]
    )
    fast = tf.visible_ranges(lo, hi)
    slow = tf.visible_ranges(lo.astype(np.float64), hi.astype(np.float64))
    np.testing.assert_array_equal(fast, slow)
    assert fast.any()
    assert not fast.all()


# ---------------------------------------------------------------------- warped rays
def _drag_warp(vol: Volume, amount: float = 4.0) -> Any:
    from benchmarks.offset_inverse import gaussian_drag_field
    from voxwarp.deform.elements.offset_field import OffsetFieldWarp

    lo, hi = vol.bounds
    field = gaussian_drag_field((7, 6, 5), (3, 3, 2), (amount, -0.5 * amount, 1.0), 1.0)
    return OffsetFieldWarp(lo, hi, field, shape=(7, 6, 5))


def _field_warp(vol: Volume, amount: float = 4.0) -> Any:
    """An imported (pull-back) field on its own rotated grid over the volume: one smooth
    bump of displacement, as a registration result."""
    from voxwarp.deform.fields.displacement import DisplacementFieldWarp
    from voxwarp.deform.warp import rotation_matrix

    n = np.array([8, 7, 6])
    r = rotation_matrix((1.0, 0.5, 0.2), 15.0)
    spacing = 1.3 * np.max(vol.size_mm) / (n - 1)
    a = np.eye(4)
    a[:3, :3] = r * spacing
    a[:3, 3] = vol.center - r @ ((n - 1) / 2 * spacing)
    i, j, k = np.meshgrid(*(np.arange(m) for m in n), indexing="ij")
    bump = np.exp(-((i - 3.5) ** 2 + (j - 3.0) ** 2 + (k - 2.5) ** 2) / 2.0)
    u = np.stack([amount * bump, -0.5 * amount * bump, 0.3 * amount * bump], axis=-1)
    return DisplacementFieldWarp(u, a)


def _random_boxes(rng: Any, lo: Any, hi: Any, n: int = 3000) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = np.asarray(lo), np.asarray(hi)
    a = rng.uniform(lo - 5, hi + 5, (n, 3))
    return a, a + rng.uniform(0, 4, (n, 3))


@pytest.mark.parametrize("chain", ["offset", "baked", "affine", "offset+affine", "field+affine"])
def test_displacement_range_holds_for_every_point_of_its_box(chain: str) -> None:
    from voxwarp.deform.warp import chain_apply, chain_displacement_range

    vol = _volume()
    baked = _drag_warp(vol)
    baked.inverse = "baked"
    warps = {
        "offset": [_drag_warp(vol)],
        "baked": [baked],
        "affine": [AffineWarp.rotation((1, 2, 0), 20.0, center=vol.center)],
        "offset+affine": [
            _drag_warp(vol),
            AffineWarp.rotation((0, 0, 1), 10.0, center=vol.center),
            _drag_warp(vol, -3.0),
        ],
        "field+affine": [
            _field_warp(vol),
            AffineWarp.rotation((0, 0, 1), 10.0, center=vol.center),
            _field_warp(vol, -3.0),
        ],
    }[chain]
    rng = np.random.default_rng(1)
    a, b = _random_boxes(rng, *vol.bounds)
    r = chain_displacement_range(warps, a, b)
    assert r is not None
    low, high = r
    assert low.shape == high.shape == (len(a), 3)
    for _ in range(8):
        p = a + (b - a) * rng.uniform(0, 1, a.shape)
        moved = chain_apply(warps, p) - p
        assert np.all(moved >= low - 1e-9)
        assert np.all(moved <= high + 1e-9)
    assert np.abs(np.r_[low, high]).max() > 1.0  # not vacuous: the warps do move points


def test_offset_range_is_local_and_signed() -> None:
    from voxwarp.deform.elements.offset_field import OffsetFieldWarp

    field = np.zeros((9, 9, 9, 3))
    field[2:5, 2:5, 2:5] = (3.0, 0.0, 0.0)  # a block of nodes dragged along +x
    w = OffsetFieldWarp((0, 0, 0), (80, 80, 80), field)
    far_lo, far_hi = w.displacement_range(np.array([[60.0, 60, 60]]), np.array([[70.0, 70, 70]]))
    assert np.abs(np.r_[far_lo, far_hi]).max() < 1e-6
    lo, hi = w.displacement_range(np.array([[28.0, 28, 28]]), np.array([[32.0, 32, 32]]))
    # inside the dragged block the sample reads 3 mm towards -x, never towards +x
    assert lo[0, 0] <= -3.0
    assert hi[0, 0] <= 0.0
    assert np.abs(np.r_[lo[0, 1:], hi[0, 1:]]).max() < 1e-6  # y, z untouched


def test_gpu_owned_field_gives_no_range() -> None:
    from voxwarp.deform.elements.offset_field import OffsetFieldWarp

    w = OffsetFieldWarp((0, 0, 0), (1, 1, 1), shape=(2, 2, 2), texture_source=lambda ctx: None)
    assert w.displacement_range(np.zeros((1, 3)), np.ones((1, 3))) is None


def test_warped_visibility_is_exact_for_a_translation_and_a_superset_of_the_truth() -> None:
    from voxwarp.deform.elements.offset_field import OffsetFieldWarp
    from voxwarp.render.skipping.maps import (
        cell_min_max,
        static_block_visibility,
        warped_cell_visibility,
    )

    vol = _volume()
    lo, hi = (np.asarray(b) for b in vol.bounds)
    scene = Scene(vol, mode="dvr", transfer_function=TF)
    visible = static_block_visibility(scene, *cell_min_max(vol.data))
    # a field that translates everything by exactly 2 voxels along y (nodes far beyond
    # the volume so the box edges do not matter): the window is one shifted cell
    shift = 2 * vol.spacing[1]
    field = np.zeros((3, 3, 3, 3))
    field[..., 1] = shift
    w = OffsetFieldWarp(lo - 40, hi + 40, field)
    out, offset = warped_cell_visibility(visible, vol.spacing, vol.origin, [w], lo - 3, hi + 3)
    assert np.all(offset <= 0)
    inner = tuple(slice(-o, -o + n) for o, n in zip(offset, visible.shape, strict=True))
    shifted = np.zeros_like(out)
    region = list(inner)
    region[1] = slice(-offset[1] + 2, -offset[1] + 2 + visible.shape[1])
    shifted[tuple(region)] = visible  # content seen 2 cells further along +y
    # half-float slack widens the window by at most one cell on the side it rounds to
    assert np.all(out >= shifted)
    grown = shifted | np.roll(shifted, 1, axis=1) | np.roll(shifted, -1, axis=1)
    assert not np.any(out & ~grown)
    # a drag: every deformed cell whose warped samples can land on visible content is
    # kept (brute force at random points)
    scene = Scene(vol, mode="dvr", transfer_function=TF, warps=[_drag_warp(vol)])
    ray_lo, ray_hi = scene.ray_bounds()
    out, offset = warped_cell_visibility(
        visible, vol.spacing, vol.origin, scene.warps, ray_lo, ray_hi
    )
    rng = np.random.default_rng(5)
    p = rng.uniform(ray_lo, ray_hi, (20000, 3))
    q = scene.warps[0].apply(p)
    texel_q = (q - vol.origin) / vol.spacing + 0.5
    cell_q = np.floor(texel_q + 0.5).astype(int)
    inside = np.all((cell_q >= 0) & (cell_q < visible.shape), axis=1)
    lands = np.zeros(len(p), bool)
    lands[inside] = visible[tuple(cell_q[inside].T)]
    cell_p = np.floor((p - vol.origin) / vol.spacing + 1.0).astype(int) - offset
    assert lands.any()
    assert np.all(out[tuple(cell_p[lands].T)])
    # no displacement: exactly the original visibility
    still = [OffsetFieldWarp(*vol.bounds, np.zeros((3, 3, 3, 3)))]
    same, offset0 = warped_cell_visibility(visible, vol.spacing, vol.origin, still, *vol.bounds)
    np.testing.assert_array_equal(offset0, 0)
    np.testing.assert_array_equal(same, visible)


def _dense_volume() -> Volume:
    """:func:`_volume` with a solid slab through its middle: moved blocks whose whole
    window is visible (counted as a block, not cell by cell) beside ragged ones."""
    vol = _volume()
    data = np.asarray(vol.data).copy()
    data[6:18, 4:16, 5:11] = 200
    return Volume(data, spacing=vol.spacing)


@pytest.mark.parametrize("compiled", [False, True], ids=["numpy", "compiled"])
@pytest.mark.parametrize("make", [_volume, _dense_volume], ids=["blobs", "dense-slab"])
def test_warped_visibility_windows_counted_one_by_one(
    make: Callable[[], Volume], compiled: bool, monkeypatch: Any
) -> None:
    """Each deformed cell of a moved block is visible iff a visible original cell lies in
    its displacement window (the block's interval, in cells), counted here by slicing
    the padded visibility cell by cell; the summed-area table only spans the box the
    moved blocks' windows reach (a local drag's part of the grid), so windows at that
    box's edges are the ones to check. Blocks that do not move keep their cells; on the
    dense slab some moved blocks' whole windows are visible (the block shortcut). The
    cells are counted by numpy or by the compiled kernel (big grids)."""
    from voxwarp.render.skipping import maps

    monkeypatch.setattr(maps, "WARPED_COMPILED_MIN_SIZE", 0 if compiled else 1 << 40)
    from voxwarp.deform.elements.offset_field import OffsetFieldWarp
    from voxwarp.deform.warp import chain_displacement_range
    from voxwarp.render.skipping.maps import (
        BLOCK,
        cell_min_max,
        static_block_visibility,
        warped_cell_grid,
        warped_cell_visibility,
    )

    vol = make()
    u = np.zeros((9, 9, 9, 3))
    u[4, 3, 5] = (3.0, -2.0, 1.5)  # one node dragged: its 2³ cells move, nothing else
    scene = Scene(vol, mode="dvr", transfer_function=TF, warps=[OffsetFieldWarp(*vol.bounds, u)])
    visible = static_block_visibility(scene, *cell_min_max(vol.data))
    ray_lo, ray_hi = scene.ray_bounds()
    out, offset = warped_cell_visibility(
        visible, vol.spacing, vol.origin, scene.warps, ray_lo, ray_hi
    )
    shape, offset2 = warped_cell_grid(visible.shape, vol.spacing, vol.origin, ray_lo, ray_hi)
    np.testing.assert_array_equal(offset, offset2)
    padded = np.zeros(tuple(shape), dtype=bool)
    padded[tuple(slice(-o, -o + n) for o, n in zip(offset, visible.shape, strict=True))] = visible
    sp, org = np.asarray(vol.spacing), np.asarray(vol.origin)
    moved_blocks = full_blocks = 0
    for b in np.argwhere(np.ones(-(-np.asarray(shape) // BLOCK), dtype=bool)):
        first = b * BLOCK + offset
        box_lo, box_hi = org + (first - 1.0) * sp, org + (first + BLOCK - 1.0) * sp
        a, z = chain_displacement_range(scene.warps, box_lo[None], box_hi[None])
        d_lo, d_hi = np.floor(a[0] / sp).astype(int), np.ceil(z[0] / sp).astype(int)
        cells = b * BLOCK + np.indices((BLOCK,) * 3).reshape(3, -1).T
        cells = cells[np.all(cells < shape, axis=1)]
        if not (d_lo.any() or d_hi.any()):
            np.testing.assert_array_equal(out[tuple(cells.T)], padded[tuple(cells.T)])
            continue
        moved_blocks += 1
        w_lo, w_hi = b * BLOCK + d_lo, b * BLOCK + BLOCK + d_hi
        if np.all(w_lo >= 0) and np.all(w_hi <= shape):
            window = tuple(slice(x, y) for x, y in zip(w_lo, w_hi, strict=True))
            full_blocks += bool(padded[window].all())
        for c in cells:
            lo_c, hi_c = np.clip(c + d_lo, 0, shape), np.clip(c + d_hi + 1, 0, shape)
            window = padded[lo_c[0] : hi_c[0], lo_c[1] : hi_c[1], lo_c[2] : hi_c[2]]
            assert out[tuple(c)] == window.any(), (c, d_lo, d_hi)
    assert 0 < moved_blocks < np.prod(-(-np.asarray(shape) // BLOCK)), "a local drag"
    assert (full_blocks > 0) == (make is _dense_volume)


@pytest.mark.parametrize("mode", ["dvr", "iso", "flm"])
@pytest.mark.parametrize("chain", ["offset", "baked", "offset+rotation", "field"])
@pytest.mark.slow
def test_warped_cell_skipping_matches_block_path(gl_ctx: Any, mode: str, chain: str) -> None:
    vol = _volume()
    lo, hi = vol.bounds
    warps: list = [_field_warp(vol, 6.0) if chain == "field" else _drag_warp(vol)]
    if chain == "baked":
        warps[0].inverse = "baked"
    if chain == "offset+rotation":
        warps.append(AffineWarp.rotation((1, 1, 0), 25.0, center=vol.center))
    cam = Camera.fit(lo, hi, view=(30.0, 25.0), projection="perspective", fov=50.0)
    scene = Scene(
        vol, mode=mode, transfer_function=TF, camera=cam, warps=warps, iso_value=60.0, seed=3
    )
    images = {}
    with OffscreenRenderer(48, 40, ctx=gl_ctx, dtype="f4") as r:
        r.renderer.warped_skip_maps = "always"
        images["cells"] = r.render(scene)
        assert r.renderer.last_skip_kind == "cells"
        r.renderer.cell_skipping = False
        images["blocks"] = r.render(scene)
        assert r.renderer.last_skip_kind == "blocks"
        r.renderer.cell_skipping = True
        images["rest"] = r.render(scene.copy(warps=warps[1:]))
    assert np.abs(images["cells"] - images["blocks"]).max() <= 1 / 255
    assert np.abs(images["cells"] - images["rest"]).max() > 0.1  # the drag shows


def test_warped_skip_maps_are_built_when_a_warp_state_is_drawn_again(gl_ctx: Any) -> None:
    vol = _volume()
    warp = _drag_warp(vol)
    scene = Scene(vol, mode="dvr", transfer_function=TF, view="+z", warps=[warp])
    with OffscreenRenderer(32, 32, ctx=gl_ctx, dtype="f4") as r:
        kinds = []
        for _ in range(3):
            r.render(scene)
            kinds.append(r.renderer.last_skip_kind)
        assert kinds == ["blocks", "cells", "cells"]  # built on the second draw, kept
        warp.update(warp.displacements * 0.5)  # a new warp state (as while dragging)
        r.render(scene)
        assert r.renderer.last_skip_kind == "blocks"
        r.renderer.warped_skip_maps = "never"
        r.render(scene)
        assert r.renderer.last_skip_kind == "blocks"
        r.renderer.warped_skip_maps = "always"
        r.render(scene)
        assert r.renderer.last_skip_kind == "cells"
        # a warp without a displacement range (a GPU-owned field) keeps block checks
        from voxwarp.deform.elements.offset_field import OffsetFieldWarp

        tex = warp.textures(gl_ctx)["displacement"]
        owned = OffsetFieldWarp(warp.lo, warp.hi, shape=warp.shape, texture_source=lambda c: tex)
        r.render(scene.copy(warps=[owned]))
        assert r.renderer.last_skip_kind == "blocks"


def test_warped_octant_maps_use_the_compiled_kernels(gl_ctx: Any, monkeypatch: Any) -> None:
    """Deformed-space octant maps are rebuilt for every warp state that rests: from
    WARPED_COMPILED_MIN_SIZE cells on they use the compiled kernels (straight maps keep
    COMPILED_MIN_SIZE), and the image is the one the numpy maps give."""
    from voxwarp.deform.elements.offset_field import OffsetFieldWarp
    from voxwarp.render.skipping import cache

    vol = _volume()
    u = np.zeros((9, 9, 9, 3))
    u[4, 3, 5] = (3.0, -2.0, 1.5)
    scene = Scene(vol, mode="dvr", transfer_function=TF, view="+z", warps=[])
    warped = scene.copy(warps=[OffsetFieldWarp(*vol.bounds, u)])
    calls: dict[int, list[bool | None]] = {}
    real = cache.octant_skip_distances
    images = {}
    for threshold in (1 << 40, 1):  # numpy maps, then compiled ones
        made = calls.setdefault(threshold, [])

        def spy(visible: np.ndarray, signs: Any, made: list = made, **kw: Any) -> np.ndarray:
            made.append(kw.get("compiled"))
            return real(visible, signs, **kw)

        monkeypatch.setattr(cache, "octant_skip_distances", spy)
        monkeypatch.setattr(cache, "WARPED_COMPILED_MIN_SIZE", threshold)
        with OffscreenRenderer(48, 40, ctx=gl_ctx, dtype="f4") as r:
            r.renderer.warped_skip_maps = "always"
            r.render(scene)
            images[threshold] = r.render(warped)
    assert calls[1 << 40]
    assert all(c is None for c in calls[1 << 40])
    assert True in calls[1], "the warped maps compiled"
    assert None in calls[1], "the straight ones by their own rule"
    np.testing.assert_array_equal(images[1 << 40], images[1])
