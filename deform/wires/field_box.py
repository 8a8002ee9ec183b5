"""The attribute field's box: the volume box grown only where a wire can bring the
object's content.

A wire moves everything its plane masks hold, and smooth ends reach far beyond the
curve's ends (the fade's length, by default twice the ends' move). Growing the volume
box by the whole reach everywhere made an MRI head's 1:1 field 2.6x the volume's
voxels, and the build pays for every voxel. Only deformed points whose original
lies in the volume show anything: :func:`content_box` bounds where those can be, and
:func:`escapes` checks the built field against that bound.

How: a swept point p is mapped by its wire's table at its fraction u to
``p + w (A p + b - p)`` (w in [0, 1] the fade, 1 on a rigid wire), a point of the
segment from p to ``A p + b``. Each table entry holds its swept points within a
*probe*, a ball around the modified curve's point as wide as the entry's plane masks
(and past the ends, balls along the end's tangent as far as the end's fade). For the
points p of a box C and a fixed w, ``p + w (A p + b - p)`` is an affine image of C,
bounded by a box; :data:`WEIGHTS` steps of w, each box grown by half the way to the
next step, bound the whole segment. A run of probes is bounded by one
representative and a margin (how far the run's other entries move points of the
run's reach from where the representative does), which also covers the table's
interpolation between neighbouring entries. A cell of a grid over the loose box is
kept when one of those boxes meets the volume box for a run whose reach meets the
cell.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from voxwarp.deform.wires.tables import WireTables, map_points

#: most cells of the search grid over the loose box (the box is at most one cell per
#: side looser than the cells that can hold content)
BOX_CELLS = 32768
#: probes per run of the search (one representative each)
RUN = 8
#: steps of the fade weight w in [0, 1] along each point's segment to its image
WEIGHTS = 8


@dataclass
class Probes:
    """Balls that hold a wire's swept points, each with the mapping ``q = A p + b`` of
    its points; consecutive probes of a ``chain`` are interpolated between (the table's
    entries), the others are not (an end's cap)."""

    centres: np.ndarray  # (n, 3)
    radii: np.ndarray  # (n,)
    matrices: np.ndarray  # (n, 3, 3)
    offsets: np.ndarray  # (n, 3)
    chain: bool


def wire_probes(
    tab: WireTables, plane_radii: np.ndarray, slack: float, caps: float
) -> list[Probes]:
    """A wire's probes: one per table entry (radius: the widest plane mask near it,
    grown by ``slack``, the along-wire offset a swept point keeps from its entry), and
    along each end's tangent out to ``caps`` mm (the end cap and fade)."""
    n = tab.size
    planes = len(plane_radii)
    pos = np.linspace(0.0, planes - 1.0, n)
    near = np.maximum(plane_radii[np.floor(pos).astype(int)], plane_radii[np.ceil(pos).astype(int)])
    entries = Probes(
        tab.modified_points, np.hypot(near, slack), tab.matrices, tab.offsets, chain=True
    )
    out = [entries]
    for i, sign in ((0, -1.0), (n - 1, 1.0)):
        step = max(float(near[i]), slack) / 2.0
        steps = np.arange(0.0, caps + step, step)[1:]
        if len(steps) == 0:
            continue
        tangent = sign * tab.modified_frames[i][:, 2]
        centres = tab.modified_points[i] + steps[:, None] * tangent
        m = len(centres)
        out.append(
            Probes(
                centres,
                np.full(m, float(np.hypot(near[i], step / 2.0))),
                np.repeat(tab.matrices[i][None], m, axis=0),
                np.repeat(tab.offsets[i][None], m, axis=0),
                chain=False,
            )
        )
    return out


def content_box(
    probes: Sequence[Probes],
    volume_box: tuple[np.ndarray, np.ndarray],
    loose_box: tuple[np.ndarray, np.ndarray],
    most_cells: int = BOX_CELLS,
) -> tuple[np.ndarray, np.ndarray]:
    """The bounding box of the volume box and of the points of ``loose_box`` that the
    probes can map into the volume box (see the module docstring), within ``loose_box``.

    ``volume_box``: where the volume has content, grown by the sampling's border;
    ``most_cells``: at most this many search cells (no finer than the field's voxels).
    """
    vlo, vhi = (np.asarray(v, dtype=np.float64) for v in volume_box)
    lo, hi = (np.asarray(v, dtype=np.float64) for v in loose_box)
    grid = _Cells(lo, hi, (vlo, vhi), most_cells)
    keep = np.zeros(grid.n, dtype=bool)
    for pr in probes:
        for ks in _runs(len(pr.radii), pr.chain):
            _mark_run(grid, keep, pr, ks, (vlo, vhi))
    out_lo, out_hi = np.minimum(vlo, hi), np.maximum(vhi, lo)
    if keep.any():
        idx = np.argwhere(keep)
        out_lo = np.minimum(out_lo, grid.lo + idx.min(0) * grid.edge)
        out_hi = np.maximum(out_hi, grid.lo + (idx.max(0) + 1) * grid.edge)
    return np.maximum(out_lo, lo), np.minimum(out_hi, hi)


def escapes(
    tables: Sequence[WireTables],
    points: np.ndarray,
    wire: np.ndarray,
    u: np.ndarray,
    volume_box: tuple[np.ndarray, np.ndarray],
) -> bool:
    """Whether any swept point (its wire and fraction u) can be mapped into the volume
    box: the segment from it to its image meets the box. Run on the swept voxels of a
    clipped face of the field: True means the clip cut content."""
    for wi in np.unique(wire):
        sel = wire == wi
        tab = tables[int(wi)]
        q = map_points(tab, u[sel] * (tab.size - 1), points[sel])
        if segments_meet_box(points[sel], q, volume_box).any():
            return True
    return False


def segments_meet_box(
    p: np.ndarray, q: np.ndarray, box: tuple[np.ndarray, np.ndarray]
) -> np.ndarray:
    """Per segment from p to q (n, 3): whether it meets the closed box (slab clipping)."""
    lo, hi = box
    d = q - p
    with np.errstate(divide="ignore", invalid="ignore"):
        a, b = (lo - p) / d, (hi - p) / d
    flat = d == 0  # parallel to a slab: inside it or not at all
    inside = (p >= lo) & (p <= hi)
    enter = np.where(flat, np.where(inside, -np.inf, np.inf), np.minimum(a, b))
    leave = np.where(flat, np.where(inside, np.inf, -np.inf), np.maximum(a, b))
    t0 = np.maximum(enter.max(axis=1), 0.0)
    t1 = np.minimum(leave.min(axis=1), 1.0)
    return t0 <= t1


class _Cells:
    """A grid of at most :data:`BOX_CELLS` equal cells over [lo, hi]."""

    def __init__(
        self, lo: np.ndarray, hi: np.ndarray, volume: tuple[np.ndarray, np.ndarray], most: int
    ) -> None:
        size = np.maximum(hi - lo, 1e-9)
        side = float(np.prod(size) / max(1, min(most, BOX_CELLS))) ** (1.0 / 3.0)
        self.n = tuple(int(v) for v in np.clip(np.ceil(size / side), 1, None))
        self.lo = lo
        self.edge = size / np.asarray(self.n)
        # cells not wholly inside the volume box (only they can widen the field's box)
        within = [
            (lo[d] + np.arange(n) * self.edge[d] >= volume[0][d])
            & (lo[d] + (np.arange(n) + 1) * self.edge[d] <= volume[1][d])
            for d, n in enumerate(self.n)
        ]
        self.beyond = ~(
            within[0][:, None, None] & within[1][None, :, None] & within[2][None, None, :]
        )

    def window(self, centre: np.ndarray, radius: float) -> tuple[slice, ...]:
        """Index slices of the cells that a ball can meet."""
        a = np.floor((centre - radius - self.lo) / self.edge).astype(int)
        b = np.floor((centre + radius - self.lo) / self.edge).astype(int) + 1
        n = np.asarray(self.n)
        a, b = np.clip(a, 0, n), np.clip(b, 0, n)
        return tuple(slice(int(i), int(j)) for i, j in zip(a, b, strict=True))

    def centres(self, window: tuple[slice, ...]) -> np.ndarray:
        """Cell centres of a window, (cells, 3) in C order of the window."""
        axes = [
            self.lo[d] + (np.arange(s.start, s.stop) + 0.5) * self.edge[d]
            for d, s in enumerate(window)
        ]
        return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


def _runs(size: int, chain: bool) -> list[np.ndarray]:
    """Runs of :data:`RUN` + 1 probes along a chain, each sharing its last probe with
    the next (the interpolation between neighbours lies within one run); one probe
    each elsewhere (an end's cap: its probes lie a probe's radius apart)."""
    if not chain:
        return [np.array([k]) for k in range(size)]
    starts = range(0, max(size - 1, 1), RUN)
    return [np.arange(s, min(s + RUN, size - 1) + 1) for s in starts]


def _mark_run(
    grid: _Cells,
    keep: np.ndarray,
    pr: Probes,
    ks: np.ndarray,
    volume: tuple[np.ndarray, np.ndarray],
) -> None:
    """Mark the cells from which the probes ``ks`` can bring a point into the volume
    box."""
    a, b, pts = pr.matrices, pr.offsets, pr.centres
    j = int(ks[len(ks) // 2])
    centre = pts[j]
    radius = float((np.linalg.norm(pts[ks] - centre, axis=1) + pr.radii[ks]).max())
    window = grid.window(centre, radius)
    # only the cells that could still widen the box: not yet kept, not in the volume
    todo = (~keep[window] & grid.beyond[window]).reshape(-1)
    if not todo.any():
        return
    # how far another probe of the run maps a point within `radius` from probe j's image
    moved = a[ks] @ centre + b[ks] - (a[j] @ centre + b[j])
    spread = np.linalg.norm(a[ks] - a[j], axis=(1, 2)) * radius
    margin = float((np.linalg.norm(moved, axis=1) + spread).max())
    c = grid.centres(window)[todo]
    half = 0.5 * grid.edge
    gap = np.maximum(np.abs(c - centre) - half, 0.0)
    near = np.einsum("ni,ni->n", gap, gap) <= radius * radius
    todo[todo] = near
    c = c[near]
    # the segment from p to its image, at WEIGHTS steps of the fade w, each step's
    # box grown by half the way to the next
    move = a[j] - np.eye(3)
    reach = float(np.linalg.norm(move @ centre + b[j]) + np.linalg.norm(move, 2) * radius)
    grow = margin + 0.5 * reach / WEIGHTS
    vlo, vhi = volume
    w = np.linspace(0.0, 1.0, WEIGHTS + 1)[:, None, None]
    m = np.eye(3) + w * move  # (steps, 3, 3)
    image = np.einsum("wij,nj->wni", m, c) + w * b[j]
    image_half = (np.abs(m) @ half + grow)[:, None, :]
    meets = np.all(image - image_half <= vhi, axis=2) & np.all(image + image_half >= vlo, axis=2)
    hit = meets.any(axis=0)
    marks = np.zeros(len(todo), dtype=bool)
    marks[todo] = hit
    keep[window] |= marks.reshape(keep[window].shape)
