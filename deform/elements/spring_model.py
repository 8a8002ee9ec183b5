"""The mass-spring model's parameters and physics, shared by its CPU and GPU solvers.

About this technique (Knoche 2008, "GPU-based volume deformation using mass-spring
systems", 2.4, 3.5, 3.6)
------------------------------------------------------------------------------------
An n_x x n_y x n_z grid of *elements* (point masses) spans the volume; springs join
neighbouring elements. Dragging elements moves their neighbours through the springs;
the elements' displacements form the *offset field* that the raycaster inverts.

Every solver (``CpuSpringSolver`` in :mod:`voxwarp.deform.elements.massspring`, ``GpuSpringSolver``
in
:mod:`voxwarp.deform.elements.massspring_gpu`) implements exactly this, so their results agree to
float32 round-off:

* Springs from element ``a`` to each neighbour ``b = a + o`` inside the grid, for the
  offsets ``o`` of :func:`spring_offsets`: 6 structural (±1 along an axis), with
  ``shear`` 12 more (±1 along two axes), with ``bend`` 6 more (±2 along an axis).
  Rest length ``L = |o * spacing|``; spring constant
  ``k_ab = spring_constant * (stiffness_a + stiffness_b) / 2``.
* Force on ``a``: ``sum_b [k_ab (|d| - L) d^ + spring_damping ((v_b - v_a) . d^) d^]
  - damping_a v_a`` with ``d = x_b - x_a``, ``d^ = d / |d|`` (0 when ``|d|`` is below
  :attr:`SpringModel.min_length`, 1e-4 of the smallest spacing: far above float32
  round-off of positions, so an element dragged onto its neighbour feels no spring on
  every backend).
  Acceleration ``f / mass_a``.
* Integrators: ``"explicit"`` (the thesis' choice): ``x' = x + dt v``,
  ``v' = v + dt a``; ``"semi-implicit"`` (symplectic Euler): ``v' = v + dt a``,
  ``x' = x + dt v'`` (position Verlet with the velocity kept as state is the same
  update, so it is not a third option).
* Displacement clamp (thesis 3.5.2): when ``|x' - x| > max_step`` (mm, 0 = off), both
  ``x' - x`` and ``v'`` are scaled by ``max_step / |x' - x|``.
* Pinned elements (fixed, held by a drag, or stiffness 1) are then set to their
  target position with zero velocity.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

INTEGRATORS: tuple[str, ...] = ("explicit", "semi-implicit")
#: A spring shorter than this fraction of the smallest element spacing has no direction.
MIN_LENGTH_FRACTION = 1e-4


def spring_offsets(shear: bool = False, bend: bool = False) -> np.ndarray:
    """Integer neighbour offsets (m, 3) of the springs of one element (see module doc)."""
    offs = [o for a in range(3) for o in _axis(a, 1)]
    if shear:
        for a in range(3):
            for b in range(a + 1, 3):
                for sa in (1, -1):
                    for sb in (1, -1):
                        o = [0, 0, 0]
                        o[a], o[b] = sa, sb
                        offs.append(tuple(o))
    if bend:
        offs += [o for a in range(3) for o in _axis(a, 2)]
    return np.array(offs, dtype=np.int64)


def _axis(a: int, step: int) -> list[tuple[int, ...]]:
    out = []
    for s in (step, -step):
        o = [0, 0, 0]
        o[a] = s
        out.append(tuple(o))
    return out


@dataclass
class SpringModel:
    """Everything a solver needs: grid, materials, springs, integrator (see module doc).

    Arrays are indexed ``[i, j, k]`` along x, y, z. Positions are world units (mm).
    """

    #: (nx, ny, nz, 3) rest positions
    rest: np.ndarray
    #: (3,) rest distance between neighbouring elements per axis
    spacing: np.ndarray
    #: (nx, ny, nz) in [0, 1]
    stiffness: np.ndarray
    #: (nx, ny, nz) velocity damping per element, >= 0 (1/s)
    damping: np.ndarray
    #: (nx, ny, nz) > 0
    mass: np.ndarray
    spring_constant: float = 50.0
    spring_damping: float = 0.5
    shear: bool = False
    bend: bool = False
    integrator: str = "explicit"
    dt: float = 0.01
    #: clamp of one step's displacement (mm); 0 = off
    max_step: float = 0.0
    offsets: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.offsets = spring_offsets(self.shear, self.bend)

    @property
    def shape(self) -> tuple[int, int, int]:
        """Elements per axis."""
        return tuple(int(n) for n in self.rest.shape[:3])  # type: ignore[return-value]

    @property
    def min_length(self) -> float:
        """Springs shorter than this (mm) have no direction (``d^ = 0``)."""
        return MIN_LENGTH_FRACTION * float(np.min(self.spacing))

    def rest_lengths(self) -> np.ndarray:
        """(m,) rest length of each spring offset."""
        return np.linalg.norm(self.offsets * np.asarray(self.spacing, float), axis=1)
