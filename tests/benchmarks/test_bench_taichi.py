"""benchmarks.taichi, the taichi reference of ``python -m benchmarks massspring`` (skipped without
taichi).

It must be the same model as voxwarp.deform.elements.massspring.CpuSpringSolver (float64), stepped
from
the same state with the same drag: in float64 the two agree to round-off (so every term
of deform/elements/spring_model.py is there, with the same constants); in float32, the
benchmark's precision (as the GPU solver's), to a few 1e-5 of the largest displacement
(float32 round-off of the positions, the same as the GPU solver's).
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("taichi")

from benchmarks.taichi import (
    make_minimal_taichi_solver,
    make_taichi_solver,
    taichi_available,
)
from voxwarp.deform.elements.grid import ElementGrid
from voxwarp.deform.elements.massspring import CpuSpringSolver, MassSpring
from voxwarp.deform.elements.spring_model import SpringModel

BOX = ((0.0, 0.0, 0.0), (100.0, 80.0, 60.0))


def _dragged(
    shear: bool, bend: bool, integrator: str
) -> tuple[SpringModel, np.ndarray, np.ndarray]:
    """A 9x8x7 grid with varied materials, three elements dragged: model, pinned, targets."""
    rng = np.random.default_rng(11)
    g = ElementGrid(BOX, shape=(9, 8, 7))
    g.set_material(
        stiffness=rng.uniform(0.2, 0.9, g.shape),
        damping=rng.uniform(0.5, 2.0, g.shape),
        mass=rng.uniform(0.5, 2.0, g.shape),
    )
    g.fix([[0, 3, 3]])
    ms = MassSpring(g, shear=shear, bend=bend, integrator=integrator)  # clamp on
    # no drag may put an element onto a neighbour's position (|d| = 0): that singular
    # state (spring direction undefined) amplifies float32 round-off without bound
    drags = {(4, 4, 3): (0.0, 0.0, 7.0), (2, 5, 5): (3.0, -4.0, 1.0), (7, 1, 2): (-5.0, 0, 0)}
    pinned = g.fixed.copy()
    targets = np.array(ms.model.rest)
    for idx, off in drags.items():
        ms.move(idx, off)
        pinned[idx] = True
        targets[idx] += off
    np.testing.assert_array_equal(ms.held | g.fixed, pinned)
    return ms.model, pinned, targets


def _run_both(
    model: SpringModel, pinned: np.ndarray, targets: np.ndarray, dtype: str, steps: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    ref = CpuSpringSolver(model)
    ti_solver = make_taichi_solver(model, dtype)
    for s in (ref, ti_solver):
        s.set_constraints(pinned, targets)
        s.step(steps)
    rest = np.asarray(model.rest)
    return (
        ref.positions() - rest,
        ti_solver.positions() - rest,
        ref.velocities(),
        ti_solver.velocities(),
    )


def test_taichi_available() -> None:
    assert taichi_available()


@pytest.mark.parametrize(
    ("shear", "bend", "integrator"), [(False, False, "explicit"), (True, True, "semi-implicit")]
)
def test_taichi_is_the_cpu_model(shear: bool, bend: bool, integrator: str) -> None:
    model, pinned, targets = _dragged(shear, bend, integrator)
    # float64: the same arithmetic up to summation order (measured <= 1e-14 relative)
    d_ref, d_ti, v_ref, v_ti = _run_both(model, pinned, targets, "f64", 200)
    scale = np.abs(d_ref).max()
    assert scale > 5.0  # the drags moved the grid (largest drag 7 mm)
    assert np.abs(d_ti - d_ref).max() <= 1e-12 * scale
    assert np.abs(v_ti - v_ref).max() <= 1e-9 * max(np.abs(v_ref).max(), 1.0)
    # float32, as benchmarked: positions (up to 100 mm, ulp 7.6e-6 mm) are rounded every
    # step. Measured max |d_f32 - d_ref| / max |d_ref| after 200 steps: 2.8e-5 explicit
    # (dt 0.21 ms), 4.5e-6 semi-implicit; the GPU solver's float32 error on this model is
    # the same to all printed digits (same arithmetic, same order of the springs)
    d_ref, d_ti, _, _ = _run_both(model, pinned, targets, "f32", 200)
    assert np.abs(d_ti - d_ref).max() <= 1e-4 * scale


def test_pinned_and_fixed_elements_sit_at_their_targets() -> None:
    model, pinned, targets = _dragged(True, False, "explicit")
    s = make_taichi_solver(model)
    s.set_constraints(pinned, targets)
    np.testing.assert_array_equal(s.positions()[pinned], targets[pinned].astype(np.float32))
    s.step(20)
    np.testing.assert_array_equal(s.positions()[pinned], targets[pinned].astype(np.float32))
    np.testing.assert_array_equal(s.velocities()[pinned], 0.0)
    assert s.max_speed() > 0


def test_bad_input() -> None:
    model, _, _ = _dragged(False, False, "explicit")
    with pytest.raises(ValueError, match="dtype"):
        make_taichi_solver(model, "f16")
    s = make_taichi_solver(model)
    with pytest.raises(ValueError, match="positions must have shape"):
        s.set_state(np.zeros((2, 2, 2, 3)), np.zeros((2, 2, 2, 3)))
    with pytest.raises(ValueError, match="pinned must have shape"):
        s.set_constraints(np.zeros((2, 2)), np.zeros((*model.shape, 3)))
    with pytest.raises(ValueError, match=">= 0"):
        s.step(-1)


def test_minimal_kernel_is_the_uniform_unpinned_model() -> None:
    # the minimal kernel (issue 19's floor for the GPU step) must still do the whole
    # step of a grid with one material and nothing pinned: same trajectory as numpy
    g = ElementGrid(BOX, shape=(9, 8, 7))  # uniform default materials
    model = MassSpring(g, integrator="explicit").model  # structural springs, clamp on
    rng = np.random.default_rng(5)
    x0 = np.asarray(model.rest) + rng.normal(0.0, 2.0, (*model.shape, 3))
    v0 = rng.normal(0.0, 50.0, (*model.shape, 3))
    ref = CpuSpringSolver(model)
    mini = make_minimal_taichi_solver(model)
    for s in (ref, mini):
        s.set_state(x0, v0)
        s.step(100)
    d_ref = ref.positions() - x0
    scale = np.abs(d_ref).max()
    assert scale > 1.0  # the springs moved the elements
    # float32 positions: the same tolerance as the full taichi solver's f32 test
    assert np.abs((mini.positions() - x0) - d_ref).max() <= 1e-4 * scale
