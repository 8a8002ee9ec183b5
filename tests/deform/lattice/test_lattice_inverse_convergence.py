"""The lattice warp's inverse iterated to convergence, on random non-folding lattices.

The default ``LatticeWarp`` applies Newton steps ``du = J(u)^-1 (grid(u) - p)`` until one
moves the original point by at most ``tolerance`` mm (or ``max_iterations`` steps). Newton
converges quadratically near a non-singular root: the last step is, to first order, the
error of the point before it, and the error after it is of the order of its square. So a
point that stopped by the rule is within ``tolerance`` of the true one (the bound these
tests assert, not tuned to measurements: those lie far below it, see docs/benchmarks.md),
and its residual ``|grid(u') - p|`` within ``tolerance`` times the lattice's largest
stretch ``|J diag(1 / size)|``. Oracles: the true points (``p = grid(u)`` for known u),
the CPU reference (float64) against the GLSL (float32); the random lattices are the lab's
(benchmarks.lattice_inverse), proven not to fold by a Bernstein certificate
(tests/benchmarks/test_lattice_inverse_study.py).
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

from benchmarks.lattice_inverse import study_cases
from tests.warp_gpu import gpu_warp
from voxwarp.deform.lattice.trilinear import TrilinearGrid
from voxwarp.deform.lattice.warp import (
    DEFAULT_MAX_ITERATIONS,
    DEFAULT_TOLERANCE,
    FAR,
    LatticeWarp,
    lattice_eval,
)
from voxwarp.deform.warp import WarpError, warp_from_dict

BOX = (np.array([-10.0, 0.0, 5.0]), np.array([70.0, 60.0, 85.0]))


def cases(trials: int = 12, points: int = 1500, seed: int = 5) -> list[tuple]:
    """Random proven non-folding lattices (1..4 cells per axis) with unit-cube points."""
    return study_cases(trials, points, seed)


def stretch(grid: TrilinearGrid, box: tuple, u: np.ndarray) -> float:
    """The largest ``|J diag(1 / size)|_2`` at ``u`` (deformed mm per original mm)."""
    _, j = lattice_eval(np.asarray(grid.nodes, dtype=np.float64), u)
    assert j is not None
    return float(np.max(np.linalg.norm(j / (box[1] - box[0])[None, None, :], ord=2, axis=(1, 2))))


# ---------------------------------------------------------------------- CPU reference
@pytest.mark.parametrize("tolerance", [1e-2, DEFAULT_TOLERANCE, 1e-4])
def test_converged_points_lie_within_the_tolerance(tolerance: float) -> None:
    for grid, box, u in cases():
        w = LatticeWarp(grid, box, tolerance=tolerance, fold_linear=False)
        p = np.asarray(grid(u))
        uc, inside, steps, converged = w.solve(p)
        assert converged.all(), "non-folding lattices converge before the cap"
        assert steps.max() <= DEFAULT_MAX_ITERATIONS
        assert steps.min() >= 1
        err = np.linalg.norm((uc - u) * w.size, axis=1)
        np.testing.assert_array_less(err, tolerance)
        res = np.linalg.norm(np.asarray(grid(np.clip(uc, 0, 1))) - p, axis=1)
        np.testing.assert_array_less(res, stretch(grid, box, u) * tolerance)
        # apply() returns the original point itself (inside points stay inside)
        q = w.apply(p)
        assert inside.all()
        np.testing.assert_array_less(np.linalg.norm(q - (box[0] + u * w.size), axis=1), tolerance)


def test_the_former_fixed_two_steps_miss_that_bound() -> None:
    # the problem the iteration solves: on the same lattices two fixed steps leave more
    # than the default tolerance at some points (kinks of the lattice, poor seeds)
    worst = 0.0
    for grid, box, u in cases():
        w = LatticeWarp(grid, box, iterations=2, fold_linear=False)
        uc, _ = w.lattice_coordinates(np.asarray(grid(u)))
        worst = max(worst, float(np.linalg.norm((uc - u) * w.size, axis=1).max()))
    assert worst > DEFAULT_TOLERANCE


def test_the_convergence_flag_is_honest() -> None:
    # capped at one step, many points stop before the rule holds: only those the rule
    # stopped claim convergence, and they keep the bound; the others report a residual
    capped_any = False
    for grid, box, u in cases(trials=8):
        w = LatticeWarp(grid, box, max_iterations=1, fold_linear=False)
        uc, _, steps, converged = w.solve(np.asarray(grid(u)))
        assert steps.max() == 1
        err = np.linalg.norm((uc - u) * w.size, axis=1)
        np.testing.assert_array_less(err[converged], DEFAULT_TOLERANCE)
        capped_any |= bool(np.any(~converged))
    assert capped_any


def test_a_singular_jacobian_is_reported_not_converged() -> None:
    # the middle cell collapsed onto a plane: J is singular in it, du = 0 there and the
    # point stops unconverged; its inverse is not unique (the whole cell maps onto the
    # plane), so only the residual bounds anything, and that is what solve() reports
    nodes = np.array(TrilinearGrid.from_box(*BOX, cells=(3, 1, 1)).nodes)
    nodes[2, :, :, 0] = nodes[1, :, :, 0]
    grid = TrilinearGrid(nodes)
    w = LatticeWarp(grid, BOX, fold_linear=False)
    u = np.random.default_rng(0).uniform(0.0, 1.0, (2000, 3))
    p = np.asarray(grid(u))
    uc, _, steps, converged = w.solve(p)
    assert steps.max() <= DEFAULT_MAX_ITERATIONS
    res = np.linalg.norm(np.asarray(grid(np.clip(uc, 0, 1))) - p, axis=1)
    err = np.linalg.norm((uc - u) * w.size, axis=1)
    collapsed = (u[:, 0] > 1 / 3) & (u[:, 0] < 2 / 3)
    assert not converged[collapsed].any()
    assert err[collapsed].max() > 1.0  # another point of the plane's preimage
    # the rule's bound holds wherever it claims convergence
    bound = stretch(grid, BOX, uc[converged]) * DEFAULT_TOLERANCE
    np.testing.assert_array_less(res[converged], bound)
    np.testing.assert_array_less(err[converged], DEFAULT_TOLERANCE)


# ---------------------------------------------------------------------- options
def test_tolerance_and_cap_round_trip_through_the_scene_dict() -> None:
    grid, box, u = cases(trials=2)[1]
    w = LatticeWarp(grid, box, tolerance=2e-4, max_iterations=5)
    d = json.loads(json.dumps(w.to_dict()))
    assert (d["tolerance"], d["max_iterations"]) == (2e-4, 5)
    assert "iterations" not in d
    w2 = warp_from_dict(d)
    assert isinstance(w2, LatticeWarp)
    assert (w2.tolerance, w2.max_iterations, w2.signature()) == (2e-4, 5, w.signature())
    p = np.asarray(grid(u))
    np.testing.assert_array_equal(w2.apply(p), w.apply(p))
    fixed = json.loads(json.dumps(LatticeWarp(grid, box, iterations=2).to_dict()))
    assert fixed["iterations"] == 2
    assert "tolerance" not in fixed
    assert warp_from_dict(fixed).steps == 2


@pytest.mark.parametrize(
    ("kw", "pattern"),
    [
        ({"tolerance": 0.0}, "tolerance must be a finite number of mm > 0"),
        ({"tolerance": -1e-3}, "tolerance must be a finite number of mm > 0"),
        ({"tolerance": float("nan")}, "tolerance must be a finite number of mm > 0"),
        ({"tolerance": "1e-3"}, "tolerance must be a number of mm > 0"),
        ({"tolerance": True}, "tolerance must be a number of mm > 0"),
        ({"max_iterations": 0}, r"max_iterations must be 1\.\.8"),
        ({"max_iterations": 9}, r"max_iterations must be 1\.\.8"),
        ({"max_iterations": 2.5}, "max_iterations must be an integer"),
        ({"iterations": 2, "tolerance": 1e-3}, "do not apply to 2 fixed Newton steps"),
        ({"inverse": "baked", "max_iterations": 3}, "do not apply to the seed alone"),
    ],
)
def test_bad_convergence_options_raise_one_line_errors(kw: dict, pattern: str) -> None:
    grid, box, _ = cases(trials=1)[0]
    with pytest.raises(WarpError, match=pattern) as info:
        LatticeWarp(grid, box, **kw)
    assert "\n" not in str(info.value)
    d = {"type": "lattice", "grid": grid.to_dict(), "box": [box[0].tolist(), box[1].tolist()]}
    with pytest.raises(WarpError, match=pattern):
        warp_from_dict({**d, **kw})


# ---------------------------------------------------------------------- GLSL
@pytest.mark.parametrize("tolerance", [DEFAULT_TOLERANCE, 1e-4])
def test_glsl_iteration_matches_the_cpu_reference(gl_ctx: Any, tolerance: float) -> None:
    llvmpipe = "llvmpipe" in gl_ctx.info.get("GL_RENDERER", "")
    for grid, box, u in cases(trials=8, points=500, seed=9):
        w = LatticeWarp(grid, box, tolerance=tolerance, fold_linear=False)
        size = box[1] - box[0]
        p = np.vstack([np.asarray(grid(u)), np.random.default_rng(1).uniform(*box, (100, 3))])
        try:
            q, jac = gpu_warp(gl_ctx, w, p)
        finally:
            w.release()
        cpu = w.apply(p)
        far_cpu, far_gpu = cpu[:, 0] >= FAR / 2, q[:, 0] >= FAR / 2
        assert np.sum(far_cpu != far_gpu) <= 2  # float32 noise at the lattice's surface
        both = ~far_cpu & ~far_gpu
        # float32 against float64 (the same rule, maybe one step apart at its threshold)
        np.testing.assert_allclose(q[both], cpu[both], atol=2e-4 if llvmpipe else 1e-2)
        # the Jacobian jumps across cell faces (a third of the points lie on them: CPU
        # and GPU may pick either side), so compare it off the faces
        g = u * (np.asarray(grid.nodes).shape[0] - 1)
        off = np.r_[np.all(np.abs(g - np.round(g)) > 1e-3, axis=1), np.ones(100, bool)]
        sel = both & off
        np.testing.assert_allclose(jac[sel], w.jacobian(p)[sel], atol=1e-4 if llvmpipe else 1e-2)
        # the GPU's original points: the tolerance plus float32 rounding of the box
        inner = both[: len(u)]
        true = box[0] + u[inner] * size
        bound = tolerance + 1e-6 * float(np.max(np.abs(box)))
        if llvmpipe:
            np.testing.assert_array_less(np.linalg.norm(q[: len(u)][inner] - true, axis=1), bound)
