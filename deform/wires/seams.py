"""Seam fade of smooth-sides wires: where the closest point on the wires jumps (on the
concave side of a bend, past its radius of curvature; where two wires' regions meet), the
sweep of the closest point is discontinuous while the side weight w is still > 0, which
tears the map. :func:`fade_seams` finds those voxels of the field and fades w to 0 at them
with a smoothstep of the distance to them, so the map goes continuously to the identity.

Use: ``n = fade_seams(weight, known, wire, u, h, tables, wires)`` on the region's weight
(changed in place) before the field is stored."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import ndimage

from voxwarp.deform.wires.constants import SEAM_STEP_VOXELS
from voxwarp.deform.wires.geometry import _smoothstep
from voxwarp.deform.wires.tables import WireTables
from voxwarp.deform.wires.wire import Wire


def _pair(axis: int, first: bool) -> tuple[slice, slice, slice]:
    """Index of the first (or second) voxel of every 6-neighbour pair along ``axis``."""
    s = [slice(None)] * 3
    s[axis] = slice(0, -1) if first else slice(1, None)
    return s[0], s[1], s[2]


def seam_voxels(
    weight: np.ndarray,
    known: np.ndarray,
    wire: np.ndarray,
    u: np.ndarray,
    h: np.ndarray,
    lengths: np.ndarray,
    smooth: np.ndarray,
) -> np.ndarray:
    """Voxels of 6-neighbour pairs (both ``known`` with weight > 0, one of a smooth-sides
    wire) whose wire id differs or whose closest point moves along the wire by more than
    :data:`SEAM_STEP_VOXELS` field voxels (``|du| * length > k * h``)."""
    gid = np.where(known & (wire >= 0), wire, 0).astype(np.int64)
    live = known & (wire >= 0) & (weight > 0)
    seam = np.zeros(weight.shape, dtype=bool)
    for axis in range(3):
        a, b = _pair(axis, True), _pair(axis, False)
        ga, gb = gid[a], gid[b]
        jump = (ga != gb) | (np.abs(u[a] - u[b]) * lengths[ga] > SEAM_STEP_VOXELS * h[axis])
        pair = live[a] & live[b] & (smooth[ga] | smooth[gb]) & jump
        seam[a] |= pair
        seam[b] |= pair
    return seam


def fade_seams(
    weight: np.ndarray,
    known: np.ndarray,
    wire: np.ndarray,
    u: np.ndarray,
    h: np.ndarray,
    tables: Sequence[WireTables],
    wires: Sequence[Wire],
) -> int:
    """Multiply the weights of smooth-sides wires' voxels by a smoothstep of their
    distance (mm) to the nearest seam voxel over the wire's ``side_falloff`` (the width
    that does not fold, as for the side fade); returns how many voxels with weight > 0
    changed. No seam (or no smooth-sides wire): ``weight`` is left untouched."""
    smooth = np.array([w.smooth_sides for w in wires], dtype=bool)
    if not smooth.any():
        return 0
    lengths = np.array([t.length_modified for t in tables], dtype=np.float64)
    seam = seam_voxels(weight, known, wire, u, np.asarray(h, dtype=np.float64), lengths, smooth)
    if not seam.any():
        return 0
    dist = ndimage.distance_transform_edt(~seam, sampling=tuple(float(x) for x in h))
    width = np.array([w.side_falloff if w.smooth_sides else np.inf for w in wires])
    gid = np.where(wire >= 0, wire, 0)
    factor = _smoothstep(dist / width[gid])
    faded = known & (wire >= 0) & smooth[gid] & (factor < 1.0) & (weight > 0)
    weight[faded] = (weight[faded] * factor[faded]).astype(np.float32)
    return int(faded.sum())
