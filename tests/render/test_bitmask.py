"""BitMask (voxwarp.render.skipping.bitmask): a bool array back bit for bit, in its own
memory order, at an eighth of its bytes (oracle: the array itself)."""

from __future__ import annotations

import numpy as np
import pytest

from voxwarp.render.skipping.bitmask import BitMask


@pytest.mark.parametrize("order", ["C", "F"])
@pytest.mark.parametrize("shape", [(37, 50, 23), (5, 1, 9), (1, 1, 1), (8, 8, 8)])
def test_unpack_gives_the_mask_back(shape: tuple[int, int, int], order: str) -> None:
    rng = np.random.default_rng(sum(shape))
    mask = np.asarray(rng.random(shape) < 0.3, order=order)
    packed = BitMask(mask)
    got = packed.unpack()
    np.testing.assert_array_equal(got, mask)
    assert got.dtype == bool
    assert got.flags.f_contiguous == mask.flags.f_contiguous
    assert packed.nbytes == -(-mask.size // 8)


def test_a_transposed_view_keeps_its_layout() -> None:
    """The skip maps' visibility is a transposed view of a (z, y, x) C array."""
    t = np.random.default_rng(1).random((6, 7, 9)) < 0.5
    mask = t.T
    got = BitMask(mask).unpack()
    np.testing.assert_array_equal(got, mask)
    assert got.T.flags.c_contiguous
