"""The default pixel grid of a named slice plane: pixel centres on voxel centres.

:func:`named_slice_grid` places a named plane (``axial`` ... ``z``) of a scene the way
``voxwarp slice`` and :meth:`~voxwarp.render.offscreen.OffscreenRenderer.render_slice`
do by default: through the voxel centre nearest the deformed box's centre, with square
pixels of the smallest voxel side laid out from a voxel centre and grown by whole
pixels to hold the deformed volume. For a plane along the voxel axes the pixel centres
are then voxel centres: the linear slice of an unwarped volume is the array's slice,
not a blur of four voxels.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from voxwarp.core.slice_plane import (
    PLANE_AXIS,
    SlicePlane,
    aligned,
    fit_pixels,
    plane_for_space,
    voxel_anchor,
)
from voxwarp.core.window_presets import default_slice_window


def named_slice_grid(
    scene: Any,
    name: str,
    *,
    at: float | None = None,
    size: tuple[int, int] | None = None,
    pixel_mm: float | None = None,
) -> tuple[SlicePlane, tuple[int, int]]:
    """The plane ``name`` of ``scene`` (a :class:`~voxwarp.scene.Scene`) and its image
    size: at ``at`` mm along its axis (default the voxel centre nearest the deformed
    box's centre); ``size`` given: framed on the deformed box and shifted by less than
    a pixel so a pixel centre is a voxel centre; else pixels of ``pixel_mm`` (default
    the smallest voxel side) on the voxel grid, as many as hold the deformed box."""
    volume = scene.volume
    name = plane_for_space(name, volume.space)  # axial etc. without orientation: z etc.
    lo, hi = (np.asarray(b, dtype=np.float64) for b in scene.deformed_bounds())
    if at is None and name in PLANE_AXIS:
        at = float(voxel_anchor(volume, (lo + hi) / 2)[PLANE_AXIS[name]])
    aspect = 1.0 if size is None else int(size[0]) / int(size[1])
    plane = SlicePlane.named(name, (lo, hi), at=at, aspect=aspect)
    anchor = voxel_anchor(volume, plane.center)
    if size is not None:
        size = (int(size[0]), int(size[1]))
        return aligned(plane, size, anchor), size
    px = float(min(volume.spacing)) if pixel_mm is None else float(pixel_mm)
    return fit_pixels(plane, lo, hi, px, anchor=anchor)


def slice_window(scene: Any) -> tuple[float, float]:
    """The window a slice of ``scene`` opens at: the scene's own (given or saved), else
    :func:`~voxwarp.core.window_presets.default_slice_window` (mediastinum for a CT in
    HU, the percentile window otherwise)."""
    if scene.window_given:
        return scene.window
    return default_slice_window(scene.volume)
