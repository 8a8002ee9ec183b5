"""DVR compositing, transfer-function colour and FLM's first-local-maximum rule against
numpy references written from the shaders' rules (not from golden images).

Both tests use the pixel-aligned orthographic camera of ``test_render`` (pixel centres
on voxel centres, ``jitter=False``, one voxel per sample along the ray), so every
sample lies on a voxel centre and trilinear interpolation returns the voxel's value
exactly. The references then need no interpolation:

* DVR (shaders/mode_dvr.glsl): per sample, the transfer function's straight colour and
  opacity ``a`` (linear between control points, evaluated here with ``np.interp``);
  opacity corrected for the sample distance ``d`` (reference distance ``r``, one
  smallest voxel) to ``1 - (1 - a) ** (d / r)``; premultiplied; composited front to
  back ``acc += (1 - acc.a) * c``; the ray stops once ``acc.a > 0.99``.
* FLM (shaders/mode_flm.glsl): walking front to back, the first sample ``v_k`` with
  ``v_k >= threshold`` and ``v_{k+1} < v_k`` (or the last sample while still at or
  above the threshold) gives the pixel the transfer function's straight colour, opaque.

Rays travel *into* the screen: for a view with screen axes right and up, along
``-(right x up)``. The background is transparent black, so the image is the composited
colour itself.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from tests.render.test_render import VIEW_AXES, aligned_camera, render, smooth_field
from voxwarp.core.volume import Volume
from voxwarp.scene import Scene

#: GPU vs numpy, per channel, in [0, 1] units. Sources of difference: the 4096-entry
#: transfer-function table looked up at the nearest entry (at most half an entry, 255 /
#: 4095 / 2 data units, times the steepest slope below: < 1e-3) and float32 compositing.
TOL = 2e-3

#: a transfer function with different red, green and blue ramps (so a swap of channels
#: moves colours by far more than TOL) and opacities from transparent to 0.4
TF_POINTS = [
    (0.0, 0.0, 0.0, 0.0, 0.0),
    (60.0, 0.9, 0.1, 0.2, 0.0),
    (120.0, 0.8, 0.3, 0.1, 0.03),
    (180.0, 0.2, 0.9, 0.3, 0.1),
    (255.0, 0.1, 0.4, 1.0, 0.4),
]


def tf_straight(values: np.ndarray, points: list[tuple[float, ...]] = TF_POINTS) -> np.ndarray:
    """Straight RGBA (..., 4) of the piecewise-linear transfer function, clamped outside."""
    pts = np.asarray(points, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    return np.stack([np.interp(v, pts[:, 0], pts[:, c]) for c in range(1, 5)], axis=-1)


def rays(data: np.ndarray, view: str) -> np.ndarray:
    """The samples of every pixel's ray, (H, W, n) in the order the ray meets them."""
    (ra, rs), (ua, us), depth = VIEW_AXES[view]
    a = np.moveaxis(data.astype(np.float64), (ra, ua, depth), (0, 1, 2))
    a = a[::rs, ::us]  # [col, row-from-bottom, depth]
    right, up = np.zeros(3), np.zeros(3)
    right[ra], up[ua] = rs, us
    travel = -np.cross(right, up)[depth]  # the ray's direction along the depth axis
    if travel < 0:
        a = a[:, :, ::-1]
    return np.transpose(a, (1, 0, 2))[::-1]  # [row-from-top, col, depth]


def dvr_reference(samples: np.ndarray, ratio: float, points: Any = TF_POINTS) -> np.ndarray:
    """Front-to-back emission-absorption of (H, W, n) samples; premultiplied (H, W, 4)."""
    rgba = tf_straight(samples, points)
    alpha = 1.0 - (1.0 - rgba[..., 3]) ** ratio
    premul = np.concatenate([rgba[..., :3] * alpha[..., None], alpha[..., None]], axis=-1)
    acc = np.zeros((*samples.shape[:2], 4))
    running = np.ones(samples.shape[:2], bool)
    for k in range(samples.shape[2]):
        acc[running] += (1.0 - acc[running, 3:4]) * premul[running, k]
        running &= acc[..., 3] <= 0.99  # early ray termination, as the shader
    return acc


def flm_reference(samples: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """FLM of (H, W, n) samples: the (H, W) value picked per ray (nan: none) and its
    opaque straight colour (H, W, 4), transparent black where no value is picked."""
    h, w, _ = samples.shape
    picked = np.full((h, w), np.nan)
    for y in range(h):
        for x in range(w):
            prev = -np.inf
            for v in samples[y, x]:
                if prev >= threshold and v < prev:
                    break
                prev = v
            if prev >= threshold:
                picked[y, x] = prev
    color = np.zeros((h, w, 4))
    hit = ~np.isnan(picked)
    color[hit, :3] = tf_straight(picked[hit])[:, :3]
    color[hit, 3] = 1.0
    return picked, color


def dvr_scene(vol: Volume, view: str, **kw: Any) -> tuple[Scene, tuple[int, int]]:
    cam, size = aligned_camera(vol, view)
    along = VIEW_AXES[view][2]
    scene = Scene(
        vol,
        transfer_function=[list(p) for p in TF_POINTS],
        view=view,
        projection="orthographic",
        step=vol.spacing[along] / min(vol.spacing),  # one voxel along the ray
        jitter=False,
        shading=False,
        background=(0.0, 0.0, 0.0, 0.0),
        camera=cam,
        **kw,
    )
    return scene, size


# ---------------------------------------------------------------------- dvr
@pytest.mark.parametrize(
    ("view", "spacing"),
    [("+z", (1.0, 1.0, 1.0)), ("-x", (1.0, 1.0, 1.0)), ("+z", (1.0, 1.0, 2.0))],
)
def test_dvr_equals_numpy_front_to_back_compositing(
    offscreen: Any, view: str, spacing: tuple[float, float, float]
) -> None:
    """GPU DVR == the numpy reference within TOL per channel. With spacing (1, 1, 2)
    and view +z the sample distance is two reference distances: the opacity correction
    ``1 - (1 - a) ** 2`` is checked too. The reference with red and green swapped, or
    composited back to front, is far outside the tolerance (the check can tell)."""
    data = np.rint(smooth_field((24, 20, 16), seed=5) * 255.0).astype(np.uint8)
    vol = Volume(data, spacing=spacing)
    scene, size = dvr_scene(vol, view, mode="dvr")
    ratio = scene.sample_distance_mm / scene.opacity_reference_mm
    assert ratio == (2.0 if spacing[2] == 2.0 else 1.0)
    samples = rays(data, view)
    expected = dvr_reference(samples, ratio)
    img = render(offscreen, scene, size)
    assert img.shape == expected.shape
    worst = float(np.abs(img.astype(np.float64) - expected).max())
    assert worst <= TOL, f"max |GPU - numpy| = {worst:.5f} > {TOL}"
    # the image is not trivial: colours of every hue and partial opacities
    assert 0.2 < float(np.median(expected[..., 3])) < 0.99
    assert float(np.abs(expected[..., 0] - expected[..., 1]).mean()) > 0.05
    # a channel swap or the wrong order would be caught
    swapped = [(v, g, r, b, a) for v, r, g, b, a in TF_POINTS]
    assert np.abs(img - dvr_reference(samples, ratio, swapped)).max() > 20 * TOL
    assert np.abs(img - dvr_reference(samples[..., ::-1], ratio)).max() > 20 * TOL


# ---------------------------------------------------------------------- flm
def flm_volume(valley: tuple[float, float]) -> np.ndarray:
    """24x20x32 uint8: along +z (the rays of view -z meet low z first), each column is
    piecewise linear: from 20 it rises through the threshold (100) to a first peak of
    130..200 at z = 6..9, falls to a valley of ``valley`` (low, high) at z = 14..16, rises
    to a higher second peak of 230..250 at z = 20..25 and falls to 40 at the end. The
    first local maximum above the threshold, the global maximum and the first sample
    above the threshold are three different values on every ray."""
    rng = np.random.default_rng(7)
    nx, ny, nz = 24, 20, 32
    z = np.arange(nz, dtype=np.float64)
    out = np.empty((nx, ny, nz))
    for i in range(nx):
        for j in range(ny):
            knots = [0, rng.integers(6, 10), rng.integers(14, 17), rng.integers(20, 26), nz - 1]
            values = [20.0, rng.uniform(130, 200), rng.uniform(*valley), rng.uniform(230, 250)]
            out[i, j] = np.interp(z, knots, [*values, 40.0])
    return np.rint(out).astype(np.uint8)


@pytest.mark.parametrize("valley", [(110.0, 125.0), (40.0, 60.0)], ids=["above", "below"])
def test_flm_picks_the_first_local_maximum_not_the_global_one(
    offscreen: Any, valley: tuple[float, float]
) -> None:
    """GPU FLM == the numpy FLM rule within TOL; on this volume the rule's pick differs
    from the global maximum and from the first sample above the threshold on every ray,
    by more than 0.1 in some colour channel at most pixels. With the valley above the
    threshold the sample loop must stop at the first peak; with it below, the rays skip
    the valley's invisible cells and the peak pending before them is emitted."""
    threshold = 100.0
    data = flm_volume(valley)
    vol = Volume(data)
    view = "-z"
    scene, size = dvr_scene(vol, view, mode="flm", flm_threshold=threshold)
    samples = rays(data, view)
    picked, expected = flm_reference(samples, threshold)
    assert np.all(np.isfinite(picked))  # every ray finds a maximum

    img = render(offscreen, scene, size)
    worst = float(np.abs(img.astype(np.float64) - expected).max())
    assert worst <= TOL, f"max |GPU - numpy| = {worst:.5f} > {TOL}"

    # the volume tells the rules apart: global maximum and threshold crossing
    glob = samples.max(axis=2)
    first_above = np.take_along_axis(
        samples, np.argmax(samples >= threshold, axis=2)[..., None], axis=2
    )[..., 0]
    assert np.all(picked < glob - 20)
    assert np.all(picked > first_above + 10)
    for other in (glob, first_above):
        colour = tf_straight(other)[..., :3]
        far = np.abs(colour - expected[..., :3]).max(axis=-1) > 0.1
        assert far.mean() > 0.9
