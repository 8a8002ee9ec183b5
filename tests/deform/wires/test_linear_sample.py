"""Tests of voxwarp.deform.wires.linear_sample: the compiled trilinear sampler of the wire
masks gives scipy's map_coordinates(order=1, mode="nearest", prefilter=False) bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from voxwarp.deform.wires.linear_sample import DTYPES, sample_linear, supported
from voxwarp.deform.wires.masks import _sample


def _data(dtype: np.dtype, shape: tuple[int, int, int], rng: np.random.Generator) -> np.ndarray:
    if dtype.kind == "f":
        return (rng.normal(size=shape) * 1000).astype(dtype)
    info = np.iinfo(dtype)
    return rng.integers(max(info.min, -40000), min(info.max, 70000), size=shape).astype(dtype)


def _coords(shape: tuple[int, int, int], rng: np.random.Generator) -> np.ndarray:
    """Random points over the volume and past it, exact nodes, halves, the last node and
    the outer faces (where scipy's nearest mode takes over)."""
    n = 60_000
    c = np.stack([rng.uniform(-3.0, s + 2.0, n) for s in shape])
    c[:, :2000] = np.stack([rng.integers(0, s, 2000) for s in shape])
    c[:, 2000:4000] = np.stack([rng.integers(-1, s, 2000) + 0.5 for s in shape])
    c[:, 4000:4100] = np.array(shape)[:, None] - 1.0
    c[:, 4100:4200] = np.array(shape)[:, None] - 0.5
    c[:, 4200:4300] = -0.5
    return c


@pytest.mark.parametrize("dtype", DTYPES, ids=str)
@pytest.mark.parametrize("shape", [(7, 5, 9), (1, 4, 6), (2, 2, 2), (30, 40, 20)])
@pytest.mark.parametrize("order", ["C", "F"])
def test_samples_are_scipys_bits(dtype: np.dtype, shape, order: str) -> None:
    rng = np.random.default_rng(abs(hash((str(dtype), shape, order))) % 2**32)
    data = np.asarray(_data(dtype, shape, rng), order=order)
    c = _coords(shape, rng)
    ref = ndimage.map_coordinates(data, c, order=1, mode="nearest", prefilter=False)
    got = sample_linear(data, c)
    assert got.dtype == ref.dtype
    assert np.array_equal(got.view(np.uint8), ref.view(np.uint8))


def test_other_arrays_go_to_scipy() -> None:
    rng = np.random.default_rng(3)
    c = _coords((4, 5, 6), rng)
    for data in (
        rng.normal(size=(4, 5, 6)).astype(">f8"),  # not native byte order
        rng.integers(0, 9, (4, 5, 6)).astype(np.uint64),
        rng.integers(0, 9, (4, 5, 6)).astype(np.int64),
    ):
        assert not supported(data)
        ref = ndimage.map_coordinates(data, c, order=1, mode="nearest", prefilter=False)
        assert np.array_equal(_sample(data, c), ref)
    assert supported(np.zeros((2, 2, 2), np.uint8))
    assert not supported(np.zeros((2, 2), np.uint8))
