"""Octant skip maps per 2³ trilinear cells (``Renderer.coarse_cell_maps``), what big
volumes keep: an eighth of the bytes of a per-cell map.

Oracles: a brute-force count of visible cells in every cube the raycaster would jump
through (the fine edge it derives from a coarse map, the same formula as
``shaders/raycast.frag.glsl`` ``cell_skip``), a brute-force pooling of the visibility,
and images with no skipping at all (identical: skipping only leaves out samples of
invisible cells, on the same sample lattice).
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pytest

from voxwarp.core.transfer_function import TransferFunction
from voxwarp.core.volume import Volume
from voxwarp.errors import RenderError
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.render.skipping.maps import coarsen_visibility, octant_skip_distances

OCTANTS = list(itertools.product((-1, 1), repeat=3))


def _random_visibility(shape: tuple[int, int, int], seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.random(shape) < 0.02


def test_coarsen_visibility_pools_with_invisible_padding() -> None:
    visible = _random_visibility((9, 6, 11), 1)
    got = coarsen_visibility(visible, 2)
    padded = np.zeros((10, 6, 12), dtype=bool)
    padded[:9, :6, :11] = visible
    want = padded.reshape(5, 2, 3, 2, 6, 2).any(axis=(1, 3, 5))
    np.testing.assert_array_equal(got, want)
    assert got.T.flags.c_contiguous  # texture order, as octant_skip_distances wants


def _fine_edge(coarse: np.ndarray, c: np.ndarray, signs: tuple[int, ...], f: int) -> int:
    """The shader's fine edge at cell ``c`` from a coarse octant map (0: sample it)."""
    cc = c // f
    d = int(coarse[tuple(cc)])
    if d == 0:
        return 0
    o = c - cc * f
    o = np.where(np.asarray(signs) < 0, f - 1 - o, o)
    return d * f - int(o.max())


@pytest.mark.parametrize("signs", OCTANTS)
def test_jumps_from_a_coarse_map_never_cross_a_visible_cell(signs: tuple[int, ...]) -> None:
    visible = _random_visibility((13, 10, 15), 5)
    coarse = octant_skip_distances(coarsen_visibility(visible, 2), signs)
    s = np.asarray(signs)
    skipped = 0
    for c in np.ndindex(visible.shape):
        c = np.asarray(c)
        edge = _fine_edge(coarse, c, signs, 2)
        if visible[tuple(c)]:
            assert edge == 0
        if edge == 0:
            continue
        skipped += 1
        ends = np.stack([c, c + s * (edge - 1)])
        lo = np.clip(ends.min(axis=0), 0, None)
        hi = np.minimum(ends.max(axis=0), np.asarray(visible.shape) - 1)
        cube = visible[lo[0] : hi[0] + 1, lo[1] : hi[1] + 1, lo[2] : hi[2] + 1]
        assert not cube.any(), (c, edge)
    assert skipped > visible.size // 2  # the map skips most of a sparse grid


def _shells(n: int = 40) -> Volume:
    x, y, z = np.meshgrid(*[np.arange(float(n))] * 3, indexing="ij")
    r = np.sqrt((x - 20) ** 2 + (y - 19) ** 2 + (z - 21) ** 2)
    data = np.where(np.abs(r - 12) < 2, 180, 0) + np.where(r < 3, 90, 0)
    return Volume(data.astype(np.uint8), (1.0, 1.1, 0.9))


TF = TransferFunction([(0, 0, 0, 0, 0), (90, 1, 0.8, 0.6, 0.3), (180, 1, 1, 1, 0.7)])


@pytest.mark.gl
@pytest.mark.parametrize("mode", ["dvr", "iso"])
def test_coarse_maps_draw_the_images_of_no_skipping(gl_ctx: Any, mode: str) -> None:
    """Views in every octant (and across octant borders): coarse maps, per-cell maps and
    no skipping give the same pixels; the coarse textures are ceil(cells / 2) per axis."""
    from voxwarp.scene import Scene

    vol = _shells()
    views = [(az, el) for az in (-135, -45, 45, 135) for el in (-35, 35)] + [(0, 0), (90, 0)]
    with OffscreenRenderer(48, 40, ctx=gl_ctx, dtype="f4") as r:
        r.renderer.cell_skip_maps = "always"
        for view in views:
            scene = Scene(vol, mode=mode, transfer_function=TF, iso_value=120, view=view)
            images = {}
            for setting in ("always", "never"):
                r.renderer.coarse_cell_maps = setting
                images[setting] = r.render(scene)
                assert r.renderer.last_skip_kind == "cells"
                maps = r.renderer._volume_gpu(vol).skip
                assert maps.cell_factor == (2 if setting == "always" else 1)
                if setting == "always":
                    assert all(t.size == (21, 21, 21) for t in maps.cell_skip.values())
            r.renderer.empty_space_skipping = False
            plain = r.render(scene)
            r.renderer.empty_space_skipping = True
            assert np.abs(plain).max() > 0.05  # something visible
            np.testing.assert_allclose(images["always"], plain, atol=1e-6, err_msg=str(view))
            np.testing.assert_allclose(images["never"], plain, atol=1e-6, err_msg=str(view))


@pytest.mark.gl
def test_auto_coarsens_only_big_volumes(gl_ctx: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    from voxwarp.render.skipping import cache as skip_cache
    from voxwarp.scene import Scene

    scene = Scene(_shells(), transfer_function=TF, view=(30, 20))
    with OffscreenRenderer(24, 24, ctx=gl_ctx) as r:
        r.renderer.cell_skip_maps = "always"
        r.render(scene)
        assert r.renderer._volume_gpu(scene.volume).skip.cell_factor == 1
        monkeypatch.setattr(skip_cache, "COARSE_MIN_CELLS", 1000)  # 41³ cells count as big
        r.render(scene)
        assert r.renderer._volume_gpu(scene.volume).skip.cell_factor == 2
        with pytest.raises(RenderError, match="coarse_cell_maps"):
            r.renderer.coarse_cell_maps = "sometimes"


@pytest.mark.gl
def test_a_big_volume_keeps_coarse_bits_and_its_warped_rays_get_fine_ones(
    gl_ctx: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Coarse maps keep the visibility per 2³ cells; warped rays (deformed-space maps,
    built from fine cells) classify the fine cells again, draw what block checks draw,
    and leave the straight rays' coarse maps as they were."""
    from benchmarks.offset_inverse import gaussian_drag_field
    from voxwarp.deform.elements.offset_field import OffsetFieldWarp
    from voxwarp.render.skipping import cache as skip_cache
    from voxwarp.scene import Scene

    monkeypatch.setattr(skip_cache, "EAGER_CELLS", 1000)  # 41³ cells count as big
    monkeypatch.setattr(skip_cache, "COARSE_MIN_CELLS", 1000)
    vol = _shells()
    lo, hi = vol.bounds
    field = gaussian_drag_field((7, 6, 5), (3, 3, 2), (4.0, -2.0, 1.0), 1.0)
    warp = OffsetFieldWarp(lo, hi, field, shape=(7, 6, 5))
    straight = Scene(vol, transfer_function=TF, view=(30, 20))
    warped = straight.copy(warps=[warp])
    with OffscreenRenderer(48, 40, ctx=gl_ctx, dtype="f4") as r:
        r.renderer.cell_skip_maps = "always"
        r.renderer.warped_skip_maps = "always"
        before = r.render(straight)
        maps = r.renderer._volume_gpu(vol).skip
        assert (maps.visible_factor, maps.cell_visible.shape) == (2, (21, 21, 21))
        textures = dict(maps.cell_skip)
        cells = r.render(warped)
        assert r.renderer.last_skip_kind == "cells"
        assert (maps.visible_factor, maps.cell_visible.shape) == (1, (41, 41, 41))
        r.renderer.cell_skipping = False
        blocks = r.render(warped)
        r.renderer.cell_skipping = True
        after = r.render(straight)
        assert maps.cell_skip == textures  # not rebuilt
    assert np.abs(cells - blocks).max() <= 1 / 255
    assert np.abs(cells - before).max() > 0.05  # the drag shows
    np.testing.assert_array_equal(after, before)
