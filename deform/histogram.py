"""Otsu's split of a histogram, shared by the tissue presets of the element grid
(:mod:`voxwarp.deform.elements.materials`), the display levels of the threshold modes
(:mod:`voxwarp.core.levels`) and the teaching demo's automatic wire."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class OtsuSplit(NamedTuple):
    """Where Otsu's method splits values in two classes."""

    #: the histogram bin edge between the classes
    edge: float
    #: the mean of the values below the edge and of those above it (bin centres)
    mean_below: float
    mean_above: float


def otsu(values: np.ndarray, bins: int = 256) -> OtsuSplit:
    """Otsu's split of ``values``: the edge of a ``bins``-bin histogram (over the values'
    range) that maximises the between-class variance, with the two classes' means.

    Example: ``otsu(np.r_[np.zeros(50), np.full(50, 10.0)]).edge`` lies between 0 and 10.
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    hist, edges = np.histogram(v, bins=bins)
    centres = 0.5 * (edges[:-1] + edges[1:])
    w0 = np.cumsum(hist).astype(np.float64)
    w1 = w0[-1] - w0
    m0 = np.cumsum(hist * centres)
    mu0 = m0 / np.maximum(w0, 1)
    mu1 = (m0[-1] - m0) / np.maximum(w1, 1)
    between = w0 * w1 * (mu0 - mu1) ** 2
    k = int(np.argmax(between[:-1]))
    return OtsuSplit(float(edges[k + 1]), float(mu0[k]), float(mu1[k]))
