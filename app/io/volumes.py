"""Reading and writing volumes, and the numbers ``voxwarp info`` prints.

Every reader returns a :class:`voxwarp.core.volume.Volume` in voxwarp's axis order:
``data[i, j, k]`` with ``i`` along x, ``j`` along y and ``k`` along z, spacing and
origin in millimetres (see :mod:`voxwarp.core.volume`).

Supported inputs (chosen by extension, or by the content of a folder):

========================  ===========================================================
``.npy`` / ``.npz``       NumPy arrays indexed ``(x, y, z)`` (``allow_pickle=False``);
                          an ``.npz`` holds the volume under ``data`` (or as its only
                          array) and optionally ``spacing``, ``origin``, ``units``, or
                          ``affine`` with ``space`` ("RAS" or "LPS").
``.raw .bin .img``        Headerless voxels, x fastest, described by a JSON sidecar
+ ``.json`` sidecar       ``vol.raw.json`` or ``vol.json``:
                          ``{"dims": [nx, ny, nz], "dtype": "uint16", "spacing":
                          [sx, sy, sz], "byte_order": "little", "origin": [...],
                          "header_bytes": 0, "units": "HU"}``, optionally an
                          ``"affine"`` (4x4 index -> world mm) with ``"space"``
                          ``"RAS"`` or ``"LPS"``. The sidecar path itself may be
                          passed too.
``.nrrd`` / ``.nhdr``     NRRD via pynrrd: ``space directions`` and ``space origin`` in
                          any ``space`` (RAS, LAS, LPS become patient RAS). voxwarp
                          writes every NRRD with ``space: right-anterior-superior``
                          (so ITK and Slicer place it as the same volume's NIfTI);
                          ``voxwarp_oriented:=false`` marks one without a patient
                          orientation, which reads back as such.
``.nii`` / ``.nii.gz``    NIfTI via nibabel: the sform, else the qform (nibabel's
                          precedence); neither code set means no orientation.
folder of DICOM files     One series (``series=``; the largest by default), sorted
                          along the slice normal, rescaled to stored units (HU for CT);
                          ImageOrientationPatient/ImagePositionPatient (LPS) give the
                          patient geometry.
``.dcm``                  A single multi-frame DICOM file.
``.tif`` / ``.tiff``      A multi-page TIFF z-stack, or a folder of single-page TIFF
                          slices in natural file-name order; ImageJ calibration is used.
``.mha`` / ``.mhd``       MetaImage via SimpleITK (``registration`` extra), LPS.
========================  ===========================================================

4-D and 5-D images (NIfTI time series and vector images, NRRD ``list``/``vector``/``time``
axes, TIFF hyperstacks with T/C/S axes, 4-D ``.npy``/``.npz`` arrays, MetaImage and
SimpleITK images with several components or a 4th dimension) load one time point or
channel: ``frame_index=`` / ``channel=`` (:mod:`voxwarp.io.frames`).

In-memory images load as their files would: a SimpleITK or ITK (``itk``) image (LPS
origin/spacing/direction, converted to RAS) and a nibabel image (its RAS affine and
scaled ``dataobj``); see :mod:`voxwarp.io.image_objects`.

:func:`save_volume` writes ``.npz``, ``.raw`` (+ ``.raw.json``), ``.nrrd``,
``.nii``/``.nii.gz`` and ``.tif`` atomically. :func:`volume_summary` and
:func:`volume_info` describe a volume as text and as a JSON-ready dict.

Files with a patient orientation are stored in the closest RAS axis order (a lossless
permutation and flip of the voxels; see :mod:`voxwarp.core.orientation`), so world space
is patient RAS+ mm whatever the format; an oblique scan keeps its rotation in
``Volume.direction`` and renders without resampling.

Every problem caused by the input raises :class:`voxwarp.errors.VolumeError` with a
message naming the problem and the fix. The format libraries (pynrrd, nibabel,
pydicom, tifffile) are imported only when a file of their format is read or written.
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np

from voxwarp.core import limits as _limits
from voxwarp.core.allowed_folders import ALLOW_DIRS_ENV, allowed_folders, outside_allowed
from voxwarp.core.files import atomic_open as _atomic_open
from voxwarp.core.files import atomic_output as _atomic_output
from voxwarp.core.input_files import check_regular, not_regular
from voxwarp.core.json_input import parse_json_text, read_json_text
from voxwarp.core.orientation import PATIENT_SPACES, affine_to_ras
from voxwarp.core.volume import Volume, check_finite
from voxwarp.core.volume import parse_triple as _triple
from voxwarp.core.volume import short_repr as _short
from voxwarp.errors import VolumeError
from voxwarp.io import frames as _frames
from voxwarp.io import samples as _samples
from voxwarp.io.dicom import list_dicom_series, read_dicom_dir, read_dicom_file
from voxwarp.io.frame_axes import nifti_extra_axes, nrrd_extra, nrrd_spatial_axes, tiff_extra
from voxwarp.io.image_objects import (
    ITK_SOURCE,
    NIBABEL_SOURCE,
    SITK_SOURCE,
    image_kind,
    itk_loaded,
    sitk_loaded,
)
from voxwarp.io.loaded import Loaded as _Loaded
from voxwarp.io.loaded import checked_affine, loaded_geometry, quiet_nibabel, rescale
from voxwarp.io.loaded import native as _native
from voxwarp.io.loaded import warn as _warn
from voxwarp.io.metaimage import METAIMAGE_SUFFIXES, read_metaimage
from voxwarp.io.volume_stream import NOT_ORIENTED_KEY

__all__ = [
    "LOAD_EXTENSIONS",
    "SAVE_FORMATS",
    "load_volume",
    "save_volume",
    "volume_info",
    "volume_summary",
]

AxisOrder = Literal["xyz", "zyx"]
NanPolicy = Literal["raise", "mask"]

#: File extensions :func:`load_volume` reads (besides folders of DICOM or TIFF slices).
LOAD_EXTENSIONS: tuple[str, ...] = (
    ".npy",
    ".npz",
    ".raw",
    ".bin",
    ".img",
    ".json",
    ".nrrd",
    ".nhdr",
    ".nii",
    ".nii.gz",
    ".hdr",
    ".mha",
    ".mhd",
    ".dcm",
    ".tif",
    ".tiff",
)

#: Formats :func:`save_volume` writes, with the extension each one uses.
SAVE_FORMATS: dict[str, str] = {
    "npz": ".npz",
    "raw": ".raw",
    "nrrd": ".nrrd",
    "nii": ".nii",
    "nii.gz": ".nii.gz",
    "tif": ".tif",
}

_RAW_EXTENSIONS = (".raw", ".bin", ".img")
#: ITK transform files (voxwarp.io.fields reads them as warps, not volumes).
_TRANSFORM_EXTENSIONS = (".h5", ".hdf5", ".tfm", ".mat")
_TIFF_EXTENSIONS = (".tif", ".tiff")
_SUPPORTED_TEXT = (
    ".npy, .npz, .raw/.bin/.img with a .json sidecar, .nrrd/.nhdr, .nii/.nii.gz,"
    " .mha/.mhd, .tif/.tiff (multi-page), .dcm (multi-frame), or a folder of DICOM or TIFF"
    " slices"
)

#: dtype names accepted in a raw sidecar, mapped to NumPy type codes.
_RAW_DTYPES: dict[str, str] = {
    "uint8": "u1",
    "uchar": "u1",
    "int8": "i1",
    "char": "i1",
    "uint16": "u2",
    "ushort": "u2",
    "int16": "i2",
    "short": "i2",
    "uint32": "u4",
    "uint": "u4",
    "int32": "i4",
    "int": "i4",
    "float32": "f4",
    "float": "f4",
    "float64": "f8",
    "double": "f8",
}
_RAW_DTYPE_TEXT = "uint8, int8, uint16, int16, uint32, int32, float32, float64"

#: Length units found in file headers, in millimetres.
_LENGTH_UNITS_MM: dict[str, float] = {
    "": 1.0,
    "mm": 1.0,
    "millimeter": 1.0,
    "millimetre": 1.0,
    "unknown": 1.0,
    "pixel": 1.0,
    "micron": 1e-3,
    "microns": 1e-3,
    "um": 1e-3,
    "µm": 1e-3,
    "μm": 1e-3,
    "\\u00b5m": 1e-3,
    "nm": 1e-6,
    "cm": 10.0,
    "m": 1000.0,
    "meter": 1000.0,
    "metre": 1000.0,
    "inch": 25.4,
}

_HIST_BINS = 16
_HIST_WIDTH = 40
_PERCENTILES = (1, 5, 50, 95, 99)
_STATS_SAMPLE_VOXELS = 1 << 24


# ---------------------------------------------------------------------------- helpers
def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _json_triple(
    value: Any, what: str, where: str, *, positive: bool
) -> tuple[float, float, float]:
    """Like :func:`_triple` but accepting only JSON numbers (no strings or booleans)."""
    items = value if isinstance(value, list) else [value]
    if not items or not all(_is_number(v) for v in items):
        raise VolumeError(
            f"'{what}' in {where} must be a number or a list of three numbers [x, y, z];"
            f" got {_short(value)}."
        )
    return _triple(items, f"'{what}'", positive=positive, where=where)


def _natural_key(name: str) -> tuple:
    """Sort key putting ``slice2`` before ``slice10``."""
    parts = re.split(r"(\d+)", name)
    return tuple(int(p) if p.isdigit() else p.lower() for p in parts)


def _stem(path: Path) -> str:
    name = path.name
    lower = name.lower()
    for double in (".nii.gz", ".raw.json", ".bin.json", ".img.json"):
        if lower.endswith(double) and len(name) > len(double):
            return name[: -len(double)]
    return path.stem or name


def _unit_scale(unit: Any, where: str) -> float:
    """Millimetres per ``unit`` (a length unit name from a file header)."""
    if not isinstance(unit, str):
        return 1.0
    key = unit.strip().lower()
    if key in _LENGTH_UNITS_MM:
        return _LENGTH_UNITS_MM[key]
    _warn(f"{where}: unknown length unit {unit!r}; spacing taken as millimetres.")
    return 1.0


def _check_choice(value: Any, name: str, choices: Sequence[str]) -> None:
    if not isinstance(value, str) or value not in choices:
        options = " or ".join(repr(c) for c in choices)
        raise VolumeError(f"{name} must be {options}; got {_short(value)}.")


def _check_downsample(factor: Any) -> int | tuple[int, int, int]:
    values = factor if isinstance(factor, list | tuple) else [factor]
    ok = len(values) in (1, 3) and all(
        isinstance(v, int | np.integer) and not isinstance(v, bool) and v >= 1 for v in values
    )
    if not ok:
        raise VolumeError(
            f"downsample must be a positive integer (or three); got {_short(factor)}."
        )
    if len(values) == 1:
        return int(values[0])
    return (int(values[0]), int(values[1]), int(values[2]))


# ---------------------------------------------------------------------------- loading
def load_volume(
    source: str | os.PathLike[str] | np.ndarray | Any,
    spacing: float | Sequence[float] | None = None,
    *,
    origin: float | Sequence[float] | None = None,
    axis_order: AxisOrder = "xyz",
    nan_policy: NanPolicy = "raise",
    downsample: int = 1,
    affine: Sequence[Sequence[float]] | np.ndarray | None = None,
    space: str = "RAS",
    series: str | int | None = None,
    allow_data_dirs: Sequence[str | os.PathLike[str]] | None = None,
    memory_budget: int | float | str | None = None,
    frame_index: int | None = None,
    channel: int | None = None,
) -> Volume:
    """Load a volume from a file, a folder of slices, a NumPy array, or an in-memory
    SimpleITK or nibabel image.

    Parameters
    ----------
    source
        Path to a volume file or to a folder of DICOM or TIFF slices (see the module
        docstring for the formats), ``"sample:NAME"`` for a bundled sample volume
        (see :func:`voxwarp.io.samples.sample_names`), an in-memory array, a
        ``SimpleITK.Image`` or an ITK Python image (``itk.Image``, ``itk.VectorImage``;
        geometry from its origin, spacing and direction, which are LPS, converted to
        RAS as for an LPS NRRD; voxels from ``GetArrayFromImage``, reordered from
        ``(z, y, x)``), or a nibabel image (``Nifti1Image``, ``Nifti2Image``,
        ``MGHImage``: geometry from its RAS ``affine``, voxels from ``dataobj`` with its
        scaling), read as the same image's file would be. No library is imported
        unless an image of it is passed; a vector or 4-D image needs ``channel=`` /
        ``frame_index=``.
    spacing
        Voxel size ``(sx, sy, sz)`` in mm (or one number for all axes). Overrides what
        the file states; default: the file's spacing, or 1 mm.
    origin
        World position ``(x, y, z)`` in mm of the centre of voxel ``(0, 0, 0)``.
        Overrides what the file states; default: the file's origin, or 0.
    axis_order
        How an array (or a ``.npy``/``.npz`` file) is indexed: ``"xyz"``
        (``array[i, j, k]``, voxwarp's order) or ``"zyx"`` (napari/tifffile order,
        transposed on load). ``spacing`` and ``origin`` are always given as
        ``(x, y, z)``. Other formats (and SimpleITK/nibabel images) define their own
        axis order, so ``"zyx"`` is an error for them.
    nan_policy
        ``"raise"`` rejects NaN/Inf voxels; ``"mask"`` replaces them by the minimum
        finite value with a warning (see :func:`voxwarp.core.volume.check_finite`).
    downsample
        Integer block-mean reduction factor per axis (1 = full resolution); warns
        when it reduces the volume.
    affine
        For arrays: the 4x4 index -> world matrix (mm) in ``space``; gives the array a
        patient orientation (e.g. ``nibabel_image.affine``). Excludes spacing/origin.
        It maps the index ``(i, j, k)`` of the array **as passed**, in ``axis_order``:
        with ``"zyx"`` its first column is the step along the array's first axis (z),
        as for ``np.asarray(nibabel_image.dataobj).T``. ITK's geometry indexes
        ``(x, y, z)`` while ``GetArrayFromImage`` is ``(z, y, x)``: pass the SimpleITK
        image itself instead (or reverse the affine's first three columns). A
        ``spacing=`` given with ``affine=`` that matches its voxel sizes only in the
        other order is reported as such (one line).
    space
        ``"RAS"`` (nibabel, Slicer) or ``"LPS"`` (DICOM, ITK): the patient space of
        ``affine``.
    series
        For a folder with several DICOM series: the 1-based index ``voxwarp info``
        lists, or a SeriesInstanceUID. Default: the largest series, with a warning.
    allow_data_dirs
        Folders a detached NRRD header (``data file:``) may name its data in, besides
        the header's own folder and its subfolders (also ``$VOXWARP_ALLOW_DATA_DIRS``,
        ``os.pathsep``-separated); any other data file is refused.
    memory_budget
        Most bytes the voxels of a file may take (an int, or a size text such as
        ``"2G"``; ``"unlimited"`` for no limit). Default: half the physical memory
        (:data:`voxwarp.core.limits.DEFAULT_MEMORY_FRACTION`). Each reader checks the
        size its header states before reading the voxels.
    frame_index, channel
        For a 4-D or 5-D image (a time series, a vector or multi-channel image): the
        0-based time point and channel to load (see :mod:`voxwarp.io.frames`). A file
        that holds several volumes without them raises
        :class:`~voxwarp.io.frames.FrameChoiceError` naming the range; NumPy arrays
        and ``.npy``/``.npz`` files with a 4th axis (last in ``"xyz"`` order, first
        in ``"zyx"``) take either. A NIfTI with a vector/displacement intent (or 5-D
        with 3 float components), a 3-component float NRRD vector axis or a SimpleITK
        float 3-vector image is a displacement field: refused (it goes to
        ``--displacement``) unless ``channel`` picks one component.

    Returns
    -------
    Volume
        With ``name`` set to the file stem (or folder name), ``source`` to the
        absolute path (``None`` for arrays) and ``units`` to the value unit when
        known (``"HU"`` for CT DICOM). A SimpleITK image is named ``"SimpleITK image"``
        (``name`` and ``source``); a nibabel image has ``source`` ``"nibabel image"``
        and its file's stem as ``name`` when it was loaded from one (its voxels may
        have changed in memory, so a scene embeds them rather than naming the file).

    Raises
    ------
    VolumeError
        For a missing file, an unsupported or corrupt file, bad metadata, NaN/Inf
        voxels under ``nan_policy="raise"`` or an invalid argument; the message names
        the problem and the fix.
    """
    _check_choice(axis_order, "axis_order", ("xyz", "zyx"))
    _check_choice(nan_policy, "nan_policy", ("raise", "mask"))
    factor = _check_downsample(downsample)
    spacing_override = None if spacing is None else _triple(spacing, "spacing", positive=True)
    origin_override = None if origin is None else _triple(origin, "origin")
    array_affine = _array_affine(affine, space, spacing_override, origin_override, axis_order)
    sample_spacing: str | None = None  # a bundled sample knows whether its spacing is real
    pick = _frames.Pick(frame_index, channel)

    if isinstance(source, str) and source.startswith("sample:") and not os.path.exists(source):
        sample = _samples.load_sample(source.split(":", 1)[1])  # looked up when called
        loaded = _Loaded(sample.data, sample.spacing, sample.origin, sample.units)
        if sample.space:
            loaded.affine, loaded.space = sample.affine, sample.space
        name, src, what = sample.name, sample.source, source
        sample_spacing = sample.spacing_source
    elif isinstance(source, str | os.PathLike):
        try:
            path = Path(os.path.abspath(os.path.expanduser(os.fspath(source))))
        except (TypeError, ValueError) as exc:
            raise VolumeError(f"invalid path {_short(source)}: {exc}") from exc
        with allowed_data_dirs(allow_data_dirs), _limits.memory_budget(memory_budget):
            loaded = _load_path(path, series, pick)
        name, src = _stem(path), str(path)
        what = path.name
    elif image_kind(source):
        loaded, name, src, what = _image_object(source, pick)
    elif isinstance(source, np.ndarray) or hasattr(source, "__array__"):
        try:
            array = np.asarray(source)
        except (TypeError, ValueError) as exc:
            raise VolumeError(f"cannot convert {type(source).__name__} to an array: {exc}") from exc
        loaded = _Loaded(array, array_like=True)
        if array_affine is not None:
            loaded.affine, loaded.space = array_affine, "RAS"
        name, src, what = "volume", None, "array"
    else:
        raise VolumeError(
            "source must be a path or a NumPy array (or a SimpleITK or nibabel image);"
            f" got {type(source).__name__}."
        )

    data = _pick(loaded, pick, axis_order, what)
    if axis_order == "zyx":
        if not loaded.array_like:
            raise VolumeError(
                f"axis_order='zyx' applies to NumPy arrays and .npy/.npz files; {what}"
                " defines its own axis order. Leave axis_order at 'xyz'."
            )
        if data.ndim != 3:
            raise VolumeError(
                f"a volume needs a 3D array; got {data.ndim}D with shape {data.shape}."
            )
        data = data.transpose(2, 1, 0)
        if loaded.affine is not None:  # the file's affine indexes the stored axes
            loaded.affine = loaded.affine[:, [2, 1, 0, 3]]

    if array_affine is not None and not loaded.array_like:
        raise VolumeError(
            f"affine= applies to NumPy arrays and .npy files; {what} states its own"
            " geometry. Leave affine out."
        )
    if array_affine is not None and loaded.affine is None:
        loaded.affine, loaded.space = array_affine, "RAS"
    loaded.data = data
    volume = _finish(loaded, spacing_override, origin_override, name, src, nan_policy, what)
    if sample_spacing is not None and spacing_override is None:
        volume.spacing_source = sample_spacing
    volume.frame_choice = pick.keywords()
    if factor != 1:
        reduced = volume.downsample(factor)
        _warn(
            f"{what}: downsampled by {factor} from {volume.shape} to {reduced.shape} voxels;"
            f" spacing is now {reduced.spacing} mm."
        )
        volume = reduced
    return volume


def _finish(
    loaded: _Loaded,
    spacing: tuple[float, float, float] | None,
    origin: tuple[float, float, float] | None,
    name: str,
    source: str | None,
    nan_policy: NanPolicy,
    what: str,
) -> Volume:
    """Normalise dtype and byte order, check NaN/Inf, orient, and build the Volume.

    ``spacing``/``origin`` are the user's overrides; they apply to the stored
    (closest-RAS) axes.
    """
    data = np.asarray(loaded.data)
    if data.dtype.kind == "f" and data.dtype != np.float32:
        with np.errstate(over="ignore", invalid="ignore"):
            data = data.astype(np.float32)  # before check_finite: overflow becomes Inf
    elif data.dtype.kind in "iub":
        data = _native(data)
    if data.dtype.kind == "f" and data.ndim == 3 and data.size:
        data = check_finite(data, nan_policy, what=what)
    if data.ndim != 3:
        raise VolumeError(
            f"a volume needs a 3D array (nx, ny, nz); got {data.ndim}D with shape"
            f" {data.shape}. For a single image, add an axis: array[..., None]."
        )
    loaded.data = data
    data, geometry = loaded_geometry(loaded, what)
    stated = geometry["spacing"] is not None
    if spacing is not None:
        geometry["spacing"] = spacing
    if origin is not None:
        geometry["origin"] = origin
    geometry["spacing"] = geometry["spacing"] or (1.0, 1.0, 1.0)
    geometry["origin"] = geometry["origin"] or (0.0, 0.0, 0.0)
    source_of_spacing = "given" if spacing is not None else "file" if stated else "assumed"
    return Volume(
        data,
        name=name,
        source=source,
        units=loaded.units,
        spacing_source=source_of_spacing,
        modality=loaded.modality,
        padding_value=loaded.padding_value,
        **geometry,
    )


def _image_object(source: Any, pick: _frames.Pick) -> tuple[_Loaded, str, str, str]:
    """A SimpleITK, ITK or nibabel image as (loaded, name, source, what); no file is
    written."""
    kind = image_kind(source)
    if kind == "sitk":
        return sitk_loaded(source), SITK_SOURCE, SITK_SOURCE, "the SimpleITK image"
    if kind == "itk":
        return itk_loaded(source), ITK_SOURCE, ITK_SOURCE, "the ITK image"
    filename = source.get_filename() if hasattr(source, "get_filename") else None
    name = _stem(Path(filename)) if filename else NIBABEL_SOURCE
    loaded = _nibabel_loaded(source, "the nibabel image", "nibabel", pick)
    return loaded, name, NIBABEL_SOURCE, "the nibabel image"


def _pick(loaded: _Loaded, pick: _frames.Pick, axis_order: str, what: str) -> np.ndarray:
    """The loaded voxels reduced to the chosen frame/channel (see :mod:`voxwarp.io.frames`);
    an array's axes beyond 3 (first in ``"zyx"`` order) are taken as unnamed."""
    data = loaded.data
    if loaded.picked:
        return data
    if loaded.array_like and data.ndim > 3:
        n = data.ndim - 3
        if axis_order == "zyx":  # (t, z, y, x): the extra axes lead
            data = np.moveaxis(data, list(range(n)), list(range(3, 3 + n)))
        loaded.extra = loaded.extra or tuple(
            _frames.ExtraAxis(_frames.ANY, int(s)) for s in data.shape[3:]
        )
    if data.ndim != 3 + len(loaded.extra):
        return data  # not a volume: _finish says so
    shape = tuple(int(s) for s in data.shape)
    indices = _frames.choose(loaded.extra, pick, what, shape, vector_field=loaded.vector_field)
    return _frames.take(data, indices)


def _array_affine(
    affine: Any, space: Any, spacing: Any, origin: Any, axis_order: str = "xyz"
) -> np.ndarray | None:
    """The RAS affine an array was given (``affine=`` in ``space``), or ``None``.

    The affine maps the index ``(i, j, k)`` of the array as passed (in ``axis_order``)
    to world mm; a ``spacing=`` equal to its voxel sizes in the other order is reported
    as a transposed array/affine pair."""
    if affine is None:
        return None
    a = checked_affine(affine, "affine=") if spacing is not None else None
    if a is not None:
        _check_transposed(a, spacing, axis_order)
    if spacing is not None or origin is not None:
        raise VolumeError(
            "pass either affine= or spacing=/origin= for an array, not both (the affine"
            " holds the spacing and the origin)."
        )
    a = checked_affine(affine, "affine=")
    return _to_ras(a, space, "space=")


def _check_transposed(affine: np.ndarray, spacing: Sequence[float], axis_order: str) -> None:
    """A one-line error when ``spacing`` (x, y, z) matches the voxel sizes of ``affine``
    only with its columns reversed: the affine indexes the other axis order."""
    sizes = np.linalg.norm(affine[:3, :3], axis=0)  # per axis of the array as passed
    if axis_order == "zyx":
        sizes = sizes[::-1]  # the array's (z, y, x) axes become (x, y, z)
    given = np.asarray(spacing, dtype=np.float64)
    if np.allclose(sizes, given, rtol=1e-4) or not np.allclose(sizes[::-1], given, rtol=1e-4):
        return
    other = "xyz" if axis_order == "zyx" else "zyx"
    raise VolumeError(
        f"affine= and axis_order={axis_order!r} disagree: the affine's voxel sizes match"
        f" spacing={tuple(float(v) for v in given)} only in {other!r} order; the affine must"
        " map the index of the array as passed (in axis_order) to world. Reverse its first"
        " three columns (affine[:, [2, 1, 0, 3]]), or pass the SimpleITK/nibabel image itself."
    )


def _to_ras(affine: np.ndarray, space: Any, where: str) -> np.ndarray:
    """``affine`` (in ``space``: "RAS", "LPS" or "LAS") as a RAS affine."""
    if space not in PATIENT_SPACES:
        raise VolumeError(f"{where} must be 'RAS' or 'LPS'; got {_short(space)}.")
    return affine_to_ras(affine, space)


def _load_path(
    path: Path, series: str | int | None = None, pick: _frames.Pick | None = None
) -> _Loaded:
    """Dispatch on the path: folder content or file extension."""
    if not path.exists():
        if path.is_symlink():
            raise VolumeError(f"{path} is a link to nothing (a dangling link or a loop)")
        raise VolumeError(f"no such file or directory: {path}")
    if path.is_dir():
        return _read_directory(path, series)
    kind = not_regular(path)  # a FIFO, socket, device or /proc file: could block forever
    if kind is not None:
        raise VolumeError(
            f"{path} is not a regular file ({kind}); voxwarp reads volume files and folders"
            " of slices. Save the data to a file first."
        )
    if path.stat().st_size == 0:
        raise VolumeError(f"{path} is empty (0 bytes); give the volume file itself")
    if series is not None:
        raise VolumeError(
            f"series= chooses among the DICOM series of a folder; {path.name} is a file."
            " Pass the folder, or leave series out."
        )
    lower = path.name.lower()
    if lower.endswith((".npy", ".npz")):
        return _read_numpy(path)
    if lower.endswith((".nii", ".nii.gz", ".hdr")):
        return _read_nifti(path, pick)
    if lower.endswith((".nrrd", ".nhdr")):
        return _read_nrrd(path)
    if lower.endswith(METAIMAGE_SUFFIXES):
        return read_metaimage(path)
    if lower.endswith(_TIFF_EXTENSIONS):
        return _read_tiff_file(path)
    if lower.endswith(".json"):
        return _read_raw(_raw_for_sidecar(path), path)
    if lower.endswith(_RAW_EXTENSIONS):
        sidecar = _sidecar_for_raw(path)
        if sidecar is None and lower.endswith(".img") and path.with_suffix(".hdr").exists():
            return _read_nifti(path, pick)  # Analyze / NIfTI pair
        if sidecar is None:
            raise VolumeError(
                f"no JSON sidecar for raw file {path}: put {path.name}.json or"
                f" {path.stem}.json beside it, e.g. "
                '{"dims": [nx, ny, nz], "dtype": "uint16", "spacing": [sx, sy, sz],'
                ' "byte_order": "little"}.'
            )
        return _read_raw(path, sidecar)
    if lower.endswith((".dcm", ".dicom")):
        return read_dicom_file(path)
    if lower.endswith(_TRANSFORM_EXTENSIONS):
        raise VolumeError(
            f"{path.name} is an ITK transform file, not a volume: load it with --displacement"
            f" {path.name} on the moving volume (voxwarp render MOVING --displacement"
            f" {path.name})"
        )
    raise VolumeError(
        f"unsupported file type {path.suffix or '(no extension)'} for {path}; voxwarp reads"
        f" {_SUPPORTED_TEXT}. Convert the file, or pass the folder for DICOM slices."
    )


# ---------------------------------------------------------------------------- numpy
def _check_npy_header(f: Any, what: str) -> None:
    """Check the shape an ``.npy`` header (open binary file ``f``) states against the
    memory budget; a header that cannot be parsed is left to ``np.load`` to report."""
    fmt = np.lib.format
    try:
        version = fmt.read_magic(f)
        read = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
        shape, _, dtype = read(f)
    except Exception:
        return
    _limits.check_load_bytes(shape, dtype.itemsize, what)


def _read_numpy(path: Path) -> _Loaded:
    if path.name.lower().endswith(".npy"):
        try:
            with open(path, "rb") as f:
                _check_npy_header(f, path.name)
        except OSError as exc:
            raise VolumeError(f"cannot read {path}: {exc.strerror or exc}.") from exc
    try:
        obj = np.load(path, allow_pickle=False)
    except Exception as exc:
        raise VolumeError(
            f"cannot read {path} as a NumPy .npy/.npz file ({type(exc).__name__}: {exc})."
            " The file may be corrupt or hold pickled objects, which voxwarp does not load;"
            " save plain numeric arrays with np.save / np.savez."
        ) from exc
    if isinstance(obj, np.ndarray):
        return _Loaded(obj, array_like=True)
    with obj:
        return _read_npz_contents(obj, path)


def _npz_get(npz: Any, key: str, path: Path) -> np.ndarray:
    try:
        return np.asarray(npz[key])
    except Exception as exc:
        raise VolumeError(
            f"cannot read array {key!r} from {path} ({type(exc).__name__}: {exc}). The file"
            " may be corrupt or hold pickled objects; save plain arrays with np.savez."
        ) from exc


def _read_npz_contents(npz: Any, path: Path) -> _Loaded:
    keys = list(npz.files)
    meta = {"spacing", "origin", "units", "affine", "space"}
    if "data" in keys:
        key = "data"
    else:
        candidates = [k for k in keys if k not in meta]
        if len(candidates) != 1:
            raise VolumeError(
                f"{path} holds the arrays {_short(keys)}; voxwarp expects the volume under"
                " the key 'data' (or a single array). Save it with"
                " np.savez(path, data=array, spacing=(sx, sy, sz))."
            )
        key = candidates[0]
    try:
        member = npz.zip.open(f"{key}.npy")
    except Exception:  # _npz_get reports a member it cannot read
        member = None
    if member is not None:
        with member:
            _check_npy_header(member, f"{path.name}[{key!r}]")
    data = _npz_get(npz, key, path)
    loaded = _Loaded(data, array_like=True)
    for name in ("spacing", "origin"):
        if name in keys and name != key:
            arr = _npz_get(npz, name, path)
            if arr.dtype.kind not in "iuf":
                raise VolumeError(
                    f"'{name}' in {path} must hold numbers; got an array of dtype {arr.dtype}."
                )
            value = _triple(arr, f"'{name}'", positive=name == "spacing", where=str(path))
            setattr(loaded, name, value)
    if "units" in keys and key != "units":
        arr = _npz_get(npz, "units", path)
        if arr.dtype.kind not in "US" or arr.size != 1:
            raise VolumeError(
                f"'units' in {path} must be a string, e.g. np.array('HU'); got an array of"
                f" dtype {arr.dtype} and shape {arr.shape}."
            )
        item = arr.reshape(()).item()
        loaded.units = item.decode("utf-8", "replace") if isinstance(item, bytes) else str(item)
    if "affine" in keys and key != "affine":
        space = _npz_get(npz, "space", path).reshape(-1) if "space" in keys else ["RAS"]
        affine = _npz_get(npz, "affine", path)
        if affine.dtype.kind not in "iuf":
            raise VolumeError(f"'affine' in {path} must hold numbers; got dtype {affine.dtype}.")
        _stated_affine(loaded, affine, str(space[0]) if len(space) == 1 else space, str(path))
    return loaded


# ---------------------------------------------------------------------------- raw
def _sidecar_for_raw(path: Path) -> Path | None:
    for candidate in (path.with_name(path.name + ".json"), path.with_suffix(".json")):
        if candidate.is_file():
            return candidate
    return None


def _raw_for_sidecar(sidecar: Path) -> Path:
    name = sidecar.name
    if name.lower().endswith(tuple(ext + ".json" for ext in _RAW_EXTENSIONS)):
        candidates = [sidecar.with_name(name[: -len(".json")])]
    else:
        candidates = [sidecar.with_suffix(ext) for ext in _RAW_EXTENSIONS]
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    names = ", ".join(c.name for c in candidates)
    raise VolumeError(
        f"no raw data file for the sidecar {sidecar}: expected {names} beside it."
        " Pass the raw file, or a volume file of another supported type."
    )


def _read_sidecar(sidecar: Path) -> dict[str, Any]:
    try:
        text = read_json_text(sidecar)
        meta = parse_json_text(text)
    except OSError as exc:
        raise VolumeError(f"cannot read the sidecar {sidecar}: {exc.strerror or exc}.") from exc
    except (ValueError, RecursionError) as exc:
        raise VolumeError(
            f"the sidecar {sidecar} is not valid JSON ({exc}). It must be a JSON object like"
            ' {"dims": [nx, ny, nz], "dtype": "uint16", "spacing": [sx, sy, sz]}.'
        ) from exc
    if not isinstance(meta, dict):
        raise VolumeError(
            f"the sidecar {sidecar} must hold a JSON object with 'dims' and 'dtype';"
            f" got {type(meta).__name__}."
        )
    return meta


def _read_raw(path: Path, sidecar: Path) -> _Loaded:
    meta = _read_sidecar(sidecar)
    where = sidecar.name
    if "dims" not in meta or "dtype" not in meta:
        raise VolumeError(
            f"the sidecar {sidecar} needs 'dims' and 'dtype' (found keys {_short(sorted(meta))}),"
            ' e.g. {"dims": [nx, ny, nz], "dtype": "uint16", "spacing": [sx, sy, sz]}.'
        )
    dims = meta["dims"]
    if not (
        isinstance(dims, list)
        and len(dims) == 3
        and all(isinstance(d, int) and not isinstance(d, bool) and d > 0 for d in dims)
    ):
        raise VolumeError(
            f"'dims' in {where} must be three positive integers [nx, ny, nz]; got {_short(dims)}."
        )
    dtype_name = meta["dtype"]
    code = _RAW_DTYPES.get(dtype_name.strip().lower()) if isinstance(dtype_name, str) else None
    if code is None:
        raise VolumeError(
            f"unsupported dtype {_short(dtype_name)} in {where}; use one of {_RAW_DTYPE_TEXT}."
        )
    byte_order = meta.get("byte_order", "little")
    if not isinstance(byte_order, str) or byte_order not in ("little", "big"):
        raise VolumeError(
            f'\'byte_order\' in {where} must be "little" or "big"; got {_short(byte_order)}.'
        )
    dtype = np.dtype(("<" if byte_order == "little" else ">") + code)
    header = meta.get("header_bytes", 0)
    if not (isinstance(header, int) and not isinstance(header, bool) and header >= 0):
        raise VolumeError(
            f"'header_bytes' in {where} must be a non-negative integer; got {_short(header)}."
        )
    spacing = (
        _json_triple(meta["spacing"], "spacing", where, positive=True)
        if "spacing" in meta
        else None
    )
    origin = (
        _json_triple(meta["origin"], "origin", where, positive=False) if "origin" in meta else None
    )
    units = meta.get("units", "")
    if not isinstance(units, str):
        raise VolumeError(f"'units' in {where} must be a string; got {_short(units)}.")

    count = dims[0] * dims[1] * dims[2]
    expected = header + count * dtype.itemsize
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise VolumeError(f"cannot read {path}: {exc.strerror or exc}.") from exc
    header_text = f" after {header} header bytes" if header else ""
    if size < expected:
        raise VolumeError(
            f"{path.name} is too short: expected {expected} bytes for dims {dims} dtype"
            f" {dtype_name}{header_text}, file has {size} bytes. Fix 'dims', 'dtype' or"
            f" 'header_bytes' in {where}, or the file is truncated."
        )
    if size > expected:
        _warn(
            f"{path.name} has {size} bytes, more than the {expected} expected for dims {dims}"
            f" dtype {dtype_name}{header_text}; the extra {size - expected} bytes are ignored."
            f" Check 'dims', 'dtype' and 'header_bytes' in {where}."
        )
    _limits.check_load_bytes(dims, dtype.itemsize, path.name)
    try:
        flat = np.fromfile(path, dtype=dtype, count=count, offset=header)
    except (OSError, ValueError) as exc:
        raise VolumeError(f"cannot read {path}: {exc}.") from exc
    if flat.size != count:  # the file changed under us
        raise VolumeError(f"{path.name}: read {flat.size} voxels, expected {count}.")
    data = _native(flat).reshape(tuple(dims), order="F")
    loaded = _Loaded(data, spacing, origin, units)
    _stated_affine(loaded, meta.get("affine"), meta.get("space", "RAS"), where)
    return loaded


def _stated_affine(loaded: _Loaded, affine: Any, space: Any, where: str) -> None:
    """Give ``loaded`` the ``affine`` (in patient ``space``) a sidecar or .npz states."""
    if affine is None:
        return
    if loaded.spacing is not None or loaded.origin is not None:
        raise VolumeError(
            f"{where} states both an 'affine' and 'spacing'/'origin'; keep only the affine"
            " (it holds both)."
        )
    loaded.affine = _to_ras(checked_affine(affine, where), space, f"'space' in {where}")
    loaded.space = "RAS"


# ---------------------------------------------------------------------------- NRRD
def _check_nrrd_budget(path: Path) -> None:
    """Check the ``sizes`` and ``type`` of an NRRD header against the memory budget
    before ``nrrd.read`` reads the voxels; a header it cannot parse is left to it."""
    import nrrd

    try:
        with open(path, "rb") as f:
            header = nrrd.read_header(f)
        sizes = [int(n) for n in header["sizes"]]
    except Exception:
        return
    try:
        from nrrd.reader import _determine_datatype

        itemsize = int(_determine_datatype(header).itemsize)
    except Exception:
        itemsize = 1
    _limits.check_load_bytes(sizes, itemsize, path.name)


def _check_nrrd_directions(dirs: np.ndarray, path: Path) -> None:
    """Refuse ``space directions`` rows that are partly not finite (a whole row of NaN is
    pynrrd's ``none``: a non-spatial axis; a NaN or inf inside a vector is damage that
    would otherwise drop the orientation without a word)."""
    finite = np.isfinite(dirs)
    bad = np.any(finite, axis=1) & ~np.all(finite, axis=1)
    if np.any(bad):
        row = int(np.argmax(bad))
        raise VolumeError(
            f"{path}: 'space directions' vector {row + 1} is {tuple(dirs[row].tolist())};"
            " each must be three finite numbers (or 'none' for a non-spatial axis): fix the"
            " header"
        )


def _read_nrrd(path: Path) -> _Loaded:
    import nrrd

    _check_nrrd_data_files(path)  # before nrrd.read opens a detached data file
    _check_nrrd_budget(path)
    try:
        data, header = nrrd.read(str(path), index_order="F")
        data = np.asarray(data)
    except Exception as exc:
        raise VolumeError(
            f"cannot read the NRRD file {path} ({type(exc).__name__}: {exc})."
            " The file may be corrupt or its header invalid."
        ) from exc
    where = path.name
    try:
        dirs = header.get("space directions")
        dirs = None if dirs is None else np.asarray(dirs, dtype=np.float64)
        spacings = header.get("spacings")
        spacings = None if spacings is None else np.asarray(spacings, dtype=np.float64)
        space_origin = header.get("space origin")
        space_origin = None if space_origin is None else np.asarray(space_origin, np.float64)
    except (TypeError, ValueError) as exc:
        raise VolumeError(f"invalid geometry in the NRRD header of {path}: {exc}.") from exc
    if dirs is not None and (dirs.ndim != 2 or dirs.shape[0] != data.ndim):
        dirs = None
    if dirs is not None:
        _check_nrrd_directions(dirs, path)

    spatial = nrrd_spatial_axes(header, dirs, data.ndim)
    extra: tuple[_frames.ExtraAxis, ...] = ()
    field = ""
    if data.ndim != 3:
        if len(spatial) != 3:
            raise VolumeError(
                f"{path} is a {data.ndim}D NRRD with sizes {list(data.shape)} whose header"
                " does not say which 3 axes are spatial; give the others a 'kinds' entry"
                " (list, vector, time) or a 'none' space direction."
            )
        data, extra, field = nrrd_extra(data, header, spatial)

    scale = 1.0
    units_field = header.get("space units")
    if isinstance(units_field, list) and units_field and len(set(units_field)) == 1:
        scale = _unit_scale(units_field[0], where)
    units = header.get("voxwarp_units", "")
    units = units if isinstance(units, str) else ""
    origin = None
    if space_origin is not None and space_origin.size == 3 and np.all(np.isfinite(space_origin)):
        origin = np.asarray(_triple(space_origin, "space origin", where=where)) * scale
    if dirs is not None and len(spatial) == 3:
        affine = np.eye(4)
        affine[:3, :3] = dirs[spatial].T * scale  # rows of space directions are axes
        if origin is not None:
            affine[:3, 3] = origin
        affine = checked_affine(affine, where, f"the geometry (space directions) of {where}")
        space = _nrrd_space(header, where)
        ras = _to_ras(affine, space, where) if space is not None else affine
        return _Loaded(
            data,
            units=units,
            affine=ras,
            space="" if space is None else "RAS",
            extra=extra,
            vector_field=field,
        )
    spacing = None
    if spacings is not None:
        finite = spacings[np.isfinite(spacings)]
        if finite.size == 3:
            spacing = _triple(finite * scale, "spacing", positive=True, where=where)
        else:
            _warn(
                f"{where}: 'spacings' {spacings.tolist()} does not give a finite spacing for"
                " each of the 3 axes; spacing treated as not stated (1 mm assumed). Fix the"
                " header or pass --spacing SX SY SZ."
            )
    origin_t = None if origin is None else tuple(origin)
    return _Loaded(data, spacing, origin_t, units, extra=extra, vector_field=field)


#: Environment variable with more allowed folders (``os.pathsep``-separated), for the CLI.
NRRD_DATA_DIRS_ENV = ALLOW_DIRS_ENV
#: Most bytes of a detached header read to find its ``data file`` field.
_NRRD_HEADER_SCAN_BYTES = 1 << 20
#: Allow detached data files under more folders while a block runs (``load_volume``'s
#: ``allow_data_dirs=``); the same as :func:`voxwarp.core.allowed_folders.allowed_folders`.
allowed_data_dirs = allowed_folders


def _nrrd_data_names(path: Path) -> tuple[str, list[str]]:
    """``(field value, file names)`` of the ``data file`` / ``datafile`` field of the NRRD
    header ``path`` (``("", [])`` when the data is attached). Covers the three forms of the
    NRRD spec: one name, ``LIST`` (the names follow, one a line) and ``<format> <min>
    <max> <step> [<subdim>]`` (the format's folder counts). The literal value is always
    among the names, since pynrrd opens it as a file name."""
    try:
        with open(path, "rb") as fh:
            raw = fh.read(_NRRD_HEADER_SCAN_BYTES)
    except OSError as exc:
        raise VolumeError(f"cannot read the NRRD file {path}: {exc}") from exc
    lines = raw.decode("ascii", "ignore").splitlines()
    for n, line in enumerate(lines[1:], start=1):
        line = line.rstrip()
        if line == "":
            break  # end of the header
        if line.startswith("#"):
            continue
        field, sep, value = line.partition(":")
        if not sep or field.strip() not in ("data file", "datafile"):
            continue
        value = value.lstrip("=").strip()
        names = [value]
        parts = value.split()
        if parts and parts[0] == "LIST":
            names += [x.strip() for x in lines[n + 1 :] if x.strip()]
        elif len(parts) >= 4 and "%" in parts[0]:
            names.append(parts[0])
        return value, names
    return "", []


def data_file_outside(header: Path, name: str) -> Path | None:
    """The data file ``name`` a detached header names, resolved, when it lies outside the
    header's folder (and subfolders) and the allowed folders
    (:mod:`voxwarp.core.allowed_folders`); ``None`` when reading it is allowed."""
    home = header.parent.resolve()
    target = (home / os.path.expanduser(name)).resolve()  # absolute names stay as they are
    return target if outside_allowed(target, home) else None


def _check_nrrd_data_files(path: Path) -> None:
    """Refuse a detached NRRD data file outside the header's folder (and its subfolders)
    and the folders allowed by ``allow_data_dirs=`` / ``$VOXWARP_ALLOW_DATA_DIRS``: a
    header must not make voxwarp read ``/etc/passwd`` or ``../../secret`` as voxels."""
    value, names = _nrrd_data_names(path)
    if not names:
        return
    for name in names:
        if "\x00" in name:
            raise VolumeError(
                f"the NRRD header {path} names a data file with a NUL byte ({name!r});"
                " fix the 'data file' line of the header"
            )
        target = data_file_outside(path, name)
        if target is not None:
            shown = name if str(target) == name else f"{name} ({target})"
            raise VolumeError(
                f"the NRRD header {path} names the data file {shown}, outside the header's"
                " folder; voxwarp reads detached data only beside the header or in"
                " its subfolders: move the data file there, or allow its folder (pass"
                f" --allow-dir {target.parent}, load_volume(..., allow_data_dirs=[...]) or"
                f" set {NRRD_DATA_DIRS_ENV}={target.parent})"
            )
        if "%" not in name and not name.startswith("LIST"):
            home = path.parent.resolve()
            check_regular(home / os.path.expanduser(name), f"{path.name}'s data file", VolumeError)
    if value.split()[:1] == ["LIST"]:
        raise VolumeError(
            f"the NRRD header {path} spreads its data over several files (data file: LIST),"
            " which voxwarp's NRRD reader (pynrrd) cannot read; join the slices into one"
            " data file and name it in the header"
        )


#: NRRD ``space`` values with a patient orientation -> the patient space of the header.
_NRRD_SPACES = {
    "right-anterior-superior": "RAS",
    "ras": "RAS",
    "left-posterior-superior": "LPS",
    "lps": "LPS",
    "left-anterior-superior": "LAS",
    "las": "LAS",
}


def _nrrd_space(header: dict[str, Any], where: str) -> str | None:
    """The patient space of the header (RAS, LPS, LAS), or ``None`` for scanner-xyz,
    3D-right-handed, 3D-left-handed or no ``space`` (geometry without orientation)."""
    space = header.get("space")
    if not isinstance(space, str) or header.get(NOT_ORIENTED_KEY) == "false":
        return None
    return _NRRD_SPACES.get(space.strip().lower().removesuffix("-time"))


# ---------------------------------------------------------------------------- NIfTI
def _read_nifti(path: Path, pick: _frames.Pick | None = None) -> _Loaded:
    import nibabel as nib

    with quiet_nibabel() as said:  # nibabel's log lines become one warning each
        try:
            img = nib.load(str(path))
        except Exception as exc:
            raise VolumeError(
                f"cannot read the NIfTI file {path} ({type(exc).__name__}: {exc})."
                " The file may be corrupt or not a NIfTI/Analyze image."
            ) from exc
        loaded = _nibabel_loaded(img, path.name, "NIfTI", pick)
    for line in said:
        _warn(f"{path.name}: {line} (nibabel); fix the header")
    return loaded


def _nibabel_loaded(img: Any, short: str, kind: str, pick: _frames.Pick | None) -> _Loaded:
    """The voxels (index order as stored) and geometry of a nibabel image: for NIfTI the
    sform, else the qform (an in-memory ``img.affine`` that differs from both wins); for
    other formats with an affine (MGH) that affine, in RAS; Analyze has none. Of a 4-D/5-D
    image only the frame/channel ``pick`` names is read (:mod:`voxwarp.io.frame_axes`)."""
    full = tuple(int(s) for s in img.shape)
    shape = full
    while len(shape) > 5 and shape[-1] == 1:
        shape = shape[:-1]
    if len(shape) < 3:
        raise VolumeError(
            f"{short} is a {len(shape)}D image with shape {shape}; voxwarp needs a 3D volume."
        )
    axes, field = nifti_extra_axes(img, shape)
    indices = _frames.choose(axes, pick or _frames.Pick(), short, shape, vector_field=field)
    slicer = (slice(None),) * 3 + indices + (0,) * (len(full) - len(shape))
    shape = shape[:3]
    _limits.check_load_bytes(shape, _nifti_itemsize(img), short)
    try:
        proxy = img.dataobj
        if hasattr(proxy, "_get_unscaled"):  # reads only the chosen frame
            raw = np.asarray(proxy._get_unscaled(slicer))
            slope = float(getattr(proxy, "slope", 1.0))
            inter = float(getattr(proxy, "inter", 0.0))
        elif hasattr(proxy, "get_unscaled"):
            raw = np.asarray(proxy.get_unscaled())[slicer]
            slope = float(getattr(proxy, "slope", 1.0))
            inter = float(getattr(proxy, "inter", 0.0))
        else:
            raw, slope, inter = np.asanyarray(proxy)[slicer], 1.0, 0.0
        hdr = img.header
        zooms = tuple(float(z) for z in hdr.get_zooms()[:3])
        affine = _nibabel_affine(img, short)
        space_unit = hdr.get_xyzt_units()[0] if hasattr(hdr, "get_xyzt_units") else "mm"
    except Exception as exc:
        raise VolumeError(
            f"cannot read the voxel data of {short} ({kind} image; {type(exc).__name__}: {exc});"
            " the file may be truncated or corrupt."
        ) from exc
    data = np.asarray(raw).reshape(shape, order="F") if raw.ndim != 3 else np.asarray(raw)
    if not (math.isfinite(slope) and math.isfinite(inter)):
        slope, inter = 1.0, 0.0
    if slope != 1.0 or inter != 0.0:
        data = rescale(data, slope, inter)

    scale = _unit_scale(space_unit, short)
    if affine is not None:
        affine[:3, :] *= scale
        return _Loaded(data, affine=affine, space="RAS", picked=True)
    spacing = _triple(zooms, "voxel size (pixdim)", positive=True, where=short)
    return _Loaded(data, tuple(s * scale for s in spacing), picked=True)  # type: ignore[arg-type]


def _nibabel_affine(img: Any, where: str) -> np.ndarray | None:
    """The RAS index -> world affine of a nibabel image, or ``None`` (no orientation)."""
    hdr = img.header
    if hasattr(hdr, "get_sform"):  # NIfTI: the codes say whether there is one
        stated = getattr(img, "affine", None)
        if stated is not None and not np.allclose(stated, hdr.get_best_affine()):
            return checked_affine(stated, where, f"the affine of {where}")  # set in memory
        return _nifti_affine(hdr, where)
    from nibabel.analyze import AnalyzeHeader

    if isinstance(hdr, AnalyzeHeader) or getattr(img, "affine", None) is None:
        return None  # Analyze states no patient orientation
    return checked_affine(img.affine, where, f"the affine of {where}")


def _nifti_itemsize(img: Any) -> int:
    """Bytes per voxel of ``img`` as stored (its header's dtype)."""
    try:
        return int(img.get_data_dtype().itemsize)
    except Exception:
        return 1


def _nifti_affine(hdr: Any, where: str) -> np.ndarray | None:
    """The sform when its code is set, else the qform when its code is set (nibabel's
    ``get_best_affine`` precedence); ``None`` for neither, or for Analyze headers: such a
    file has no patient orientation. A coded transform that is not finite or not
    invertible is passed over with a warning."""
    if not hasattr(hdr, "get_sform"):
        return None
    for name in ("sform", "qform"):
        try:
            affine, code = getattr(hdr, f"get_{name}")(coded=True)
        except ValueError as exc:  # e.g. a qform quaternion that is no rotation
            _warn(f"{where}: the {name} cannot be read ({exc}); ignored. Fix the header.")
            continue
        if not code or affine is None:
            continue
        a = np.asarray(affine, dtype=np.float64)
        if np.all(np.isfinite(a)) and abs(np.linalg.det(a[:3, :3])) > 1e-12:
            if name == "sform":
                _warn_if_qform_differs(hdr, a, where)
            return a
        _warn(
            f"{where}: the {name} (code {int(code)}) is not a finite, invertible matrix;"
            " ignored. Fix the header (e.g. nibabel's set_sform) for a patient orientation."
        )
    return None


#: corner distance (mm) from which a coded qform that differs from the sform is reported
FORMS_DISAGREE_MM = 0.01


def _warn_if_qform_differs(hdr: Any, sform: np.ndarray, where: str) -> None:
    """Warn when a NIfTI also codes a qform that puts the volume's corners elsewhere
    than its sform does: voxwarp (as nibabel) takes the sform, ITK-based tools may take
    the qform, so the two would show the patient differently."""
    try:
        qform, code = hdr.get_qform(coded=True)
    except ValueError:
        return
    if not code or qform is None or not np.all(np.isfinite(qform)):
        return
    shape = np.asarray(hdr.get_data_shape()[:3], dtype=np.float64) - 1.0
    corners = np.array([[i, j, k, 1.0] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    corners[:, :3] *= shape
    far = float(np.max(np.linalg.norm((corners @ (sform - qform).T)[:, :3], axis=1)))
    if far > FORMS_DISAGREE_MM:
        _warn(
            f"{where}: the sform and the qform (both coded) place the volume up to"
            f" {far:.3g} mm apart; voxwarp uses the sform, as nibabel does (ITK-based tools"
            " may use the qform): check the patient orientation, or fix the header"
        )


# ---------------------------------------------------------------------------- folders
def _list_files(directory: Path) -> list[Path]:
    """Visible files directly inside ``directory``, in natural name order."""
    try:
        return sorted(
            (p for p in directory.iterdir() if p.is_file() and not p.name.startswith(".")),
            key=lambda p: _natural_key(p.name),
        )
    except OSError as exc:
        raise VolumeError(f"cannot list the folder {directory}: {exc.strerror or exc}.") from exc


def dicom_series(path: str | os.PathLike[str]) -> list[Any]:
    """The DICOM series in a folder (``SeriesInfo``, largest first); empty otherwise."""
    folder = Path(os.path.abspath(os.path.expanduser(os.fspath(path))))
    if not folder.is_dir():
        return []
    files = [p for p in _list_files(folder) if not p.name.lower().endswith(_TIFF_EXTENSIONS)]
    return list_dicom_series(folder, files)


def _read_directory(directory: Path, series: str | int | None = None) -> _Loaded:
    entries = _list_files(directory)
    tiffs = [p for p in entries if p.name.lower().endswith(_TIFF_EXTENSIONS)]
    others = [p for p in entries if not p.name.lower().endswith(_TIFF_EXTENSIONS)]
    loaded = read_dicom_dir(directory, others, series)
    if loaded is not None:
        return loaded
    if series is not None:
        raise VolumeError(f"series= needs a folder of DICOM files; {directory} holds none.")
    if tiffs:
        return _read_tiff_dir(directory, tiffs)
    raise VolumeError(
        f"no DICOM files in {directory}; voxwarp reads a folder of DICOM slices (one image"
        " per file, any file names, directly inside the folder) or of TIFF slices (.tif/.tiff)."
        f" Pass the folder holding the series, or a volume file: {_SUPPORTED_TEXT}."
    )


# ---------------------------------------------------------------------------- TIFF
def _tiff_geometry(tif: Any, where: str) -> tuple[tuple | None, tuple | None, str]:
    """Spacing, origin (mm) and value unit from ImageJ metadata; ``None`` when absent."""
    meta = tif.imagej_metadata
    if not meta:
        return None, None, ""
    scale = _unit_scale(meta.get("unit", ""), where)
    page = tif.pages[0]
    xy = []
    for tag_name in ("XResolution", "YResolution"):
        tag = page.tags.get(tag_name)
        value = 1.0
        if tag is not None:
            try:
                num, den = tag.value
                if num > 0 and den > 0:
                    value = den / num
            except (TypeError, ValueError):
                pass
        xy.append(value)
    z = meta.get("spacing", 1.0)
    z = float(z) if _is_number(z) and z > 0 and math.isfinite(z) else 1.0
    spacing = (xy[0] * scale, xy[1] * scale, z * scale)
    origin_px = []
    for key in ("xorigin", "yorigin", "zorigin"):
        value = meta.get(key, 0.0)
        origin_px.append(float(value) if _is_number(value) and math.isfinite(value) else 0.0)
    origin = tuple(-o * s for o, s in zip(origin_px, spacing, strict=True))
    units = meta.get("vunit", "")
    return spacing, origin, units if isinstance(units, str) else ""


def _tiff_to_zyx(data: np.ndarray, axes: str, path: Path) -> np.ndarray:
    """Reduce a tifffile series to a ``(z, y, x)`` stack, or explain why not."""
    keep = [i for i, a in enumerate(axes) if a in "YX" or data.shape[i] != 1]
    squeezed = np.squeeze(data, axis=tuple(i for i in range(data.ndim) if i not in keep))
    axes = "".join(axes[i] for i in keep)
    if axes == "YX":
        return squeezed[None]
    if len(axes) == 3 and axes[1:] == "YX" and axes[0] not in "CS":
        return squeezed
    raise VolumeError(
        f"{path} holds images with axes {axes!r} and shape {squeezed.shape}; voxwarp reads a"
        " grayscale z-stack (pages of 2D images). Split channels, colours or time points into"
        " separate single-channel stacks first."
    )


def _tiff_stack(tif: Any, path: Path) -> np.ndarray:
    """Every image of an open TIFF file as one ``(z, y, x)`` stack, whatever its layout.

    A file whose pages form one series (an ImageJ hyperstack, a stack written in one
    call, pages of one size without metadata) reads through that series, so ImageJ's
    axes hold. Otherwise (a stack written page by page, where each page is its own
    series; pages of different kinds; a series that misses pages) every page in file
    order is a slice; reduced-resolution pages (thumbnails) are skipped. Pages must
    share size and type: the first that does not is named.
    """
    series = tif.series
    if not series:
        raise VolumeError(f"{path} holds no images; voxwarp reads a grayscale z-stack.")
    pages = [p for p in tif.pages if not getattr(p, "is_reduced", False)]
    first = series[0]
    if len(series) == 1 and (tif.is_imagej or len(first.pages) >= len(pages)):
        _limits.check_load_bytes(first.shape, first.dtype.itemsize, path.name)
        return _tiff_to_zyx(np.asarray(first.asarray()), first.axes, path)
    return _tiff_pages(pages, path)


def _tiff_pages(pages: list[Any], path: Path) -> np.ndarray:
    """Every page of a TIFF file in file order as one ``(z, y, x)`` stack."""
    try:  # the pages' size as their tags state it (a page that has none reads as 0)
        voxels, itemsize = sum(math.prod(p.shape) for p in pages), pages[0].dtype.itemsize
    except (AttributeError, TypeError, ValueError):
        voxels, itemsize = 0, 1
    _limits.check_load_bytes((voxels,), itemsize, path.name)
    out: np.ndarray | None = None
    count = 0
    for index, page in enumerate(pages):
        page = page.aspage() if hasattr(page, "aspage") else page
        image = _tiff_to_zyx(np.asarray(page.asarray()), page.axes, path)
        if out is None:
            out = np.empty((len(pages) * image.shape[0], *image.shape[1:]), image.dtype)
        elif image.shape[1:] != out.shape[1:] or image.dtype != out.dtype:
            raise VolumeError(
                f"page {index + 1} of {path.name} is {image.shape[2]}x{image.shape[1]} pixels"
                f" of {image.dtype} but page 1 is {out.shape[2]}x{out.shape[1]} of {out.dtype};"
                " all pages of a TIFF z-stack must have the same size and type. Crop or"
                " convert the odd pages, or save them as a separate file."
            )
        end = count + image.shape[0]
        if end > out.shape[0]:  # a page holding several planes: grow the stack
            grown = np.empty((end, *out.shape[1:]), out.dtype)
            grown[:count] = out[:count]
            out = grown
        out[count:end] = image
        count = end
    if out is None:
        raise VolumeError(f"{path} holds only reduced-resolution images (thumbnails).")
    return out[:count]


def _read_tiff_file(path: Path) -> _Loaded:
    import tifffile

    extra: tuple[_frames.ExtraAxis, ...] = ()
    try:
        with tifffile.TiffFile(path) as tif:
            first = tif.series[0] if len(tif.series) == 1 else None
            if first is not None and any(a in "TCS" for a in first.axes):
                _limits.check_load_bytes(first.shape, first.dtype.itemsize, path.name)
                data, extra = tiff_extra(np.asarray(first.asarray()), first.axes, path.name)
                data = _tiff_to_zyx(data, first.axes, path) if not extra else data
            else:
                data = _tiff_stack(tif, path)
            spacing, origin, units = _tiff_geometry(tif, path.name)
    except VolumeError:
        raise
    except Exception as exc:
        raise VolumeError(
            f"cannot read the TIFF file {path} ({type(exc).__name__}: {exc})."
            " The file may be corrupt or not a TIFF image."
        ) from exc
    order = [2, 1, 0, *range(3, data.ndim)]
    return _Loaded(data.transpose(order), spacing, origin, units, extra=extra)


def _read_tiff_dir(directory: Path, files: list[Path]) -> _Loaded:
    import tifffile

    slices = []
    geometry: tuple = (None, None, "")
    for index, p in enumerate(files):
        try:
            with tifffile.TiffFile(p) as tif:
                image = _tiff_stack(tif, p)
                if index == 0:
                    geometry = _tiff_geometry(tif, p.name)
                    size = image.dtype.itemsize
                    _limits.check_load_bytes((*image.shape, len(files)), size, directory.name)
        except VolumeError:
            raise
        except Exception as exc:
            raise VolumeError(
                f"cannot read the TIFF slice {p} ({type(exc).__name__}: {exc})."
                " Remove it from the folder or replace it."
            ) from exc
        if image.shape[0] != 1:
            raise VolumeError(
                f"{p} holds {image.shape[0]} pages; a folder of TIFF slices needs one 2D image"
                " per file. Load the multi-page file on its own instead."
            )
        if slices and image.shape != slices[0].shape:
            raise VolumeError(
                f"{p.name} is {image.shape[2]}x{image.shape[1]} pixels but {files[0].name} is"
                f" {slices[0].shape[2]}x{slices[0].shape[1]}; all TIFF slices must have the"
                " same size."
            )
        slices.append(image)
    stack = np.concatenate(slices, axis=0)  # (z, y, x)
    spacing, origin, units = geometry
    return _Loaded(stack.transpose(2, 1, 0), spacing, origin, units)


# ---------------------------------------------------------------------------- saving
def save_volume(volume: Volume, path: str | os.PathLike[str], *, format: str | None = None) -> Path:
    """Write ``volume`` to ``path`` atomically.

    Parameters
    ----------
    volume
        The volume to write.
    path
        Destination. Its extension picks the format unless ``format`` is given; with
        ``format`` and no extension, the format's extension is appended. Missing parent
        folders are created.
    format
        One of ``"npz"``, ``"raw"`` (plus a ``.raw.json`` sidecar), ``"nrrd"``,
        ``"nii"``, ``"nii.gz"`` or ``"tif"`` (ImageJ-calibrated multi-page TIFF).

    Returns
    -------
    Path
        The path of the data file written (for ``raw``, the sidecar is that path plus
        ``.json``).

    Raises
    ------
    VolumeError
        For an unknown format or an extension that contradicts ``format``.
    OutputError
        For a file that cannot be written (disk full, read-only, permission): one
        line naming the path and the cause; no partial or temporary file is left.

    Notes
    -----
    Every file is written to a temporary name in the destination folder and then
    renamed over the destination with :func:`os.replace`, so readers never see a
    partial file. NIfTI stores spacing and origin as float32; the other formats keep
    them exactly. Value units are kept by ``npz``, ``raw``, ``nrrd`` and ``tif``.
    """
    if not isinstance(volume, Volume):
        raise VolumeError(f"save_volume needs a Volume; got {type(volume).__name__}.")
    try:
        target = Path(os.path.expanduser(os.fspath(path)))
    except TypeError as exc:
        raise VolumeError(f"invalid path {_short(path)}: {exc}") from exc
    detected = _format_from_name(target.name)
    if format is None:
        if detected is None:
            raise VolumeError(
                f"cannot tell the format of {target} from its extension; use one of"
                " .npz, .raw, .nrrd, .nii, .nii.gz, .tif (or pass format=...)."
            )
        fmt = detected
    else:
        fmt = "tif" if format == "tiff" else format
        if not isinstance(fmt, str) or fmt not in SAVE_FORMATS:
            raise VolumeError(
                f"unknown format {_short(format)}; use one of {', '.join(SAVE_FORMATS)}."
            )
        if detected is None and not target.suffix:
            target = target.with_name(target.name + SAVE_FORMATS[fmt])
        elif detected is not None and detected != fmt:
            raise VolumeError(
                f"the extension of {target.name} does not match format {fmt!r}; use a"
                f" {SAVE_FORMATS[fmt]} file name or drop the extension."
            )
    target = Path(os.path.abspath(target))
    # a failed write raises OutputError (one line: path and cause) and leaves no file
    if fmt == "raw":
        _save_raw(volume, target)
    else:
        writer = {
            "npz": _write_npz,
            "nrrd": _write_nrrd,
            "nii": _write_nifti,
            "nii.gz": _write_nifti,
            "tif": _write_tiff,
        }[fmt]
        with _atomic_output(target, SAVE_FORMATS[fmt]) as tmp:
            writer(volume, tmp)
    return target


def _format_from_name(name: str) -> str | None:
    lower = name.lower()
    if lower.endswith(".nii.gz"):
        return "nii.gz"
    for fmt, extensions in (
        ("npz", (".npz",)),
        ("raw", (".raw", ".bin")),
        ("nrrd", (".nrrd",)),
        ("nii", (".nii",)),
        ("tif", (".tif", ".tiff")),
    ):
        if lower.endswith(extensions):
            return fmt
    return None


def _write_npz(volume: Volume, tmp: Path) -> None:
    with open(tmp, "xb") as f:
        np.savez_compressed(
            f,
            data=volume.data,
            units=np.array(volume.units),
            **_npz_geometry(volume),
        )


def _oriented(volume: Volume) -> bool:
    """Whether the geometry needs a full affine (a patient orientation or a rotation)."""
    return bool(volume.space) or volume.is_oblique


def _npz_geometry(volume: Volume) -> dict[str, np.ndarray]:
    if _oriented(volume):
        return {"affine": volume.affine, "space": np.array(volume.space or "RAS")}
    return {
        "spacing": np.asarray(volume.spacing, dtype=np.float64),
        "origin": np.asarray(volume.origin, dtype=np.float64),
    }


def _save_raw(volume: Volume, final: Path) -> None:
    sidecar = final.with_name(final.name + ".json")
    meta = {
        "dims": list(volume.shape),
        "dtype": volume.dtype.name,
        "byte_order": "little",
        "header_bytes": 0,
        "units": volume.units,
    }
    if _oriented(volume):
        meta.update(affine=volume.affine.tolist(), space=volume.space or "RAS")
    else:
        meta.update(spacing=list(volume.spacing), origin=list(volume.origin))
    data = volume.data.astype(volume.dtype.newbyteorder("<"), copy=False)
    # both files are complete before either is renamed (the data first, then its sidecar)
    with _atomic_open(sidecar, "w", suffix=".json") as side:
        json.dump(meta, side, indent=2)
        side.write("\n")
        side.flush()
        os.fsync(side.fileno())
        with _atomic_open(final, "wb", suffix=".raw") as f:
            # C order of (z, y, x): x fastest; a file write (not tofile) keeps the errno
            f.write(np.ascontiguousarray(data.T).reshape(-1).view(np.uint8).data)


def _write_nrrd(volume: Volume, tmp: Path) -> None:
    import nrrd

    # always a space (ITK and Slicer read a NRRD without one as LPS, 180 degrees from the
    # NIfTI); a volume without patient orientation is marked so it reads back as one
    header: dict[str, Any] = {
        "space": "right-anterior-superior",
        "space directions": volume.affine[:3, :3].T,
        "space origin": np.asarray(volume.origin, dtype=np.float64),
        "space units": ["mm", "mm", "mm"],
        "kinds": ["domain", "domain", "domain"],
        "encoding": "gzip",
    }
    if not volume.space:
        header[NOT_ORIENTED_KEY] = "false"
    if volume.units:
        header["voxwarp_units"] = volume.units
    nrrd.write(str(tmp), np.asarray(volume.data), header, index_order="F")


def _write_nifti(volume: Volume, tmp: Path) -> None:
    import nibabel as nib

    img = nib.Nifti1Image(np.asarray(volume.data), volume.affine)
    code = 1 if volume.space else 2  # scanner (patient) space, or "aligned" to something
    img.set_sform(volume.affine, code=code)
    img.set_qform(volume.affine, code=code)
    img.header.set_xyzt_units("mm")
    nib.save(img, str(tmp))


def _write_tiff(volume: Volume, tmp: Path) -> None:
    import tifffile

    if _oriented(volume):
        _warn(
            f"TIFF stores no patient orientation; {volume.name} keeps spacing and origin only"
            " (save as .nii.gz or .nrrd to keep the orientation)."
        )
    sx, sy, sz = volume.spacing
    ox, oy, oz = volume.origin
    metadata: dict[str, Any] = {
        "axes": "ZYX",
        "spacing": sz,
        "unit": "mm",
        "xorigin": -ox / sx,
        "yorigin": -oy / sy,
        "zorigin": -oz / sz,
    }
    if volume.units:
        metadata["vunit"] = volume.units
    tifffile.imwrite(
        tmp,
        volume.texture_array(),  # (z, y, x)
        imagej=True,
        resolution=(1.0 / sx, 1.0 / sy),
        metadata=metadata,
    )


# ---------------------------------------------------------------------------- info
def volume_info(volume: Volume) -> dict[str, Any]:
    """Numbers describing ``volume``, JSON-serialisable (``voxwarp info --json``).

    Parameters
    ----------
    volume
        The volume to describe.

    Returns
    -------
    dict
        Keys ``name``, ``source``, ``dims`` ``[nx, ny, nz]``, ``voxels``, ``dtype``,
        ``units``, ``spacing_mm``, ``spacing_source`` (file, given or assumed),
        ``origin_mm``, ``orientation`` (axis code of the stored axes, ``None`` without a
        patient orientation), ``file_axes`` (the file's axis code), ``world``,
        ``oblique_deg``, ``affine`` (4x4 index -> world), ``modality``,
        ``padding_value``, ``size_mm``, ``memory_mb``, ``min``,
        ``max``, ``mean``, ``std``, ``nonfinite`` (count of NaN/Inf voxels, left out of
        the statistics), ``percentiles`` (``{"1": ..., "5": ..., "50": ..., "95": ...,
        "99": ...}``, from an evenly strided sample above 2**24 voxels),
        ``percentiles_sampled`` and ``histogram`` (``{"edges": [17 floats], "counts":
        [16 ints]}`` over ``[min, max]``). Every value is a plain Python number,
        string, list, dict or ``None``.
    """
    data = volume.data
    flat = data.ravel(order="K")
    if data.dtype.kind == "f":
        finite_mask = np.isfinite(flat)
        nonfinite = int(flat.size - np.count_nonzero(finite_mask))
        values = flat[finite_mask] if nonfinite else flat
    else:
        nonfinite, values = 0, flat
    if values.size:
        lo, hi = float(values.min()), float(values.max())
        mean = float(values.mean(dtype=np.float64))
        std = float(values.std(dtype=np.float64))
        step = max(1, values.size // _STATS_SAMPLE_VOXELS)
        sample = values[::step]
        if sample.dtype.kind == "f" and max(abs(lo), abs(hi)) > 1e37:
            sample = sample.astype(np.float64)  # float32 interpolation would overflow
        pct = np.percentile(sample, _PERCENTILES)
        percentiles = {str(p): float(v) for p, v in zip(_PERCENTILES, pct, strict=True)}
        counts, edges = _histogram(values, lo, hi)
    else:
        lo = hi = mean = std = 0.0
        step = 1
        percentiles = {str(p): 0.0 for p in _PERCENTILES}
        counts, edges = np.zeros(_HIST_BINS, dtype=int), np.zeros(_HIST_BINS + 1)
    return {
        "name": volume.name,
        "source": volume.source,
        "dims": list(volume.shape),
        "voxels": int(data.size),
        "dtype": str(volume.dtype),
        "units": volume.units,
        "spacing_mm": [float(s) for s in volume.spacing],
        "spacing_source": volume.spacing_source,
        "origin_mm": [float(o) for o in volume.origin],
        "orientation": volume.orientation or None,
        "file_axes": volume.file_axes or None,
        "world": "RAS+ mm" if volume.space else "index axes along +x, +y, +z (no orientation)",
        "oblique_deg": volume.obliquity,
        "affine": volume.affine.tolist(),
        "modality": volume.modality or None,
        "padding_value": volume.padding_value,
        "size_mm": [float(s) for s in volume.size_mm],
        "memory_mb": volume.nbytes / 2**20,
        "min": lo,
        "max": hi,
        "mean": mean,
        "std": std,
        "nonfinite": nonfinite,
        "percentiles": percentiles,
        "percentiles_sampled": step > 1,
        "histogram": {
            "edges": [float(e) for e in edges],
            "counts": [int(c) for c in counts],
        },
    }


#: Values per chunk of :func:`_histogram` (bounds its float64 temporaries to 32 MiB).
_HIST_CHUNK = 1 << 22


def _histogram(values: np.ndarray, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
    """Counts and edges of :data:`_HIST_BINS` equal bins over ``[lo, hi]``, in float64
    chunk by chunk: any finite range works, float32 values near +-3.4e38 (whose range
    overflows float32) and a constant volume of large values (edges ``lo +- 0.5`` equal
    to ``lo`` in floating point) included."""
    if hi > lo:
        edges = np.linspace(lo, hi, _HIST_BINS + 1)
    else:  # one value: a bin of width 1 around it, wider where 1 is below its resolution
        half = max(0.5, abs(lo) * 2.0**-20)
        edges = np.linspace(lo - half, lo + half, _HIST_BINS + 1)
    first, width = float(edges[0]), (float(edges[-1]) - float(edges[0])) / _HIST_BINS
    counts = np.zeros(_HIST_BINS, dtype=np.int64)
    for start in range(0, values.size, _HIST_CHUNK):
        chunk = values[start : start + _HIST_CHUNK].astype(np.float64)
        index = np.floor((chunk - first) / width)
        np.clip(index, 0, _HIST_BINS - 1, out=index)
        counts += np.bincount(index.astype(np.intp), minlength=_HIST_BINS)
    return counts, edges


_SPACING_NOTE = {
    "file": "from the file",
    "given": "given by the user",
    "assumed": "assumed: the input states none; pass --spacing",
}


def _orientation_text(volume: Volume) -> str:
    if not volume.space:
        return "none (no patient orientation; index axes along world +x, +y, +z)"
    text = f"{volume.file_axes or 'RAS'} in the file"
    if volume.file_axes and volume.file_axes != "RAS":
        text += ", stored as RAS (axes permuted/flipped, no resampling)"
    if volume.is_oblique:
        text += f", oblique by {volume.obliquity:.1f} deg (rendered through the affine)"
    return text + "; world is patient RAS+ mm"


def _affine_lines(affine: np.ndarray) -> list[str]:
    rows = [" ".join(f"{v:>10.4g}" for v in row) for row in affine]
    return [f"affine:      [{rows[0]}]", *(f"             [{r}]" for r in rows[1:])]


def _fmt(value: float) -> str:
    return f"{value:.6g}"


def _fmt3(values: Sequence[float]) -> str:
    return "(" + ", ".join(_fmt(v) for v in values) + ")"


def volume_summary(volume: Volume) -> str:
    """The multi-line text ``voxwarp info`` prints for ``volume``.

    Parameters
    ----------
    volume
        The volume to describe.

    Returns
    -------
    str
        Name and source, dims ``(nx, ny, nz)``, dtype, units, spacing, origin and
        physical size in mm, memory in MB, value range, mean/std, the 1/5/50/95/99
        percentiles and a 16-bin text histogram: one line per bin with its value range,
        a bar of ``#`` whose length grows with the logarithm of the count, and the count.
        The numbers are those of :func:`volume_info`.
    """
    info = volume_info(volume)
    nx, ny, nz = info["dims"]
    lines = [
        f"name:        {info['name']}",
        f"source:      {info['source'] if info['source'] is not None else '(in memory)'}",
        f"dims:        ({nx}, {ny}, {nz})  = {info['voxels']:,} voxels",
        f"dtype:       {info['dtype']}",
        f"units:       {info['units'] or '(unknown)'}",
        f"spacing:     {_fmt3(info['spacing_mm'])} mm ({_SPACING_NOTE[volume.spacing_source]})",
        f"origin:      {_fmt3(info['origin_mm'])} mm (centre of voxel 0, 0, 0)",
        f"orientation: {_orientation_text(volume)}",
        *_affine_lines(volume.affine),
        f"modality:    {volume.modality or '(not stated by the file)'}"
        + (
            f"; padding value {_fmt(volume.padding_value)}"
            if volume.padding_value is not None
            else ""
        ),
        f"size:        {_fmt3(info['size_mm'])} mm",
        f"memory:      {info['memory_mb']:.2f} MB ({volume.nbytes:,} bytes)",
        f"range:       [{_fmt(info['min'])}, {_fmt(info['max'])}]",
        f"mean / std:  {_fmt(info['mean'])} / {_fmt(info['std'])}",
        "percentiles: "
        + "  ".join(f"p{p}={_fmt(v)}" for p, v in info["percentiles"].items())
        + ("  (sampled)" if info["percentiles_sampled"] else ""),
    ]
    if info["nonfinite"]:
        lines.append(f"non-finite:  {info['nonfinite']:,} NaN/Inf voxels (left out above)")
    counts = info["histogram"]["counts"]
    edges = info["histogram"]["edges"]
    top = max(counts) if counts else 0
    lines.append(f"histogram ({len(counts)} bins, bar length ~ log(count)):")
    width = max(len(_fmt(e)) for e in edges) if edges else 1
    for b, count in enumerate(counts):
        length = 0
        if count > 0 and top > 0:
            length = max(1, round(_HIST_WIDTH * math.log1p(count) / math.log1p(top)))
        closing = "]" if b == len(counts) - 1 else ")"
        lines.append(
            f"  [{_fmt(edges[b]):>{width}}, {_fmt(edges[b + 1]):>{width}}{closing}"
            f" {'#' * length:<{_HIST_WIDTH}} {count}"
        )
    return "\n".join(lines)
