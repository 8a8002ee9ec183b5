"""What a format reader hands back (:class:`Loaded`) and the helpers readers share.

A reader returns the voxels in file index order plus the geometry the file states: a
4x4 index -> world ``affine`` (mm), the ``space`` it is in (``"RAS"`` for patient
coordinates, ``""`` for none) and how it got the numbers. :func:`loaded_geometry` turns
that into the fields of a :class:`voxwarp.core.volume.Volume`: the voxels in the closest
RAS axis order (a lossless permutation and flip) and ``spacing``, ``origin``,
``direction``.
"""

from __future__ import annotations

import math
import os
import sys
import tempfile
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.core.orientation import (
    axis_code,
    obliquity_degrees,
    shear_of,
    split_affine,
    to_closest_ras,
)
from voxwarp.errors import VolumeError
from voxwarp.io.frames import ExtraAxis

_IO_DIR = str(Path(__file__).resolve().parent)

#: Largest axis cosine accepted as an orthogonal voxel grid (a shear above it warns).
_SHEAR_TOL = 1e-3
#: Obliquity below which the axes count as the world axes: header rounding (DICOM
#: ImageOrientationPatient is often written to 6 digits), not an oblique acquisition;
#: 0.001 degrees moves a point 500 mm away by 0.009 mm.
_SNAP_DEGREES = 1e-3


@dataclass
class Loaded:
    """What a format reader found: data (file index order) plus the file's geometry.

    ``affine`` is the 4x4 index -> world matrix in mm when the file states one (world
    RAS+ when ``space == "RAS"``); otherwise ``spacing``/``origin`` (axis-aligned) when
    known. ``array_like`` marks .npy/.npz data (``axis_order`` applies). ``extra``
    describes axes after the three spatial ones (:class:`voxwarp.io.frames.ExtraAxis`,
    one per axis, time or channels) that :func:`voxwarp.io.volumes.load_volume` picks
    from; ``picked`` marks a reader that chose the frame/channel itself;
    ``vector_field`` says why the header marks a displacement field (``""``: it does not).
    """

    data: np.ndarray
    spacing: tuple[float, float, float] | None = None
    origin: tuple[float, float, float] | None = None
    units: str = ""
    array_like: bool = False
    affine: np.ndarray | None = None
    space: str = ""
    modality: str = ""
    padding_value: float | None = None
    extra: tuple[ExtraAxis, ...] = ()
    picked: bool = False
    vector_field: str = ""


def warn(message: str) -> None:
    """Warn, attributing the warning to the first caller outside voxwarp.io."""
    level = 2  # stacklevel=2 is the frame that called warn
    frame = sys._getframe(1)
    while frame is not None and str(Path(frame.f_code.co_filename).parent) == _IO_DIR:
        frame = frame.f_back
        level += 1
    warnings.warn(message, UserWarning, stacklevel=level)


def native(data: np.ndarray) -> np.ndarray:
    """Return ``data`` in native byte order (keeps the dtype's kind and width)."""
    if data.dtype.byteorder not in ("=", "|") and data.dtype.fields is None:
        return data.astype(data.dtype.newbyteorder("="))
    return data


def floats(value: Any, n: int) -> np.ndarray | None:
    """``value`` as ``n`` finite floats, or ``None`` when absent or malformed."""
    if value is None:
        return None
    try:
        arr = np.asarray([float(v) for v in value], dtype=np.float64)
    except (TypeError, ValueError):
        return None
    if arr.size != n or not np.all(np.isfinite(arr)):
        return None
    return arr


def to_float(value: Any, default: float | None) -> float | None:
    """``float(value)`` when that is a finite number, else ``default``."""
    try:
        out = float(value)
    except (TypeError, ValueError):
        return default
    return out if math.isfinite(out) else default


def rescale(data: np.ndarray, slope: float, inter: float) -> np.ndarray:
    """``data * slope + inter``, as integers when that is exact and fits 32 bits."""
    integral = data.dtype.kind in "iub" and float(slope).is_integer() and float(inter).is_integer()
    scaled = data.astype(np.float64) * slope + inter
    if integral and scaled.size:
        lo, hi = float(scaled.min()), float(scaled.max())
        if -(2**31) <= lo and hi < 2**31:
            return scaled.astype(np.int32)  # Volume narrows it to uint8/int16/uint16
    return scaled.astype(np.float32)


def checked_affine(value: Any, where: str, what: str = "") -> np.ndarray:
    """``value`` as a finite, invertible 4x4 affine; raises VolumeError naming ``what``
    (default: the ``'affine'`` key) in ``where``."""
    what = what or f"'affine' in {where}"
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise VolumeError(f"{what} must be a 4x4 matrix of numbers (index -> world mm).") from exc
    if a.shape == (3, 4):
        a = np.vstack([a, [0.0, 0.0, 0.0, 1.0]])
    if a.shape != (4, 4) or not np.all(np.isfinite(a)):
        raise VolumeError(
            f"{what} must be a finite 4x4 matrix (index -> world mm); got shape {a.shape}."
        )
    if not np.allclose(a[3], [0, 0, 0, 1]) or abs(np.linalg.det(a[:3, :3])) < 1e-12:
        raise VolumeError(
            f"{what} is not an invertible index -> world map (a zero or repeated voxel"
            " axis, or a last row other than 0, 0, 0, 1); fix the file's geometry."
        )
    return a


def loaded_geometry(loaded: Loaded, where: str) -> tuple[np.ndarray, dict[str, Any]]:
    """The voxels in closest-RAS order and the Volume geometry keywords of ``loaded``.

    Without an affine the data and ``spacing``/``origin`` pass through unchanged (index
    axes along +x, +y, +z). With one, the axes are permuted and flipped losslessly so
    that each runs closest to +x, +y, +z; the rotation left over (oblique scans) becomes
    ``direction``. A sheared grid keeps its nearest orthogonal grid, with a warning.
    """
    data = loaded.data
    if loaded.affine is None:
        return data, {"spacing": loaded.spacing, "origin": loaded.origin}
    affine = loaded.affine
    file_axes = axis_code(affine[:3, :3]) if loaded.space else ""
    if shear_of(affine) > _SHEAR_TOL:
        warn(
            f"{where}: the voxel axes are not orthogonal (sheared by up to"
            f" {math.degrees(math.asin(min(1.0, shear_of(affine)))):.2f} deg, e.g. a CT"
            " gantry tilt); voxwarp renders the nearest orthogonal grid. Resample the scan"
            " onto an orthogonal grid for exact geometry."
        )
    data, affine = to_closest_ras(data, affine)
    spacing, origin, direction = split_affine(affine)
    if obliquity_degrees(direction) < _SNAP_DEGREES:
        direction = np.eye(3)  # rounding noise in the header, not an oblique scan
    geometry = {
        "spacing": tuple(float(s) for s in spacing),
        "origin": tuple(float(o) for o in origin),
        "direction": direction,
        "space": loaded.space,
        "file_axes": file_axes,
    }
    return data, geometry


@contextmanager
def native_stderr() -> Iterator[list[str]]:
    """Hold back what C libraries print to stderr (file descriptor 2) during the block.

    ITK's bundled HDF5 prints its whole error stack there when a file is damaged;
    voxwarp reports one line instead. Yields a list that holds the held-back lines
    once the block ends (to quote the useful one). Where fd 2 cannot be redirected,
    nothing is held back.
    """
    lines: list[str] = []
    try:
        saved = os.dup(2)
    except OSError:
        yield lines
        return
    with tempfile.TemporaryFile() as held:
        sys.stderr.flush()
        os.dup2(held.fileno(), 2)
        try:
            yield lines
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            held.seek(0)
            lines.extend(held.read().decode("utf-8", "replace").splitlines())


@contextmanager
def quiet_nibabel() -> Iterator[list[str]]:
    """Keep nibabel's log lines (``pixdim[1,2,3] should be non-zero ...``, printed on
    its ``nibabel.global`` logger) off stderr during the block; yields a list that holds
    them (distinct, in order) for the caller to report in its own words."""
    import logging

    said: list[str] = []

    class _Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            text = " ".join(record.getMessage().split())
            if text not in said:
                said.append(text)

    logger = logging.getLogger("nibabel.global")
    keep, propagate = _Keep(), logger.propagate
    saved = logger.handlers[:]
    logger.handlers, logger.propagate = [keep], False
    try:
        yield said
    finally:
        logger.handlers, logger.propagate = saved, propagate
