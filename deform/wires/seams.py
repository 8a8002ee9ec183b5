"""Seam fade of smooth-sides wires: where the closest point on the wires jumps (on the
concave side of a bend, past its radius of curvature; where two wires' regions meet), the
sweep of the closest point is discontinuous while the side weight w is still > 0, which
tears the map. :func:`fade_seams` finds those voxels of the field and fades w to 0 at them
with a smoothstep of the distance to them, so the map goes continuously to the identity.

Use: ``n = fade_seams(weight, known, wire, u, (origin, h), tables, wires)`` on the region's weight
(changed in place) before the field is stored."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import ndimage

from voxwarp.deform.wires.constants import LUT_SIZE, SEAM_STEP_VOXELS, SIDE_FALLOFF_MOVES
from voxwarp.deform.wires.geometry import _smoothstep
from voxwarp.deform.wires.tables import WireTables, map_points
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


def _moves(
    weight: np.ndarray,
    u: np.ndarray,
    tab: WireTables,
    sel: np.ndarray,
    origin: np.ndarray,
    h: np.ndarray,
) -> np.ndarray:
    """|w (A p + b - p)| (mm) at the region voxels of flat indices ``sel`` (their centres
    ``origin + index * h``): the displacement a seam fade has to take away."""
    p = origin + np.stack(np.unravel_index(sel, weight.shape), -1) * h
    q = map_points(tab, u.ravel()[sel] * (LUT_SIZE - 1), p)
    return weight.ravel()[sel] * np.linalg.norm(q - p, axis=1)


def seam_width(
    dist: np.ndarray, zone: np.ndarray, moves: np.ndarray, falloff: float, floor: float
) -> float:
    """The seam fade's width (mm) for one wire: the smallest W >= ``floor`` with
    W >= :data:`SIDE_FALLOFF_MOVES` x the largest weighted move within W of a seam (the
    side fade's rule that keeps det J > 0, applied to what the seam fade takes away), at
    most ``falloff``. ``dist`` and ``moves`` are given at the wire's voxels ``zone``
    (flat indices), ``moves`` from :func:`_moves`."""
    d = dist.ravel()[zone]
    width = floor
    for _ in range(64):
        near = d < width
        need = SIDE_FALLOFF_MOVES * float(moves[near].max()) if near.any() else 0.0
        if need <= width or width >= falloff:
            return min(width, falloff)
        width = need
    return falloff


def fade_seams(
    weight: np.ndarray,
    known: np.ndarray,
    wire: np.ndarray,
    u: np.ndarray,
    grid: tuple[np.ndarray, np.ndarray],
    tables: Sequence[WireTables],
    wires: Sequence[Wire],
) -> int:
    """Multiply the weights of smooth-sides wires' voxels by a smoothstep of their
    distance (mm) to the nearest seam voxel (0 at the seam, so the map meets the identity
    there continuously) over a width that does not fold (:func:`seam_width`: at most the
    wire's ``side_falloff``); returns how many voxels with weight > 0 changed. No seam (or
    no smooth-sides wire): ``weight`` is left untouched. ``grid`` is the region voxel
    (0, 0, 0)'s centre and the voxel size (mm)."""
    smooth = np.array([w.smooth_sides for w in wires], dtype=bool)
    if not smooth.any():
        return 0
    origin, h = (np.asarray(x, dtype=np.float64) for x in grid)
    lengths = np.array([t.length_modified for t in tables], dtype=np.float64)
    seam = seam_voxels(weight, known, wire, u, h, lengths, smooth)
    if not seam.any():
        return 0
    dist = ndimage.distance_transform_edt(~seam, sampling=tuple(float(x) for x in h))
    width = np.full(len(wires), np.inf)
    for wi, w in enumerate(wires):
        zone = np.flatnonzero(known & (wire == wi) & (weight > 0))
        if w.smooth_sides and len(zone):
            near = zone[dist.ravel()[zone] < w.side_falloff]
            moves = _moves(weight, u, tables[wi], near, origin, h)
            width[wi] = seam_width(dist, near, moves, w.side_falloff, 2.0 * float(h.max()))
    gid = np.where(wire >= 0, wire, 0)
    factor = _smoothstep(dist / width[gid])
    faded = known & (wire >= 0) & smooth[gid] & (factor < 1.0) & (weight > 0)
    weight[faded] = (weight[faded] * factor[faded]).astype(np.float32)
    return int(faded.sum())
