"""The state of the linked slice views (multi-planar reformatting), without Qt.

About linked slice views
------------------------
The GUI shows three orthogonal planes of the deformed volume next to the 3D view, as
3D Slicer and ITK-SNAP do: ``axial``, ``coronal`` and ``sagittal`` for volumes in patient
RAS space, ``z``, ``y`` and ``x`` otherwise (:func:`voxwarp.core.slice_plane.plane_names`).
All three pass through one point, the *crosshair* (world mm): a click in one view moves
it, and with it the two other planes. :class:`SliceViews` holds that point, each view's
zoom, pan and tilt (oblique planes), and what all views share: the window
``(level, width)``, the look (grey window or transfer function), the shown state
(deformed, rest, checkerboard, difference), the slab and the interpolation, and the
window layout (``"2x2"``, ``"1x3"``, ``"3d"``). :meth:`SliceViews.plane` turns one view's
state into the :class:`~voxwarp.core.slice_plane.SlicePlane` the renderer samples.

The widgets (``voxwarp.ui.slice_view``) only translate mouse events into these methods
and paint what :meth:`SliceViews.plane` and :func:`handles_near` give them.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from voxwarp.core.orientation import axis_letters
from voxwarp.core.slice_plane import SlicePlane, aligned, plane_names
from voxwarp.deform.warp import box_corners, rotation_matrix
from voxwarp.errors import SceneError
from voxwarp.render.overlay import OverlayLayer
from voxwarp.render.slice_image import LOOKS, SHOWS
from voxwarp.render.slices import INTERPOLATIONS, SLAB_MODES

#: window layouts: 3D view and three slices in a 2x2 grid, 3D large with the slices in
#: a column, 3D only
LAYOUTS: tuple[str, ...] = ("2x2", "1x3", "3d")
#: fraction of the volume's value range one pixel of a window/level drag changes
WINDOW_DRAG_PER_PX = 1.0 / 512
#: zoom limits of a slice view (1 = the volume fills the view)
MIN_ZOOM, MAX_ZOOM = 0.1, 50.0
#: neighbours of each handle :func:`layer_spacing` looks at
NEIGHBOURS = 26
#: the colour of each plane, as 3D Slicer's views: axial red, sagittal yellow, coronal green
PLANE_COLORS: dict[str, tuple[float, float, float]] = {
    "axial": (0.95, 0.33, 0.33),
    "z": (0.95, 0.33, 0.33),
    "coronal": (0.44, 0.82, 0.36),
    "y": (0.44, 0.82, 0.36),
    "sagittal": (0.93, 0.84, 0.31),
    "x": (0.93, 0.84, 0.31),
}


@dataclasses.dataclass
class ViewState:
    """One slice view: its named plane, zoom (1: the volume fills it), pan (in-plane mm
    along the plane's right and up) and tilt (a rotation of the named plane's axes)."""

    name: str
    zoom: float = 1.0
    pan: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(2))
    tilt: np.ndarray = dataclasses.field(default_factory=lambda: np.eye(3))


class SliceViews:
    """Linked slice views of a volume (see the module docstring).

    Parameters
    ----------
    volume
        The scene's :class:`~voxwarp.core.volume.Volume` (bounds, spacing, orientation,
        value range).
    window
        The initial ``(level, width)``, usually the scene's.
    """

    def __init__(self, volume: Any, window: tuple[float, float]) -> None:
        self.volume = volume
        self.names: tuple[str, str, str] = plane_names(getattr(volume, "space", ""))
        self.default_window = (float(window[0]), float(window[1]))
        self.look = "window"
        self.show = "deformed"
        self.slab_mm = 0.0
        self.slab_mode = "mip"
        self.interpolation = "linear"
        self.layout = "2x2"
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Crosshair at the voxel nearest the volume's centre, views unzoomed, untilted,
        the window back to its default."""
        shape = np.asarray(self.volume.shape)
        self.crosshair = np.asarray(self.volume.index_to_world(shape // 2), dtype=np.float64)
        self.views: dict[str, ViewState] = {n: ViewState(n) for n in self.names}
        self.window = self.default_window

    def set_option(self, name: str, value: Any) -> None:
        """Set ``look``, ``show``, ``slab_mm``, ``slab_mode``, ``interpolation`` or
        ``layout``, checked (a :class:`SceneError` names the allowed values)."""
        allowed = {
            "look": LOOKS,
            "show": SHOWS,
            "slab_mode": tuple(SLAB_MODES),
            "interpolation": INTERPOLATIONS,
            "layout": LAYOUTS,
        }
        if name == "slab_mm":
            v = float(value)
            if not (math.isfinite(v) and v >= 0):
                raise SceneError(f"slab thickness must be a finite number of mm >= 0; got {value}")
            self.slab_mm = v
        elif name in allowed:
            if value not in allowed[name]:
                raise SceneError(f"{name} must be one of {', '.join(allowed[name])}; got {value!r}")
            setattr(self, name, value)
        else:
            raise SceneError(
                f"no slice view option {name!r}; use one of slab_mm, {', '.join(allowed)}"
            )

    def set_crosshair(self, point: Sequence[float]) -> None:
        """Move the crosshair (and so every plane) to ``point`` (world mm), kept inside
        the volume's bounds."""
        p = np.asarray(point, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(p)):
            raise SceneError(f"crosshair must be a finite point; got {p.tolist()}")
        lo, hi = self.volume.bounds
        self.crosshair = np.clip(p, lo, hi)

    # ------------------------------------------------------------------ planes
    def plane(
        self, name: str, aspect: float = 1.0, size: tuple[int, int] | None = None
    ) -> SlicePlane:
        """The plane view ``name`` shows in an image of width/height ``aspect``: the
        named plane through the crosshair framing the volume, tilted about the
        crosshair, then panned and zoomed. With the image ``size`` (W, H) an untilted
        plane is shifted by less than a pixel so that a pixel centre lies on a voxel
        centre: at 1:1 zoom (:meth:`native_zoom`) every pixel shows one voxel."""
        view = self.views[name]
        lo, hi = self.volume.bounds
        base = SlicePlane.named(name, (lo, hi), aspect=aspect).through(self.crosshair)
        if not np.allclose(view.tilt, np.eye(3)):
            c = self.crosshair
            base = SlicePlane(
                c + view.tilt @ (base.center - c),
                view.tilt @ base.right,
                view.tilt @ base.up,
                base.height_mm,
                "oblique",
            )
        center = base.center + view.pan[0] * base.right + view.pan[1] * base.up
        plane = dataclasses.replace(base, center=center, height_mm=base.height_mm / view.zoom)
        if size is None or base.name == "oblique":
            return plane
        # a fixed voxel (the centre one), not the crosshair's: a click keeps the view still
        centre = np.asarray(self.volume.shape) // 2
        return aligned(plane, size, np.asarray(self.volume.index_to_world(centre), float))

    def native_zoom(self, name: str, size: tuple[int, int]) -> float:
        """The zoom of view ``name`` at which one pixel of its ``(W, H)`` image is the
        volume's smallest voxel side (1:1)."""
        unzoomed = self.plane(name, size[0] / size[1]).height_mm * self.views[name].zoom
        return unzoomed / (int(size[1]) * float(min(self.volume.spacing)))

    def step_mm(self, name: str) -> float:
        """One scroll step of view ``name``: the volume's voxel spacing along the
        plane's scroll axis (for an oblique scan or plane, along that direction)."""
        axis = self.plane(name).scroll_axis
        direction = np.asarray(getattr(self.volume, "direction", np.eye(3)), dtype=np.float64)
        in_index = (direction.T @ axis) / np.asarray(self.volume.spacing, dtype=np.float64)
        return float(1.0 / np.linalg.norm(in_index))

    def scroll(self, name: str, steps: float) -> None:
        """Move view ``name``'s plane by ``steps`` voxel spacings along its scroll axis
        (the crosshair moves with it; the plane stays inside the volume)."""
        plane = self.plane(name)
        axis = plane.scroll_axis
        target = self.crosshair + float(steps) * self.step_mm(name) * axis
        corners = box_corners(*(np.asarray(b, float) for b in self.volume.bounds)) @ axis
        along = float(np.clip(target @ axis, corners.min(), corners.max()))
        self.crosshair = target + (along - float(target @ axis)) * axis

    def zoom(self, name: str, factor: float) -> None:
        """Magnify view ``name`` by ``factor`` (kept within :data:`MIN_ZOOM` ..
        :data:`MAX_ZOOM`)."""
        view = self.views[name]
        view.zoom = float(np.clip(view.zoom * float(factor), MIN_ZOOM, MAX_ZOOM))

    def pan(self, name: str, right_mm: float, up_mm: float) -> None:
        """Shift what view ``name`` shows: its centre moves by these mm in the plane."""
        self.views[name].pan = self.views[name].pan + np.array([right_mm, up_mm], float)

    def rotate(self, name: str, degrees: float, about: str = "up") -> None:
        """Tilt view ``name``'s plane by ``degrees`` about its own ``"up"`` or
        ``"right"`` axis through the crosshair (an oblique plane)."""
        if about not in ("up", "right"):
            raise SceneError(f"rotate about 'up' or 'right'; got {about!r}")
        plane = self.plane(name)
        axis = plane.up if about == "up" else plane.right
        view = self.views[name]
        view.tilt = rotation_matrix(axis, float(degrees)) @ view.tilt

    def window_drag(self, dx: float, dy: float) -> None:
        """Slicer's window/level drag by ``(dx, dy)`` pixels: right widens the window,
        down raises the level, each pixel :data:`WINDOW_DRAG_PER_PX` of the value range."""
        vmin, vmax = self.volume.value_range
        scale = max(vmax - vmin, 1e-6) * WINDOW_DRAG_PER_PX
        level, width = self.window
        self.window = (level + float(dy) * scale, max(width + float(dx) * scale, scale / 4))

    # ------------------------------------------------------------------ drawing helpers
    def outline_layers(self) -> list[OverlayLayer]:
        """The three planes where they cut the volume's box, as line layers in their
        colours (the 3D view shows them)."""
        lo, hi = (np.asarray(b, float) for b in self.volume.bounds)
        layers = []
        for name in self.names:
            ring = plane_box_polygon(self.plane(name), lo, hi)
            if len(ring) >= 3:
                segments = np.repeat(np.vstack([ring, ring[:1]]), 2, axis=0)[1:-1]
                color = (*PLANE_COLORS[name], 1.0)
                layers.append(OverlayLayer("lines", segments, color, name=f"{name} plane"))
        return layers


def plane_box_polygon(plane: SlicePlane, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(N, 3) corners, in order around it, of the polygon where ``plane`` cuts the box
    ``lo``..``hi`` (empty when it misses the box)."""
    corners = box_corners(lo, hi)
    d = (corners - plane.center) @ plane.normal
    eps = 1e-9 * max(float(np.max(hi - lo)), 1.0)
    points = [corners[i] for i in range(8) if abs(d[i]) <= eps]
    for i in range(8):
        for j in range(i + 1, 8):
            edge = np.count_nonzero(corners[i] != corners[j]) == 1
            if edge and d[i] * d[j] < 0 and abs(d[i]) > eps and abs(d[j]) > eps:
                t = d[i] / (d[i] - d[j])
                points.append(corners[i] + t * (corners[j] - corners[i]))
    if len(points) < 3:
        return np.zeros((0, 3))
    pts = np.unique(np.round(np.asarray(points), 9), axis=0)
    mid = pts.mean(axis=0)
    rel = pts - mid
    angle = np.arctan2(rel @ plane.up, rel @ plane.right)
    return pts[np.argsort(angle)]


def handles_near(
    points: np.ndarray, plane: SlicePlane, size: tuple[int, int], slab_mm: float = 0.0
) -> np.ndarray:
    """Indices of the handles a slice view draws: those within :func:`near_plane_mm`
    of ``plane``."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0:
        return np.zeros(0, dtype=int)
    dist = np.abs((pts - plane.center) @ plane.normal)
    return np.flatnonzero(dist <= near_plane_mm(pts, plane, size, slab_mm))


def near_plane_mm(
    points: np.ndarray, plane: SlicePlane, size: tuple[int, int], slab_mm: float = 0.0
) -> float:
    """How far from ``plane`` a handle may lie and still show in (and be picked from) a
    slice view: max(half the slab, one pixel, half the handles' spacing along the
    normal), so that a grid's nearest layer of elements always shows."""
    return max(slab_mm / 2, plane.pixel_mm(size), layer_spacing(points, plane.normal) / 2)


def layer_spacing(points: np.ndarray, normal: np.ndarray) -> float:
    """The handles' typical spacing along ``normal``: for each handle, the nearest of its
    :data:`NEIGHBOURS` nearest handles that lies mostly along ``normal`` (within about
    45 degrees), its distance along ``normal``; the median of those (a grid's layer
    spacing, also when deformed; 0 when no handle has a neighbour that way)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) < 2:
        return 0.0
    from scipy.spatial import cKDTree

    n = np.asarray(normal, dtype=np.float64).reshape(3)
    k = min(len(pts), NEIGHBOURS + 1)
    dist, idx = cKDTree(pts).query(pts, k=k)
    off = pts[idx[:, 1:]] - pts[:, None, :]
    along = np.abs(off @ n)
    aligned = along > 0.7 * np.maximum(dist[:, 1:], 1e-12)
    gap = np.where(aligned, along, np.inf).min(axis=1)
    gap = gap[np.isfinite(gap)]
    return float(np.median(gap)) if len(gap) else 0.0


def readout(
    point: Sequence[float], space: str, deformed: float, rest: float, rest_label: str = "rest"
) -> str:
    """The position line of a slice view: patient mm as Slicer writes it for RAS
    volumes (the letter of the side, then the distance: ``L 12.2  A 3.0  S 0.0``), signed
    ``x``, ``y``, ``z`` otherwise, then the deformed and rest values (5 significant
    digits: the texture's float interpolation is not exact to more); ``rest_label``
    names the second value (``"fixed"`` with a fixed image)."""
    p = np.asarray(point, dtype=np.float64).reshape(3)
    if space == "RAS":
        parts = [f"{axis_letters(a, v)} {abs(v):.1f}" for a, v in enumerate(p)]
    else:
        parts = [f"{a} {v:+.1f}" for a, v in zip(("x", "y", "z"), p, strict=True)]
    return f"{'  '.join(parts)} mm   deformed {_value(deformed)}   {rest_label} {_value(rest)}"


def _value(v: float) -> str:
    return "—" if not math.isfinite(v) else f"{v:.5g}"


def scale_bar_mm(pixel_mm: float, max_px: float) -> float:
    """A round length (1, 2 or 5 times a power of ten mm) that fits in ``max_px``
    pixels of ``pixel_mm`` mm each."""
    longest = max(float(pixel_mm) * float(max_px), 1e-9)
    k = 10.0 ** math.floor(math.log10(longest))
    return max(m * k for m in (1, 2, 5) if m * k <= longest)


def edge_labels(plane: SlicePlane, space: str) -> dict[str, str]:
    """Labels at a slice image's ``left``, ``right``, ``top`` and ``bottom`` edges:
    patient letters (:meth:`SlicePlane.letters`) for RAS volumes, else the signed world
    axis each edge's direction mostly points along (``"+x"``, ``"-z"``)."""
    if space == "RAS":
        return plane.letters()
    out = {}
    for side, v in (
        ("right", plane.right),
        ("left", -plane.right),
        ("top", plane.up),
        ("bottom", -plane.up),
    ):
        axis = int(np.argmax(np.abs(v)))
        out[side] = ("+" if v[axis] >= 0 else "-") + "xyz"[axis]
    return out
