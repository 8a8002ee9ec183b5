"""Tests of SAMPLES_PER_CHECK: straight rays with cell maps that check the skip map once
per several lattice samples (shaders/raycast.frag.glsl; unshaded dvr takes 2).

Oracles: the program with one check per sample (the schedule before) must draw the same
image bit for bit, since a sample in an invisible cell adds exactly nothing; scenes
where the unchecked samples would show if they were wrong: a clip box through visible
content (a sample past the ray's last one would add what lies beyond it), an opaque
transfer function (early termination must stop at the same sample) and jittered rays
(every residue of the sample count per ray); and renders without skipping, which
must agree to 1/255 (skipping only leaves out samples that cannot contribute).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from benchmarks.skip_checks import _state, _with_defines
from voxwarp import shaders
from voxwarp.core.camera import Camera
from voxwarp.core.transfer_function import TransferFunction
from voxwarp.core.volume import Volume
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.scene import Scene


def _volume() -> Volume:
    rng = np.random.default_rng(11)
    data = np.zeros((28, 22, 18), np.float32)
    g = np.indices(data.shape).transpose(1, 2, 3, 0)
    for _ in range(14):  # blobs with empty space between them in every direction
        c = rng.uniform((2, 2, 2), (26, 20, 16))
        data += 120.0 * np.exp(-np.sum((g - c) ** 2, axis=-1) / rng.uniform(1.5, 3.5) ** 2)
    return Volume(np.clip(data, 0, 255).astype(np.uint8), spacing=(1.0, 0.8, 1.3))


SOFT = TransferFunction([(0, 0, 0, 0, 0), (30, 1, 0.5, 0.2, 0), (80, 1, 1, 0.8, 0.5)])
OPAQUE = TransferFunction([(0, 0, 0, 0, 0), (20, 1, 0.5, 0.2, 0), (40, 0.3, 1, 0.8, 1)])


@pytest.fixture
def per_check(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """Lets a test force SAMPLES_PER_CHECK through ``_state`` (as the lab study does)."""
    monkeypatch.setattr(shaders, "with_defines", _with_defines(shaders.with_defines))
    yield
    _state["per_check"] = None


def _render(ctx: Any, scene: Scene, n: int | None, skipping: bool = True) -> np.ndarray:
    _state["per_check"] = n
    try:
        with OffscreenRenderer(56, 48, ctx=ctx, dtype="f4") as r:
            r.renderer.empty_space_skipping = skipping
            r.render(scene)  # small volumes get cell maps on the first draw; to be sure
            image = np.asarray(r.render(scene))
            assert r.renderer.last_skip_kind == ("cells" if skipping else "none")
            return image
    finally:
        _state["per_check"] = None


def _scene(tf: TransferFunction, view: Any, clip: bool, mode: str = "dvr") -> Scene:
    vol = _volume()
    lo, hi = vol.bounds
    cam = Camera.fit(lo, hi, view=view, projection="perspective", fov=40.0, zoom=1.3)
    box = (lo + 0.31 * (hi - lo), hi - 0.27 * (hi - lo)) if clip else None
    return Scene(
        vol, mode=mode, transfer_function=tf, camera=cam, clip_box=box, iso_value=60.0,
        flm_threshold=60.0, shading=False, seed=5,
    )  # fmt: skip


def test_unshaded_dvr_programs_check_every_second_sample() -> None:
    # the shipped choice, so that the tests below compare 2 against 1 (not 1 against 1)
    dvr = shaders.read("mode_dvr.glsl")
    assert "#define SAMPLES_PER_CHECK 2" in dvr
    assert "SAMPLES_PER_CHECK" not in shaders.read("mode_iso.glsl")


@pytest.mark.parametrize("tf", [SOFT, OPAQUE], ids=["translucent", "opaque"])
@pytest.mark.parametrize("view", [(30.0, 20.0), (-130.0, -35.0), "+x"])
@pytest.mark.parametrize("clip", [False, True], ids=["whole", "clipped"])
def test_fewer_checks_draw_the_same_image(
    gl_ctx: Any, per_check: None, tf: TransferFunction, view: Any, clip: bool
) -> None:
    scene = _scene(tf, view, clip)
    one = _render(gl_ctx, scene, 1)
    assert np.abs(one[..., 3]).max() > 0.2  # something visible
    for n in (None, 3, 4):  # the shipped 2, and the other schedules the study times
        assert np.array_equal(_render(gl_ctx, scene, n), one), f"{n} samples per check"


@pytest.mark.parametrize("mode", ["iso", "flm"])
def test_fewer_checks_keep_the_threshold_modes_exact(
    gl_ctx: Any, per_check: None, mode: str
) -> None:
    # an unchecked sample in an invisible cell changes these modes' state (previous
    # value, bisection start); what they draw must not change
    scene = _scene(SOFT, (30.0, 20.0), True, mode)
    one = _render(gl_ctx, scene, 1)
    assert np.array_equal(_render(gl_ctx, scene, 2), one)
    assert np.array_equal(_render(gl_ctx, scene, 3), one)


def test_fewer_checks_match_no_skipping(gl_ctx: Any, per_check: None) -> None:
    scene = _scene(SOFT, (-130.0, -35.0), True)
    plain = _render(gl_ctx, scene, None, skipping=False)
    assert np.abs(_render(gl_ctx, scene, None) - plain).max() <= 1 / 255
