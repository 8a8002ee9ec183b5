"""Fixed/moving comparison (``Scene(fixed=...)``) in 3D and in slices.

Oracles:

* identity: the fixed image equal to the moving one and no warp: the 3D difference
  (``|moving - fixed|`` through a transfer function transparent at 0) is the bare
  background, the 3D checkerboard is the moving image's own render, and the slice's
  fixed values equal its moving values;
* physical placement: the same data stored flipped and permuted (the direction matrix
  says so) lies at the same world points: slice values agree to the texture filter's
  tolerance and the 3D difference stays (nearly) background;
* the 3D checkerboard against the two volumes rendered alone (same grid, camera and
  transfer function): an orthographic view along z through a volume one cell deep, so
  every pixel's ray lies in one cell: it equals the moving render where the cell is
  even and the fixed render where odd (:func:`voxwarp.core.comparison.checker_fixed`,
  the CPU pattern at the pixel's world point), away from cell borders;
* slices: blend 0 and 1 give the moving and fixed colours, and the world checker
  pattern picks the fixed colours exactly where :func:`checker_fixed` says.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

from voxwarp.core.comparison import Comparison, checker_fixed, default_checker_mm
from voxwarp.core.transfer_function import TransferFunction
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import AffineWarp
from voxwarp.errors import SceneError
from voxwarp.render.slice_image import colorize
from voxwarp.scene import Scene

SHAPE = (24, 20, 6)
ORIGIN = (-11.5, -9.5, 1.5)  # box x -12..12, y -10..10, z 1..7: one 8 mm cell deep
CELL = 8.0
SIZE = (96, 80)
#: trilinear filtering with 8-bit weights: 3/512 of the value range (tests/render/test_slices.py)
FILTER = 3 * 255 / 512


def _blobs(seed: int) -> np.ndarray:
    """Smooth uint8 data (a few Gaussian blobs), so shading and filtering are tame."""
    rng = np.random.default_rng(seed)
    x, y, z = np.meshgrid(*(np.arange(n, dtype=float) for n in SHAPE), indexing="ij")
    v = np.zeros(SHAPE)
    for _ in range(6):
        c = rng.uniform((0, 0, 0), SHAPE)
        v += np.exp(-((x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2) / 18.0)
    return (255 * v / v.max()).astype(np.uint8)


def _volume(seed: int = 1) -> Volume:
    return Volume(_blobs(seed), (1.0, 1.0, 1.0), ORIGIN, space="RAS")


def _flipped_permuted(vol: Volume) -> Volume:
    """The same voxels at the same world points, stored with x reversed and x/y swapped."""
    n = vol.shape[0]
    data = np.asfortranarray(vol.data[::-1].transpose(1, 0, 2))
    origin = np.asarray(vol.origin) + np.array([(n - 1) * vol.spacing[0], 0.0, 0.0])
    direction = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    spacing = (vol.spacing[1], vol.spacing[0], vol.spacing[2])
    return Volume(data, spacing, origin, direction=direction, space="RAS")


TF = TransferFunction([(0, 0, 0, 0, 0), (40, 0.2, 0.4, 1.0, 0.0), (255, 1.0, 0.9, 0.6, 0.8)])


def _scene(vol: Volume, **kw: Any) -> Scene:
    base = {
        "transfer_function": TF,
        "view": "+z",
        "projection": "orthographic",
        "jitter": False,
        "shading": False,
        "background": (0.0, 0.0, 0.0, 1.0),
    }
    return Scene(vol, **{**base, **kw})


@pytest.fixture(scope="module")
def r3d(offscreen: Any) -> Any:
    return offscreen(*SIZE)


def _diff(a: np.ndarray, b: np.ndarray) -> int:
    return int(np.abs(a.astype(int) - b.astype(int)).max())


def test_identity_difference_is_background_and_checker_is_moving(r3d: Any) -> None:
    vol = _volume()
    moving = r3d.render(_scene(vol))
    assert moving[..., :3].max() > 60  # the volume shows
    diff = r3d.render(_scene(vol, fixed=vol, compare="difference"))
    assert diff[..., :3].max() <= 1
    checker = r3d.render(_scene(vol, fixed=vol, compare="checkerboard", checker_mm=CELL))
    assert _diff(checker, moving) <= 1
    for b in (0.0, 1.0):
        blend = r3d.render(_scene(vol, fixed=vol, compare="blend", blend=b))
        assert _diff(blend, moving) <= 1


@pytest.mark.parametrize("gradient_texture", [True, False])
def test_shaded_checkerboard_of_the_same_image_is_the_moving_render(
    r3d: Any, gradient_texture: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Shading in fixed cells uses the fixed image's gradient (its gradient texture, or
    central differences in world mm for a volume over the texture limit): the same
    image gives the same shaded picture, to the gradients' rounding."""
    from voxwarp.render import fixed_texture

    if not gradient_texture:  # both images by central differences
        monkeypatch.setattr(fixed_texture, "MAX_VOXELS", 0)
        monkeypatch.setattr(r3d.renderer, "gradient_texture", False)
    vol = _volume()
    moving = r3d.render(_scene(vol, shading=True, view=(30.0, 20.0)))
    checker = r3d.render(_scene(vol, fixed=vol, checker_mm=CELL, shading=True, view=(30.0, 20.0)))
    assert _diff(checker, moving) <= 4
    other = r3d.render(_scene(vol, fixed=_volume(seed=2), checker_mm=CELL, shading=True))
    assert _diff(other, moving) > 20


def test_fixed_on_another_grid_lines_up(r3d: Any) -> None:
    vol = _volume()
    other = _flipped_permuted(vol)
    # the construction is right: world point of voxel (i, j, k) of vol holds the same value
    ijk = np.array([3, 5, 2])
    q = np.rint(other.world_to_index(vol.index_to_world(ijk))).astype(int)
    assert other.data[tuple(q)] == vol.data[tuple(ijk)]
    diff = r3d.render(_scene(vol, fixed=other, compare="difference"))
    assert diff[..., :3].max() <= 3
    # a fixed image that differs shows: the oracle can fail
    shifted = r3d.render(_scene(vol, fixed=_volume(seed=2), compare="difference"))
    assert shifted[..., :3].max() > 40


def _constant_field(d: np.ndarray) -> Any:
    """A pull-back field ``u = d`` on a grid well around the test volumes."""
    from voxwarp.deform.fields.displacement import DisplacementFieldWarp

    n = 13
    affine = np.diag([5.0, 5.0, 5.0, 1.0])
    affine[:3, 3] = -30.0
    return DisplacementFieldWarp(np.broadcast_to(d, (n, n, n, 3)).copy(), affine)


@pytest.mark.parametrize("kind", ["affine", "field"])
def test_moving_seen_through_the_chain_matches_the_fixed(r3d: Any, kind: str) -> None:
    """The moving image is the fixed one moved by d; the chain's pull-back p -> p + d
    (a translation: straight rays; a constant field: warped rays) brings it back onto
    the fixed image, so the difference is (nearly) background; the wrong sign is not."""
    d = np.array([3.0, -2.0, 1.0])
    fixed = _volume()
    moving = fixed.with_geometry(origin=tuple(np.asarray(fixed.origin) + d))

    def chain(sign: float) -> list:
        if kind == "affine":
            return [AffineWarp.translation(-sign * d)]
        return [_constant_field(sign * d)]

    right = r3d.render(_scene(moving, warps=chain(1.0), fixed=fixed, compare="difference"))
    wrong = r3d.render(_scene(moving, warps=chain(-1.0), fixed=fixed, compare="difference"))
    assert right[..., :3].max() <= 3
    assert wrong[..., :3].max() > 40


def _pixel_points(scene: Scene, size: tuple[int, int]) -> np.ndarray:
    """(H, W, 3) world points on each pixel centre's ray (orthographic: any depth)."""
    w, h = size
    inv = np.linalg.inv(scene.resolved_camera().view_projection(w / h))
    cols, rows = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    ndc = np.stack([cols / w * 2 - 1, 1 - rows / h * 2, np.zeros_like(cols), np.ones_like(cols)])
    p = np.einsum("ij,jhw->hwi", inv, ndc)
    return p[..., :3] / p[..., 3:]


def test_3d_checkerboard_matches_the_two_renders(r3d: Any) -> None:
    moving_vol, fixed_vol = _volume(1), _volume(2)
    moving = r3d.render(_scene(moving_vol))
    fixed = r3d.render(_scene(fixed_vol))
    assert _diff(moving, fixed) > 40  # the two differ: the oracle can fail
    scene = _scene(moving_vol, fixed=fixed_vol, checker_mm=CELL)
    checker = r3d.render(scene)
    pts = _pixel_points(scene, SIZE)
    pts[..., 2] = 4.0  # the box's depth lies in one cell layer (z 1..7 mm)
    odd = checker_fixed(pts, CELL)
    px = 24.0 / SIZE[0] * 2  # two pixels of margin, in mm (generous)
    inner = np.all(np.abs(pts[..., :2] / CELL - np.rint(pts[..., :2] / CELL)) * CELL > px, -1)
    assert odd[inner].any()
    assert (~odd[inner]).any()
    want = np.where(odd[..., None], fixed, moving)
    assert _diff(checker[inner], want[inner]) <= 1


def test_comparison_settings_are_checked() -> None:
    vol = _volume()
    with pytest.raises(SceneError, match="compare must be one of"):
        Scene(vol, fixed=vol, compare="swipe")
    with pytest.raises(SceneError, match="blend must be in"):
        Scene(vol, fixed=vol, compare="blend", blend=1.5)
    with pytest.raises(SceneError, match="checker size"):
        Scene(vol, fixed=vol, checker_mm=0)
    # the default cell: an eighth of the longest side (24 mm), two significant digits
    assert default_checker_mm(vol) == 3.0
    c = Comparison(vol, "difference")
    m, f = np.array([5.0, 1.0]), np.array([2.0, 4.0])
    assert np.allclose(c.combine(m, f, np.zeros((2, 3))), [3.0, 3.0])


def test_scene_json_keeps_the_fixed_image(tmp_path: Any) -> None:
    from voxwarp.io.volumes import save_volume

    vol = _volume()
    fixed_path = save_volume(_volume(seed=2), tmp_path / "fixed.nrrd")
    scene = Scene(vol, fixed=str(fixed_path), compare="difference", checker_mm=5.0)
    path = scene.save(tmp_path / "scene.json")
    d = json.loads(path.read_text())
    assert d["fixed"]["path"] == "fixed.nrrd"  # relative to the scene, as the volume's
    back = Scene.load(path)
    assert back.comparison is not None
    assert back.comparison.show == "difference"
    assert back.comparison.checker_mm == 5.0
    assert np.array_equal(back.fixed.data, _volume(seed=2).data)
    assert "fixed" not in Scene(vol).to_dict()  # no comparison: scene JSON as before
    d["compare"]["swipe"] = 1
    with pytest.raises(SceneError, match="drop swipe"):
        Scene.from_dict(d, base_dir=tmp_path)


# ------------------------------------------------------------------------------ slices
def _slice(offscreen: Any, scene: Scene, **kw: Any) -> Any:
    r = offscreen(16, 16)
    return r.render_slice(scene, "z", size=(48, 40), at=4.0, **kw)


def test_slice_identity_and_other_grid(offscreen: Any) -> None:
    vol = _volume()
    same = _slice(offscreen, _scene(vol, fixed=vol))
    inside = np.isfinite(same.values)
    assert inside.mean() > 0.5
    assert np.array_equal(np.isfinite(same.fixed), inside)
    assert np.abs(same.fixed - same.values)[inside].max() < 1e-2
    other = _slice(offscreen, _scene(vol, fixed=_flipped_permuted(vol)))
    err = np.abs(other.fixed - other.values)[inside]
    assert err.max() <= FILTER
    third = _slice(offscreen, _scene(vol, fixed=_volume(seed=2)))
    assert np.abs(third.fixed - third.values)[inside].max() > 20


def test_slice_blend_checker_and_difference(offscreen: Any) -> None:
    moving_vol, fixed_vol = _volume(1), _volume(2)
    # a warp: the moving side goes through the chain, the fixed side does not
    warp = AffineWarp.translation((1.5, -1.0, 0.0))
    scene = _scene(moving_vol, fixed=fixed_vol, warps=[warp], checker_mm=CELL)
    win = (128.0, 256.0)
    img = _slice(offscreen, scene, window=win, show="deformed")
    moving = img.rgba.copy()
    fixed = colorize(img, window=win, show="rest")
    assert _diff(moving, fixed) > 20
    assert _diff(colorize(img, window=win, show="blend", blend=0.0), moving) == 0
    assert _diff(colorize(img, window=win, show="blend", blend=1.0), fixed) == 0
    checker = colorize(img, window=win, show="checkerboard", checker_mm=CELL)
    odd = checker_fixed(img.pixel_points(), CELL)
    assert odd.any()
    assert (~odd).any()
    assert np.array_equal(checker, np.where(odd[..., None], fixed, moving))
    same = _slice(offscreen, _scene(moving_vol, fixed=moving_vol), window=win, show="difference")
    rgb = same.rgba[..., :3].astype(int)
    assert np.array_equal(rgb[..., 0], rgb[..., 2])  # no red, no blue: no difference
