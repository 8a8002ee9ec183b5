"""Nearest-seed propagation (the wire field's distance transform): OpenCL vs scipy.

:func:`benchmark_nearest_seed` times :func:`voxwarp.deform.wires.propagation.nearest_seed` with
both backends on a synthetic helix of seeds (:func:`helix_seeds`); ``python -m benchmarks
wires`` reports it.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from voxwarp.deform.wires.propagation import (
    MAX_LINE,
    check_sampling,
    nearest_seed,
    opencl_available,
    opencl_device_name,
)


def seed_distance(nearest: np.ndarray, sampling: float | Sequence[float] = 1.0) -> np.ndarray:
    """Distance (mm) from every voxel to the seed :func:`nearest_seed` chose for it.

    Parameters
    ----------
    nearest : np.ndarray
        int32 (nx, ny, nz) output of :func:`nearest_seed` (must contain a seed; -1
        entries give NaN).
    sampling : float or sequence of 3 floats
        Voxel spacing (mm).

    Returns
    -------
    np.ndarray
        float64 (nx, ny, nz).
    """
    spacing = check_sampling(sampling)
    shape = nearest.shape
    seed = np.unravel_index(np.maximum(nearest, 0).ravel(), shape)
    own = np.indices(shape).reshape(3, -1)
    d2 = sum(((own[a] - seed[a]) * spacing[a]) ** 2 for a in range(3))
    d = np.sqrt(d2).reshape(shape)
    d[nearest < 0] = np.nan
    return d


def helix_seeds(shape: Sequence[int], turns: float = 3.0) -> np.ndarray:
    """Synthetic seed set: the 8 corner voxels of every cell a helix passes through.

    Parameters
    ----------
    shape : sequence of 3 ints
        Grid shape (nx, ny, nz); the helix winds around the z axis through the grid.
    turns : float
        Number of turns.

    Returns
    -------
    np.ndarray
        bool array of ``shape``.
    """
    nx, ny, nz = (int(n) for n in shape)
    seeds = np.zeros((nx, ny, nz), dtype=bool)
    n = 8 * (nx + ny + nz) * max(1, math.ceil(turns))
    t = np.linspace(0.0, 1.0, n)
    ang = 2 * math.pi * turns * t
    pts = np.stack(
        [
            (0.5 + 0.35 * np.cos(ang)) * (nx - 1),
            (0.5 + 0.35 * np.sin(ang)) * (ny - 1),
            (0.05 + 0.9 * t) * (nz - 1),
        ],
        axis=1,
    )
    cells = np.unique(np.floor(pts).astype(np.int64), axis=0)
    for corner in np.ndindex(2, 2, 2):
        c = cells + np.array(corner)
        c = np.minimum(c, np.array(seeds.shape) - 1)
        seeds[c[:, 0], c[:, 1], c[:, 2]] = True
    return seeds


def benchmark_nearest_seed(
    shape: Sequence[int],
    sampling: float | Sequence[float] = (1.0, 1.0, 1.0),
    repeats: int = 3,
) -> dict[str, Any]:
    """Time :func:`nearest_seed` with OpenCL and with scipy on the same helix seed set.

    Parameters
    ----------
    shape : sequence of 3 ints
        Grid shape (nx, ny, nz).
    sampling : float or sequence of 3 floats
        Voxel spacing (mm).
    repeats : int
        Timed runs per backend; the median is reported. OpenCL runs once untimed first
        (kernel build, buffer allocation).

    Returns
    -------
    dict
        ``shape``, ``n_seeds``, ``device`` (OpenCL device name or ``""``), ``opencl_s``
        and ``scipy_s`` (median wall seconds; ``opencl_s`` is None without OpenCL),
        ``speedup`` (scipy_s / opencl_s, or None) and ``agree`` (the distances to the
        chosen seeds match within 1e-4 relative; None without OpenCL).
    """
    shape = tuple(int(n) for n in shape)
    spacing = check_sampling(sampling)
    repeats = max(1, int(repeats))
    seeds = helix_seeds(shape)

    def timed(backend: str) -> tuple[float, np.ndarray]:
        times, res = [], None
        for _ in range(repeats):
            t0 = time.perf_counter()
            res = nearest_seed(seeds, spacing, backend=backend)
            times.append(time.perf_counter() - t0)
        return float(np.median(times)), res

    result: dict[str, Any] = {
        "shape": shape,
        "n_seeds": int(seeds.sum()),
        "device": opencl_device_name(),
        "opencl_s": None,
        "scipy_s": None,
        "speedup": None,
        "agree": None,
    }
    scipy_s, ref = timed("scipy")
    result["scipy_s"] = scipy_s
    if opencl_available() and max(shape) <= MAX_LINE:
        nearest_seed(seeds, spacing, backend="opencl")  # build + allocate, untimed
        opencl_s, got = timed("opencl")
        result["opencl_s"] = opencl_s
        result["speedup"] = scipy_s / opencl_s if opencl_s > 0 else None
        d_ref, d_got = (seed_distance(r, spacing) for r in (ref, got))
        result["agree"] = bool(np.allclose(d_got, d_ref, rtol=1e-4, atol=1e-4))
    return result
