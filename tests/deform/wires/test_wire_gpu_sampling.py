"""The wire warp's GLSL (shaders/warp_wire.glsl) at single points against its CPU
reference (voxwarp.deform.wires.warp.WireFieldWarp.apply), for both field layouts.

Rendered images compare the two only through a few pixels at a marker's edge, so a
GPU sampler that takes the nearest voxel's t instead of interpolating it (packed layout)
passed the image tests. Here ``warp(p)`` is read back for thousands of points inside
the swept region and compared with the CPU's ``A(t) p + b(t)`` at its interpolated t.

Tolerance: the CPU interpolates t in float64 and reads the lookup table exactly; the GPU
computes t in float32 and reads the table through the texture unit, whose filter weights
have 8 bits on llvmpipe (t off by up to 1/512 of a table entry), which moves points by
orders of magnitude less than TOL_MM on this wire. Taking the nearest voxel's t instead
of interpolating it moves most swept points by more than TOL_MM (a half turn of twist
along the wire turns a point 4 mm off the axis by a visible fraction of a voxel).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from tests.deform.wires.test_wires import AXIS_Y, AXIS_Z, axis_points, build, cylinder, wire
from tests.warp_gpu import gpu_warp
from voxwarp.deform.wires.constants import FAR

#: max |GPU - CPU| of warp(p), mm (see the module docstring)
TOL_MM = 2e-3


@pytest.mark.parametrize("layout", ["packed", "float", "paper"])
def test_gpu_wire_warp_equals_the_cpu_sampler_at_points(gl_ctx: Any, layout: str) -> None:
    vol = cylinder()
    ws = [wire(modified=axis_points(dy=3.0, dz=-3.0), twist=[(0, 0), (1, math.pi)])]
    w = build(vol, ws, layout=layout, field_scale=2)
    try:
        rng = np.random.default_rng(31)
        # around the modified wire (3 mm along +y, -3 mm along z) and the original place
        lo = np.array([2.0, AXIS_Y - 8.0, AXIS_Z - 12.0])
        hi = np.array([62.0, AXIS_Y + 12.0, AXIS_Z + 8.0])
        p = rng.uniform(lo, hi, (4096, 3))
        state, _, _ = w._lookup(p)
        q_gpu, _ = gpu_warp(gl_ctx, w, p)
    finally:
        w.release()
    q_cpu = w.apply(p)
    swept = state == 2
    assert swept.sum() > 1000  # the sample really tests the swept region
    assert (state == 1).sum() > 50  # and vacated points
    # identity / vacated / swept agree everywhere (the nearest voxel decides)
    far_gpu, far_cpu = q_gpu[:, 0] >= FAR / 2, q_cpu[:, 0] >= FAR / 2
    np.testing.assert_array_equal(far_gpu, far_cpu)
    np.testing.assert_allclose(q_gpu[state == 0], p[state == 0], atol=1e-4)
    err = np.linalg.norm(q_gpu[swept] - q_cpu[swept], axis=1)
    assert err.max() <= TOL_MM, f"max |GPU - CPU| = {err.max():.2e} mm > {TOL_MM} mm"
    # the warp does move these points: a wrong t would show
    assert np.median(np.linalg.norm(q_cpu[swept] - p[swept], axis=1)) > 1.0
