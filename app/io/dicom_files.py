"""The files of a DICOM folder: which are image slices, and their pixels, checked first.

:func:`image_headers` reads every file's header (never its pixels) and keeps the image
slices; files that are not DICOM are passed over silently, DICOM files that cannot be
read or hold no image are summed up in one warning (or, when no image is left, in the
one error line, naming a DICOMDIR's image folder when there is one).
:func:`check_grayscale` refuses colour images and :func:`decoded_pixels` decodes one
file's pixels with a one-line error naming the transfer syntax and the fix.
"""

from __future__ import annotations

import warnings
from collections import Counter
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np

from voxwarp.errors import VolumeError
from voxwarp.io.loaded import to_float, warn

#: what pydicom's decoders need, and how to do without them
_DECODER_HINT = (
    "Install the decoders (pip install 'voxwarp[dicom]': pylibjpeg with its JPEG, JPEG 2000"
    " and RLE plugins) or decompress the files first (gdcmconv --raw, dcmdjpeg)"
)
#: the media storage SOP class of a DICOMDIR
_DICOMDIR_CLASS = "1.2.840.10008.1.3.10"
_GRAYSCALE = ("MONOCHROME1", "MONOCHROME2", "")


def image_headers(directory: Path, files: list[Path]) -> list[tuple[Path, Any]] | None:
    """(path, header) of every image slice in ``files``; ``None`` when none is DICOM.
    Raises one line when DICOM files are there but none is a readable image."""
    import pydicom
    from pydicom.errors import InvalidDicomError

    headers: list[tuple[Path, Any]] = []
    skipped: list[str] = []
    others: Counter[str] = Counter()
    dicomdir: Path | None = None
    for p in files:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                ds = pydicom.dcmread(p, stop_before_pixels=True, force=False)
        except InvalidDicomError:
            continue
        except Exception as exc:
            skipped.append(f"{p.name} ({_file_syntax(p)}{type(exc).__name__}: {_short(exc)})")
            continue
        meta = getattr(ds, "file_meta", None)
        if str(getattr(meta, "MediaStorageSOPClassUID", "")) == _DICOMDIR_CLASS:
            dicomdir = p
        elif "SOPClassUID" not in ds and "Rows" not in ds:
            skipped.append(f"{p.name} ({_file_syntax(p)}no dataset after its file meta)")
        elif "Rows" not in ds or "Columns" not in ds:
            others[str(ds.get("Modality", "") or "no image")] += 1
        elif not _whole_sizes(ds):
            skipped.append(f"{p.name} (Rows/Columns not positive whole numbers)")
        else:
            headers.append((p, ds))
    if headers:
        if skipped:
            warn(
                f"{directory}: skipped {len(skipped)} unreadable DICOM file(s), e.g. {skipped[0]}."
            )
        return headers
    if dicomdir is not None:
        raise VolumeError(_dicomdir_message(directory, dicomdir))
    if skipped:
        raise VolumeError(
            f"{directory}: no readable DICOM image; {len(skipped)} damaged file(s), e.g."
            f" {skipped[0]}. Pass a folder of intact slices."
        )
    if others:
        kinds = ", ".join(f"{n} {k}" for k, n in others.most_common(4))
        raise VolumeError(
            f"{directory} holds DICOM files but no image ({kinds}: no Rows/Columns, e.g."
            " a structured report or RT structure set); pass the folder of the image series."
        )
    return None


def _file_syntax(p: Path) -> str:
    """``"NAME (UID); "`` of the transfer syntax the file meta of ``p`` states, or ``""``."""
    try:
        from pydicom.filereader import read_file_meta_info

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            meta = read_file_meta_info(p)
        return f"{syntax_name(meta)}; " if "TransferSyntaxUID" in meta else ""
    except Exception:
        return ""


def _short(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= 160 else text[:157] + "..."


def _whole_sizes(ds: Any) -> bool:
    """Whether the header's Rows and Columns are positive whole numbers."""
    try:
        return int(ds.Rows) > 0 and int(ds.Columns) > 0
    except Exception:  # pydicom's BytesLengthException, int(''), a sequence, ...
        return False


def _dicomdir_message(directory: Path, dicomdir: Path) -> str:
    """The error for a folder whose only DICOM file is a DICOMDIR: name the folder that
    holds most of the images it lists."""
    import pydicom

    folders: Counter[str] = Counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ds = pydicom.dcmread(dicomdir, force=False)
        for record in ds.get("DirectoryRecordSequence", []):
            if str(record.get("DirectoryRecordType", "")).upper() != "IMAGE":
                continue
            parts = record.get("ReferencedFileID")
            parts = [parts] if isinstance(parts, str) else list(parts or [])
            if len(parts) > 1:
                folders[str(PurePosixPath(*map(str, parts[:-1])))] += 1
    except Exception:  # a damaged index: the plain advice below still holds
        folders.clear()
    hint = "the folder inside it that holds one series' image files"
    if folders:
        folder, count = folders.most_common(1)[0]
        hint = f"a series folder, e.g. {directory / folder} ({count} images listed there)"
    return (
        f"{directory} holds a DICOMDIR (an index of files in subfolders) but no image"
        f" slices; voxwarp reads the slices themselves: pass {hint}."
    )


def check_grayscale(p: Path, ds: Any) -> None:
    """One line unless ``ds`` is a grayscale image (one sample, MONOCHROME1/2)."""
    photometric = str(ds.get("PhotometricInterpretation", "") or "").strip().upper()
    samples = to_float(ds.get("SamplesPerPixel"), 1.0)
    if photometric not in _GRAYSCALE or samples != 1:
        raise VolumeError(
            f"{p.name} is a colour image ({photometric or '?'}, SamplesPerPixel"
            f" {ds.get('SamplesPerPixel', '?')}); voxwarp reads grayscale DICOM"
            " (MONOCHROME1/2, one sample per pixel). Choose the grayscale series with"
            " --series, or convert the images to grayscale first."
        )


def syntax_name(ds: Any) -> str:
    """The transfer syntax of ``ds`` by name and UID, e.g. ``RLE Lossless (1.2.840...)``."""
    from pydicom.uid import UID

    meta = ds if "TransferSyntaxUID" in ds else getattr(ds, "file_meta", None)
    uid = getattr(meta, "TransferSyntaxUID", None)
    if uid is None:
        return "no transfer syntax"
    name = UID(str(uid)).name
    return f"{name} ({uid})" if name != str(uid) else f"unknown transfer syntax {uid}"


def _decoder_ready(ds: Any) -> bool | None:
    """Whether pydicom has a working decoder for the syntax of ``ds`` (``None``: unknown)."""
    try:
        from pydicom.pixels import get_decoder

        return bool(get_decoder(ds.file_meta.TransferSyntaxUID).is_available)
    except NotImplementedError:
        return False
    except Exception:
        return None


def decoded_pixels(p: Path, ds: Any) -> np.ndarray:
    """The pixels of ``ds`` (read from ``p``); one line naming the syntax and the fix."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return np.asarray(ds.pixel_array)
    except Exception as exc:
        syntax = syntax_name(ds)
        cause = f"{type(exc).__name__}: {_short(exc)}"
        missing = isinstance(exc, NotImplementedError) or "missing dependencies" in str(exc)
        if missing or _decoder_ready(ds) is False:
            raise VolumeError(
                f"cannot decode {p}: no decoder for {syntax} is installed ({cause})."
                f" {_DECODER_HINT}."
            ) from exc
        raise VolumeError(
            f"cannot decode the pixel data of {p} ({syntax}; {cause}); the file is damaged"
            " or its syntax is not what the data holds. Check it with dcmdump, or"
            " decompress it with gdcmconv --raw / dcmdjpeg."
        ) from exc
