"""When a minimum intensity projection shows nothing, and the slab that would.

A ray through a whole chest or head meets air (outside the body, in the lungs) or the
background somewhere, so its minimum is the window's black: a ``minip`` of a thick
volume is (nearly) all dark, physically right and useless. A slab a couple of
centimetres thick keeps the surrounding air out and shows the airways.
:func:`minip_slab_hint` says so in one phrase, which ``voxwarp render`` appends to the
line it prints about its choices (:meth:`voxwarp.scene.Scene.display_note`).

The test is cheap and done on the CPU: the minimum along the volume axis nearest the
view direction, on a copy strided to about :data:`HINT_VOXELS` voxels per axis and cut
to the box the rays march in (the clip box, ``--slab``); the hint appears when the rays
there cross more than :data:`THICK_MM` mm and at least :data:`DARK_SHARE` of them end
within :data:`DARK_LEVEL` of the window's low end.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from voxwarp.core.volume import Volume

#: Rays crossing less than this (mm) already look through a slab: no hint.
THICK_MM = 40.0
#: The hint appears when at least this share of the rays is dark ...
DARK_SHARE = 0.9
#: ... i.e. their minimum within this fraction of the window's width of its low end.
DARK_LEVEL = 0.05
#: The slab thickness (mm) the hint suggests.
SLAB_MM = 20.0
#: The estimate strides the volume to about this many voxels per axis.
HINT_VOXELS = 128

_PLANES = {0: "sagittal", 1: "coronal", 2: "axial"}


def dark_share(volume: Volume, window: tuple[float, float], axis: int, box: Sequence) -> float:
    """The share of rays along volume index ``axis`` through world box ``box`` (``(lo,
    hi)``, mm) whose minimum lies within :data:`DARK_LEVEL` of ``window``'s low end."""
    corners = np.array(
        [[box[i][0], box[j][1], box[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)]
    )
    idx = volume.world_to_index(corners)
    lo = np.clip(np.floor(idx.min(axis=0)).astype(int), 0, np.asarray(volume.shape) - 1)
    hi = np.clip(np.ceil(idx.max(axis=0)).astype(int) + 1, lo + 1, volume.shape)
    step = max(1, max(volume.shape) // HINT_VOXELS)
    sub = volume.data[lo[0] : hi[0] : step, lo[1] : hi[1] : step, lo[2] : hi[2] : step]
    level, width = window
    dark_below = level - width / 2 + DARK_LEVEL * width
    return float(np.mean(sub.min(axis=axis) <= dark_below))


class SlabAdvice(NamedTuple):
    """A nearly all dark ``minip``: along world ``axis`` (0, 1, 2) the rays cross
    ``thickness`` mm, ``share`` of them dark; a slab centred at ``centre`` mm helps."""

    axis: int
    centre: float
    thickness: float
    share: float

    def slab_box(self, box: Sequence, thickness: float = SLAB_MM) -> tuple[tuple, tuple]:
        """``box`` (``(lo, hi)``, world mm) cut to a ``thickness`` mm slab around
        :attr:`centre` along :attr:`axis` (a clip box)."""
        lo, hi = (np.asarray(b, dtype=np.float64).copy() for b in box)
        lo[self.axis] = max(lo[self.axis], self.centre - thickness / 2)
        hi[self.axis] = min(hi[self.axis], self.centre + thickness / 2)
        return tuple(map(float, lo)), tuple(map(float, hi))


def minip_advice(
    volume: Volume, window: tuple[float, float], back: Sequence[float], box: Sequence
) -> SlabAdvice | None:
    """A :class:`SlabAdvice` when a ``minip`` seen from direction ``back`` (the camera's,
    world) through world box ``box`` (``(lo, hi)``, mm: where the rays march) is nearly
    all dark, else None (see the module docstring)."""
    back = np.asarray(back, dtype=np.float64)
    world_axis = int(np.argmax(np.abs(back)))
    lo, hi = (np.asarray(b, dtype=np.float64) for b in box)
    thickness = float(hi[world_axis] - lo[world_axis])
    if thickness <= THICK_MM:
        return None
    directions = volume.affine[:3, :3] / np.linalg.norm(volume.affine[:3, :3], axis=0)
    axis = int(np.argmax(np.abs(directions.T @ back)))
    share = dark_share(volume, window, axis, (lo, hi))
    if share < DARK_SHARE:
        return None
    centre = 0.5 * (lo[world_axis] + hi[world_axis])
    return SlabAdvice(world_axis, centre, thickness, share)


def minip_slab_hint(
    volume: Volume, window: tuple[float, float], back: Sequence[float], box: Sequence
) -> str | None:
    """One phrase suggesting a slab when :func:`minip_advice` finds the ``minip`` nearly
    all dark; None otherwise."""
    advice = minip_advice(volume, window, back, box)
    if advice is None:
        return None
    oriented = volume.space == "RAS"
    letter = ("RAS" if oriented else "xyz")[advice.axis]
    plane = _PLANES[advice.axis] if oriented else "xyz"[advice.axis]
    return (
        f"the minIP through {advice.thickness:.0f} mm is {advice.share:.0%} dark (the air or"
        " background on the way is the minimum): a slab shows the airways, e.g. voxwarp"
        f" render --mode minip --slab {letter}:{advice.centre:.0f}:{SLAB_MM:g} or voxwarp"
        f" slice INPUT --plane {plane} --slab {SLAB_MM:g} --mode minip"
    )
