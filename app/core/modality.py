"""Modality-aware display defaults: what a volume is, and how to show it without options.

:func:`detect_modality` says whether a volume is a CT in Hounsfield units, an MR, or
other data, and why. :func:`display_defaults` picks the transfer function, window and
shading for a render mode from that; :func:`mask_padding` replaces the padding outside a
CT's field of view; :func:`iso_range_warning` names an iso value the data never reach.

Modality
--------
Detected by :mod:`voxwarp.core.modality_detection` (the rules are listed there).

Defaults
--------
========  ===========================  ==========================================
modality  transfer function (dvr,      window (mip, minip, average, xray)
          flm, iso)
========  ===========================  ==========================================
CT        ``ct-bone`` (HU), shaded     robust percentiles of the voxels inside the
MR        ``mri`` (0.5-99.5 %), shaded field of view (padding excluded):
other     ``ramp`` over 1-99.9 %,      mip 1-99.9 %, minip 0.5-99.5 %,
          shaded                       average 1-99.5 %; xray from 1 %, white at
                                       the 99.5th percentile of the line integrals
                                       along the volume axes
========  ===========================  ==========================================

Shading (when ``shading`` is not given): ``iso`` and ``flm`` always; ``dvr`` where the
transfer function shows surfaces, i.e. for the presets in :data:`SURFACE_PRESETS`
(``ct-bone``, ``ct-skin``, ``ct-muscle``, ``mri`` and the automatic ``ramp``: they rise
steeply to a high opacity, so the first opaque layer is a surface a light makes
readable). ``ct-soft``, ``grayscale`` and ``hot`` stay unshaded: they are translucent
over a wide range (a fog, where gradients mostly show noise), as are custom control
points, whose intent voxwarp cannot know.

Padding
-------
Voxels outside the scanner's field of view carry a padding value (DICOM
PixelPaddingValue, often -2048 or -3024): in a CT, those and any value below -1024 HU.
:func:`mask_padding` replaces them by the **minimum value inside the field of view**
(the air, about -1024 HU, in a CT): then the padding looks like the air around the
patient in every mode and stops stretching the windows. ``voxwarp render --keep-padding``
(``load_input(..., keep_padding=True)``) keeps the file's values.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, replace

import numpy as np

from voxwarp.core.modality_detection import (
    STAT_VOXELS,
    Modality,
    detect_modality,
    is_hu,
    sample_values,
    volume_cache,
)
from voxwarp.core.modes import xray_reference_length
from voxwarp.core.transfer_function import TransferFunction
from voxwarp.core.volume import Volume

#: Presets that show surfaces: DVR shades them by default (see module docstring).
SURFACE_PRESETS: frozenset[str] = frozenset({"ct-bone", "ct-skin", "ct-muscle", "mri", "ramp"})
#: The default transfer function preset per modality (``ramp`` is built per volume).
DEFAULT_PRESETS: dict[str, str] = {"CT": "ct-bone", "MR": "mri", "other": "ramp"}
#: Modes that draw through the transfer function (the others use the window).
TF_MODES: frozenset[str] = frozenset({"dvr", "flm", "iso"})
#: Percentiles (of the voxels inside the field of view) of the default window per mode.
WINDOW_PERCENTILES: dict[str, tuple[float, float]] = {
    "mip": (1.0, 99.9),
    "minip": (0.5, 99.5),
    "average": (1.0, 99.5),
    "xray": (1.0, 99.5),
}
#: The ``xray`` window's width: this percentile of the line integrals shows white.
XRAY_WHITE_PERCENTILE = 99.5
#: The ``xray`` window is estimated on a volume strided to about this many voxels per axis.
XRAY_ESTIMATE_VOXELS = 128
#: Percentiles the ``ramp`` transfer function of *other* data spans.
RAMP_PERCENTILES: tuple[float, float] = (1.0, 99.9)
#: In a CT (HU), values below this are padding outside the field of view.
HU_PADDING_BELOW = -1024.0


@dataclass(frozen=True)
class DisplayDefaults:
    """The defaults :func:`display_defaults` chose for one volume and mode.

    ``transfer_function`` (resolved to the volume's values), ``window`` ``(level,
    width)``, ``shading`` (for this mode), ``modality`` and ``description``: one line
    saying what was chosen and why (printed by ``voxwarp render``, shown by the GUI).
    """

    modality: Modality
    transfer_function: TransferFunction
    window: tuple[float, float]
    shading: bool
    description: str


# volumes mask_padding produced -> (padding text, voxel count), for the description
_MASKED: weakref.WeakKeyDictionary[Volume, tuple[str, int]] = weakref.WeakKeyDictionary()


# ---------------------------------------------------------------------------- padding
def padding_mask(volume: Volume) -> np.ndarray | None:
    """True at padding voxels (outside the field of view), or None when there are none:
    the file's ``padding_value``; in a CT (HU) also every value below -1024."""
    data = volume.data
    mask = None
    if volume.padding_value is not None:
        mask = data == np.asarray(volume.padding_value, dtype=data.dtype)
    if data.dtype.kind in "if" and volume.value_range[0] < HU_PADDING_BELOW and is_hu(volume):
        below = data < HU_PADDING_BELOW
        mask = below if mask is None else (mask | below)
    if mask is None or not mask.any():
        return None
    return mask


def _padding_text(volume: Volume, mask: np.ndarray) -> str:
    values = np.unique(volume.data[mask])
    if values.size == 1:
        return f"{values[0]:g}"
    return f"{values.min():g}..{values.max():g}"


def mask_padding(volume: Volume) -> tuple[Volume, int]:
    """``(volume, count)``: ``volume`` with its padding voxels (:func:`padding_mask`)
    replaced by the minimum value inside the field of view, and how many there were.

    Returns the volume itself and 0 when it has no padding (or nothing but padding).
    The result keeps the geometry, name, source and units.
    """
    mask = padding_mask(volume)
    if mask is None:
        return volume, 0
    count = int(np.count_nonzero(mask))
    if count == volume.data.size:
        return volume, 0
    inside = volume.data[~mask]
    fill = inside.min()
    text = _padding_text(volume, mask)
    data = np.array(volume.data, order="F", copy=True)
    data[mask] = fill
    out = replace(volume, data=data, _range=None, _window=None)
    _MASKED[out] = (text, count)
    # the masked copy is the same modality (the evidence was read on the raw values),
    # and its statistics still leave the (former) padding out
    volume_cache(out).update(modality=detect_modality(volume), inside=_thin(inside))
    return out, count


def _count_text(n: int) -> str:
    if n >= 1_000_000:
        return f"{n / 1e6:.1f} M"
    if n >= 1_000:
        return f"{n / 1e3:.0f} k"
    return str(n)


# ---------------------------------------------------------------------------- defaults
def inside_values(volume: Volume) -> np.ndarray:
    """A subsample of the voxel values inside the field of view (padding excluded)."""
    cache = volume_cache(volume)
    if "inside" not in cache:
        mask = padding_mask(volume)
        if mask is None or mask.all():
            cache["inside"] = sample_values(volume.data)
        else:
            cache["inside"] = _thin(volume.data[~mask])
    return cache["inside"]  # type: ignore[return-value]


def _thin(values: np.ndarray) -> np.ndarray:
    """Every n-th of the (flat) ``values``, at most about :data:`STAT_VOXELS`."""
    return values[:: max(1, values.size // STAT_VOXELS)]


def robust_range(volume: Volume, lo: float, hi: float) -> tuple[float, float]:
    """Percentiles ``lo`` and ``hi`` of the values inside the field of view; widened to
    the value range (and then to one unit) when they coincide."""
    p_lo, p_hi = (float(x) for x in np.percentile(inside_values(volume), [lo, hi]))
    if p_hi <= p_lo:
        p_lo, p_hi = volume.value_range
    if p_hi <= p_lo:
        p_hi = p_lo + 1.0
    return p_lo, p_hi


def _window(volume: Volume, mode: str) -> tuple[float, float]:
    lo, hi = robust_range(volume, *WINDOW_PERCENTILES.get(mode, (1.0, 99.5)))
    if mode == "xray":
        return _xray_window(volume, lo)
    return 0.5 * (lo + hi), hi - lo


def _xray_window(volume: Volume, low: float) -> tuple[float, float]:
    """``xray``'s window: the low end at the 1st value percentile (zero attenuation, the
    air), the width such that the 99.5th percentile of the line integrals along the three
    volume axes (over the mode's reference length) shows as white, so a radiograph of
    mostly empty data is not dim."""
    step = max(1, max(volume.shape) // XRAY_ESTIMATE_VOXELS)
    sub = np.maximum(volume.data[::step, ::step, ::step].astype(np.float32) - low, 0.0)
    length = xray_reference_length(volume)
    tops = []
    for axis in range(3):
        line = sub.sum(axis=axis) * (step * volume.spacing[axis]) / length
        tops.append(float(np.percentile(line, XRAY_WHITE_PERCENTILE)))
    width = max(tops)
    if not (np.isfinite(width) and width > 0):
        width = 1.0
    return low + 0.5 * width, width


def ramp_transfer_function(volume: Volume) -> TransferFunction:
    """The ``ramp`` of *other* data: transparent at the 1st percentile, rising with the
    square of the value to white at the 99.9th (values inside the field of view); dim
    low values stay a faint haze, the brightest structures become surfaces."""
    lo, hi = robust_range(volume, *RAMP_PERCENTILES)
    pts = []
    for f in (0.0, 0.1, 0.25, 0.5, 0.75, 1.0):
        grey = 0.35 + 0.65 * f
        pts.append((lo + f * (hi - lo), grey, grey, grey, 0.85 * f * f))
    return TransferFunction(pts, name="ramp")


def default_transfer_function(volume: Volume) -> TransferFunction:
    """The default transfer function of ``volume`` for its modality."""
    preset = DEFAULT_PRESETS[detect_modality(volume).kind]
    if preset == "ramp":
        return ramp_transfer_function(volume)
    return TransferFunction.preset(preset, volume)


def default_shading(mode: str, tf: TransferFunction) -> bool:
    """Shading when none is given: ``iso``/``flm`` always, ``dvr`` for surface presets."""
    if mode in ("iso", "flm"):
        return True
    return mode == "dvr" and tf.name in SURFACE_PRESETS


def display_defaults(volume: Volume, mode: str = "dvr") -> DisplayDefaults:
    """Transfer function, window, shading and a one-line description for ``mode``."""
    cache = volume_cache(volume)
    key = f"defaults:{mode}"
    if key in cache:
        return cache[key]  # type: ignore[return-value]
    modality = detect_modality(volume)
    tf = cache.get("tf")
    if tf is None:
        tf = cache["tf"] = default_transfer_function(volume)
    window = _window(volume, mode)
    shading = default_shading(mode, tf)  # type: ignore[arg-type]
    result = DisplayDefaults(
        modality,
        tf,  # type: ignore[arg-type]
        window,
        shading,
        describe(volume, mode, tf, window, shading),  # type: ignore[arg-type]
    )
    cache[key] = result
    return result


def describe(
    volume: Volume,
    mode: str,
    tf: TransferFunction,
    window: tuple[float, float],
    shading: bool,
    *,
    window_given: bool = False,
    level: str | None = None,
    hint: str | None = None,
) -> str:
    """One line: the modality and its evidence, what ``mode`` draws with, the padding
    (``window_given``: the window is the user's, not from the percentiles; ``level``:
    the iso value or FLM threshold and why; ``hint``: advice appended at the end)."""
    modality = detect_modality(volume)
    unit = " HU" if modality.hu else ""
    if mode in TF_MODES:
        what = f"tf {tf.name}, {'shaded' if shading else 'unshaded'} {mode.upper()}"
        if level is not None:
            what += f", {level}"
    else:
        pct = WINDOW_PERCENTILES.get(mode, (1.0, 99.5))
        what = f"{mode.upper()} window {window[0]:.4g}/{window[1]:.4g}{unit}"
        if not window_given and mode == "xray":
            what += f" (from the {pct[0]:g} % value, white at the thickest material)"
        elif not window_given:
            what += f" (percentiles {pct[0]:g}-{pct[1]:g} inside the field of view)"
    text = f"{modality}: {what}"
    masked = _MASKED.get(volume)
    if masked is not None:
        text += f"; padding {masked[0]} masked ({_count_text(masked[1])} voxels)"
    else:
        mask = padding_mask(volume)
        if mask is not None:
            text += (
                f"; padding {_padding_text(volume, mask)} kept"
                f" ({_count_text(int(np.count_nonzero(mask)))} voxels)"
            )
    return text if hint is None else f"{text}; {hint}"


def uses_transfer_function(mode: str) -> bool:
    """Whether ``mode`` draws through the transfer function (dvr, flm, iso)."""
    return mode in TF_MODES


def iso_range_warning(volume: Volume, iso: float) -> str | None:
    """One line when ``iso`` lies outside the data range of ``volume``, else None."""
    lo, hi = volume.value_range
    if lo <= iso <= hi:
        return None
    suggestion = robust_range(volume, 50.0, 99.5)
    return (
        f"iso value {iso:g} lies outside the data range {lo:g}..{hi:g} of volume"
        f" {volume.name!r}: the image shows no surface; give an iso value (--iso)"
        f" between {lo:g} and {hi:g} (e.g. {0.5 * (suggestion[0] + suggestion[1]):.4g})"
    )
