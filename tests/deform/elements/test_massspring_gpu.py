"""GpuSpringSolver (deform/elements/massspring_gpu.py) against the CPU reference of the same
physics.

The reference is ``voxwarp.deform.elements.massspring.CpuSpringSolver`` when that module exists (the
project's float64 reference), else the small numpy solver below, written straight from
``deform/elements/spring_model.py``.
"""

from __future__ import annotations

import importlib
import importlib.util
from typing import Any

import moderngl
import numpy as np
import pytest

from voxwarp.deform.elements.spring_model import SpringModel

massspring_gpu = pytest.importorskip("voxwarp.deform.elements.massspring_gpu")
GpuSpringSolver = massspring_gpu.GpuSpringSolver
gpu_grid = pytest.importorskip("voxwarp.deform.elements.gpu_grid")

SHAPE = (5, 4, 6)
SPACING = np.array([2.0, 1.5, 1.0])


# ---------------------------------------------------------------------- reference
class _NumpyReference:
    """Straight transcription of deform/elements/spring_model.py (float64, loops over offsets)."""

    def __init__(self, model: SpringModel, ctx: Any = None) -> None:
        self.model = model
        self.x = np.array(model.rest, float)
        self.v = np.zeros_like(self.x)
        self.pinned = np.zeros(model.shape, bool)
        self.targets = self.x.copy()

    def set_state(self, positions: np.ndarray, velocities: np.ndarray) -> None:
        self.x, self.v = np.array(positions, float), np.array(velocities, float)

    def set_constraints(self, pinned: np.ndarray, targets: np.ndarray) -> None:
        self.pinned, self.targets = np.array(pinned, bool), np.array(targets, float)
        self.x[self.pinned] = self.targets[self.pinned]  # as CpuSpringSolver: at once
        self.v[self.pinned] = 0.0

    def step(self, n: int = 1) -> None:
        m = self.model
        shape = m.shape
        for _ in range(n):
            x, v = self.x, self.v
            f = -m.damping[..., None] * v
            for o, rest_len in zip(m.offsets, m.rest_lengths(), strict=True):
                a = tuple(slice(max(0, -c), n_ - max(0, c)) for c, n_ in zip(o, shape, strict=True))
                b = tuple(slice(s.start + c, s.stop + c) for s, c in zip(a, o, strict=True))
                d = x[b] - x[a]
                length = np.linalg.norm(d, axis=-1, keepdims=True)
                dh = np.where(length < 1e-9, 0.0, d / np.maximum(length, 1e-300))
                k = m.spring_constant * (m.stiffness[a] + m.stiffness[b])[..., None] / 2
                dv = np.sum((v[b] - v[a]) * dh, axis=-1, keepdims=True)
                f[a] += k * (length - rest_len) * dh + m.spring_damping * dv * dh
            v_new = v + m.dt * f / m.mass[..., None]
            step_x = m.dt * (v_new if m.integrator == "semi-implicit" else v)
            if m.max_step > 0:
                size = np.linalg.norm(step_x, axis=-1, keepdims=True)
                scale = np.where(size > m.max_step, m.max_step / np.maximum(size, 1e-300), 1.0)
                step_x, v_new = step_x * scale, v_new * scale
            x_new = x + step_x
            x_new[self.pinned] = self.targets[self.pinned]
            v_new[self.pinned] = 0.0
            self.x, self.v = x_new, v_new

    def positions(self) -> np.ndarray:
        return self.x.copy()

    def velocities(self) -> np.ndarray:
        return self.v.copy()


def _reference_class() -> type:
    """The project's CpuSpringSolver when present, else the numpy transcription above."""
    if importlib.util.find_spec("voxwarp.deform.elements.massspring") is not None:
        module = importlib.import_module("voxwarp.deform.elements.massspring")
        if hasattr(module, "CpuSpringSolver"):
            return module.CpuSpringSolver
    return _NumpyReference


def _model(rng: np.random.Generator, **kw: Any) -> SpringModel:
    axes = [np.arange(n) * s for n, s in zip(SHAPE, SPACING, strict=True)]
    rest = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1) + 10.0
    return SpringModel(
        rest=rest,
        spacing=SPACING.copy(),
        stiffness=rng.uniform(0.2, 0.9, SHAPE),
        damping=rng.uniform(0.0, 1.0, SHAPE),
        mass=rng.uniform(0.5, 2.0, SHAPE),
        **kw,
    )


def _displacement(tex: Any) -> np.ndarray:
    """Read a (nx, ny, nz) RGBA16F 3D texture as (nx, ny, nz, 4) float64."""
    nx, ny, nz = tex.size
    raw = np.frombuffer(tex.read(), np.float16).reshape(nz, ny, nx, 4)
    return raw.transpose(2, 1, 0, 3).astype(np.float64)


# ---------------------------------------------------------------------- tests
@pytest.mark.parametrize("integrator", ["explicit", "semi-implicit"])
@pytest.mark.parametrize("max_step", [0.0, 0.05])
@pytest.mark.parametrize("block", [None, (1, 1, 1), (2, 1, 2), (4, 1, 1), (1, 2, 2)])
def test_matches_cpu_reference(
    gl_ctx: Any, integrator: str, max_step: float, block: tuple[int, int, int] | None
) -> None:
    rng = np.random.default_rng(7)
    model = _model(rng, shear=True, bend=True, integrator=integrator, max_step=max_step, dt=0.01)
    x0 = model.rest + rng.normal(0.0, 0.3, model.rest.shape)
    v0 = rng.normal(0.0, 1.0, model.rest.shape)
    pinned = np.zeros(SHAPE, bool)
    pinned[0, 0, 0] = pinned[-1, -1, -1] = True
    targets = model.rest + 0.5

    ref = _reference_class()(model, None)
    gpu = GpuSpringSolver(model, gl_ctx, **({} if block is None else {"block": block}))
    try:
        for solver in (ref, gpu):
            solver.set_state(x0, v0)
            solver.set_constraints(pinned, targets)
            solver.step(50)
        extent = float(np.ptp(model.rest.reshape(-1, 3), axis=0).max())  # 8 mm
        err = np.abs(gpu.positions() - ref.positions()).max()
        # measured vs CpuSpringSolver (llvmpipe, float32 vs float64): 3.9e-6 .. 8.7e-6 mm,
        # i.e. ~1e-6 x extent. max_step 0.05 mm is active here (it changes the result).
        assert err <= 1e-4 * extent, f"max position error {err} mm"
        verr = np.abs(gpu.velocities() - ref.velocities()).max()
        assert verr <= 1e-2, f"max velocity error {verr} mm/s"  # measured <= 6.5e-5
    finally:
        gpu.release()


def test_pinned_elements_sit_at_targets(gl_ctx: Any) -> None:
    rng = np.random.default_rng(3)
    model = _model(rng, shear=True, integrator="semi-implicit")
    gpu = GpuSpringSolver(model, gl_ctx)
    try:
        gpu.set_state(model.rest + rng.normal(0.0, 0.2, model.rest.shape), np.ones((*SHAPE, 3)))
        pinned = rng.random(SHAPE) < 0.2
        targets = (model.rest + rng.normal(0.0, 1.0, model.rest.shape)).astype(np.float32)
        gpu.set_constraints(pinned, targets)
        # at once, before any step (as CpuSpringSolver)
        np.testing.assert_array_equal(gpu.positions()[pinned], targets[pinned])
        gpu.step(7)
        x, v = gpu.positions(), gpu.velocities()
        np.testing.assert_array_equal(x[pinned], targets[pinned])  # exact (float32 targets)
        np.testing.assert_array_equal(v[pinned], 0.0)
        assert np.abs(v[~pinned]).max() > 0  # the others do move
    finally:
        gpu.release()


@pytest.mark.parametrize("steps", [1, 5])
def test_set_state_after_constraints_matches_cpu(gl_ctx: Any, steps: int) -> None:
    # pinned elements keep a state given by set_state until the next step puts them back
    rng = np.random.default_rng(11)
    model = _model(rng, shear=True, integrator="explicit", dt=0.01)
    pinned = rng.random(SHAPE) < 0.25
    targets = model.rest + rng.normal(0.0, 0.5, model.rest.shape)
    x0 = model.rest + rng.normal(0.0, 0.3, model.rest.shape)
    v0 = rng.normal(0.0, 1.0, model.rest.shape)
    ref = _reference_class()(model, None)
    gpu = GpuSpringSolver(model, gl_ctx)
    try:
        for solver in (ref, gpu):
            solver.set_constraints(pinned, targets)
            solver.set_state(x0, v0)
        np.testing.assert_allclose(gpu.positions(), x0, atol=1e-5)  # as given, also pinned
        np.testing.assert_allclose(gpu.velocities(), v0, atol=1e-5)
        for solver in (ref, gpu):
            solver.step(steps)
        assert np.abs(gpu.positions() - ref.positions()).max() <= 1e-4
        assert np.abs(gpu.velocities() - ref.velocities()).max() <= 1e-3
        np.testing.assert_array_equal(gpu.velocities()[pinned], 0.0)
    finally:
        gpu.release()


def test_displacement_texture_follows_steps_on_gpu(gl_ctx: Any, monkeypatch: Any) -> None:
    rng = np.random.default_rng(5)
    model = _model(rng, bend=True)
    gpu = GpuSpringSolver(model, gl_ctx)
    try:
        tex = gpu.displacement_texture()
        assert tex.size == SHAPE
        assert tex.components == 4
        assert tex.dtype == "f2"
        assert tex.filter == (gl_ctx.LINEAR, gl_ctx.LINEAR)
        assert not tex.repeat_x
        assert not tex.repeat_y
        assert isinstance(tex, moderngl.TextureArray)  # z-slices as layers
        np.testing.assert_array_equal(_displacement(tex)[..., :3], 0.0)  # at rest

        gpu.set_state(model.rest + rng.normal(0.0, 0.5, model.rest.shape), np.zeros((*SHAPE, 3)))

        # step() must not read anything back: make every read of the state fail
        for t in (*gpu._pos[0], *gpu._pos[1], *gpu._vel[0], *gpu._vel[1]):
            monkeypatch.setattr(t, "read", _no_readback)
        gpu.step(20)
        monkeypatch.undo()

        assert gpu.displacement_texture() is tex  # the same texture, updated in place
        disp = _displacement(tex)
        expected = gpu.positions() - model.rest
        # float16 has an 11-bit significand and llvmpipe converts by truncation: up to one
        # ulp, i.e. 2^-10 relative (|displacement| < 2 mm here: <= 2e-3 mm absolute)
        np.testing.assert_allclose(disp[..., :3], expected, rtol=2**-10, atol=2e-3)
        assert np.abs(expected).max() > 0.05  # it did move
        np.testing.assert_allclose(disp[..., 3], model.stiffness, rtol=2**-10, atol=0)
    finally:
        gpu.release()


def _no_readback(*args: Any, **kwargs: Any) -> bytes:
    raise AssertionError("the solver read GPU state back during step()")


def test_release_is_idempotent(gl_ctx: Any) -> None:
    gpu = GpuSpringSolver(_model(np.random.default_rng(1)), gl_ctx)
    gpu.step(3)
    gpu.release()
    gpu.release()
    assert gl_ctx.error == "GL_NO_ERROR"
    with pytest.raises(RuntimeError, match="after release"):
        gpu.step()


def test_bad_input(gl_ctx: Any) -> None:
    rng = np.random.default_rng(2)
    model = _model(rng)
    with pytest.raises(ValueError, match=r"moderngl\.Context"):
        GpuSpringSolver(model, None)
    gpu = GpuSpringSolver(model, gl_ctx)
    try:
        good = np.zeros((*SHAPE, 3))
        with pytest.raises(ValueError, match=r"positions must have shape \(5, 4, 6, 3\)"):
            gpu.set_state(np.zeros((5, 4, 6)), good)
        with pytest.raises(ValueError, match="velocities must have shape"):
            gpu.set_state(good, np.zeros((4, 5, 6, 3)))
        with pytest.raises(ValueError, match="finite"):
            gpu.set_state(np.full((*SHAPE, 3), np.nan), good)
        with pytest.raises(ValueError, match=r"pinned must have shape \(5, 4, 6\)"):
            gpu.set_constraints(np.zeros((5, 4)), good)
        with pytest.raises(ValueError, match="targets must have shape"):
            gpu.set_constraints(np.zeros(SHAPE, bool), np.zeros((*SHAPE, 2)))
        with pytest.raises(ValueError, match=">= 0"):
            gpu.step(-1)
    finally:
        gpu.release()
    with pytest.raises(ValueError, match="block"):
        GpuSpringSolver(model, gl_ctx, block=(2, 2, 2))
    bad = _model(rng)
    bad.mass = np.zeros(SHAPE)
    with pytest.raises(ValueError, match="mass"):
        GpuSpringSolver(bad, gl_ctx)


def test_atlas_layout() -> None:
    atlas_layout = gpu_grid.atlas_layout
    assert atlas_layout((128, 128, 128), 16384) == (11, 12)
    assert atlas_layout((64, 64, 64), 16384) == (8, 8)
    assert atlas_layout((5, 4, 6), 16384) == (2, 3)
    tx, ty = atlas_layout((10, 10, 50), 100)
    assert max(tx, ty) * 10 <= 100
    assert tx * ty >= 50
    with pytest.raises(ValueError, match="does not fit"):
        atlas_layout((128, 128, 128), 1024)
