"""What carries over when an element model is switched for the other kind
(``MassSpring.from_model`` / ``ChainMail.from_model``; Knoche 2008, §5: ChainMail to
mass-spring is always possible, mass-spring to ChainMail must restore the limits).

Carried over: the element grid (a copy: rest positions, materials, boundary conditions:
anchor mode, region of influence, fixed, anchored and user-freed elements), the current
positions, and the held elements with their offsets. Not carried: velocities (the new
model starts still) and the other model's own settings. :class:`SwitchReport` says how
far the switch moved elements.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import numpy as np

from voxwarp.deform.elements.grid import ElementGrid

#: distances (mm) below this count as not moved
MOVED_TOL_MM = 1e-9


@dataclass(frozen=True)
class SwitchReport:
    """How far switching models moved the elements.

    Attributes
    ----------
    max_mm, rms_mm
        Largest and root-mean-square distance (mm) an element moved; the RMS is over
        all elements, the ones that did not move included.
    moved
        Elements that moved (by more than 1e-9 mm).
    violation_before
        Largest ChainMail limit violation (mm) of the positions taken over (0 for a
        switch to mass-spring, which has no limits).
    sweeps
        Sweeps of the projection onto the limits (0 when none was needed).
    cuts_joined
        Links a ChainMail had cut, which the mass-spring model (it has no cut springs)
        joins again with springs.
    anchors_freed
        Elements anchored by the region of influence that were freed because the
        limits could not be restored with them at rest.
    released
        Held elements let go because the limits could not be restored with them held.
    """

    max_mm: float
    rms_mm: float
    moved: int
    violation_before: float = 0.0
    sweeps: int = 0
    cuts_joined: int = 0
    anchors_freed: int = 0
    released: int = 0

    def describe(self) -> str:
        """One line for a status bar or a log."""
        if self.moved == 0:
            text = "deformation kept: no element moved"
        else:
            text = (
                f"deformation kept; {self.moved} element(s) moved up to {self.max_mm:.3g} mm"
                f" (RMS {self.rms_mm:.3g} mm)"
            )
            if self.violation_before > 0.0:
                text += f" to restore the ChainMail limits (worst {self.violation_before:.3g} mm)"
        if self.anchors_freed:
            text += f"; {self.anchors_freed} anchored element(s) freed"
        if self.released:
            text += f"; {self.released} held element(s) released"
        if self.cuts_joined:
            text += f"; {self.cuts_joined} cut link(s) joined by springs again"
        return text


def movement_report(before: Any, after: Any, **fields: Any) -> SwitchReport:
    """The :class:`SwitchReport` of positions ``before`` -> ``after`` ((..., 3) mm);
    ``fields``: its other attributes."""
    a = np.asarray(before, np.float64).reshape(-1, 3)
    b = np.asarray(after, np.float64).reshape(-1, 3)
    dist = np.linalg.norm(b - a, axis=1)
    return SwitchReport(
        max_mm=float(dist.max()) if dist.size else 0.0,
        rms_mm=float(np.sqrt(np.mean(dist * dist))) if dist.size else 0.0,
        moved=int(np.count_nonzero(dist > MOVED_TOL_MM)),
        **fields,
    )


def switched_grid(other: Any, grid: ElementGrid | None, error: type[Exception]) -> ElementGrid:
    """The grid of a model switched from ``other``: a copy of ``other.grid``, or
    ``grid`` (its materials, e.g. rebuilt from the session's settings) with ``other``'s
    boundary conditions (anchor mode, region of influence, fixed, anchored and
    user-freed elements). ``error`` when ``grid``'s elements are
    not ``other``'s (another shape or box)."""
    old = other.grid
    if grid is None:
        return copy.deepcopy(old)
    same = grid.shape == old.shape and np.allclose(
        grid.rest_positions, old.rest_positions, rtol=0.0, atol=1e-9 * float(np.max(old.spacing))
    )
    if not same:
        raise error(
            f"the grid {grid.shape} over {grid.lo.tolist()}..{grid.hi.tolist()} mm is not the"
            f" model's {old.shape} over {old.lo.tolist()}..{old.hi.tolist()} mm; switch on the"
            " same grid (grid=None copies it)"
        )
    grid.anchor, grid.fix_outside = old.anchor, old.fix_outside
    grid.fixed = old.fixed.copy()
    grid.anchored = old.anchored.copy()
    grid.unanchored = old.unanchored.copy()
    return grid


def held_state(other: Any) -> tuple[np.ndarray, np.ndarray]:
    """``other``'s held elements ((nx, ny, nz) bool) and their offsets from rest
    ((nx, ny, nz, 3) mm)."""
    held = np.asarray(other.held, dtype=bool)
    offsets = np.where(held[..., None], np.asarray(other.held_offsets, np.float64), 0.0)
    return held, offsets
