"""Boundary conditions of the element grid: which elements are held at rest so that a
drag stays local.

Two conditions, both shared by mass-spring and ChainMail:

* the **anchor mode** (:data:`ANCHOR_MODES`) picks the grid's default *fixed* elements:
  ``"shell"`` (every element on the grid's outer faces: the box is a wall the tissue
  is attached to), ``"corners"`` (the 8 corners only, the thesis's set-up, Knoche 2008
  3.6: the grid cannot drift but a drag moves everything) or ``"none"``;
* the **region of influence** (``fix_outside``, mm): while elements are held by a drag,
  every element farther than the radius from all held elements is *anchored* at rest.
  Anchored elements are pinned like fixed ones but kept apart from them
  (``ElementGrid.anchored``), so each new drag recomputes them.

:func:`influence_radius` is the default radius (``fix_outside="auto"``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from voxwarp.errors import VoxwarpError

#: the anchor modes: fixed elements of a new grid
ANCHOR_MODES = ("shell", "corners", "none")
#: the anchor mode of a new grid (a saved grid without ``"anchor"`` is ``"corners"``)
DEFAULT_ANCHOR = "shell"
#: a setting's anchor ``"default"``: the model's own (the settings class's
#: ``default_anchor``, :mod:`voxwarp.editing.model_settings`)
MODEL_DEFAULT = "default"
#: what a setting may say: a mode, or the model's own default
ANCHOR_CHOICES = (MODEL_DEFAULT, *ANCHOR_MODES)
#: ``fix_outside``: the radius follows the grid and the drag
AUTO = "auto"
#: ``fix_outside`` of a new grid: ``"auto"`` with the shell anchor, off with the others
#: (``"corners"`` is the thesis's set-up, ``"none"`` no boundary condition at all)
DEFAULT = "default"
#: the shortest automatic radius (mm): a push fades over a few centimetres
MIN_INFLUENCE_MM = 30.0
#: the automatic radius is at least this many element spacings ...
SPACINGS_PER_RADIUS = 4.0
#: ... and at least this many times the largest drag
DRAGS_PER_RADIUS = 3.0


class AnchorError(VoxwarpError, ValueError):
    """A bad anchor mode or region radius (the message names the fix)."""


def check_anchor(mode: Any) -> str:
    """``mode`` if it is one of :data:`ANCHOR_MODES`; else an :class:`AnchorError`."""
    if mode not in ANCHOR_MODES:
        raise AnchorError(f"unknown anchor {mode!r}; choose one of {', '.join(ANCHOR_MODES)}")
    return str(mode)


def check_fix_outside(value: Any, anchor: str = DEFAULT_ANCHOR) -> float | str | None:
    """The region radius as stored: a positive float (mm), ``"auto"`` or None (off).

    Accepts a number (0 turns the region off), ``"off"``, ``"auto"``, None, or
    :data:`DEFAULT` (``"auto"`` with the ``"shell"`` anchor, else off)."""
    if isinstance(value, str) and value == DEFAULT:
        return AUTO if anchor == "shell" else None
    if value is None or value == "off":
        return None
    if value == AUTO:
        return AUTO
    try:
        r = float(value)
    except (TypeError, ValueError) as exc:
        raise AnchorError(
            f"fix_outside must be a radius in mm (0 or 'off': none, 'auto'); got {value!r}"
        ) from exc
    if not np.isfinite(r) or r < 0:
        raise AnchorError(f"fix_outside must be a finite radius >= 0 mm; got {value!r}")
    return r if r > 0 else None


def anchor_mask(shape: tuple[int, int, int], mode: str) -> np.ndarray:
    """Bool mask of the elements ``mode`` fixes on a grid of ``shape``.

    ``"shell"``: every element with an index 0 or n-1 on some axis
    (``n^3 - (n-2)^3`` of an n^3 grid); ``"corners"``: the 8 corners; ``"none"``: none.
    """
    m = np.zeros(shape, dtype=bool)
    mode = check_anchor(mode)
    if mode == "corners":
        m[:: shape[0] - 1, :: shape[1] - 1, :: shape[2] - 1] = True
    elif mode == "shell":
        m[[0, -1], :, :] = True
        m[:, [0, -1], :] = True
        m[:, :, [0, -1]] = True
    return m


def influence_radius(spacing: Any, drag_mm: float) -> float:
    """The automatic region radius (mm) for a grid ``spacing`` and the largest drag.

    ``max(30 mm, 4 spacings, 3 x drag)``: four spacings leave at least three free
    elements between a held element and the first anchored one, so the push can fade
    rather than stop at a wall; three times the drag keeps the mean strain of the
    fading tissue under a third (soft tissue tolerates tens of per cent); 30 mm lets a
    small push on a fine grid still fade over a few centimetres, as pressed tissue does.
    """
    h = float(np.max(np.asarray(spacing, dtype=np.float64)))
    return max(MIN_INFLUENCE_MM, SPACINGS_PER_RADIUS * h, DRAGS_PER_RADIUS * float(drag_mm))


def outside_mask(spacing: Any, held: np.ndarray, radius: float) -> np.ndarray:
    """Elements farther than ``radius`` mm (at rest) from every ``held`` element.

    An exact Euclidean distance transform over the grid with its ``spacing``; all False
    when nothing is held (no drag, no region).
    """
    from scipy import ndimage  # scipy loads when used: the CLI's options import this module

    held = np.asarray(held, dtype=bool)
    if not held.any():
        return np.zeros(held.shape, dtype=bool)
    dist = ndimage.distance_transform_edt(~held, sampling=np.asarray(spacing, dtype=np.float64))
    return dist > radius


def region_radius(fix_outside: float | str | None, spacing: Any, offsets: Any) -> float | None:
    """The radius (mm) a region setting gives for these held ``offsets`` ((m, 3) mm)."""
    if fix_outside is None:
        return None
    if fix_outside == AUTO:
        off = np.asarray(offsets, dtype=np.float64).reshape(-1, 3)
        drag = float(np.max(np.linalg.norm(off, axis=1))) if len(off) else 0.0
        return influence_radius(spacing, drag)
    return float(fix_outside)


def describe(
    mode: str, fix_outside: float | str | None, spacing: Any, drag_mm: float | None = None
) -> str:
    """One phrase of the boundary conditions, e.g. ``grid shell fixed; elements beyond
    45 mm of a drag anchored (auto)``; ``drag_mm``: the largest drag, if known."""
    fixed = {"shell": "grid shell fixed", "corners": "8 grid corners fixed"}.get(
        mode, "no grid element fixed"
    )
    if fix_outside is None:
        return f"{fixed}; no region of influence"
    if fix_outside == AUTO and drag_mm is None:
        low = influence_radius(spacing, 0.0)
        return (
            f"{fixed}; elements beyond max({low:.0f} mm, {DRAGS_PER_RADIUS:g} x drag) of a"
            " drag anchored"
        )
    r = region_radius(fix_outside, spacing, np.array([[drag_mm or 0.0, 0.0, 0.0]]))
    how = " (auto)" if fix_outside == AUTO else ""
    return f"{fixed}; elements beyond {r:.3g} mm of a drag anchored{how}"
