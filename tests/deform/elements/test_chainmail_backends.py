"""ChainMail through its public API on the GPU backend (GL): the same guarantees as
the CPU -- every link within its limits after every move, fixed elements unmoved,
blocked drags limited -- and the same result as the CPU for feasible drags.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from voxwarp.deform import ChainMail
from voxwarp.deform.elements.grid import ElementGrid

pytestmark = pytest.mark.gl

#: float32 positions on the GPU (coordinates up to ~100 mm, 16 ulp ~1.2e-4 mm; the
#: solver's feasibility check allows twice its move tolerance): links checked to this
#: many mm; a blocked drag would leave millimetres
TOL = 5e-4


def _grid(shape: tuple[int, int, int], spacing: float = 10.0) -> ElementGrid:
    hi = tuple(spacing * (n - 1) for n in shape)
    return ElementGrid(((0.0, 0.0, 0.0), hi), shape=shape, anchor="corners")


def test_gpu_feasible_drags_match_the_cpu(gl_ctx: Any) -> None:
    results = {}
    for backend in ("cpu", "gpu"):
        cm = ChainMail(_grid((7, 6, 5)), backend=backend, ctx=gl_ctx if backend == "gpu" else None)
        try:
            for idx, off in (((3, 3, 2), (3.0, -1.5, 1.0)), ((4, 2, 3), (-2.0, 3.0, 0.0))):
                stats = cm.move(idx, off)
                assert stats.fraction == 1.0
                assert cm.violation() <= TOL
            results[backend] = cm.positions()
        finally:
            cm.close()
    np.testing.assert_allclose(results["gpu"], results["cpu"], atol=1e-4)


def test_gpu_blocked_drag_is_limited_and_keeps_every_link(gl_ctx: Any) -> None:
    g = _grid((8, 3, 3))
    g.fix((2, 1, 1))
    cpu = ChainMail(g, variant="enhanced")
    gpu = ChainMail(_grid((8, 3, 3)), backend="gpu", ctx=gl_ctx)
    gpu.fix((2, 1, 1))
    try:
        a = cpu.move((3, 1, 1), (30.0, 0.0, 0.0))
        b = gpu.move((3, 1, 1), (30.0, 0.0, 0.0))
        assert b.limited
        assert b.fraction == pytest.approx(a.fraction, abs=2.0**-12)
        assert gpu.violation() <= TOL
        x = gpu.positions()
        np.testing.assert_allclose(x[2, 1, 1], g.rest_positions[2, 1, 1], atol=1e-5)
        assert x[3, 1, 1, 0] - x[2, 1, 1, 0] == pytest.approx(12.5, abs=30.0 * 2.0**-12)
    finally:
        cpu.close()
        gpu.close()


def test_gpu_random_drags_with_fixed_elements_keep_every_link(gl_ctx: Any) -> None:
    rng = np.random.default_rng(3)
    g = _grid((6, 6, 6))
    g.fix(np.argwhere(rng.random(g.shape) < 0.05))
    cm = ChainMail(g, backend="gpu", ctx=gl_ctx)
    rest = g.rest_positions
    try:
        for _ in range(25):
            idx = tuple(int(v) for v in rng.integers(0, 6, 3))
            cm.move(idx, rng.uniform(-25.0, 25.0, 3))
            assert cm.violation() <= TOL
            x = cm.positions()
            np.testing.assert_allclose(x[g.fixed], rest[g.fixed], atol=1e-5)
            if rng.random() < 0.3:
                cm.release()
    finally:
        cm.close()


def test_gpu_warp_follows_a_rebuilt_solver(gl_ctx: Any) -> None:
    """A cut rebuilds the GPU solver: the warp must sample the new solver's texture."""
    cm = ChainMail(_grid((6, 4, 4)), backend="gpu", ctx=gl_ctx)
    try:
        warp = cm.warp()
        first = warp.textures(gl_ctx)["displacement"]
        cm.cut((25.0, 0.0, 0.0), (1.0, 0.0, 0.0))
        assert warp.textures(gl_ctx)["displacement"] is cm._solver.displacement_texture()
        assert warp.textures(gl_ctx)["displacement"] is not first
        cm.move((4, 2, 2), (3.0, 0.0, 0.0))
        np.testing.assert_allclose(cm.displacements()[4, 2, 2], (3.0, 0.0, 0.0), atol=1e-5)
    finally:
        cm.close()
