"""The grid a warp chain is exported on as a displacement field (``Scene.displacement_field``).

Three grids, all given as a 4x4 index -> world (RAS mm) affine and a node count per axis
(with ``grid="input"`` the first two are indexed in the input file's axis order,
:func:`voxwarp.core.orientation.grid_in_file_order`: the same nodes):

* the volume's own grid (its affine, direction included): one node per voxel centre;
* the volume's box at another node ``spacing`` (one number or three, mm), keeping the
  volume's direction: per index axis ``round(extent / spacing)`` nodes (at least 2) at
  exactly that spacing, centred in the box the voxels span;
* a world box ``(lo, hi)`` (axis-aligned in world), sampled the same way, at
  ``spacing`` or by default the volume's smallest voxel size.

A node the chain does not carry (a wire's vacated space, sent "infinitely far") is
*outside*: it holds its nearest carried node's vector, so that ITK's trilinear
interpolation next to it stays close to the chain (:mod:`voxwarp.core.field_check`);
:func:`export_chain` measures that interpolation and refines the default spacing.
The field's vectors are float32 (12 bytes a node), checked against the memory budget
(:func:`voxwarp.core.limits.current_memory_budget`) before anything is allocated.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from voxwarp.core import limits
from voxwarp.core.field_check import (
    TOLERANCE_MM,
    FieldCheck,
    check_field,
    fill_outside,
    sample_carried,
)
from voxwarp.core.field_spacing import default_spacing
from voxwarp.core.orientation import grid_in_file_order
from voxwarp.core.volume import Volume
from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.deform.warp import Warp
from voxwarp.errors import SceneError

#: Bytes of one node of an exported field (3 float32 components).
NODE_BYTES = 12
#: Most nodes a field refined by :func:`export_chain` may have (12 bytes each).
MAX_AUTO_NODES = 1 << 25
#: Most refinements :func:`export_chain` makes.
MAX_REFINE = 3

#: ``sampler(warps, affine, shape) -> (u, outside)``: samples a chain on a grid as
#: :func:`~voxwarp.core.field_check.sample_carried` (the CPU) or
#: :class:`voxwarp.render.field_sampling.GpuFieldSampler` (the GPU) does.
Sampler = Callable[[Sequence[Warp], np.ndarray, Sequence[int]], tuple[np.ndarray, np.ndarray]]


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
    volume: Volume, spacing: Any = None, box: Any = None, grid: str = "volume"
) -> tuple[np.ndarray, tuple[int, int, int]]:
    """``(affine, shape)`` of the grid to sample a field on (see the module doc).

    ``grid="input"`` indexes a grid along the volume's axes in its file's axis order
    (:attr:`Volume.file_axes`; unchanged without one, or with a ``box``).

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
    if grid == "input" and box is None and volume.file_axes:
        affine, shape = grid_in_file_order(affine, shape, volume.file_axes)
    _check_budget(shape)
    return affine, shape  # type: ignore[return-value]


def _check_budget(shape: Sequence[int]) -> None:
    over = limits.over_budget(shape, NODE_BYTES)
    if over is not None:
        dims = "x".join(str(int(n)) for n in shape)
        raise SceneError(
            f"a {dims} displacement field needs {over[0]}, over the memory budget of"
            f" {over[1]}; use a coarser spacing (--spacing) or a smaller box (or raise"
            " --memory-budget)"
        )


def chain_field(
    warps: Sequence[Warp],
    affine: np.ndarray,
    shape: Sequence[int],
    sampler: Sampler | None = None,
) -> tuple[DisplacementFieldWarp, np.ndarray]:
    """The pull-back field ``chain(p) - p`` of ``warps`` on the grid ``(affine, shape)``
    and the ``(nx, ny, nz)`` bool mask of its *outside* nodes.

    A node the chain does not carry (a wire's vacated space, NaN, a point sent farther
    than :data:`~voxwarp.deform.warp.FAR_MM`) is outside; it holds its nearest carried
    node's vector (:func:`~voxwarp.core.field_check.fill_outside`), so ITK's trilinear
    interpolation next to it keeps the carried side's value. ``sampler`` samples the
    chain (default :func:`~voxwarp.core.field_check.sample_carried`, the CPU).
    """
    u, outside = (sample_carried if sampler is None else sampler)(list(warps), affine, shape)
    return DisplacementFieldWarp(fill_outside(u, outside), affine), outside


@dataclass(frozen=True)
class FieldExport:
    """An exported field with what was measured of it (:func:`export_chain`).

    Attributes
    ----------
    field : DisplacementFieldWarp
        The field (RAS; :func:`voxwarp.io.fields.save_displacement_field` writes it).
    outside : numpy.ndarray
        ``(nx, ny, nz)`` bool: nodes the chain does not carry (filled from neighbours).
    check : FieldCheck
        Its measured interpolation error and torn nodes.
    needed_spacing : numpy.ndarray
        Spacing per grid axis (mm) that meets the tolerance: the field's own when it
        does; else a finer spacing tried that met it (``needed_met``), or the last
        estimate (``needed_met`` False).
    refined : bool
        True when the spacing was made finer than the starting grid to meet the
        tolerance.
    capped : bool
        True when a finer spacing was needed but over :data:`MAX_AUTO_NODES` or the
        memory budget.
    """

    field: DisplacementFieldWarp
    outside: np.ndarray
    check: FieldCheck
    needed_spacing: np.ndarray
    refined: bool = False
    capped: bool = False
    needed_met: bool = True

    def report(self) -> str:
        """One line: the measured error, outside and torn node counts."""
        c = self.check
        return (
            f"field check: trilinear within {c.max_error:.3g} mm of the chain in {c.checked}"
            f" cells of the deformed volume (tolerance {c.tolerance:g} mm);"
            f" {int(self.outside.sum())} outside node(s) not carried by the chain hold their"
            f" nearest carried vector; {int(c.torn.sum())} node(s) border a tear (left out)"
        )

    def metadata(self) -> dict[str, str]:
        """What the written file records of the check (short key -> text)."""
        return {
            "max_error_mm": f"{self.check.max_error:.3g}",
            "tolerance_mm": f"{self.check.tolerance:g}",
            "outside_nodes": str(int(self.outside.sum())),
            "torn_nodes": str(int(self.check.torn.sum())),
        }


def export_chain(
    volume: Volume,
    warps: Sequence[Warp],
    spacing: Any = None,
    box: Any = None,
    tolerance: float = TOLERANCE_MM,
    grid: str = "volume",
    sampler: Sampler | None = None,
) -> FieldExport:
    """Sample ``warps`` as a field on ``field_grid(volume, spacing, box, grid)`` and
    measure it; ``spacing=None`` starts from
    :func:`voxwarp.core.field_spacing.default_spacing` (coarser than the voxels for
    element grids, lattices and affine maps).

    Where ITK's trilinear interpolation misses the chain by more than ``tolerance`` mm
    away from tears, finer spacings are tried (up to :data:`MAX_REFINE` times, within
    :data:`MAX_AUTO_NODES` nodes and the memory budget). With ``spacing=None`` the
    finest one tried is returned (``refined``); a given ``spacing`` is kept, and the
    spacing that met the tolerance (or the last estimate) is its
    :attr:`FieldExport.needed_spacing`. ``sampler`` samples the chain on each grid
    (:func:`chain_field`); the field check always measures against the exact CPU chain.
    """
    chain = list(warps)
    to_index = np.linalg.inv(np.asarray(volume.affine, float))

    def measured(step: Any) -> FieldExport:
        affine, shape = field_grid(volume, step, box, grid)
        field, outside = chain_field(chain, affine, shape, sampler)
        return _measured(chain, field, outside, to_index, volume.shape, tolerance)

    start = default_spacing(volume, chain).spacing if spacing is None else spacing
    first = trial = measured(start)
    capped = False
    for _ in range(MAX_REFINE):
        if trial.check.met:
            break
        try:
            finer = measured(_capped(volume, trial.needed_spacing, box))
        except SceneError:  # over the memory budget or the node cap
            capped = True
            break
        trial = replace(finer, refined=True)
    if spacing is None:
        return replace(trial, capped=capped, needed_met=False)
    return replace(
        first, capped=capped, needed_spacing=trial.needed_spacing, needed_met=trial.check.met
    )


def _capped(volume: Volume, spacing: np.ndarray, box: Any) -> np.ndarray:
    """``spacing``, or :class:`SceneError` when its grid has over :data:`MAX_AUTO_NODES`."""
    _, shape = field_grid(volume, spacing, box)
    if int(np.prod(shape)) > MAX_AUTO_NODES:
        raise SceneError(f"over {MAX_AUTO_NODES} nodes")
    return spacing


def _measured(
    chain: list[Warp],
    field: DisplacementFieldWarp,
    outside: np.ndarray,
    to_index: np.ndarray,
    volume_shape: Sequence[int],
    tolerance: float,
) -> FieldExport:
    check = check_field(chain, field, to_index, volume_shape, tolerance=tolerance)
    return FieldExport(field, outside, check, np.asarray(field.spacing) * check.scale)
