"""Mass-spring volume deformation: the user API and the CPU reference solver.

About this technique (Knoche 2008, 2.4, 3.5, 3.6)
--------------------------------------------------
An :class:`~voxwarp.deform.elements.grid.ElementGrid` of point masses spans the volume, joined by
springs (:mod:`voxwarp.deform.elements.spring_model` states the physics exactly). The user drags
elements (:meth:`MassSpring.move`); the springs pull the others along, and the
elements' displacements from rest form an *offset field* that the raycaster inverts
(:meth:`MassSpring.warp`), so the volume itself is never resampled.

Two solvers implement the same physics: :class:`CpuSpringSolver` here (numpy, float64,
the reference) and ``GpuSpringSolver`` in :mod:`voxwarp.deform.elements.massspring_gpu` (fragment
shaders, float32). :class:`MassSpring` drives either one through the same small
interface and never reads GPU state back except in :meth:`MassSpring.displacements`,
:meth:`MassSpring.energy` and :meth:`MassSpring.settle`.

Stable time step
----------------
Linearised about a state, every vibration mode of the grid is a damped oscillator
``x'' + gamma x' + omega^2 x = 0`` (per unit mass). Gershgorin's theorem bounds the
spring stiffness seen by one element by twice the sum of its springs' constants, so
``omega^2 <= omega2_max = 2 n k_max / m_min`` (``n`` spring offsets per element,
``k_max = spring_constant * max(stiffness)``) — valid also for stretched springs, whose
transverse stiffness ``k (1 - L/|d|)`` is below ``k``. Likewise
``gamma <= gamma_max = (max(damping) + 2 n spring_damping) / m_min``, and every mode is
damped at least by ``gamma_min = min(damping) / max(mass)`` (spring damping acts only
along springs, not on transverse modes).

* ``"explicit"`` Euler amplifies a mode unless ``dt < gamma / omega^2`` and
  ``dt gamma < 2`` (the Jury conditions of its 2x2 step matrix; an *undamped*
  oscillator grows for every ``dt``), so
  ``dt = 0.9 * min(gamma_min / omega2_max, 2 / gamma_max)``.
* ``"semi-implicit"`` (symplectic) Euler is stable while
  ``dt^2 omega^2 + 2 dt gamma < 4``; we take half the largest such ``dt`` for the
  worst case: ``dt = 0.5 * 4 / (gamma_max + sqrt(gamma_max^2 + 4 omega2_max))``.

With the defaults (stiffness 0.5, damping 1, mass 1, ``spring_constant`` 50,
``spring_damping`` 0.5, structural springs) that is 3.0 ms explicit and 47 ms
semi-implicit. A ``dt`` larger than :meth:`MassSpring.stable_time_step` is clamped to
it with a warning. The displacement clamp ``max_step`` (thesis 3.5.2, on by default)
additionally bounds how far any element moves in one step.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np

from voxwarp.deform.elements.grid import ElementGrid, Selection, grid_from_entry
from voxwarp.deform.elements.model import BACKENDS as BACKENDS
from voxwarp.deform.elements.model import (
    HELD_FORM,
    ElementWarpMixin,
    check_gpu_context,
    check_grid_and_backend,
    closed_on_error,
    held_entries,
    held_index,
    held_items,
)
from voxwarp.deform.elements.spring_model import INTEGRATORS, SpringModel
from voxwarp.deform.elements.switching import (
    SwitchReport,
    held_state,
    movement_report,
    switched_grid,
)
from voxwarp.errors import VoxwarpError

#: solver backends of :class:`MassSpring`
#: ``"type"`` of a mass-spring model in scene JSON (an offset-field warp's ``"model"``)
MODEL_TYPE = "massspring"

#: safety factors of :meth:`MassSpring.stable_time_step` (see the module doc)
_EXPLICIT_SAFETY = 0.9
_SEMI_IMPLICIT_SAFETY = 0.5
#: how often (steps) :meth:`MassSpring.settle` reads the maximum speed
_SETTLE_CHECK_EVERY = 50


class MassSpringError(VoxwarpError, ValueError):
    """A mass-spring model was given invalid parameters (the message names the fix)."""


def _axis_slices(o: np.ndarray, shape: tuple[int, int, int]) -> tuple[tuple, tuple] | None:
    """Slices of the elements ``a`` and their neighbours ``a + o`` inside the grid."""
    sa, sb = [], []
    for s, n in zip(o.tolist(), shape, strict=True):
        if abs(s) >= n:
            return None
        sa.append(slice(max(0, -s), n - max(0, s)))
        sb.append(slice(max(0, s), n - max(0, -s)))
    return tuple(sa), tuple(sb)


def _half_offsets(offsets: np.ndarray) -> np.ndarray:
    """The offsets whose first non-zero component is positive (one of each ± pair)."""
    keep = []
    for o in offsets:
        nz = o[np.nonzero(o)[0][0]]
        keep.append(nz > 0)
    return offsets[np.asarray(keep, dtype=bool)]


def spring_energy(model: SpringModel, positions: np.ndarray, velocities: np.ndarray) -> float:
    """Kinetic plus spring potential energy of a state of ``model``.

    Parameters
    ----------
    model
        The spring model (grid, materials, springs).
    positions, velocities
        (n_x, n_y, n_z, 3) state.

    Returns
    -------
    float
        ``sum 0.5 m |v|^2 + sum_springs 0.5 k_ab (|d| - L)^2``, each spring counted once
        (units: mass * mm^2 / s^2).
    """
    x = np.asarray(positions, dtype=np.float64)
    v = np.asarray(velocities, dtype=np.float64)
    mass = np.asarray(model.mass, dtype=np.float64)
    stiff = np.asarray(model.stiffness, dtype=np.float64)
    spacing = np.asarray(model.spacing, dtype=np.float64)
    e = 0.5 * float(np.sum(mass * np.sum(v * v, axis=-1)))
    for o in _half_offsets(model.offsets):
        sl = _axis_slices(o, model.shape)
        if sl is None:
            continue
        sa, sb = sl
        length = np.linalg.norm(x[sb] - x[sa], axis=-1)
        k = model.spring_constant * 0.5 * (stiff[sa] + stiff[sb])
        rest = float(np.linalg.norm(o * spacing))
        e += 0.5 * float(np.sum(k * (length - rest) ** 2))
    return e


class CpuSpringSolver:
    """Vectorised numpy (float64) solver of exactly the physics of
    :mod:`voxwarp.deform.elements.spring_model`.

    The materials, springs and grid are read from ``model`` once, at construction; the
    step parameters (``dt``, ``integrator``, ``max_step``, ``spring_constant``,
    ``spring_damping``) are read from ``model`` at every :meth:`step`.

    Parameters
    ----------
    model
        The spring model.
    ctx
        Ignored (the GPU solver's moderngl context; kept for the same interface).
    """

    def __init__(self, model: SpringModel, ctx: Any = None) -> None:
        self.model = model
        self.shape = model.shape
        self._rest = np.array(model.rest, dtype=np.float64).reshape((*self.shape, 3))
        self._mass = np.array(model.mass, dtype=np.float64)
        self._damping = np.array(model.damping, dtype=np.float64)
        stiff = np.array(model.stiffness, dtype=np.float64)
        spacing = np.asarray(model.spacing, dtype=np.float64)
        # one spring per ± pair: the force on b is minus the force on a (same k, |d|,
        # and (v_b - v_a) . d^), so each pair is computed once and applied to both ends
        self._springs: list[tuple[tuple, tuple, float, np.ndarray]] = []
        for o in _half_offsets(model.offsets):
            sl = _axis_slices(o, self.shape)
            if sl is None:
                continue
            sa, sb = sl
            rest = float(np.linalg.norm(o * spacing))
            self._springs.append((sa, sb, rest, 0.5 * (stiff[sa] + stiff[sb])))
        self._x = self._rest.copy()
        self._v = np.zeros_like(self._rest)
        self._pinned = np.zeros(self.shape, dtype=bool)
        self._targets = self._rest.copy()

    # ------------------------------------------------------------------ state
    def set_state(self, positions: np.ndarray, velocities: np.ndarray) -> None:
        """Replace the state.

        Parameters
        ----------
        positions, velocities
            (n_x, n_y, n_z, 3) arrays (mm, mm/s).
        """
        self._x = self._checked(positions, "positions").copy()
        self._v = self._checked(velocities, "velocities").copy()

    def set_constraints(self, pinned: np.ndarray, targets: np.ndarray) -> None:
        """Pin elements at targets; pinned elements move there at once, at rest.

        Parameters
        ----------
        pinned
            (n_x, n_y, n_z) bool: elements that do not move by themselves.
        targets
            (n_x, n_y, n_z, 3) where the pinned elements sit (other entries unused).
        """
        p = np.asarray(pinned, dtype=bool)
        if p.shape != self.shape:
            raise MassSpringError(f"pinned must have the grid shape {self.shape}; got {p.shape}")
        self._pinned = p.copy()
        self._targets = self._checked(targets, "targets").copy()
        self._x[p] = self._targets[p]
        self._v[p] = 0.0

    def _checked(self, a: np.ndarray, what: str) -> np.ndarray:
        arr = np.asarray(a, dtype=np.float64)
        if arr.shape != (*self.shape, 3):
            raise MassSpringError(
                f"{what} must have shape {(*self.shape, 3)} (grid shape + xyz); got {arr.shape}"
            )
        return arr

    def positions(self) -> np.ndarray:
        """(n_x, n_y, n_z, 3) float64 copy of the element positions (mm)."""
        return self._x.copy()

    def velocities(self) -> np.ndarray:
        """(n_x, n_y, n_z, 3) float64 copy of the element velocities (mm/s)."""
        return self._v.copy()

    def max_speed(self) -> float:
        """Largest element speed (mm/s)."""
        return float(np.sqrt(np.max(np.sum(self._v * self._v, axis=-1))))

    def displacement_texture(self) -> None:
        """The GPU solver's displacement texture; the CPU solver has none."""
        return None

    def release(self) -> None:
        """Free resources (nothing to free on the CPU)."""

    # ------------------------------------------------------------------ physics
    def accelerations(self, positions: np.ndarray, velocities: np.ndarray) -> np.ndarray:
        """Accelerations (n_x, n_y, n_z, 3) of all elements in the given state.

        Spring, spring-damping and element-damping forces divided by mass, exactly as in
        :mod:`voxwarp.deform.elements.spring_model` (constraints are not applied here).
        """
        x, v = positions, velocities
        m = self.model
        f = -self._damping[..., None] * v
        for sa, sb, rest, k_avg in self._springs:
            d = x[sb] - x[sa]
            length = np.sqrt(np.einsum("...i,...i->...", d, d))
            # d^ = d / |d|, and 0 where |d| < min_length
            inv = np.divide(
                1.0, length, out=np.zeros_like(length), where=length >= self.model.min_length
            )
            dh = d * inv[..., None]
            along = np.einsum("...i,...i->...", v[sb] - v[sa], dh)
            mag = m.spring_constant * k_avg * (length - rest) + m.spring_damping * along
            fa = mag[..., None] * dh
            f[sa] += fa
            f[sb] -= fa
        return f / self._mass[..., None]

    def step(self, n: int = 1) -> None:
        """Advance ``n`` time steps of ``model.dt``.

        Parameters
        ----------
        n
            Number of steps (>= 0).
        """
        m = self.model
        if m.integrator not in INTEGRATORS:
            raise MassSpringError(f"unknown integrator {m.integrator!r}; use one of {INTEGRATORS}")
        dt = float(m.dt)
        semi = m.integrator == "semi-implicit"
        max_step = float(m.max_step)
        pinned = self._pinned
        for _ in range(int(n)):
            x, v = self._x, self._v
            v_new = v + dt * self.accelerations(x, v)
            step_x = dt * (v_new if semi else v)
            if max_step > 0:
                length = np.sqrt(np.sum(step_x * step_x, axis=-1))
                scale = np.where(length > max_step, max_step / np.maximum(length, 1e-300), 1.0)
                step_x *= scale[..., None]
                v_new *= scale[..., None]
            x_new = x + step_x
            x_new[pinned] = self._targets[pinned]
            v_new[pinned] = 0.0
            self._x, self._v = x_new, v_new


class MassSpring(ElementWarpMixin):
    """Interactive mass-spring deformation of a volume (see the module doc).

    Parameters
    ----------
    grid
        The elements: rest positions, fixed elements and materials. Materials are read
        once, here; fixing and freeing later goes through :meth:`fix` / :meth:`free`.
    backend
        ``"cpu"`` (numpy reference) or ``"gpu"`` (needs ``ctx``).
    ctx
        moderngl context of the GPU backend.
    integrator
        ``"explicit"`` (Euler, the thesis' choice) or ``"semi-implicit"`` (symplectic
        Euler).
    dt
        Time step (s); ``None`` uses :meth:`stable_time_step`. A larger ``dt`` than
        that is clamped to it, with a warning.
    spring_constant
        Spring constant of two elements of stiffness 1 (> 0).
    spring_damping
        Damping of the relative velocity along each spring (>= 0).
    shear, bend
        Add shear (face-diagonal) and bend (second-neighbour) springs.
    max_step
        Largest displacement of an element in one step (mm, thesis 3.5.2); ``None``
        means half the smallest element spacing, 0 turns the clamp off.

    Examples
    --------
    >>> grid = ElementGrid(((0, 0, 0), (100, 100, 100)), shape=(6, 6, 6))
    >>> ms = MassSpring(grid)
    >>> ms.move((2, 2, 5), (0, 0, 15.0))     # drag an element 15 mm up
    >>> steps = ms.settle()
    >>> bool(ms.displacements()[2, 2, 4, 2] > 0)  # its neighbour followed
    True
    """

    model_type = MODEL_TYPE
    label = "mass-spring"
    error = MassSpringError
    #: how far :meth:`from_model` moved elements (None: not made by it)
    switch_report: SwitchReport | None = None

    def __init__(
        self,
        grid: ElementGrid,
        backend: str = "cpu",
        ctx: Any = None,
        integrator: str = "explicit",
        dt: float | None = None,
        spring_constant: float = 50.0,
        spring_damping: float = 0.5,
        shear: bool = False,
        bend: bool = False,
        max_step: float | None = None,
    ) -> None:
        check_grid_and_backend(grid, ElementGrid, backend, MassSpringError)
        if integrator not in INTEGRATORS:
            raise MassSpringError(
                f"unknown integrator {integrator!r}; valid integrators: {INTEGRATORS}"
            )
        check_gpu_context(backend, ctx, MassSpringError)
        spring_constant = _number(spring_constant, "spring_constant", positive=True)
        spring_damping = _number(spring_damping, "spring_damping", positive=False)
        if max_step is None:
            max_step = 0.5 * float(np.min(grid.spacing))
        max_step = _number(max_step, "max_step (0 turns the clamp off)", positive=False)
        self.grid = grid
        self.backend = backend
        self._model = SpringModel(
            rest=grid.rest_positions.copy(),
            spacing=grid.spacing.copy(),
            stiffness=grid.stiffness.copy(),
            damping=grid.damping.copy(),
            mass=grid.mass.copy(),
            spring_constant=spring_constant,
            spring_damping=spring_damping,
            shear=bool(shear),
            bend=bool(bend),
            integrator=integrator,
            max_step=max_step,
        )
        stable = self.stable_time_step()
        if dt is None:
            dt = stable
        else:
            dt = _number(dt, "dt", positive=True)
            if dt > stable:
                warnings.warn(
                    f"dt={dt:g} s exceeds the stable time step {stable:g} s of the "
                    f"{integrator} integrator; using dt={stable:g} s",
                    RuntimeWarning,
                    stacklevel=2,
                )
                dt = stable
        self._model.dt = dt
        self._held = np.zeros(grid.shape, dtype=bool)
        self._offsets = np.zeros((*grid.shape, 3), dtype=np.float64)
        self._warp: Any = None
        if backend == "gpu":
            # the GPU backend (moderngl) loads only when asked for
            from voxwarp.deform.elements.massspring_gpu import GpuSpringSolver

            self._solver: Any = GpuSpringSolver(self._model, ctx)
        else:
            self._solver = CpuSpringSolver(self._model)
        self._solver.set_state(self._model.rest, np.zeros_like(self._model.rest))
        self._sync_constraints()

    # ------------------------------------------------------------------ parameters
    @property
    def model(self) -> SpringModel:
        """The :class:`~voxwarp.deform.elements.spring_model.SpringModel` the solver runs."""
        return self._model

    @property
    def dt(self) -> float:
        """Time step (s)."""
        return float(self._model.dt)

    @property
    def integrator(self) -> str:
        """``"explicit"`` or ``"semi-implicit"``."""
        return self._model.integrator

    @property
    def max_step(self) -> float:
        """Displacement clamp per step (mm); 0 = off."""
        return float(self._model.max_step)

    @property
    def held(self) -> np.ndarray:
        """(n_x, n_y, n_z) bool copy: elements held by a drag (:meth:`move`)."""
        return self._held.copy()

    @property
    def held_offsets(self) -> np.ndarray:
        """(n_x, n_y, n_z, 3) copy: where held elements are held, as offsets from rest."""
        return self._offsets.copy()

    @classmethod
    def from_model(
        cls,
        other: Any,
        backend: str | None = None,
        ctx: Any = None,
        grid: ElementGrid | None = None,
        **settings: Any,
    ) -> MassSpring:
        """A mass-spring model that continues ``other``'s deformation (e.g. a
        :class:`~voxwarp.deform.elements.chainmail.ChainMail`; Knoche 2008, §5: always
        possible, springs have no geometric limits).

        Parameters
        ----------
        other
            An element model (:class:`~voxwarp.deform.elements.model.ElementModel` with
            ``held`` and ``held_offsets``).
        backend, ctx
            The new model's backend (default ``other``'s) and, for ``"gpu"``, its
            moderngl context.
        grid
            The elements (same shape and rest positions as ``other``'s; its materials
            are used); default a copy of ``other.grid``. The boundary conditions
            (anchor mode, region of influence, fixed, anchored and user-freed
            elements) come from ``other``'s grid either way.
        **settings
            The constructor's keywords (``integrator``, ``spring_constant``, ...).

        The positions are taken over exactly and the velocities start at 0; held
        elements stay held at their offsets. Not carried: cut links (springs join
        them again; :attr:`switch_report` counts them), and rigid (stiffness 1)
        elements go back to rest, where mass-spring pins them. :attr:`switch_report`
        says how far elements moved.
        """
        grid = switched_grid(other, grid, MassSpringError)
        held, offsets = held_state(other)
        positions = np.asarray(other.positions(), dtype=np.float64)
        ms = cls(grid, backend=backend or other.backend, ctx=ctx, **settings)
        with closed_on_error(ms):
            ms._held = held & ~ms._rest_pinned()
            ms._offsets = np.where(ms._held[..., None], offsets, 0.0)
            ms.set_state(positions)
            cuts = len(getattr(other, "cuts", ()))
            ms.switch_report = movement_report(positions, ms.positions(), cuts_joined=cuts)
        return ms

    def stable_time_step(self) -> float:
        """A conservative stable time step (s) for the current integrator.

        See the module doc for the derivation: with ``n`` springs per element,
        ``omega2 = 2 n spring_constant max(stiffness) / min(mass)``,
        ``gamma_max = (max(damping) + 2 n spring_damping) / min(mass)`` and
        ``gamma_min = min(damping) / max(mass)``:

        * explicit: ``0.9 * min(gamma_min / omega2, 2 / gamma_max)``;
        * semi-implicit: ``2 / (gamma_max + sqrt(gamma_max^2 + 4 omega2))``.

        Returns
        -------
        float
            The time step. Explicit Euler without element damping (``gamma_min = 0``)
            has no stable step once springs stretch; the semi-implicit value is used
            then and the displacement clamp keeps the motion bounded.
        """
        m = self._model
        n = len(m.offsets)
        mass = np.asarray(m.mass, dtype=np.float64)
        damping = np.asarray(m.damping, dtype=np.float64)
        k_max = m.spring_constant * float(np.max(m.stiffness))
        omega2 = 2.0 * n * k_max / float(mass.min())
        gamma_max = (float(damping.max()) + 2.0 * n * m.spring_damping) / float(mass.min())
        gamma_min = float(damping.min()) / float(mass.max())
        if omega2 <= 0:  # no spring force: only the damping limits the step
            return _SEMI_IMPLICIT_SAFETY * 2.0 / gamma_max if gamma_max > 0 else 1.0
        semi = _SEMI_IMPLICIT_SAFETY * 4.0 / (gamma_max + math.sqrt(gamma_max**2 + 4 * omega2))
        if m.integrator == "semi-implicit" or gamma_min <= 0:
            return semi
        return _EXPLICIT_SAFETY * min(gamma_min / omega2, 2.0 / gamma_max)

    # ------------------------------------------------------------------ constraints
    def fix(self, sel: Selection) -> None:
        """Fix elements at their rest positions (see :meth:`ElementGrid.fix`).

        Fixed elements that were held by a drag are released.
        """
        self.grid.fix(sel)
        self._held &= ~self.grid.fixed
        self._offsets[self.grid.fixed] = 0.0
        self._sync_constraints()

    def free(self, sel: Selection) -> None:
        """Unfix elements (see :meth:`ElementGrid.free`); held ones stay held."""
        self.grid.free(sel)
        self._sync_constraints()

    def move(self, sel: Selection, offsets: Any) -> None:
        """Drag elements: hold them at ``rest + offset`` until :meth:`release`.

        Parameters
        ----------
        sel
            A bool mask of the grid shape, one index ``(i, j, k)`` or (m, 3) indices.
        offsets
            World-space offsets (mm) from the *rest* positions: one (3,) offset for all
            selected elements, or (m, 3) offsets, one per index of ``sel``.

        Fixed and rigid (stiffness 1) elements in the selection are skipped: they stay
        at rest and are not held (free them first to drag them).

        Raises
        ------
        MassSpringError
            On offsets of the wrong shape or not finite.
        voxwarp.deform.elements.grid.ElementGridError
            On an index outside the grid.
        """
        try:
            off = np.asarray(offsets, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise MassSpringError("offsets must be numbers (mm)") from exc
        if not np.all(np.isfinite(off)):
            raise MassSpringError("offsets must be finite numbers (mm)")
        sel_arr = np.asarray(sel)
        movable = ~(self.grid.fixed | (np.asarray(self._model.stiffness) >= 1.0))
        if sel_arr.dtype == bool:
            mask = self.grid.mask(sel_arr) & movable
            if off.shape != (3,):
                raise MassSpringError(
                    f"move with a bool mask takes one (3,) offset; got shape {off.shape}"
                )
            self._offsets[mask] = off
            self._held |= mask
        else:
            idx = self.grid.indices(sel_arr)
            if off.shape == (3,):
                off = np.broadcast_to(off, idx.shape)
            if off.shape != idx.shape:
                raise MassSpringError(
                    f"offsets must be one (3,) offset or one per selected element "
                    f"{idx.shape}; got shape {off.shape}"
                )
            keep = movable[idx[:, 0], idx[:, 1], idx[:, 2]]
            idx, off = idx[keep], off[keep]
            self._offsets[idx[:, 0], idx[:, 1], idx[:, 2]] = off
            self._held[idx[:, 0], idx[:, 1], idx[:, 2]] = True
        self.grid.anchor_around(self._held, self._offsets)
        self._sync_constraints()
        self._update_warp()

    def release(self, sel: Selection = None) -> None:
        """Let held elements go (they move freely again unless fixed).

        Parameters
        ----------
        sel
            Elements to release (see :meth:`ElementGrid.mask`); ``None`` releases all.
        """
        mask = self.grid.mask(sel)
        self._held &= ~mask
        self._offsets[mask] = 0.0
        self.grid.anchor_around(self._held, self._offsets)
        self._sync_constraints()

    def _rest_pinned(self) -> np.ndarray:
        """Elements pinned at rest: fixed, anchored by the region of influence
        (:meth:`ElementGrid.anchor_around`, recomputed by every drag), or rigid
        (stiffness 1 in the model)."""
        return self.grid.constrained() | (np.asarray(self._model.stiffness) >= 1.0)

    def _pinned_and_targets(self) -> tuple[np.ndarray, np.ndarray]:
        rest_pinned = self._rest_pinned()
        pinned = rest_pinned | self._held
        targets = self._model.rest.copy()
        drag = self._held & ~rest_pinned
        targets[drag] += self._offsets[drag]
        return pinned, targets

    def _sync_constraints(self) -> None:
        pinned, targets = self._pinned_and_targets()
        self._solver.set_constraints(pinned, targets)

    # ------------------------------------------------------------------ simulation
    def step(self, n: int = 1) -> None:
        """Advance ``n`` time steps of :attr:`dt`."""
        if int(n) < 0:
            raise MassSpringError(f"step count must be >= 0; got {n}")
        self._solver.step(int(n))
        self._update_warp()

    def settle(self, max_steps: int = 2000, tol: float = 1e-3) -> int:
        """Step until every element is slower than ``tol`` (mm/s), or ``max_steps``.

        The speed is checked every 50 steps (one GPU read-back each time).

        Parameters
        ----------
        max_steps
            Most steps to take.
        tol
            Speed (mm/s) below which the grid counts as settled.

        Returns
        -------
        int
            Steps taken.
        """
        taken = 0
        while taken < max_steps:
            n = min(_SETTLE_CHECK_EVERY, max_steps - taken)
            self._solver.step(n)
            taken += n
            if self._solver.max_speed() < tol:
                break
        self._update_warp()
        return taken

    def reset(self) -> None:
        """Put every element back at rest, at rest; drags are kept and re-applied."""
        self._solver.set_state(self._model.rest, np.zeros_like(self._model.rest))
        self._sync_constraints()
        self._update_warp()

    # ------------------------------------------------------------------ results
    def positions(self) -> np.ndarray:
        """(n_x, n_y, n_z, 3) float64 element positions (mm; a GPU read-back)."""
        return np.asarray(self._solver.positions(), dtype=np.float64)

    def displacements(self) -> np.ndarray:
        """(n_x, n_y, n_z, 3) float32 displacements from rest (mm; a GPU read-back)."""
        return (self.positions() - self._model.rest).astype(np.float32)

    def velocities(self) -> np.ndarray:
        """(n_x, n_y, n_z, 3) float64 element velocities (mm/s; a GPU read-back): with
        :meth:`positions` the whole dynamic state, for :meth:`set_state` (undo)."""
        return np.asarray(self._solver.velocities(), dtype=np.float64)

    def energy(self) -> float:
        """Kinetic plus spring potential energy (see :func:`spring_energy`)."""
        return spring_energy(self._model, self.positions(), self._solver.velocities())

    def _update_warp(self) -> None:
        if self._warp is not None and self.backend == "cpu" and not self.defer_warp_updates:
            self._warp.update(self.displacements())

    # ------------------------------------------------------------------ serialisation
    def to_dict(self, include_positions: bool = False) -> dict[str, Any]:
        """JSON-serialisable description of the model (plain lists and numbers).

        Parameters
        ----------
        include_positions
            Also write ``"positions"``, the current element positions (a GPU
            read-back), so that :meth:`from_dict` resumes from this state.

        Returns
        -------
        dict
            ``grid`` (:meth:`ElementGrid.to_dict`: box, shape, fixed elements and the
            materials the solver runs), ``integrator``, ``dt``, ``spring_constant``,
            ``spring_damping``, ``shear``, ``bend``, ``max_step``, ``held`` (a list of
            ``{"index": [i, j, k], "offset": [dx, dy, dz]}``: held elements and their
            world-space offsets from rest in mm, see :meth:`move`) and, with
            ``include_positions``, ``positions`` ((n_x, n_y, n_z, 3) nested list, mm).
            The backend is not part of the model: :meth:`from_dict` chooses it.
        """
        m = self._model
        grid = self.grid.to_dict()
        for name in ("stiffness", "damping", "mass"):  # the materials the solver runs
            a = np.asarray(getattr(m, name), dtype=np.float32)
            grid[name] = float(a.flat[0]) if np.all(a == a.flat[0]) else a.tolist()
        where = np.argwhere(self._held)
        held = held_entries(where, self._offsets[tuple(where.T)])
        d: dict[str, Any] = {
            "grid": grid,
            "integrator": self.integrator,
            "dt": self.dt,
            "spring_constant": float(m.spring_constant),
            "spring_damping": float(m.spring_damping),
            "shear": bool(m.shear),
            "bend": bool(m.bend),
            "max_step": self.max_step,
            "held": held,
        }
        if include_positions:
            d["positions"] = self.positions().tolist()
        return d

    @classmethod
    def from_dict(
        cls,
        d: Mapping[str, Any],
        backend: str = "cpu",
        ctx: Any = None,
        positions: Any = None,
    ) -> MassSpring:
        """Rebuild a model from :meth:`to_dict`'s form.

        Parameters
        ----------
        d
            Mapping with ``grid`` (required) and optionally ``integrator``, ``dt``,
            ``spring_constant``, ``spring_damping``, ``shear``, ``bend``, ``max_step``
            (the constructor's defaults when absent), ``held`` and ``positions``. A
            ``"type"`` key (scene JSON's ``"massspring"``) is accepted.
        backend, ctx
            Solver backend and, for ``"gpu"``, its moderngl context.
        positions
            (n_x, n_y, n_z, 3) positions (mm) to resume from; overrides
            ``d["positions"]``. Velocities start at 0. Without positions the elements
            start at rest. Held elements sit at ``rest + offset`` either way.

        Returns
        -------
        MassSpring

        Raises
        ------
        MassSpringError
            On a missing or malformed key; the message names the key and the fix.
        """
        return cls._from_entry(d, backend, ctx, positions)

    @classmethod
    def _entry_parts(cls, d: Mapping[str, Any]) -> tuple[ElementGrid, dict[str, Any], Any]:
        grid = _grid_from(d)
        kwargs: dict[str, Any] = {}
        for key in ("integrator", "dt", "spring_constant", "spring_damping", "max_step"):
            if key in d:
                kwargs[key] = d[key]
        for key in ("shear", "bend"):
            if key in d:
                if not isinstance(d[key], bool):
                    raise MassSpringError(
                        f"massspring '{key}' must be true or false; got {d[key]!r:.40}"
                    )
                kwargs[key] = d[key]
        return grid, kwargs, None

    @classmethod
    def _entry_held(cls, held: Any, grid: ElementGrid) -> list[tuple[Any, np.ndarray]]:
        return _parse_held(held, grid)  # type: ignore[return-value]

    def _resume(self, extra: Any, held: list[tuple[Any, np.ndarray]], positions: Any) -> None:
        if positions is not None:
            self.set_state(positions)
        for idx, off in held:
            self.move(idx, off)

    def set_state(self, positions: Any, velocities: Any = None) -> None:
        """Replace the element positions (and velocities; default 0).

        Held, fixed and rigid elements are put back at their targets at once.

        Parameters
        ----------
        positions
            (n_x, n_y, n_z, 3) positions in world mm.
        velocities
            (n_x, n_y, n_z, 3) velocities in mm/s; ``None`` means at rest.

        Raises
        ------
        MassSpringError
            On a wrong shape or values that are not finite numbers.
        """
        shape = (*self.grid.shape, 3)
        arrays = []
        for name, value in (("positions", positions), ("velocities", velocities)):
            if value is None and name == "velocities":
                arrays.append(np.zeros(shape))
                continue
            try:
                a = np.asarray(value, dtype=np.float64)
            except (TypeError, ValueError) as exc:
                raise MassSpringError(
                    f"{name} must be an array of numbers of shape {shape}"
                ) from exc
            if a.shape != shape:
                raise MassSpringError(
                    f"{name} must have shape {shape} (grid shape + xyz); got {a.shape}"
                )
            if not np.all(np.isfinite(a)):
                raise MassSpringError(f"{name} must be finite numbers")
            arrays.append(a)
        self._solver.set_state(arrays[0], arrays[1])
        self._sync_constraints()
        self._update_warp()

    def __repr__(self) -> str:
        return (
            f"MassSpring(shape={self.grid.shape}, backend={self.backend!r}, "
            f"integrator={self.integrator!r}, dt={self.dt:g}, held={int(self._held.sum())})"
        )


def _number(value: Any, what: str, *, positive: bool) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError) as exc:
        raise MassSpringError(f"{what} must be a number; got {value!r:.40}") from exc
    if not math.isfinite(x) or (x <= 0 if positive else x < 0):
        raise MassSpringError(f"{what} must be {'> 0' if positive else '>= 0'}; got {x!r}")
    return x


def _grid_from(d: Mapping[str, Any]) -> ElementGrid:
    """The ``"grid"`` of a massspring entry as an :class:`ElementGrid`."""
    return grid_from_entry(d, MODEL_TYPE, MassSpringError)


def _parse_held(held: Any, grid: ElementGrid) -> list[tuple[tuple[int, int, int], np.ndarray]]:
    """Validate a ``"held"`` list: ``[{"index": [i, j, k], "offset": [dx, dy, dz]}, ...]``."""
    pinned = grid.pinned()
    out = []
    for where, entry in held_items(held, MODEL_TYPE, MassSpringError):
        if not isinstance(entry, Mapping):
            raise MassSpringError(f"{where} must be an object; {HELD_FORM}; got {entry!r:.80}")
        missing = [k for k in ("index", "offset") if k not in entry]
        if missing:
            raise MassSpringError(f"{where} needs the keys {missing}; {HELD_FORM}")
        raw = held_index(entry["index"], where, MassSpringError)
        idx = tuple(int(v) for v in raw)
        if any(v < 0 or v >= s for v, s in zip(idx, grid.shape, strict=True)):
            raise MassSpringError(
                f"{where} 'index' {idx} is outside the grid of shape {grid.shape}; indices"
                f" run from (0, 0, 0) to {tuple(s - 1 for s in grid.shape)}"
            )
        if pinned[idx]:
            why = "fixed" if grid.fixed[idx] else "rigid (stiffness 1)"
            raise MassSpringError(
                f"{where}: element {idx} is {why} and cannot be held; remove it from"
                " 'held' or free it in 'grid'"
            )
        try:
            off = np.asarray(entry["offset"], dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise MassSpringError(f"{where} 'offset' must be 3 numbers [dx, dy, dz] (mm)") from exc
        if off.shape != (3,) or not np.all(np.isfinite(off)):
            raise MassSpringError(
                f"{where} 'offset' must be 3 finite numbers [dx, dy, dz] (mm);"
                f" got {entry['offset']!r:.80}"
            )
        out.append((idx, off))
    return out
