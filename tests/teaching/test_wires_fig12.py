"""The wire paper's Figure 12 close-up sheet: its crop and difference images."""

from __future__ import annotations

import numpy as np

from voxwarp.teaching.wires_fig12 import DIFF_GAIN, content_crop, difference


def test_content_crop_holds_what_any_image_shows_with_a_margin() -> None:
    a = np.zeros((100, 200, 3), np.uint8)
    b = a.copy()
    a[20:30, 50:60] = 200
    b[40:45, 120:130] = 30
    rows, cols = content_crop([a, b], margin=0.1)
    assert (rows.start, rows.stop) == (10, 55)
    assert (cols.start, cols.stop) == (30, 150)
    assert content_crop([np.zeros((4, 4, 3), np.uint8)]) == (slice(None), slice(None))


def test_difference_is_the_largest_channel_amplified_and_clipped() -> None:
    ref = np.zeros((2, 2, 3), np.uint8)
    img = ref.copy()
    img[0, 0] = (5, 10, 0)
    img[1, 1] = (0, 0, 200)
    d = difference(img, ref)
    assert d.dtype == np.uint8
    assert d[0, 0] == 10 * DIFF_GAIN
    assert d[1, 1] == 255
    assert d[0, 1] == 0
    assert not difference(ref, ref).any()
