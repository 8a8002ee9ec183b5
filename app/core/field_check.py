"""How well an exported displacement field reproduces its warp chain between nodes.

ITK (``DisplacementFieldTransform``), ANTs and Slicer interpolate a field trilinearly
between its nodes. An export is exact on the nodes; between them it is as good as the
chain is smooth at the node spacing. This module samples a chain on a grid and says
where that holds:

* **Outside nodes.** A node the chain does not carry (a rigid wire's vacated space,
  NaN, a point sent farther than :data:`~voxwarp.deform.warp.FAR_MM`;
  :func:`~voxwarp.deform.warp.chain_apply_carried`) shows nothing in voxwarp. Its vector
  is *filled* with the vector of the nearest carried node (Euclidean, in index space), so
  it stays within the carried nodes' range and cannot bleed into its neighbours'
  interpolation: a carried point next to vacated space keeps its own side's value.
* **Measured error.** At the centre and at one random point of every cell (a seeded
  random subset of :data:`MAX_CHECK_CELLS` cells when there are more; on a grid of
  fewer cells, more random points a cell, up to :data:`MAX_DRAWS`, so a coarse default
  grid is measured at about as many points as a fine one), the field's
  trilinear value is compared with the chain itself, at the points the chain carries
  into the volume (the deformed volume). The largest difference is the export's
  measured interpolation error.
* **Tears.** A cell off by more than the tolerance is probed :data:`PROBE` times finer
  (``PROBE + 1`` nodes per axis inside it). Where the map is continuous the finer grid's
  error falls (as ``h^2`` where smooth, as ``h`` at a kink) and the differences of
  neighbouring nodes shrink; where the error stays (over half) or a difference of over
  the tolerance stays, or some probe point is not carried, the map jumps there (the
  rigid wire's cylinder edge, the vacated border, a wire field voxel's edge) and no
  spacing interpolates it: the cell is *torn*, its 8 nodes *border a tear*, and it is
  left out of the measured error. Otherwise the cell is continuous but too coarse, and
  the spacing that would meet the tolerance is estimated assuming the error falls as
  ``h``, with a 20 % margin (at most :data:`PROBE` times finer).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.deform.warp import Warp, chain_apply_carried

#: ITK's trilinear interpolation of an export should stay this close to the chain (mm).
TOLERANCE_MM = 0.5
#: Most cell centres checked per export (a seeded random subset beyond).
MAX_CHECK_CELLS = 1_000_000
#: Most off cells probed for a tear (the rest count as smooth but coarse).
MAX_PROBED_CELLS = 20_000
#: Most random points measured per cell (on grids of few cells; one on large grids).
MAX_DRAWS = 16
#: A probed cell is refined this many times per axis.
PROBE = 4
_SLAB = 1 << 18


@dataclass(frozen=True)
class FieldCheck:
    """What :func:`check_field` measured (see the module docstring).

    Attributes
    ----------
    max_error : float
        Largest ``|trilinear - chain|`` (mm) at the checked points inside the deformed
        volume, torn cells left out.
    checked : int
        Cells measured (inside the deformed volume), torn cells left out.
    torn : numpy.ndarray
        ``(nx, ny, nz)`` bool: the nodes of torn cells (they border a tear).
    scale : float
        Factor on the spacing that would meet ``tolerance`` (1.0 when it is met).
    tolerance : float
        The tolerance (mm).
    """

    max_error: float
    checked: int
    torn: np.ndarray
    scale: float
    tolerance: float

    @property
    def met(self) -> bool:
        """True when the measured error is within the tolerance."""
        return self.max_error <= self.tolerance


def sample_carried(
    warps: Sequence[Warp], affine: np.ndarray, shape: Sequence[int]
) -> tuple[np.ndarray, np.ndarray]:
    """``chain(p) - p`` at every node (float32 ``(nx, ny, nz, 3)``) and the ``(nx, ny,
    nz)`` bool mask of the nodes the chain does not carry (their vectors are 0).

    The chain maps whole slabs of about :data:`_SLAB` nodes at once, each a run of
    first-axis planes, so every slab fills a contiguous block of the output."""
    nx, ny, nz = (int(v) for v in shape)
    u = np.zeros((nx, ny, nz, 3), dtype=np.float32)
    outside = np.zeros((nx, ny, nz), dtype=bool)
    a = np.asarray(affine, dtype=np.float64)
    jj, kk = np.meshgrid(np.arange(ny), np.arange(nz), indexing="ij")
    plane = np.stack([jj.ravel(), kk.ravel()], axis=1).astype(float) @ a[:3, 1:3].T + a[:3, 3]
    per = max(1, _SLAB // max(ny * nz, 1))
    for i0 in range(0, nx, per):
        i = np.arange(i0, min(i0 + per, nx), dtype=float)
        p = (i[:, None, None] * a[:3, 0] + plane[None]).reshape(-1, 3)
        q, ok = chain_apply_carried(warps, p)
        d = np.where(ok[:, None], q - p, 0.0)
        u[i0 : i0 + len(i)] = d.reshape(len(i), ny, nz, 3)
        outside[i0 : i0 + len(i)] = ~ok.reshape(len(i), ny, nz)
    return u, outside


def fill_outside(u: np.ndarray, outside: np.ndarray) -> np.ndarray:
    """``u`` with every outside node given its nearest carried node's vector (in place
    where possible); all zero when no node is carried.

    The distance transform runs on the outside nodes' bounding box grown by one node
    (:func:`_around`): that ring is carried, and it holds every outside node's nearest
    carried node (clamping a farther node to the ring only brings it closer)."""
    if not outside.any():
        return u
    if outside.all():
        u[...] = 0.0
        return u
    from scipy import ndimage  # deferred: voxwarp --help stays light

    box = _around(outside)
    sub, part = outside[box], u[box]
    idx = ndimage.distance_transform_edt(sub, return_distances=False, return_indices=True)
    part[sub] = part[idx[0][sub], idx[1][sub], idx[2][sub]]
    return u


def _around(mask: np.ndarray) -> tuple[slice, slice, slice]:
    """The bounding box of ``mask``'s True nodes grown by one node (within the grid)."""
    box = []
    for ax in range(3):
        hit = np.flatnonzero(mask.any(axis=tuple(a for a in range(3) if a != ax)))
        box.append(slice(max(int(hit[0]) - 1, 0), min(int(hit[-1]) + 2, mask.shape[ax])))
    return box[0], box[1], box[2]


def _cells(shape: Sequence[int], rng: np.random.Generator) -> np.ndarray:
    """Lower-corner indices (M, 3) of the cells to check: all, or a random subset."""
    cells = np.asarray(shape) - 1
    count = int(np.prod(cells))
    if count <= MAX_CHECK_CELLS:
        flat = np.arange(count)
    else:  # sorted, without repeats (a few fewer than asked): np.unique's set, in O(count)
        hit = np.zeros(count, dtype=bool)
        hit[rng.integers(0, count, MAX_CHECK_CELLS)] = True
        flat = np.flatnonzero(hit)
    return np.stack(np.unravel_index(flat, tuple(cells)), axis=1)


def _inside(volume_index: np.ndarray, volume_shape: Sequence[int]) -> np.ndarray:
    n = np.asarray(volume_shape, float)
    return np.all((volume_index >= -0.5) & (volume_index <= n - 0.5), axis=1)


def _probe_torn(
    warps: Sequence[Warp], affine: np.ndarray, corners: np.ndarray, errors: np.ndarray, tol: float
) -> np.ndarray:
    """Per cell (lower corners (M, 3), centre errors (M,)): True when the chain is
    discontinuous inside it (see :func:`_discontinuous`)."""
    s = np.arange(PROBE + 1) / PROBE
    sub = np.stack(np.meshgrid(s, s, s, indexing="ij"), axis=-1).reshape(-1, 3)
    c = (np.arange(PROBE) + 0.5) / PROBE
    mid = np.stack(np.meshgrid(c, c, c, indexing="ij"), axis=-1).reshape(-1, 3)
    torn = np.zeros(len(corners), dtype=bool)
    per = max(1, _SLAB // (len(sub) + len(mid)))
    for lo in range(0, len(corners), per):
        base = corners[lo : lo + per].astype(float)
        m = len(base)
        pts = (base[:, None, :] + sub[None]).reshape(-1, 3) @ affine[:3, :3].T + affine[:3, 3]
        q, ok = chain_apply_carried(warps, pts)
        u = (q - pts).reshape(m, PROBE + 1, PROBE + 1, PROBE + 1, 3)
        cen = (base[:, None, :] + mid[None]).reshape(-1, 3) @ affine[:3, :3].T + affine[:3, 3]
        qc, okc = chain_apply_carried(warps, cen)
        err = np.linalg.norm(_subcell_trilinear(u) - (qc - cen).reshape(m, -1, 3), axis=-1)
        gone = ~ok.reshape(m, -1).all(axis=1) | ~okc.reshape(m, -1).all(axis=1)
        fine = np.nan_to_num(err.max(axis=1), nan=np.inf)
        torn[lo : lo + m] = gone | _discontinuous(u, fine, errors[lo : lo + m], tol)
    return torn


def _discontinuous(u: np.ndarray, fine: np.ndarray, coarse: np.ndarray, tol: float) -> np.ndarray:
    """A cell's map jumps when its :data:`PROBE` times finer grid misses it by more than
    half the cell's own error (trilinear error falls as ``h^2`` where the map is smooth,
    as ``h`` at a kink such as an element face: by :data:`PROBE` at least; a jump keeps
    it), or when along a line of probe nodes one step changes the map by more than
    ``tol`` and by more than all the line's other steps together (a continuous map
    spreads its change over the steps). ``u``: (M, P+1, P+1, P+1, 3) probe values;
    ``fine``, ``coarse``: (M,) errors."""
    jump = np.zeros(len(u), dtype=bool)
    for ax in range(1, 4):
        d = np.nan_to_num(np.linalg.norm(np.diff(u, axis=ax), axis=-1), nan=np.inf)
        top, total = d.max(axis=ax), d.sum(axis=ax)
        line = (top > tol) & (2.0 * top > total)
        jump |= line.reshape(len(u), -1).any(axis=1)
    return ~(2.0 * fine <= coarse) | jump


def _subcell_trilinear(u: np.ndarray) -> np.ndarray:
    """Trilinear values at the centres of the sub-cells of sub-node values ``u``
    (M, P+1, P+1, P+1, 3): the mean of each sub-cell's 8 corners, (M, P^3, 3)."""
    acc = np.zeros((u.shape[0], PROBE, PROBE, PROBE, 3))
    for o in range(8):
        a, b, c = o & 1, (o >> 1) & 1, (o >> 2) & 1
        acc += u[:, a : a + PROBE, b : b + PROBE, c : c + PROBE]
    return (acc / 8.0).reshape(u.shape[0], -1, 3)


def check_field(
    warps: Sequence[Warp],
    field: DisplacementFieldWarp,
    volume_to_index: np.ndarray,
    volume_shape: Sequence[int],
    *,
    tolerance: float = TOLERANCE_MM,
    seed: int = 0,
) -> FieldCheck:
    """Measure ``field`` against ``warps`` between nodes (see the module docstring).

    Each checked cell is measured at its centre and at seeded random points in it (one
    on large grids, more on coarse ones: :func:`_draws_per_cell`; trilinear error
    peaks at the centre where the map is smooth, elsewhere at a kink).
    ``volume_to_index`` (4x4) and ``volume_shape`` place the original volume: a point
    counts when the chain carries it into that volume.
    """
    rng = np.random.default_rng(seed)
    corners = _cells(field.shape, rng)
    errors, torn_cells, budget = [], [], MAX_PROBED_CELLS
    for lo in range(0, len(corners), _SLAB):
        base = corners[lo : lo + _SLAB]
        err = _cell_errors(warps, field, base, rng, volume_to_index, volume_shape)
        base, err = base[~np.isnan(err)], err[~np.isnan(err)]
        torn = np.zeros(len(err), dtype=bool)
        probe = np.flatnonzero(~(err <= tolerance))[:budget]
        if probe.size:
            budget -= probe.size
            torn[probe] = _probe_torn(warps, field.affine, base[probe], err[probe], tolerance)
            torn_cells.append(base[torn])
        errors.append(err[~torn])
    smooth = np.concatenate(errors) if errors else np.zeros(0)
    worst = float(smooth.max()) if smooth.size else 0.0
    return FieldCheck(
        max_error=worst,
        checked=int(smooth.size),
        torn=_torn_nodes(field.shape, torn_cells),
        scale=_scale(worst, tolerance),
        tolerance=float(tolerance),
    )


def _cell_errors(
    warps: Sequence[Warp],
    field: DisplacementFieldWarp,
    base: np.ndarray,
    rng: np.random.Generator,
    to_index: np.ndarray,
    volume_shape: Sequence[int],
) -> np.ndarray:
    """Per cell (lower corners (M, 3)): the largest ``|trilinear - chain|`` (mm) at its
    centre and a random point that the chain carries into the volume; NaN at none."""
    a = field.affine
    out = np.full(len(base), np.nan)
    draws = _draws_per_cell(field.shape)
    offsets = [np.full((len(base), 3), 0.5), *(rng.random((len(base), 3)) for _ in range(draws))]
    for offset in offsets:
        p = (base + offset) @ a[:3, :3].T + a[:3, 3]
        q, ok = chain_apply_carried(warps, p)
        vi = q @ to_index[:3, :3].T + to_index[:3, 3]
        keep = ok & _inside(vi, volume_shape)
        u = _in_cells(field.displacements, base[keep], offset[keep])
        err = np.linalg.norm(p[keep] + u - q[keep], axis=1)
        out[keep] = np.fmax(out[keep], err)
    return out


def _in_cells(u: np.ndarray, base: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """Trilinear values (M, 3) of node vectors ``u`` (nx, ny, nz, 3) at ``offset`` (M, 3,
    in [0, 1]) inside the cells of lower corners ``base`` (M, 3): what
    :meth:`DisplacementFieldWarp.displacement_at` gives there, with no world -> index
    round trip; each corner is one flat gather."""
    n = u.shape[:3]
    step = np.array([n[1] * n[2], n[2], 1], dtype=np.intp)
    flat, at = u.reshape(-1, 3), base.astype(np.intp) @ step
    val = np.zeros((len(base), 3))
    for corner in range(8):
        o = [(corner >> k) & 1 for k in range(3)]
        w = np.prod([offset[:, k] if o[k] else 1.0 - offset[:, k] for k in range(3)], axis=0)
        val += w[:, None] * flat[at + int(np.dot(o, step))]
    return val


def _draws_per_cell(shape: Sequence[int]) -> int:
    """Random points measured per cell besides its centre: one on a grid of
    :data:`MAX_CHECK_CELLS` cells or more, more on coarser grids (up to
    :data:`MAX_DRAWS`), so that a coarse grid is measured at as many points."""
    cells = int(np.prod(np.asarray(shape) - 1))
    return int(np.clip(MAX_CHECK_CELLS // max(cells, 1), 1, MAX_DRAWS))


def _torn_nodes(shape: Sequence[int], cells: list[np.ndarray]) -> np.ndarray:
    """The nodes (bool grid) of the torn cells (lower corners)."""
    out = np.zeros(tuple(shape), dtype=bool)
    if not cells:
        return out
    c = np.concatenate(cells, axis=0)
    for o in range(8):
        d = np.array([o & 1, (o >> 1) & 1, (o >> 2) & 1])
        n = c + d
        out[n[:, 0], n[:, 1], n[:, 2]] = True
    return out


def _scale(error: float, tolerance: float) -> float:
    """Spacing factor that would meet ``tolerance``: trilinear error falls at least as
    ``h`` (``h^2`` where smooth), with a 20 % margin (where a kink crosses a cell
    depends on the grid), at most :data:`PROBE` times finer."""
    if error <= tolerance:
        return 1.0
    return float(np.clip(0.8 * tolerance / error, 1.0 / PROBE, 0.8))
