"""scipy's ``ndimage.map_coordinates(data, coords, order=1, mode="nearest",
prefilter=False)`` of a 3D array, compiled, bit for bit.

The wire field's plane masks sample the volume at millions of points per build and
threshold the samples with β, so a sample must be scipy's to the bit: another rounding
could flip a mask pixel. :func:`sample_linear` repeats scipy's arithmetic (ndimage's
geometric transform at order 1): the corner weights ``1 - f`` and ``1 - (1 - f)`` (f
the coordinate's fraction), the corners' indices clamped into ``[0, n - 1]`` (the mode
"nearest"), the eight corners in C order, each corner's value times its three weights
in axis order, summed from 0; then scipy's conversion to the array's dtype (integers
rounded half away from zero and clamped to the type's range). Arrays of other dtypes,
or not in native byte order, go to scipy (:func:`supported`). The kernel is serial and
releases the GIL: the caller's threads sample blocks at once.
``tests/deform/wires/test_linear_sample.py`` holds it to scipy's output on every
supported dtype, random points inside and outside the array, its nodes and its faces.

A module of its own so that importing the wire field does not import numba.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: dtypes the kernel samples (scipy's conversion of each is repeated in :func:`_convert`)
DTYPES = tuple(
    np.dtype(t)
    for t in (
        np.uint8,
        np.uint16,
        np.uint32,
        np.int8,
        np.int16,
        np.int32,
        np.float32,
        np.float64,
    )
)


def supported(data: np.ndarray) -> bool:
    """Whether :func:`sample_linear` takes ``data`` (else use scipy): 3D, one of
    :data:`DTYPES`, native byte order."""
    return data.ndim == 3 and data.dtype in DTYPES and data.dtype.isnative


def sample_linear(data: np.ndarray, coords: np.ndarray) -> np.ndarray:
    """``map_coordinates(data, coords, order=1, mode="nearest", prefilter=False)``: the
    samples of ``data`` at index coordinates ``coords`` (3, n), in ``data``'s dtype."""
    coords = np.ascontiguousarray(coords, dtype=np.float64)
    t = np.empty(coords.shape[1], dtype=np.float64)
    _linear_nearest(data, coords, t)
    return _convert(t, data.dtype)


def _convert(t: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """scipy's store of the summed value t in the output dtype."""
    if dtype.kind == "f":
        return t.astype(dtype)
    info = np.iinfo(dtype)
    if dtype.kind == "u":
        t = np.where(t > 0, t + 0.5, 0.0)
    else:
        t = np.where(t > 0, t + 0.5, t - 0.5)
    return np.clip(t, info.min, info.max).astype(dtype)


@njit(cache=True, nogil=True)
def _corner_weights(c: float, n: int) -> tuple:  # pragma: no cover - compiled
    """(first index, second index, weight of the first, of the second) along one axis of
    length n: scipy's weights at c, the corners' indices clamped into [0, n - 1]."""
    f = np.floor(c)
    i0 = int(f)
    w0 = 1.0 - (c - f)
    w1 = 1.0 - w0
    i1 = min(max(i0 + 1, 0), n - 1)
    i0 = min(max(i0, 0), n - 1)
    return i0, i1, w0, w1


@njit(cache=True, nogil=True)
def _linear_nearest(data, coords, out):  # type: ignore[no-untyped-def]  # pragma: no cover
    n0, n1, n2 = data.shape
    for p in range(coords.shape[1]):
        a0, a1, wa0, wa1 = _corner_weights(coords[0, p], n0)
        b0, b1, wb0, wb1 = _corner_weights(coords[1, p], n1)
        c0, c1, wc0, wc1 = _corner_weights(coords[2, p], n2)
        t = 0.0
        for ia in range(2):
            i = a0 if ia == 0 else a1
            wa = wa0 if ia == 0 else wa1
            for ib in range(2):
                j = b0 if ib == 0 else b1
                wb = wb0 if ib == 0 else wb1
                for ic in range(2):
                    k = c0 if ic == 0 else c1
                    wc = wc0 if ic == 0 else wc1
                    coeff = float(data[i, j, k])
                    coeff *= wa
                    coeff *= wb
                    coeff *= wc
                    t += coeff
        out[p] = t
