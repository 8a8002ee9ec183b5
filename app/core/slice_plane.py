"""Slice planes: where a 2D slice view cuts world space and how its pixels map to mm.

About slice planes
------------------
A :class:`SlicePlane` is a rectangle in world space (patient mm): its centre
``center``, two unit in-plane axes ``right`` (image columns, left to right) and ``up``
(image rows, bottom to top) and the height ``height_mm`` the image shows; the width
follows from the image's aspect, so pixels are square, as an orthographic camera's
(:meth:`SlicePlane.camera`). Its normal ``right x up`` points *towards the viewer*.

Named planes follow the radiological convention of 3D Slicer and ITK-SNAP when world
space is patient RAS (``Volume.space == "RAS"``):

========  =====================  ==================  =====================
plane     normal (scroll axis)    image right          image top
========  =====================  ==================  =====================
axial     S (+z), seen from I     patient left (L)     anterior (A)
coronal   A (+y), seen from A     patient left (L)     superior (S)
sagittal  R (+x), seen from L     posterior (P)        superior (S)
========  =====================  ==================  =====================

(The normal column names the world axis a plane's *position* is measured along:
``axial at 12`` is the plane z = 12 mm, S positive.) Volumes without a patient
orientation get the plain axis planes ``"x"``, ``"y"`` and ``"z"`` (the plane normal to
that world axis; ``z``: +x right, +y up; ``y``: +x right, +z up; ``x``: +y right, +z
up), the layout of :mod:`voxwarp.render.field_views`.

Oblique planes: :meth:`SlicePlane.oblique` takes any point and normal and tilts the
named plane closest to that normal onto it (the smallest rotation), so the image stays
upright the way the user knows it; :meth:`SlicePlane.rotated` turns a plane about its
in-plane axes (the GUI's oblique handles). :func:`parse_plane` reads the command line's
``axial|coronal|sagittal|x|y|z|X,Y,Z:NX,NY,NZ`` (a point and a normal in world mm).

Pixels: pixel ``(col, row)`` of a ``(W, H)`` image (row 0 at the top) has its centre at
``pixel_to_world(size) @ (col, row, 0, 1)``; :meth:`SlicePlane.world_to_pixel` is the
inverse in the plane (and reports each point's signed distance from it).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from voxwarp.core.camera import Camera
from voxwarp.core.orientation import axis_letters
from voxwarp.deform.warp import box_corners, rotation_matrix
from voxwarp.errors import SceneError

#: (right, up) of each named plane; the normal is right x up
_AXES: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    "axial": ((-1, 0, 0), (0, 1, 0)),
    "coronal": ((-1, 0, 0), (0, 0, 1)),
    "sagittal": ((0, -1, 0), (0, 0, 1)),
    "x": ((0, 1, 0), (0, 0, 1)),
    "y": ((1, 0, 0), (0, 0, 1)),
    "z": ((1, 0, 0), (0, 1, 0)),
}
#: the world axis each named plane's position is measured along (its scroll axis)
PLANE_AXIS: dict[str, int] = {"axial": 2, "coronal": 1, "sagittal": 0, "x": 0, "y": 1, "z": 2}
#: planes of volumes in patient RAS space, and of volumes without an orientation
ANATOMICAL_PLANES: tuple[str, ...] = ("axial", "coronal", "sagittal")
AXIS_PLANES: tuple[str, ...] = ("z", "y", "x")
PLANE_NAMES: tuple[str, ...] = (*ANATOMICAL_PLANES, *AXIS_PLANES)
#: largest image side :func:`native_size` returns
MAX_SLICE_PIXELS = 4096


#: the world axis plane each anatomical plane name means on a volume without a patient
#: orientation
AXIS_OF: dict[str, str] = {"axial": "z", "coronal": "y", "sagittal": "x"}


def plane_for_space(name: str, space: str) -> str:
    """The named plane to draw for a volume in ``space``: an anatomical name on a
    volume without a patient orientation (``space != "RAS"``) becomes the plane normal
    to its world axis (axial -> z, coronal -> y, sagittal -> x), whose layout does not
    pretend to know where the patient's left is; other names are kept."""
    return AXIS_OF.get(name, name) if space != "RAS" else name


def plane_names(space: str) -> tuple[str, str, str]:
    """The three orthogonal planes a volume's views show: anatomical for patient RAS
    space (``space == "RAS"``), x/y/z otherwise (order: axial/z, coronal/y, sagittal/x)."""
    return ANATOMICAL_PLANES if space == "RAS" else AXIS_PLANES  # type: ignore[return-value]


def _unit(v: Sequence[float], what: str) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64).reshape(3)
    n = float(np.linalg.norm(a))
    if not (np.all(np.isfinite(a)) and n > 1e-12):
        raise SceneError(f"{what} must be a finite non-zero 3-vector; got {a.tolist()}")
    return a / n


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking unit vector ``a`` onto unit vector ``b``."""
    v = np.cross(a, b)
    c = float(a @ b)
    if c < -1 + 1e-12:  # opposite: half a turn about any axis normal to a
        axis = np.cross(a, [1.0, 0, 0] if abs(a[0]) < 0.9 else [0, 1.0, 0])
        axis /= np.linalg.norm(axis)
        return 2 * np.outer(axis, axis) - np.eye(3)
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k / (1 + c)


@dataclasses.dataclass(frozen=True)
class SlicePlane:
    """A slice plane in world mm (see the module docstring).

    Parameters
    ----------
    center
        World point at the image centre (mm).
    right, up
        Orthonormal in-plane axes: image columns run along ``right``, rows upwards
        along ``up``.
    height_mm
        World height the image shows (its width follows the image's aspect).
    name
        ``"axial"``, ``"coronal"``, ``"sagittal"``, ``"x"``, ``"y"``, ``"z"`` or
        ``"oblique"``.
    """

    center: np.ndarray
    right: np.ndarray
    up: np.ndarray
    height_mm: float = 100.0
    name: str = "oblique"

    def __post_init__(self) -> None:
        c = np.asarray(self.center, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(c)):
            raise SceneError(f"slice centre must be finite; got {c.tolist()}")
        r = _unit(self.right, "slice right axis")
        u = np.asarray(self.up, dtype=np.float64).reshape(3)
        u = _unit(u - (u @ r) * r, "slice up axis (not parallel to right)")
        h = float(self.height_mm)
        if not (math.isfinite(h) and h > 0):
            raise SceneError(f"slice height must be positive and finite; got {h}")
        object.__setattr__(self, "center", c)
        object.__setattr__(self, "right", r)
        object.__setattr__(self, "up", u)
        object.__setattr__(self, "height_mm", h)

    # ------------------------------------------------------------------ construction
    @classmethod
    def named(
        cls,
        name: str,
        bounds: tuple[Sequence[float], Sequence[float]],
        at: float | None = None,
        aspect: float = 1.0,
    ) -> SlicePlane:
        """The named plane (``axial``, ``coronal``, ``sagittal``, ``x``, ``y``, ``z``)
        framing the box ``bounds = (lo, hi)`` in an image of width/height ``aspect``;
        ``at`` is its position in mm along :data:`PLANE_AXIS` (default: the box centre)."""
        if name not in _AXES:
            raise SceneError(f"unknown plane {name!r}; use one of {', '.join(PLANE_NAMES)}")
        right, up = _AXES[name]
        lo, hi = (np.asarray(b, dtype=np.float64).reshape(3) for b in bounds)
        center = (lo + hi) / 2
        if at is not None:
            center[PLANE_AXIS[name]] = _finite(at, "slice position")
        plane = cls(center, np.asarray(right, float), np.asarray(up, float), 1.0, name)
        return plane.framing(lo, hi, aspect)

    @classmethod
    def oblique(
        cls,
        point: Sequence[float],
        normal: Sequence[float],
        bounds: tuple[Sequence[float], Sequence[float]],
        aspect: float = 1.0,
        names: Sequence[str] = ANATOMICAL_PLANES,
    ) -> SlicePlane:
        """The plane through ``point`` normal to ``normal``: the plane of ``names``
        whose normal is closest to it, tilted onto it by the smallest rotation, framing
        ``bounds``."""
        n = _unit(normal, "slice normal")
        p = np.asarray(point, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(p)):
            raise SceneError(f"slice point must be finite; got {p.tolist()}")
        best = max(names, key=lambda k: abs(float(np.cross(*_AXES[k]) @ n)))
        r0, u0 = (np.asarray(v, float) for v in _AXES[best])
        n0 = np.cross(r0, u0)
        if n0 @ n < 0:
            n = -n  # keep the named plane's side: the same image, not its mirror
        rot = _rotation_between(n0, n)
        name = best if np.allclose(n, n0, atol=1e-9) else "oblique"
        plane = cls(p, rot @ r0, rot @ u0, 1.0, name)
        lo, hi = (np.asarray(b, dtype=np.float64).reshape(3) for b in bounds)
        return plane.framing(lo, hi, aspect)  # recentred in-plane: the point stays on it

    def framing(self, lo: np.ndarray, hi: np.ndarray, aspect: float = 1.0) -> SlicePlane:
        """This plane recentred in-plane on the box ``lo``..``hi`` and sized to show all
        of it (5 % margin) in an image of width/height ``aspect``."""
        corners = box_corners(lo, hi)
        rel = corners - self.center
        x, y = rel @ self.right, rel @ self.up
        cx, cy = (x.min() + x.max()) / 2, (y.min() + y.max()) / 2
        height = max(float(y.max() - y.min()), float(x.max() - x.min()) / max(aspect, 1e-9))
        center = self.center + cx * self.right + cy * self.up
        return dataclasses.replace(self, center=center, height_mm=max(height * 1.05, 1e-3))

    # ------------------------------------------------------------------ geometry
    @property
    def normal(self) -> np.ndarray:
        """Unit normal ``right x up`` (towards the viewer)."""
        return np.cross(self.right, self.up)

    @property
    def position(self) -> float:
        """Signed position of the plane along :attr:`scroll_axis` (``center @ axis``, mm);
        for a named plane, the world coordinate of its scroll axis with that axis's sign."""
        if self.name in PLANE_AXIS:
            return float(self.center[PLANE_AXIS[self.name]])
        return float(self.center @ self.scroll_axis)

    def moved(self, mm: float) -> SlicePlane:
        """The plane shifted by ``mm`` along its scroll direction (named planes: their
        world axis, +S/+A/+R or +z/+y/+x; oblique: the normal, signed so that its
        largest component is positive, as the named plane it was tilted from scrolls)."""
        shift = _finite(mm, "move") * self.scroll_axis
        return dataclasses.replace(self, center=self.center + shift)

    @property
    def scroll_axis(self) -> np.ndarray:
        """Unit direction :meth:`moved` and :attr:`position` count along (oblique: the
        normal, its largest component positive, so a slight tilt keeps the direction)."""
        if self.name in PLANE_AXIS:
            axis = np.zeros(3)
            axis[PLANE_AXIS[self.name]] = 1.0
            return axis
        n = self.normal  # signed like the named planes' axes: its main component positive
        return n if n[int(np.argmax(np.abs(n)))] > 0 else -n

    def through(self, point: Sequence[float]) -> SlicePlane:
        """The plane moved along its scroll axis to contain ``point`` (its framing kept)."""
        p = np.asarray(point, dtype=np.float64).reshape(3)
        a = self.scroll_axis
        d = float((p - self.center) @ self.normal) / float(a @ self.normal)
        return dataclasses.replace(self, center=self.center + d * a)

    def at(self, position: float) -> SlicePlane:
        """The plane moved to ``position`` mm along its scroll axis (see :attr:`position`)."""
        return self.moved(_finite(position, "slice position") - self.position)

    def rotated(self, about_right: float = 0.0, about_up: float = 0.0) -> SlicePlane:
        """The plane turned by degrees about its own right and up axes through its centre."""
        rot = rotation_matrix(self.up, about_up) @ rotation_matrix(self.right, about_right)
        return dataclasses.replace(self, right=rot @ self.right, up=rot @ self.up, name="oblique")

    def pixel_mm(self, size: tuple[int, int]) -> float:
        """Side of one (square) pixel in mm for an image of ``size = (W, H)``."""
        return self.height_mm / max(int(size[1]), 1)

    def pixel_to_world(self, size: tuple[int, int]) -> np.ndarray:
        """4x4 matrix taking ``(col, row, 0, 1)`` to the world centre of that pixel of a
        ``(W, H)`` image (row 0 at the top); the third column is the unit normal."""
        w, h = int(size[0]), int(size[1])
        px = self.pixel_mm(size)
        m = np.eye(4)
        m[:3, 0] = self.right * px
        m[:3, 1] = -self.up * px
        m[:3, 2] = self.normal
        m[:3, 3] = self.center + self.right * px * (0.5 - w / 2) + self.up * px * (h / 2 - 0.5)
        return m

    def world_to_pixel(
        self, points: np.ndarray, size: tuple[int, int]
    ) -> tuple[np.ndarray, np.ndarray]:
        """World points (N, 3) -> ``(pixels (N, 2) as (col, row), signed distance (N,)
        from the plane in mm)``; the inverse of :meth:`pixel_to_world`."""
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        inv = np.linalg.inv(self.pixel_to_world(size))
        q = np.c_[p, np.ones(len(p))] @ inv.T
        return q[:, :2], q[:, 2]

    def camera(self, depth_mm: float = 1000.0) -> Camera:
        """The orthographic camera looking at this plane along ``-normal`` (picking,
        dragging, overlays): its view plane is this plane, its image this image."""
        rot = np.column_stack([self.right, self.up, self.normal])
        return Camera(
            center=self.center,
            rotation=rot,
            distance=depth_mm,
            projection="orthographic",
            ortho_height=self.height_mm,
            radius=depth_mm / 2,
        )

    def letters(self) -> dict[str, str]:
        """Patient orientation letters at the image's left, right, top and bottom
        edges (RAS world): the one or two world axes a direction mostly points along,
        the stronger first (``"L"``, ``"LA"``)."""
        out = {}
        for side, v in (("right", self.right), ("left", -self.right), ("top", self.up)):
            out[side] = direction_letters(v)
        out["bottom"] = direction_letters(-self.up)
        return out


def direction_letters(v: np.ndarray, second: float = 0.3) -> str:
    """Letters of the RAS directions ``v`` points along: the main axis, then a second
    one whose component is at least ``second`` (an oblique direction)."""
    order = np.argsort(-np.abs(v))
    out = axis_letters(int(order[0]), float(v[order[0]]))
    if abs(v[order[1]]) >= second:
        out += axis_letters(int(order[1]), float(v[order[1]]))
    return out


def _finite(value: object, what: str) -> float:
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError) as exc:
        raise SceneError(f"{what} must be a number (mm); got {value!r}") from exc
    if not math.isfinite(v):
        raise SceneError(f"{what} must be finite; got {v}")
    return v


def split_point_normal(text: str) -> tuple[list[float], list[float]] | None:
    """``"X,Y,Z:NX,NY,NZ"`` as (point, normal) lists of 3 numbers, or None when the
    text is not of that form (the numbers may be infinite or the normal zero: the
    callers check)."""
    point_text, sep, normal_text = str(text).partition(":")
    try:
        point = [float(v) for v in point_text.split(",")]
        normal = [float(v) for v in normal_text.split(",")]
    except ValueError:
        return None
    if not sep or len(point) != 3 or len(normal) != 3:
        return None
    return point, normal


def parse_plane(
    text: str,
    bounds: tuple[Sequence[float], Sequence[float]],
    at: float | None = None,
    aspect: float = 1.0,
) -> SlicePlane:
    """A plane from the command line: a name (:data:`PLANE_NAMES`) placed at ``at`` mm
    along its axis, or ``"X,Y,Z:NX,NY,NZ"``, a point and a normal (``at`` then moves
    it along the normal)."""
    spec = str(text).strip().lower()
    if spec in _AXES:
        return SlicePlane.named(spec, bounds, at=at, aspect=aspect)
    parts = split_point_normal(spec)
    if parts is None:
        raise SceneError(
            f"plane {text!r} is neither a plane name ({', '.join(PLANE_NAMES)}) nor"
            " POINT:NORMAL such as 0,0,10:0,0.3,1 (world mm)"
        )
    plane = SlicePlane.oblique(*parts, bounds, aspect)
    if at is not None:
        plane = plane.moved(at)
    return plane


def fit_pixels(
    plane: SlicePlane,
    lo: Sequence[float],
    hi: Sequence[float],
    pixel_mm: float,
    anchor: Sequence[float] | None = None,
) -> tuple[SlicePlane, tuple[int, int]]:
    """``plane`` reframed to show the box ``lo``..``hi`` with square pixels of about
    ``pixel_mm`` (coarser if the image would exceed :data:`MAX_SLICE_PIXELS` a side),
    and the image size ``(W, H)`` that does it.

    With ``anchor`` (a world point, e.g. a voxel centre: :func:`voxel_anchor`) the
    pixel grid is laid out from it: one pixel centre sits on the anchor's projection and
    the image grows by whole pixels to hold the box (2.5 % margin a side), so at the
    native pixel size of a plane along the voxel axes every pixel centre is a voxel
    centre and a linear slice equals the array's own slice."""
    px = _finite(pixel_mm, "pixel size")
    if px <= 0:
        raise SceneError(f"pixel size must be positive; got {px} mm")
    corners = box_corners(np.asarray(lo, float), np.asarray(hi, float)) - plane.center
    w = float(np.ptp(corners @ plane.right)) * 1.05
    h = float(np.ptp(corners @ plane.up)) * 1.05
    if anchor is not None:  # whole pixels from the anchor add up to two a side
        px = max(px, max(w, h) / (MAX_SLICE_PIXELS - 2))
        return _anchored_grid(plane, corners + plane.center, px, anchor)
    px = max(px, max(w, h) / MAX_SLICE_PIXELS)
    size = (max(1, math.ceil(w / px)), max(1, math.ceil(h / px)))
    framed = plane.framing(np.asarray(lo, float), np.asarray(hi, float), size[0] / size[1])
    return dataclasses.replace(framed, height_mm=size[1] * px), size


def _anchored_grid(
    plane: SlicePlane, corners: np.ndarray, px: float, anchor: Sequence[float]
) -> tuple[SlicePlane, tuple[int, int]]:
    """The pixel grid of step ``px`` through ``anchor``'s projection whose pixels
    (edges, not only centres) hold ``corners`` with a 2.5 % margin a side: pixel indices
    ``i0..i1`` from the anchor."""
    a = np.asarray(anchor, dtype=np.float64).reshape(3)
    a = a - float((a - plane.center) @ plane.normal) * plane.normal  # onto the plane
    rel = corners - a
    middle = [0.0, 0.0]
    size = [1, 1]
    for k, axis in enumerate((plane.right, plane.up)):
        x = rel @ axis
        margin = 0.025 * float(np.ptp(x))
        # the fewest pixels whose edges hold the box and its margin
        i0 = math.floor((float(x.min()) - margin) / px + 0.5 + 1e-9)
        i1 = math.ceil((float(x.max()) + margin) / px - 0.5 - 1e-9)
        size[k] = max(1, i1 - i0 + 1)
        middle[k] = (i0 + i0 + size[k] - 1) / 2 * px
    center = a + middle[0] * plane.right + middle[1] * plane.up
    framed = dataclasses.replace(plane, center=center, height_mm=size[1] * px)
    return framed, (size[0], size[1])


def voxel_anchor(volume: object, point: Sequence[float]) -> np.ndarray:
    """The centre of the voxel of ``volume`` (a :class:`~voxwarp.core.volume.Volume`)
    nearest ``point`` (world mm; indices rounded, not clipped to the volume)."""
    index = volume.world_to_index(np.asarray(point, dtype=np.float64).reshape(3))  # type: ignore[attr-defined]
    centre = volume.index_to_world(np.round(index))  # type: ignore[attr-defined]
    return np.asarray(centre, dtype=np.float64).reshape(3)


def aligned(plane: SlicePlane, size: tuple[int, int], anchor: Sequence[float]) -> SlicePlane:
    """``plane`` shifted in-plane by less than a pixel so that a pixel centre of its
    ``(W, H)`` image lies on ``anchor``'s projection (a voxel centre: the GUI's views
    sample the voxel grid, not between voxels, when a pixel is a voxel)."""
    px = plane.pixel_mm(size)
    corner = plane.pixel_to_world(size)[:3, 3]
    rel = np.asarray(anchor, dtype=np.float64).reshape(3) - corner
    shift = np.zeros(3)
    for axis in (plane.right, plane.up):
        d = float(rel @ axis)
        shift += (d - round(d / px) * px) * axis
    return dataclasses.replace(plane, center=plane.center + shift)
