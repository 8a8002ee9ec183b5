"""What a volume is: a CT in Hounsfield units, an MR, or other data, and why.

:mod:`voxwarp.core.modality` picks display defaults from it; the transfer functions'
HU presets ask :func:`is_hu`. This module sits below both.

Modality
--------
* **CT**: the file's DICOM Modality is ``CT`` and the values are Hounsfield units, or
  ``units == "HU"``, or the values *look like* HU: a signed type with a peak of air
  voxels around -1000 (at least 0.5 % of the voxels in [-1100, -900] and twice as many
  per HU there as in [-700, -500]), values up to at least +200, and anything below
  -1100 concentrated on a few padding values. A float MRI (no air peak), a z-scored
  array (no values near -1000), a phase image (values spread evenly over +-4096) or an
  unsigned 0..32 array is not CT.
* A CT whose values are **not** HU (the bundled ``sample:stent`` is a real CT stored as
  0..32) counts as *other*: the HU presets and the -1024 HU padding rule need calibrated
  values, and a percentile ramp shows it without guessing a calibration.
* **MR**: the DICOM Modality (or the bundled sample's metadata) says ``MR``. NIfTI has no
  modality field, so an MRI from a NIfTI file is *other* data; its defaults differ only
  in colour (the ``grayscale``-like ramp instead of ``mri``).
* **other**: everything else; no unit is assumed.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import Literal

import numpy as np

from voxwarp.core.volume import Volume

ModalityKind = Literal["CT", "MR", "other"]

#: At most this many voxels enter the statistics (a regular subsample).
STAT_VOXELS = 2_000_000

# per volume: detected modality and per-mode defaults (the volume's data never change)
_CACHE: weakref.WeakKeyDictionary[Volume, dict[str, object]] = weakref.WeakKeyDictionary()


def volume_cache(volume: Volume) -> dict[str, object]:
    """The per-volume cache (detected modality; :mod:`voxwarp.core.modality`'s defaults)."""
    c = _CACHE.get(volume)
    if c is None:
        c = _CACHE[volume] = {}
    return c


def sample_values(data: np.ndarray) -> np.ndarray:
    """A regular subsample of at most about :data:`STAT_VOXELS` voxels (flattened)."""
    stride = max(1, int(np.ceil((data.size / STAT_VOXELS) ** (1 / 3))))
    return np.asarray(data[::stride, ::stride, ::stride]).ravel()


@dataclass(frozen=True)
class Modality:
    """What a volume is, for display: ``kind`` (``"CT"``, ``"MR"``, ``"other"``),
    ``reason`` (the evidence, e.g. ``"DICOM Modality"``) and ``hu`` (values are HU)."""

    kind: ModalityKind
    reason: str
    hu: bool = False

    def __str__(self) -> str:
        return f"{self.kind} ({self.reason})"


# ---------------------------------------------------------------------------- modality
def _hu_evidence(values: np.ndarray) -> str | None:
    """Why ``values`` look like Hounsfield units, or None (see module docstring)."""
    if values.dtype.kind not in "if" or values.size == 0:
        return None
    v = values.astype(np.float32, copy=False)
    n = v.size
    air = np.count_nonzero((v >= -1100) & (v <= -900))
    between = np.count_nonzero((v >= -700) & (v <= -500))
    if air < 0.005 * n or air < 2 * between:
        return None
    if float(v.max()) < 200:
        return None
    below = v[v < -1100]
    if below.size:
        _, counts = np.unique(below, return_counts=True)
        top = np.sort(counts)[::-1][:3].sum()  # padding: one or a few constant values
        if below.size - top > 0.01 * n:
            return None
    return "values look like HU: an air peak near -1000"


def detect_modality(volume: Volume) -> Modality:
    """The modality of ``volume`` and the evidence (see the module docstring)."""
    cache = volume_cache(volume)
    if "modality" in cache:
        return cache["modality"]  # type: ignore[return-value]
    result = _detect(volume)
    cache["modality"] = result
    return result


def _detect(volume: Volume) -> Modality:
    tag = (volume.modality or "").strip().upper()
    units_hu = volume.units.strip().upper() == "HU"
    lo, hi = volume.value_range
    field = "sample metadata" if (volume.source or "").startswith("sample:") else "DICOM Modality"
    if tag == "MR":
        return Modality("MR", field)
    if units_hu:
        return Modality("CT", field if tag == "CT" else "units HU", hu=True)
    evidence = _hu_evidence(sample_values(volume.data))
    if tag == "CT":
        if evidence is not None:
            return Modality("CT", field, hu=True)
        return Modality("other", f"CT, but values {lo:g}..{hi:g} are not Hounsfield units")
    if evidence is not None:
        return Modality("CT", evidence, hu=True)
    if tag:
        return Modality("other", f"{field} {tag}")
    return Modality("other", "no modality in the file, values not HU")


def is_hu(volume: Volume) -> bool:
    """Whether the values of ``volume`` are Hounsfield units."""
    return detect_modality(volume).hu


__all__ = [
    "STAT_VOXELS",
    "Modality",
    "ModalityKind",
    "detect_modality",
    "is_hu",
    "sample_values",
    "volume_cache",
]
