"""``flm`` and ``iso`` with their default levels (voxwarp.core.levels) on real scans and on
a noisy phantom: rays that cross only background (air, noise) draw the background colour,
rays that cross the object draw it (not a flat box, not speckle).

The oracle of "crosses the object" is a MIP of the same scene and camera (same samples:
orthographic, no jitter) through a window that turns white just above the level, and for
the phantom the ball's known outline.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from scipy import ndimage

from tests.core.test_levels import phantom
from voxwarp.core.volume import Volume
from voxwarp.inputs import load_input
from voxwarp.scene import Scene

BG = (0.2, 0.3, 0.4, 1.0)
SIZE = 128


def is_background(img: np.ndarray) -> np.ndarray:
    return np.all(np.abs(img[..., :3] - np.asarray(BG[:3], np.float32)) <= 1.5 / 255, axis=-1)


def draw(offscreen: Any, scene: Scene) -> np.ndarray:
    return offscreen(SIZE, SIZE, dtype="f4").render(scene)


def rays_above(offscreen: Any, scene: Scene, level: float) -> tuple[np.ndarray, np.ndarray]:
    """``(above, below)``: pixels whose ray's maximum is above ``level`` (by a hair) and
    those whose maximum is at most ``level`` (off the volume included)."""
    eps = 1e-4 * float(np.ptp(scene.volume.value_range) or 1.0)
    mip = scene.copy(mode="mip", window=(level + eps / 2, eps), background=(0, 0, 0, 1))
    grey = draw(offscreen, mip)[..., 0]
    return grey >= 0.999, grey <= 1e-6


def threshold_scene(vol: Volume, mode: str) -> Scene:
    return Scene(vol, mode=mode, projection="orthographic", jitter=False, background=BG)


def check_coverage(offscreen: Any, scene: Scene) -> tuple[float, float, float]:
    """The share of object rays drawn, of background rays left as background, and of the
    rays through the volume's box left as background."""
    img = draw(offscreen, scene)
    level = scene.resolved_level().value
    above, below = rays_above(offscreen, scene, level)
    in_box, _ = rays_above(offscreen, scene, scene.volume.value_range[0] - 1.0)
    bg = is_background(img)
    return float(np.mean(~bg[above])), float(np.mean(bg[below])), float(np.mean(bg[in_box]))


@pytest.mark.slow
@pytest.mark.parametrize("sample", ["colin27", "stent"])
@pytest.mark.parametrize("mode", ["flm", "iso"])
def test_real_scans_show_the_object_on_background(offscreen: Any, sample: str, mode: str) -> None:
    scene = threshold_scene(load_input(f"sample:{sample}"), mode)
    drawn, background, box_background = check_coverage(offscreen, scene)
    # measured: drawn 1.0, background 1.0; background in the box 18 % (colin27), 38 %
    # (stent flm), 82 % (stent iso); the old stent FLM (threshold 0) drew the whole box
    assert drawn >= 0.97, f"{sample} {mode}: only {drawn:.1%} of the object's rays drawn"
    assert background >= 0.995, f"{sample} {mode}: {1 - background:.1%} of background rays drawn"
    # not a flat box: the air and noise around the object in the box stay background
    assert box_background >= 0.1, f"{sample} {mode}: {box_background:.1%} of the box is background"


@pytest.mark.slow
def test_mri_iso_is_the_skin(offscreen: Any) -> None:
    """colin27's default iso surface is its outer surface: its silhouette is the head's,
    the rays meeting any voxel brighter than 2 % of the value range (colin27's air is 0),
    without holes."""
    scene = threshold_scene(load_input("sample:colin27"), "iso")
    drawn = ~is_background(draw(offscreen, scene))
    head, _ = rays_above(offscreen, scene, 0.02 * scene.volume.value_range[1])
    iou = np.count_nonzero(drawn & head) / np.count_nonzero(drawn | head)
    holes = ndimage.binary_fill_holes(drawn) & ~drawn
    assert iou >= 0.95, f"the iso silhouette covers {iou:.1%} of the head's (IoU)"
    assert holes.sum() <= 0.002 * drawn.sum(), "holes in the head's surface"


@pytest.mark.parametrize("kind", ["mri", "ct"])
@pytest.mark.parametrize("mode", ["flm", "iso"])
def test_noisy_ball_shows_the_ball_and_no_noise(offscreen: Any, kind: str, mode: str) -> None:
    """A ball in Gaussian/Rician noise (tests/core/test_levels.py): pixels off the ball's
    outline (by 1.5 voxels) are background, pixels inside it are the ball."""
    data, _ = phantom(kind)
    vol = Volume(data, units="HU" if kind == "ct" else "")
    scene = threshold_scene(vol, mode).copy(view="+z")
    img = draw(offscreen, scene)
    cam = scene.resolved_camera()
    pixel = cam.ortho_height / SIZE
    offs = (np.arange(SIZE) - SIZE / 2 + 0.5) * pixel
    x = cam.center[0] + offs[None, :]  # +z view: screen right +x, up +y (row 0 at the top)
    y = cam.center[1] - offs[:, None]
    centre = (data.shape[0] - 1) / 2
    r = np.hypot(x - centre, y - centre)
    bg = is_background(img)
    assert np.all(bg[r > 14.0 + 1.5]), "noise drawn off the ball"
    inside = r < 14.0 - 1.5
    assert np.mean(~bg[inside]) >= 0.99, "the ball is not drawn"
