"""What the axes of an image beyond x, y, z hold, per format (NIfTI, NRRD, TIFF).

Each function names those axes as :class:`~voxwarp.io.frames.ExtraAxis` (time or
channels) for :func:`voxwarp.io.frames.choose`, and says whether the header marks a
displacement field.

* NIfTI fixes the meaning of its dimensions: the 4th is time (``pixdim[4]`` apart, in
  the header's time unit), the 5th the components of a vector or multi-valued voxel
  (the ``intent_code`` says which), the 6th and 7th are rarely used and refused. ITK and
  ANTs write a displacement field as 5-D ``(x, y, z, 1, 3)`` with intent ``vector``
  (1007); intent ``dispvect`` (1006) marks one too.
* NRRD names each axis in ``kinds``: ``domain``/``space`` axes (or those with a space
  direction) are spatial, ``time`` is time, anything else (``list``, ``vector``,
  ``RGB-color``...) a channel axis; one 3-component float ``vector`` axis is a field.
* TIFF (tifffile/ImageJ axes): ``T`` is time, ``C`` and ``S`` (samples, e.g. RGB) are
  channels.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from voxwarp.errors import VolumeError
from voxwarp.io.frames import CHANNEL, FRAME, ExtraAxis

#: NIfTI intent codes of displacement fields, and how a message names them.
FIELD_INTENTS = {1006: "NIfTI intent displacement vector", 1007: "NIfTI intent vector"}


def nifti_extra_axes(img: Any, shape: tuple[int, ...]) -> tuple[tuple[ExtraAxis, ...], str]:
    """The :class:`ExtraAxis` of each axis of ``shape`` after the third, and why the
    image is a displacement field (``""`` when it is not)."""
    step, unit = _time_step(img)
    axes = []
    for axis, size in enumerate(shape[3:], start=3):
        if axis == 3:
            axes.append(ExtraAxis(FRAME, size, step, unit))
        else:
            axes.append(ExtraAxis(CHANNEL, size))
    return tuple(axes), _field_reason(img, shape)


def _time_step(img: Any) -> tuple[float | None, str]:
    """``pixdim[4]`` and the header's time unit, or ``(None, "")`` when not stated."""
    hdr = img.header
    try:
        zooms = hdr.get_zooms()
        unit = hdr.get_xyzt_units()[1] if hasattr(hdr, "get_xyzt_units") else ""
    except Exception:
        return None, ""
    if len(zooms) < 4 or not float(zooms[3]) > 0:
        return None, ""
    unit = {"sec": "s", "msec": "ms", "usec": "µs", "unknown": ""}.get(str(unit), str(unit))
    return float(zooms[3]), unit


def _field_reason(img: Any, shape: tuple[int, ...]) -> str:
    """Why ``img`` holds displacement vectors: its intent, or ITK's 5-D layout of
    3 float components over one time point; ``""`` for a volume."""
    hdr = img.header
    try:
        intent = int(hdr["intent_code"]) if "intent_code" in hdr else 0
        kind = img.get_data_dtype().kind
    except Exception:
        return ""
    if len(shape) < 4:
        return ""
    if intent in FIELD_INTENTS:
        return FIELD_INTENTS[intent]
    if len(shape) == 5 and shape[3] == 1 and shape[4] == 3 and kind == "f":
        return "5-D with 3 float components per voxel, as ITK writes displacement fields"
    return ""


# ---------------------------------------------------------------------------- NRRD
#: NRRD ``kinds`` of a component axis that holds displacement-like vectors.
_NRRD_VECTOR_KINDS = ("vector", "covariant-vector", "3-vector", "normal")
#: NRRD ``kinds`` of spatial axes.
_NRRD_SPATIAL_KINDS = ("domain", "space")


def _nrrd_kinds(header: dict[str, Any], ndim: int) -> list[str]:
    kinds = header.get("kinds")
    if not isinstance(kinds, list) or len(kinds) != ndim:
        return [""] * ndim
    return [str(k).strip().lower() for k in kinds]


def nrrd_spatial_axes(header: dict[str, Any], dirs: np.ndarray | None, ndim: int) -> list[int]:
    """The spatial axes of an NRRD: those with a space direction, else those of a
    spatial ``kinds`` entry, else all."""
    if dirs is not None:
        return [a for a in range(ndim) if np.all(np.isfinite(dirs[a]))]
    kinds = _nrrd_kinds(header, ndim)
    if ndim > 3 and any(kinds):
        return [a for a in range(ndim) if kinds[a] in _NRRD_SPATIAL_KINDS]
    return list(range(ndim))


def nrrd_extra(
    data: np.ndarray, header: dict[str, Any], spatial: list[int]
) -> tuple[np.ndarray, tuple[ExtraAxis, ...], str]:
    """``data`` with its non-spatial axes moved last, one :class:`ExtraAxis` each (a
    ``time`` kind is a frame axis, any other a channel axis), and why it is a
    displacement field (one 3-component float ``vector`` axis), else ``""``."""
    kinds = _nrrd_kinds(header, data.ndim)
    others = [a for a in range(data.ndim) if a not in spatial]
    moved = np.moveaxis(data, others, list(range(3, data.ndim)))
    extra = tuple(
        ExtraAxis(FRAME if kinds[a] == "time" else CHANNEL, data.shape[a]) for a in others
    )
    field = ""
    if len(others) == 1 and data.shape[others[0]] == 3 and data.dtype.kind == "f":
        if kinds[others[0]] in _NRRD_VECTOR_KINDS:
            field = f"NRRD '{kinds[others[0]]}' axis of 3 float components"
    return moved, extra, field


# ---------------------------------------------------------------------------- TIFF
def tiff_extra(data: np.ndarray, axes: str, where: str) -> tuple[np.ndarray, tuple[ExtraAxis, ...]]:
    """A tifffile series with time (``T``) or channel (``C``, ``S``) axes of length > 1
    as ``(z, y, x, ...)`` plus one :class:`ExtraAxis` per such axis; any other series
    comes back as it is, with no extra axis (a z-stack for the caller to reduce)."""
    keep = [i for i, a in enumerate(axes) if a in "YX" or data.shape[i] != 1]
    kept = "".join(axes[i] for i in keep)
    others = [n for n, a in enumerate(kept) if a in "TCS"]
    if not others:
        return data, ()
    data = np.squeeze(data, axis=tuple(i for i in range(data.ndim) if i not in keep))
    space = [n for n in range(len(kept)) if n not in others]
    if "".join(kept[n] for n in space)[-2:] != "YX" or len(space) > 3:
        raise VolumeError(
            f"{where} holds images with axes {kept!r} and shape {data.shape}; voxwarp reads"
            " z-stacks with time (T) and channel (C, S) axes. Save a ZYX stack per channel."
        )
    data = data.transpose(space + others)
    if len(space) == 2:
        data = data[None]
    extra = tuple(
        ExtraAxis(FRAME if kept[n] == "T" else CHANNEL, data.shape[3 + m])
        for m, n in enumerate(others)
    )
    return data, extra
