"""The volume texture's layouts (:mod:`voxwarp.render.volume_texture`): the one-copy
"slice_layers" layout gives the same pixels as the two-copy "slice_pairs" layout, in the
raycaster and in the slice views, and ``sampling="auto"`` on a software rasteriser keeps
big volumes in one copy.

Oracle: the slice-pair images. Both layouts take the same two bilinear values (layers k
and k + 1, the same filter weights per channel) and the same lerp across z, so the
images are identical, not merely close; the texture's bytes are read back and compared
with the array itself.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from typing import Any

import numpy as np
import pytest

from tests.model_scenes import massspring_push, padded_colin
from voxwarp.core.volume import Volume
from voxwarp.render import raycaster
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.render.raycaster import Renderer
from voxwarp.scene import Scene

pytestmark = pytest.mark.gl


def _blobs(shape: tuple[int, int, int], dtype: Any) -> np.ndarray:
    """Smooth random blobs over the dtype's range (air between them)."""
    from scipy import ndimage

    rng = np.random.default_rng(7)
    raw = ndimage.gaussian_filter(rng.random(shape), 2.0)
    raw = (raw - raw.min()) / np.ptp(raw)
    if dtype == np.int16:
        return (raw * 3000 - 1000).astype(np.int16)
    return (raw * 255).astype(np.uint8)


def _renderer(ctx: Any, sampling: str, size: tuple[int, int] = (48, 40)) -> OffscreenRenderer:
    r = OffscreenRenderer(*size, ctx=ctx, dtype="f4")
    r.renderer.release()
    r.renderer = Renderer(ctx, sampling=sampling)
    return r


@pytest.mark.parametrize("dtype", [np.uint8, np.int16])
@pytest.mark.parametrize("mode", ["dvr", "mip", "iso"])
def test_slice_layers_raycast_the_same_pixels_as_slice_pairs(
    gl_ctx: Any, dtype: Any, mode: str
) -> None:
    vol = Volume(_blobs((21, 17, 13), dtype), (1.0, 1.2, 1.5))
    scene = Scene(vol, mode=mode, view=(30.0, 20.0), shading=mode == "iso")
    images = {}
    for sampling in ("slice_pairs", "slice_layers"):
        with _renderer(gl_ctx, sampling) as r:
            images[sampling] = r.render(scene)
            assert r.renderer._volume_gpu(vol).layout == sampling
    np.testing.assert_array_equal(images["slice_layers"], images["slice_pairs"])
    assert np.ptp(images["slice_pairs"][..., :3]) > 0.05  # something was drawn


@pytest.mark.parametrize("interpolation", ["linear", "nearest"])
def test_slice_views_are_the_same_with_either_layout(gl_ctx: Any, interpolation: str) -> None:
    """A deformed slice (mass-spring push on colin27) through both layouts."""
    vol = padded_colin()
    scene = Scene(vol, warps=massspring_push(vol, 5, 40))
    values = {}
    for sampling in ("slice_pairs", "slice_layers"):
        with _renderer(gl_ctx, sampling, (64, 64)) as r:
            for plane in ("axial", "coronal"):
                s = r.render_slice(scene, plane, interpolation=interpolation)
                values[sampling, plane] = (s.values, s.rest)
    for plane in ("axial", "coronal"):
        (a, rest_a), (b, rest_b) = values["slice_pairs", plane], values["slice_layers", plane]
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(rest_a, rest_b)
        assert np.nanmax(a) > 0  # the head is in the slice
        if interpolation == "linear":
            assert np.nanmax(np.abs(a - rest_a)) > 0  # and deformed


def test_auto_keeps_big_volumes_in_one_copy(gl_ctx: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    """On llvmpipe "auto" gives slice pairs up to PAIRS_MAX_BYTES of pair texture and
    slice layers above, whose texture holds each voxel once (its bytes are the array's);
    the image does not change."""
    vol = Volume(_blobs((20, 18, 16), np.int16))
    scene = Scene(vol, mode="dvr", view=(30.0, 20.0))
    with _renderer(gl_ctx, "slice_pairs") as r:
        want = r.render(scene)
    r = _renderer(gl_ctx, "auto")
    try:
        if r.renderer.sampling != "auto-software":
            pytest.skip("not a software rasteriser: auto picks texture3d")
        assert r.renderer.layout_for(vol.shape, vol.dtype) == "slice_pairs"
        monkeypatch.setattr(raycaster, "PAIRS_MAX_BYTES", 2 * vol.data.nbytes - 1)
        assert r.renderer.layout_for(vol.shape, vol.dtype) == "slice_layers"
        np.testing.assert_array_equal(r.render(scene), want)
        gpu = r.renderer._volume_gpu(vol)
        assert gpu.nbytes == vol.data.nbytes
        texels = np.frombuffer(gpu.texture.read(alignment=1), np.uint16)
        expect = (vol.data.T.astype(np.int32) + 32768).astype(np.uint16)
        np.testing.assert_array_equal(texels, expect.reshape(-1))
    finally:
        r.release()


# ---------------------------------------------------------------------- memory
def test_block_info_written_in_slabs_holds_the_grids(
    gl_ctx: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The block info texture, written a few z layers at a time (its host copy one
    slab), holds the block (distance, min, max, 0) grids, and draws the same image."""
    from voxwarp.core.transfer_function import TransferFunction
    from voxwarp.render.skipping import cache as skip_cache

    vol = Volume(_blobs((30, 26, 41), np.int16), (1.0, 1.1, 0.9))
    tf = TransferFunction([(-1000, 0, 0, 0, 0), (1200, 0, 0, 0, 0), (1600, 1, 0.9, 0.8, 0.8)])
    scene = Scene(vol, mode="dvr", view=(30.0, 20.0), transfer_function=tf)
    images = []
    for slab_bytes in (1 << 30, 1):  # one slab; one z layer per write
        monkeypatch.setattr(skip_cache, "INFO_SLAB_BYTES", slab_bytes)
        with _renderer(gl_ctx, "slice_pairs") as r:
            r.renderer.cell_skipping = False  # block skipping reads the info texture
            images.append(r.render(scene))
            maps = r.renderer._volume_gpu(vol).skip
            info = np.frombuffer(maps.info.read(), "f2" if maps.info.dtype == "f2" else "f4")
            info = info.reshape(*maps.block_min.shape[::-1], 4).transpose(2, 1, 0, 3)
            np.testing.assert_array_equal(info[..., 1], maps.block_min)
            np.testing.assert_array_equal(info[..., 2], maps.block_max)
            assert np.all(info[..., 3] == 0)
            assert np.ptp(info[..., 0]) > 0  # some blocks are further from visible ones
    np.testing.assert_array_equal(images[0], images[1])
    assert np.ptp(images[0][..., :3]) > 0.05  # the bright blobs were drawn


@pytest.mark.parametrize("dtype", [np.float32, np.int16])
def test_block_visibility_in_slabs_equals_the_whole_grid(
    monkeypatch: pytest.MonkeyPatch, dtype: Any
) -> None:
    """dvr block visibility classified a few z layers at a time (bounded temporaries)
    equals the transfer function's classification of the whole grid."""
    from voxwarp.core.transfer_function import TransferFunction
    from voxwarp.render.skipping import maps as skip_maps

    rng = np.random.default_rng(5)
    lo = np.asfortranarray(rng.integers(-1000, 2000, (9, 7, 13)).astype(dtype))
    hi = lo + np.asarray(rng.integers(0, 400, lo.shape), dtype=dtype)
    tf = TransferFunction([(-1000, 0, 0, 0, 0), (300, 0, 0, 0, 0), (600, 1, 1, 1, 0.5)])
    scene = Scene(Volume(np.zeros((4, 4, 4), np.int16)), mode="dvr", transfer_function=tf)
    want = tf.visible_ranges(lo, hi)
    monkeypatch.setattr(skip_maps, "_SLAB_BLOCKS", 2 * 9 * 7)  # two z layers a slab
    got = skip_maps.static_block_visibility(scene, lo, hi)
    np.testing.assert_array_equal(got, want)
    assert 0 < want.sum() < want.size


_MEMORY_SCRIPT = r"""
import gc, json, sys
from benchmarks.scale import PeakRSS, _status_kib, scale_transfer_function, synthetic_cube
from voxwarp.bench.render import bench_camera
from voxwarp.core.volume import Volume
from voxwarp.render import raycaster
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.render.skipping import cache as skip_cache
from voxwarp.scene import Scene

n = int(sys.argv[1])
raycaster.PAIRS_MAX_BYTES = int(sys.argv[2])
skip_cache.COARSE_MIN_CELLS = int(sys.argv[3])
tf = scale_transfer_function()


def scene(vol):
    return Scene(vol, mode="dvr", transfer_function=tf, camera=bench_camera(vol))


with OffscreenRenderer(256, 256) as r:
    # programs compiled and numba's kernels loaded beforehand: once per process, not per
    # volume (a 208³ volume is over skipping.maps.COMPILED_MIN_SIZE)
    r.renderer.cell_skip_maps = "always"
    r.render(scene(Volume(synthetic_cube(16), (1.0, 1.0, 1.0))))
    r.render(scene(Volume(synthetic_cube(208), (1.0, 1.0, 1.0))))
    r.renderer.cell_skip_maps = "auto"
    gc.collect()
    r.render(scene(Volume(synthetic_cube(16), (1.0, 1.0, 1.0))))  # drops the 208³ textures
    data = synthetic_cube(n)
    base = _status_kib("VmRSS")
    with PeakRSS() as first:  # a new Volume of the array to its first image (blocks)
        vol = Volume(data, (1.0, 1.0, 1.0))
        r.render(scene(vol))
    r.render(scene(vol))  # the second frame builds the cell maps
    kept = (_status_kib("VmRSS") - base) * 1024
    print(json.dumps({"first": first.mib * 2**20, "kept": kept, "nbytes": data.nbytes,
                      "layout": r.renderer._volume_gpu(vol).layout}))
"""


@pytest.mark.slow
def test_memory_beyond_the_array_of_a_256_cube(gl_ctx: Any) -> None:
    """A new 256³ uint8 volume on the big-volume path (slice layers, a block-skipped
    first frame, cell maps on the second), in a fresh process: the resident-set high
    water of its first frame beyond the array is at most 2.5x the array's bytes (the
    slice-pair texture alone was 2x), and what stays resident once the cell maps are
    built (texture, one octant map per 2³ cells per ray octant, the visibility's bits)
    at most 2x (was 5.6x; 3.0x with per-cell octant maps). Not timed."""
    if not os.path.exists("/proc/self/clear_refs"):
        pytest.skip("needs Linux /proc to measure the resident set")
    run = subprocess.run(
        [sys.executable, "-c", _MEMORY_SCRIPT, "256", "0", "0"],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
    )
    assert run.returncode == 0, run.stderr[-2000:]
    got = json.loads(run.stdout.strip().splitlines()[-1])
    if got["layout"] == "texture3d":
        pytest.skip("a GPU: the texture is not process memory")
    assert got["layout"] == "slice_layers"
    assert 0 < got["first"] <= 2.5 * got["nbytes"], got
    assert 0 < got["kept"] <= 2.0 * got["nbytes"], got
