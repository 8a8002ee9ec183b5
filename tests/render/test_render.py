"""Oracle tests of the raycaster (voxwarp.render.raycaster) on llvmpipe through EGL.

Most tests use a pixel-aligned orthographic camera: pixel centres fall on voxel
centres across the screen and, with ``jitter=False`` and a step of one voxel along the
ray, every sample lies on a voxel centre. Trilinear interpolation is then exact, so the
grey-value modes must equal numpy reductions of the data (``max``, ``min``, ``mean``)
mapped through the window, up to 8-bit filtering weights and float round-off.

Screen orientation per standard view (voxwarp.core.camera): ``+z`` has +x right and +y up;
``-z`` has -x right, +y up; ``+x`` has +y right, +z up; ``-x`` has -y right, +z up;
``+y`` has -x right, +z up; ``-y`` has +x right, +z up. Image row 0 is the top.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from scipy import ndimage

from voxwarp.core.camera import Camera, view_rotation
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import AffineWarp, IdentityWarp
from voxwarp.errors import VolumeTooLargeError
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.render.raycaster import Renderer
from voxwarp.scene import MODES, Scene

#: 8-bit texture filtering weights and float round-off: one grey level plus a little.
#: Measured on llvmpipe (LLVM 15): at most 5e-4/255 for MIP/MinIP/average of all dtypes,
#: exactly 0 for the translation shifts.
EXACT_TOL = 1 / 255 + 1e-4
BLUE = (0.0, 0.0, 1.0, 1.0)


# ---------------------------------------------------------------------- volumes
def smooth_field(shape: tuple[int, int, int], seed: int, sigma: float = 2.0) -> np.ndarray:
    """Random but smooth field in [0, 1] (seeded), so interpolation errors stay small."""
    rng = np.random.default_rng(seed)
    a = ndimage.gaussian_filter(rng.standard_normal(shape), sigma=sigma, mode="wrap")
    return (a - a.min()) / (a.max() - a.min())


def smooth_volume(
    shape: tuple[int, int, int], dtype: Any, lo: float, hi: float, seed: int = 0, **kw: Any
) -> Volume:
    a = lo + smooth_field(shape, seed) * (hi - lo)
    if np.dtype(dtype).kind in "iu":
        a = np.rint(a)
    return Volume(a.astype(dtype), **kw)


def phantom() -> Volume:
    """40x32x28 int16 CT-like phantom in HU, spacing (1, 1, 1.2) mm.

    Air -1000; a tilted ellipsoid body of soft tissue (20..60 HU, smooth texture) that
    runs out of the box through both z faces; two bone spheres (1200 HU at the centre
    falling to 300 HU at the rim); an air pocket (-950 HU) inside the body. Edges are
    blurred by 0.8 voxel, like a scanner's point spread.
    """
    shape = (40, 32, 28)
    sp = np.array([1.0, 1.0, 1.2])
    i, j, k = np.meshgrid(*(np.arange(n, dtype=float) for n in shape), indexing="ij")
    x, y, z = (i - 19.5) * sp[0], (j - 15.5) * sp[1], (k - 13.5) * sp[2]
    t = np.radians(20.0)  # body tilted in the xz plane
    xr, zr = np.cos(t) * x + np.sin(t) * z, -np.sin(t) * x + np.cos(t) * z
    body = (xr / 17.0) ** 2 + (y / 13.0) ** 2 + (zr / 30.0) ** 2 <= 1.0
    vol = np.full(shape, -1000.0)
    vol[body] = 20.0 + 40.0 * smooth_field(shape, seed=3)[body]
    for c, r in (((-8.0, -3.0, -5.0), 6.0), ((9.0, 5.0, 6.0), 5.0)):
        d = np.sqrt((x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2)
        bone = d <= r
        vol[bone] = 1200.0 - 900.0 * d[bone] / r
    pocket = (x - 2.0) ** 2 + (y + 6.0) ** 2 + (z - 2.0) ** 2 <= 16.0
    vol[pocket] = -950.0
    vol = ndimage.gaussian_filter(vol, sigma=0.8)  # soften the voxel staircase
    return Volume(np.rint(vol).astype(np.int16), spacing=tuple(sp), name="phantom", units="HU")


def blob(n: int = 32) -> Volume:
    """n³ float32: an off-axis smooth ellipsoidal blob plus a bump (no rotational symmetry)."""
    c = (n - 1) / 2
    i, j, k = np.meshgrid(*(np.arange(n, dtype=float) - c,) * 3, indexing="ij")
    f = np.exp(-((i / 9.0) ** 2 + (j / 5.5) ** 2 + (k / 7.0) ** 2))
    f += 0.8 * np.exp(-(((i - 6.0) / 3.0) ** 2 + ((j - 4.0) / 3.0) ** 2 + (k / 3.0) ** 2))
    return Volume((1000.0 * f).astype(np.float32), name="blob")


# ---------------------------------------------------------------------- cameras / oracles
#: view -> (screen-right (axis, sign), screen-up (axis, sign), depth axis); from the
#: view definitions in voxwarp.core.camera, written out independently of view_rotation().
VIEW_AXES = {
    "+z": ((0, 1), (1, 1), 2),
    "-z": ((0, -1), (1, 1), 2),
    "+x": ((1, 1), (2, 1), 0),
    "-x": ((1, -1), (2, 1), 0),
    "+y": ((0, -1), (2, 1), 1),
    "-y": ((0, 1), (2, 1), 1),
}


def aligned_camera(vol: Volume, view: str, pixel: float = 1.0) -> tuple[Camera, tuple[int, int]]:
    """Orthographic camera whose pixel centres hit voxel centres, and its image size (W, H).

    Pixels are ``pixel`` mm; along each screen axis ``pixel`` must be a whole number of
    voxels. The first column / bottom row sits on the first voxel along the screen axis.
    """
    (ra, rs), (ua, us), _ = VIEW_AXES[view]
    sp, org, n = np.asarray(vol.spacing), np.asarray(vol.origin), np.asarray(vol.shape)
    size = []
    center = vol.center.copy()
    for axis, sign in ((ra, rs), (ua, us)):
        stride = pixel / sp[axis]
        assert abs(stride - round(stride)) < 1e-9, "pixel must be a multiple of the spacing"
        npx = (n[axis] - 1) // round(stride) + 1
        first = 0 if sign > 0 else n[axis] - 1
        center[axis] = org[axis] + first * sp[axis] + sign * (npx / 2 - 0.5) * pixel
        size.append(int(npx))
    radius = float(np.linalg.norm(vol.size_mm))
    cam = Camera(
        center=center,
        rotation=view_rotation(view),
        distance=2 * radius,
        projection="orthographic",
        ortho_height=size[1] * pixel,
        radius=radius,
    )
    return cam, (size[0], size[1])


def projected(vol: Volume, view: str, reduce: Any, pixel: float = 1.0) -> np.ndarray:
    """``reduce`` of the data along the view's depth axis, laid out as the (H, W) image."""
    (ra, rs), (ua, us), depth = VIEW_AXES[view]
    proj = reduce(np.moveaxis(vol.data.astype(np.float64), (ra, ua, depth), (0, 1, 2)), axis=2)
    sp = np.asarray(vol.spacing)
    step_r, step_u = round(pixel / sp[ra]), round(pixel / sp[ua])
    proj = proj[:: rs * step_r, :: us * step_u]
    # proj[col, row-from-bottom] -> image[row-from-top, col]
    return proj.T[::-1, :]


def windowed(values: np.ndarray, window: tuple[float, float]) -> np.ndarray:
    level, width = window
    return np.clip((values - (level - width / 2)) / width, 0.0, 1.0)


def full_window(vol: Volume) -> tuple[float, float]:
    lo, hi = vol.value_range
    return (0.5 * (lo + hi), hi - lo)


def grey_scene(vol: Volume, mode: str, view: str, cam: Camera, **kw: Any) -> Scene:
    along = VIEW_AXES[view][2]
    kw.setdefault("step", vol.spacing[along] / min(vol.spacing))  # one voxel along the ray
    return Scene(
        vol,
        mode=mode,
        transfer_function="grayscale",
        view=view,
        projection="orthographic",
        window=kw.pop("window", full_window(vol)),
        jitter=False,
        camera=cam,
        **kw,
    )


def render(offscreen: Any, scene: Scene, size: tuple[int, int], dtype: str = "f4") -> np.ndarray:
    img = offscreen(*size, dtype=dtype).render(scene)
    assert img.shape == (size[1], size[0], 4)
    return img


def max_diff(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(np.asarray(a, np.float64) - np.asarray(b, np.float64))))


class GenericAffine(AffineWarp):
    """An affine warp the renderer cannot fold: forces the generic warp-chain path."""

    @property
    def is_affine(self) -> bool:
        return False


class GenericIdentity(IdentityWarp):
    """The identity through the generic warp-chain path (no folding, no block walk)."""

    @property
    def is_affine(self) -> bool:
        return False


# ---------------------------------------------------------------------- grey-value modes
@pytest.mark.parametrize("view", ["+x", "+y", "+z", "-x", "-y", "-z"])
def test_mip_orthographic_equals_numpy_max(offscreen: Any, view: str) -> None:
    vol = smooth_volume((24, 20, 16), np.uint8, 0, 255, seed=1)
    cam, size = aligned_camera(vol, view)
    img = render(offscreen, grey_scene(vol, "mip", view, cam), size)
    expected = windowed(projected(vol, view, np.max), full_window(vol))
    # explicit orientation check, independent of the helpers' axis table
    explicit = {
        "+z": lambda d: d.max(axis=2).T[::-1, :],
        "-z": lambda d: d.max(axis=2).T[::-1, ::-1],
        "+x": lambda d: d.max(axis=0).T[::-1, :],
        "-x": lambda d: d.max(axis=0).T[::-1, ::-1],
        "+y": lambda d: d.max(axis=1).T[::-1, ::-1],
        "-y": lambda d: d.max(axis=1).T[::-1, :],
    }[view](vol.data.astype(float))
    np.testing.assert_allclose(expected, explicit / 255.0, atol=1e-12)
    for c in range(3):
        assert max_diff(img[..., c], expected) <= EXACT_TOL, (view, c)
    assert np.all(img[..., 3] == 1.0)


@pytest.mark.parametrize(
    ("dtype", "lo", "hi"),
    [(np.int16, -1000, 3000), (np.uint16, 0, 60000), (np.float32, -1.5, 2.5)],
)
@pytest.mark.parametrize("view", ["+z", "-x"])
def test_mip_value_mapping_per_dtype(
    offscreen: Any, dtype: Any, lo: float, hi: float, view: str
) -> None:
    vol = smooth_volume((24, 20, 16), dtype, lo, hi, seed=2)
    assert vol.dtype == np.dtype(dtype)
    cam, size = aligned_camera(vol, view)
    for window in (full_window(vol), (0.5 * (lo + hi), 0.5 * (hi - lo))):  # full, clipped
        img = render(offscreen, grey_scene(vol, "mip", view, cam, window=window), size)
        expected = windowed(projected(vol, view, np.max), window)
        assert max_diff(img[..., 0], expected) <= EXACT_TOL, (dtype, window)


@pytest.mark.parametrize(("view", "pixel"), [("+z", 2.0), ("+x", 2.0), ("-y", 1.0)])
def test_mip_anisotropic_spacing(offscreen: Any, view: str, pixel: float) -> None:
    # spacing (1, 2, 0.5) and an offset origin; the pixel size is a whole number of voxels
    # along both screen axes and the step one voxel along the ray, so samples are exact.
    vol = smooth_volume(
        (24, 20, 16), np.int16, -500, 1500, seed=4, spacing=(1.0, 2.0, 0.5), origin=(-7, 3, 11)
    )
    cam, size = aligned_camera(vol, view, pixel)
    img = render(offscreen, grey_scene(vol, "mip", view, cam), size)
    expected = windowed(projected(vol, view, np.max, pixel), full_window(vol))
    assert max_diff(img[..., 0], expected) <= EXACT_TOL


@pytest.mark.parametrize("view", ["+z", "-x"])
def test_average_and_minip_equal_numpy(offscreen: Any, view: str) -> None:
    vol = smooth_volume((24, 20, 16), np.uint8, 0, 255, seed=5)
    cam, size = aligned_camera(vol, view)
    avg = render(offscreen, grey_scene(vol, "average", view, cam), size)
    expected = windowed(projected(vol, view, np.mean), full_window(vol))
    assert max_diff(avg[..., 0], expected) <= 2e-3  # float sum of exact samples
    mnp = render(offscreen, grey_scene(vol, "minip", view, cam), size)
    expected = windowed(projected(vol, view, np.min), full_window(vol))
    assert max_diff(mnp[..., 0], expected) <= EXACT_TOL


# ---------------------------------------------------------------------- warps
K = 3  # voxels


@pytest.mark.parametrize("axis", [0, 1])
@pytest.mark.parametrize("warp_cls", [AffineWarp, GenericAffine])
def test_translation_shifts_mip(offscreen: Any, axis: int, warp_cls: type) -> None:
    vol = smooth_volume((24, 20, 16), np.uint8, 0, 255, seed=6)
    cam, size = aligned_camera(vol, "+z")  # camera stays on the undeformed volume
    base = render(offscreen, grey_scene(vol, "mip", "+z", cam, background=BLUE), size)
    offset = np.zeros(3)
    offset[axis] = K
    warp = warp_cls.translation(offset)
    moved = render(
        offscreen, grey_scene(vol, "mip", "+z", cam, background=BLUE, warps=[warp]), size
    )
    if axis == 0:  # +x is screen right: the image moves K columns right
        assert max_diff(moved[:, K:], base[:, :-K]) <= EXACT_TOL
        vacated = moved[:, :K]
    else:  # +y is screen up: the image moves K rows up (row 0 is the top)
        assert max_diff(moved[:-K], base[K:]) <= EXACT_TOL
        vacated = moved[-K:]
    assert np.all(vacated == np.asarray(BLUE, np.float32)), "vacated strip must be background"
    # and against numpy directly
    expected = windowed(projected(vol, "+z", np.max), full_window(vol))
    shifted = moved[:, K:, 0] if axis == 0 else moved[:-K, :, 0]
    ref = expected[:, :-K] if axis == 0 else expected[K:]
    assert max_diff(shifted, ref) <= EXACT_TOL


def test_identity_warp_equals_no_warp(offscreen: Any) -> None:
    vol = phantom()
    size = (64, 64)
    for mode in ("dvr", "mip", "iso"):
        scene = Scene(vol, mode=mode, view=(30, 20), seed=0)
        plain = render(offscreen, scene, size)
        folded = render(offscreen, scene.copy(warps=[IdentityWarp()]), size)
        np.testing.assert_array_equal(folded, plain)  # the same folded uniforms: bit-equal
        generic = render(offscreen, scene.copy(warps=[GenericIdentity()]), size)
        # generic path: per-sample warp_chain round-off only; measured max 0.002/255
        assert max_diff(generic, plain) <= 1 / 255, mode


def test_rotation_90_about_z_rotates_mip(offscreen: Any) -> None:
    vol = smooth_volume((20, 20, 20), np.uint8, 0, 255, seed=7)
    cam, size = aligned_camera(vol, "+z")
    warp = AffineWarp.rotation((0, 0, 1), 90.0, center=vol.center)
    img = render(offscreen, grey_scene(vol, "mip", "+z", cam, warps=[warp]), size)
    expected = windowed(projected(vol, "+z", np.max), full_window(vol))
    # the object turns counter-clockwise seen from +z (x -> y); the image turns with it
    assert max_diff(img[..., 0], np.rot90(expected, k=1)) <= EXACT_TOL
    assert max_diff(img[..., 0], np.rot90(expected, k=-1)) > 0.1  # the sense matters


# ---------------------------------------------------------------------- modes on a phantom
PHANTOM_BG = (0.2, 0.3, 0.4, 1.0)


def phantom_scene(**kw: Any) -> Scene:
    kw.setdefault("view", "+z")
    kw.setdefault("background", PHANTOM_BG)
    kw.setdefault("window", (100.0, 2200.0))
    kw.setdefault("zoom", 1.25)
    return Scene(phantom(), **kw)


def mean_abs(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.mean(np.abs(np.asarray(a, np.float64) - np.asarray(b, np.float64))))


@pytest.mark.parametrize("mode", MODES)
def test_every_mode_renders_something(offscreen: Any, mode: str) -> None:
    img = render(offscreen, phantom_scene(mode=mode), (64, 64))
    assert np.all(np.isfinite(img))
    rgb = img[..., :3]
    not_bg = np.any(np.abs(rgb - np.asarray(PHANTOM_BG[:3], np.float32)) > 2 / 255, axis=-1)
    # measured: 5.5 % (iso) .. 65 % (grey-value modes) of pixels; std 0.10..0.26
    assert not_bg.mean() > 0.02, f"{mode}: only {not_bg.mean():.1%} of pixels not background"
    assert float(rgb[not_bg].std()) > 0.02, f"{mode}: (nearly) constant where drawn"


@pytest.mark.parametrize(
    ("a", "b"),
    [
        ({"transfer_function": "ct-bone"}, {"transfer_function": "ct-skin"}),
        ({"mode": "dvr"}, {"mode": "mip"}),
        ({"mode": "mip"}, {"mode": "average"}),
        ({"view": (30, 20)}, {"view": "+z"}),
        ({"view": "+x"}, {"view": "-x"}),  # mirror views of an asymmetric phantom
    ],
)
def test_scene_changes_change_image(offscreen: Any, a: dict, b: dict) -> None:
    ia = render(offscreen, phantom_scene(**a), (64, 64))
    ib = render(offscreen, phantom_scene(**b), (64, 64))
    assert mean_abs(ia, ib) > 0.01  # measured 0.03..0.11


def test_jitter_is_deterministic_per_seed(offscreen: Any) -> None:
    s0 = phantom_scene(mode="dvr", jitter=True, seed=0)
    a = render(offscreen, s0, (64, 64))
    b = render(offscreen, s0.copy(), (64, 64))
    np.testing.assert_array_equal(a, b)
    c = render(offscreen, s0.copy(seed=1), (64, 64))
    assert max_diff(a, c) > 0
    d = render(offscreen, s0.copy(jitter=False), (64, 64))
    assert max_diff(a, d) > 0


def test_dvr_opacity_correction_keeps_brightness(offscreen: Any) -> None:
    s1 = phantom_scene(mode="dvr", jitter=False, step=1.0)
    a = render(offscreen, s1, (64, 64))
    b = render(offscreen, s1.copy(step=0.5), (64, 64))
    ma, mb = float(a[..., :3].mean()), float(b[..., :3].mean())
    # opacity correction: means within 5 % (measured 0.03 %)
    assert abs(ma - mb) <= 0.05 * ma, (ma, mb)
    assert max_diff(a, b) > 1 / 255  # but finer sampling does change the image (6/255)


@pytest.mark.parametrize("mode", ["dvr", "mip", "minip", "iso", "flm"])
@pytest.mark.parametrize("rotated", [False, True], ids=["identity", "rot90"])
def test_empty_space_skipping_does_not_change_image(
    offscreen: Any, mode: str, rotated: bool
) -> None:
    # Folded path (block walk that jumps invisible blocks) vs generic path (per-sample
    # warp chain, no jumps). A 90-degree rotation keeps the warped box axis-aligned, so
    # both paths start their sample lattice at the same box entry and see the same
    # samples; an oblique rotation would not (the folded path starts at the true box
    # entry, the generic one at the entry of the bounding box), so it is not used here.
    vol = phantom()
    if rotated:
        fold: Any = AffineWarp.rotation((0, 0, 1), 90.0, center=vol.center)
        generic: Any = GenericAffine(fold.forward_matrix)
    else:
        fold, generic = IdentityWarp(), GenericIdentity()
    scene = phantom_scene(mode=mode, view=(30, 20), jitter=True, seed=0)
    a = render(offscreen, scene.copy(warps=[fold]), (64, 64))
    b = render(offscreen, scene.copy(warps=[generic]), (64, 64))
    # measured max over the modes: 0.0022/255 (identity), 0.0028/255 (rot90), llvmpipe 15
    assert max_diff(a, b) <= 2 / 255, f"{mode}: max abs diff {max_diff(a, b) * 255:.2f}/255"


# ---------------------------------------------------------------------- shading / Jacobian
def iso_scene(vol: Volume, cam: Camera, warps: list | None = None) -> Scene:
    return Scene(
        vol,
        mode="iso",
        transfer_function="grayscale",
        projection="orthographic",
        iso_value=500.0,
        jitter=False,
        step=0.5,
        camera=cam,
        warps=warps or [],
    )


def test_iso_rotation_about_view_axis(offscreen: Any) -> None:
    # Geometry of a rotated isosurface. (With an orthographic headlight along the rotation
    # axis the shading is blind to the Jacobian; the next test covers that.)
    vol = blob()
    cam, size = aligned_camera(vol, "+z")
    base = render(offscreen, iso_scene(vol, cam), size)
    warp = AffineWarp.rotation((0, 0, 1), 90.0, center=vol.center)
    rot = render(offscreen, iso_scene(vol, cam, [warp]), size)
    diff = np.abs(rot - np.rot90(base, k=1)).max(axis=-1)
    assert np.mean(diff <= 2 / 255) >= 0.99, f"max diff {diff.max() * 255:.1f}/255"
    assert mean_abs(rot, base) > 0.02  # the blob is not symmetric: rotation is visible


@pytest.mark.parametrize("warp_cls", [AffineWarp, GenericAffine])
def test_iso_shading_goes_through_jacobian(offscreen: Any, warp_cls: type) -> None:
    # Rotating the object by R (warp) looks like rotating the camera by R^-1 (headlight
    # included) -- only if normals are carried by the warp's Jacobian. R turns +y to +z
    # about the x axis through the centre; the cube box maps onto itself, so both renders
    # sample the same points of the original volume.
    vol = blob()
    cam, size = aligned_camera(vol, "+z")
    warp = warp_cls.rotation((1, 0, 0), 90.0, center=vol.center)
    moved = render(offscreen, iso_scene(vol, cam, [warp]), size)
    r_inv = warp.inverse[:3, :3]
    cam2 = Camera(
        center=cam.center,
        rotation=r_inv @ cam.rotation,
        distance=cam.distance,
        projection="orthographic",
        ortho_height=cam.ortho_height,
        radius=cam.radius,
    )
    turned = render(offscreen, iso_scene(vol, cam2), size)
    diff = np.abs(moved - turned).max(axis=-1)
    assert np.mean(diff <= 2 / 255) >= 0.99, f"max diff {diff.max() * 255:.1f}/255"
    plain = render(offscreen, iso_scene(vol, cam), size)
    assert mean_abs(moved, plain) > 0.01  # the rotation is visible from +z


def _shading_ratio(offscreen: Any, mode: str) -> float:
    """Mean brightness of shaded / unshaded renders over the pixels the mode draws."""
    shaded = render(offscreen, phantom_scene(mode=mode, shading=True), (64, 64))
    flat = render(offscreen, phantom_scene(mode=mode, shading=False), (64, 64))
    hit = np.any(np.abs(flat[..., :3] - np.asarray(PHANTOM_BG[:3], np.float32)) > 2 / 255, -1)
    assert hit.mean() > 0.02
    return float(shaded[hit, :3].mean() / flat[hit, :3].mean())


def test_iso_honours_shading_off(offscreen: Any) -> None:
    assert _shading_ratio(offscreen, "iso") != pytest.approx(1.0, abs=1e-3)


def test_flm_shading_is_lit_like_a_surface(offscreen: Any) -> None:
    # a convex bright blob under a headlight: about ambient + 2/3 diffuse (~0.7)
    assert _shading_ratio(offscreen, "flm") >= 0.5


# ---------------------------------------------------------------------- clipping
def test_clip_box_cuts_image(offscreen: Any) -> None:
    vol = smooth_volume((24, 20, 16), np.uint8, 0, 255, seed=8)
    cam, size = aligned_camera(vol, "+z")
    base = render(offscreen, grey_scene(vol, "mip", "+z", cam, background=BLUE), size)
    # clip x to voxels 4..15 and y to 2..11 (box faces on voxel boundaries)
    box = ((3.5, 1.5, -10.0), (15.5, 11.5, 100.0))
    img = render(offscreen, grey_scene(vol, "mip", "+z", cam, background=BLUE, clip_box=box), size)
    inside = np.zeros(size[::-1], bool)
    rows = slice(size[1] - 1 - 11, size[1] - 1 - 2 + 1)  # y 11..2 from the top
    inside[rows, 4:16] = True
    assert max_diff(img[inside], base[inside]) <= EXACT_TOL
    assert np.all(img[~inside] == np.asarray(BLUE, np.float32))
    # clipping along the ray: only the voxels with z <= 7 remain
    box = ((-10.0, -10.0, -10.0), (100.0, 100.0, 7.5))
    img = render(offscreen, grey_scene(vol, "mip", "+z", cam, clip_box=box), size)
    expected = windowed(vol.data[:, :, :8].max(axis=2).T[::-1].astype(float), full_window(vol))
    assert max_diff(img[..., 0], expected) <= EXACT_TOL


# ---------------------------------------------------------------------- errors / output
def test_volume_over_budget_raises(gl_ctx: Any, offscreen: Any) -> None:
    vol = Volume(np.zeros((16, 16, 16), np.uint8))  # 4096 bytes of texture
    scene = Scene(vol, transfer_function="grayscale")
    fbo = offscreen(8, 8).framebuffer
    renderer = Renderer(gl_ctx, texture_budget_bytes=1000, sampling="texture3d")
    try:
        with pytest.raises(VolumeTooLargeError) as info:
            renderer.draw(scene, fbo)
    finally:
        renderer.release()
    msg = str(info.value)
    assert "budget" in msg
    assert "downsample" in msg.lower()
    assert "downsample=2" in msg  # (4096 B / 1000 B) ** (1/3) -> factor 2
    assert gl_ctx.error == "GL_NO_ERROR"


def test_perspective_differs_from_orthographic(offscreen: Any) -> None:
    a = render(offscreen, phantom_scene(mode="mip", projection="perspective"), (64, 64))
    b = render(offscreen, phantom_scene(mode="mip", projection="orthographic"), (64, 64))
    assert mean_abs(a, b) > 0.01


def test_uint8_output_row_zero_is_top(offscreen: Any) -> None:
    data = np.zeros((24, 20, 16), np.uint8)
    data[:, 16:, :] = 255  # bright only at high y
    vol = Volume(data)
    cam, size = aligned_camera(vol, "+z")
    img = render(offscreen, grey_scene(vol, "mip", "+z", cam), size, dtype="u1")
    assert img.dtype == np.uint8
    assert img.shape == (20, 24, 4)
    assert np.all(img[:4, :, :3] == 255)  # y = 19..16 are the top rows
    assert np.all(img[4:, :, :3] == 0)
    assert np.all(img[..., 3] == 255)


# ---------------------------------------------------------------------- golden images
@pytest.mark.parametrize("mode", MODES)
def test_golden_image(offscreen: Any, golden: Any, mode: str) -> None:
    scene = phantom_scene(
        mode=mode, projection="perspective", view=(30, 20), zoom=1.1, jitter=True, seed=0
    )
    if mode == "dvr":  # the golden DVR image is unshaded (DVR's default shading came later)
        scene.shading = False
    img = render(offscreen, scene, (96, 96), dtype="u1")
    # llvmpipe versions differ slightly: 99.5 % of pixels within 3/255, none beyond 24/255
    golden(f"render_{mode}", img, 3 / 255, fraction=0.995, max_abs=24 / 255)


# ---------------------------------------------------------------------- sampling paths
@pytest.mark.parametrize("mode", ["dvr", "mip", "iso", "flm", "average"])
def test_slice_pair_sampling_matches_texture3d(gl_ctx: Any, mode: str) -> None:
    """The slice-pair texture (bilinear + lerp in z) reproduces hardware trilinear.

    Tolerance 2/255: both are trilinear interpolation of the same voxels, differing
    only in filtering precision (llvmpipe uses 8-bit fixed-point weights).
    """
    scene = phantom_scene(mode=mode)
    images = []
    for sampling in ("texture3d", "slice_pairs"):
        with OffscreenRenderer(64, 64, ctx=gl_ctx, dtype="f4") as r:
            r.renderer.release()
            r.renderer = Renderer(gl_ctx, sampling=sampling)
            images.append(r.render(scene))
    assert np.abs(images[0] - images[1]).max() <= 2 / 255
    assert np.abs(images[0] - np.asarray(PHANTOM_BG, np.float32)).max() > 0.05  # not empty


@pytest.mark.parametrize("mode", ["dvr", "iso", "flm"])
def test_cell_block_and_no_skipping_give_the_same_image(gl_ctx: Any, mode: str) -> None:
    """Every empty-space-skipping strategy renders the same image (tolerance 1/255):
    skipping only jumps over samples that cannot contribute, on the same lattice."""
    scene = phantom_scene(mode=mode)
    images = {}
    for kind in ("cells", "blocks", "none"):
        with OffscreenRenderer(64, 64, ctx=gl_ctx, dtype="f4") as r:
            r.renderer.cell_skipping = kind == "cells"
            r.renderer.empty_space_skipping = kind != "none"
            images[kind] = r.render(scene)
    assert np.abs(images["cells"] - images["none"]).max() <= 1 / 255
    assert np.abs(images["blocks"] - images["none"]).max() <= 1 / 255
    assert np.abs(images["none"] - np.asarray(PHANTOM_BG, np.float32)).max() > 0.05


# ---------------------------------------------------------------------- interactive use
def _warped_scene() -> Scene:
    from benchmarks.offset_inverse import gaussian_drag_field
    from voxwarp.deform.elements.offset_field import OffsetFieldWarp

    vol = phantom()
    lo, hi = vol.bounds
    field = gaussian_drag_field((6, 6, 6), (3, 3, 3), (5.0, -2.0, 1.0), 1.0)
    warp = OffsetFieldWarp(lo, hi, field, shape=(6, 6, 6))
    return Scene(vol, mode="dvr", transfer_function="ct-bone", warps=[warp], jitter=False)


def _draw(r: OffscreenRenderer, fn: Any) -> np.ndarray:
    with r.current():
        fn()
        raw = r.framebuffer.read(components=4, alignment=1)
    w, h = r.size
    return np.frombuffer(raw, np.uint8).reshape(h, w, 4)[::-1].astype(np.float64)


def test_draw_scaled_is_draw_at_scale_one_and_a_blurred_draw_below(offscreen: Any) -> None:
    """The interactive level of detail: scale 1 is exactly :meth:`Renderer.draw`; scale 0.5
    draws a quarter of the pixels and upscales them, so the frame is close to the full one
    (same picture, softer) without being it."""
    r = offscreen(96, 80)
    scene = _warped_scene()
    full = r.render(scene)[..., :4].astype(np.float64)
    one = _draw(r, lambda: r.renderer.draw_scaled(scene, r.framebuffer, scale=1.0))
    np.testing.assert_array_equal(one, full)
    half = _draw(r, lambda: r.renderer.draw_scaled(scene, r.framebuffer, scale=0.5))
    assert np.abs(half - full).mean() < 0.15 * full.mean()
    assert np.abs(half - full).max() > 8  # it is a lower resolution, not the same draw
    # the low-resolution frame itself: a 48 x 40 render, upscaled, matches at its pixels
    small = offscreen(48, 40).render(scene).astype(np.float64)
    centres = half[1::2, 1::2]  # upscaled pixels between two low-res texel centres
    assert np.abs(centres - small).mean() < 0.1 * small.mean() + 1


def test_background_skip_maps_are_offered_as_a_job_and_do_not_change_the_image(
    offscreen: Any,
) -> None:
    """``warped_skip_maps = "background"``: a warped draw marches blocks and offers the
    skip-map work as a job (CPU only, any thread); once its result is installed the same
    state draws with cell skipping, pixel for pixel the same image."""
    r = offscreen(64, 64)
    scene = _warped_scene()
    rr = r.renderer
    old = rr.warped_skip_maps
    rr.warped_skip_maps = "background"
    try:
        assert rr.needs_skip_maps(scene)
        blocks = r.render(scene)
        assert rr.last_skip_kind == "blocks"
        wanted = rr.skip_map_job()
        assert wanted is not None
        assert rr.skip_map_job() is None  # handed out once
        key, job = wanted
        rr.install_skip_map(key, job())
        assert not rr.needs_skip_maps(scene)
        cells = r.render(scene)
        assert rr.last_skip_kind == "cells"
        np.testing.assert_array_equal(cells, blocks)
        # a new warp state needs new maps
        scene.warps[0].inverse = "approx"
        assert rr.needs_skip_maps(scene)
    finally:
        rr.warped_skip_maps = old


def test_a_closed_renderer_says_so_in_one_line(gl_ctx: Any) -> None:
    """Rendering after the ``with`` block (or release) is a RenderError naming the fix,
    not a moderngl traceback; releasing twice stays harmless."""
    from voxwarp.errors import RenderError

    scene = Scene(Volume(np.zeros((4, 4, 4), np.uint8), spacing=(1, 1, 1)))
    with OffscreenRenderer(16, 16, ctx=gl_ctx) as r:
        assert r.render(scene).shape == (16, 16, 4)
    for use in (lambda: r.render(scene), lambda: r.render_slice(scene, "z")):
        with pytest.raises(RenderError, match=r"closed.*make a new one"):
            use()
    r.release()
