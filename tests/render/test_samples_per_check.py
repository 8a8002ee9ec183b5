"""Tests of ``Renderer.samples_per_check``: straight rays with cell maps that check the
skip map once per several lattice samples (voxwarp.render.skipping.checks).

Oracles: the program with one check per sample (the schedule before) must draw the same
image bit for bit, since a sample in an invisible cell adds exactly nothing; scenes
where the unchecked samples would show if they were wrong: a clip box through visible
content (a sample past the ray's last one would add what lies beyond it), an opaque
transfer function (early termination must stop at the same sample) and jittered rays
(every residue of the sample count per ray); and renders without skipping, which
must agree to 1/255 (skipping only leaves out samples that cannot contribute). Warped
rays on the support's map path take the same schedule in their straight phases (a local
drag: straight before and after the moved region, through the chain inside it), and
samples through the chain take up to two per check (the warped loop, a chained phase).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from voxwarp import shaders
from voxwarp.core.camera import Camera
from voxwarp.core.transfer_function import TransferFunction
from voxwarp.core.volume import Volume
from voxwarp.deform.elements.offset_field import OffsetFieldWarp
from voxwarp.errors import RenderError
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.render.skipping.checks import (
    CHAINED_DENSE_VISIBLE,
    DENSE_VISIBLE,
    SPARSE_VISIBLE,
    chained_samples_per_check,
    samples_per_check,
)
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
def defines(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The defines of every program built while the test runs (a spy)."""
    seen: list[str] = []
    original = shaders.with_defines

    def spy(text: str, lines: list[str]) -> str:
        seen.extend(lines)
        return original(text, lines)

    monkeypatch.setattr(shaders, "with_defines", spy)
    return seen


def _render(
    ctx: Any, scene: Scene, n: int | str, skipping: bool = True, coarse: str = "auto"
) -> np.ndarray:
    with OffscreenRenderer(56, 48, ctx=ctx, dtype="f4") as r:
        r.renderer.empty_space_skipping = skipping
        r.renderer.coarse_cell_maps = coarse
        r.renderer.samples_per_check = n
        r.render(scene)  # small volumes get cell maps on the first draw; to be sure
        image = np.asarray(r.render(scene))
        assert r.renderer.last_skip_kind == ("cells" if skipping else "none")
        return image


def _drawn_with(defines: list[str], n: int) -> bool:
    return f"#define SAMPLES_PER_CHECK {n}" in defines


def _scene(tf: TransferFunction, view: Any, clip: bool, mode: str = "dvr") -> Scene:
    vol = _volume()
    lo, hi = vol.bounds
    cam = Camera.fit(lo, hi, view=view, projection="perspective", fov=40.0, zoom=1.3)
    box = (lo + 0.31 * (hi - lo), hi - 0.27 * (hi - lo)) if clip else None
    return Scene(
        vol, mode=mode, transfer_function=tf, camera=cam, clip_box=box, iso_value=60.0,
        flm_threshold=60.0, shading=False, seed=5,
    )  # fmt: skip


def test_auto_checks_every_second_sample_of_unshaded_dvr_on_a_cpu_rasteriser() -> None:
    vol = _volume()
    dvr, shaded = Scene(vol, shading=False), Scene(vol, shading=True)
    assert samples_per_check("auto", dvr, software=True) == 2  # visibility not known yet
    assert samples_per_check("auto", dvr, software=True, visible=0.1) == 2
    assert samples_per_check("auto", dvr, software=False) == 1  # a GPU skips the branch
    assert samples_per_check("auto", shaded, software=True) == 1
    assert samples_per_check("auto", Scene(vol, mode="iso"), software=True) == 1
    assert samples_per_check(3, shaded, software=False) == 3


@pytest.mark.parametrize("bad", [0, 5, 2.0, "two", True])
def test_bad_settings_are_refused_with_the_allowed_values(gl_ctx: Any, bad: Any) -> None:
    with OffscreenRenderer(8, 8, ctx=gl_ctx) as r:
        with pytest.raises(RenderError, match="samples_per_check must be"):
            r.renderer.samples_per_check = bad


@pytest.mark.parametrize("tf", [SOFT, OPAQUE], ids=["translucent", "opaque"])
@pytest.mark.parametrize("view", [(30.0, 20.0), (-130.0, -35.0), "+x"])
@pytest.mark.parametrize("clip", [False, True], ids=["whole", "clipped"])
def test_fewer_checks_draw_the_same_image(
    gl_ctx: Any, defines: list[str], tf: TransferFunction, view: Any, clip: bool
) -> None:
    scene = _scene(tf, view, clip)
    one = _render(gl_ctx, scene, 1)
    assert np.abs(one[..., 3]).max() > 0.2  # something visible
    assert not any("SAMPLES_PER_CHECK" in d for d in defines)
    for n in (2, 3, 4):  # the choice on llvmpipe, and the other schedules the study times
        assert np.array_equal(_render(gl_ctx, scene, n), one), f"{n} samples per check"
        assert _drawn_with(defines, n)


@pytest.mark.parametrize("mode", ["iso", "flm"])
def test_fewer_checks_keep_the_threshold_modes_exact(
    gl_ctx: Any, defines: list[str], mode: str
) -> None:
    # an unchecked sample in an invisible cell changes these modes' state (previous
    # value, bisection start); what they draw must not change
    scene = _scene(SOFT, (30.0, 20.0), True, mode)
    one = _render(gl_ctx, scene, 1)
    assert np.array_equal(_render(gl_ctx, scene, 2), one)
    assert np.array_equal(_render(gl_ctx, scene, 3), one)
    assert _drawn_with(defines, 2)
    assert _drawn_with(defines, 3)


def test_fewer_checks_match_no_skipping(gl_ctx: Any, defines: list[str]) -> None:
    scene = _scene(SOFT, (-130.0, -35.0), True)
    plain = _render(gl_ctx, scene, "auto", skipping=False)
    assert not any("SAMPLES_PER_CHECK" in d for d in defines)  # no cell maps: no checks
    assert np.abs(_render(gl_ctx, scene, 2) - plain).max() <= 1 / 255
    assert _drawn_with(defines, 2)


def test_fewer_checks_on_coarse_maps_draw_the_same_image(gl_ctx: Any, defines: list[str]) -> None:
    # big volumes' maps of 2³ cells (COARSE_CELLS): another cell_skip, the same loop
    scene = _scene(SOFT, (30.0, 20.0), True)
    one = _render(gl_ctx, scene, 1, coarse="always")
    assert np.array_equal(_render(gl_ctx, scene, 2, coarse="always"), one)
    assert any(d.startswith("#define COARSE_CELLS") for d in defines)
    assert _drawn_with(defines, 2)


def test_auto_follows_the_share_of_visible_cells() -> None:
    """Sparse views check every sample, dense ones every fourth (unshaded dvr, CPU
    rasteriser); the shares are the module's thresholds, on either side."""
    dvr = Scene(_volume(), shading=False)
    assert samples_per_check("auto", dvr, True, visible=0.0) == 1
    assert samples_per_check("auto", dvr, True, visible=SPARSE_VISIBLE - 1e-9) == 1
    assert samples_per_check("auto", dvr, True, visible=SPARSE_VISIBLE) == 2
    assert samples_per_check("auto", dvr, True, visible=DENSE_VISIBLE - 1e-9) == 2
    assert samples_per_check("auto", dvr, True, visible=DENSE_VISIBLE) == 4
    assert samples_per_check("auto", dvr, True, visible=1.0) == 4
    assert samples_per_check("auto", dvr, False, visible=1.0) == 1  # a GPU: every sample
    shaded = Scene(_volume(), shading=True)  # dearer samples: 2 on dense views only
    assert samples_per_check("auto", shaded, True, visible=DENSE_VISIBLE) == 2
    assert samples_per_check("auto", shaded, True, visible=DENSE_VISIBLE - 1e-9) == 1
    assert samples_per_check("auto", shaded, True, visible=None) == 1
    assert samples_per_check("auto", shaded, False, visible=1.0) == 1
    assert samples_per_check("auto", Scene(_volume(), mode="iso"), True, visible=1.0) == 1


@pytest.mark.parametrize(("opaque", "expected"), [(True, 4), (False, 1)])
def test_a_draw_takes_the_share_of_its_transfer_function(
    gl_ctx: Any, opaque: bool, expected: int
) -> None:
    """The raycaster reads the share from the volume's kept cell visibility: a transfer
    function that shows everything gives dense checks, one that shows a sliver sparse
    ones, and both draw what one check per sample draws."""
    vol = _volume()
    lo, hi = vol.value_range
    if opaque:
        tf = [(lo - 1.0, 0.5, 0.5, 0.5, 0.2), (hi + 1.0, 1.0, 1.0, 1.0, 0.4)]
    else:  # only the brightest values show
        top = hi - 0.02 * (hi - lo)
        tf = [(lo, 0.0, 0.0, 0.0, 0.0), (top, 1.0, 1.0, 1.0, 0.0), (hi, 1.0, 1.0, 1.0, 0.9)]
    scene = Scene(vol, transfer_function=tf, shading=False, seed=5)
    with OffscreenRenderer(48, 40, ctx=gl_ctx) as r:
        for _ in range(2):  # the cell visibility is kept by the first draw
            image = np.asarray(r.render(scene))
        if not r.renderer._software:
            pytest.skip("a GPU keeps one check per sample")
        assert r.renderer.last_skip_kind == "cells"
        assert r.renderer.last_samples_per_check == expected
        r.renderer.samples_per_check = 1
        assert np.array_equal(np.asarray(r.render(scene)), image)


def _local_drag(vol: Volume) -> OffsetFieldWarp:
    """A 7³ offset field over the volume's box with one inner node dragged 3 mm: a
    support of a few bricks, crossed by some rays and missed by others."""
    lo, hi = vol.bounds
    u = np.zeros((7, 7, 7, 3))
    u[3, 2, 3] = (3.0, -1.0, 0.5)
    return OffsetFieldWarp(lo, hi, u, inverse="baked")


@pytest.mark.parametrize("tf", [SOFT, OPAQUE], ids=["translucent", "opaque"])
@pytest.mark.parametrize("view", [(30.0, 20.0), (-130.0, -35.0)])
def test_fewer_checks_in_the_straight_phases_of_warped_rays(
    gl_ctx: Any, defines: list[str], tf: TransferFunction, view: Any
) -> None:
    """A local drag on the map path draws the same image with 2-4 samples per check in
    its straight phases as with one, and differs from the undeformed image (the chained
    phase is drawn)."""
    plain = _scene(tf, view, False)
    scene = plain.copy(warps=[_local_drag(plain.volume)])
    with OffscreenRenderer(56, 48, ctx=gl_ctx, dtype="f4") as r:
        r.renderer.support_maps = "always"
        r.renderer.samples_per_check = 1
        for _ in range(2):  # the deformed-space maps and the support come with the draws
            one = np.asarray(r.render(scene))
        assert r.renderer.last_support == "map"
        assert r.renderer.last_skip_kind == "cells"
        assert not any("SAMPLES_PER_CHECK" in d for d in defines)
        assert np.abs(one - np.asarray(r.render(plain))).max() > 0.02  # the drag shows
        for n in (2, 3, 4):
            r.renderer.samples_per_check = n
            assert np.array_equal(np.asarray(r.render(scene)), one), f"{n} samples per check"
            assert r.renderer.last_support == "map"
            assert r.renderer.last_samples_per_check == n


def test_chained_samples_take_two_per_check_only_on_dense_views() -> None:
    dvr = Scene(_volume(), shading=False)
    shaded = Scene(_volume(), shading=True)
    assert chained_samples_per_check("auto", dvr, True, CHAINED_DENSE_VISIBLE) == 2
    assert chained_samples_per_check("auto", dvr, True, CHAINED_DENSE_VISIBLE - 1e-9) == 1
    assert chained_samples_per_check("auto", dvr, True, None) == 1  # not known yet
    assert chained_samples_per_check("auto", dvr, False, 1.0) == 1  # a GPU
    assert chained_samples_per_check("auto", shaded, True, DENSE_VISIBLE) == 2
    assert chained_samples_per_check("auto", shaded, True, DENSE_VISIBLE - 1e-9) == 1
    assert chained_samples_per_check("auto", Scene(_volume(), mode="mip"), True, 1.0) == 1
    assert chained_samples_per_check(4, shaded, False, 0.0) == 2  # a number: at most 2
    assert chained_samples_per_check(1, dvr, True, 1.0) == 1


@pytest.mark.parametrize("tf", [SOFT, OPAQUE], ids=["translucent", "opaque"])
@pytest.mark.parametrize(("path", "clip"), [("all", False), ("all", True), ("map", False)])
def test_two_chained_samples_per_check_draw_the_same_image(
    gl_ctx: Any, defines: list[str], tf: TransferFunction, path: str, clip: bool
) -> None:
    """Warped rays with the chain at every sample ("all", also with a clip box through
    visible content: a sample past the ray's last would add what lies beyond it) and a
    local drag's chained phase ("map") draw the same image with two samples through the
    chain per check as with one."""
    plain = _scene(tf, (30.0, 20.0), clip)
    scene = plain.copy(warps=[_local_drag(plain.volume)])
    with OffscreenRenderer(56, 48, ctx=gl_ctx, dtype="f4") as r:
        r.renderer.support_maps = "always"
        r.renderer.support_skipping = path == "map"
        r.renderer.samples_per_check = 1
        for _ in range(2):
            one = np.asarray(r.render(scene))
        assert r.renderer.last_support == path
        assert r.renderer.last_chained_per_check == 1
        assert np.abs(one - np.asarray(r.render(plain))).max() > 0.02  # the drag shows
        r.renderer.samples_per_check = 2
        assert np.array_equal(np.asarray(r.render(scene)), one)
        assert r.renderer.last_support == path
        assert r.renderer.last_chained_per_check == 2
        assert "#define CHAINED_PER_CHECK 2" in defines


@pytest.mark.parametrize("warped", [False, True], ids=["straight", "warped"])
def test_fewer_checks_with_shading_draw_the_same_image(gl_ctx: Any, warped: bool) -> None:
    """Shaded dvr (dense views take two samples per check) draws what one check per
    sample draws, straight rays and rays through the chain alike: an unchecked sample in
    an invisible cell is neither coloured nor shaded."""
    scene = _scene(OPAQUE, (30.0, 20.0), False).copy(shading=True)
    if warped:
        scene = scene.copy(warps=[_local_drag(scene.volume)])
    with OffscreenRenderer(56, 48, ctx=gl_ctx, dtype="f4") as r:
        r.renderer.support_skipping = False  # warped: the chain at every sample
        r.renderer.samples_per_check = 1
        for _ in range(2):
            one = np.asarray(r.render(scene))
        r.renderer.samples_per_check = 2
        assert np.array_equal(np.asarray(r.render(scene)), one)
        if warped:
            assert r.renderer.last_chained_per_check == 2
        else:
            assert r.renderer.last_samples_per_check == 2
