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
zero correction, so elements that nothing pushes do not move at all.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from voxwarp.deform.elements.chainmail_model import ChainMailModel

#: default cap of sweeps over all links (each sweep visits every link once)
MAX_SWEEPS = 4000
#: a sweep whose largest correction is below this fraction of the smallest spacing, with
#: every link satisfied to it, ends the iteration
TOL_FRACTION = 1e-7


def project_onto_limits(
    model: ChainMailModel,
    positions: Any,
    pinned: Any = None,
    max_sweeps: int = MAX_SWEEPS,
) -> tuple[np.ndarray, float, int]:
    """``positions`` moved as little as possible (least squares) onto ``model``'s limits.

    Parameters
    ----------
    model
        The limits and links (cut links bind nothing).
    positions
        (nx, ny, nz, 3) element positions (mm).
    pinned
        (nx, ny, nz) bool: elements that must not move (default ``model.fixed``).
    max_sweeps
        Cap on the sweeps over the links; a state not converged by then is left
        slightly outside the limits (the caller's propagation finishes it).

    Returns
    -------
    tuple
        ``(x, violation, sweeps)``: the (nx, ny, nz, 3) float64 projected positions,
        the largest violation (mm) of ``positions`` and the sweeps taken (0: nothing
        was violated).
    """
    y = np.asarray(positions, dtype=np.float64)
    x = y.copy()
    fixed = model.fixed if pinned is None else np.asarray(pinned, dtype=bool)
    free = (~fixed).astype(np.float64)
    before = model.violation(y)
    tol = TOL_FRACTION * float(np.min(model.spacing))
    groups = [_Group(model, free, axis, parity) for axis in range(3) for parity in (0, 1)]
    groups = [g for g in groups if g.size]
    sweeps = 0
    if before > tol:
        while sweeps < max_sweeps:
            sweeps += 1
            change = max(g.visit(x) for g in groups)
            if change <= tol and model.violation(x) <= tol:
                break
    return x, before, sweeps


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
