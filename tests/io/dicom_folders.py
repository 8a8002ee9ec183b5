"""Small DICOM series written with pydicom for the DICOM folder tests (tests only).

:func:`series` makes the datasets of one CT series (8x8 pixels, 6 slices by default)
with its geometry stated exactly: slice ``k`` sits at ``origin + k * dz * normal``
(plus ``k * dz * tan(tilt)`` along the column direction for a gantry tilt), so a test
can compare voxel positions with the ImagePositionPatient it wrote. :func:`save` writes
them into a folder, one file per slice; tests change fields in between.
"""

from __future__ import annotations

import contextlib
import io
import math
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

#: the series UID of :func:`series` unless told otherwise
UID = "1.2.826.0.1.3680043.8.498.33"


def dataset(
    k: int,
    *,
    rows: int = 8,
    cols: int = 8,
    uid: str = UID,
    iop: Sequence[float] = (1, 0, 0, 0, 1, 0),
    ipp: Sequence[float] = (0, 0, 0),
    pixel_spacing: Sequence[float] = (0.5, 0.5),
    syntax: str = "1.2.840.10008.1.2.1",
) -> Any:
    """Slice ``k`` of a CT series: int16 pixels ``100 * k + row * cols + col``."""
    from pydicom.dataset import FileDataset, FileMetaDataset
    from pydicom.uid import CTImageStorage

    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = CTImageStorage
    meta.MediaStorageSOPInstanceUID = f"{uid}.{k + 1}"
    meta.TransferSyntaxUID = syntax
    ds = FileDataset("x", {}, file_meta=meta, preamble=b"\0" * 128)
    ds.SOPClassUID = CTImageStorage
    ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
    ds.StudyInstanceUID = "1.2.826.0.1.3680043.8.498.3"
    ds.SeriesInstanceUID = uid
    ds.PatientID, ds.PatientName, ds.StudyID, ds.SeriesNumber = "P33", "Test^Dicom", "1", 1
    ds.StudyDate, ds.StudyTime = "20260101", "120000"
    ds.Modality = "CT"
    ds.SeriesDescription = f"test {rows}x{cols}"
    ds.Rows, ds.Columns = rows, cols
    ds.SamplesPerPixel = 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 16, 16, 15, 1
    ds.PixelSpacing = [float(v) for v in pixel_spacing]
    ds.SliceThickness = 1.0
    ds.ImageOrientationPatient = [float(v) for v in iop]
    ds.ImagePositionPatient = [round(float(v), 6) for v in ipp]
    ds.InstanceNumber = k + 1
    ds.RescaleSlope, ds.RescaleIntercept = 1, 0
    ds.PixelData = pixels(k, rows, cols).astype("<i2").tobytes()
    return ds


def pixels(k: int, rows: int, cols: int) -> np.ndarray:
    """The (rows, cols) image :func:`dataset` stores for slice ``k``."""
    return (100 * k + np.arange(rows * cols) % 97).reshape(rows, cols).astype(np.int16)


def positions(
    n: int,
    *,
    iop: Sequence[float] = (1, 0, 0, 0, 1, 0),
    origin: Sequence[float] = (-2.0, -3.0, 4.0),
    dz: float = 1.0,
    tilt_deg: float = 0.0,
) -> list[np.ndarray]:
    """ImagePositionPatient (LPS mm) of slices 0..n-1: ``dz`` apart along the normal,
    shifted along the column direction by ``tan(tilt)`` per mm (a tilted gantry)."""
    row, col = np.asarray(iop[:3], float), np.asarray(iop[3:], float)
    normal = np.cross(row, col)
    shift = math.tan(math.radians(tilt_deg))
    return [np.asarray(origin, float) + k * dz * (normal + shift * col) for k in range(n)]


def series(
    n: int = 6,
    *,
    rows: int = 8,
    cols: int = 8,
    uid: str = UID,
    iop: Sequence[float] = (1, 0, 0, 0, 1, 0),
    origin: Sequence[float] = (-2.0, -3.0, 4.0),
    dz: float = 1.0,
    tilt_deg: float = 0.0,
    syntax: str = "1.2.840.10008.1.2.1",
) -> list[Any]:
    """The ``n`` datasets of one series (see :func:`positions` for the geometry)."""
    ipps = positions(n, iop=iop, origin=origin, dz=dz, tilt_deg=tilt_deg)
    return [
        dataset(k, rows=rows, cols=cols, uid=uid, iop=iop, ipp=ipps[k], syntax=syntax)
        for k in range(n)
    ]


def encoded(ds: Any) -> bytes:
    """``ds`` as a DICOM file (preamble, meta group, dataset), written as its meta says."""
    buf = io.BytesIO()
    ds.save_as(buf, enforce_file_format=True)
    return buf.getvalue()


def save(folder: Path, datasets: Sequence[Any], prefix: str = "IM") -> Path:
    """Write ``datasets`` into ``folder`` (made if needed) as PREFIX0001.dcm, ...;
    returns the folder."""
    folder.mkdir(parents=True, exist_ok=True)
    for n, ds in enumerate(datasets, start=1):
        (folder / f"{prefix}{n:04d}.dcm").write_bytes(encoded(ds))
    return folder


def lps_to_ras(p: Sequence[float]) -> np.ndarray:
    """A point in DICOM's LPS+ patient space, in RAS+ (x and y negated)."""
    return np.asarray(p, float) * np.array([-1.0, -1.0, 1.0])


def _print_warning(message, category, filename, lineno, file=None, line=None) -> None:  # type: ignore[no-untyped-def]
    sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


def cli_in_process(argv: Sequence[str]) -> tuple[int, list[str], str]:
    """``voxwarp ARGV`` in this process: (exit code, non-empty stderr lines, stderr).
    Warnings are printed on stderr as the command line prints them (not recorded by
    pytest), so a warning before an error counts as a second line."""
    from voxwarp.cli.main import main

    out, err = io.StringIO(), io.StringIO()
    with warnings.catch_warnings():
        warnings.showwarning = _print_warning
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(list(argv))
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else 1
    text = err.getvalue()
    return code, [line for line in text.splitlines() if line.strip()], text
