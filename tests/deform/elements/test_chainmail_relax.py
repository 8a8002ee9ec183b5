"""ChainMail relaxation: the GPU (GLSL) half-sweeps against the CPU (numba) ones, and
local relaxation against full relaxation.

Oracles: an independent numpy implementation of the rule over the *whole* grid (red,
then black half-sweeps of constrained Laplacian smoothing, float64), which both
backends' box-limited sweeps must reproduce (CPU to 1e-9 mm, GPU float32 to 1e-4 mm);
:meth:`ChainMailModel.violation` after every step (the links' min/max/shear limits);
held and fixed elements bit for bit where they were; local relaxation against full
relaxation where the elements outside the drag are at the rule's fixed point (at rest,
or relaxed to convergence), and a measured difference where they are not.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from tests.deform.elements.chainmail_oracle import link_bounds, link_ends
from voxwarp.deform import ChainMail, ChainMailError
from voxwarp.deform.elements.chainmail_model import ChainMailModel
from voxwarp.deform.elements.grid import ElementGrid

#: float32 GPU positions against the float64 CPU ones, and the GPU's link violations (mm)
GPU_TOL = 1e-4
#: the CPU's link violations (mm)
CPU_TOL = 1e-6


def _grid(n: int = 12, spacing: float = 10.0, anchor: str = "corners") -> ElementGrid:
    """An n³ grid, 8 corners (or the shell) fixed, no region of influence."""
    hi = (spacing * (n - 1),) * 3
    return ElementGrid(((0.0, 0.0, 0.0), hi), shape=n, anchor=anchor, fix_outside=None)


def _tight(cm: ChainMail, seed: int = 3) -> None:
    """Random, anisotropic limits with little shear: relaxation runs into them."""
    rng = np.random.default_rng(seed)
    shape = (*cm.grid.shape, 3)
    s = cm.grid.spacing
    cm.set_limits(
        s * rng.uniform(0.7, 0.95, shape),
        s * rng.uniform(1.05, 1.3, shape),
        s * rng.uniform(0.05, 0.2, shape),
    )


# ---------------------------------------------------------------------- oracle
def _neighbour_terms(
    model: ChainMailModel, x: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per element: interval ``(lo, hi)`` its links allow, the sum of its linked
    neighbours' displacements and their count."""
    su = np.zeros(x.shape)
    cnt = np.zeros(x.shape[:3])
    u = x - model.rest
    for axis in range(3):
        linked = model.link_limits(axis)[3]
        a_t, b_t = link_ends(axis)
        on = linked[..., None]
        su[b_t] += np.where(on, u[a_t], 0.0)
        su[a_t] += np.where(on, u[b_t], 0.0)
        cnt[b_t] += linked
        cnt[a_t] += linked
    return (*link_bounds(model, x), su, cnt)


def _oracle(
    model: ChainMailModel, x0: np.ndarray, pinned: np.ndarray, steps: int, clamp: bool = True
) -> np.ndarray:
    """``steps`` red-black steps of the rule over the whole grid (numpy, float64);
    ``clamp=False`` drops the constraints (to show that they matter)."""
    x = np.array(x0, np.float64)
    i, j, k = np.indices(model.shape)
    for _ in range(steps):
        for colour in (0, 1):
            lo, hi, su, cnt = _neighbour_terms(model, x)
            target = model.rest + su / np.maximum(cnt, 1)[..., None]
            new = np.minimum(np.maximum(target, lo), hi) if clamp else target
            ok = (lo <= hi) | (not clamp)
            mine = ((i + j + k) % 2 == colour) & ~pinned & (cnt > 0)
            x = np.where(mine[..., None] & ok, new, x)
    return x


def _pinned(cm: ChainMail) -> np.ndarray:
    return cm.model.fixed | cm.held


# ---------------------------------------------------------------------- fixtures
@pytest.fixture
def models(gl_ctx: Any) -> Any:
    """Factory of ChainMail models on either backend, closed at the end."""
    made: list[ChainMail] = []

    def make(grid: ElementGrid, backend: str = "cpu", **kw: Any) -> ChainMail:
        ctx = gl_ctx if backend == "gpu" else None
        made.append(ChainMail(grid, backend=backend, ctx=ctx, **kw))
        return made[-1]

    yield make
    for cm in made:
        cm.close()


# ---------------------------------------------------------------------- full relaxation
def test_cpu_box_sweeps_equal_the_whole_grid_rule() -> None:
    """Half-sweeps over the growing box of displaced elements give the whole grid's
    result (the box grows by one element per half-sweep: growing it once per step, as
    before, left black elements two layers out unrelaxed, 0.009 mm off here)."""
    cm = ChainMail(_grid(16))
    cm.move((8, 8, 8), (12.0, 5.0, 0.0))
    x0, pinned = cm.positions(), _pinned(cm)
    for steps in (1, 2, 3):
        cm.relax(1)
        expected = _oracle(cm.model, x0, pinned, steps)
        np.testing.assert_allclose(cm.positions(), expected, rtol=0, atol=1e-9)


@pytest.mark.parametrize("scene", ["dragged", "cut"])
def test_gpu_relaxation_agrees_with_the_cpu_and_keeps_the_limits(models: Any, scene: str) -> None:
    grid = _grid(12)
    cms = [models(grid, backend) for backend in ("cpu", "gpu")]
    for cm in cms:
        _tight(cm)
        if scene == "cut":  # every x link between i = 5 and 6
            assert cm.cut((55.0, 0.0, 0.0), (1.0, 0.0, 0.0)) == 144
        assert cm.move((7, 6, 5), (5.0, -3.0, 4.0)).fraction == 1.0
        assert cm.move((8, 3, 8), (2.0, 3.0, -2.0)).fraction == 1.0
    cpu, gpu = cms
    gpu.set_state(cpu.positions())  # the relaxations start from the same state
    np.testing.assert_allclose(gpu.positions(), cpu.positions(), rtol=0, atol=1e-5)
    pinned = _pinned(cpu)
    assert pinned.sum() == 10  # 8 corners and 2 held
    before = [cm.positions() for cm in cms]
    # the limits bind: the unconstrained rule would break links by millimetres
    free = _oracle(cpu.model, before[0], pinned, 1, clamp=False)
    assert cpu.model.violation(free) > 0.5
    for step in range(1, 5):
        for cm in cms:
            cm.relax(1)
        x_cpu, x_gpu = cpu.positions(), gpu.positions()
        np.testing.assert_allclose(x_gpu, x_cpu, rtol=0, atol=GPU_TOL)
        np.testing.assert_allclose(
            x_cpu, _oracle(cpu.model, before[0], pinned, step), rtol=0, atol=1e-9
        )
        assert cpu.violation() <= CPU_TOL
        assert gpu.violation() <= GPU_TOL
        for x, x0 in zip((x_cpu, x_gpu), before, strict=True):
            np.testing.assert_array_equal(x[pinned], x0[pinned])  # bit for bit
    assert np.abs(x_cpu - before[0]).max() > 1.0  # it did relax
    if scene == "cut":  # nothing crosses the cut: the near side stays at rest
        for x in (x_cpu, x_gpu):
            np.testing.assert_array_equal(x[:6], grid.rest_positions[:6])


@pytest.mark.parametrize("shape", [(20, 18, 12), (9, 5, 2)], ids=["tiled-atlas", "slab"])
def test_gpu_relaxation_on_other_grid_shapes(models: Any, shape: tuple[int, int, int]) -> None:
    """Non-cubic grids: an atlas of several rows of z-slices, a two-slice slab."""
    hi = tuple(7.0 * max(n - 1, 1) for n in shape)
    grid = ElementGrid(((0.0, 0.0, 0.0), hi), shape=shape, anchor="corners", fix_outside=None)
    cpu, gpu = models(grid, "cpu"), models(grid, "gpu")
    assert gpu._solver.tiles[1] > 1 or shape[2] == 2  # rows of z-slices
    e = (shape[0] // 2, shape[1] // 2, shape[2] // 2)
    for cm in (cpu, gpu):
        assert cm.move(e, (4.0, -3.0, 2.0)).fraction == 1.0
    gpu.set_state(cpu.positions())
    x0 = cpu.positions()
    for cm in (cpu, gpu):
        cm.relax(3)
    np.testing.assert_allclose(gpu.positions(), cpu.positions(), rtol=0, atol=GPU_TOL)
    np.testing.assert_allclose(
        cpu.positions(), _oracle(cpu.model, x0, _pinned(cpu), 3), rtol=0, atol=1e-9
    )
    assert np.abs(cpu.positions() - x0).max() > 0.3
    assert gpu.violation() <= GPU_TOL


def test_gpu_relaxation_reads_nothing_back_and_keeps_both_buffers(
    models: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    """No read-back during relax(); a drag after it (whose passes write only their box
    into the other ping-pong buffer) still agrees with the CPU."""
    grid = _grid(10)
    cpu, gpu = models(grid, "cpu"), models(grid, "gpu")
    for cm in (cpu, gpu):
        cm.move((4, 4, 4), (8.0, 3.0, -2.0))
    solver = gpu._solver
    revision = solver.revision
    for t in (*solver._pos, *solver._links, solver._target, solver._rest):
        monkeypatch.setattr(t, "read", _no_readback)
    gpu.relax(3)
    monkeypatch.undo()
    assert solver.revision > revision  # the displacement texture follows
    cpu.relax(3)
    np.testing.assert_allclose(gpu.positions(), cpu.positions(), rtol=0, atol=GPU_TOL)
    for cm in (cpu, gpu):
        cm.release()
        cm.move((6, 5, 3), (-5.0, 4.0, 3.0))
        cm.relax(2)
    np.testing.assert_allclose(gpu.positions(), cpu.positions(), rtol=0, atol=GPU_TOL)
    assert gpu.violation() <= GPU_TOL
    w = gpu.warp()  # its texture holds the relaxed displacements
    assert w.gpu_owned


def _no_readback(*args: Any, **kwargs: Any) -> bytes:
    raise AssertionError("the GPU relaxation read state back")


# ---------------------------------------------------------------------- local relaxation
@pytest.mark.parametrize("backend", ["cpu", "gpu"])
def test_local_relaxation_of_a_drag_from_rest_equals_the_whole_grid(
    models: Any, backend: str
) -> None:
    """From rest every element the drag did not move is at the rule's fixed point, so
    relaxing around the drag gives the whole grid's result; elements farther than
    two layers per step from the moved ones stay at rest, bit for bit."""
    grid = _grid(16)
    cm = models(grid, backend, relax_local=True)
    cm.move((4, 5, 4), (6.0, 0.0, 3.0))
    x0, pinned = cm.positions(), _pinned(cm)
    moved = np.argwhere(np.any(x0 != grid.rest_positions, axis=-1))
    cm.relax(2)
    x = cm.positions()
    tol = 1e-9 if backend == "cpu" else GPU_TOL
    np.testing.assert_allclose(x, _oracle(cm.model, x0, pinned, 2), rtol=0, atol=tol)
    hi = moved.max(axis=0) + 1 + 4  # the box of the moved ones grown by 2 x 2 steps
    np.testing.assert_array_equal(x[hi[0] :], grid.rest_positions[hi[0] :])
    assert hi[0] < 16


@pytest.mark.parametrize("backend", ["cpu", "gpu"])
def test_local_equals_full_relaxation_after_a_converged_one(models: Any, backend: str) -> None:
    """A drag, relaxed to convergence (a fixed point of the rule), then a second drag:
    relaxing around the second drag only equals relaxing everything (to 1e-4 mm), and
    leaves the first drag's region exactly as it was."""
    grid = _grid(12, anchor="shell")  # converges in a few hundred steps
    local, full = models(grid, backend), models(grid, backend)
    for cm in (local, full):
        cm.move((3, 3, 3), (6.0, 4.0, 0.0))
        _relax_to_convergence(cm)
        cm.move((9, 9, 9), (-3.0, 0.0, 2.0))  # (3, 3, 3) held: a release would move it
    before = local.positions()
    local.relax(2, local=True)
    full.relax(2)
    np.testing.assert_allclose(local.positions(), full.positions(), rtol=0, atol=GPU_TOL)
    np.testing.assert_array_equal(local.positions()[:3, :3, :3], before[:3, :3, :3])
    assert np.abs(full.positions() - before).max() > 0.2  # it did relax


def _relax_to_convergence(cm: ChainMail, tol: float = 1e-8) -> None:
    x = cm.positions()
    for _ in range(200):
        cm.relax(10)
        y = cm.positions()
        if np.abs(y - x).max() < tol:
            return
        x = y
    raise AssertionError("the relaxation did not converge")  # pragma: no cover


def test_local_relaxation_differs_where_the_rest_is_not_at_a_fixed_point() -> None:
    """After one unconverged relaxation step the first drag's region is still off the
    fixed point: full relaxation goes on smoothing it, local relaxation leaves it."""
    grid = _grid(12)
    local, full = ChainMail(grid), ChainMail(grid)
    for cm in (local, full):
        cm.move((3, 3, 3), (8.0, 4.0, 0.0))
        cm.relax(1)
        cm.move((9, 9, 9), (-5.0, 0.0, 4.0))
    before = local.positions()
    local.relax(2, local=True)
    full.relax(2)
    np.testing.assert_array_equal(local.positions()[:4, :4, :4], before[:4, :4, :4])
    assert np.abs(full.positions() - local.positions())[:4, :4, :4].max() > 0.1
    assert local.violation() <= CPU_TOL
    assert full.smoothness_energy() < local.smoothness_energy()


def test_relax_local_setting_is_used_after_moves_and_saved() -> None:
    grid = _grid(10)
    a = ChainMail(grid, relax_steps=2, relax_local=True)
    b = ChainMail(grid)
    for cm in (a, b):
        cm.move((3, 3, 3), (6.0, 0.0, 0.0))
    b.relax(2)
    for cm in (a, b):
        cm.move((7, 6, 6), (0.0, 5.0, 0.0))
    b.relax(2, local=True)
    np.testing.assert_array_equal(a.positions(), b.positions())
    d = a.to_dict()
    assert d["relax_local"] is True
    assert "relax_local" not in b.to_dict()  # older readers: the key only when set
    assert ChainMail.from_dict(d).relax_local
    with pytest.raises(ChainMailError, match="relax_local must be true or false"):
        ChainMail(grid, relax_local="yes")  # type: ignore[arg-type]
