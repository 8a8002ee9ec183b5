"""3D ChainMail volume deformation: the user API and the CPU solver.

About this technique (Gibson 1997, "3D ChainMail"; Schill et al. 1998, "Enhanced
ChainMail"; Knoche 2008, 2.4.2.2, 3.5.3)
------------------------------------------------------------------------------------
The elements of an :class:`~voxwarp.deform.elements.grid.ElementGrid` are linked to their 6
neighbours like the rings of a chain mail (:mod:`voxwarp.deform.elements.chainmail_model` states the
constraints exactly): per element and axis ``i`` a least and a largest distance
``min_i <= d_i <= max_i`` and a largest shear ``|d_j| <= shear_i`` (``d = x_b - x_a``
for ``b = a + e_i``, world mm; a link uses the mean of its two elements' limits). The
user drags elements (:meth:`ChainMail.move`); a dragged element moves freely within
the slack of its links and pulls or pushes its neighbours once a link is taut, and
those their neighbours, so that after every move **every link satisfies its limits**
and fixed elements have not moved. The displacements form an offset field that the
raycaster inverts (:meth:`ChainMail.warp`), exactly as for
:class:`~voxwarp.deform.elements.massspring.MassSpring`.

Limits from the material map
----------------------------
By default the limits follow the grid's stiffness ``k`` in [0, 1] (e.g. from
:meth:`ElementGrid.materials_from_volume`), with ``slack = 1 - k`` per element and
``s_i`` the rest spacing along axis ``i``::

    min_i = s_i (1 - stretch * slack)     max_i = s_i (1 + stretch * slack)
    shear_i = s_i * shear * slack

``stretch = shear = 0.5`` by default: stiffness 0 stretches or compresses a link by
half a spacing and shears it by half a spacing, the default stiffness 0.5 by a quarter;
stiffness 1 is **rigid** (no slack: such material moves as a rigid body, it is not
pinned as in the mass-spring model; only ``fixed`` elements never move).
:meth:`ChainMail.set_limits` sets any limits, per element and per axis (anisotropic
materials such as muscle, heterogeneous ones); the rest state must satisfy them.

Moves
-----
:meth:`ChainMail.move` puts the dragged elements at ``rest + offset`` (as
:meth:`MassSpring.move <voxwarp.deform.elements.massspring.MassSpring.move>`) and **holds** them
there
until :meth:`ChainMail.release`: later moves and relaxation treat held elements like
fixed ones. The constraints are then restored by moving every other element *as little
as possible*. If that would need a fixed or held element to move (the drag pulls
against them further than the slack between allows), the move is **limited**: the
dragged elements go the largest fraction ``t`` of the way from their positions to their
targets for which the propagation succeeds (found by bisection, to within
``2**-LIMIT_BISECTIONS`` of the way) and are held where they stopped;
:attr:`MoveStats.fraction` reports ``t``. A move that stays within the slack moves
nothing else (:attr:`MoveStats.touched` is 1).

Variants
--------
* ``"gibson"`` (Gibson 1997): the dragged element *sponsors* its neighbours. Six FIFO
  candidate lists, one per neighbour direction (+x, -x, +y, -y, +z, -z), are processed
  in rotation, each until empty. An element taken from a list is checked against its
  sponsor only; if the link is violated, it moves to the nearest position within the
  sponsor's constraint box and queues its neighbours: an element of an x list its
  neighbour further along x and its y and z neighbours, one of a y list further along y
  and its z neighbours, one of a z list further along z (never its sponsor). An element
  is moved at most once per move; an element found inside its slack stops the wave.
  For a homogeneous material this is exact; with heterogeneous limits, or with several
  dragged or held elements, a single sponsor can leave a link to a *non*-sponsor
  neighbour violated. The **cleanup** then continues with the priority queue of
  ``"enhanced"`` from every violated link of a moved element (the element that moved
  less follows), until no link is violated; :attr:`MoveStats.cleanup` counts its
  corrections (0 in homogeneous materials; in the heterogeneous random drags of
  ``tests/deform/elements/test_chainmail.py`` a few per move).
* ``"enhanced"`` (Schill et al. 1998): one priority queue of (element, coordinate)
  entries ordered by how far the entry asks the element to move; the largest goes
  first and moves the element to the nearest value allowed by *all* its links
  (when they conflict, the side it was pushed to); neighbours whose link it then
  violates are queued. Because the constraints are difference bounds per coordinate
  (see :mod:`voxwarp.deform.elements.chainmail_cpu`), this is Dijkstra's order for a single drag:
  every
  element is settled by its most demanding neighbour first, also in heterogeneous
  materials.

For a single dragged element both variants end in the same state, the least motion of
every element that satisfies the constraints (each coordinate of each element moves
only in the direction of the drag, and no further than some chain of taut links
demands); they differ in the work done (:attr:`MoveStats.checks`).

Relaxation
----------
:meth:`ChainMail.relax` (or ``relax_steps`` after every move) runs Gauss-Seidel sweeps
of *constrained Laplacian smoothing* of the displacement ``u = x - rest``: every free,
non-held element moves, per coordinate, to ``rest + mean(u)`` of its linked neighbours,
clamped into the interval its links allow with the neighbours where they are. That is
the exact minimiser, within the constraints, of the smoothness energy
``E = sum_links |u_b - u_a|^2`` (:meth:`ChainMail.smoothness_energy`) over that
element, so ``E`` never grows and the constraints stay satisfied. A red-black
colouring makes one step two parallel half-sweeps (colour ``(i + j + k) % 2`` 0, then
1). The thesis shows 0, 1 and 4 steps (Knoche 2008, 2.4.2.2.1: every element is
adjusted once per step, e.g. to the centre of its neighbours; a few steps suffice).

An element whose neighbours and itself are unchanged since it was last at the rule's
fixed point stays there, so a half-sweep can change only elements in the previous
half-sweep's box grown by one element
(:func:`~voxwarp.deform.elements.chainmail_model.relax_boxes`). *Full* relaxation (the
default) starts from the box of every element displaced since the last
:meth:`~ChainMail.reset` (at rest, everything else is at the fixed point), which gives
exactly the result of half-sweeps over the whole grid. Both backends sweep the same
boxes: the CPU with the numba kernel (float64), the GPU with one fragment-shader draw
per half-sweep (``shaders/chainmail_relax.frag.glsl``, float32, ping-pong, nothing read
back); they agree to float32 round-off (``tests/deform/elements/test_chainmail_relax.py``
asks for 1e-4 mm).

Local relaxation
----------------
The thesis' outlook (Knoche 2008, 5) proposes relaxing only the elements the ChainMail
propagation moved, for speed. ``relax(steps, local=True)`` (or ``relax_local=True``)
starts the half-sweeps from the box of the elements changed since the first move after
the last relaxation (moved, released, freed, re-anchored or next to a cut; a change of
limits counts as the whole grid) instead of every displaced element. It equals full
relaxation when the elements outside that box were at the rule's fixed point: after a
drag from rest (then the boxes are the same), or after a relaxation run to convergence
(to the convergence's own tolerance). It differs when an earlier deformation was left
unconverged, e.g. by ``relax_steps = 4`` after every drag: full relaxation goes on
smoothing the earlier drags, local relaxation leaves them as they are. So it is an
option, not the default; it is saved in scene JSON (``"relax_local": true``).

Cutting and joining
-------------------
:meth:`ChainMail.cut` removes the links whose segment between the two elements'
*current* positions crosses a plane (or a disk of radius ``extent`` on it);
:meth:`ChainMail.cut_pairs` removes links between given neighbour pairs. The parts on
either side then move independently. Removing a link never violates anything, so the
state stays valid. Scene JSON stores the removed links (:attr:`ChainMail.cuts`).

Links "can be removed to cut, and conversely added to connect different tissues"
(Knoche 2008, 2.4.2.2): :meth:`ChainMail.link_pairs` and :meth:`ChainMail.link` are the
inverses of ``cut_pairs`` and ``cut``. A link exists only between grid neighbours, so
joining restores a link of the grid's structure: a model cut and linked again is the
uncut model (same links, same moves). Regions that were never linked (a model loaded
with ``cuts``) are joined the same way. A removed link whose elements have drifted
beyond its limits (a drag pulled the sides apart) is *stretched*; joining it as it is
would leave a violated constraint, so ``stretched`` (:data:`STRETCHED`) decides:

* ``"refuse"`` (the default of ``link_pairs``): an error naming how many links, the
  worst and by how many mm; nothing changes.
* ``"skip"`` (the default of ``link`` and of the GUI's join): only the links whose
  elements touch are joined, the others stay cut; nothing moves.
* ``"pull"``: a suture. The worst stretched link first, one of its ends is dragged to
  the nearest position the link allows (the upper-index end, or the lower one when
  that is held, fixed or blocked), its tissue following by the usual propagation
  (held and fixed elements stay), and every link that then touches is joined; repeated
  until all are joined. If neither end of a link can get there, nothing changes and
  an error says so. (A repair of the whole state, as :meth:`ChainMail.set_limits`
  does, is meant for round-off and gives up on gaps of a few millimetres.) On the GPU
  backend this runs on the CPU, on read-back positions, as :meth:`ChainMail.relax`.

Only ``"pull"`` moves elements; a join never violates a link.

Why numba
---------
Propagation is a sequential, data-dependent queue walk that numpy cannot vectorise, and
pure Python loops do not get a local drag on 128³ elements under 100 ms; the kernels
in :mod:`voxwarp.deform.elements.chainmail_cpu` are
``numba.njit(cache=True, nogil=True)``, imported on first use (so ``import deform`` does
not pay for numba).

Backends
--------
``backend="cpu"`` runs the kernels above (float64). ``backend="gpu"`` drives
``voxwarp.deform.elements.chainmail_gpu.GpuChainMailSolver`` (created lazily) through
``set_positions``,
``enforce(held_mask, held_targets, max_passes) -> passes``, ``last_changed`` (the box
that enforce changed), ``feasible`` (a check pass over the region the enforce
changed), ``relax(box, steps) -> box`` (the relaxation's half-sweeps),
``snapshot()``/``restore()`` (GPU copies of the state), ``positions()``,
``displacement_texture()``, ``revision`` and ``release()``;
limits, cuts and fixed elements reach it by rebuilding the solver from the model. A
drag the GPU cannot satisfy is limited as on the CPU: the state is restored and the
largest feasible fraction found by bisection (feasibility depends only on where the
pinned elements are, so the GPU's result and the CPU's fraction agree).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from voxwarp.deform.elements.chainmail_model import (
    VIOLATION_TOL_MM,
    Box,
    ChainMailError,
    ChainMailModel,
    check_limits,
    relax_boxes,
    union_box,
)
from voxwarp.deform.elements.grid import ElementGrid, ElementGridError, Selection, grid_from_entry
from voxwarp.deform.elements.limits_projection import project_onto_limits
from voxwarp.deform.elements.model import (
    BACKENDS,
    HELD_FORM,
    ElementWarpMixin,
    check_gpu_context,
    check_grid_and_backend,
    closed_on_error,
    held_entries,
    held_index,
    held_items,
)
from voxwarp.deform.elements.switching import (
    SwitchReport,
    held_state,
    movement_report,
    switched_grid,
)

__all__ = [
    "BACKENDS",
    "MODEL_TYPE",
    "STRETCHED",
    "VARIANTS",
    "ChainMail",
    "ChainMailError",
    "MoveStats",
    "limits_from_stiffness",
    "neighbour_pairs",
]

#: propagation variants of :class:`ChainMail`
VARIANTS: tuple[str, ...] = ("gibson", "enhanced")
#: solver backends of :class:`ChainMail`
#: ``"type"`` of a ChainMail model in scene JSON (an offset-field warp's ``"model"``)
MODEL_TYPE = "chainmail"
#: default largest relative stretch/compression of a stiffness-0 element's links
DEFAULT_STRETCH = 0.5
#: default largest shear, in spacings, of a stiffness-0 element's links
DEFAULT_SHEAR = 0.5
#: what :meth:`ChainMail.link_pairs` does with a link its elements violate where they are
STRETCHED: tuple[str, ...] = ("refuse", "skip", "pull")
#: a link to join whose elements are within its limits to this many mm touches (CPU:
#: float64 round-off, :data:`VIOLATION_TOL_MM`; GPU: float32 positions, the tolerance of
#: its feasibility check, ``chainmail_gpu.CHECK_TOL_MM``)
_JOIN_TOL_MM = {"cpu": VIOLATION_TOL_MM, "gpu": 1e-4}
#: bisection steps of a limited move (the fraction is found to within 2**-14)
LIMIT_BISECTIONS = 14
#: the priority queue gives up (the move counts as infeasible) after this many pops
#: per element and coordinate
_POPS_PER_COORDINATE = 32
#: tolerance of the rest-state check of :meth:`ChainMail.set_limits` (relative to the
#: spacing; the last element layer sits on the box face, off by round-off)
_REST_TOL = 1e-9


@dataclass(frozen=True)
class MoveStats:
    """What one :meth:`ChainMail.move` did.

    Attributes
    ----------
    touched
        Elements whose position changed, the dragged ones included (-1 on the GPU
        backend, which does not count them).
    seconds
        Wall time of the solve (propagation and, for a limited move, the bisection;
        not the warp update nor ``relax_steps``).
    fraction
        Fraction of the way to their targets the dragged elements went: 1, or less
        when fixed or held elements limited the move.
    checks
        Constraint checks: candidate-list entries and priority-queue pops.
    cleanup
        ``"gibson"``: element-coordinate corrections made by the cleanup after the
        sponsor lists (0 when Gibson's single sponsors sufficed); ``"enhanced"``:
        corrections made by the priority queue.
    attempts
        Propagations run (1, or 2 + the bisection steps for a limited move).
    passes
        GPU backend: constraint passes the solver ran (0 on the CPU).
    """

    touched: int
    seconds: float
    fraction: float = 1.0
    checks: int = 0
    cleanup: int = 0
    attempts: int = 1
    passes: int = 0

    @property
    def limited(self) -> bool:
        """True when the dragged elements stopped short of their targets."""
        return self.fraction < 1.0


def limits_from_stiffness(
    spacing: Any,
    stiffness: Any,
    stretch: float = DEFAULT_STRETCH,
    shear: float = DEFAULT_SHEAR,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per element and axis ``(min_dist, max_dist, max_shear)`` from a stiffness map.

    Parameters
    ----------
    spacing
        (3,) rest spacing per axis (mm).
    stiffness
        (nx, ny, nz) stiffness in [0, 1]; ``slack = 1 - stiffness``.
    stretch, shear
        Relative stretch/compression and shear (in spacings) of a stiffness-0 element.

    Returns
    -------
    tuple of numpy.ndarray
        Three (nx, ny, nz, 3) float64 arrays: ``s (1 - stretch slack)``,
        ``s (1 + stretch slack)`` and ``s shear slack``.
    """
    stretch = _number(stretch, "stretch", lo=0.0, hi=1.0)
    shear = _number(shear, "shear", lo=0.0, hi=math.inf)
    s = np.asarray(spacing, dtype=np.float64).reshape(3)
    slack = (1.0 - np.clip(np.asarray(stiffness, dtype=np.float64), 0.0, 1.0))[..., None]
    return s * (1.0 - stretch * slack), s * (1.0 + stretch * slack), s * (shear * slack)


def _kernels() -> Any:
    from voxwarp.deform.elements import chainmail_cpu  # numba: loaded when first used

    return chainmail_cpu


class ChainMail(ElementWarpMixin):
    """Interactive 3D ChainMail deformation of a volume (see the module doc).

    Parameters
    ----------
    grid
        The elements: rest positions, fixed elements and the stiffness the default
        limits come from. Fixing and freeing later goes through :meth:`fix` /
        :meth:`free` (which also change ``grid.fixed``).
    variant
        ``"gibson"`` (sponsor lists) or ``"enhanced"`` (priority queue).
    backend
        ``"cpu"`` (numba kernels, float64) or ``"gpu"`` (needs ``ctx``).
    ctx
        moderngl context of the GPU backend.
    stretch, shear
        Default limits from the grid's stiffness (:func:`limits_from_stiffness`).
    relax_steps
        Relaxation steps (:meth:`relax`) run after every :meth:`move`.
    relax_local
        Default of :meth:`relax`'s ``local``: relax only around the elements moved
        since the last relaxation (see the module doc, "Local relaxation").

    Examples
    --------
    >>> grid = ElementGrid(((0, 0, 0), (70, 70, 70)), shape=8)   # 10 mm spacing
    >>> cm = ChainMail(grid)
    >>> stats = cm.move((4, 4, 4), (20.0, 0, 0))   # drag an element 20 mm along x
    >>> stats.touched > 1, cm.violation() <= 1e-6
    (True, True)
    """

    model_type = MODEL_TYPE
    label = "ChainMail"
    error = ChainMailError
    #: how far :meth:`from_model` moved elements (None: not made by it)
    switch_report: SwitchReport | None = None

    def __init__(
        self,
        grid: ElementGrid,
        variant: str = "enhanced",
        backend: str = "cpu",
        ctx: Any = None,
        stretch: float = DEFAULT_STRETCH,
        shear: float = DEFAULT_SHEAR,
        relax_steps: int = 0,
        relax_local: bool = False,
    ) -> None:
        check_grid_and_backend(grid, ElementGrid, backend, ChainMailError)
        check_gpu_context(backend, ctx, ChainMailError)
        self.grid = grid
        self.backend = backend
        self._ctx = ctx
        self._variant = _variant(variant)
        self.relax_steps = relax_steps
        self.relax_local = relax_local
        mn, mx, sh = limits_from_stiffness(grid.spacing, grid.stiffness, stretch, shear)
        self._model = ChainMailModel(
            rest=grid.rest_positions.copy(),
            spacing=grid.spacing.copy(),
            min_dist=mn,
            max_dist=mx,
            max_shear=sh,
            links=np.ones((*grid.shape, 3), dtype=bool),
            fixed=grid.constrained(),
        )
        self._check_rest()
        n = grid.count
        self._rest = self._model.rest.reshape(n, 3)
        self._x = self._rest.copy()
        self._held = np.zeros(n, dtype=bool)
        self._offsets = np.zeros((n, 3), dtype=np.float64)
        self._pinned = self._model.fixed.reshape(n).copy()
        _, ny, nz = grid.shape
        self._strides = np.array([ny * nz, nz, 1], dtype=np.int64)
        # scratch of the kernels: never cleared (epochs), pages touched only when used
        self._mark = np.zeros(n, dtype=np.int64)
        self._slot = np.zeros(n, dtype=np.int64)
        self._t_idx = np.empty(n, dtype=np.int64)
        self._t_old = np.empty((n, 3), dtype=np.float64)
        self._epoch = 0
        self._recorded = 0
        # box holding every element displaced since the last reset (None: none is) ...
        self._box: Box | None = None
        # ... and every element changed since the first move after the last relaxation:
        # where a local relaxation starts (see the module doc)
        self._active: Box | None = None
        self._relaxed = False  # a relaxation ran since the last move
        self._warp: Any = None
        self._solver: Any = None
        if backend == "gpu":
            self._solver = self._make_gpu_solver()
            self._solver.set_positions(self._model.rest.copy())

    @classmethod
    def from_model(
        cls,
        other: Any,
        backend: str | None = None,
        ctx: Any = None,
        grid: ElementGrid | None = None,
        **settings: Any,
    ) -> ChainMail:
        """A ChainMail that continues ``other``'s deformation (e.g. a
        :class:`~voxwarp.deform.elements.massspring.MassSpring`), moved as little as
        possible onto the ChainMail limits (Knoche 2008, §5: a mass-spring state in
        general breaks them).

        Parameters
        ----------
        other
            An element model (:class:`~voxwarp.deform.elements.model.ElementModel` with
            ``held`` and ``held_offsets``).
        backend, ctx
            The new model's backend (default ``other``'s) and, for ``"gpu"``, its
            moderngl context.
        grid
            The elements (same shape and rest positions as ``other``'s; its stiffness
            gives the limits); default a copy of ``other.grid``. The boundary
            conditions (anchor mode, region of influence, fixed, anchored and
            user-freed elements) come from ``other``'s grid either way.
        **settings
            The constructor's keywords (``variant``, ``stretch``, ``shear``,
            ``relax_steps``).

        The positions are projected onto the limits with the least movement (sum of
        squared distances; :func:`~voxwarp.deform.elements.limits_projection.project_onto_limits`),
        fixed, anchored and held elements staying put; held elements stay held, and
        the cut links of a ChainMail ``other`` stay cut. If that cannot meet the
        limits (the held elements dragged further from the anchored or fixed ones, or
        from each other, than the links allow), the region of influence's anchors are
        freed (the next drag anchors again) and, if that is not enough either, the held
        elements are released; the projection then runs again.
        A propagation then removes what round-off the projection left.
        :attr:`switch_report` says how far elements moved.

        Raises
        ------
        ChainMailError
            On a grid that is not ``other``'s, bad settings, or limits that cannot be
            met with the fixed and anchored elements at rest.
        """
        grid = switched_grid(other, grid, ChainMailError)
        held, offsets = held_state(other)
        positions = np.asarray(other.positions(), dtype=np.float64)
        cm = cls(grid, backend=backend or other.backend, ctx=ctx, **settings)
        with closed_on_error(cm):
            cm._cut_links(np.asarray(getattr(other, "cuts", ()), dtype=np.int64).tolist())
            held &= ~cm._model.fixed
            freed = released = 0
            if not cm._reachable(held, offsets):
                freed = cm._drop_anchors()
            if not cm._reachable(held, offsets):
                released, held = int(held.sum()), np.zeros_like(held)
            try:
                sweeps, before = cm._project_from(positions, held, offsets)
            except ChainMailError:  # not expected: the held elements were reachable
                released, held = released + int(held.sum()), np.zeros_like(held)
                sweeps, before = cm._project_from(positions, held, offsets)
            cm.switch_report = movement_report(
                positions,
                cm.positions(),
                violation_before=before,
                sweeps=sweeps,
                anchors_freed=freed,
                released=released,
            )
        return cm

    def _reachable(self, held: np.ndarray, offsets: np.ndarray) -> bool:
        """Whether a drag of ``held`` to ``offsets`` from rest meets the limits with the
        fixed elements at rest (a trial propagation; this model must be at rest)."""
        flat = np.flatnonzero(held)
        if flat.size == 0:
            return True
        pinned = self._pinned
        self._pinned = self._model.fixed.reshape(-1) | held.reshape(-1)
        try:
            target = self._rest[flat] + offsets.reshape(-1, 3)[flat]
            ok, *_ = self._attempt(flat, target, commit=False)
        finally:
            self._pinned = pinned
        return ok

    def _drop_anchors(self) -> int:
        """Free the elements anchored by the region of influence (the next drag anchors
        again); how many were anchored."""
        count = int(self.grid.anchored.sum())
        self.grid.anchored[:] = False
        self._model.fixed = self.grid.constrained()
        if self.backend == "gpu":
            self._rebuild_gpu()
        return count

    def _project_from(
        self, positions: np.ndarray, held: np.ndarray, offsets: np.ndarray
    ) -> tuple[int, float]:
        """Hold ``held`` at ``offsets`` and take ``positions`` projected onto the limits
        (:meth:`from_model`); the projection's sweeps and the violation before it."""
        flat = held.reshape(-1)
        self._held = flat.copy()
        self._offsets = np.where(flat[:, None], offsets.reshape(-1, 3), 0.0)
        self._pinned = self._model.fixed.reshape(-1) | self._held
        x, before, sweeps = project_onto_limits(
            self._model, positions, self._pinned.reshape(self.grid.shape)
        )
        self.set_state(x)  # the CPU raises when the limits cannot be met
        if self.backend == "gpu" and not self._solver.feasible:
            raise ChainMailError(
                "the positions cannot be brought within the ChainMail limits with the"
                " fixed, anchored and held elements where they are"
            )
        return sweeps, before

    # ------------------------------------------------------------------ parameters
    @property
    def model(self) -> ChainMailModel:
        """The :class:`~voxwarp.deform.elements.chainmail_model.ChainMailModel` the solver runs
        (live;
        change it through :meth:`set_limits`, :meth:`cut`, :meth:`link`, :meth:`fix`,
        :meth:`free`)."""
        return self._model

    @property
    def variant(self) -> str:
        """``"gibson"`` or ``"enhanced"``; may be changed between moves."""
        return self._variant

    @variant.setter
    def variant(self, value: str) -> None:
        self._variant = _variant(value)

    @property
    def relax_steps(self) -> int:
        """Relaxation steps run after every :meth:`move` (0: none)."""
        return self._relax_steps

    @relax_steps.setter
    def relax_steps(self, value: int) -> None:
        self._relax_steps = _count(value, "relax_steps")

    @property
    def relax_local(self) -> bool:
        """Whether :meth:`relax` (and ``relax_steps``) relaxes only around the elements
        moved since the last relaxation (module doc, "Local relaxation")."""
        return self._relax_local

    @relax_local.setter
    def relax_local(self, value: bool) -> None:
        if not isinstance(value, bool | np.bool_):
            raise ChainMailError(f"relax_local must be true or false; got {value!r:.40}")
        self._relax_local = bool(value)

    @property
    def held(self) -> np.ndarray:
        """(nx, ny, nz) bool copy: elements held by a drag (:meth:`move`)."""
        return self._held.reshape(self.grid.shape).copy()

    @property
    def held_offsets(self) -> np.ndarray:
        """(nx, ny, nz, 3) copy: where held elements are held, as offsets from rest."""
        return self._offsets.reshape((*self.grid.shape, 3)).copy()

    @property
    def cuts(self) -> np.ndarray:
        """(m, 4) int64 ``[i, j, k, axis]``: removed links from ``(i, j, k)`` to the next
        element along ``axis``."""
        return np.argwhere(_possible(self.grid.shape) & ~self._model.links).astype(np.int64)

    def _check_rest(self, model: ChainMailModel | None = None) -> None:
        """Raise when the rest state violates the limits (naming a link and the fix)."""
        m = self._model if model is None else model
        x = m.rest
        for axis in range(3):
            mn, mx, _, _ = m.link_limits(axis)
            d = np.diff(x, axis=axis)[..., axis]
            tol = _REST_TOL * max(1.0, float(m.spacing[axis]))
            for bad, what in (
                (mn > d + tol, "min_dist"),
                (mx < d - tol, "max_dist"),
            ):
                if np.any(bad):
                    where = tuple(int(v) for v in np.argwhere(bad)[0])
                    raise ChainMailError(
                        f"{what} along axis {axis} at element {where} is"
                        f" {float((mn if what == 'min_dist' else mx)[where]):g} mm but the"
                        f" rest spacing is {float(d[where]):g} mm: the undeformed grid would"
                        f" violate its own limits; use min_dist <= spacing <= max_dist"
                        f" (spacing {self.grid.spacing.tolist()} mm)"
                    )

    # ------------------------------------------------------------------ limits
    def set_limits(
        self,
        min_dist: Any = None,
        max_dist: Any = None,
        max_shear: Any = None,
    ) -> None:
        """Set the per element, per axis limits (world mm); ``None`` keeps a limit.

        Parameters
        ----------
        min_dist, max_dist, max_shear
            Each a number (all elements and axes), 3 numbers (per axis x, y, z), an
            (nx, ny, nz) array (per element, all axes) or an (nx, ny, nz, 3) array.
            ``min_dist[i]`` / ``max_dist[i]`` bound ``d_i`` of an element's links along
            axis ``i``, ``max_shear[i]`` their ``|d_j|``, ``j != i``.

        If the current deformation violates the new limits, the constraints are
        restored (held and fixed elements staying put).

        Raises
        ------
        ChainMailError
            On NaN/Inf, negative limits, ``min_dist > max_dist``, limits the rest
            state violates (``min_dist <= spacing <= max_dist`` is needed), a wrong
            shape, or when the current deformation cannot be brought within the new
            limits without moving held elements (release them first). Nothing changes
            then.
        """
        m = self._model
        new = {}
        for name, value in (
            ("min_dist", min_dist),
            ("max_dist", max_dist),
            ("max_shear", max_shear),
        ):
            new[name] = getattr(m, name) if value is None else self._limit_array(value, name)
        check_limits(new["min_dist"], new["max_dist"], new["max_shear"])
        trial = ChainMailModel(
            rest=m.rest,
            spacing=m.spacing,
            min_dist=new["min_dist"],
            max_dist=new["max_dist"],
            max_shear=new["max_shear"],
            links=m.links,
            fixed=m.fixed,
        )
        self._check_rest(trial)
        old = (m.min_dist, m.max_dist, m.max_shear)
        m.min_dist, m.max_dist, m.max_shear = trial.min_dist, trial.max_dist, trial.max_shear
        self._note_moved(self._full_box())  # the relaxation's fixed point moved
        if self.backend == "gpu":
            self._rebuild_gpu()
            return
        if not m.satisfied(self.positions()):
            ok = self._repair()
            if not ok:
                m.min_dist, m.max_dist, m.max_shear = old
                raise ChainMailError(
                    "the current deformation violates the new limits and cannot be"
                    " brought within them without moving held or fixed elements;"
                    " release() the held elements (or reset()) before setting them"
                )
            self._update_warp()

    def set_limits_from_stiffness(
        self, stretch: float = DEFAULT_STRETCH, shear: float = DEFAULT_SHEAR
    ) -> None:
        """Set the limits from ``grid.stiffness`` again (:func:`limits_from_stiffness`),
        e.g. after :meth:`ElementGrid.materials_from_volume`."""
        mn, mx, sh = limits_from_stiffness(self.grid.spacing, self.grid.stiffness, stretch, shear)
        self.set_limits(mn, mx, sh)

    def _limit_array(self, value: Any, name: str) -> np.ndarray:
        shape = self.grid.shape
        form = (
            f"a number, 3 numbers (per axis), an {shape} array (per element) or an"
            f" {(*shape, 3)} array"
        )
        try:
            a = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ChainMailError(f"{name} must be {form} in mm; got {value!r:.80}") from exc
        if a.shape in ((), (3,), (*shape, 3)):
            return np.broadcast_to(a, (*shape, 3)).copy()
        if a.shape == shape:
            return np.repeat(a[..., None], 3, axis=-1)
        raise ChainMailError(f"{name} must be {form} in mm; got shape {a.shape}")

    # ------------------------------------------------------------------ constraints
    def fix(self, sel: Selection) -> None:
        """Fix elements at their rest positions (see :meth:`ElementGrid.fix`).

        Displaced elements are moved back to rest first, with propagation; fixed
        elements that were held are released.

        Raises
        ------
        ChainMailError
            When moving them back to rest would move held or other fixed elements
            (nothing changes then).
        """
        mask = self.grid.mask(sel) & ~self.grid.fixed
        flat = np.flatnonzero(mask)
        if flat.size and self.backend == "cpu":
            was = self._pinned[flat].copy()
            self._pinned[flat] = True
            ok, *_ = self._attempt(flat, self._rest[flat], commit=True)
            if ok:
                self._grow_box()
            else:
                self._pinned[flat] = was
                raise ChainMailError(
                    f"cannot fix {flat.size} element(s) at rest: moving them back would"
                    " move held or fixed elements; release() the held ones first"
                )
        self.grid.fix(mask)
        self._model.fixed = self.grid.constrained()
        fixed = self._model.fixed.reshape(-1)
        self._held &= ~fixed
        self._offsets[fixed] = 0.0
        self._pinned = fixed | self._held
        if self.backend == "gpu":
            self._rebuild_gpu()
        self._update_warp()

    def free(self, sel: Selection) -> None:
        """Unfix elements (see :meth:`ElementGrid.free`; anchored ones too); they stay
        where they are."""
        self._note_mask(self.grid.mask(sel) & self.grid.constrained())
        self.grid.free(sel)
        self._model.fixed = self.grid.constrained()
        self._pinned = self._model.fixed.reshape(-1) | self._held
        if self.backend == "gpu":
            self._rebuild_gpu()

    def release(self, sel: Selection = None) -> None:
        """Let held elements go: they stay where they are but may move again.

        Parameters
        ----------
        sel
            Elements to release (see :meth:`ElementGrid.mask`); ``None`` releases all.
        """
        mask = self.grid.mask(sel).reshape(-1)
        self._note_mask(self._held & mask)  # free now: maybe off the relaxed state
        self._update_anchors(self._held & ~mask, self._offsets)
        self._held &= ~mask
        self._offsets[mask] = 0.0
        self._pinned = self._model.fixed.reshape(-1) | self._held

    def reset(self) -> None:
        """Put every element back at rest and release all held elements."""
        self._held[:] = False
        self._offsets[:] = 0.0
        self._update_anchors(self._held, self._offsets)
        self._pinned = self._model.fixed.reshape(-1).copy()
        self._box = self._active = None
        self._relaxed = False
        if self.backend == "gpu":
            # the rest state satisfies every link (set_limits checks it)
            self._solver.set_positions(self._model.rest.copy(), valid=True)
        else:
            self._x[:] = self._rest
        self._update_warp()

    # ------------------------------------------------------------------ moves
    def move(self, sel: Selection, offsets: Any) -> MoveStats:
        """Drag elements to ``rest + offset`` and hold them there; propagate.

        Parameters
        ----------
        sel
            A bool mask of the grid shape, one index ``(i, j, k)`` or (m, 3) indices.
        offsets
            World-space offsets (mm) from the *rest* positions: one (3,) offset for all
            selected elements, or (m, 3) offsets, one per index of ``sel`` (an index
            given twice takes its last offset).

        Fixed elements in the selection are skipped (free them first to drag them).
        When fixed or held elements block the move it is limited (see the module
        doc): the elements are held where they stopped.

        Returns
        -------
        MoveStats
            Elements touched, time, the fraction of the way moved and more.

        Raises
        ------
        ChainMailError
            On offsets of the wrong shape or not finite.
        voxwarp.deform.elements.grid.ElementGridError
            On an index outside the grid.
        """
        t0 = time.perf_counter()
        flat, off = self._selection(sel, offsets)
        held, offs = self._held.copy(), self._offsets.copy()
        held[flat], offs[flat] = True, off
        self._update_anchors(held, offs)
        self._held[flat] = True
        self._offsets[flat] = off
        self._pinned[flat] = True
        goal = self._rest[flat] + off
        if self.backend == "gpu":
            stats = self._move_gpu(flat, goal, t0)
        else:
            stats = self._move_cpu(flat, goal, t0)
        if self._relax_steps:
            self.relax(self._relax_steps)
        else:
            self._update_warp()
        return stats

    def _enforce_gpu(self) -> int:
        shape = (*self.grid.shape, 3)
        passes = self._solver.enforce(self.held, self._targets().reshape(shape), self.max_passes)
        self._note_moved(self._solver.last_changed)
        return int(passes)

    def _move_gpu(self, flat: np.ndarray, goal: np.ndarray, t0: float) -> MoveStats:
        """The GPU enforces the constraints; a drag it cannot satisfy (fixed or held
        elements in the way) is limited like on the CPU: the state before the move is
        restored from a GPU copy and the largest feasible fraction of the way is found
        by bisection (feasibility depends only on where the pinned elements are). Only
        then are the dragged elements' previous positions read back."""
        solver = self._solver
        solver.snapshot()
        passes = self._enforce_gpu()
        if solver.feasible:
            return MoveStats(touched=-1, seconds=time.perf_counter() - t0, passes=passes)
        solver.restore()
        start = solver.positions().reshape(-1, 3)[flat]
        delta = goal - start
        lo, hi, attempts = 0.0, 1.0, 1
        for _ in range(LIMIT_BISECTIONS):
            mid = 0.5 * (lo + hi)
            self._offsets[flat] = start + mid * delta - self._rest[flat]
            passes += self._enforce_gpu()
            attempts += 1
            if solver.feasible:
                lo = mid
            else:
                hi = mid
            solver.restore()
        self._offsets[flat] = start + lo * delta - self._rest[flat]
        passes += self._enforce_gpu()
        if not solver.feasible:  # cannot happen: the same trial succeeded
            raise ChainMailError("internal error: a limited ChainMail move did not repeat")
        return MoveStats(
            touched=-1,
            seconds=time.perf_counter() - t0,
            fraction=lo,
            attempts=attempts,
            passes=passes,
        )

    def _move_cpu(self, flat: np.ndarray, goal: np.ndarray, t0: float) -> MoveStats:
        ok, moved, checks, fixes, _ = self._attempt(flat, goal, commit=True)
        if ok:
            self._grow_box()
            return MoveStats(moved, time.perf_counter() - t0, 1.0, checks, fixes, 1)
        start = self._x[flat].copy()
        delta = goal - start
        lo, hi, attempts = 0.0, 1.0, 1
        for _ in range(LIMIT_BISECTIONS):
            mid = 0.5 * (lo + hi)
            ok, *_ = self._attempt(flat, start + mid * delta, commit=False)
            attempts += 1
            if ok:
                lo = mid
            else:
                hi = mid
        moved = checks = fixes = 0
        if lo > 0.0:
            ok, moved, checks, fixes, _ = self._attempt(flat, start + lo * delta, commit=True)
            attempts += 1
            if not ok:  # cannot happen: the same trial succeeded
                raise ChainMailError("internal error: a limited ChainMail move did not repeat")
            self._grow_box()
        # held where they stopped
        self._offsets[flat] = self._x[flat] - self._rest[flat]
        return MoveStats(moved, time.perf_counter() - t0, lo, checks, fixes, attempts)

    @property
    def max_passes(self) -> int:
        """Constraint passes the GPU backend may run per move: ``4 (nx + ny + nz)``
        (each of the two monotone phases of a coordinate needs about ``nx + ny + nz``)."""
        return 4 * int(sum(self.grid.shape))

    def _flat_limits(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        m = self._model
        n = self.grid.count
        return (
            m.min_dist.reshape(n, 3),
            m.max_dist.reshape(n, 3),
            m.max_shear.reshape(n, 3),
            m.links.reshape(n, 3),
        )

    def _attempt(
        self,
        seeds: np.ndarray,
        targets: np.ndarray,
        *,
        commit: bool,
        repair: bool = False,
    ) -> tuple[bool, int, int, int, bool]:
        """One propagation (see :func:`voxwarp.deform.elements.chainmail_cpu.propagate`)."""
        k = _kernels()
        self._epoch += 1
        if self._epoch >= 2**62:
            self._mark[:] = 0
            self._epoch = 1
        mn, mx, sh, links = self._flat_limits()
        max_pops = _POPS_PER_COORDINATE * 3 * self.grid.count + 4096
        ok, moved, checks, fixes, capped, n_t = k.propagate(
            self._x,
            mn,
            mx,
            sh,
            links,
            self._pinned,
            self._mark,
            self._slot,
            self._epoch,
            self._strides,
            np.ascontiguousarray(seeds, dtype=np.int64),
            np.ascontiguousarray(targets, dtype=np.float64).reshape(-1, 3),
            self._variant == "gibson",
            repair,
            commit,
            max_pops,
            self._t_idx,
            self._t_old,
        )
        self._recorded = int(n_t) if ok and commit else 0
        return bool(ok), int(moved), int(checks), int(fixes), bool(capped)

    def _repair(self) -> bool:
        """Restore the constraints from the current state (held and fixed stay)."""
        empty = np.zeros(0, dtype=np.int64)
        ok, *_ = self._attempt(empty, np.zeros((0, 3)), commit=True, repair=True)
        self._note_moved(self._full_box())
        return ok and self._model.satisfied(self.positions())

    def _full_box(self) -> Box:
        return ((0, 0, 0), self.grid.shape)

    def _grow_box(self) -> None:
        """Note the elements the last committed propagation moved (:meth:`_note_moved`)."""
        if self._recorded == 0:
            return
        idx = np.unravel_index(self._t_idx[: self._recorded], self.grid.shape)
        lo = tuple(int(a.min()) for a in idx)
        hi = tuple(int(a.max()) + 1 for a in idx)
        self._note_moved((lo, hi))  # type: ignore[arg-type]

    def _note_mask(self, mask: np.ndarray) -> None:
        """:meth:`_note_moved` with the bounding box of a (grid-shaped or flat) mask."""
        idx = np.nonzero(np.asarray(mask).reshape(self.grid.shape))
        if idx[0].size:
            box = (tuple(int(a.min()) for a in idx), tuple(int(a.max()) + 1 for a in idx))
            self._note_moved(box)  # type: ignore[arg-type]

    def _note_moved(self, box: Box | None) -> None:
        """Add the box of elements a move (or repair) changed to the displaced box and
        the region a local relaxation starts from (anew after a relaxation)."""
        if box is None:
            return
        self._box = union_box(self._box, box)
        self._active = box if self._relaxed else union_box(self._active, box)
        self._relaxed = False

    def _selection(self, sel: Selection, offsets: Any) -> tuple[np.ndarray, np.ndarray]:
        """Flat indices (fixed ones dropped, duplicates: last wins) and (m, 3) offsets."""
        try:
            off = np.asarray(offsets, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ChainMailError("offsets must be numbers (mm)") from exc
        if not np.all(np.isfinite(off)):
            raise ChainMailError("offsets must be finite numbers (mm)")
        sel_arr = np.asarray(sel)
        if sel_arr.dtype == bool:
            if off.shape != (3,):
                raise ChainMailError(
                    f"move with a bool mask takes one (3,) offset; got shape {off.shape}"
                )
            flat = np.flatnonzero(self.grid.mask(sel_arr))
            off = np.broadcast_to(off, (flat.size, 3))
        else:
            idx = self.grid.indices(sel_arr)
            if off.shape == (3,):
                off = np.broadcast_to(off, idx.shape)
            if off.shape != idx.shape:
                raise ChainMailError(
                    "offsets must be one (3,) offset or one per selected element"
                    f" {idx.shape}; got shape {off.shape}"
                )
            flat = np.ravel_multi_index(tuple(idx.T), self.grid.shape).astype(np.int64)
            # a repeated index takes its last offset
            _, first_rev = np.unique(flat[::-1], return_index=True)
            keep = np.sort(flat.size - 1 - first_rev)
            flat, off = flat[keep], off[keep]
        free = ~self.grid.fixed.reshape(-1)[flat]
        return flat[free], np.array(off[free], dtype=np.float64).reshape(-1, 3)

    def _update_anchors(self, held: np.ndarray, offsets: np.ndarray) -> None:
        """Anchor the elements at rest beyond the region of influence of ``held``
        (:meth:`ElementGrid.anchor_around`); the GPU solver is rebuilt when they change.
        A region that only shrinks (a drag growing) needs no GPU read-back."""
        before = self.grid.anchored.copy()
        grown = self.grid.anchor_around(held, offsets) & ~before
        if grown.any():
            if self.backend == "gpu":
                x = self._solver.positions().reshape(-1, 3)
            else:
                x = self._x
            at_rest = np.all(x == self._rest, axis=1)
            self.grid.anchor_around(held, offsets, at_rest & ~self._held)
        if np.array_equal(before, self.grid.anchored):
            return
        self._note_mask(before != self.grid.anchored)
        self._model.fixed = self.grid.constrained()
        self._pinned = self._model.fixed.reshape(-1) | self._held
        if self.backend == "gpu":
            self._rebuild_gpu()

    def _targets(self) -> np.ndarray:
        """(N, 3) rest positions with the held elements at ``rest + offset``."""
        t = self._rest.copy()
        t[self._held] += self._offsets[self._held]
        return t

    # ------------------------------------------------------------------ relaxation
    def relax(self, steps: int = 1, local: bool | None = None) -> None:
        """Run ``steps`` relaxation steps (constrained Laplacian smoothing, module doc).

        Fixed and held elements do not move; the constraints stay satisfied and the
        smoothness energy (:meth:`smoothness_energy`) does not grow. On the GPU
        backend the sweeps run as fragment-shader passes, nothing read back.

        Parameters
        ----------
        steps
            Number of steps (>= 0); each is one red-black Gauss-Seidel sweep.
        local
            Relax only around the elements moved since the last relaxation (module
            doc, "Local relaxation"); ``None``: :attr:`relax_local`. The default
            relaxes every element (over the box of those displaced since the last
            :meth:`reset`, which gives the same result).
        """
        steps = _count(steps, "steps")
        if steps == 0:
            return
        start = self.relax_region(local)
        if self.backend == "gpu":
            end = self._solver.relax(start, steps)
        else:
            end = self._relax_cpu(start, steps)
        self._box = union_box(self._box, end)
        self._active = end
        self._relaxed = True
        self._update_warp()

    def relax_region(self, local: bool | None = None) -> Box | None:
        """The box ``((i0, j0, k0), (i1, j1, k1))`` (half-open) the next :meth:`relax`
        starts from (each half-sweep covers it grown by one more element); ``None``
        when every element is at the rule's fixed point (nothing would move).

        Parameters
        ----------
        local
            As in :meth:`relax`; ``None``: :attr:`relax_local`.
        """
        local = self._relax_local if local is None else bool(local)
        return self._active if local else self._box

    def _relax_cpu(self, start: Box | None, steps: int) -> Box | None:
        """The red-black half-sweeps of the numba kernel over :func:`relax_boxes` from
        ``start``; returns the last box (everything changed lies in it)."""
        boxes = relax_boxes(start, steps, self.grid.shape)
        if not boxes:
            return start
        k = _kernels()
        mn, mx, sh, links = self._flat_limits()
        shape = np.asarray(self.grid.shape, dtype=np.int64)
        for n, (lo, hi) in enumerate(boxes):
            box = np.array([v for a in range(3) for v in (lo[a], hi[a])], dtype=np.int64)
            k.relax_sweep(self._x, self._rest, mn, mx, sh, links, self._pinned, shape, box, n % 2)
        return boxes[-1]

    def smoothness_energy(self) -> float:
        """``sum over present links of |u_b - u_a|^2`` (mm²), ``u`` the displacements."""
        u = self.displacements()
        e = 0.0
        for axis in range(3):
            d = np.diff(u, axis=axis)
            lo: list[Any] = [slice(None)] * 3
            lo[axis] = slice(0, -1)
            linked = self._model.links[(*lo, axis)]
            e += float(np.sum(np.sum(d * d, axis=-1)[linked]))
        return e

    # ------------------------------------------------------------------ cutting
    def cut(
        self,
        plane_point: Any,
        plane_normal: Any,
        extent: float | None = None,
    ) -> int:
        """Remove the links that cross a plane (or a disk on it).

        A link crosses when its two elements' *current* positions lie on different
        sides (signed distances ``s_a < 0 <= s_b`` or ``s_b < 0 <= s_a``: an element
        on the plane counts as the positive side).

        Parameters
        ----------
        plane_point, plane_normal
            A point on the plane and its normal (mm; need not be unit length).
        extent
            ``None``: the whole plane. Otherwise only links whose segment meets the
            plane within this distance (mm) of ``plane_point``: a disk.

        Returns
        -------
        int
            Links removed (not counting ones cut before).
        """
        return self._remove_links(self._crossing(plane_point, plane_normal, extent))

    def _crossing(self, plane_point: Any, plane_normal: Any, extent: float | None) -> np.ndarray:
        """(nx, ny, nz, 3) bool: the grid's links (present or not) that cross the plane
        or disk at the current positions (the test of :meth:`cut`)."""
        p0 = _vec3(plane_point, "plane_point")
        normal = _vec3(plane_normal, "plane_normal")
        length = float(np.linalg.norm(normal))
        if length == 0.0:
            raise ChainMailError("plane_normal must not be the zero vector")
        normal = normal / length
        if extent is not None:
            extent = _number(extent, "extent (None: the whole plane)", lo=0.0, hi=math.inf)
        x = self.positions()
        s = (x - p0) @ normal
        cross_all = np.zeros_like(self._model.links)
        for axis in range(3):
            lo_t, hi_t = _link_ends(axis)
            sa, sb = s[lo_t], s[hi_t]
            cross = ((sa < 0) & (sb >= 0)) | ((sb < 0) & (sa >= 0))
            if extent is not None and np.any(cross):
                with np.errstate(divide="ignore", invalid="ignore"):
                    t = np.where(cross, sa / (sa - sb), 0.0)
                xa, xb = x[lo_t], x[hi_t]
                hit = xa + t[..., None] * (xb - xa)
                cross &= np.linalg.norm(hit - p0, axis=-1) <= extent
            cross_all[(*lo_t, axis)] = cross
        return cross_all

    def cut_pairs(self, pairs: Any) -> int:
        """Remove the links between given pairs of neighbouring elements.

        Parameters
        ----------
        pairs
            (m, 2, 3) element indices: ``[[(i, j, k), (i2, j2, k2)], ...]``, each pair
            6-neighbours (one index differing by 1).

        Returns
        -------
        int
            Links removed (not counting ones cut before).
        """
        mask = np.zeros_like(self._model.links)
        mask[tuple(self._pair_links(pairs).T)] = True
        return self._remove_links(mask)

    def _pair_links(self, pairs: Any) -> np.ndarray:
        """(m, 4) int64 links ``[i, j, k, axis]`` between ``pairs`` (validated, each once)."""
        try:
            p = np.asarray(pairs, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ChainMailError(
                "pairs must be (m, 2, 3) element indices [[(i, j, k), (i2, j2, k2)], ...]"
            ) from exc
        if p.size == 0:
            return np.zeros((0, 4), dtype=np.int64)
        if p.ndim != 3 or p.shape[1:] != (2, 3) or np.any(p != np.round(p)):
            raise ChainMailError(
                "pairs must be (m, 2, 3) integer element indices"
                f" [[(i, j, k), (i2, j2, k2)], ...]; got shape {p.shape}"
            )
        a = self.grid.indices(p[:, 0].astype(np.int64))
        b = self.grid.indices(p[:, 1].astype(np.int64))
        diff = b - a
        ok = np.sum(np.abs(diff), axis=1) == 1
        if not np.all(ok):
            n = int(np.argmin(ok))
            raise ChainMailError(
                f"pair {n} ({a[n].tolist()}, {b[n].tolist()}) are not neighbours; a link"
                " joins elements whose indices differ by 1 along one axis"
            )
        low = np.minimum(a, b)
        axis = np.argmax(np.abs(diff), axis=1)
        flat = np.unique(np.ravel_multi_index((*low.T, axis), self._model.links.shape))
        return np.column_stack(np.unravel_index(flat, self._model.links.shape)).astype(np.int64)

    def _remove_links(self, cut: np.ndarray) -> int:
        newly = cut & self._model.links
        ends = np.any(newly, axis=-1)
        for axis in range(3):  # both ends of a removed link: their rule changed
            lo = (slice(None),) * axis + (slice(0, -1),)
            hi = (slice(None),) * axis + (slice(1, None),)
            ends[hi] |= newly[..., axis][lo]
        self._note_mask(ends)
        self._model.links &= ~cut
        if self.backend == "gpu" and np.any(newly):
            self._rebuild_gpu()
        return int(newly.sum())

    # ------------------------------------------------------------------ joining
    def link_pairs(self, pairs: Any, stretched: str = "refuse") -> int:
        """Restore the links between given pairs of neighbouring elements: the inverse
        of :meth:`cut_pairs` (a cut then linked model moves exactly as the uncut one).

        Links exist only between 6-neighbours of the grid, so this also joins regions
        that were never linked (a model loaded with ``cuts``) where they are neighbours.
        Pairs already linked are ignored, as :meth:`cut_pairs` ignores pairs already cut.

        Parameters
        ----------
        pairs
            (m, 2, 3) element indices ``[[(i, j, k), (i2, j2, k2)], ...]``, each pair
            6-neighbours (one index differing by 1).
        stretched
            What to do with a link its two elements violate where they are now
            (pulled apart, pushed together or sheared beyond its limits; see
            :data:`STRETCHED`, the module doc): ``"refuse"`` (default) raises and
            changes nothing; ``"skip"`` restores only the links whose elements touch
            (within the limits) and leaves the others cut; ``"pull"`` drags free
            elements, the worst link first, until every link touches, and joins all.

        Returns
        -------
        int
            Links restored (not counting ones present before).

        Raises
        ------
        ChainMailError
            On malformed pairs or pairs that are not neighbours; with ``"refuse"``, on
            a stretched link (naming how many, the worst, by how many mm, and the
            fixes); with ``"pull"``, when held or fixed elements keep a link's ends
            apart. Nothing changes then.
        """
        return self._restore_links(self._pair_links(pairs), _stretched(stretched))

    def link(
        self,
        plane_point: Any,
        plane_normal: Any,
        extent: float | None = None,
        stretched: str = "skip",
    ) -> int:
        """Restore the removed links that cross a plane (or a disk on it): the
        counterpart of :meth:`cut`, joining the regions on either side where they touch.

        A link crosses as in :meth:`cut` (at the elements' current positions).
        ``stretched`` is as in :meth:`link_pairs` but defaults to ``"skip"``: a plane
        also crosses links whose ends a drag pulled apart, and those stay cut.

        Returns
        -------
        int
            Links restored.
        """
        crossing = self._crossing(plane_point, plane_normal, extent)
        return self._restore_links(np.argwhere(crossing), _stretched(stretched))

    def _restore_links(self, add: np.ndarray, stretched: str) -> int:
        """Restore the links ``add`` (``[i, j, k, axis]``, each once) that are cut."""
        m = self._model
        new = add[~m.links[tuple(add.T)]]
        if len(new) == 0:
            return 0
        # the CPU's own positions (no copy): a join changes none
        x = self._x.reshape(m.rest.shape) if self.backend == "cpu" else self.positions()
        excess = m.link_excess(x, new)
        far = excess > _JOIN_TOL_MM[self.backend]
        if stretched == "refuse" and far.any():
            raise ChainMailError(_stretched_message(new, far, excess))
        if stretched == "skip":
            new = new[~far]
        if stretched == "pull" and far.any():
            self._pull(new, x)
        elif len(new):
            m.links[tuple(new.T)] = True
            if self.backend == "gpu":
                self._rebuild_gpu()
        self._note_link_ends(new)  # both ends' rule changed: a local relaxation's region
        return len(new)

    def _note_link_ends(self, links: np.ndarray) -> None:
        """Note both elements of each link ``[i, j, k, axis]`` as changed."""
        if len(links):
            low = links[:, :3]
            high = low + np.eye(3, dtype=np.int64)[links[:, 3]]
            mask = np.zeros(self.grid.shape, dtype=bool)
            mask[tuple(np.concatenate([low, high]).T)] = True
            self._note_mask(mask)

    def _pull(self, new: np.ndarray, x: np.ndarray) -> None:
        """Join links ``new`` (``[i, j, k, axis]``), some stretched, at positions ``x``:
        the worst first, an end of it is dragged to the nearest place its link allows
        (the upper end, or the lower if that is held or fixed or blocked), its tissue
        following by propagation; links that then touch are joined. On the GPU backend
        this runs on the CPU, on read-back positions. Nothing changes on failure."""
        m = self._model
        gpu = self.backend == "gpu"
        if gpu:
            self._x[:] = x.reshape(-1, 3)
        saved = (self._x.copy(), m.links.copy(), self._box, self._active, self._relaxed)
        # a closed gap's link touches at the next check unless the propagation moved its
        # other end too (the two ends also linked around the cut): a bound on retries
        closes = 2 * len(new) + 8
        try:
            todo = new
            while len(todo):
                excess = m.link_excess(self._x.reshape(x.shape), todo)
                touch = excess <= _JOIN_TOL_MM[self.backend]
                m.links[tuple(todo[touch].T)] = True
                todo = todo[~touch]
                if not len(todo):
                    break
                closes -= 1
                if closes < 0 or not self._close_gap(todo[int(np.argmax(excess[~touch]))]):
                    raise ChainMailError(
                        "cannot pull the elements of the links to join within their limits:"
                        " held or fixed elements are in the way; release() the held ones"
                        ' (or drag them closer) first, or join with stretched="skip"'
                    )
        except ChainMailError:
            self._x[:], m.links[:], self._box, self._active, self._relaxed = saved
            if gpu:
                self._x[:] = self._rest
            raise
        if gpu:
            self._rebuild_gpu(self._x.reshape(x.shape).copy())
            self._x[:] = self._rest
        else:
            self._update_warp()

    def _close_gap(self, link: np.ndarray) -> bool:
        """Drag an end of ``link`` (``[i, j, k, axis]``) to the nearest position within
        its limits, the other end staying (a propagation of the CPU kernels on
        :attr:`_x`); False when neither end can go there."""
        m, axis = self._model, int(link[3])
        a = tuple(int(v) for v in link[:3])
        b = tuple(v + (c == axis) for c, v in enumerate(a))
        lo = np.full(3, -0.5 * (m.max_shear[a][axis] + m.max_shear[b][axis]))
        hi = -lo
        lo[axis] = 0.5 * (m.min_dist[a][axis] + m.min_dist[b][axis])
        hi[axis] = 0.5 * (m.max_dist[a][axis] + m.max_dist[b][axis])
        ea, eb = (int(np.ravel_multi_index(e, self.grid.shape)) for e in (a, b))
        d = self._x[eb] - self._x[ea]
        for end, target in (
            (eb, self._x[ea] + np.clip(d, lo, hi)),
            (ea, self._x[eb] - np.clip(d, lo, hi)),
        ):
            if self._pinned[end]:
                continue
            self._pinned[end] = True
            ok, *_ = self._attempt(np.array([end]), target[None], commit=True)
            self._pinned[end] = False
            if ok:
                self._grow_box()
                return True
        return False

    # ------------------------------------------------------------------ results
    def positions(self) -> np.ndarray:
        """(nx, ny, nz, 3) float64 element positions (mm; a GPU read-back)."""
        if self.backend == "gpu":
            return np.asarray(self._solver.positions(), dtype=np.float64).reshape(
                (*self.grid.shape, 3)
            )
        return self._x.reshape((*self.grid.shape, 3)).copy()

    def displacements(self) -> np.ndarray:
        """(nx, ny, nz, 3) float64 displacements from rest (mm; a GPU read-back).

        float64 (unlike the mass-spring model's float32) so that a saved field
        restores a state that satisfies the constraints exactly (:meth:`from_warp`).
        """
        return self.positions() - self._model.rest

    def violation(self) -> float:
        """Largest constraint violation (mm) at the current positions (0: none)."""
        return self._model.violation(self.positions())

    def set_state(self, positions: Any) -> None:
        """Replace the element positions.

        Fixed elements are put back at rest and held ones at ``rest + offset``; if the
        result violates a link (e.g. positions saved in lower precision), the
        constraints are restored by propagation.

        Parameters
        ----------
        positions
            (nx, ny, nz, 3) positions in world mm.

        Raises
        ------
        ChainMailError
            On a wrong shape, values that are not finite, or positions that cannot be
            brought within the limits with the fixed and held elements where they are
            (the state is then unchanged).
        """
        shape = (*self.grid.shape, 3)
        try:
            a = np.asarray(positions, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ChainMailError(f"positions must be an array of numbers of shape {shape}") from exc
        if a.shape != shape:
            raise ChainMailError(
                f"positions must have shape {shape} (grid shape + xyz); got {a.shape}"
            )
        if not np.all(np.isfinite(a)):
            raise ChainMailError("positions must be finite numbers")
        x = a.reshape(-1, 3).copy()
        fixed = self._model.fixed.reshape(-1)
        x[fixed] = self._rest[fixed]
        x[self._held] = self._rest[self._held] + self._offsets[self._held]
        if self.backend == "gpu":
            self._solver.set_positions(x.reshape(shape))
            self._solver.enforce(self.held, self._targets().reshape(shape), self.max_passes)
            self._note_moved(self._full_box())
            return
        old, old_boxes = self._x.copy(), (self._box, self._active, self._relaxed)
        self._x[:] = x
        self._note_moved(self._full_box())
        if not self._model.satisfied(self.positions()) and not self._repair():
            self._x[:] = old
            self._box, self._active, self._relaxed = old_boxes
            raise ChainMailError(
                "these positions violate the ChainMail limits and cannot be brought within"
                " them with the fixed and held elements where they are"
            )
        self._update_warp()

    # ------------------------------------------------------------------ warp
    def _update_warp(self) -> None:
        """Keep a CPU warp current: only the box of displaced elements (every element
        that changed since the last reset lies in it) is rewritten, so a local drag on
        a large grid does not re-upload the whole field."""
        if self._warp is None or self.backend != "cpu" or self.defer_warp_updates:
            return
        box = self._box
        n = self.grid.count
        if box is None or math.prod(h - lo for lo, h in zip(*box, strict=True)) > n // 2:
            self._warp.update(self.displacements())
            return
        sl = tuple(slice(lo, h) for lo, h in zip(*box, strict=True))
        x = self._x.reshape((*self.grid.shape, 3))[sl]
        self._warp.update_region(np.array(box[0]), x - self._model.rest[sl])

    # ------------------------------------------------------------------ GPU backend
    def _make_gpu_solver(self) -> Any:
        try:
            # the GPU backend (moderngl) loads only when asked for
            from voxwarp.deform.elements.chainmail_gpu import GpuChainMailSolver
        except ImportError as exc:
            raise ChainMailError(
                'backend="gpu" needs voxwarp.deform.elements.chainmail_gpu.GpuChainMailSolver,'
                f' which could not be imported ({exc}); use backend="cpu"'
            ) from exc
        return GpuChainMailSolver(self._model, self._ctx)

    def _rebuild_gpu(self, positions: np.ndarray | None = None) -> None:
        """Make a new GPU solver for the changed model, keeping the positions (or
        starting from ``positions``, (nx, ny, nz, 3) mm)."""
        x = self.positions() if positions is None else positions
        fixed = self._model.fixed
        x[fixed] = self._model.rest[fixed]
        self._solver.release()
        self._solver = self._make_gpu_solver()
        self._solver.set_positions(x)
        self._solver.enforce(
            self.held, self._targets().reshape((*self.grid.shape, 3)), self.max_passes
        )
        self._note_moved(self._solver.last_changed)

    # ------------------------------------------------------------------ serialisation
    def to_dict(self, include_positions: bool = False) -> dict[str, Any]:
        """JSON-serialisable description of the model (plain lists and numbers).

        Parameters
        ----------
        include_positions
            Also write ``"positions"`` (a GPU read-back) so :meth:`from_dict` resumes
            from this state.

        Returns
        -------
        dict
            ``grid`` (:meth:`ElementGrid.to_dict`), ``variant``, ``relax_steps``,
            ``relax_local`` (only when true), ``limits`` (``min_dist``, ``max_dist``,
            ``max_shear``: each a number when uniform, 3 numbers when uniform per
            axis, else an (nx, ny, nz, 3) nested list), ``cuts`` (removed links
            ``[i, j, k, axis]``, :attr:`cuts`), ``held`` (``{"index": [i, j, k],
            "offset": [dx, dy, dz]}``: where held elements are held, mm from rest)
            and, with ``include_positions``, ``positions``. The backend is not part
            of the model.
        """
        m = self._model
        flat = np.flatnonzero(self._held)
        held = held_entries(
            np.stack(np.unravel_index(flat, self.grid.shape), -1), self._offsets[flat]
        )
        d: dict[str, Any] = {
            "grid": self.grid.to_dict(),
            "variant": self._variant,
            "relax_steps": self._relax_steps,
            "limits": {
                name: _compact(getattr(m, name)) for name in ("min_dist", "max_dist", "max_shear")
            },
            "cuts": self.cuts.tolist(),
            "held": held,
        }
        if self._relax_local:  # written only when set: older readers load the rest
            d["relax_local"] = True
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
    ) -> ChainMail:
        """Rebuild a model from :meth:`to_dict`'s form.

        Parameters
        ----------
        d
            Mapping with ``grid`` (required) and optionally ``variant``,
            ``relax_steps``, ``relax_local``, ``limits`` (default: from the stiffness), ``cuts``,
            ``held`` and ``positions``. A ``"type"`` key (``"chainmail"``) is accepted.
        backend, ctx
            Solver backend and, for ``"gpu"``, its moderngl context.
        positions
            (nx, ny, nz, 3) positions (mm) to resume from; overrides
            ``d["positions"]``. With positions the held elements are held where the
            entry says (:meth:`set_state`); without, the elements start at rest and
            the held elements are dragged there again, one :meth:`move` each.

        Raises
        ------
        ChainMailError
            On a missing or malformed key; the message names the key and the fix.
        """
        return cls._from_entry(d, backend, ctx, positions)

    @classmethod
    def _entry_parts(cls, d: Mapping[str, Any]) -> tuple[ElementGrid, dict[str, Any], Any]:
        grid = _grid_from(d)
        kwargs: dict[str, Any] = {}
        for key in ("variant", "relax_steps", "relax_local"):
            if key in d:
                kwargs[key] = d[key]
        limits = d.get("limits", {})
        if not isinstance(limits, Mapping) or set(limits) - {"min_dist", "max_dist", "max_shear"}:
            raise ChainMailError(
                "chainmail 'limits' must be an object with keys among 'min_dist',"
                f" 'max_dist', 'max_shear'; got {limits!r:.80}"
            )
        return grid, kwargs, (limits, d.get("cuts", []))

    @classmethod
    def _entry_held(cls, held: Any, grid: ElementGrid) -> list[tuple[Any, np.ndarray]]:
        return _parse_held(held, grid)  # type: ignore[return-value]

    def _resume(self, extra: Any, held: list[tuple[Any, np.ndarray]], positions: Any) -> None:
        limits, cuts = extra
        if limits:
            self.set_limits(**{k: v for k, v in limits.items()})
        self._cut_links(cuts)
        if positions is not None:
            for e, off in held:
                self._held[e] = True
                self._offsets[e] = off
            self._pinned = self._model.fixed.reshape(-1) | self._held
            self.set_state(positions)
            self._update_anchors(self._held, self._offsets)
        else:
            for e, off in held:
                self.move(np.unravel_index(e, self.grid.shape), off)

    def _cut_links(self, cuts: Any) -> None:
        form = "chainmail 'cuts' must be a list of removed links [i, j, k, axis]"
        try:
            c = np.asarray(cuts, dtype=np.float64).reshape(-1, 4) if len(cuts) else None
        except (TypeError, ValueError) as exc:
            raise ChainMailError(f"{form}; got {cuts!r:.80}") from exc
        if c is None:
            return
        if np.any(c != np.round(c)) or np.any(c[:, 3] < 0) or np.any(c[:, 3] > 2):
            raise ChainMailError(f"{form} (integers, axis 0..2); got {cuts!r:.80}")
        c = c.astype(np.int64)
        a = self.grid.indices(c[:, :3])
        b = a.copy()
        b[np.arange(len(b)), c[:, 3]] += 1
        if np.any(b >= np.asarray(self.grid.shape)):
            raise ChainMailError(f"{form}: a link leaves the grid of shape {self.grid.shape}")
        self.cut_pairs(np.stack([a, b], axis=1))

    def __repr__(self) -> str:
        return (
            f"ChainMail(shape={self.grid.shape}, variant={self._variant!r},"
            f" backend={self.backend!r}, held={int(self._held.sum())},"
            f" cuts={len(self.cuts)})"
        )


# ---------------------------------------------------------------------- helpers
def neighbour_pairs(mask: Any, boundary: bool = True) -> np.ndarray:
    """(m, 2, 3) int64 pairs of 6-neighbour elements with one end in ``mask``.

    Parameters
    ----------
    mask
        (nx, ny, nz) bool: selected elements.
    boundary
        True: exactly one end selected (the links around the selection: cutting them
        sets it loose); False: at least one (also the links inside it).

    Returns
    -------
    numpy.ndarray
        Pairs for :meth:`ChainMail.cut_pairs` / :meth:`ChainMail.link_pairs`, the lower
        index first.
    """
    m = np.asarray(mask, dtype=bool)
    if m.ndim != 3:
        raise ChainMailError(f"mask must be an (nx, ny, nz) bool array; got shape {m.shape}")
    out = []
    for axis in range(3):
        lo_t, hi_t = _link_ends(axis)
        a, b = m[lo_t], m[hi_t]
        low = np.argwhere(a ^ b if boundary else a | b)
        high = low.copy()
        high[:, axis] += 1
        out.append(np.stack([low, high], axis=1))
    return np.concatenate(out).astype(np.int64)


def _link_ends(axis: int) -> tuple[tuple[Any, ...], tuple[Any, ...]]:
    """Index tuples of the lower and upper ends of the links along ``axis``."""
    lo: list[Any] = [slice(None)] * 3
    hi: list[Any] = [slice(None)] * 3
    lo[axis] = slice(0, -1)
    hi[axis] = slice(1, None)
    return tuple(lo), tuple(hi)


def _possible(shape: tuple[int, int, int]) -> np.ndarray:
    """(nx, ny, nz, 3) bool: the links a grid of ``shape`` can have (none past the last
    layer along each axis)."""
    possible = np.ones((*shape, 3), dtype=bool)
    for a in range(3):
        idx: list[Any] = [slice(None)] * 3
        idx[a] = -1
        possible[(*idx, a)] = False
    return possible


def _stretched(value: Any) -> str:
    if value not in STRETCHED:
        raise ChainMailError(f"stretched must be one of {STRETCHED}; got {value!r}")
    return str(value)


def _stretched_message(links: np.ndarray, far: np.ndarray, excess: np.ndarray) -> str:
    """The error of a refused join: how many links, the worst and the fixes."""
    worst = int(np.argmax(np.where(far, excess, -np.inf)))
    a = [int(v) for v in links[worst, :3]]
    b = list(a)
    b[int(links[worst, 3])] += 1
    return (
        f"{int(far.sum())} of the links to join are beyond their limits where the elements"
        f" are now (worst: {tuple(a)}-{tuple(b)}, {float(excess[worst]):.3g} mm too far);"
        ' drag them closer first, or join with stretched="skip" to leave those cut or'
        ' stretched="pull" to pull them together'
    )


def _variant(value: Any) -> str:
    if value not in VARIANTS:
        raise ChainMailError(f"unknown variant {value!r}; valid variants: {VARIANTS}")
    return str(value)


def _count(value: Any, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
        raise ChainMailError(f"{what} must be an integer >= 0; got {value!r}")
    return int(value)


def _number(value: Any, what: str, *, lo: float, hi: float) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError) as exc:
        raise ChainMailError(f"{what} must be a number; got {value!r:.40}") from exc
    if not math.isfinite(x) or not lo <= x <= hi:
        raise ChainMailError(f"{what} must be in [{lo:g}, {hi:g}]; got {x!r}")
    return x


def _vec3(value: Any, what: str) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise ChainMailError(f"{what} must be 3 numbers (mm); got {value!r:.80}") from exc
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ChainMailError(f"{what} must be 3 finite numbers (mm); got {value!r:.80}")
    return a


def _compact(a: np.ndarray) -> Any:
    """A limit array as a number, 3 numbers (per axis) or a nested list."""
    flat = a.reshape(-1, 3)
    if np.all(flat == flat[0]):
        if np.all(flat[0] == flat[0, 0]):
            return float(flat[0, 0])
        return flat[0].tolist()
    return a.tolist()


def _grid_from(d: Mapping[str, Any]) -> ElementGrid:
    """The ``"grid"`` of a chainmail entry as an :class:`ElementGrid`."""
    return grid_from_entry(d, MODEL_TYPE, ChainMailError)


def _parse_held(held: Any, grid: ElementGrid) -> list[tuple[int, np.ndarray]]:
    """Validate a ``"held"`` list; returns (flat index, offset) pairs."""
    out = []
    for where, entry in held_items(held, MODEL_TYPE, ChainMailError):
        if not isinstance(entry, Mapping) or not {"index", "offset"} <= set(entry):
            raise ChainMailError(f"{where}: {HELD_FORM}; got {entry!r:.80}")
        raw = held_index(entry["index"], where, ChainMailError)
        try:
            idx = tuple(int(v) for v in grid.indices(raw)[0])
        except ElementGridError as exc:
            raise ChainMailError(f"{where}: {exc}") from exc
        if grid.fixed[idx]:
            raise ChainMailError(
                f"{where}: element {idx} is fixed and cannot be held; remove it from"
                " 'held' or free it in 'grid'"
            )
        off = _vec3(entry["offset"], f"{where} 'offset'")
        out.append((int(np.ravel_multi_index(idx, grid.shape)), off))
    return out
