"""Projecting element positions onto the ChainMail limits with the least movement:
what :meth:`ChainMail.from_model <voxwarp.deform.elements.chainmail.ChainMail.from_model>`
does to a mass-spring state (Knoche 2008, §5: a mass-spring result in general breaks
the ChainMail's geometric limits, so a switch to ChainMail must restore them).

The limits of :mod:`voxwarp.deform.elements.chainmail_model` decouple per coordinate:
coordinate ``c`` of the link ``a -> b`` asks ``lo <= x_b[c] - x_a[c] <= hi`` (a slab).
The least movement, in the sum of squared distances, that satisfies every present link
with the pinned elements (fixed, anchored, held) where they are is the Euclidean
projection onto the intersection of those slabs. :func:`project_onto_limits` computes
it with Hildreth's method (Dykstra's alternating projections for halfspaces): it visits
the links again and again, each time undoing the correction it made at its last visit
and projecting that link alone (both free ends move half the excess apart or together,
a free end of a pinned one the whole excess), and converges to that projection. Links
are visited in six groups (axis x parity of the lower end) whose links share no
element, so a group is one vectorised step. A link that never was violated keeps a
zero correction, so elements that nothing pushes do not move at all, and the sweeps run
on a box around the violated links only (grown while its border has to give way).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from voxwarp.deform.elements.chainmail_model import ChainMailModel

EPS = float(np.finfo(np.float64).eps)
#: elements the first box reaches beyond the violated links
PAD = 2
#: default cap of sweeps over all links (each sweep visits every link once)
MAX_SWEEPS = 4000
#: a sweep whose largest correction is below this fraction of the smallest spacing, with
#: every link satisfied to it, ends the iteration: far below the propagation's round-off
#: tolerance (1e-9 mm), so the result needs no repair, which could fail where many links
#: sit at their limits (the sweeps converge linearly: about 20 more per factor of 10)
TOL_FRACTION = 1e-12


def project_onto_limits(
    model: ChainMailModel,
    positions: Any,
    pinned: Any = None,
    max_sweeps: int = MAX_SWEEPS,
) -> tuple[np.ndarray, float, int]:
    """``positions`` moved as little as possible (least squares) onto ``model``'s limits.

    Only a box of elements is iterated on: the violated links' elements padded by
    :data:`PAD`, the layer around it held where it is. When a link into that layer
    ends up corrected (the layer would have to move), the box doubles and the
    projection starts again; otherwise the layer's links need no force, and the box's
    projection is the whole grid's.

    Parameters
    ----------
    model
        The limits and links (cut links bind nothing).
    positions
        (nx, ny, nz, 3) element positions (mm).
    pinned
        (nx, ny, nz) bool: elements that must not move (default ``model.fixed``).
    max_sweeps
        Cap on the sweeps over the links per box; a state not converged by then is
        left slightly outside the limits (the caller's propagation finishes it).

    Returns
    -------
    tuple
        ``(x, violation, sweeps)``: the (nx, ny, nz, 3) float64 projected positions,
        the largest violation (mm) of ``positions`` and the sweeps taken over all boxes
        (0: nothing was violated).
    """
    y = np.asarray(positions, dtype=np.float64)
    fixed = model.fixed if pinned is None else np.asarray(pinned, dtype=bool)
    before = model.violation(y)
    # (and above the round-off of differences of positions this far from the origin)
    tol = max(TOL_FRACTION * float(np.min(model.spacing)), 64 * EPS * float(np.max(np.abs(y))))
    x = y.copy()
    if before <= tol:
        return x, before, 0
    shape = np.asarray(model.shape)
    where = np.argwhere(_violated(model, y, tol))
    lo = np.maximum(where.min(axis=0) - PAD, 0)
    hi = np.minimum(where.max(axis=0) + 1 + PAD, shape)
    total = 0
    while True:
        ext = tuple(
            slice(int(a), int(b))
            for a, b in zip(np.maximum(lo - 1, 0), np.minimum(hi + 1, shape), strict=True)
        )
        ring = np.ones(y[ext].shape[:3], dtype=bool)
        ring[
            tuple(
                slice(int(a - e.start), int(b - e.start))
                for a, b, e in zip(lo, hi, ext, strict=True)
            )
        ] = False
        sub = _sub_model(model, ext, fixed[ext] | ring)
        xs, engaged, sweeps = _hildreth(sub, y[ext], tol, max_sweeps)
        total += sweeps
        if not np.any(engaged & ring):
            x[ext] = xs
            return x, before, total
        size = hi - lo
        lo, hi = np.maximum(lo - size, 0), np.minimum(hi + size, shape)


def _violated(model: ChainMailModel, x: np.ndarray, tol: float) -> np.ndarray:
    """(nx, ny, nz) bool: elements with a link violated by more than ``tol`` mm."""
    out = np.zeros(model.shape, dtype=bool)
    for axis in range(3):
        if model.shape[axis] < 2:
            continue
        mn, mx, sh, linked = model.link_limits(axis)
        d = np.diff(x, axis=axis)
        v = np.maximum(mn - d[..., axis], d[..., axis] - mx)
        for j in range(3):
            if j != axis:
                v = np.maximum(v, np.abs(d[..., j]) - sh)
        bad = linked & (v > tol)
        lo: list[Any] = [slice(None)] * 3
        hi: list[Any] = [slice(None)] * 3
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        out[tuple(lo)] |= bad
        out[tuple(hi)] |= bad
    return out


def _sub_model(model: ChainMailModel, box: tuple[slice, ...], fixed: np.ndarray) -> ChainMailModel:
    """``model`` on the elements of ``box`` (its links out of the box dropped)."""
    return ChainMailModel(
        rest=model.rest[box],
        spacing=model.spacing,
        min_dist=model.min_dist[box],
        max_dist=model.max_dist[box],
        max_shear=model.max_shear[box],
        links=model.links[box],
        fixed=fixed,
    )


def _hildreth(
    model: ChainMailModel, y: np.ndarray, tol: float, max_sweeps: int
) -> tuple[np.ndarray, np.ndarray, int]:
    """Hildreth's sweeps from ``y`` with ``model.fixed`` pinned: the positions, the
    elements of links left with a correction, and the sweeps taken."""
    x = y.copy()
    free = (~model.fixed).astype(np.float64)
    groups = [_Group(model, free, axis, parity) for axis in range(3) for parity in (0, 1)]
    groups = [g for g in groups if g.size]
    sweeps = 0
    while groups and sweeps < max_sweeps:
        sweeps += 1
        change = max(g.visit(x) for g in groups)
        if change <= tol and model.violation(x) <= tol:
            break
    engaged = np.zeros(model.shape, dtype=bool)
    for g in groups:
        g.mark_engaged(engaged)
    return x, engaged, sweeps


class _Group:
    """The links along ``axis`` whose lower end has index ``parity`` modulo 2 along it:
    no two share an element. Keeps each link's last correction (per coordinate)."""

    def __init__(self, model: ChainMailModel, free: np.ndarray, axis: int, parity: int) -> None:
        n = model.shape[axis]
        lo_idx: list[Any] = [slice(None)] * 3
        hi_idx: list[Any] = [slice(None)] * 3
        lo_idx[axis] = slice(parity, n - 1, 2)
        hi_idx[axis] = slice(parity + 1, n, 2)
        self.a, self.b = tuple(lo_idx), tuple(hi_idx)
        mn, mx, sh, linked = model.link_limits(axis)
        sub: list[Any] = [slice(None)] * 3
        sub[axis] = slice(parity, None, 2)
        sub_t = tuple(sub)
        shape = (*linked[sub_t].shape, 3)
        self.size = int(np.prod(shape[:3]))
        lo = np.broadcast_to(-sh[sub_t][..., None], shape).copy()
        hi = np.broadcast_to(sh[sub_t][..., None], shape).copy()
        lo[..., axis], hi[..., axis] = mn[sub_t], mx[sub_t]
        cut = ~linked[sub_t]
        lo[cut], hi[cut] = -np.inf, np.inf
        self.lo, self.hi = lo, hi
        self.fa, self.fb = free[self.a][..., None], free[self.b][..., None]
        w = self.fa + self.fb
        # a link between two pinned elements cannot be corrected here
        self.inv_w = np.divide(1.0, w, out=np.zeros_like(w), where=w > 0)
        self.t = np.zeros(shape)

    def mark_engaged(self, engaged: np.ndarray) -> None:
        """Set ``engaged`` at both ends of every link left with a correction."""
        active = np.any(self.t != 0.0, axis=-1)
        engaged[self.a] |= active
        engaged[self.b] |= active

    def visit(self, x: np.ndarray) -> float:
        """Undo this group's last corrections, project each link alone; the largest
        change of a correction (mm)."""
        if not self.size:
            return 0.0
        xa, xb = x[self.a], x[self.b]
        # the gap as it would be without this group's last correction t, which moved
        # b by -t fb and a by +t fa (t > 0 shortened the link)
        g = (xb - xa) + self.t * (self.fa + self.fb)
        t_new = (np.maximum(g - self.hi, 0.0) - np.maximum(self.lo - g, 0.0)) * self.inv_w
        dt = t_new - self.t
        xa += dt * self.fa
        xb -= dt * self.fb
        self.t = t_new
        return float(np.max(np.abs(dt))) if dt.size else 0.0
