"""Precomputed gradient textures for shading (voxwarp.render.gradients).

Oracles: numpy's edge-replicated central differences (the texture read back), and the
six-fetch shading path's image (the same gradients, filtered before the difference).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from voxwarp.core.transfer_function import TransferFunction
from voxwarp.core.volume import Volume
from voxwarp.render import gradients
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.render.raycaster import Renderer
from voxwarp.scene import Scene


def central_differences(data: np.ndarray) -> np.ndarray:
    """Half the central difference per axis, edges replicated (x, y, z, 3)."""
    p = np.pad(data.astype(np.float64), 1, mode="edge")
    c = (slice(1, -1),) * 3
    out = []
    for axis in range(3):
        hi = list(c)
        lo = list(c)
        hi[axis], lo[axis] = slice(2, None), slice(None, -2)
        out.append((p[tuple(hi)] - p[tuple(lo)]) / 2)
    return np.stack(out, -1)


@pytest.mark.parametrize("sampling", ["slice_pairs", "slice_layers", "texture3d"])
@pytest.mark.parametrize(
    ("dtype", "top"), [(np.uint8, 255), (np.int16, 3000), (np.uint16, 60000), (np.float32, 1.0)]
)
def test_texture_holds_central_differences(
    gl_ctx: Any, sampling: str, dtype: Any, top: float
) -> None:
    rng = np.random.default_rng(1)
    raw = rng.random((13, 11, 7)) * top
    data = (raw - (1000 if dtype == np.int16 else 0)).astype(dtype)
    vol = Volume(data)
    r = Renderer(gl_ctx, sampling=sampling)
    try:
        tex = r._volume_gpu(vol).gradient_texture(gl_ctx, vol)
        g = np.frombuffer(tex.read(), np.float16).reshape(7, 11, 13, 4)
        g = g.transpose(2, 1, 0, 3)[..., :3].astype(np.float64)
    finally:
        r.release()
    ref = central_differences(data)
    # half floats keep 11 significant bits; unorm16 texels are exact to 1 / 65535
    np.testing.assert_allclose(g, ref, rtol=2**-10, atol=np.abs(ref).max() * 2**-11 + 1e-6)


def smooth_ball() -> Volume:
    x, y, z = np.meshgrid(*[np.arange(40.0)] * 3, indexing="ij")
    r = np.sqrt((x - 20) ** 2 + (y - 18) ** 2 + (z - 21) ** 2)
    return Volume((200 / (1 + np.exp((r - 12) / 1.5))).astype(np.uint8))


TF = TransferFunction([(0, 0, 0, 0, 0), (80, 0.9, 0.7, 0.5, 0.0), (120, 1, 0.9, 0.8, 0.8)])


def test_shaded_image_matches_the_six_fetch_path(offscreen: Any) -> None:
    """Same gradients, filtered after instead of before the difference: the images
    agree within a few levels (both paths differ as much between texture layouts)."""
    r = offscreen(96, 96)
    scene = Scene(smooth_ball(), transfer_function=TF, view=(-40, 30), shading=True, jitter=False)
    images = {}
    try:
        for setting in (False, True):
            r.renderer.gradient_texture = setting
            images[setting] = r.render(scene)[..., :3].astype(float)
            assert r.renderer.last_gradient_texture is setting
    finally:
        r.renderer.gradient_texture = "auto"
    assert images[True].max() > 150
    d = np.abs(images[True] - images[False])
    assert d.mean() < 0.5
    assert d.max() <= 12


def test_auto_uses_the_texture_only_for_shading_and_small_volumes(
    offscreen: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    r = offscreen(32, 32)
    vol = smooth_ball()
    r.render(Scene(vol, transfer_function=TF, shading=False))
    assert r.renderer.last_gradient_texture is False
    r.render(Scene(vol, transfer_function=TF, shading=True))
    assert r.renderer.last_gradient_texture is True
    monkeypatch.setattr(gradients, "MAX_VOXELS", vol.data.size - 1)
    r.render(Scene(vol, transfer_function=TF, shading=True))
    assert r.renderer.last_gradient_texture is False


def test_released_with_its_volume(gl_ctx: Any) -> None:
    vol = smooth_ball()
    with OffscreenRenderer(16, 16, ctx=gl_ctx) as r:
        r.render(Scene(vol, transfer_function=TF, shading=True))
        gpu = r.renderer._volume_gpu(vol)
        assert gpu.gradient is not None
    assert gpu.gradient is None


def test_bad_setting_names_the_choices(offscreen: Any) -> None:
    from voxwarp.errors import RenderError

    r = offscreen(8, 8)
    with pytest.raises(RenderError, match="gradient_texture must be 'auto', True or False"):
        r.renderer.gradient_texture = "yes"
    assert r.renderer.gradient_texture == "auto"
