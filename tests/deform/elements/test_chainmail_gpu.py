"""GpuChainMailSolver (deform/elements/chainmail_gpu.py): constraints, locality, displacement
texture.

The oracle is the small numpy clamp iteration below (float64), written from
``deform/elements/chainmail_model.py``: per coordinate, a lowering phase then a raising phase,
each to a fixed point (their results are unique, whatever the order of updates, so
the GPU's Jacobi passes must match it to float32 round-off).
"""

from __future__ import annotations

from typing import Any

import moderngl
import numpy as np
import pytest

from tests.deform.elements.chainmail_oracle import link_bounds
from voxwarp.deform.elements.chainmail_model import ChainMailModel

chainmail_gpu = pytest.importorskip("voxwarp.deform.elements.chainmail_gpu")
GpuChainMailSolver = chainmail_gpu.GpuChainMailSolver

SHAPE = (7, 6, 5)
SPACING = np.array([1.0, 1.5, 2.0])
ORIGIN = np.array([10.0, -5.0, 3.0])
#: float32 positions against the float64 oracle / the constraints (mm)
TOL = 1e-4


def _model(
    shape: tuple[int, int, int] = SHAPE,
    *,
    slack: float = 0.2,
    shear: float = 0.2,
    fixed: np.ndarray | None = None,
    links: np.ndarray | None = None,
    rng: np.random.Generator | None = None,
) -> ChainMailModel:
    """Grid with ``min = (1 - slack) s``, ``max = (1 + slack) s``, shear ``shear s``;
    with ``rng``: heterogeneous and anisotropic limits instead."""
    idx = np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), axis=-1)
    spacing = SPACING.copy()
    if rng is None:
        mn = (1.0 - slack) * spacing
        mx = (1.0 + slack) * spacing
        sh = shear * spacing
    else:
        mn = rng.uniform(0.6, 0.95, (*shape, 3)) * spacing
        mx = rng.uniform(1.05, 1.5, (*shape, 3)) * spacing
        sh = rng.uniform(0.05, 0.4, (*shape, 3)) * spacing
    return ChainMailModel(
        rest=idx * spacing + ORIGIN,
        spacing=spacing,
        min_dist=mn,
        max_dist=mx,
        max_shear=sh,
        links=np.ones((*shape, 3), bool) if links is None else links,
        fixed=np.zeros(shape, bool) if fixed is None else fixed,
    )


# ---------------------------------------------------------------------- oracle
def _oracle(
    model: ChainMailModel, x0: np.ndarray, held: np.ndarray, targets: np.ndarray
) -> np.ndarray:
    """Hold, then clamp: a lowering phase (x > hi -> hi) to its fixed point, then a
    raising phase (x < lo -> lo); held and fixed elements never move."""
    x = np.array(x0, np.float64)
    hold = held & ~model.fixed
    x[hold] = targets[hold]
    free = ~(hold | model.fixed)[..., None]
    for lower in (True, False):
        for _ in range(10_000):
            lo, hi = link_bounds(model, x)
            move = free & ((x > hi + 1e-9) if lower else (x < lo - 1e-9))
            if not move.any():
                break
            x = np.where(move, hi if lower else lo, x)
        else:  # pragma: no cover - the test configurations are feasible
            raise AssertionError("oracle did not converge")
    return x


def _displacement(tex: Any) -> np.ndarray:
    """Read a (nx, ny, nz) RGBA16F array texture as (nx, ny, nz, 4) float64."""
    nx, ny, nz = tex.size
    raw = np.frombuffer(tex.read(), np.float16).reshape(nz, ny, nx, 4)
    return raw.transpose(2, 1, 0, 3).astype(np.float64)


def _held(shape: tuple[int, int, int], *elements: tuple[int, int, int]) -> np.ndarray:
    mask = np.zeros(shape, bool)
    for e in elements:
        mask[e] = True
    return mask


def _check(model: ChainMailModel, x: np.ndarray, held: np.ndarray, targets: np.ndarray) -> None:
    """The three promises of enforce: links satisfied, held at targets, fixed at rest."""
    assert model.violation(x) <= TOL
    hold = held & ~model.fixed
    np.testing.assert_allclose(x[hold], targets[hold], rtol=0, atol=2e-5)  # float32
    np.testing.assert_allclose(x[model.fixed], model.rest[model.fixed], rtol=0, atol=2e-5)


@pytest.fixture
def solvers(gl_ctx: Any) -> Any:
    made: list[Any] = []

    def make(model: ChainMailModel, **kw: Any) -> Any:
        made.append(GpuChainMailSolver(model, gl_ctx, **kw))
        return made[-1]

    yield make
    for s in made:
        s.release()


# ---------------------------------------------------------------------- tests
@pytest.mark.parametrize(
    ("shape", "local"),
    [(SHAPE, True), (SHAPE, False), ((20, 18, 12), True), ((9, 5, 1), True)],
    ids=["box", "full", "tiled-atlas", "sheet"],
)
def test_drag_satisfies_constraints_and_matches_oracle(
    solvers: Any, shape: tuple[int, int, int], local: bool
) -> None:
    fixed = np.zeros(shape, bool)
    fixed[:, 0, 0] = True  # one edge
    model = _model(shape, fixed=fixed)
    gpu = solvers(model, local=local)
    if shape == (20, 18, 12):
        assert gpu.tiles[1] > 1  # an atlas of several rows of z-slices
    e = (shape[0] // 2, shape[1] - 2, shape[2] - 1)
    held = _held(shape, e)
    targets = model.rest.copy()
    # stretches towards the fixed edge (a sheet's element is 3 links from it)
    targets[e] += (0.6, -0.5, 0.6) if shape[2] == 1 else (1.3, -0.8, 0.9)
    passes = gpu.enforce(held, targets)
    assert gpu.converged
    assert 2 <= passes <= 4 * sum(shape)
    x = gpu.positions()
    _check(model, x, held, targets)
    np.testing.assert_array_equal(x[fixed], gpu_rest(model)[fixed])  # bit for bit
    np.testing.assert_array_equal(x[held], _stored(model, targets)[held])
    expected = _oracle(model, model.rest, held, targets)
    assert model.violation(expected) <= 1e-9  # a feasible drag
    np.testing.assert_allclose(x, expected, rtol=0, atol=TOL)
    assert np.abs(x - model.rest).max(axis=-1)[~held].max() > 0.3  # neighbours followed


def gpu_rest(model: ChainMailModel) -> np.ndarray:
    """Rest positions as the solver stores them."""
    return _stored(model, model.rest)


def _stored(model: ChainMailModel, x: np.ndarray) -> np.ndarray:
    """Positions as the solver stores them: float32, relative to the rest box centre."""
    flat = model.rest.reshape(-1, 3)
    origin = 0.5 * (flat.min(axis=0) + flat.max(axis=0))
    return (x - origin).astype(np.float32).astype(np.float64) + origin


def test_move_inside_slack_changes_nothing_else(solvers: Any) -> None:
    model = _model(slack=0.2, shear=0.2)
    gpu = solvers(model)
    gpu.enforce(np.zeros(SHAPE, bool), model.rest)
    before = gpu.positions()
    held = _held(SHAPE, (3, 2, 2))
    targets = model.rest.copy()
    targets[3, 2, 2] += (0.15, -0.15, 0.19)  # the x links' slack and shear are 0.2 mm
    gpu.enforce(held, targets)
    x = gpu.positions()
    np.testing.assert_array_equal(x[~held], before[~held])
    np.testing.assert_allclose(x[3, 2, 2], targets[3, 2, 2], atol=2e-5)


def test_rigid_material_translates_the_whole_body(solvers: Any) -> None:
    model = _model(slack=0.0, shear=0.0)  # min = max = spacing, no shear
    gpu = solvers(model)
    held = _held(SHAPE, (0, 5, 2))
    shift = np.array([2.5, -1.25, 0.75])
    targets = model.rest + shift
    passes = gpu.enforce(held, targets)
    x = gpu.positions()
    np.testing.assert_allclose(x, model.rest + shift, rtol=0, atol=TOL)
    # the wave crosses the grid from the held corner: one element per pass
    assert passes >= sum(n - 1 for n in SHAPE)


def test_cut_links_let_one_side_stay(solvers: Any) -> None:
    links = np.ones((*SHAPE, 3), bool)
    links[3, :, :, 0] = False  # cut between x = 3 and x = 4
    fixed = np.zeros(SHAPE, bool)
    fixed[0, :, :] = True
    model = _model(slack=0.1, shear=0.1, links=links, fixed=fixed)
    gpu = solvers(model)
    held = _held(SHAPE, (6, 3, 2))
    targets = model.rest.copy()
    targets[6, 3, 2] += (3.0, 2.0, -1.0)
    gpu.enforce(held, targets)
    x = gpu.positions()
    _check(model, x, held, targets)
    rest32 = gpu_rest(model)
    np.testing.assert_array_equal(x[:4], rest32[:4])  # the fixed side stays put
    assert np.abs(x[4:] - model.rest[4:]).max() > 1.0  # the cut-off side follows
    # the same drag without the cut pulls the fixed side's free elements too
    whole = _oracle(_model(slack=0.1, shear=0.1, fixed=fixed), model.rest, held, targets)
    assert np.abs(whole[1:4] - model.rest[1:4]).max() > 0.1


@pytest.mark.parametrize("seed", [1, 2])
def test_heterogeneous_anisotropic_limits(solvers: Any, seed: int) -> None:
    rng = np.random.default_rng(seed)
    fixed = _held(SHAPE, (0, 5, 0), (0, 0, 4), (6, 5, 0))
    model = _model(rng=rng, fixed=fixed)
    gpu = solvers(model)
    # held elements pulled apart and pushed: both phases of every coordinate
    held = _held(SHAPE, (1, 1, 1), (5, 4, 3), (6, 0, 4))
    targets = model.rest.copy()
    targets[1, 1, 1] += (-0.8, -0.6, -0.7)
    targets[5, 4, 3] += (0.7, 0.8, 0.5)
    targets[6, 0, 4] += (0.3, -0.6, 0.8)
    x0 = model.rest + rng.uniform(-0.02, 0.02, model.rest.shape)  # within the slack
    x0[fixed] = model.rest[fixed]
    expected = _oracle(model, x0, held, targets)
    assert model.violation(expected) <= 1e-9  # a feasible configuration
    gpu.set_positions(x0)
    gpu.enforce(held, targets)
    assert gpu.converged
    x = gpu.positions()
    _check(model, x, held, targets)
    np.testing.assert_allclose(x, expected, rtol=0, atol=TOL)


def test_violating_upload_is_repaired_everywhere(solvers: Any) -> None:
    rng = np.random.default_rng(4)
    model = _model(slack=0.15, shear=0.15)
    gpu = solvers(model)
    x0 = model.rest + rng.normal(0.0, 0.4, model.rest.shape)  # violates links all over
    assert model.violation(x0) > 0.3
    gpu.set_positions(x0)
    held = np.zeros(SHAPE, bool)
    gpu.enforce(held, x0)
    x = gpu.positions()
    assert model.violation(x) <= TOL
    np.testing.assert_allclose(x, _oracle(model, x0, held, x0), rtol=0, atol=TOL)


def test_growing_box_matches_full_passes_and_oracle(solvers: Any) -> None:
    shape = (12, 11, 10)
    fixed = np.zeros(shape, bool)
    fixed[:, :, 0] = True
    model = _model(shape, slack=0.1, shear=0.1, fixed=fixed)
    local, full = solvers(model, local=True), solvers(model, local=False)
    held = _held(shape, (6, 5, 9), (2, 2, 9))
    targets = model.rest.copy()
    for gpu in (local, full):  # the first enforce checks the whole grid
        gpu.enforce(held, targets)
    expected = model.rest.copy()
    shaded = {True: 0, False: 0}
    steps = [(0.15, 0.0, 0.0)] * 4 + [(0.0, -0.2, -0.1)] * 3 + [(-0.25, 0.1, 0.05)] * 2
    for i, step in enumerate(steps):
        # a drag, frame by frame, from each solver's last state; the second element
        # moves the other way on odd frames (both phases of a coordinate), else not
        targets[6, 5, 9] += step
        targets[2, 2, 9] -= np.array(step) * (0.25 * (i % 2))
        expected = _oracle(model, expected, held, targets)  # always both phases
        assert model.violation(expected) <= 1e-9  # feasible
        for gpu in (local, full):
            gpu.enforce(held, targets)
            assert gpu.converged
            shaded[gpu.local] += gpu.last_elements
        x = local.positions()
        np.testing.assert_allclose(x, full.positions(), rtol=0, atol=TOL)
        _check(model, x, held, targets)
        np.testing.assert_allclose(x, expected, rtol=0, atol=TOL)
    assert shaded[True] < shaded[False] / 3  # and it was local (measured: 1/4.3)
    # the same targets again, then the elements released: nothing to do
    assert local.enforce(held, targets) == 0
    assert local.enforce(np.zeros(shape, bool), targets) == 0
    np.testing.assert_array_equal(local.positions(), x)


def test_infeasible_drag_terminates_and_prefers_the_held(solvers: Any) -> None:
    fixed = np.zeros(SHAPE, bool)
    fixed[:, :, 0] = True
    model = _model(slack=0.1, shear=0.1, fixed=fixed)
    gpu = solvers(model)
    held = _held(SHAPE, (3, 3, 4))
    targets = model.rest.copy()
    targets[3, 3, 4, 2] += 6.0  # beyond the 4 links' stretch of 0.8 mm
    gpu.enforce(held, targets)
    assert gpu.converged
    x = gpu.positions()
    assert model.violation(x) > 1.0
    upper = ChainMailModel(
        rest=model.rest[:, :, 1:],
        spacing=model.spacing,
        min_dist=model.min_dist[:, :, 1:],
        max_dist=model.max_dist[:, :, 1:],
        max_shear=model.max_shear[:, :, 1:],
        links=model.links[:, :, 1:],
        fixed=fixed[:, :, 1:],
    )
    # the free elements follow the held one; only the links to the fixed layer break
    assert upper.violation(x[:, :, 1:]) <= TOL
    np.testing.assert_allclose(x[3, 3, 4], targets[3, 3, 4], atol=2e-5)
    np.testing.assert_array_equal(x[fixed], gpu_rest(model)[fixed])
    # on from the infeasible state, the growing box still matches full passes
    full = solvers(model, local=False)
    full.enforce(held, targets)
    np.testing.assert_allclose(full.positions(), x, rtol=0, atol=TOL)
    for step in [(0.0, 0.0, 1.0), (0.0, 0.0, -3.0), (0.5, -0.4, 0.0), (0.0, 0.0, -4.0)]:
        targets[3, 3, 4] += step
        for g in (gpu, full):
            g.enforce(held, targets)
        x = gpu.positions()
        np.testing.assert_allclose(full.positions(), x, rtol=0, atol=TOL)
        np.testing.assert_array_equal(x[fixed], gpu_rest(model)[fixed])
    assert model.violation(x) <= TOL  # back within reach: feasible again
    # a local infeasible drag just above the fixed layer, then a far element held
    # instead: the violation left at the fixed layer is found by the growing box too
    # (recorded by the last passes), not only by the full passes
    low = _held(SHAPE, (3, 3, 2))
    targets = model.rest.copy()
    targets[3, 3, 2, 2] += 1.0  # (3, 3, 1) can rise 0.2 mm only
    for g in (gpu, full):
        g.enforce(low, targets)
    assert model.violation(gpu.positions()) > 0.5
    np.testing.assert_allclose(full.positions(), gpu.positions(), rtol=0, atol=TOL)
    far = _held(SHAPE, (0, 0, 4))
    targets[0, 0, 4] += (0.01, 0.0, 0.0)
    for g in (gpu, full):
        g.enforce(far, targets)
    np.testing.assert_allclose(full.positions(), gpu.positions(), rtol=0, atol=TOL)
    assert model.violation(gpu.positions()) <= TOL  # released: it relaxed


def test_fixed_wins_over_held(solvers: Any) -> None:
    fixed = _held(SHAPE, (2, 2, 2))
    model = _model(fixed=fixed)
    gpu = solvers(model)
    targets = model.rest + 1.0
    gpu.enforce(fixed | _held(SHAPE, (4, 4, 4)), targets)
    x = gpu.positions()
    np.testing.assert_allclose(x[2, 2, 2], model.rest[2, 2, 2], atol=2e-5)
    np.testing.assert_allclose(x[4, 4, 4], targets[4, 4, 4], atol=2e-5)
    assert model.violation(x) <= TOL


def test_max_passes_stops_early_then_resumes(solvers: Any) -> None:
    model = _model(slack=0.0, shear=0.0)
    gpu = solvers(model)
    held = _held(SHAPE, (0, 0, 0))
    targets = model.rest + 1.0
    assert gpu.enforce(held, targets, max_passes=3) == 3
    assert not gpu.converged
    assert model.violation(gpu.positions()) > 0.5
    gpu.enforce(held, targets)  # checks the whole grid again
    assert gpu.converged
    np.testing.assert_allclose(gpu.positions(), model.rest + 1.0, atol=TOL)


def test_displacement_texture_and_no_readback(solvers: Any, monkeypatch: Any) -> None:
    model = _model(slack=0.1, shear=0.1)
    gpu = solvers(model)
    tex = gpu.displacement_texture()
    assert isinstance(tex, moderngl.TextureArray)  # z-slices as layers
    assert tex.size == SHAPE
    assert tex.components == 4
    assert tex.dtype == "f2"
    assert tex.filter == (moderngl.LINEAR, moderngl.LINEAR)
    assert not tex.repeat_x
    assert not tex.repeat_y
    np.testing.assert_array_equal(_displacement(tex), 0.0)  # at rest

    revision = gpu.revision
    held = _held(SHAPE, (3, 3, 2))
    targets = model.rest.copy()
    targets[3, 3, 2] += (1.5, -1.0, 2.0)
    for t in (*gpu._pos, *gpu._links, gpu._target, gpu._rest):  # enforce reads none back
        monkeypatch.setattr(t, "read", _no_readback)
    gpu.enforce(held, targets)
    monkeypatch.undo()
    assert gpu.revision > revision
    assert gpu.displacement_texture() is tex  # the same texture, updated in place
    disp = _displacement(tex)
    expected = gpu.positions() - model.rest
    assert np.abs(expected).max() > 1.0
    # float16: up to one ulp (2^-10 relative) plus the float32 state's round-off
    np.testing.assert_allclose(disp[..., :3], expected, rtol=2**-10, atol=1e-3)
    np.testing.assert_array_equal(disp[..., 3], 0.0)

    x0 = model.rest + 0.25
    gpu.set_positions(x0)
    np.testing.assert_allclose(_displacement(tex)[..., :3], 0.25, rtol=0, atol=1e-3)


def _no_readback(*args: Any, **kwargs: Any) -> bytes:
    raise AssertionError("the solver read GPU state back during enforce()")


def test_release_is_idempotent_and_bad_input(gl_ctx: Any) -> None:
    model = _model()
    with pytest.raises(ValueError, match=r"moderngl\.Context"):
        GpuChainMailSolver(model, None)
    gpu = GpuChainMailSolver(model, gl_ctx)
    try:
        held = np.zeros(SHAPE, bool)
        with pytest.raises(ValueError, match=r"positions must have shape \(7, 6, 5, 3\)"):
            gpu.set_positions(np.zeros(SHAPE))
        with pytest.raises(ValueError, match="finite"):
            gpu.set_positions(np.full((*SHAPE, 3), np.nan))
        with pytest.raises(ValueError, match=r"held_mask must have shape \(7, 6, 5\)"):
            gpu.enforce(np.zeros((7, 6)), model.rest)
        with pytest.raises(ValueError, match="held_targets must have shape"):
            gpu.enforce(held, np.zeros((*SHAPE, 2)))
        bad = model.rest.copy()
        bad[1, 1, 1] = np.inf
        with pytest.raises(ValueError, match="finite where held"):
            gpu.enforce(_held(SHAPE, (1, 1, 1)), bad)
        gpu.enforce(held, bad)  # not held there: ignored
        with pytest.raises(ValueError, match="max_passes"):
            gpu.enforce(held, model.rest, max_passes=-1)
    finally:
        gpu.release()
    gpu.release()
    assert gl_ctx.error == "GL_NO_ERROR"
    with pytest.raises(RuntimeError, match="after release"):
        gpu.enforce(np.zeros(SHAPE, bool), model.rest)


def test_valid_positions_skip_the_full_check(gl_ctx: Any) -> None:
    """set_positions(rest, valid=True) (ChainMail.reset) lets the next enforce start at
    the held elements: far fewer elements shaded than after an unverified upload, and
    the same result."""
    g = np.zeros((24, 24, 24), bool)
    from voxwarp.deform.elements.chainmail_model import ChainMailModel
    from voxwarp.deform.elements.grid import ElementGrid

    grid = ElementGrid(((0, 0, 0), (230, 230, 230)), shape=(24, 24, 24), anchor="corners")
    s = grid.spacing
    model = ChainMailModel(
        grid.rest_positions, s, 0.9 * s, 1.1 * s, 0.1 * s, np.ones((24, 24, 24, 3), bool), g
    )
    solver = GpuChainMailSolver(model, gl_ctx)
    try:
        held = np.zeros(model.shape, bool)
        held[12, 12, 12] = True
        targets = model.rest.copy()
        targets[12, 12, 12] += (3.0, 0.0, 0.0)
        results = {}
        for valid in (False, True):
            solver.set_positions(model.rest, valid=valid)
            solver.enforce(held, targets)
            results[valid] = (solver.last_elements, solver.positions())
        assert results[True][0] < results[False][0] / 10
        np.testing.assert_allclose(results[True][1], results[False][1], atol=1e-5)
        assert model.violation(results[True][1]) <= 1e-4
    finally:
        solver.release()
