"""The volume at the interactive resolution (``Scene.interactive_downsample``): the same
box and world geometry at every level (a linear ramp's exact block means, a ball drawn
where it is, warps applied unchanged), and scene JSON that keeps it."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from voxwarp.core.volume import Volume
from voxwarp.deform.warp import AffineWarp
from voxwarp.errors import SceneError
from voxwarp.render.interaction_volume import InteractionVolumes, reduced_volume
from voxwarp.scene import Scene

SIZE = (96, 80)
#: the ramp's gradient in value per world mm
GRADIENT = np.array([0.5, -0.25, 0.125])


def _ramp(shape: tuple[int, int, int], direction: np.ndarray | None = None) -> Volume:
    """A float volume whose value is a linear function of the world position (mm)."""
    kw: dict[str, Any] = {} if direction is None else {"direction": direction}
    vol = Volume(np.zeros(shape, np.float32), (0.7, 1.3, 2.0), (-10.0, 4.0, 2.5), **kw)
    ijk = np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), -1)
    world = vol.index_to_world(ijk.reshape(-1, 3)).reshape(*shape, 3)
    data = (world @ GRADIENT + 3.0).astype(np.float32)
    return vol.with_geometry(data)


def _world_of_voxels(vol: Volume) -> np.ndarray:
    ijk = np.stack(np.meshgrid(*[np.arange(n) for n in vol.shape], indexing="ij"), -1)
    return vol.index_to_world(ijk.reshape(-1, 3)).reshape(*vol.shape, 3)


@pytest.mark.parametrize("factor", [2, 3, 5, 16])
def test_reduced_volume_keeps_the_box_and_the_world_positions(factor: int) -> None:
    """Shapes that the factor divides or not, axis-aligned or oblique: the same box
    (corners), and each new voxel holds a ramp's value at its own world position:
    exactly where whole blocks average, within a quarter of an old voxel where a new
    voxel covers parts of old ones (a half-shifted grid would be ``factor / 2`` off)."""
    c, s = np.cos(0.4), np.sin(0.4)
    oblique = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    for direction in (None, oblique):
        for shape in ((23, 17, 11), tuple(factor * n for n in (3, 2, 1))):
            vol = _ramp(shape, direction)
            small = reduced_volume(vol, factor)
            assert small.shape == tuple(int(np.ceil(n / factor)) for n in vol.shape)
            np.testing.assert_allclose(small.corners(), vol.corners(), atol=1e-9)
            expected = _world_of_voxels(small) @ GRADIENT + 3.0
            per_voxel = np.abs(GRADIENT @ vol.direction) * np.asarray(vol.spacing)
            divides = all(n % factor == 0 for n in shape)
            tol = 1e-4 if divides else 0.25 * per_voxel.sum()
            np.testing.assert_allclose(small.data, expected, atol=tol)


def test_reduced_volume_keeps_the_total_and_integer_types() -> None:
    rng = np.random.default_rng(3)
    vol = Volume(rng.integers(0, 4000, (30, 21, 14)).astype(np.uint16), (1.0, 1.0, 1.0))
    small = reduced_volume(vol, 4)
    assert small.dtype == np.uint16
    # every old voxel counts once, by its overlap: the mass is kept (up to the rounding)
    mass = small.data.astype(np.float64).sum() * np.prod(small.spacing)
    assert mass == pytest.approx(vol.data.astype(np.float64).sum(), rel=1e-3)
    assert reduced_volume(vol, 1) is vol


def test_interaction_volumes_cache_one_copy_per_volume_and_level() -> None:
    vol = _ramp((20, 20, 20))
    cache = InteractionVolumes()
    assert cache.cached(vol, 2) is None  # not made yet: a GUI makes it on a worker
    assert cache.cached(vol, 1) is vol
    a = cache.volume(vol, 2)
    assert cache.cached(vol, 2) is a
    assert cache.volume(vol, 2) is a
    assert cache.volume(vol, 4) is not a
    assert cache.volume(vol, 1) is vol
    other = _ramp((20, 20, 20))
    cache.put(other, 2, a)  # a copy made elsewhere
    assert cache.volume(other, 2) is a


def test_scene_json_keeps_the_setting_and_old_files_load() -> None:
    vol = _ramp((12, 12, 12))
    scene = Scene(vol, interactive_downsample=4)
    d = scene.to_dict()
    assert d["interactive_downsample"] == 4
    assert Scene.from_dict(d).interactive_downsample == 4
    assert scene.copy().interactive_downsample == 4
    # full resolution writes nothing: files stay as before, and those load at 1
    d.pop("interactive_downsample")
    assert Scene.from_dict(d).interactive_downsample == 1
    assert "interactive_downsample" not in Scene(vol).to_dict()
    for bad in (0, 17, 2.5, True, "2"):
        with pytest.raises(SceneError, match="interactive downsample must be an integer"):
            Scene(vol, interactive_downsample=bad)  # type: ignore[arg-type]
    with pytest.raises(SceneError, match="interactive_downsample"):
        Scene.from_dict({**d, "interactive_downsample": "2"})


def _ball(shape: tuple[int, int, int] = (63, 57, 41)) -> Volume:
    """A bright ball of radius 9 mm off the volume's centre, in a dark box."""
    vol = Volume(np.zeros(shape, np.float32), (1.0, 1.2, 1.5), (-20.0, -30.0, -25.0))
    d = np.linalg.norm(_world_of_voxels(vol) - np.array([6.0, 0.0, -4.0]), axis=-1)
    return vol.with_geometry(np.clip(10.0 - d, 0.0, 1.0).astype(np.float32) * 100.0)


def _mask(img: np.ndarray) -> np.ndarray:
    return img[..., :3].astype(np.float64).max(axis=-1) > 60


@pytest.mark.parametrize("warped", [False, True])
def test_the_reduced_volume_draws_the_same_geometry(offscreen: Any, warped: bool) -> None:
    """A MIP of the ball (and of the ball moved by a warp) at 1/3 resolution covers the
    same pixels as at full resolution: the same silhouette, centre within a pixel."""
    vol = _ball()
    warps = [AffineWarp.translation((5.0, -4.0, 3.0))] if warped else []
    scene = Scene(vol, mode="mip", view="+z", projection="orthographic", jitter=False, warps=warps)
    scene.window = (50.0, 100.0)
    camera = scene.resolved_camera()
    full = offscreen(*SIZE).render(scene, camera)
    scene.interactive_downsample = 3
    small_scene = InteractionVolumes().scene(scene)
    assert small_scene.volume.shape == (21, 19, 14)
    np.testing.assert_allclose(small_scene.ray_bounds(), scene.ray_bounds(), atol=1e-9)
    small = offscreen(*SIZE).render(small_scene, camera)
    a, b = _mask(full), _mask(small)
    assert a.sum() > 200  # the ball shows
    iou = (a & b).sum() / (a | b).sum()
    assert iou > 0.85
    ca, cb = (np.argwhere(m).mean(axis=0) for m in (a, b))
    assert np.abs(ca - cb).max() < 1.0


def test_a_slice_through_the_ball_is_in_the_same_place(offscreen: Any) -> None:
    """An axial slice through the (translated) ball's centre: the same pixel grid, and
    the disc at 1/3 resolution where it is at full resolution (centre within half a mm,
    area within 10 %); its centre is where the warp moved the ball."""
    vol = _ball()
    move = np.array([5.0, -4.0, 3.0])
    scene = Scene(vol, jitter=False, warps=[AffineWarp.translation(tuple(move))])
    z = -4.0 + move[2]
    full = offscreen(*SIZE).render_slice(scene, "z", at=z, pixel_mm=0.5)
    scene.interactive_downsample = 3
    small = offscreen(*SIZE).render_slice(
        InteractionVolumes().scene(scene), "z", at=z, pixel_mm=0.5
    )
    np.testing.assert_allclose(small.pixel_to_world, full.pixel_to_world)
    centres, areas = [], []
    for image in (full, small):
        disc = np.asarray(image.values) > 50.0
        areas.append(disc.sum() * 0.25)
        rc = np.argwhere(disc).mean(axis=0)
        centres.append((image.pixel_to_world @ np.array([rc[1], rc[0], 0.0, 1.0]))[:3])
    np.testing.assert_allclose(centres[0][:2], np.array([6.0, 0.0]) + move[:2], atol=0.5)
    np.testing.assert_allclose(centres[1], centres[0], atol=0.5)
    assert areas[1] == pytest.approx(areas[0], rel=0.1)
    assert areas[0] == pytest.approx(np.pi * 9.5**2, rel=0.1)


def test_stills_ignore_the_interactive_resolution(offscreen: Any) -> None:
    """``voxwarp render``, exports and screenshots draw ``scene.volume``: a scene set to
    1/4 while interacting renders the very picture of the same scene at 1."""
    scene = Scene(_ball(), mode="mip", view="+z", jitter=False)
    scene.window = (50.0, 100.0)
    full = np.asarray(offscreen(*SIZE).render(scene))
    scene.interactive_downsample = 4
    assert np.array_equal(np.asarray(offscreen(*SIZE).render(scene)), full)
    coarse = np.asarray(offscreen(*SIZE).render(InteractionVolumes().scene(scene)))
    assert not np.array_equal(coarse, full)  # the interactive picture is another one
