"""DICOM: a folder of single-frame slices (one series) or one multi-frame file.

Geometry comes from ImageOrientationPatient, ImagePositionPatient and PixelSpacing in
DICOM's patient space (LPS+ mm) and is handed on as a RAS+ affine: column index i runs
along the row direction (IOP[:3], PixelSpacing[1] apart), row index j along the column
direction (IOP[3:], PixelSpacing[0]) and k along the slice normal (slices sorted by their
position on it and checked against a regular grid: :mod:`voxwarp.io.dicom_geometry`).
Values are rescaled to stored units (HU for CT); the Modality and the PixelPaddingValue
(rescaled) are kept. A series is one SeriesInstanceUID and one image size; only
grayscale images (MONOCHROME1/2, one sample per pixel) are read. pydicom is imported
only here and in :mod:`voxwarp.io.dicom_files`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.core.limits import check_load_bytes
from voxwarp.core.orientation import affine_to_ras
from voxwarp.errors import VolumeError
from voxwarp.io.dicom_files import check_grayscale, decoded_pixels, image_headers
from voxwarp.io.dicom_geometry import Stack, stack_slices
from voxwarp.io.loaded import Loaded, floats, rescale, to_float, warn


@dataclass(frozen=True)
class SeriesInfo:
    """One DICOM series in a folder, as ``voxwarp info`` lists it."""

    index: int  # 1-based, in the order listed (largest first)
    uid: str
    description: str
    modality: str
    files: int
    rows: int
    columns: int

    def line(self) -> str:
        """One line: index, file count, size, modality, description and UID."""
        return (
            f"{self.index}: {self.files} files, {self.columns}x{self.rows},"
            f" {self.modality or '?'}, {self.description or 'no description'}"
            f" ({self.uid or 'no SeriesInstanceUID'})"
        )


def _number(ds: Any, keyword: str, default: float | None) -> float | None:
    return to_float(ds.get(keyword), default)


def _group_series(headers: list[tuple[Path, Any]]) -> list[tuple[SeriesInfo, list]]:
    """Series in the folder, largest first (ties in UID order): one per
    SeriesInstanceUID and image size (a UID holding two sizes is two series)."""
    groups: dict[tuple[str, int, int], list[tuple[Path, Any]]] = {}
    for p, ds in headers:
        key = (str(ds.get("SeriesInstanceUID", "")), int(ds.Rows), int(ds.Columns))
        groups.setdefault(key, []).append((p, ds))
    ordered = sorted(groups.items(), key=lambda item: (-len(item[1]), item[0]))
    out = []
    for n, ((uid, _, _), items) in enumerate(ordered, start=1):
        ds = items[0][1]
        info = SeriesInfo(
            index=n,
            uid=uid,
            description=str(ds.get("SeriesDescription", "") or ""),
            modality=str(ds.get("Modality", "") or ""),
            files=len(items),
            rows=int(ds.Rows),
            columns=int(ds.Columns),
        )
        out.append((info, items))
    return out


def list_dicom_series(directory: Path, files: list[Path]) -> list[SeriesInfo]:
    """The DICOM series among ``files`` (largest first); empty when none is DICOM."""
    try:
        headers = image_headers(directory, files)
    except VolumeError:
        return []
    return [info for info, _ in _group_series(headers or [])]


def _pick_series(
    directory: Path, groups: list[tuple[SeriesInfo, list]], series: str | int | None
) -> tuple[SeriesInfo, list]:
    """The series ``series`` names (1-based index or UID); the largest when ``None``."""
    listing = "; ".join(info.line() for info, _ in groups)
    if series is None:
        chosen = groups[0]
        if len(groups) > 1:
            warn(
                f"{directory} holds {len(groups)} DICOM series; loading the largest"
                f" ({chosen[0].line()}). Choose another with --series N or --series UID"
                f" (voxwarp info lists them): {listing}"
            )
        return chosen
    text = str(series).strip()
    found = [g for g in groups if text == g[0].uid or (text.isdigit() and int(text) == g[0].index)]
    if len(found) > 1:
        raise VolumeError(
            f"{directory}: the SeriesInstanceUID {text} holds {len(found)} image sizes"
            f" (series {', '.join(str(g[0].index) for g in found)}); pass --series with"
            f" the index of one: {listing}"
        )
    if found:
        return found[0]
    raise VolumeError(
        f"{directory} has no DICOM series {text!r}; pass an index 1..{len(groups)} or a"
        f" SeriesInstanceUID: {listing}"
    )


def read_dicom_dir(
    directory: Path, files: list[Path], series: str | int | None = None
) -> Loaded | None:
    """Load one DICOM series among ``files``; ``None`` if none of them is DICOM.

    Its warnings (several series, skipped files, missing slices) are given only when
    the series loads: a refusal is its one error line alone (naming the other series
    when the largest was taken by default)."""
    if not files:
        return None
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        try:
            loaded = _read_series(directory, files, series)
        except VolumeError as exc:
            others = [w for w in said if "DICOM series; loading the largest" in str(w.message)]
            if others:
                raise VolumeError(f"{exc}{_series_note(others)}") from exc
            raise
    for w in said:
        if issubclass(w.category, UserWarning):
            warn(str(w.message))
    return loaded


def _series_note(said: list) -> str:
    """' (loading the largest of N DICOM series; ...)' from the several-series warning."""
    count = str(said[0].message).split(" holds ", 1)[1].split(";", 1)[0]
    return f" (the largest of {count}; choose another with --series N: voxwarp info lists them)"


def _read_series(directory: Path, files: list[Path], series: str | int | None) -> Loaded | None:
    headers = image_headers(directory, files)
    if not headers:
        return None
    _, chosen = _pick_series(directory, _group_series(headers), series)
    frames = [int(_number(ds, "NumberOfFrames", 1) or 1) for _, ds in chosen]
    if max(frames) > 1:
        if len(chosen) == 1:
            return read_dicom_file(chosen[0][0])
        raise VolumeError(
            f"{directory} holds several multi-frame DICOM files in one series; pass one"
            " of them (a .dcm file) instead of the folder."
        )
    return _assemble_series(directory, chosen)


def _positions_on_normal(iop: np.ndarray | None, ipps: list) -> np.ndarray | None:
    """Each slice's position along the slice normal (mm), or ``None`` without
    ImageOrientationPatient or an ImagePositionPatient per slice."""
    if iop is None or any(p is None for p in ipps):
        return None
    normal = np.cross(iop[:3], iop[3:])
    if np.linalg.norm(normal) <= 1e-6:
        return None
    normal /= np.linalg.norm(normal)
    return np.array([float(np.dot(p, normal)) for p in ipps])


def _pixel_spacing(where: str, value: Any) -> np.ndarray:
    """PixelSpacing (row, column spacing; 1 mm with a warning when absent); one line when
    it is there but not two positive finite numbers."""
    if value is None or (hasattr(value, "__len__") and len(value) == 0):
        warn(f"{where}: no PixelSpacing; in-plane spacing set to 1 mm.")
        return np.array([1.0, 1.0])
    pixel = floats(value, 2)
    if pixel is None or np.any(pixel <= 0):
        raise VolumeError(
            f"{where}: its PixelSpacing ({str(value)[:60]}) is not two positive numbers;"
            " the header is damaged. Fix it (e.g. dcmodify -m PixelSpacing=0.5\\0.5)."
        )
    return pixel


def _ras_affine(
    iop: np.ndarray | None, first_ipp: np.ndarray | None, pixel: np.ndarray, dz: float
) -> tuple[np.ndarray | None, tuple[float, float, float]]:
    """RAS affine (or ``None`` without IOP/IPP) and the (sx, sy, sz) spacing."""
    spacing = (float(pixel[1]), float(pixel[0]), float(dz))
    if iop is None or first_ipp is None:
        return None, spacing
    row, col = iop[:3], iop[3:]
    normal = np.cross(row, col)
    if np.linalg.norm(normal) < 1e-6:
        return None, spacing
    lps = np.eye(4)
    lps[:3, 0] = row / np.linalg.norm(row) * spacing[0]
    lps[:3, 1] = col / np.linalg.norm(col) * spacing[1]
    lps[:3, 2] = normal / np.linalg.norm(normal) * spacing[2]
    lps[:3, 3] = first_ipp
    return affine_to_ras(lps, "LPS"), spacing


def _check_pixel_length(p: Path, ds: Any) -> None:
    """Refuse uncompressed pixel data whose length does not fit Rows x Columns (x
    frames, samples, bytes): shorter, or longer by a whole row or more (a slice whose
    Rows/Columns were changed); a padding byte or a few trailing bytes are accepted."""
    syntax = getattr(getattr(ds, "file_meta", None), "TransferSyntaxUID", None)
    data = ds.get("PixelData")
    if data is None or syntax is None or getattr(syntax, "is_compressed", True):
        return  # compressed: the decoder checks the frame size
    rows, cols = int(_number(ds, "Rows", 0) or 0), int(_number(ds, "Columns", 0) or 0)
    frames = int(_number(ds, "NumberOfFrames", 1) or 1)
    bits = int(_number(ds, "BitsAllocated", 16) or 16)
    samples = int(_number(ds, "SamplesPerPixel", 1) or 1)
    need = (rows * cols * frames * samples * bits + 7) // 8
    row = max(1, cols * samples * bits // 8)
    got = len(data)
    if got < need or got - need >= row:
        raise VolumeError(
            f"{p.name}: its pixel data holds {got:,} bytes but Rows x Columns = {rows} x"
            f" {cols} ({frames} frame(s), {bits}-bit) need {need:,}; the slice is damaged"
            " (fix Rows/Columns or remove the file from the series)"
        )


def _pixels(p: Path, full: Any) -> np.ndarray:
    check_grayscale(p, full)
    _check_pixel_length(p, full)
    return decoded_pixels(p, full)


def _bytes_per_voxel(ds: Any) -> int:
    """Bytes per voxel once decoded: BitsAllocated (in bytes) times SamplesPerPixel."""
    bits = int(_number(ds, "BitsAllocated", 16) or 16)
    samples = int(_number(ds, "SamplesPerPixel", 1) or 1)
    return max(1, (bits + 7) // 8) * max(1, samples)


def _padding(ds: Any, slope: float, inter: float) -> float | None:
    value = _number(ds, "PixelPaddingValue", None)
    return None if value is None else float(value * slope + inter)


def _assemble_series(directory: Path, chosen: list[tuple[Path, Any]]) -> Loaded:
    """One volume from the slices of one series, placed on their grid (headers are
    checked before any pixels are read; missing slots get the lowest value)."""
    ds0 = chosen[0][1]
    for p, ds in chosen:
        check_grayscale(p, ds)
    pixel = _pixel_spacing(str(directory), ds0.get("PixelSpacing") or ds0.get("ImagerPixelSpacing"))
    stack = stack_slices(directory, chosen, pixel)
    affine, spacing = _ras_affine(stack.iop, stack.first_ipp, pixel, stack.dz)
    rows, cols = int(ds0.Rows), int(ds0.Columns)
    check_load_bytes((cols, rows, stack.count), _bytes_per_voxel(ds0), directory.name)
    slopes = np.array([_number(ds, "RescaleSlope", 1.0) or 1.0 for _, ds in stack.files])
    inters = np.array([_number(ds, "RescaleIntercept", 0.0) or 0.0 for _, ds in stack.files])
    rescaled = bool(np.any(slopes != 1.0) or np.any(inters != 0.0))
    out, integer_pixels = _read_slices(stack, (rows, cols), slopes, inters, rescaled)
    slope0, inter0 = float(slopes[0]), float(inters[0])
    _fill_missing(out, stack, _padding(ds0, slope0, inter0))
    if rescaled:
        integral = (
            integer_pixels
            and all(float(s).is_integer() for s in slopes)
            and all(float(i).is_integer() for i in inters)
        )
        if integral and out.min() >= -32768 and out.max() <= 32767:
            out = out.astype(np.int16)
    return _loaded(out, spacing, affine, ds0, slope0, inter0)


def _read_slices(
    stack: Stack,
    shape: tuple[int, int],
    slopes: np.ndarray,
    inters: np.ndarray,
    rescaled: bool,
) -> tuple[np.ndarray, bool]:
    """The (cols, rows, count) array of the slices in their slots (other slots unset)
    and whether every slice held integers."""
    import pydicom

    out: np.ndarray | None = None
    integer_pixels = True
    for k, ((p, _), slot) in enumerate(zip(stack.files, stack.slots, strict=True)):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                full = pydicom.dcmread(p, force=False)
        except Exception as exc:
            raise VolumeError(
                f"cannot read the DICOM file {p} ({type(exc).__name__}: {exc})."
            ) from exc
        arr = _pixels(p, full)
        if arr.shape != shape:
            raise VolumeError(
                f"{p.name} has an image of shape {arr.shape}, but its header says {shape};"
                " the file is damaged: remove it from the series."
            )
        integer_pixels = integer_pixels and arr.dtype.kind in "iub"
        if stack.shifts is not None:
            arr = _untilted(arr, stack.shifts[k])
        if out is None:
            dtype = np.float32 if rescaled else arr.dtype
            out = np.zeros((shape[1], shape[0], stack.count), dtype=dtype, order="F")
        elif not rescaled and arr.dtype != out.dtype:
            out = out.astype(np.result_type(out.dtype, arr.dtype))
        if rescaled:
            out[:, :, slot] = _rescaled(p, arr, float(slopes[k]), float(inters[k])).T
        else:
            out[:, :, slot] = arr.T
    assert out is not None
    return out, integer_pixels


def _untilted(arr: np.ndarray, shift: tuple[float, float]) -> np.ndarray:
    """A slice moved by ``shift`` (rows, columns; pixels) in its plane onto the grid
    (linear interpolation; uncovered pixels take the slice's lowest value); integer
    slices stay integers (rounded)."""
    from scipy import ndimage

    exact = np.round(np.asarray(shift), 4)  # no round-off drift past the edge (cval)
    moved = ndimage.shift(
        arr.astype(np.float32), exact, order=1, mode="constant", cval=float(arr.min())
    )
    return np.rint(moved).astype(arr.dtype) if arr.dtype.kind in "iub" else moved


def _rescaled(p: Path, arr: np.ndarray, slope: float, inter: float) -> np.ndarray:
    """``arr * slope + inter`` as float32; one line when that leaves the float32 range."""
    with np.errstate(over="ignore", invalid="ignore"):
        scaled = (arr.astype(np.float64) * slope + inter).astype(np.float32)
    if not np.all(np.isfinite(scaled)) and np.all(np.isfinite(arr)):
        raise VolumeError(
            f"{p.name}: RescaleSlope {slope:g} and RescaleIntercept {inter:g} take its values"
            " past the float32 range; the header is damaged. Fix them (e.g. dcmodify) or"
            " remove the file from the series."
        )
    return scaled


def _fill_missing(out: np.ndarray, stack: Stack, padding: float | None) -> None:
    """Set the slots no slice filled to ``padding``, else to the series' lowest value."""
    missing = sorted(set(range(stack.count)) - set(stack.slots))
    if not missing:
        return
    value = out[:, :, stack.slots].min()
    if padding is not None:
        stated = int(padding) if float(padding).is_integer() else padding
        if np.can_cast(np.min_scalar_type(stated), out.dtype):
            value = stated
    out[:, :, missing] = value


def _loaded(
    data: np.ndarray,
    spacing: tuple[float, float, float],
    affine: np.ndarray | None,
    ds: Any,
    slope: float,
    inter: float,
) -> Loaded:
    modality = str(ds.get("Modality", "") or "").upper()
    return Loaded(
        data,
        spacing=spacing,
        units="HU" if modality == "CT" else "",
        affine=affine,
        space="RAS" if affine is not None else "",
        modality=modality,
        padding_value=_padding(ds, slope, inter),
    )


def _functional_attr(ds: Any, keyword: str, frame: int | None = None) -> Any:
    """Find ``keyword`` at top level or in the (per-frame or shared) functional groups."""
    if keyword in ds:
        return ds.get(keyword)
    groups = []
    if frame is not None and "PerFrameFunctionalGroupsSequence" in ds:
        seq = ds.PerFrameFunctionalGroupsSequence
        if frame < len(seq):
            groups.append(seq[frame])
    if "SharedFunctionalGroupsSequence" in ds and len(ds.SharedFunctionalGroupsSequence):
        groups.append(ds.SharedFunctionalGroupsSequence[0])
    for group in groups:
        for element in group:
            if element.VR == "SQ" and len(element.value) and keyword in element.value[0]:
                return element.value[0].get(keyword)
    return None


def _read_multiframe(path: Path) -> Any:
    import pydicom
    from pydicom.errors import InvalidDicomError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return pydicom.dcmread(path, force=False)
    except InvalidDicomError as exc:
        raise VolumeError(f"{path} is not a DICOM file ({exc}).") from exc
    except Exception as exc:
        raise VolumeError(
            f"cannot read the DICOM file {path} ({type(exc).__name__}: {exc})."
        ) from exc


def read_dicom_file(path: Path) -> Loaded:
    """Load a single multi-frame DICOM file (frames stacked along the slice normal)."""
    ds = _read_multiframe(path)
    frames = int(_number(ds, "NumberOfFrames", 1) or 1)
    if frames <= 1:
        raise VolumeError(
            f"{path} is a single DICOM slice; pass the folder holding the whole series"
            f" instead: {path.parent}"
        )
    rows, cols = int(_number(ds, "Rows", 0) or 0), int(_number(ds, "Columns", 0) or 0)
    check_load_bytes((cols, rows, frames), _bytes_per_voxel(ds), path.name)
    arr = _pixels(path, ds)
    if arr.ndim != 3 or arr.shape[0] != frames:
        raise VolumeError(
            f"{path} has pixel data of shape {arr.shape}; voxwarp reads grayscale multi-frame"
            " images (frames, rows, columns)."
        )
    data = arr.transpose(2, 1, 0)  # (frames, rows, cols) -> (x, y, z)
    iop = floats(_functional_attr(ds, "ImageOrientationPatient", 0), 6)
    ipps = [floats(_functional_attr(ds, "ImagePositionPatient", f), 3) for f in range(frames)]
    dz, first_ipp = None, None
    pos = _positions_on_normal(iop, ipps)
    if pos is not None:
        order = np.argsort(pos, kind="stable")
        gaps = np.diff(pos[order])
        if np.all(gaps > 1e-4):
            data = data[:, :, order]
            dz = float(np.median(gaps))
            first_ipp = ipps[int(order[0])]
    if dz is None:
        for keyword in ("SpacingBetweenSlices", "SliceThickness"):
            value = to_float(_functional_attr(ds, keyword, 0), None)
            if value is not None and value > 0:
                dz = value
                break
    if dz is None:
        dz = 1.0
        warn(f"{path.name}: no frame positions or slice thickness; slice spacing set to 1 mm.")
    pixel = _pixel_spacing(path.name, _functional_attr(ds, "PixelSpacing", 0))
    affine, spacing = _ras_affine(iop, first_ipp, pixel, dz)
    s = to_float(_functional_attr(ds, "RescaleSlope", 0), 1.0) or 1.0
    i = to_float(_functional_attr(ds, "RescaleIntercept", 0), 0.0) or 0.0
    if s != 1.0 or i != 0.0:
        data = rescale(data, s, i)
        if data.dtype == np.int32 and data.min() >= -32768 and data.max() <= 32767:
            data = data.astype(np.int16)
        elif data.dtype == np.int32:
            data = data.astype(np.float32)
    return _loaded(data, spacing, affine, ds, s, i)
