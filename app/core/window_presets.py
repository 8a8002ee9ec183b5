"""Grey window presets (level, width) for reading slices, per modality.

The CT presets are the radiology reading windows in Hounsfield units (level, width):

===========  =====  =====
preset       level  width
===========  =====  =====
lung          -600   1500
mediastinum     40    400
bone           400   1800
brain           40     80
===========  =====  =====

They need calibrated HU, so they are offered for volumes
:func:`~voxwarp.core.modality_detection.detect_modality` finds to be CT in HU; an MR or
other data gets ``percentile`` only: the robust percentile window of its values
(:func:`~voxwarp.core.modality.display_defaults`). :func:`default_slice_window` is what
slice views open at: ``mediastinum`` (soft tissue) for a CT in HU, the percentile window
otherwise. :func:`parse_window` reads ``--window NAME|LEVEL,WIDTH``.
"""

from __future__ import annotations

import math

from voxwarp.core.modality import display_defaults
from voxwarp.core.modality_detection import detect_modality
from voxwarp.core.volume import Volume
from voxwarp.errors import InputError

#: CT reading windows in HU: name -> (level, width)
CT_PRESETS: dict[str, tuple[float, float]] = {
    "lung": (-600.0, 1500.0),
    "mediastinum": (40.0, 400.0),
    "bone": (400.0, 1800.0),
    "brain": (40.0, 80.0),
}
#: the data-driven preset every volume has (the robust percentile window)
PERCENTILE = "percentile"
#: the preset a CT in HU opens at in the slice views
CT_DEFAULT = "mediastinum"
#: every preset name ``--window`` accepts
PRESET_NAMES: tuple[str, ...] = (*CT_PRESETS, PERCENTILE)


def presets_for(volume: Volume) -> tuple[str, ...]:
    """The preset names that suit ``volume``: the CT windows and ``percentile`` for a CT
    in HU, ``percentile`` only otherwise."""
    return (*CT_PRESETS, PERCENTILE) if detect_modality(volume).hu else (PERCENTILE,)


def preset_window(name: str, volume: Volume) -> tuple[float, float]:
    """The ``(level, width)`` of preset ``name`` for ``volume`` (``percentile``: its
    robust percentile window); an :class:`InputError` naming the presets otherwise."""
    if name == PERCENTILE:
        return display_defaults(volume).window
    if name not in CT_PRESETS:
        raise InputError(
            f"unknown window preset {name!r}; use one of {', '.join(PRESET_NAMES)} or LEVEL,WIDTH"
        )
    modality = detect_modality(volume)
    if not modality.hu:
        raise InputError(
            f"window preset {name!r} is in HU, but the volume is {modality}; use"
            f" {PERCENTILE} or LEVEL,WIDTH in its units"
        )
    return CT_PRESETS[name]


def default_slice_window(volume: Volume) -> tuple[float, float]:
    """The window slices open at: :data:`CT_DEFAULT` for a CT in HU, else the
    percentile window."""
    return preset_window(CT_DEFAULT if detect_modality(volume).hu else PERCENTILE, volume)


def preset_of(window: tuple[float, float], volume: Volume) -> str | None:
    """The name of the preset of ``volume`` whose window is ``window``, or None."""
    for name in presets_for(volume):
        preset = preset_window(name, volume)
        if all(math.isclose(a, b, abs_tol=1e-6) for a, b in zip(preset, window, strict=True)):
            return name
    return None


def parse_window(text: str) -> str | tuple[float, float]:
    """``NAME`` (a preset of :data:`PRESET_NAMES`, resolved per volume later) or
    ``LEVEL,WIDTH`` (numbers, width > 0); an :class:`InputError` otherwise."""
    spec = str(text).strip().lower()
    if spec in PRESET_NAMES:
        return spec
    form = f"{', '.join(PRESET_NAMES)} or LEVEL,WIDTH with WIDTH > 0 (e.g. 40,400)"
    try:
        level, width = (float(v) for v in spec.split(","))
    except ValueError as exc:
        raise InputError(f"window {text!r}: expected {form}") from exc
    if not (math.isfinite(level) and math.isfinite(width) and width > 0):
        raise InputError(f"window {text!r}: expected {form}")
    return level, width


def resolve_window(
    spec: str | tuple[float, float] | None, volume: Volume
) -> tuple[float, float] | None:
    """A parsed ``--window`` for ``volume``: a preset's ``(level, width)``, the pair
    itself, or None (no ``--window``)."""
    if spec is None or not isinstance(spec, str):
        return None if spec is None else (float(spec[0]), float(spec[1]))
    return preset_window(spec, volume)
