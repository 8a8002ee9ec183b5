"""Otsu's split (voxwarp.deform.histogram.otsu), the one the tissue presets, the display
levels and the teaching wire share. Oracle: two separated classes split in their gap, and
the class means are the means of the values on each side (to a bin's width)."""

from __future__ import annotations

import numpy as np

from voxwarp.deform.histogram import otsu


def test_two_classes_split_in_their_gap_with_their_means() -> None:
    rng = np.random.default_rng(3)
    low, high = rng.normal(10.0, 1.0, 4000), rng.normal(60.0, 3.0, 1000)
    split = otsu(np.r_[low, high])
    assert low.max() < split.edge < high.min()
    width = (high.max() - low.min()) / 256
    assert abs(split.mean_below - low.mean()) < width
    assert abs(split.mean_above - high.mean()) < width


def test_shifting_and_scaling_moves_the_split_alike() -> None:
    values = np.r_[np.zeros(30), np.full(70, 5.0)]
    a, b = otsu(values), otsu(values * 10.0 - 1000.0)
    assert b.edge == a.edge * 10.0 - 1000.0
