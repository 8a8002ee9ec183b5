"""An automatic wire for data voxwarp has never seen (``voxwarp demo INPUT``).

A wire laid blindly (say, up the middle of the box) cuts whatever it ends inside and
sweeps air and neighbours along with the object. :func:`auto_wire` lays it where it is
safe instead:

1. **Object.** The volume (thinned to at most :data:`MAX_SAMPLES` voxels) is split at an
   Otsu threshold of its values between the 0.5th and 99.5th percentiles (air against
   tissue in a CT, background against head in an MRI, whatever the units); the largest
   6-connected part above it is the object.
2. **Axis.** The wire runs along the object's principal axis (the largest eigenvector of
   its voxels' covariance, in world mm) through its centroid (when a view is given and
   that axis points along it, along the second axis instead if the object is at least
   :data:`SIDE_EXTENT` as long that way: a bend along the view would hardly show), from
   :data:`END_MARGIN` of the object's length before its first voxel along that axis to as
   far after its last, so both ends lie outside the object.
3. **Radius.** It covers the object: the 99.5th percentile of the object voxels' distance
   from the axis plus two voxels (the sweep is rigid within the radius; the smooth fade
   lies beyond it).
4. **Bend.** The modified wire leans sideways by :data:`BEND` of the wire's length at
   its far end (quadratically from the start): across the view when one is given (so
   the bend shows), else along the second principal axis. No twist: a scan often cuts
   its object at the box's faces, and a twist would turn such a cut face into view.
   β is the object's value range, with plane masks, so only the object the wire runs
   through moves; the ends are smooth.

It skips (returns no wire, with the reason) when no object stands out: nothing above
the threshold, an object under :data:`MIN_OBJECT` of the volume, or one filling more than
:data:`MAX_OBJECT` of it (the threshold did not separate anything).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage

from voxwarp.deform.histogram import otsu
from voxwarp.deform.wires.field import Wire

#: most voxels the object search looks at (the volume is thinned by a whole stride)
MAX_SAMPLES = 96**3
#: how far each wire end lies beyond the object, as a share of its length
END_MARGIN = 0.1
#: sideways lean of the modified wire's far end, as a share of the wire's length
BEND = 0.2
#: how long (a share of the principal extent) the second axis must be to carry the wire
#: when the principal axis points along the view
SIDE_EXTENT = 0.6
#: the smallest and largest object, as shares of the (thinned) volume's voxels
MIN_OBJECT = 0.005
MAX_OBJECT = 0.9


@dataclass
class AutoWire:
    """What :func:`auto_wire` decided: the wire (None when it skipped) and one line
    saying what it did or why it skipped."""

    wire: Wire | None
    message: str


def otsu_threshold(values: np.ndarray, bins: int = 256) -> float:
    """The Otsu threshold of ``values`` (:func:`~voxwarp.deform.histogram.otsu`'s edge)."""
    return otsu(values, bins).edge


def auto_wire(volume: Any, view: Any = None) -> AutoWire:
    """A safe demo wire for ``volume`` (see the module docstring).

    Parameters
    ----------
    volume
        A :class:`voxwarp.core.volume.Volume` (any modality, orientation, spacing).
    view
        Optional direction (x, y, z) the camera looks along: the wire bends across it.

    Returns
    -------
    AutoWire
        The wire, or None and the reason it was skipped.
    """
    data = np.asarray(volume.data)
    stride = max(1, int(np.ceil((data.size / MAX_SAMPLES) ** (1 / 3))))
    thin = data[::stride, ::stride, ::stride].astype(np.float32)
    lo, hi = np.percentile(thin, [0.5, 99.5])
    if not hi > lo:
        return AutoWire(None, "skipped the wire: the volume's values are (nearly) constant")
    level = otsu_threshold(np.clip(thin, lo, hi))
    labels, n = ndimage.label(thin > level)
    if n == 0:
        return AutoWire(None, f"skipped the wire: nothing above the threshold {level:.4g}")
    sizes = np.bincount(labels.ravel())[1:]
    share = float(sizes.max()) / thin.size
    if share < MIN_OBJECT or share > MAX_OBJECT:
        return AutoWire(
            None,
            f"skipped the wire: the largest object above {level:.4g} fills {100 * share:.1f}%"
            f" of the volume (no single object stands out)",
        )
    idx = np.argwhere(labels == int(np.argmax(sizes)) + 1) * stride
    pts = volume.index_to_world(idx.astype(np.float64))
    wire = _wire_along(pts, volume, level, float(data.max()), view)
    return AutoWire(wire, _summary(wire, level))


def _axes(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centroid and the first two principal axes of points (N, 3)."""
    centre = pts.mean(axis=0)
    _, vecs = np.linalg.eigh(np.cov((pts - centre).T))
    return centre, vecs[:, 2], vecs[:, 1]


def _wire_along(pts: np.ndarray, volume: Any, level: float, top: float, view: Any) -> Wire:
    """The demo wire along the principal axis of the object points ``pts``."""
    centre, axis, side = _axes(pts)
    if view is not None:
        v = np.asarray(view, dtype=np.float64) / np.linalg.norm(view)
        extent = [float(np.ptp((pts - centre) @ a)) for a in (axis, side)]
        if abs(axis @ v) > 0.7 and extent[1] >= SIDE_EXTENT * extent[0]:
            axis, side = side, axis
        across = np.cross(axis, np.asarray(view, dtype=np.float64))
        if np.linalg.norm(across) > 0.3 * np.linalg.norm(view):  # not along the wire
            side = across / np.linalg.norm(across)
    along = (pts - centre) @ axis
    first, last = float(along.min()), float(along.max())
    margin = END_MARGIN * (last - first) + 2.0 * float(np.max(volume.spacing))
    first, last = first - margin, last + margin
    across = np.linalg.norm(pts - centre - np.outer(along, axis), axis=1)
    radius = float(np.percentile(across, 99.5)) + 2.0 * float(np.max(volume.spacing))
    s = np.linspace(0.0, 1.0, 4)
    base = centre + np.outer(first + s * (last - first), axis)
    modified = base + np.outer(BEND * (last - first) * s**2, side)
    return Wire(
        base,
        modified,
        radius=radius,
        beta=(level, max(top, level)),
        ends="smooth",
        sides="rigid",  # the teaching demo shows the paper's sweep of the object
        name="auto",
    )


def _summary(wire: Wire, level: float) -> str:
    ends = wire.base.control_points[[0, -1]]
    axis = (ends[1] - ends[0]) / np.linalg.norm(ends[1] - ends[0])
    return (
        f"wire along the largest object (values above {level:.4g}): axis"
        f" {np.round(axis, 2).tolist()}, {np.linalg.norm(ends[1] - ends[0]):.0f} mm,"
        f" radius {wire.radius:.0f} mm, both ends outside it"
    )
