"""Geometry of a folder of DICOM slices: where each slice goes on a regular grid.

A volume is a regular grid, so the reader checks the slices' own positions against it
instead of trusting a median spacing (:func:`stack_slices`):

* ImageOrientationPatient (IOP) must be two perpendicular unit vectors, the same on
  every slice (within :data:`IOP_TOLERANCE`); ImagePositionPatient (IPP) three finite
  numbers on every slice or on none.
* Slices are sorted along the normal. Slices at one position that are one instance
  (same SOPInstanceUID: a copied file) are kept once, with a warning; different
  instances at one position (echoes, phases) are refused.
* Each gap must be a whole number of slice spacings: a missing slice becomes a slot
  that the reader fills (with a warning naming it), so the other slices keep their
  true positions. At most as many slots as real slices are filled.
* Every slice's IPP must lie within :data:`GRID_TOLERANCE` of a voxel of that grid
  along the normal (uneven spacing), else one line names the slice and the fix.
* Across the normal, a stack whose slices drift sideways in step (a tilted CT gantry
  shears the stack) is put back on the orthogonal grid: each slice is shifted in its
  plane by its drift (linear interpolation, as dcm2niix does), with a warning naming
  the tilt. Sideways offsets that are not a shear are one line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.errors import VolumeError
from voxwarp.io.loaded import floats, to_float, warn

#: Largest distance (in voxels) between a slice's ImagePositionPatient and the voxel of
#: the regular grid it is put at, along the normal and across it.
GRID_TOLERANCE = 0.1
#: Largest difference between two slices' direction cosines (0.001 is 0.06 degrees:
#: 0.36 mm at the edge of a 360 mm field of view, half a CT pixel).
IOP_TOLERANCE = 1e-3
#: Steepest stack tilt (degrees) put back on an orthogonal grid; CT gantries tilt up to
#: about 30 degrees.
MAX_TILT_DEG = 45.0
#: Positions closer than this (mm) along the normal are one position.
SAME_POSITION_MM = 1e-4

_FIX = (
    "Resample the series onto a regular orthogonal grid (e.g. dcm2niix, which also"
    " corrects a gantry tilt) or remove the odd files"
)


@dataclass(frozen=True)
class Stack:
    """Where the slices of a series go: ``files[m]`` fills slot ``slots[m]`` of
    ``count`` slots (missing slots are filled by the reader); the RAS-ready LPS axes."""

    files: list[tuple[Path, Any]]
    slots: list[int]
    count: int
    dz: float
    iop: np.ndarray | None
    first_ipp: np.ndarray | None
    #: per file, the in-plane shift (rows, columns; pixels) that puts it on the grid
    #: (a gantry tilt), or ``None`` when every slice is on it already
    shifts: list[tuple[float, float]] | None = None


def _vector(where: str, ds: Any, keyword: str, n: int) -> np.ndarray | None:
    """``keyword`` as ``n`` finite floats; ``None`` when absent; one line when damaged."""
    try:
        value = ds.get(keyword)
    except Exception:  # pydicom cannot even parse the value
        value = "?"
    if value is None or (hasattr(value, "__len__") and len(value) == 0):
        return None
    out = floats(value, n)
    if out is None:
        raise VolumeError(
            f"{where}: its {keyword} ({str(value)[:60]}) is not {n} finite numbers; the"
            " header is damaged. Fix it (e.g. dcmodify) or remove the file from the series."
        )
    return out


def orientation(files: list[tuple[Path, Any]]) -> np.ndarray | None:
    """The series' IOP (row, column cosines), the same on every slice; ``None`` if absent."""
    iops = [_vector(p.name, ds, "ImageOrientationPatient", 6) for p, ds in files]
    if all(v is None for v in iops):
        return None
    for (p, _), v in zip(files, iops, strict=True):
        if v is None:
            raise VolumeError(
                f"{p.name} has no ImageOrientationPatient but other slices of its series do;"
                " remove it from the folder or choose another series with --series."
            )
    iop = iops[0]
    row, col = iop[:3], iop[3:]
    if (
        abs(np.linalg.norm(row) - 1) > IOP_TOLERANCE
        or abs(np.linalg.norm(col) - 1) > IOP_TOLERANCE
        or abs(float(np.dot(row, col))) > IOP_TOLERANCE
    ):
        raise VolumeError(
            f"{files[0][0].name}: its ImageOrientationPatient {iop.tolist()} is not two"
            " perpendicular unit vectors; the header is damaged. Fix it or remove the file."
        )
    for (p, _), v in zip(files, iops, strict=True):
        if float(np.max(np.abs(v - iop))) > IOP_TOLERANCE:
            raise VolumeError(
                f"{p.name} is oriented {v.round(4).tolist()}, {files[0][0].name}"
                f" {iop.round(4).tolist()}: the slices of one series must share their"
                " ImageOrientationPatient (a localizer holds several planes). Choose"
                " another series with --series or remove the odd files."
            )
    return iop


def _positions(files: list[tuple[Path, Any]]) -> list[np.ndarray] | None:
    """Every slice's IPP, or ``None`` when no slice states one (one line when some do)."""
    ipps = [_vector(p.name, ds, "ImagePositionPatient", 3) for p, ds in files]
    if all(v is None for v in ipps):
        return None
    missing = [p.name for (p, _), v in zip(files, ipps, strict=True) if v is None]
    if missing:
        raise VolumeError(
            f"{missing[0]} has no ImagePositionPatient but other slices of its series do;"
            " remove it from the folder (or fix its header)."
        )
    return ipps  # type: ignore[return-value]


def _unit_normal(iop: np.ndarray) -> np.ndarray:
    normal = np.cross(iop[:3], iop[3:])
    return normal / np.linalg.norm(normal)


def _drop_copies(
    directory: Path, files: list[tuple[Path, Any]], along: np.ndarray
) -> tuple[list[tuple[Path, Any]], np.ndarray]:
    """Sorted by position; copies of one instance at one position kept once (warning),
    different instances at one position refused."""
    order = np.argsort(along, kind="stable")
    files, along = [files[i] for i in order], along[order]
    keep = [0]
    copies = 0
    for m in range(1, len(files)):
        if along[m] - along[keep[-1]] >= SAME_POSITION_MM:
            keep.append(m)
            continue
        a, b = (str(files[i][1].get("SOPInstanceUID", "") or "") for i in (keep[-1], m))
        if not a or a != b:
            raise VolumeError(
                f"{directory}: {files[keep[-1]][0].name} and {files[m][0].name} are"
                f" different images at one position ({along[m]:.4g} mm along the normal);"
                " the series may hold several acquisitions (echoes, phases, time points)."
                " Put one acquisition per folder or choose the series with --series."
            )
        copies += 1
    if copies:
        warn(
            f"{directory}: {copies} file(s) repeat a slice (same SOPInstanceUID and"
            " position); each slice is read once."
        )
    return [files[i] for i in keep], along[keep]


def _slots(directory: Path, files: list[tuple[Path, Any]], along: np.ndarray) -> list[int]:
    """The grid slot of each sorted slice: gaps of whole spacings leave slots empty."""
    gaps = np.diff(along)
    unit = _unit(gaps)
    steps = np.maximum(1, np.rint(gaps / unit)).astype(np.int64)
    for m, (gap, step) in enumerate(zip(gaps, steps, strict=True)):
        if abs(gap - step * unit) > GRID_TOLERANCE * unit:
            raise VolumeError(
                f"{directory}: uneven slice spacing: {files[m][0].name} and"
                f" {files[m + 1][0].name} (slices {m + 1} and {m + 2}) are {gap:.4g} mm"
                f" apart, the series' spacing is {unit:.4g} mm (a slice may be off its"
                f" grid by at most {GRID_TOLERANCE:g} of a spacing). {_FIX}."
            )
    slots = [0, *np.cumsum(steps).tolist()]
    missing = slots[-1] + 1 - len(files)
    if missing > len(files):
        raise VolumeError(
            f"{directory}: {len(files)} slices spread over {slots[-1] + 1} positions"
            f" {unit:.4g} mm apart; more slices are missing than present. {_FIX}."
        )
    if missing:
        holes = sorted(set(range(slots[-1] + 1)) - set(slots))
        warn(
            f"{directory}: {missing} slice(s) missing (positions {_listed(holes)} of"
            f" 1..{slots[-1] + 1}, {unit:.4g} mm apart); they are filled with the"
            " series' lowest value so the others keep their true positions."
        )
    return slots


def _unit(gaps: np.ndarray) -> float:
    """The slice spacing: the lower median gap, else the smallest gap when every gap is a
    whole number of it (most slices missing every other position); for the messages,
    the lower median when neither fits."""
    median = float(np.sort(gaps)[(len(gaps) - 1) // 2])
    for unit in (median, float(gaps.min())):
        steps = np.maximum(1, np.rint(gaps / unit))
        if np.all(np.abs(gaps - steps * unit) <= GRID_TOLERANCE * unit):
            return unit
    return median


def _listed(slots: list[int]) -> str:
    text = ", ".join(str(s + 1) for s in slots[:8])
    return text + (", ..." if len(slots) > 8 else "")


def _grid_shifts(
    directory: Path,
    files: list[tuple[Path, Any]],
    ipps: list[np.ndarray],
    slots: list[int],
    iop: np.ndarray,
    spacing: tuple[float, float, float],
) -> list[tuple[float, float]] | None:
    """The in-plane shift (rows, columns; pixels) of each slice onto the normal through
    the first one: ``None`` when all are within :data:`GRID_TOLERANCE`; a gantry tilt's
    shear (offsets growing in step with the slot) is returned with a warning; anything
    else is one line."""
    row, col = iop[:3], iop[3:]
    normal = _unit_normal(iop)
    offs = np.array(
        [
            ipp - (ipps[0] + slot * spacing[2] * normal)
            for ipp, slot in zip(ipps, slots, strict=True)
        ]
    )
    pix = np.stack([offs @ col / spacing[1], offs @ row / spacing[0]], axis=1)  # rows, cols
    if np.abs(pix).max() <= GRID_TOLERANCE:
        return None
    k = np.asarray(slots, dtype=np.float64)
    per_slot = (k @ pix) / float(k @ k)  # least squares through the first slice
    residual = np.abs(pix - np.outer(k, per_slot)).max(axis=1)
    height = float(np.dot(ipps[-1] - ipps[0], normal))
    shift = float(np.linalg.norm((ipps[-1] - ipps[0]) - height * normal))
    tilt = math.degrees(math.atan2(shift, abs(height))) if height else 90.0
    if residual.max() > GRID_TOLERANCE or tilt > MAX_TILT_DEG:
        worst = int(np.argmax(residual))
        raise VolumeError(
            f"{directory}: {files[worst][0].name} lies {np.linalg.norm(offs[worst]):.3g} mm"
            f" beside the slice normal through the first slice, out of step with the other"
            f" slices (not a gantry tilt of at most {MAX_TILT_DEG:g} deg); voxwarp reads"
            f" orthogonal grids only and would misplace it. {_FIX}."
        )
    warn(
        f"{directory}: the stack is tilted {tilt:.1f} deg from its slice normal (a CT gantry"
        f" tilt); each slice is shifted in its plane by up to {np.abs(pix).max():.3g} pixels"
        " onto an orthogonal grid (linear interpolation, as dcm2niix does)."
    )
    return [(float(a), float(b)) for a, b in pix]


def stack_slices(directory: Path, files: list[tuple[Path, Any]], pixel: np.ndarray) -> Stack:
    """Sort, check and place the slices of one series (see the module docstring);
    ``pixel`` is PixelSpacing (row spacing, column spacing)."""
    iop = orientation(files)
    ipps = _positions(files)
    if iop is None or ipps is None or len(files) == 1:
        return _unplaced(directory, files, iop, ipps)
    normal = _unit_normal(iop)
    along = np.array([float(np.dot(v, normal)) for v in ipps])
    files, along = _drop_copies(directory, files, along)
    if len(files) == 1:
        return _unplaced(directory, files, iop, [floats(files[0][1].ImagePositionPatient, 3)])
    slots = _slots(directory, files, along)
    dz = float(along[-1] - along[0]) / slots[-1]
    ipps = [_vector(p.name, ds, "ImagePositionPatient", 3) for p, ds in files]
    spacing = (float(pixel[1]), float(pixel[0]), dz)
    shifts = _grid_shifts(directory, files, ipps, slots, iop, spacing)
    return Stack(files, slots, slots[-1] + 1, dz, iop, ipps[0], shifts)


def _unplaced(
    directory: Path,
    files: list[tuple[Path, Any]],
    iop: np.ndarray | None,
    ipps: list[np.ndarray] | None,
) -> Stack:
    """A single slice, or slices without positions: InstanceNumber order (else file
    names), SpacingBetweenSlices or SliceThickness apart (else 1 mm, with a warning)."""
    numbers = [to_float(ds.get("InstanceNumber"), None) for _, ds in files]
    if all(n is not None for n in numbers):
        order = np.argsort(np.asarray(numbers, dtype=np.float64), kind="stable")
        files = [files[i] for i in order]
    elif len(files) > 1:
        warn(
            f"{directory}: the slices have neither ImagePositionPatient nor"
            " InstanceNumber; they are stacked in file-name order."
        )
    ds0 = files[0][1]
    dz = None
    for keyword in ("SpacingBetweenSlices", "SliceThickness"):
        value = to_float(ds0.get(keyword), None)
        if value is not None and value > 0:
            dz = value
            break
    if dz is None:
        if len(files) > 1:
            warn(f"{directory}: no slice positions or thickness; slice spacing set to 1 mm.")
        dz = 1.0
    first = ipps[0] if ipps is not None and len(files) == 1 else None
    return Stack(files, list(range(len(files))), len(files), dz, iop, first)
