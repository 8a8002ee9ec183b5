"""Streaming volume writer: NIfTI or NRRD written one k-slice at a time.

``voxwarp export-volume`` resamples a deformed volume slice by slice on the GPU; this
writer takes those slices as they come and never holds the whole volume. The header
goes first (NIfTI: a nibabel header object with the sform and qform set to the output
affine in RAS, as :func:`voxwarp.io.volumes.save_volume` writes them; NRRD: header text
with ``space directions``/``space origin``, ``right-anterior-superior`` when the volume
has a patient orientation), then each slice's bytes in file order (x fastest, z
slowest), through gzip for ``.nii.gz`` and for ``.nrrd`` (``encoding: gzip``).

Atomic: the bytes go to a temporary name in the destination folder
(:func:`voxwarp.core.files.atomic_open`), which is synced and renamed over the
destination only once every slice is written; on any error or interruption (a full
disk, Ctrl-C) neither the file nor the temporary file is left.
"""

from __future__ import annotations

import contextlib
import gzip
import os
from collections.abc import Iterable
from pathlib import Path
from typing import IO, Any

import numpy as np

from voxwarp.core.files import atomic_open
from voxwarp.errors import VolumeError

#: output formats by file ending
STREAM_FORMATS: dict[str, str] = {".nii.gz": "nii.gz", ".nii": "nii", ".nrrd": "nrrd"}
#: voxel types the writer takes, with their NRRD names
NRRD_TYPES: dict[str, str] = {
    "uint8": "uint8",
    "int16": "int16",
    "uint16": "uint16",
    "float32": "float",
}
#: gzip level (nibabel's default for .nii.gz: fast, most of the gain)
GZIP_LEVEL = 1


def stream_format(path: str | os.PathLike) -> str:
    """``"nii.gz"``, ``"nii"`` or ``"nrrd"`` from ``path``'s ending; a one-line
    :class:`~voxwarp.errors.VolumeError` naming the endings otherwise."""
    name = Path(path).name.lower()
    for ending, fmt in STREAM_FORMATS.items():
        if name.endswith(ending):
            return fmt
    raise VolumeError(
        f"-o {path}: cannot write a volume with this ending; use one of {', '.join(STREAM_FORMATS)}"
    )


def _nifti_header(
    affine: np.ndarray, shape: tuple[int, int, int], dtype: np.dtype, oriented: bool
) -> Any:
    """A nibabel ``Nifti1Header`` of the grid (no scaling, data at byte 352)."""
    import nibabel as nib

    hdr = nib.Nifti1Header()
    try:
        hdr.set_data_shape(shape)
    except nib.spatialimages.HeaderDataError as exc:  # a side over 32767 (int16 dim)
        raise VolumeError(
            f"a NIfTI file cannot hold {'x'.join(map(str, shape))} voxels ({exc}); write"
            " .nrrd or use a coarser grid"
        ) from exc
    hdr.set_data_dtype(dtype)
    code = 1 if oriented else 2  # scanner (patient) space, or "aligned", as save_volume
    hdr.set_sform(affine, code=code)
    hdr.set_qform(affine, code=code)
    hdr.set_xyzt_units("mm")
    hdr.set_slope_inter(1.0, 0.0)
    hdr["vox_offset"] = 352  # 348-byte header + the 4-byte "no extensions" flag
    return hdr


def _vector(v: np.ndarray) -> str:
    return "(" + ",".join(repr(float(x)) for x in v) + ")"


#: NRRD key of a volume written without a patient orientation: its ``space`` is voxwarp's
#: world (RAS mm), so ITK and Slicer place it as the NIfTI, and voxwarp reads it back as
#: a volume without orientation
NOT_ORIENTED_KEY = "voxwarp_oriented"


def nrrd_header(
    affine: np.ndarray, shape: tuple[int, int, int], dtype: np.dtype, oriented: bool
) -> str:
    """The NRRD header text (ending in its blank line) of a gzip-encoded volume."""
    lines = [
        "NRRD0004",
        "# Complete NRRD file format specification at:",
        "# http://teem.sourceforge.net/nrrd/format.html",
        f"type: {NRRD_TYPES[np.dtype(dtype).name]}",
        "dimension: 3",
        # always a space: without it ITK and Slicer read the axes as LPS, 180 degrees from
        # the same volume's NIfTI; a volume without patient orientation says so below
        "space: right-anterior-superior",
        f"sizes: {shape[0]} {shape[1]} {shape[2]}",
        "space directions: " + " ".join(_vector(affine[:3, i]) for i in range(3)),
        "kinds: domain domain domain",
        "endian: little",
        "encoding: gzip",
        f"space origin: {_vector(affine[:3, 3])}",
        'space units: "mm" "mm" "mm"',
    ]
    if not oriented:
        lines.append(f"{NOT_ORIENTED_KEY}:=false")
    return "\n".join(lines) + "\n\n"


def write_volume_slices(
    path: str | os.PathLike,
    affine: np.ndarray,
    shape: tuple[int, int, int],
    dtype: np.dtype | str,
    slices: Iterable[np.ndarray],
    *,
    oriented: bool,
) -> Path:
    """Write a volume whose k-slices ``slices`` yields, one at a time, atomically.

    Parameters
    ----------
    path
        ``.nii.gz``, ``.nii`` or ``.nrrd`` (:func:`stream_format`).
    affine
        4x4 index -> world (RAS mm) matrix of the voxel grid.
    shape
        ``(nx, ny, nz)``.
    dtype
        ``uint8``, ``int16``, ``uint16`` or ``float32``; each slice is converted to it.
    slices
        ``nz`` arrays of shape ``(ny, nx)`` (indexed ``[j, i]``), slice k = 0 first.
    oriented
        Whether world space is patient RAS (NIfTI codes 1 vs 2; NRRD ``space``).

    Raises
    ------
    VolumeError
        For a bad ending, dtype, or a slice of the wrong shape or count.
    OutputError
        For a failed write (nothing is left behind; also on any other exception).
    """
    fmt = stream_format(path)
    dt = np.dtype(dtype)
    if dt.name not in NRRD_TYPES:
        raise VolumeError(f"cannot stream {dt.name} voxels; use one of {', '.join(NRRD_TYPES)}")
    shape = (int(shape[0]), int(shape[1]), int(shape[2]))
    a = np.asarray(affine, dtype=np.float64)
    file_dt = dt.newbyteorder("<")
    suffix = ".nii.gz" if fmt == "nii.gz" else f".{fmt}"
    header = None if fmt == "nrrd" else _nifti_header(a, shape, dt, oriented)  # before a file
    with atomic_open(path, "wb", suffix=suffix) as fh:
        if fmt == "nrrd":
            fh.write(nrrd_header(a, shape, dt, oriented).encode("ascii"))
        body: IO[bytes] = fh
        if fmt in ("nii.gz", "nrrd"):
            body = gzip.GzipFile(fileobj=fh, mode="wb", compresslevel=GZIP_LEVEL, mtime=0)
        try:
            if header is not None:
                header.write_to(body)
            _write_slices(body, slices, shape, file_dt)
        except BaseException:
            if body is not fh:  # the first error is the one to report
                with contextlib.suppress(Exception):
                    body.close()
            raise
        if body is not fh:
            body.close()  # writes the gzip trailer (an error here fails the write)
    return Path(path)


def _write_slices(
    body: IO[bytes], slices: Iterable[np.ndarray], shape: tuple[int, int, int], dt: np.dtype
) -> None:
    nx, ny, nz = shape
    k = 0
    for k, data in enumerate(slices, start=1):
        s = np.asarray(data)
        if k > nz or s.shape != (ny, nx):
            what = f"shape {s.shape}" if k <= nz else "a slice too many"
            raise VolumeError(f"slice {k - 1}: expected ({ny}, {nx}) of {nz} slices; got {what}")
        body.write(np.ascontiguousarray(s, dtype=dt).tobytes())
    if k != nz:
        raise VolumeError(f"got {k} slices of {nz}: the volume would be incomplete")
