"""Boundary conditions of the element grid (voxwarp.deform.elements.anchors): anchor
masks, the region of influence, saved grids, and the models honouring them on both
backends; tissue presets (voxwarp.deform.elements.materials).

Oracles: counting (a shell of an n^3 grid holds n^3 - (n-2)^3 elements), brute-force
distances, the old file format (a grid without the keys is the thesis's corners), CPU
against GPU (GL) results, and the ordering bone > soft tissue > air.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from voxwarp.core.volume import Volume
from voxwarp.deform import ChainMail, MassSpring
from voxwarp.deform.elements import anchors, materials
from voxwarp.deform.elements.grid import ElementGrid, ElementGridError
from voxwarp.editing.families.elements import material_preset

BOX = ((0.0, 0.0, 0.0), (80.0, 80.0, 80.0))  # 9^3 elements: 10 mm spacing
SAMPLES = Path(__file__).resolve().parents[3] / "sample_volumes"


@pytest.mark.parametrize("shape", [(2, 2, 2), (3, 3, 3), (5, 5, 5), (16, 16, 16), (3, 4, 5)])
def test_anchor_masks_count(shape: tuple[int, int, int]) -> None:
    inner = int(np.prod([max(n - 2, 0) for n in shape]))
    assert anchors.anchor_mask(shape, "shell").sum() == np.prod(shape) - inner
    assert anchors.anchor_mask(shape, "corners").sum() == 8
    assert anchors.anchor_mask(shape, "none").sum() == 0
    shell = anchors.anchor_mask(shape, "shell")
    assert not shell[tuple(slice(1, n - 1) for n in shape)].any()


def test_new_grid_fixes_the_shell_and_modes_are_checked() -> None:
    g = ElementGrid(BOX, shape=9)
    assert g.anchor == "shell"
    assert g.fix_outside == "auto"
    np.testing.assert_array_equal(g.fixed, anchors.anchor_mask(g.shape, "shell"))
    corners = ElementGrid(BOX, shape=9, anchor="corners")
    assert int(corners.fixed.sum()) == 8
    assert corners.fix_outside is None
    assert ElementGrid(BOX, shape=9, anchor="none").fixed.sum() == 0
    with pytest.raises(anchors.AnchorError, match="shell, corners, none"):
        ElementGrid(BOX, shape=9, anchor="walls")
    with pytest.raises(anchors.AnchorError, match=">= 0"):
        ElementGrid(BOX, shape=9, fix_outside=-3)
    assert ElementGrid(BOX, shape=9, fix_outside=0).fix_outside is None
    assert ElementGrid(BOX, shape=9, fix_outside="off").fix_outside is None


def test_influence_radius_rule() -> None:
    assert anchors.influence_radius((2.0, 2.0, 2.0), 1.0) == anchors.MIN_INFLUENCE_MM
    assert anchors.influence_radius((1.0, 12.0, 5.0), 1.0) == pytest.approx(48.0)
    assert anchors.influence_radius((2.0, 2.0, 2.0), 20.0) == pytest.approx(60.0)


def test_outside_mask_matches_brute_force_on_an_anisotropic_grid() -> None:
    rng = np.random.default_rng(1)
    shape, spacing = (7, 5, 6), np.array([3.0, 7.0, 4.5])
    held = rng.random(shape) < 0.05
    held[3, 2, 1] = True
    got = anchors.outside_mask(spacing, held, 12.0)
    pts = np.stack(np.indices(shape), axis=-1).reshape(-1, 3) * spacing
    hp = np.argwhere(held) * spacing
    dist = np.linalg.norm(pts[:, None] - hp[None], axis=-1).min(axis=1).reshape(shape)
    np.testing.assert_array_equal(got, dist > 12.0)
    assert not anchors.outside_mask(spacing, np.zeros(shape, bool), 12.0).any()


def test_anchor_around_excludes_fixed_held_and_freed() -> None:
    g = ElementGrid(BOX, shape=9, fix_outside=25.0)
    held = np.zeros(g.shape, bool)
    held[4, 4, 4] = True
    offsets = np.zeros((*g.shape, 3))
    a = g.anchor_around(held, offsets)
    dist = np.linalg.norm(g.rest_positions - g.rest_positions[4, 4, 4], axis=-1)
    np.testing.assert_array_equal(a, (dist > 25.0) & ~g.fixed)
    g.free((4, 4, 8))  # a shell element: freed, never anchored
    g.free((1, 1, 1))  # an anchored element: freed from the region for good
    assert not g.anchor_around(held, offsets)[1, 1, 1]
    assert g.anchor_around(held, offsets)[1, 1, 2]
    assert not g.anchor_around(np.zeros(g.shape, bool), offsets).any()


def test_auto_radius_grows_with_the_drag() -> None:
    g = ElementGrid(((0.0, 0.0, 0.0), (160.0, 160.0, 160.0)), shape=17)  # 10 mm spacing
    held = np.zeros(g.shape, bool)
    held[8, 8, 8] = True
    off = np.zeros((*g.shape, 3))
    small = int(g.anchor_around(held, off).sum())  # 40 mm: 4 spacings
    off[8, 8, 8] = (0.0, 0.0, 20.0)  # 60 mm: 3 x drag
    big = int(g.anchor_around(held, off).sum())
    assert 0 < big < small


def test_saved_grids_keep_anchors_and_old_files_load_as_corners() -> None:
    g = ElementGrid(BOX, shape=5, fix_outside=33.0)
    d = json.loads(json.dumps(g.to_dict()))
    back = ElementGrid.from_dict(d)
    assert (back.anchor, back.fix_outside) == ("shell", 33.0)
    np.testing.assert_array_equal(back.fixed, g.fixed)
    old = {k: v for k, v in d.items() if k not in ("anchor", "fix_outside", "fixed")}
    legacy = ElementGrid.from_dict(old)
    assert (legacy.anchor, legacy.fix_outside, int(legacy.fixed.sum())) == ("corners", None, 8)
    # the thesis's set-up saves as before: no new keys, the same bytes
    assert "anchor" not in legacy.to_dict()
    assert "fix_outside" not in legacy.to_dict()
    assert ElementGrid.from_dict({**d, "fix_outside": None}).to_dict()["fix_outside"] is None
    with pytest.raises(ElementGridError, match="unknown anchor"):
        ElementGrid.from_dict({**d, "anchor": "box"})


def test_bundled_model_files_load_with_the_thesis_set_up() -> None:
    for name in ("fish_massspring_jiggle_anim.json", "fish_chainmail_poke_anim.json"):
        model = json.loads((SAMPLES / name).read_text())["warps"][0]["model"]
        grid = ElementGrid.from_dict(model["grid"])
        assert (grid.anchor, grid.fix_outside) == ("corners", None), name


@pytest.mark.parametrize("cls", [MassSpring, ChainMail])
def test_drag_leaves_everything_beyond_the_region_at_rest(cls: Any) -> None:
    g = ElementGrid(BOX, shape=9, anchor="corners", fix_outside=30.0)
    model = cls(g)
    try:
        model.move((4, 4, 4), (0.0, 0.0, 6.0))
        if cls is MassSpring:
            model.step(400)
        d = np.linalg.norm(model.displacements(), axis=-1)
        assert g.anchored.sum() > 0
        assert d[g.anchored].max() == 0.0
        assert d[4, 4, 5] > 1.0  # the neighbour in the push's way moved
        # a new drag elsewhere recomputes the anchors around both held elements
        before = g.anchored.copy()
        model.move((1, 1, 1), (0.0, 2.0, 0.0))
        assert not g.anchored[1, 1, 1]
        assert before[1, 1, 1]
        assert not np.array_equal(before, g.anchored)
        model.reset()
        if cls is ChainMail:
            assert not g.anchored.any()
    finally:
        model.close()


def test_corners_without_region_moves_the_far_side_and_the_shell_does_not() -> None:
    ratio = {}
    for anchor in ("corners", "shell"):
        g = ElementGrid(BOX, shape=9, anchor=anchor)
        ms = MassSpring(g, integrator="semi-implicit")
        ms.move((4, 4, 7), (0.0, 0.0, -10.0))
        ms.settle(max_steps=4000)
        d = np.linalg.norm(ms.displacements(), axis=-1)
        ratio[anchor] = float(d[:, :, 1].mean() / d[:, :, 6].mean())  # far / near layer
        ms.close()
    assert ratio["corners"] > 0.2  # the whole grid slid with the drag
    assert ratio["shell"] < 0.2


# ---------------------------------------------------------------------- CPU == GPU
@pytest.mark.gl
def test_massspring_gpu_pins_anchored_elements_like_the_cpu(gl_ctx: Any) -> None:
    models = [
        MassSpring(ElementGrid(BOX, shape=9, fix_outside=25.0), backend=b, ctx=c)
        for b, c in (("cpu", None), ("gpu", gl_ctx))
    ]
    try:
        for ms in models:
            ms.move((4, 4, 4), (3.0, 0.0, 5.0))
            ms.step(80)
            ms.move((3, 5, 4), (0.0, 2.0, 0.0))
            ms.step(80)
        cpu, gpu = models
        np.testing.assert_array_equal(cpu.grid.anchored, gpu.grid.anchored)
        assert cpu.grid.anchored.any()
        d_cpu, d_gpu = cpu.displacements(), gpu.displacements()
        assert np.abs(d_gpu[gpu.grid.anchored]).max() == 0.0
        scale = float(np.abs(d_cpu).max())
        assert float(np.abs(d_gpu - d_cpu).max()) <= 1e-4 * scale
    finally:
        for ms in models:
            ms.close()


@pytest.mark.gl
def test_chainmail_gpu_pins_anchored_elements_like_the_cpu(gl_ctx: Any) -> None:
    models = [
        ChainMail(ElementGrid(BOX, shape=9, anchor="none", fix_outside=25.0), backend=b, ctx=c)
        for b, c in (("cpu", None), ("gpu", gl_ctx))
    ]
    try:
        stats = [cm.move((4, 4, 4), (0.0, 0.0, 12.0)) for cm in models]
        assert stats[0].limited
        assert stats[1].limited
        assert stats[1].fraction == pytest.approx(stats[0].fraction, abs=2.0**-12)
        cpu, gpu = models
        np.testing.assert_array_equal(cpu.grid.anchored, gpu.grid.anchored)
        x = gpu.positions()
        rest = gpu.grid.rest_positions
        np.testing.assert_allclose(x[gpu.grid.anchored], rest[gpu.grid.anchored], atol=1e-5)
        np.testing.assert_allclose(x, cpu.positions(), atol=1e-3)
    finally:
        for cm in models:
            cm.close()


# ---------------------------------------------------------------------- materials
def _ct() -> Volume:
    data = np.full((40, 8, 8), -1000.0, np.float32)  # air
    data[10:20] = -100.0  # fat
    data[20:30] = 40.0  # soft tissue
    data[30:] = 1000.0  # bone
    return Volume(data, spacing=(1.0, 1.0, 1.0), name="ct")


def test_ct_preset_orders_bone_soft_air() -> None:
    vol = _ct()
    g = ElementGrid(vol, shape=(40, 2, 2))
    s = g.materials_from_preset(vol, "ct")[:, 0, 0]
    air, fat, soft, bone = s[5], s[15], s[25], s[35]
    assert bone > soft >= fat > air
    assert air == pytest.approx(materials.FREE)
    assert bone < 1.0


def test_mr_preset_frees_the_background_from_the_histogram() -> None:
    rng = np.random.default_rng(0)
    for scale in (1.0, 3000.0):  # no absolute units: the same split at any scale
        data = rng.normal(5.0, 2.0, (30, 10, 10)).clip(0)  # background noise
        data[10:] = rng.normal(100.0, 10.0, (20, 10, 10))  # tissue
        vol = Volume((scale * data).astype(np.float32), spacing=(1.0, 1.0, 1.0), name="mr")
        g = ElementGrid(vol, shape=(30, 2, 2))
        s = g.materials_from_preset(vol, "mr")[:, 0, 0]
        assert s[:8].max() == pytest.approx(materials.FREE)
        assert s[12:].min() >= materials.SOFT - 1e-6


def test_auto_preset_follows_the_modality_and_bad_names_fail() -> None:
    assert material_preset("auto", _ct()) == "ct"
    mr = Volume(np.linspace(0, 500, 4000, dtype=np.float32).reshape(20, 20, 10), name="mr")
    assert material_preset("auto", mr) == "mr"
    with pytest.raises(materials.MaterialPresetError, match="ct, mr"):
        materials.preset_stiffness(np.zeros(3), "bone")
