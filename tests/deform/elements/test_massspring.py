"""Tests of voxwarp.deform.elements.massspring: the CPU solver's physics and the MassSpring API.

Oracles: a single step of one free element checked against the force formula of
``deform/elements/spring_model.py`` written out by hand; rigid motions exert no force; the
static equilibrium of a stretched bar is a uniform stretch (displacement linear along
the bar); the energy of a hand-built state; a derived energy bound under random drags;
decay of the energy at the stable time step and growth well above the stability limit.
All tests run on the CPU (no GL).
"""

from __future__ import annotations

import functools
import math
from typing import Any, ClassVar

import numpy as np
import pytest

from voxwarp.deform.elements.grid import ElementGrid, ElementGridError
from voxwarp.deform.elements.massspring import CpuSpringSolver, MassSpring, MassSpringError
from voxwarp.deform.elements.spring_model import SpringModel

CUBE = ((0.0, 0.0, 0.0), (50.0, 50.0, 50.0))


# --------------------------------------------------------------------- single step
def _two_cube_model(integrator: str, shear: bool, max_step: float = 0.0) -> SpringModel:
    """A 2x2x2 grid with spacing 10 mm and varied materials."""
    g = ElementGrid(((0, 0, 0), (10, 10, 10)), shape=2, anchor="corners")
    stiff = np.array([0.2, 0.4, 0.6, 0.8, 0.3, 0.5, 0.7, 0.9]).reshape(2, 2, 2)
    g.set_material(stiffness=stiff, damping=0.7, mass=1.5)
    g.set_material((1, 0, 0), damping=0.4, mass=2.0)
    return SpringModel(
        rest=g.rest_positions,
        spacing=g.spacing,
        stiffness=g.stiffness,
        damping=g.damping,
        mass=g.mass,
        spring_constant=40.0,
        spring_damping=0.3,
        shear=shear,
        integrator=integrator,
        dt=0.01,
        max_step=max_step,
    )


def _hand_acceleration(model: SpringModel, x_a: np.ndarray, v_a: np.ndarray) -> np.ndarray:
    """spring_model.py's force on element a = (1, 0, 0), its neighbours at rest, still."""
    a = (1, 0, 0)
    neighbours = [(0, 0, 0), (1, 1, 0), (1, 0, 1)]  # structural, inside the 2x2x2 grid
    if model.shear:
        neighbours += [(0, 1, 0), (0, 0, 1), (1, 1, 1)]  # face diagonals inside the grid
    s_a = float(model.stiffness[a])
    f = np.zeros(3)
    for b in neighbours:
        x_b = np.array(b, float) * 10.0  # rest position, pinned
        d = x_b - x_a
        length = math.sqrt(d @ d)
        rest = 10.0 * math.sqrt(sum((p - q) ** 2 for p, q in zip(b, a, strict=True)))
        dh = d / length
        k = model.spring_constant * (s_a + float(model.stiffness[b])) / 2
        f += k * (length - rest) * dh + model.spring_damping * ((0.0 - v_a) @ dh) * dh
    f -= float(model.damping[a]) * v_a
    return f / float(model.mass[a])


@pytest.mark.parametrize("shear", [False, True])
@pytest.mark.parametrize("integrator", ["explicit", "semi-implicit"])
def test_single_step_matches_hand_written_force(integrator: str, shear: bool) -> None:
    model = _two_cube_model(integrator, shear)
    solver = CpuSpringSolver(model)
    x0 = model.rest.copy()
    x0[1, 0, 0] += (2.0, 0.0, 0.0)  # displaced along x
    v0 = np.zeros_like(x0)
    v0[1, 0, 0] = (0.3, -0.2, 0.1)
    pinned = np.ones((2, 2, 2), dtype=bool)
    pinned[1, 0, 0] = False
    solver.set_state(x0, v0)
    solver.set_constraints(pinned, model.rest)
    solver.step()
    acc = _hand_acceleration(model, x0[1, 0, 0], v0[1, 0, 0])
    v1 = v0[1, 0, 0] + model.dt * acc
    x1 = x0[1, 0, 0] + model.dt * (v1 if integrator == "semi-implicit" else v0[1, 0, 0])
    assert abs(acc[0]) > 1.0  # the displaced element is pulled back noticeably
    np.testing.assert_allclose(solver.velocities()[1, 0, 0], v1, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(solver.positions()[1, 0, 0], x1, rtol=1e-12, atol=1e-12)
    # the pinned elements stay at rest, still
    np.testing.assert_array_equal(solver.positions()[pinned], model.rest[pinned])
    assert not solver.velocities()[pinned].any()


@pytest.mark.parametrize("integrator", ["explicit", "semi-implicit"])
def test_displacement_clamp_scales_step_and_velocity(integrator: str) -> None:
    free = _two_cube_model(integrator, shear=False)
    clamped = _two_cube_model(integrator, shear=False, max_step=1e-3)
    x0 = free.rest.copy()
    x0[1, 0, 0] += (2.0, 0.0, 0.0)
    v0 = np.zeros_like(x0)
    v0[1, 0, 0] = (3.0, -2.0, 1.0)  # one unclamped step moves ~0.04 mm
    pinned = np.ones((2, 2, 2), dtype=bool)
    pinned[1, 0, 0] = False
    out = []
    for model in (free, clamped):
        s = CpuSpringSolver(model)
        s.set_state(x0, v0)
        s.set_constraints(pinned, model.rest)
        s.step()
        out.append((s.positions()[1, 0, 0] - x0[1, 0, 0], s.velocities()[1, 0, 0]))
    (dx, v), (dx_c, v_c) = out
    scale = 1e-3 / np.linalg.norm(dx)
    assert scale < 0.1
    assert np.linalg.norm(dx_c) == pytest.approx(1e-3, rel=1e-9)
    np.testing.assert_allclose(dx_c, dx * scale, rtol=1e-9)
    np.testing.assert_allclose(v_c, v * scale, rtol=1e-9)


@pytest.mark.parametrize(("shear", "bend"), [(False, False), (True, True)])
def test_rigid_motions_exert_no_force(shear: bool, bend: bool) -> None:
    g = ElementGrid(((0, 0, 0), (40, 30, 20)), shape=(5, 4, 3), anchor="corners")
    m = SpringModel(
        rest=g.rest_positions,
        spacing=g.spacing,
        stiffness=np.random.default_rng(3).uniform(0, 1, g.shape),
        damping=np.zeros(g.shape),
        mass=g.mass,
        shear=shear,
        bend=bend,
    )
    s = CpuSpringSolver(m)
    c, sn = math.cos(0.7), math.sin(0.7)
    rot = np.array([[c, -sn, 0], [sn, c, 0], [0, 0, 1]]) @ np.array(
        [[1, 0, 0], [0, c, -sn], [0, sn, c]]
    )
    x = g.rest_positions @ rot.T + (5.0, -3.0, 12.0)
    still = np.zeros_like(x)
    assert np.abs(s.accelerations(x, still)).max() < 1e-9
    # a rigid rotation's velocity field stretches no spring: spring damping is 0 too
    omega = np.array([0.2, -0.5, 0.3])
    spin = np.cross(omega, x)
    assert np.abs(s.accelerations(x, spin)).max() < 1e-9
    # while a stretch does exert force
    assert np.abs(s.accelerations(x * 1.01, still)).max() > 0.1


# --------------------------------------------------------------------- constraints
def test_fixed_never_move_and_held_stay_exactly_where_held() -> None:
    rng = np.random.default_rng(7)
    g = ElementGrid(CUBE, shape=5, anchor="corners")
    g.fix([[2, 2, 2], [0, 3, 1]])
    ms = MassSpring(g)
    rest = g.rest_positions
    fixed = g.fixed.copy()
    held: dict[tuple[int, int, int], np.ndarray] = {}
    moved_free = 0.0
    for _ in range(200):
        idx = tuple(int(i) for i in rng.integers(0, 5, 3))
        off = rng.uniform(-25, 25, 3)
        ms.move(idx, off)  # a fixed element must ignore this
        if not fixed[idx]:
            held[idx] = off
        if rng.random() < 0.1 and held:
            key = list(held)[int(rng.integers(len(held)))]
            ms.release(key)
            del held[key]
        ms.step()
        x = ms.positions()
        np.testing.assert_array_equal(x[fixed], rest[fixed])
        for k, o in held.items():
            np.testing.assert_array_equal(x[k], rest[k] + o)
        free = ~fixed & ~ms.held
        moved_free = max(moved_free, float(np.abs(x[free] - rest[free]).max()))
    assert moved_free > 1.0  # the drags did move the free elements
    expected_held = np.zeros(g.shape, dtype=bool)
    for k in held:
        expected_held[k] = True
    np.testing.assert_array_equal(ms.held, expected_held)


def test_move_by_mask_list_and_release() -> None:
    g = ElementGrid(CUBE, shape=4, anchor="corners")
    ms = MassSpring(g, integrator="semi-implicit")
    face = np.zeros(g.shape, dtype=bool)
    face[:, :, 3] = True
    ms.move(face, (0, 0, 4.0))
    d = ms.displacements()
    assert d.dtype == np.float32
    corners = g.corner_mask()
    np.testing.assert_allclose(d[face & ~corners], [[0, 0, 4.0]] * 12)
    np.testing.assert_array_equal(d[face & corners], 0.0)  # fixed corners stay
    ms.move([[1, 1, 0], [2, 1, 0]], [[1.0, 0, 0], [0, 2.0, 0]])
    d = ms.displacements()
    np.testing.assert_allclose(d[1, 1, 0], [1, 0, 0])
    np.testing.assert_allclose(d[2, 1, 0], [0, 2, 0])
    ms.release(face)
    ms.step(20)
    d = ms.displacements()
    np.testing.assert_allclose(d[1, 1, 0], [1, 0, 0])  # still held
    assert abs(d[1, 1, 3, 2] - 4.0) > 1e-3  # released: the face springs back
    ms.fix((1, 1, 0))  # fixing a held element releases it, back to rest
    assert not ms.held[1, 1, 0]
    np.testing.assert_array_equal(ms.positions()[1, 1, 0], g.rest_positions[1, 1, 0])
    ms.free((1, 1, 0))
    assert not ms.held[1, 1, 0]
    with pytest.raises(MassSpringError, match=r"one \(3,\) offset"):
        ms.move(face, [[1, 0, 0]] * 16)
    with pytest.raises(MassSpringError, match="one per selected"):
        ms.move([[1, 1, 1], [2, 2, 2]], [[1, 0, 0]] * 3)
    with pytest.raises(ElementGridError, match=r"\(4, 0, 0\).*\(4, 4, 4\)"):
        ms.move((4, 0, 0), (1, 0, 0))
    with pytest.raises(ElementGridError, match="outside the grid"):
        ms.fix([[0, 0, 9]])


# --------------------------------------------------------------------- equilibrium
BAR_SHAPE = (12, 3, 3)
BAR_PULL = 5.5


@functools.cache
def _settled_bar(integrator: str) -> tuple[np.ndarray, int]:
    """Bar 110 x 10 x 10 mm, face i=0 fixed, face i=11 pulled +5.5 mm along x."""
    g = ElementGrid(((0, 0, 0), (110, 10, 10)), shape=BAR_SHAPE, anchor="corners")
    first = np.zeros(g.shape, dtype=bool)
    first[0] = True
    last = np.zeros(g.shape, dtype=bool)
    last[-1] = True
    g.free(g.corner_mask())
    ms = MassSpring(g, integrator=integrator)  # structural springs, uniform stiffness
    ms.fix(first)
    ms.move(last, (BAR_PULL, 0, 0))
    steps = ms.settle(max_steps=30_000, tol=1e-4)
    return ms.displacements(), steps


@pytest.mark.parametrize("integrator", ["explicit", "semi-implicit"])
def test_bar_settles_to_uniform_stretch(integrator: str) -> None:
    d, steps = _settled_bar(integrator)
    assert steps < 30_000, "did not settle"
    i = np.arange(BAR_SHAPE[0], dtype=float)[:, None, None]
    expected_x = BAR_PULL * i / (BAR_SHAPE[0] - 1)  # 0 at i=0, 5.5 at i=11
    assert np.abs(d[..., 0] - expected_x).max() < 0.02 * BAR_PULL
    assert np.abs(d[..., 1:]).max() < 0.02 * BAR_PULL


def test_explicit_and_semi_implicit_reach_the_same_equilibrium() -> None:
    d_e, _ = _settled_bar("explicit")
    d_s, _ = _settled_bar("semi-implicit")
    assert np.abs(d_e - d_s).max() < 0.01 * BAR_PULL


# --------------------------------------------------------------------- energy
def test_energy_of_hand_built_state() -> None:
    g = ElementGrid(((0, 0, 0), (10, 10, 10)), shape=2, anchor="corners")
    g.fix(np.ones(g.shape, dtype=bool))
    g.free((1, 0, 0))
    g.set_material(stiffness=0.25)  # exact in float32
    g.set_material([[1, 0, 0], [1, 1, 0], [0, 1, 1]], stiffness=0.75)
    ms = MassSpring(g, spring_constant=30.0)
    assert ms.energy() == 0.0
    ms.move((1, 0, 0), (2.0, 0, 0))
    # springs of (1,0,0): x to (0,0,0) stretched by 2 (k = 30 * (0.75 + 0.25) / 2);
    # y to (1,1,0) (k = 30 * 0.75) and z to (1,0,1) (k = 15) turned, length
    # sqrt(10^2 + 2^2); every other spring joins two elements at rest
    turned = math.hypot(10.0, 2.0) - 10.0
    expected = 0.5 * 15.0 * 2.0**2 + 0.5 * 22.5 * turned**2 + 0.5 * 15.0 * turned**2
    assert ms.energy() == pytest.approx(expected, rel=1e-12)
    ms.release((1, 0, 0))
    ms.step(300)  # now it swings back; the damping takes energy out
    assert 0 < ms.energy() < 0.5 * expected


@pytest.mark.slow
def test_random_drags_stay_bounded() -> None:
    """10,000 random drags of a 6x6x6 grid with the displacement clamp on.

    Bound: every drag puts an element at most R = 3 * spacing from rest; fixed
    elements sit at rest. A static configuration of such constraints has its free
    elements within R of rest too (discrete maximum principle of the spring network),
    so no spring is stretched or compressed by more than 2R and the potential energy
    is at most U_max = N_springs * 0.5 * k_max * (2R)^2. A stable, damped integration
    only dissipates the energy the drags put in, so the total energy must stay below
    U_max; an unstable one grows without bound (or turns into NaN).
    """
    rng = np.random.default_rng(2024)
    g = ElementGrid(CUBE, shape=6, anchor="corners")
    h = float(g.spacing.min())
    ms = MassSpring(g)  # explicit, clamp on (max_step = h / 2)
    assert ms.max_step == pytest.approx(0.5 * h)
    big_r = 3.0 * h
    n_springs = 3 * 5 * 6 * 6  # structural springs of a 6^3 grid
    k_max = 50.0 * 0.5
    u_max = n_springs * 0.5 * k_max * (2 * big_r) ** 2
    e_max = 0.0
    for it in range(10_000):
        idx = rng.integers(0, 6, 3)
        direction = rng.normal(size=3)
        ms.move(idx, direction / np.linalg.norm(direction) * rng.uniform(0, big_r))
        ms.step()
        if rng.random() < 0.1:
            ms.release(None if rng.random() < 0.2 else idx)
        if it % 10 == 0:
            e = ms.energy()
            assert math.isfinite(e)
            e_max = max(e_max, e)
    x = ms.positions()
    assert np.all(np.isfinite(x))
    assert e_max < u_max
    assert e_max > 1e-3 * u_max  # the drags did stress the grid


@pytest.mark.parametrize(("integrator", "limit"), [("explicit", 0.03), ("semi-implicit", 0.17)])
def test_stable_time_step_is_stable_and_the_limit_is_real(integrator: str, limit: float) -> None:
    """Without the clamp: energy decays at stable_time_step(); it explodes above the limit.

    ``limit`` is the stability limit of the stiffest mode at rest for the defaults
    (k = 25, damping 1, spring damping 0.5, mass 1; alternating x-displacement along x
    has omega^2 = 4k = 100, gamma = 1 + 4 * 0.5 = 3): explicit Euler needs
    dt < gamma / omega^2 = 0.03, symplectic Euler dt^2 omega^2 + 2 dt gamma < 4,
    i.e. dt < 0.17.
    """
    rng = np.random.default_rng(5)
    energies = {}
    for name in ("stable", "unstable"):
        g = ElementGrid(CUBE, shape=6, anchor="corners")
        ms = MassSpring(g, integrator=integrator, max_step=0)
        assert ms.dt < limit
        if name == "unstable":
            ms.model.dt = 2.0 * limit  # bypass the clamping of dt on purpose
        ms.move(np.ones(g.shape, dtype=bool), (0, 0, 0))
        ms.move(np.argwhere(~g.fixed), rng.uniform(-0.2, 0.2, (6**3 - 8, 3)))
        ms.release()  # start from a small random perturbation, at rest
        e0 = ms.energy()
        with np.errstate(all="ignore"):  # the unstable run overflows
            ms.step(1000)
            energies[name] = ms.energy() / e0
    assert energies["stable"] < 1.0
    assert not energies["unstable"] < 1e3  # grows (or is NaN)


# --------------------------------------------------------------------- settle / warp
def test_settle_stops_when_still_or_at_max_steps() -> None:
    g = ElementGrid(CUBE, shape=4, anchor="corners")
    ms = MassSpring(g, integrator="semi-implicit")
    ms.move((1, 1, 1), (0, 5.0, 0))
    assert ms.settle(max_steps=30, tol=1e-6) == 30
    steps = ms.settle(max_steps=5000, tol=1e-2)
    assert steps < 5000
    d_still = ms.displacements()
    ms.step(50)  # 2.4 s at < 0.01 mm/s
    assert np.abs(ms.displacements() - d_still).max() < 0.03
    assert ms.displacements()[1, 1, 2, 1] > 0.1  # a neighbour of the dragged element


def test_warp_follows_the_displacements() -> None:
    pytest.importorskip("voxwarp.deform.elements.offset_field")
    g = ElementGrid(CUBE, shape=4, anchor="corners")
    ms = MassSpring(g)
    w = ms.warp()
    assert ms.warp() is w
    ms.move((1, 2, 1), (3.0, 0, 0))
    np.testing.assert_allclose(w.displacements, ms.displacements())
    ms.step(10)
    np.testing.assert_allclose(w.displacements, ms.displacements())
    assert np.abs(w.displacements).max() == pytest.approx(3.0, rel=1e-6)


class _RecordingSolver:
    """Stands in for GpuSpringSolver: a CPU solver that records read-backs."""

    instances: ClassVar[list[_RecordingSolver]] = []

    def __init__(self, model: SpringModel, ctx: Any) -> None:
        self.inner = CpuSpringSolver(model)
        self.ctx = ctx
        self.reads: list[str] = []
        self.released = False
        _RecordingSolver.instances.append(self)

    def set_state(self, positions: np.ndarray, velocities: np.ndarray) -> None:
        self.inner.set_state(positions, velocities)

    def set_constraints(self, pinned: np.ndarray, targets: np.ndarray) -> None:
        self.inner.set_constraints(pinned, targets)

    def step(self, n: int = 1) -> None:
        self.inner.step(n)

    def positions(self) -> np.ndarray:
        self.reads.append("positions")
        return self.inner.positions()

    def velocities(self) -> np.ndarray:
        self.reads.append("velocities")
        return self.inner.velocities()

    def max_speed(self) -> float:
        self.reads.append("max_speed")
        return self.inner.max_speed()

    def displacement_texture(self) -> str:
        return "texture"

    def release(self) -> None:
        self.released = True


def test_gpu_backend_reads_back_only_when_asked(monkeypatch: pytest.MonkeyPatch) -> None:
    gpu = pytest.importorskip("voxwarp.deform.elements.massspring_gpu")
    pytest.importorskip("voxwarp.deform.elements.offset_field")
    monkeypatch.setattr(gpu, "GpuSpringSolver", _RecordingSolver)
    g = ElementGrid(CUBE, shape=4, anchor="corners")
    ms = MassSpring(g, backend="gpu", ctx="ctx")
    solver = _RecordingSolver.instances[-1]
    assert solver.ctx == "ctx"
    ms.move((1, 1, 1), (2.0, 0, 0))
    ms.fix((2, 2, 2))
    ms.free((2, 2, 2))
    ms.step(5)
    ms.release()
    assert solver.reads == []
    ms.settle(max_steps=100, tol=1e-9)
    assert solver.reads == ["max_speed", "max_speed"]
    assert ms.displacements().shape == (4, 4, 4, 3)
    assert "positions" in solver.reads
    w = ms.warp()  # reads the solver's texture, no read-back
    assert ms.warp() is w
    assert tuple(w.shape) == g.shape
    ms.step(3)
    assert solver.reads.count("positions") == 1
    ms.close()
    assert solver.released


# --------------------------------------------------------------------- bad parameters
def test_bad_parameters() -> None:
    g = ElementGrid(CUBE, shape=3, anchor="corners")
    with pytest.raises(ElementGridError, match=r"\[0, 1\]"):
        g.set_material(stiffness=1.2)
    with pytest.raises(MassSpringError, match=r"unknown integrator 'rk4'.*explicit.*semi-implicit"):
        MassSpring(g, integrator="rk4")
    with pytest.raises(MassSpringError, match=r"unknown backend 'cuda'.*cpu.*gpu"):
        MassSpring(g, backend="cuda")
    with pytest.raises(MassSpringError, match=r"moderngl context.*backend=\"cpu\""):
        MassSpring(g, backend="gpu")
    with pytest.raises(MassSpringError, match="spring_constant must be > 0"):
        MassSpring(g, spring_constant=0.0)
    with pytest.raises(MassSpringError, match="max_step"):
        MassSpring(g, max_step=-1.0)
    with pytest.raises(MassSpringError, match="dt must be > 0"):
        MassSpring(g, dt=0.0)
    with pytest.raises(MassSpringError, match="ElementGrid"):
        MassSpring(CUBE)  # type: ignore[arg-type]


def test_unstable_dt_warns_and_is_clamped() -> None:
    g = ElementGrid(CUBE, shape=3, anchor="corners")
    stable = MassSpring(g).stable_time_step()
    with pytest.warns(RuntimeWarning, match=rf"dt=1 s exceeds the stable time step {stable:g}"):
        ms = MassSpring(g, dt=1.0)
    assert ms.dt == stable
    small = MassSpring(g, dt=0.5 * stable)
    assert small.dt == 0.5 * stable
    # stiffer springs need smaller steps; more damping allows larger explicit steps,
    # heavier elements larger semi-implicit ones
    assert MassSpring(g, spring_constant=500.0).dt < stable
    semi = MassSpring(g, integrator="semi-implicit").dt
    g.set_material(damping=2.0)
    assert MassSpring(g).dt > stable
    g.set_material(mass=10.0)
    assert MassSpring(g, integrator="semi-implicit").dt > semi
