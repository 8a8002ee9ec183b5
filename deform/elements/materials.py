"""Tissue presets for element stiffness: a push moves soft tissue around bone.

:func:`preset_stiffness` turns a preset name into the ``(value, stiffness)`` control
points :meth:`ElementGrid.materials_from_volume
<voxwarp.deform.elements.grid.ElementGrid.materials_from_volume>` interpolates:

* ``"ct"``: Hounsfield units. Air (below -400 HU) is free (stiffness
  :data:`FREE`), fat and soft tissue (-100..100 HU) soft, and stiffness climbs through
  dense tissue to bone (300..700 HU and above: :data:`BONE`, stiff but not rigid so a
  dragged bone element still moves).
* ``"mr"``: MRI has no absolute units, so the points come from the volume's own
  histogram: below Otsu's threshold between background and object the elements are
  free; above it they are soft tissue, a little stiffer towards the brightest values.

Choosing ``"ct"`` or ``"mr"`` from a volume's modality (``"auto"``) is the editing
layer's job (it knows the modality detection).
"""

from __future__ import annotations

import numpy as np

from voxwarp.deform.histogram import otsu
from voxwarp.errors import VoxwarpError

#: the presets :func:`preset_stiffness` knows
PRESETS = ("ct", "mr")
#: stiffness of air / background: almost free (not 0, so no element is left unsprung)
FREE = 0.01
#: stiffness of soft tissue
SOFT = 0.3
#: stiffness of bone: stiff, below 1 (rigid elements cannot be dragged)
BONE = 0.95
#: the CT preset (HU -> stiffness)
CT_POINTS = ((-1000.0, FREE), (-400.0, FREE), (-100.0, SOFT), (100.0, SOFT), (700.0, BONE))


class MaterialPresetError(VoxwarpError, ValueError):
    """An unknown material preset (the message lists the known ones)."""


def preset_stiffness(values: np.ndarray, preset: str) -> list[tuple[float, float]]:
    """Control points ``[(value, stiffness), ...]`` of ``preset`` for volume ``values``.

    ``values`` is read only by ``"mr"`` (its histogram); see the module doc.
    """
    if preset == "ct":
        return list(CT_POINTS)
    if preset == "mr":
        return _mr_points(np.asarray(values))
    raise MaterialPresetError(
        f"unknown material preset {preset!r}; choose one of {', '.join(PRESETS)} (or"
        " give VALUE:STIFFNESS points)"
    )


def _mr_points(values: np.ndarray) -> list[tuple[float, float]]:
    """Free below Otsu's threshold, soft above it, up to twice as stiff at the top."""
    v = values[np.isfinite(values)].astype(np.float64).ravel()
    if v.size > 2_000_000:
        v = v[:: v.size // 1_000_000]
    lo, hi = (float(x) for x in np.percentile(v, [0.5, 99.5])) if v.size else (0.0, 1.0)
    if not hi > lo:
        return [(lo, SOFT)]
    t = otsu_threshold(np.clip(v, lo, hi))
    edge = lo + 0.5 * (t - lo)
    return [(edge, FREE), (t, SOFT), (hi, min(2 * SOFT, BONE))]


def otsu_threshold(values: np.ndarray, bins: int = 256) -> float:
    """Otsu's threshold (:func:`~voxwarp.deform.histogram.otsu`), placed midway between
    the two classes' means (any cut in an empty gap splits alike)."""
    split = otsu(values, bins)
    return 0.5 * (split.mean_below + split.mean_above)
