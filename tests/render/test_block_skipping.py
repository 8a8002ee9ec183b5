"""Tests of the empty-space-skipping grid (voxwarp.render.raycaster.block_min_max) and of
Renderer.check_volume (texture size and memory limits).

``block_min_max`` is compared with a brute-force loop over blocks; ``check_volume`` with
the byte counts of each dtype and with its own advice (the downsample factor it names
must make the volume fit).
"""

from __future__ import annotations

import itertools
import math
import re
from typing import Any

import numpy as np
import pytest

from voxwarp.core.volume import Volume
from voxwarp.errors import VolumeTooLargeError
from voxwarp.render.raycaster import Renderer
from voxwarp.render.skipping.maps import BLOCK, block_min_max


def brute_force_block_min_max(data: np.ndarray, block: int) -> tuple[np.ndarray, np.ndarray]:
    """Block b covers voxels [b*B - 1, (b+1)*B] (inclusive, clamped) along each axis."""
    nb = [math.ceil(n / block) for n in data.shape]
    lo = np.empty(nb)
    hi = np.empty(nb)
    for b in itertools.product(*(range(n) for n in nb)):
        sl = tuple(
            slice(max(bi * block - 1, 0), min((bi + 1) * block, n - 1) + 1)
            for bi, n in zip(b, data.shape, strict=True)
        )
        lo[b] = data[sl].min()
        hi[b] = data[sl].max()
    return lo, hi


SHAPES = [(17, 9, 23), (8, 8, 8), (1, 5, 33), (4, 4, 4), (16, 24, 9), (3, 1, 2)]


@pytest.mark.parametrize("block", [4, 8])
@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.uint16, np.float32])
def test_block_min_max_matches_brute_force(block: int, shape: tuple, dtype: Any) -> None:
    rng = np.random.default_rng(hash((block, shape)) % 2**32)
    if np.dtype(dtype).kind == "f":
        data = rng.normal(0, 100, shape).astype(dtype)
    else:
        info = np.iinfo(dtype)
        data = rng.integers(info.min, info.max, shape, endpoint=True).astype(dtype)
    data = np.asfortranarray(data)
    lo, hi = block_min_max(data, block)
    expected_lo, expected_hi = brute_force_block_min_max(data, block)
    assert lo.shape == hi.shape == tuple(math.ceil(n / block) for n in shape)
    assert lo.dtype == hi.dtype == np.float32
    np.testing.assert_array_equal(lo, expected_lo.astype(np.float32))
    np.testing.assert_array_equal(hi, expected_hi.astype(np.float32))


def test_block_min_max_includes_the_apron_voxel() -> None:
    """A single bright voxel at a block edge shows in both neighbouring blocks."""
    data = np.zeros((16, 16, 16), np.uint8)
    data[8, 3, 3] = 200  # first voxel of block 1 along x: apron of block 0
    _, hi = block_min_max(data, 8)
    assert hi[0, 0, 0] == 200
    assert hi[1, 0, 0] == 200
    data[:] = 0
    data[7, 3, 3] = 100  # last voxel of block 0 along x: apron of block 1
    _, hi = block_min_max(data, 8)
    assert hi[0, 0, 0] == 100
    assert hi[1, 0, 0] == 100
    data[:] = 0
    data[5, 3, 3] = 50  # interior voxel: only its own block
    lo, hi = block_min_max(data, 8)
    assert hi[0, 0, 0] == 50
    assert hi[1, 0, 0] == 0
    assert lo.max() == 0


def test_block_min_max_default_block_and_c_order_input() -> None:
    data = np.random.default_rng(0).random((20, 13, 11)).astype(np.float32)
    lo, hi = block_min_max(np.ascontiguousarray(data))
    expected_lo, expected_hi = brute_force_block_min_max(data, BLOCK)
    np.testing.assert_array_equal(lo, expected_lo)
    np.testing.assert_array_equal(hi, expected_hi)


def test_block_min_max_int16_extremes_are_exact_in_float32() -> None:
    data = np.full((9, 9, 9), 7, np.int16)
    data[0, 0, 0] = -32768
    data[8, 8, 8] = 32767
    lo, hi = block_min_max(data, 4)
    assert lo.min() == -32768
    assert hi.max() == 32767
    assert lo[2, 2, 2] == 7  # block 2 = voxels 7..8 reaches the max, not the min
    assert hi[2, 2, 2] == 32767


# ---------------------------------------------------------------------- check_volume
#: bytes per voxel of the GPU copy: uint8 as R8, int16/uint16 as R16, float32 as R32F
GPU_BYTES = {np.dtype(np.uint8): 1, np.dtype(np.int16): 2, np.dtype(np.uint16): 2}
GPU_BYTES[np.dtype(np.float32)] = 4


def texture_bytes(r: Renderer, shape: tuple[int, ...], dtype: Any) -> int:
    """Texture memory of a volume; slice-pair sampling stores every slice twice."""
    copies = 2 if r.layout_for(shape, dtype) == "slice_pairs" else 1
    return int(np.prod(shape)) * GPU_BYTES[np.dtype(dtype)] * copies


def downsample_factor(message: str) -> int | tuple[int, ...]:
    """The advice's factor: one number, or per-axis factors ``(fx, fy, fz)``."""
    m = re.search(r"downsample=(\d+|\(\d+, \d+, \d+\))", message)
    assert m, f"no downsample factor in {message!r}"
    text = m.group(1)
    if text.isdigit():
        assert f"--downsample {text}" in message
        return int(text)
    factors = tuple(int(v) for v in text.strip("()").split(", "))
    assert f"--downsample {','.join(map(str, factors))}" in message
    return factors


def megabytes(message: str, before: str) -> float:
    m = re.search(before + r" ([\d.]+) MB", message)
    assert m, f"no '{before} N MB' in {message!r}"
    return float(m.group(1))


@pytest.mark.gl
@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.uint16, np.float32])
def test_check_volume_budget_is_exact_per_dtype(gl_ctx: Any, dtype: Any) -> None:
    shape = (40, 30, 20)
    vol = Volume(np.zeros(shape, dtype))
    need = texture_bytes(Renderer(gl_ctx), shape, dtype)
    Renderer(gl_ctx, texture_budget_bytes=need).check_volume(vol)  # exactly fits
    with pytest.raises(VolumeTooLargeError, match="budget"):
        Renderer(gl_ctx, texture_budget_bytes=need - 1).check_volume(vol)


@pytest.mark.gl
@pytest.mark.parametrize("dtype", [np.uint8, np.int16])
def test_check_volume_over_budget_names_the_limit_and_a_factor_that_works(
    gl_ctx: Any, dtype: Any
) -> None:
    shape = (256, 256, 160)
    vol = Volume(np.zeros(shape, dtype))
    budget = 2**20
    r = Renderer(gl_ctx, texture_budget_bytes=budget)
    need = texture_bytes(r, shape, dtype)
    with pytest.raises(VolumeTooLargeError) as info:
        r.check_volume(vol)
    msg = str(info.value)
    assert megabytes(msg, "budget of") == pytest.approx(1.0)  # the limit
    assert megabytes(msg, "needs") == pytest.approx(need / 2**20, rel=0.01)
    assert "VOXWARP_TEXTURE_BUDGET_MB" in msg
    assert "downsample" in msg.lower()
    # the factor named is the smallest integer that makes the volume fit
    smallest = next(
        f for f in range(2, 100) if texture_bytes(r, tuple(n // f for n in shape), dtype) <= budget
    )
    factor = downsample_factor(msg)
    assert factor == smallest
    r.check_volume(vol.downsample(factor))  # the advice works
    if factor > 2:
        with pytest.raises(VolumeTooLargeError):
            r.check_volume(vol.downsample(factor - 1))


@pytest.mark.gl
def test_check_volume_over_texture_size(gl_ctx: Any) -> None:
    r = Renderer(gl_ctx)
    assert r.max_texture_size >= 256  # GL 4.3 guarantees at least 2048
    r.max_texture_size = 16  # pretend a small GPU
    vol = Volume(np.zeros((40, 8, 8), np.uint8))
    with pytest.raises(VolumeTooLargeError) as info:
        r.check_volume(vol)
    msg = str(info.value)
    assert "maximum 3D texture size 16" in msg
    factor = downsample_factor(msg)
    assert factor == (3, 1, 1)  # ceil(40 / 16) along x only: y and z already fit
    r.check_volume(vol.downsample(factor))
    r.check_volume(Volume(np.zeros((16, 16, 16), np.uint8)))  # the limit itself fits


@pytest.mark.gl
def test_check_volume_passes_within_limits(gl_ctx: Any) -> None:
    r = Renderer(gl_ctx)
    assert r.texture_budget_bytes > 0
    for dtype in (np.uint8, np.int16, np.float32):
        r.check_volume(Volume(np.zeros((64, 48, 32), dtype)))


@pytest.mark.gl
def test_texture_budget_from_the_environment(gl_ctx: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    shape = (64, 64, 128)  # 0.5 MiB of uint8
    need = texture_bytes(Renderer(gl_ctx), shape, np.uint8)
    monkeypatch.setenv("VOXWARP_TEXTURE_BUDGET_MB", str(need / 2**20))
    r = Renderer(gl_ctx)
    assert r.texture_budget_bytes == need
    r.check_volume(Volume(np.zeros(shape, np.uint8)))  # fits exactly
    with pytest.raises(VolumeTooLargeError, match="budget"):
        r.check_volume(Volume(np.zeros((64, 64, 129), np.uint8)))


def test_cell_min_max_matches_brute_force() -> None:
    """Cell c covers texel coordinates [c - 1/2, c + 1/2]: its range is that of voxels
    c - 1 and c per axis (clamped to the edge)."""
    from voxwarp.render.skipping.maps import cell_min_max

    rng = np.random.default_rng(3)
    data = rng.integers(-50, 50, size=(5, 4, 6)).astype(np.int16)
    lo, hi = cell_min_max(data)
    assert lo.shape == (6, 5, 7)
    n = data.shape
    for c in np.ndindex(lo.shape):
        sl = tuple(slice(max(ci - 1, 0), min(ci, ni - 1) + 1) for ci, ni in zip(c, n, strict=True))
        assert lo[c] == data[sl].min()
        assert hi[c] == data[sl].max()
