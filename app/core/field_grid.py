"""The grid a warp chain is exported on as a displacement field (``Scene.displacement_field``).

Three grids, all given as a 4x4 index -> world (RAS mm) affine and a node count per axis:

* the volume's own grid (its affine, direction included): one node per voxel centre;
* the volume's box at another node ``spacing`` (one number or three, mm), keeping the
  volume's direction: per index axis ``round(extent / spacing)`` nodes (at least 2) at
  exactly that spacing, centred in the box the voxels span;
* a world box ``(lo, hi)`` (axis-aligned in world), sampled the same way, at
  ``spacing`` or by default the volume's smallest voxel size.

A point the chain leaves empty (a wire's vacated space, sent "infinitely far") points
one box size outside the volume in the field, where resampling tools find nothing.
The field's vectors are float32 (12 bytes a node), checked against the memory budget
(:func:`voxwarp.core.limits.current_memory_budget`) before anything is allocated.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from voxwarp.core import limits
from voxwarp.core.volume import Volume
from voxwarp.deform.fields.displacement import (
    MAX_DISPLACEMENT_MM,
    DisplacementFieldWarp,
    sample_chain_field,
)
from voxwarp.deform.warp import Warp, chain_apply
from voxwarp.errors import SceneError

#: Bytes of one node of an exported field (3 float32 components).
NODE_BYTES = 12


def _spacing(spacing: Any) -> np.ndarray:
    try:
        s = np.asarray(spacing, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise SceneError(f"spacing must be one number or three (mm); got {spacing!r}") from exc
    if s.size == 1:
        s = np.repeat(s, 3)
    if s.size != 3 or not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise SceneError(
            f"spacing must be one positive number or three (mm); got {np.asarray(spacing).tolist()}"
        )
    return s


def _box(box: Any) -> tuple[np.ndarray, np.ndarray]:
    try:
        lo, hi = (np.asarray(c, dtype=np.float64).reshape(3) for c in box)
    except (TypeError, ValueError) as exc:
        raise SceneError(
            "box must be ((x0, y0, z0), (x1, y1, z1)) in world mm, e.g. ((-90, -120, -70),"
            " (90, 90, 100))"
        ) from exc
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))) or np.any(hi <= lo):
        raise SceneError(
            f"box must be finite with x0 < x1, y0 < y1, z0 < z1 (world mm); got"
            f" {lo.tolist()} .. {hi.tolist()}"
        )
    return lo, hi


def _centred(
    extent: np.ndarray, spacing: np.ndarray, centre: np.ndarray, direction: np.ndarray
) -> tuple[np.ndarray, tuple[int, int, int]]:
    """Nodes at ``spacing`` along ``direction``'s columns, centred on ``centre``."""
    n = np.maximum(np.rint(extent / spacing), 2).astype(np.int64)
    affine = np.eye(4)
    affine[:3, :3] = direction * spacing
    affine[:3, 3] = centre - affine[:3, :3] @ ((n - 1) / 2.0)
    return affine, (int(n[0]), int(n[1]), int(n[2]))


def field_grid(
    volume: Volume, spacing: Any = None, box: Any = None
) -> tuple[np.ndarray, tuple[int, int, int]]:
    """``(affine, shape)`` of the grid to sample a field on (see the module doc).

    Raises :class:`~voxwarp.errors.SceneError` for a bad ``spacing`` or ``box``, or a
    grid over the memory budget.
    """
    if box is not None:
        lo, hi = _box(box)
        s = _spacing(min(volume.spacing) if spacing is None else spacing)
        affine, shape = _centred(hi - lo, s, (lo + hi) / 2.0, np.eye(3))
    elif spacing is not None:
        s = _spacing(spacing)
        extent = np.asarray(volume.shape, float) * np.asarray(volume.spacing, float)
        centre = volume.index_to_world((np.asarray(volume.shape, float) - 1.0) / 2.0)
        affine, shape = _centred(extent, s, centre, np.asarray(volume.direction, float))
    else:
        affine, shape = np.asarray(volume.affine, float), tuple(volume.shape)
    _check_budget(shape)
    return affine, shape  # type: ignore[return-value]


def _check_budget(shape: Sequence[int]) -> None:
    over = limits.over_budget(shape, NODE_BYTES)
    if over is not None:
        dims = "x".join(str(int(n)) for n in shape)
        raise SceneError(
            f"a {dims} displacement field needs {over[0]}, over the memory budget of"
            f" {over[1]}; use a coarser spacing or a smaller box (or raise --memory-budget)"
        )


def chain_field(
    warps: Sequence[Warp],
    affine: np.ndarray,
    shape: Sequence[int],
    vacated: Sequence[float] | None = None,
) -> DisplacementFieldWarp:
    """The pull-back field ``chain(p) - p`` of ``warps`` on the grid ``(affine, shape)``.

    A node the chain sends farther than :data:`MAX_DISPLACEMENT_MM` or to NaN (the space
    a wire's object left: nothing to draw there) points at ``vacated`` instead, a point
    outside the volume, so resampling tools draw nothing there either.
    """
    chain = list(warps)
    out = None if vacated is None else np.asarray(vacated, dtype=np.float64).reshape(1, 3)

    def apply(p: np.ndarray) -> np.ndarray:
        q = chain_apply(chain, p)
        if out is not None:
            far = ~np.all(np.abs(q - p) < MAX_DISPLACEMENT_MM, axis=1)
            q[far] = out
        return q

    u = sample_chain_field(apply, affine, shape)
    return DisplacementFieldWarp(u, affine)
