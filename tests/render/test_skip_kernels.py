"""The compiled skip-map builders (voxwarp.render.skipping.kernels behind
voxwarp.render.skipping.maps), the slab-wise volume upload and the block-first policy for big
volumes (issue 19, lever 6).

Oracles: the numpy builders voxwarp used before (voxwarp.render.skipping.numpy_maps, verbatim, still
used below skipping.COMPILED_MIN_SIZE), scipy's chamfer distance transform, the old
one-shot texture upload, and renders with block skipping, which must equal the
cell-skipping image. Every test here forces the compiled path in its own process.
"""

from __future__ import annotations

import itertools
import subprocess
import sys
import tracemalloc
from typing import Any

import numpy as np
import pytest

from voxwarp.core.transfer_function import TransferFunction
from voxwarp.core.volume import Volume
from voxwarp.render import volume_texture
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.render.skipping import cache as skip_cache
from voxwarp.render.skipping import maps as skipping
from voxwarp.render.skipping import numpy_maps as skip_numpy
from voxwarp.scene import Scene

OCTANTS = list(itertools.product((1, -1), repeat=3))
SHAPES = [(37, 50, 23), (5, 1, 9), (16, 12, 8)]
TF = TransferFunction(
    [(0, 0, 0, 0, 0), (90, 0, 0, 0, 0), (120, 1, 0.8, 0.6, 0.4), (255, 1, 1, 1, 0.9)]
)


@pytest.fixture(autouse=True)
def compiled(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every array of this process through the compiled kernels."""
    monkeypatch.setattr(skipping, "COMPILED_MIN_SIZE", 0)


def _blobs(shape: tuple, dtype: Any, seed: int = 0) -> np.ndarray:
    """Smooth random blobs plus noise (clustered visible cells), F-ordered like a Volume."""
    rng = np.random.default_rng(seed)
    g = np.indices(shape).transpose(1, 2, 3, 0).astype(np.float32)
    v = np.zeros(shape, np.float32)
    for _ in range(4):
        c = rng.uniform(0, shape)
        v += 200.0 * np.exp(-np.sum((g - c) ** 2, axis=-1) / rng.uniform(4, 30))
    v += rng.uniform(0, 40, shape)
    if np.dtype(dtype) == np.int16:
        v = v * 10 - 1000  # negative values too
    return np.asfortranarray(v.astype(dtype))


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.uint16, np.float32])
@pytest.mark.slow
def test_block_and_cell_ranges_match_the_numpy_builders(shape: tuple, dtype: Any) -> None:
    data = _blobs(shape, dtype)
    for block in (4, 3):
        for got, exp in zip(
            skipping.block_min_max(data, block), skip_numpy.block_min_max(data, block), strict=True
        ):
            np.testing.assert_array_equal(got, exp)
    for got, exp in zip(skipping.cell_min_max(data), skip_numpy.cell_min_max(data), strict=True):
        assert got.dtype == exp.dtype
        np.testing.assert_array_equal(got, exp)


@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.float32])
@pytest.mark.parametrize("mode", ["dvr", "iso", "flm", "mip", "minip", "xray", "average"])
@pytest.mark.slow
def test_cell_visibility_matches_the_numpy_builder(
    dtype: Any, mode: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    data = _blobs((37, 50, 23), dtype, seed=3)
    lo, hi = float(data.min()), float(data.max())
    tf = TransferFunction(
        [(lo, 0, 0, 0, 0), (lo + 0.55 * (hi - lo), 0, 0, 0, 0), (hi, 1, 1, 1, 0.8)]
    )
    scene = Scene(
        Volume(data, (1.0, 1.0, 1.0)),
        mode=mode,
        transfer_function=tf,
        iso_value=lo + 0.6 * (hi - lo),
        window=(lo + 0.5 * (hi - lo), 0.3 * (hi - lo)),
    )
    monkeypatch.setattr(skipping, "_SLAB_CELLS", 3000)  # float data: several slabs
    got = skipping.cell_visibility(scene, data, *skipping.block_min_max(data))
    expected = skipping.static_block_visibility(scene, *skip_numpy.cell_min_max(data))
    assert got.shape == expected.shape == (38, 51, 24)
    np.testing.assert_array_equal(got, expected)
    if mode not in ("average", "minip"):
        assert 0 < expected.sum() < expected.size  # some cells visible, some not


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("density", [0.002, 0.05])
@pytest.mark.slow
def test_octant_skip_distances_match_the_numpy_builder(shape: tuple, density: float) -> None:
    rng = np.random.default_rng(11)
    visible = rng.random(tuple(n + 1 for n in shape)) < density
    visible[tuple(n // 2 for n in visible.shape)] = True
    for signs in OCTANTS:
        for cap, block in ((8, 4), (255, 4), (3, 3), (1, 4)):
            got = skipping.octant_skip_distances(visible, signs, cell_cap=cap, block=block)
            expected = skip_numpy.octant_skip_distances(visible, signs, cap, block)
            assert got.dtype == np.uint8
            np.testing.assert_array_equal(got, expected, err_msg=f"{signs} {cap} {block}")


def test_octant_maps_of_a_rendered_volume_match_the_numpy_builder() -> None:
    """The maps the renderer builds: cells of a blob volume under a transfer function."""
    data = _blobs((37, 50, 23), np.uint8, seed=5)
    scene = Scene(Volume(data, (1.0, 1.0, 1.0)), mode="dvr", transfer_function=TF)
    visible = skipping.cell_visibility(scene, data, *skipping.block_min_max(data))
    assert 0 < visible.mean() < 0.5
    for signs in OCTANTS:
        np.testing.assert_array_equal(
            skipping.octant_skip_distances(visible, signs),
            skip_numpy.octant_skip_distances(visible, signs, 8, 4),
        )


def test_block_skip_distances_match_scipy() -> None:
    from scipy.ndimage import distance_transform_cdt

    rng = np.random.default_rng(2)
    for shape, p in [
        ((7, 5, 3), 0.05),
        ((20, 31, 9), 0.01),
        ((1, 1, 6), 0.3),
        ((30, 3, 40), 0.002),
    ]:
        visible = rng.random(shape) < p
        visible[0, 0, 0] = True
        expected = np.clip(distance_transform_cdt(~visible, metric="chessboard"), 0, 255)
        np.testing.assert_array_equal(skipping.block_skip_distances(visible), expected)


def test_octant_map_memory_is_its_output() -> None:
    """The compiled builders allocate (on the traced heap) little more than their result:
    no full-size int16 or float copies as the numpy builders made."""
    data = _blobs((96, 80, 64), np.uint8, seed=1)
    scene = Scene(Volume(data, (1.0, 1.0, 1.0)), mode="dvr", transfer_function=TF)
    bmin, bmax = skipping.block_min_max(data)
    visible = skipping.cell_visibility(scene, data, bmin, bmax)  # compiles outside the trace
    skipping.octant_skip_distances(visible, (1, -1, 1))
    cells = visible.size
    peaks = {}
    tracemalloc.start()
    try:
        for name, build in (
            ("visibility", lambda: skipping.cell_visibility(scene, data, bmin, bmax)),
            ("octant", lambda: skipping.octant_skip_distances(visible, (1, -1, 1))),
            ("reference", lambda: skip_numpy.octant_skip_distances(visible, (1, -1, 1), 8, 4)),
        ):
            tracemalloc.reset_peak()
            before = tracemalloc.get_traced_memory()[0]
            build()
            peaks[name] = (tracemalloc.get_traced_memory()[1] - before) / cells
    finally:
        tracemalloc.stop()
    assert peaks["visibility"] < 1.5  # its bool output, plus tables independent of size
    assert peaks["octant"] < 1.2  # its uint8 output and the small block map
    assert peaks["reference"] > 4  # the old builder, for scale


@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.float32])
@pytest.mark.parametrize("layout", ["texture3d", "slice_layers", "slice_pairs"])
def test_slab_upload_equals_the_one_shot_upload(
    gl_ctx: Any, dtype: Any, layout: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    pairs = layout == "slice_pairs"
    data = _blobs((13, 7, 11), dtype, seed=4)
    fmt = {np.uint8: "f1", np.int16: "nu2", np.float32: "f4"}[dtype]
    arr = np.ascontiguousarray(data.T)
    if dtype == np.int16:
        arr = (arr.astype(np.int32) + 32768).astype(np.uint16)
    if pairs:
        arr = np.stack([arr, np.concatenate([arr[1:], arr[-1:]])], axis=-1)
    monkeypatch.setattr(volume_texture, "SLAB_BYTES", 200)  # several slabs, one odd one
    tex = volume_texture.upload_volume_texture(gl_ctx, data, fmt, layout)
    try:
        got = np.frombuffer(tex.read(alignment=1), dtype=arr.dtype)
    finally:
        tex.release()
    np.testing.assert_array_equal(got, arr.reshape(-1))


def test_a_big_volume_draws_its_first_frame_with_blocks(
    gl_ctx: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Above EAGER_CELLS the first draw skips per block and builds no cell map; the second
    builds them; both images equal a renderer that uses cell maps at once."""
    vol = Volume(_blobs((40, 36, 30), np.uint8, seed=6), (1.0, 0.9, 1.2))
    scene = Scene(vol, mode="dvr", transfer_function=TF, view=(30.0, 20.0))
    monkeypatch.setattr(skip_cache, "EAGER_CELLS", 1000)
    with OffscreenRenderer(64, 48, ctx=gl_ctx, dtype="f4") as r:
        first = r.render(scene)
        assert r.renderer.last_skip_kind == "blocks"
        second = r.render(scene)
        assert r.renderer.last_skip_kind == "cells"
    with OffscreenRenderer(64, 48, ctx=gl_ctx, dtype="f4") as r:
        r.renderer.cell_skip_maps = "always"
        eager = r.render(scene)
        assert r.renderer.last_skip_kind == "cells"
    assert first[..., 3].max() > 0.2  # something is drawn
    assert np.abs(first - eager).max() <= 1 / 255
    np.testing.assert_array_equal(second, eager)


def test_small_volumes_build_their_maps_without_numba() -> None:
    """Below COMPILED_MIN_SIZE the numpy builders run: no numba (or scipy) start-up for
    a small volume (a fresh interpreter)."""
    code = (
        "import sys, numpy as np\n"
        "from voxwarp.core.transfer_function import TransferFunction\n"
        "from voxwarp.core.volume import Volume\n"
        "from voxwarp.render.skipping import maps as s\n"
        "from voxwarp.scene import Scene\n"
        "d = np.asfortranarray(np.random.default_rng(0).integers(0, 255, (40, 30, 20), np.uint8))\n"
        "tf = TransferFunction([(0, 0, 0, 0, 0), (200, 1, 1, 1, 1)])\n"
        "sc = Scene(Volume(d, (1, 1, 1)), mode='dvr', transfer_function=tf)\n"
        "lo, hi = s.block_min_max(d)\n"
        "v = s.cell_visibility(sc, d, lo, hi)\n"
        "s.octant_skip_distances(v, (1, -1, 1))\n"
        "s.block_skip_distances(s.static_block_visibility(sc, lo, hi))\n"
        "assert 'numba' not in sys.modules, 'numba was imported'\n"
        "assert 'scipy' not in sys.modules, 'scipy was imported'\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-2000:]
