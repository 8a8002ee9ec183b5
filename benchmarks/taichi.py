"""The mass-spring model in taichi on the CPU: the reference of ``python -m benchmarks massspring``.

:class:`TaichiSpringSolver` integrates exactly the physics of
:mod:`voxwarp.deform.elements.spring_model`
(the same as :class:`voxwarp.deform.elements.massspring.CpuSpringSolver` and
:class:`voxwarp.deform.elements.massspring_gpu.GpuSpringSolver`, to float32 round-off) with taichi's
LLVM CPU backend (``ti.init(arch=ti.cpu)``, once per process, all cores). It is written
the way one would write it for speed in taichi, so that the benchmark compares against
a fair implementation:

* dense fields: positions and velocities (``ti.Vector.field(3)``, two of each,
  ping-pong), stiffness, damping, mass, pinned flag and pin target per element;
* one ``ti.kernel`` per step whose outermost loop is a struct-for over the grid
  (parallelised over the CPU's threads); it reads the previous state of an element
  and of its spring neighbours and writes the new state into the other buffer, so no
  element reads a value written in the same step;
* the grid shape, the spring offsets and their rest lengths are compile-time constants
  (``ti.static``), so the spring loop unrolls; a neighbour outside the grid is clamped
  into it and weighted 0 instead of skipped by an ``if`` (as in the GPU shader; about
  15% faster here than the branching loop); the integrator is a template parameter
  (one compiled kernel per integrator and buffer direction); ``dt``, the spring
  constants and the clamp are run-time arguments.

taichi is optional (extra ``[bench]``); this module imports it lazily, so importing the
module never fails: use :func:`taichi_available` first.
"""

# no `from __future__ import annotations`: taichi reads the kernels' annotations
# (ti.template(), ti.f64) as objects, not strings
import contextlib
import importlib.util
import os
import sys
import warnings
from typing import Any

import numpy as np

from voxwarp.deform.elements.spring_model import INTEGRATORS, SpringModel

_ti: Any = None


def taichi_available() -> bool:
    """Whether the ``taichi`` package is installed (``pip install '.[bench]'``)."""
    return importlib.util.find_spec("taichi") is not None


def taichi_module() -> Any:
    """The ``taichi`` module, initialised once per process on the CPU backend.

    The version check (a network request) and the import banner are switched off, and
    ``ti.init``'s "Starting on arch" line goes to stderr, so the benchmark's stdout is
    only its table. If the process already initialised taichi, that is kept.

    Raises
    ------
    ImportError
        If taichi is not installed.
    """
    global _ti
    if _ti is not None:
        return _ti
    os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")
    os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "0")
    with warnings.catch_warnings():  # taichi 1.7 calls the deprecated getdefaultlocale
        warnings.simplefilter("ignore", DeprecationWarning)
        import taichi as ti

    try:
        initialised = ti.lang.impl.get_runtime().prog is not None
    except Exception:  # private API changed: initialise ourselves
        initialised = False
    if not initialised:
        with contextlib.redirect_stdout(sys.stderr):
            ti.init(arch=ti.cpu, log_level="warn")
    _ti = ti
    return ti


def taichi_version() -> str:
    """``"1.7.4"``-style version of the installed taichi (``""`` if not installed)."""
    if not taichi_available():
        return ""
    from importlib.metadata import version

    return version("taichi")


def make_taichi_solver(model: SpringModel, dtype: str = "f32") -> Any:
    """A :class:`TaichiSpringSolver` of ``model`` (see :class:`TaichiSpringSolver`)."""
    return _solver_class()(model, dtype)


_SOLVER_CLASS: Any = None
_CLAMP: Any = None


def _clamp_func(ti: Any) -> Any:
    """The taichi function ``_clamp(b, o, n)`` both solvers use, defined once."""
    global _CLAMP
    if _CLAMP is None:

        @ti.func
        def _clamp(b, o: ti.template(), n: ti.template()):
            """Index ``b = a + o`` clamped into ``[0, n)`` (only the side ``o`` points to)."""
            if ti.static(o > 0):
                return ti.min(b, n - 1)
            elif ti.static(o < 0):
                return ti.max(b, 0)
            else:
                return b

        _CLAMP = _clamp
    return _CLAMP


def _solver_class() -> type:
    """Define the taichi solver class on first use (it needs taichi's decorators)."""
    global _SOLVER_CLASS
    if _SOLVER_CLASS is not None:
        return _SOLVER_CLASS
    ti = taichi_module()

    _clamp = _clamp_func(ti)

    @ti.data_oriented
    class TaichiSpringSolver:
        """Solver of :mod:`voxwarp.deform.elements.spring_model` in taichi (see the module doc).

        Same interface as :class:`voxwarp.deform.elements.massspring.CpuSpringSolver`:
        ``set_state``,
        ``set_constraints``, ``step``, ``positions``, ``velocities``, ``max_speed``.
        The grid, materials and springs are read from ``model`` once; ``dt``,
        ``integrator``, ``max_step``, ``spring_constant`` and ``spring_damping`` at
        every :meth:`step`.

        Parameters
        ----------
        model
            The spring model.
        dtype
            ``"f32"`` (as the GPU solver; the benchmark's choice) or ``"f64"``.
        """

        def __init__(self, model: SpringModel, dtype: str = "f32") -> None:
            if dtype not in ("f32", "f64"):
                raise ValueError(f"dtype must be 'f32' or 'f64'; got {dtype!r}")
            self.model = model
            self.shape: tuple[int, int, int] = model.shape
            self.dtype = dtype
            self._np = np.float32 if dtype == "f32" else np.float64
            real = ti.f32 if dtype == "f32" else ti.f64
            self._real = real
            shape = self.shape
            self._x = [ti.Vector.field(3, real, shape=shape) for _ in range(2)]
            self._v = [ti.Vector.field(3, real, shape=shape) for _ in range(2)]
            self._stiffness = ti.field(real, shape=shape)
            self._damping = ti.field(real, shape=shape)
            self._mass = ti.field(real, shape=shape)
            self._pinned = ti.field(ti.i32, shape=shape)
            self._target = ti.Vector.field(3, real, shape=shape)
            #: compile-time spring tables
            self._offsets = tuple(tuple(int(c) for c in o) for o in model.offsets.tolist())
            self._rest_lengths = tuple(float(r) for r in model.rest_lengths())
            self._min_length = float(model.min_length)
            self._rest_field = ti.field(real, shape=max(1, len(self._rest_lengths)))
            self._rest_field.from_numpy(self._cast(self._rest_lengths or (0.0,)))
            self._stiffness.from_numpy(self._cast(model.stiffness))
            self._damping.from_numpy(self._cast(model.damping))
            self._mass.from_numpy(self._cast(model.mass))
            self._cur = 0
            rest = np.asarray(model.rest, np.float64)
            self.set_state(rest, np.zeros_like(rest))

        def _cast(self, a: Any) -> np.ndarray:
            return np.ascontiguousarray(a, dtype=self._np)

        def _checked(self, a: Any, what: str) -> np.ndarray:
            arr = np.asarray(a, dtype=np.float64)
            if arr.shape != (*self.shape, 3):
                raise ValueError(f"{what} must have shape {(*self.shape, 3)}; got {arr.shape}")
            return arr

        # -------------------------------------------------------------- state
        def set_state(self, positions: np.ndarray, velocities: np.ndarray) -> None:
            """Replace the state ((n_x, n_y, n_z, 3) positions in mm, velocities in mm/s)."""
            self._x[self._cur].from_numpy(self._cast(self._checked(positions, "positions")))
            self._v[self._cur].from_numpy(self._cast(self._checked(velocities, "velocities")))

        def set_constraints(self, pinned: np.ndarray, targets: np.ndarray) -> None:
            """Pin elements at targets; pinned elements move there at once, at rest."""
            p = np.asarray(pinned, dtype=bool)
            if p.shape != self.shape:
                raise ValueError(f"pinned must have shape {self.shape}; got {p.shape}")
            t = self._checked(targets, "targets")
            self._pinned.from_numpy(p.astype(np.int32))
            self._target.from_numpy(self._cast(t))
            self._pin(self._x[self._cur], self._v[self._cur])

        def positions(self) -> np.ndarray:
            """(n_x, n_y, n_z, 3) float64 copy of the element positions (mm)."""
            return self._x[self._cur].to_numpy().astype(np.float64)

        def velocities(self) -> np.ndarray:
            """(n_x, n_y, n_z, 3) float64 copy of the element velocities (mm/s)."""
            return self._v[self._cur].to_numpy().astype(np.float64)

        def max_speed(self) -> float:
            """Largest element speed (mm/s)."""
            v = self.velocities()
            return float(np.sqrt(np.max(np.sum(v * v, axis=-1))))

        def sync(self) -> None:
            """Wait until the launched kernels are done (for timing)."""
            ti.sync()

        def release(self) -> None:
            """Nothing to free explicitly (taichi frees fields with the program)."""

        # -------------------------------------------------------------- physics
        def step(self, n: int = 1) -> None:
            """Advance ``n`` time steps of ``model.dt`` (one kernel launch per step)."""
            m = self.model
            if m.integrator not in INTEGRATORS:
                raise ValueError(f"unknown integrator {m.integrator!r}; use one of {INTEGRATORS}")
            if int(n) < 0:
                raise ValueError(f"step count must be >= 0; got {n}")
            semi = 1 if m.integrator == "semi-implicit" else 0
            args = (
                float(m.dt),
                float(m.spring_constant),
                float(m.spring_damping),
                float(m.max_step),
            )
            for _ in range(int(n)):
                src, dst = self._cur, 1 - self._cur
                self._step(self._x[src], self._v[src], self._x[dst], self._v[dst], *args, semi)
                self._cur = dst

        @ti.func
        def _rest_length_of(self, s: ti.template()):
            # a Python float in a kernel is a constant of taichi's default_fp (f32): exact
            # for f32, but in f64 the rest lengths come from a field to stay f64
            if ti.static(self.dtype == "f64"):
                return self._rest_field[s]
            else:
                return ti.static(self._rest_lengths[s])

        @ti.kernel
        def _pin(self, x: ti.template(), v: ti.template()):
            for i, j, k in self._pinned:
                if self._pinned[i, j, k] != 0:
                    x[i, j, k] = self._target[i, j, k]
                    v[i, j, k] = ti.Vector([0.0, 0.0, 0.0], dt=self._real)

        @ti.kernel
        def _step(
            self,
            xs: ti.template(),
            vs: ti.template(),
            xd: ti.template(),
            vd: ti.template(),
            dt_: ti.f64,
            spring_constant: ti.f64,
            spring_damping: ti.f64,
            max_step_: ti.f64,
            semi: ti.template(),
        ):
            real = self._real
            nx, ny, nz = self.shape
            dt = ti.cast(dt_, real)
            half_k = ti.cast(0.5 * spring_constant, real)
            kd = ti.cast(spring_damping, real)
            max_step = ti.cast(max_step_, real)
            zero = ti.Vector([0.0, 0.0, 0.0], dt=real)
            for i, j, k in xs:  # struct-for over the grid: one parallel loop
                xa = xs[i, j, k]
                va = vs[i, j, k]
                sa = self._stiffness[i, j, k]
                f = -self._damping[i, j, k] * va
                for s in ti.static(range(len(self._offsets))):
                    oi, oj, ok = ti.static(self._offsets[s])
                    bi, bj, bk = i + oi, j + oj, k + ok
                    # the neighbour clamped into the grid, weight 0 if it was outside (no
                    # spring) or |d| < min_length (d^ = 0): branch-free, ~15% faster than ifs
                    ci, cj, ck = _clamp(bi, oi, nx), _clamp(bj, oj, ny), _clamp(bk, ok, nz)
                    d = xs[ci, cj, ck] - xa
                    length = d.norm()
                    spring = (ci == bi) & (cj == bj) & (ck == bk) & (length >= self._min_length)
                    dh = d * (ti.select(spring, 1.0, 0.0) / ti.max(length, self._min_length))
                    along = (vs[ci, cj, ck] - va).dot(dh)
                    k_ab = half_k * (sa + self._stiffness[ci, cj, ck])
                    rest = self._rest_length_of(s)
                    f += (k_ab * (length - rest) + kd * along) * dh
                v_new = va + dt * f / self._mass[i, j, k]
                step_x = dt * va
                if ti.static(semi):
                    step_x = dt * v_new
                if max_step > 0:
                    size = step_x.norm()
                    if size > max_step:
                        scale = max_step / size
                        step_x *= scale
                        v_new *= scale
                x_new = xa + step_x
                if self._pinned[i, j, k] != 0:
                    x_new = self._target[i, j, k]
                    v_new = zero
                xd[i, j, k] = x_new
                vd[i, j, k] = v_new

    _SOLVER_CLASS = TaichiSpringSolver
    return TaichiSpringSolver


def make_minimal_taichi_solver(model: SpringModel) -> Any:
    """A :class:`MinimalTaichiSprings` of ``model`` (the lower bound the GPU step is held to)."""
    return _minimal_class()(model)


_MINIMAL_CLASS: Any = None


def _minimal_class() -> type:
    """Define the minimal taichi kernel's class on first use (it needs taichi)."""
    global _MINIMAL_CLASS
    if _MINIMAL_CLASS is not None:
        return _MINIMAL_CLASS
    ti = taichi_module()

    _clamp = _clamp_func(ti)

    @ti.data_oriented
    class MinimalTaichiSprings:
        """The least a mass-spring step can do: issue 19's reference for the GPU step.

        Float32 positions and velocities only (``ti.Vector.field(3)``, two of each,
        ping-pong; 24 bytes read and 24 written per element and step), the 6 structural
        springs with compile-time offsets and rest lengths, neighbours outside the grid
        clamped (on the side the spring points to) and weighted 0; ONE stiffness, damping
        and mass for the whole grid (the model's first element's, run-time scalars), no
        pinned elements, explicit Euler with the displacement clamp. Not the model of
        :class:`TaichiSpringSolver` (no per-element material, no pinning): a speed floor,
        not a reference for the physics.

        Parameters
        ----------
        model
            Grid shape, spacing, constants and the state it starts from (its rest).
        """

        def __init__(self, model: SpringModel) -> None:
            self.model = model
            self.shape: tuple[int, int, int] = model.shape
            spacing = [float(s) for s in np.asarray(model.spacing)]
            self._axes = tuple(
                (tuple(int(a == b) * sgn for b in range(3)), spacing[a])
                for a in range(3)
                for sgn in (-1, 1)
            )
            self._x = [ti.Vector.field(3, ti.f32, shape=self.shape) for _ in range(2)]
            self._v = [ti.Vector.field(3, ti.f32, shape=self.shape) for _ in range(2)]
            rest = np.ascontiguousarray(model.rest, np.float32)
            self._x[0].from_numpy(rest)
            self._v[0].from_numpy(np.zeros_like(rest))
            self._cur = 0

        def set_state(self, positions: np.ndarray, velocities: np.ndarray) -> None:
            """Replace the state ((n_x, n_y, n_z, 3) positions in mm, velocities in mm/s)."""
            self._x[self._cur].from_numpy(np.ascontiguousarray(positions, np.float32))
            self._v[self._cur].from_numpy(np.ascontiguousarray(velocities, np.float32))

        def positions(self) -> np.ndarray:
            """(n_x, n_y, n_z, 3) float64 copy of the element positions (mm)."""
            return self._x[self._cur].to_numpy().astype(np.float64)

        def sync(self) -> None:
            """Wait until the launched kernels are done (for timing)."""
            ti.sync()

        def release(self) -> None:
            """Nothing to free explicitly (taichi frees fields with the program)."""

        def step(self, n: int = 1) -> None:
            """Advance ``n`` time steps of ``model.dt`` (one kernel launch per step)."""
            m = self.model
            args = (
                float(m.dt),
                0.5 * float(m.spring_constant) * 2.0 * float(np.ravel(m.stiffness)[0]),
                float(m.spring_damping),
                float(np.ravel(m.damping)[0]),
                1.0 / float(np.ravel(m.mass)[0]),
                float(m.max_step),
            )
            for _ in range(int(n)):
                src, dst = self._cur, 1 - self._cur
                self._step(self._x[src], self._v[src], self._x[dst], self._v[dst], *args)
                self._cur = dst

        @ti.kernel
        def _step(
            self,
            xs: ti.template(),
            vs: ti.template(),
            xd: ti.template(),
            vd: ti.template(),
            dt: ti.f32,
            k: ti.f32,
            kd: ti.f32,
            damping: ti.f32,
            inv_mass: ti.f32,
            max_step: ti.f32,
        ):
            nx, ny, nz = self.shape
            for i, j, kk in xs:
                xa = xs[i, j, kk]
                va = vs[i, j, kk]
                f = -damping * va
                for s in ti.static(range(6)):
                    o = ti.static(self._axes[s][0])
                    rest = ti.static(self._axes[s][1])
                    bi, bj, bk = i + o[0], j + o[1], kk + o[2]
                    ci, cj, ck = _clamp(bi, o[0], nx), _clamp(bj, o[1], ny), _clamp(bk, o[2], nz)
                    d = xs[ci, cj, ck] - xa
                    length = d.norm()
                    inside = (ci == bi) & (cj == bj) & (ck == bk) & (length > 1e-12)
                    w = ti.select(inside, 1.0, 0.0)
                    dh = d * (w / ti.max(length, 1e-12))
                    f += (k * (length - rest) + kd * (vs[ci, cj, ck] - va).dot(dh)) * dh
                v_new = va + dt * inv_mass * f
                step_x = dt * va
                size = step_x.norm()
                scale = ti.select(size > max_step, max_step / ti.max(size, 1e-30), 1.0)
                xd[i, j, kk] = xa + scale * step_x
                vd[i, j, kk] = scale * v_new

    _MINIMAL_CLASS = MinimalTaichiSprings
    return MinimalTaichiSprings
