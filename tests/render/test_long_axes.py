"""Volumes with a long axis (more than 256 skip blocks, up to the GL 3D texture limit).

A 512 x 512 x 1100 CT used to fail with an OverflowError in the skip-map code: block
distances were counted in uint8 past 255. Oracles: a brute-force search for the largest
invisible cube ahead of each cell (skip distances may be capped, never larger than the
truth), renders with skipping off (skipping jumps only over samples that cannot
contribute, on the same sample lattice, so the images must agree), and the numpy MIP
along the long axis (the three bright spots, at both ends and in the middle, each show
with its own value). Above the limit: a one-line error naming the axis and the fix.
"""

from __future__ import annotations

import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from voxwarp.core.transfer_function import TransferFunction
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import AffineWarp
from voxwarp.errors import VolumeTooLargeError
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.render.raycaster import Renderer
from voxwarp.render.skipping.maps import (
    BLOCK,
    CELL_CAP,
    block_skip_distances,
    octant_skip_distances,
)
from voxwarp.scene import Scene

#: values of the spots at the start, the middle and the end of the long axis
SPOT_VALUES = (100, 160, 220)
TF = TransferFunction(
    [(0, 0, 0, 0, 0), (60, 1, 1, 1, 0), (90, 1, 0.5, 0.2, 0.8), (255, 1, 1, 1, 1)]
)
SIZE = 32


def exact_octant(visible: np.ndarray, signs: tuple[int, int, int]) -> np.ndarray:
    """Uncapped edge of the largest invisible cube starting at each cell towards ``signs``
    (a large number where no visible cell lies ahead)."""
    pts = np.argwhere(visible)
    s = np.asarray(signs)
    cells = np.argwhere(np.ones(visible.shape, bool))
    best = np.full(len(cells), 10**6, dtype=np.int64)
    for p in pts:  # few visible cells: loop over them, vectorise over the cells
        delta = (p[None, :] - cells) * s
        ahead = (delta >= 0).all(axis=1)
        best[ahead] = np.minimum(best[ahead], delta[ahead].max(axis=1))
    return best.reshape(visible.shape)


@pytest.mark.parametrize("shape", [(2, 3, 1100), (1100, 2, 3)], ids=["long-z", "long-x"])
@pytest.mark.parametrize("signs", [(1, 1, 1), (-1, -1, -1), (1, -1, 1)])
def test_octant_distances_over_256_blocks_never_exceed_the_truth(
    shape: tuple[int, int, int], signs: tuple[int, int, int]
) -> None:
    long_axis = int(np.argmax(shape))
    n = shape[long_axis]
    visible = np.zeros(shape, bool)
    for k, (i, j) in zip((0, n // 2, n - 1), ((0, 0), (1, 2), (1, 0)), strict=True):
        idx = [i, j]
        idx.insert(long_axis, k)
        visible[tuple(idx)] = True
    d = octant_skip_distances(visible, signs)  # raised OverflowError before (275 blocks)
    assert d.dtype == np.uint8
    assert d.shape == visible.shape
    exact = exact_octant(visible, signs)
    assert (d.astype(np.int64) <= exact).all(), "a jump would leave the invisible cube"
    assert (d[visible] == 0).all()
    assert (d >= np.minimum(exact, CELL_CAP)).all(), "exact up to the cell cap"
    # far from every visible cell (ahead or not, so the cell's own blocks are clear):
    # the block-level bound reaches the uint8 cap (capped, not lost)
    far = np.ones(shape, bool)
    for p in np.argwhere(visible):
        grid = np.indices(shape).reshape(3, -1).T
        far &= (np.abs(grid - p).max(axis=1) >= 255 + 2 * BLOCK).reshape(shape)
    assert far.sum() > 200
    assert (d[far] == 255).all()


@pytest.mark.parametrize("shape", [(1, 1, 600), (600, 2, 1)])
def test_block_distances_over_256_blocks_are_capped_chessboard(shape: tuple[int, ...]) -> None:
    visible = np.zeros(shape, bool)
    visible[0, 0, 0] = True
    d = block_skip_distances(visible)
    assert d.dtype == np.uint8
    along = np.arange(600)
    line = d.reshape(-1) if shape[1] == 1 else d[:, 0, 0]
    np.testing.assert_array_equal(line, np.minimum(along, 255))


def long_volume(shape: tuple[int, int, int]) -> Volume:
    """Zeros with three bright boxes (8 voxels along the long axis, 3 or 4 across) at
    the start, the middle and the end of the long axis, at different places across."""
    data = np.zeros(shape, np.uint8)
    long_axis = int(np.argmax(shape))
    n = shape[long_axis]
    short = [s for i, s in enumerate(shape) if i != long_axis]
    w = max(3, short[0] // 4)
    corners = ((1, 1), (1 + w + 1, 1), (1, 1 + w + 1))
    for start, (a, b), value in zip((0, n // 2 - 4, n - 8), corners, SPOT_VALUES, strict=True):
        sl = [slice(a, a + w), slice(b, b + w)]
        sl.insert(long_axis, slice(start, start + 8))
        data[tuple(sl)] = value
    return Volume(data)


def _zero_field_warp(vol: Volume) -> Any:
    from voxwarp.deform.elements.offset_field import OffsetFieldWarp

    return OffsetFieldWarp(*vol.bounds, np.zeros((3, 3, 3, 3)))


@pytest.fixture(scope="module")
def renderers(gl_ctx: Any) -> Iterator[dict[bool, OffscreenRenderer]]:
    """Two renderers (programs compiled once): skipping on (warped rays build their
    deformed-space maps on first use) and off."""
    made = {}
    for skipping in (True, False):
        r = OffscreenRenderer(SIZE, SIZE, ctx=gl_ctx, dtype="f4")
        r.renderer.empty_space_skipping = skipping
        r.renderer.warped_skip_maps = "always"
        made[skipping] = r
    yield made
    for r in made.values():
        r.release()


@pytest.mark.parametrize(
    ("shape", "view"),
    [((16, 16, 2048), "+z"), ((2048, 8, 8), "-x"), ((8, 8, 1100), "-z")],
    ids=["16x16x2048", "2048x8x8", "8x8x1100"],
)
@pytest.mark.parametrize("mode", ["dvr", "mip"])
def test_long_axis_renders_match_no_skipping_and_the_numpy_mip(
    gl_ctx: Any,
    renderers: dict[bool, OffscreenRenderer],
    shape: tuple[int, int, int],
    view: str,
    mode: str,
) -> None:
    vol = long_volume(shape)
    fits_cells = max(shape) + 1 <= int(gl_ctx.info["GL_MAX_3D_TEXTURE_SIZE"])
    scene = Scene(
        vol,
        mode=mode,
        transfer_function=TF,
        view=view,
        projection="orthographic",
        window=(127.5, 255.0),
        seed=3,
    )
    # straight rays along the long axis; tilted (affine: still straight) so that rays
    # cross the short axes too; warped (a zero offset field: the same picture, but the
    # warped path's block or deformed-space cell skipping)
    tilt_axis = (1.0, 0.0, 0.0) if shape[0] < shape[2] else (0.0, 0.0, 1.0)
    variants = {
        "straight": scene,
        "tilted": scene.copy(warps=[AffineWarp.rotation(tilt_axis, 0.2, center=vol.center)]),
        "warped": scene.copy(warps=[_zero_field_warp(vol)]),
    }
    images = {}
    for name, sc in variants.items():
        on = renderers[True].render(sc)
        kind = renderers[True].renderer.last_skip_kind
        off = renderers[False].render(sc)
        assert np.abs(on - off).max() <= 1 / 255, f"{name}: skipping changed the image"
        if mode == "dvr":
            # cells where the cell map fits a 3D texture, per-block skipping otherwise
            assert kind == ("cells" if fits_cells else "blocks"), name
        elif name == "warped":
            assert kind == "blocks"
        images[name] = on
    np.testing.assert_allclose(images["warped"], images["straight"], atol=2 / 255)
    img = images["straight"]
    if mode == "mip":
        # numpy MIP along the long axis: three plateaus, one per spot, each its own value
        mip = vol.data.max(axis=int(np.argmax(shape)))
        assert sorted(set(np.unique(mip)) - {0}) == list(SPOT_VALUES)
        grey = img[..., 0]
        for v in SPOT_VALUES:
            assert (np.abs(grey - v / 255) < 2e-3).sum() >= 16, f"spot {v} is missing"
        assert grey.max() <= max(SPOT_VALUES) / 255 + 2e-3
    else:
        background = np.asarray(scene.background, np.float32)
        shown = np.abs(img - background).max(axis=-1) > 0.05
        # three separate spots, the one in the middle as large as those at the ends
        from scipy.ndimage import label

        labels, count = label(shown)
        assert count == 3
        sizes = np.bincount(labels.ravel())[1:]
        assert sizes.min() >= 0.5 * sizes.max()


def test_volume_over_the_texture_limit_is_one_line_naming_the_axis(gl_ctx: Any) -> None:
    r = Renderer(gl_ctx)
    limit = r.max_texture_size
    for axis in range(3):
        shape = [4, 4, 4]
        shape[axis] = limit + 1
        vol = Volume(np.zeros(shape, np.uint8))
        with pytest.raises(VolumeTooLargeError) as info:
            r.check_volume(vol)
        msg = str(info.value)
        assert "\n" not in msg
        assert f"{limit + 1} voxels along axis {axis} ({'xyz'[axis]})" in msg
        assert f"{limit}" in msg
        advice = re.search(r"--downsample ([0-9,]+)", msg)
        assert advice is not None, msg
        factor = [int(f) for f in advice.group(1).split(",")]
        assert max(factor) == 2
        r.check_volume(vol.downsample(factor if len(factor) == 3 else factor[0]))  # it works
    # rendering says the same, and leaves no GL error behind (checked by the fixture)
    with OffscreenRenderer(8, 8, ctx=gl_ctx) as off, pytest.raises(VolumeTooLargeError):
        off.render(Scene(Volume(np.zeros((4, limit + 1, 4), np.uint8)), mode="mip"))
    r.release()


def test_cli_over_the_texture_limit_exits_2_with_one_line(tmp_path: Path) -> None:
    path = tmp_path / "long.npy"
    np.save(path, np.zeros((4, 4, 16385), np.uint8))  # over any GPU's 3D texture size
    out = tmp_path / "out.png"
    proc = subprocess.run(
        [sys.executable, "-m", "voxwarp", "render", str(path), "-o", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("voxwarp: error: volume (4, 4, 16385) has 16385 voxels along axis 2")
    assert "--downsample" in lines[0]
    assert "Traceback" not in proc.stderr
    assert not out.exists()


def test_wire_field_over_the_texture_limit_is_one_line(gl_ctx: Any) -> None:
    from types import SimpleNamespace

    from voxwarp.deform.warp import WarpError
    from voxwarp.deform.wires.field import Wire, WireDeformer

    data = np.zeros((40, 12, 12), np.float32)
    data[4:36, 3:9, 3:9] = 100.0
    vol = Volume(data)
    base = [[x, 6.0, 6.0] for x in (2.0, 14.0, 26.0, 38.0)]
    bent = [[x, 6.0 + (2.0 if 10 < x < 30 else 0.0), 6.0] for x in (2.0, 14.0, 26.0, 38.0)]
    deformer = WireDeformer(vol, [Wire(base, bent, radius=4.0)], field_scale=1)
    deformer.build()
    warp = deformer.warp()
    shape = warp.field.shape
    assert max(shape) >= 40
    small_gpu = SimpleNamespace(info={"GL_MAX_3D_TEXTURE_SIZE": max(shape) - 1})
    with pytest.raises(WarpError) as info:
        warp.textures(small_gpu)
    msg = str(info.value)
    assert "\n" not in msg
    axis = int(np.argmax(shape))
    assert f"axis {axis} ({'xyz'[axis]})" in msg
    assert "field_scale" in msg
    textures = warp.textures(gl_ctx)  # within the real limit: uploads
    assert textures
    warp.release()
