"""Small geometry helpers of the wire field build: closest-point refinement,
wire-local coordinates, the smooth fade, index boxes."""

from __future__ import annotations

import numpy as np

from voxwarp.deform.wires.constants import LUT_SIZE, RADIAL_FADE, REFINE_STEPS
from voxwarp.deform.wires.curves import Curve
from voxwarp.deform.wires.tables import WireTables
from voxwarp.deform.wires.wire import Wire


def _refine_u(
    points: np.ndarray, tangents: np.ndarray, length: float, u: np.ndarray, p: np.ndarray
) -> np.ndarray:
    """Closest-point fractions u of points p, refined from the nearest seed's u.

    The nearest seed voxel's u is off by up to about a voxel along the wire, and where
    the wire twists fast that error turns the cross-section (by twist rate x error). Each
    step moves u by the along-wire offset of p from the wire point at u (a Newton step of
    the closest-point condition, ignoring curvature), using the nearest table entry of
    the wire's ``points`` and unit ``tangents`` (equally spaced in arc length).
    """
    n = len(points) - 1
    u = np.asarray(u, dtype=np.float64)
    for _ in range(REFINE_STEPS):
        i = np.clip(np.rint(u * n).astype(np.int64), 0, n)
        z = np.einsum("ni,ni->n", p - points[i], tangents[i])
        u = np.clip(i / n + z / length, 0.0, 1.0)
    return u


def _region_centres(
    lo: np.ndarray,
    h: np.ndarray,
    region_lo: np.ndarray,
    rshape: tuple[int, int, int],
    flat: np.ndarray,
) -> np.ndarray:
    """World centres (mm) of region voxels given by flat region indices."""
    ii = np.stack(np.unravel_index(flat, rshape), -1)
    return lo + (ii + region_lo + 0.5) * h


def side_tables(tab: WireTables, side: str) -> tuple[np.ndarray, np.ndarray, float]:
    """The wire points, frames and arc length of ``side`` (``"modified"`` or ``"base"``)."""
    if side == "modified":
        return tab.modified_points, tab.modified_frames, tab.length_modified
    return tab.base_points, tab.base_frames, tab.length_base


def _wire_local(
    tab: WireTables, side: str, u: np.ndarray, p: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Coordinates (x, y, z) of points p in the frame of ``side``'s wire at their
    closest point (u refined from the given u), and that u."""
    points, frames, length = side_tables(tab, side)
    u = _refine_u(points, frames[:, :, 2], length, u, p)
    i = np.rint(u * (LUT_SIZE - 1)).astype(np.int64)
    x, y, z = _frame_coords(points, frames, i, p)
    return x, y, z, u


def _frame_coords(
    points: np.ndarray,
    frames: np.ndarray,
    i: np.ndarray,
    p: np.ndarray,
    axes: tuple[int, ...] = (0, 1, 2),
) -> tuple[np.ndarray, ...]:
    """Coordinates of points p along ``axes`` of the frames at table entries ``i``
    (x, y, z for the default axes)."""
    d = p - points[i]
    f = frames[i]
    return tuple(np.einsum("ni,ni->n", d, f[:, :, a]) for a in axes)


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _fade(wire: Wire, tab: WireTables, u: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Displacement weight of deformed points p of a smooth wire: 1 within its (scaled)
    radius and between its end planes, fading smoothly (smoothstep) to 0 beyond the
    radius over ``side_falloff`` mm (``sides="smooth"``) or :data:`RADIAL_FADE` times
    the radius (smooth ends only), and over ``falloff`` mm beyond each end plane
    (``ends="smooth"``; rigid ends keep 1 there)."""
    x, y, z, u = _wire_local(tab, "modified", u, p)
    rm = wire.radius * wire.scale_at(u)
    width = wire.side_falloff if wire.smooth_sides else RADIAL_FADE * rm
    radial = 1.0 - _smoothstep((np.hypot(x, y) - rm) / width)
    if not wire.smooth:
        return radial.astype(np.float32)
    beyond = np.where(u >= 1.0, np.maximum(z, 0.0), 0.0) + np.where(
        u <= 0.0, np.maximum(-z, 0.0), 0.0
    )
    along = 1.0 - _smoothstep(beyond / wire.falloff)
    return (radial * along).astype(np.float32)


def _box_overlap(
    a_lo: np.ndarray, a_shape: tuple[int, int, int], b_lo: np.ndarray, b_shape: tuple[int, int, int]
) -> tuple[tuple[slice, ...], tuple[slice, ...]] | None:
    """The overlap of boxes a and b (first voxel, shape) as slices into each, or None."""
    first = np.maximum(a_lo, b_lo)
    end = np.minimum(np.asarray(a_lo) + a_shape, np.asarray(b_lo) + b_shape)
    if np.any(end <= first):
        return None
    into_a = tuple(slice(int(f - a), int(e - a)) for f, e, a in zip(first, end, a_lo, strict=True))
    into_b = tuple(slice(int(f - b), int(e - b)) for f, e, b in zip(first, end, b_lo, strict=True))
    return into_a, into_b


def _box_slices(first: np.ndarray, shape: tuple[int, int, int]) -> tuple[slice, slice, slice]:
    return tuple(slice(int(first[a]), int(first[a]) + shape[a]) for a in range(3))  # type: ignore[return-value]


_CORNERS = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=np.int64)


def _curve_box(curve: Curve) -> tuple[np.ndarray, np.ndarray]:
    pts = curve.evaluate(np.linspace(0.0, 1.0, 257))
    return pts.min(axis=0), pts.max(axis=0)
