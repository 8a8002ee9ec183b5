"""One 3-D volume out of a 4-D or 5-D image: a time point (frame) or a channel.

A reader that finds axes beyond the three spatial ones describes each with an
:class:`ExtraAxis` (a time axis, a channel/component axis, or an axis whose meaning the
file does not state) and moves them after the spatial axes. :func:`choose` turns the
caller's ``frame_index=`` / ``channel=`` into one index per extra axis, or raises a
one-line error naming what the file holds and the option that picks one
(:class:`FrameChoiceError`, which the GUI catches to ask). :func:`take` applies the
indices. A file whose header says it holds displacement vectors is refused with a pointer
to ``--displacement`` unless a channel is chosen.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from voxwarp.errors import VolumeError

#: Kinds of :class:`ExtraAxis`: time points, channels/components, or not stated.
FRAME, CHANNEL, ANY = "frame", "channel", "any"
#: Most extra axes a volume file may have (a time axis and a channel axis).
MAX_EXTRA_AXES = 2


@dataclass(frozen=True)
class ExtraAxis:
    """A non-spatial axis of an image: its ``kind`` (:data:`FRAME`, :data:`CHANNEL` or
    :data:`ANY`), its ``size`` and, for time, the ``step`` between frames in ``unit``
    when the file states it."""

    kind: str
    size: int
    step: float | None = None
    unit: str = ""

    def text(self) -> str:
        """``"180 time points"``, ``"3 channels"`` or ``"4 volumes"``."""
        noun = {FRAME: "time point", CHANNEL: "channel", ANY: "volume"}[self.kind]
        return f"{self.size} {noun}{'' if self.size == 1 else 's'}"


class FrameChoiceError(VolumeError):
    """A file holds several volumes and none was chosen. ``axes`` (the
    :class:`ExtraAxis` list) and ``shape`` (the full shape) say what can be chosen."""

    def __init__(self, message: str, axes: tuple[ExtraAxis, ...], shape: tuple[int, ...]):
        super().__init__(message)
        self.axes = axes
        self.shape = shape


@dataclass(frozen=True)
class Pick:
    """The caller's choice: ``frame_index`` and ``channel`` (``None``: not given)."""

    frame_index: int | None = None
    channel: int | None = None

    def __post_init__(self) -> None:
        for name in ("frame_index", "channel"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or not _is_int(value)):
                raise VolumeError(f"{name} must be an integer index; got {value!r}.")

    def keywords(self) -> dict[str, int]:
        """The given choices as keywords of ``load_volume``: ``{"frame_index": 3}``."""
        given = {"frame_index": self.frame_index, "channel": self.channel}
        return {k: int(v) for k, v in given.items() if v is not None}


def _is_int(value: object) -> bool:
    return isinstance(value, int | np.integer)


def _option(name: str) -> str:
    return "--frame-index" if name == "frame_index" else "--channel"


def _wanted(axis: ExtraAxis) -> str:
    """The option that picks along ``axis`` (an :data:`ANY` axis takes either)."""
    return "channel" if axis.kind == CHANNEL else "frame_index"


def choose(
    axes: tuple[ExtraAxis, ...],
    pick: Pick,
    what: str,
    shape: tuple[int, ...],
    *,
    vector_field: str = "",
) -> tuple[int, ...]:
    """One index per axis of ``axes`` from ``pick``, checked; ``what`` names the file.

    An axis of size 1 needs no choice. Raises :class:`FrameChoiceError` when a choice is
    missing, :class:`VolumeError` for an index out of range, an option the file has no
    axis for, an empty axis or too many axes. ``vector_field`` (e.g. ``"NIfTI intent
    vector"``) marks a displacement field: refused unless ``channel`` is given."""
    if len(axes) > MAX_EXTRA_AXES:
        raise VolumeError(
            f"{what} is a {len(shape)}-D image with shape {shape}; voxwarp reads 3-D volumes"
            " with at most a time axis and a channel axis (5-D). Save the volume you need as"
            " a 3-D file first."
        )
    for axis in axes:
        if axis.size < 1:
            raise VolumeError(
                f"{what} has shape {shape}: its {axis.kind} axis has length 0, so it holds no"
                " volume; the file is empty or truncated. Write it again."
            )
    if vector_field and pick.channel is None:
        _refuse_field(axes, what, vector_field)
    given = {"frame_index": pick.frame_index, "channel": pick.channel}
    used = {_wanted(a) for a in axes}
    any_axis = [a for a in axes if a.kind == ANY]
    if any_axis and len(axes) == 1 and given["frame_index"] is None:
        given["frame_index"], given["channel"] = given["channel"], None  # either option
    for name, value in given.items():
        if value is not None and name not in used:
            raise VolumeError(
                f"{_option(name)} {value} was given but {what} (shape {shape}) has no"
                f" {'channels' if name == 'channel' else 'time axis'}; leave {_option(name)}"
                " out."
            )
    missing = [a for a in axes if a.size > 1 and given[_wanted(a)] is None]
    if missing:
        raise FrameChoiceError(_missing_text(axes, what), axes, shape)
    out = []
    for axis in axes:
        index = given[_wanted(axis)]
        index = 0 if index is None else int(index)
        if not 0 <= index < axis.size:
            raise VolumeError(
                f"{_option(_wanted(axis))} {index} is out of range: {what} holds"
                f" {axis.text()} (0..{axis.size - 1})."
            )
        out.append(index)
    return tuple(out)


def _missing_text(axes: tuple[ExtraAxis, ...], what: str) -> str:
    """``"x.nii.gz holds 180 time points; pick one with --frame-index 0..179 (or
    load_volume(..., frame_index=))"``."""
    many = [a for a in axes if a.size > 1]
    held = " of ".join(a.text() for a in many)
    opts = " and ".join(f"{_option(_wanted(a))} 0..{a.size - 1}" for a in many)
    kws = ", ".join(f"{_wanted(a)}=" for a in many)
    if len(many) == 1 and many[0].kind == ANY:
        opts += f" or --channel 0..{many[0].size - 1}"
    return f"{what} holds {held}; pick one with {opts} (or load_volume(..., {kws}))"


def _refuse_field(axes: tuple[ExtraAxis, ...], what: str, why: str) -> None:
    last = max(next((a.size for a in axes if a.kind != FRAME), 1) - 1, 0)
    if what.startswith("the "):  # an in-memory image: no file to name
        raise VolumeError(
            f"{what} is a displacement field ({why}), not a volume: write it to a file"
            " (e.g. field.nii.gz) and pass that with --displacement, or read one component"
            f" as a scalar volume with load_volume(..., channel=0..{last})"
        )
    raise VolumeError(
        f"{what} is a displacement field ({why}), not a volume: load it with --displacement"
        f" {what} on the moving volume (voxwarp render MOVING --displacement {what}), or"
        f" read one component as a scalar volume with --channel 0..{last}"
    )


def take(data: np.ndarray, indices: tuple[int, ...]) -> np.ndarray:
    """``data`` (three spatial axes, then one axis per index) at ``indices``."""
    if not indices:
        return data
    return np.asarray(data[(slice(None),) * 3 + tuple(indices)])


def frame_text(axes: tuple[ExtraAxis, ...]) -> str:
    """A short description of what an image holds beyond 3-D, for dialogs and ``info``:
    ``"180 time points (2 s apart)"``."""
    parts = []
    for a in axes:
        step = f" ({a.step:g} {a.unit} apart)".replace("  ", " ") if a.step else ""
        parts.append(a.text() + step)
    return ", ".join(parts)
