"""What the axes of a NIfTI (or other nibabel) image beyond x, y, z hold.

NIfTI fixes the meaning of its dimensions: the 4th is time (``pixdim[4]`` apart, in the
header's time unit), the 5th the components of a vector or multi-valued voxel (the
``intent_code`` says which), the 6th and 7th are rarely used and refused. ITK and ANTs
write a displacement field as 5-D ``(x, y, z, 1, 3)`` with intent ``vector`` (1007);
intent ``dispvect`` (1006) marks one too.
"""

from __future__ import annotations

from typing import Any

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
