"""The GLSL lattice inverse stops by the CPU's rule, also at a loose tolerance (issue 33).

At the default tolerance the last Newton step is so small that a stop rule loosened
√-fold (``|dq|² <= tol`` instead of ``tol²``) still lands within float32 noise of the
CPU: a mutation audit passed it. At a loose tolerance (0.3 mm) the rule decides: with
the same rule GPU and CPU stop after the same step (measured on llvmpipe: 3e-5 mm
apart), while the loosened rule stops one step early where the last step lies between
0.3 and 0.55 mm, leaving the rest of that Newton step (0.057 mm on these lattices).
The bound, 0.02 mm, sits between the two and above the GPU noise the reference test
allows (1e-2 mm).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from tests.deform.lattice.test_lattice_inverse_convergence import cases
from tests.warp_gpu import gpu_warp
from voxwarp.deform.lattice.warp import FAR, LatticeWarp

LOOSE = 0.3
BOUND_MM = 0.02


def test_glsl_stops_by_the_cpu_rule_at_a_loose_tolerance(gl_ctx: Any) -> None:
    worst = 0.0
    for grid, box, u in cases(trials=8, points=500, seed=9):
        w = LatticeWarp(grid, box, tolerance=LOOSE, fold_linear=False)
        p = np.asarray(grid(u))
        try:
            q, _ = gpu_warp(gl_ctx, w, p)
        finally:
            w.release()
        cpu = w.apply(p)
        both = (cpu[:, 0] < FAR / 2) & (q[:, 0] < FAR / 2)
        assert both.mean() > 0.99
        worst = max(worst, float(np.abs(q[both] - cpu[both]).max()))
    assert worst < BOUND_MM
