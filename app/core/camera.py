"""Cameras: view and projection matrices, standard views, orbit / pan / zoom.

The camera looks at ``center`` from ``center + distance * back``, where ``rotation``'s
columns are the camera's right, up and back axes in world coordinates (mm).

Standard views name the side the camera sits on: ``"+z"`` looks from +z towards -z
with +x to the right and +y up; ``"-z"`` has +y up and +x to the left;
``"+x"``/``"-x"``/``"+y"``/``"-y"`` keep +z up. A view may also be ``(azimuth,
elevation)`` in degrees: the camera sits at azimuth degrees about +z, counted from +x
towards +y, and elevation degrees above the xy plane, looking at the centre with +z
up (so ``(0, 0)`` is ``"+x"`` and ``(90, 0)`` is ``"+y"``). Straight from above or below
(elevation ±90) the azimuth direction points down the image: ``(0, 90)`` looks down
from +z with +x down and +y to the right.

Anatomical views (``"anterior"``, ``"posterior"``, ``"left"``, ``"right"``,
``"superior"``, ``"inferior"``) are the axis views of patient RAS world space
(:data:`voxwarp.core.orientation.ANATOMICAL_VIEWS`): in RAS, +x is the patient's
right, +y anterior and +z superior, so ``(90, 0)`` is the anterior view.
"""

from __future__ import annotations

import numbers
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from voxwarp.core.orientation import ANATOMICAL_VIEWS
from voxwarp.deform.warp import rotation_matrix
from voxwarp.errors import SceneError

Projection = Literal["perspective", "orthographic"]
PROJECTIONS: tuple[str, ...] = ("perspective", "orthographic")

# (right, up) per standard view; back = right x up
_VIEWS: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    "+x": ((0, 1, 0), (0, 0, 1)),
    "-x": ((0, -1, 0), (0, 0, 1)),
    "+y": ((-1, 0, 0), (0, 0, 1)),
    "-y": ((1, 0, 0), (0, 0, 1)),
    "+z": ((1, 0, 0), (0, 1, 0)),
    "-z": ((-1, 0, 0), (0, 1, 0)),
}
VIEWS: tuple[str, ...] = tuple(_VIEWS)
#: Every named view: the axis views and the anatomical ones.
VIEW_NAMES: tuple[str, ...] = (*VIEWS, *ANATOMICAL_VIEWS)

View = str | tuple[float, float]
#: camera entries holding arrays of numbers, with their shapes (the others: a projection
#: name, or a number)
CAMERA_ARRAYS: dict[str, tuple[int, ...]] = {"center": (3,), "rotation": (3, 3)}


def view_rotation(view: View) -> np.ndarray:
    """3x3 rotation (columns right, up, back) for a standard view or (azimuth, elevation)."""
    if isinstance(view, str):
        view = ANATOMICAL_VIEWS.get(view, view)
        if view not in _VIEWS:
            raise SceneError(
                f"unknown view {view!r}; use one of {', '.join(VIEW_NAMES)} or (azimuth, elevation)"
            )
        right, up = (np.asarray(v, float) for v in _VIEWS[view])
        return np.column_stack([right, up, np.cross(right, up)])
    try:
        az, el = (float(v) for v in view)
    except (TypeError, ValueError) as exc:
        raise SceneError(
            f"view must be one of {', '.join(VIEWS)} or (azimuth, elevation) degrees; got {view!r}"
        ) from exc
    if not (np.isfinite(az) and np.isfinite(el)):
        raise SceneError(f"view angles must be finite; got {view!r}")
    a, e = np.radians(az), np.radians(el)
    back = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    world_up = np.array([0.0, 0.0, 1.0])
    if abs(back[2]) > 0.9999:  # looking straight down/up: keep azimuth as the screen's up
        world_up = np.array([-np.cos(a), -np.sin(a), 0.0]) * np.sign(back[2])
    right = np.cross(world_up, back)
    right /= np.linalg.norm(right)
    up = np.cross(back, right)
    return np.column_stack([right, up, back])


@dataclass
class Camera:
    """A look-at camera with perspective or orthographic projection.

    Parameters
    ----------
    center
        Point looked at (mm).
    rotation
        3x3 matrix whose columns are the camera's right, up and back axes.
    distance
        Eye distance from ``center`` (mm).
    fov
        Vertical field of view in degrees (perspective).
    projection
        ``"perspective"`` or ``"orthographic"``.
    ortho_height
        World height (mm) that fills the image vertically (orthographic).
    radius
        Radius of the scene around ``center``; sets the near and far planes.
    """

    center: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rotation: np.ndarray = field(default_factory=lambda: view_rotation("+z"))
    distance: float = 100.0
    fov: float = 30.0
    projection: Projection = "perspective"
    ortho_height: float = 100.0
    radius: float = 50.0

    def __post_init__(self) -> None:
        if self.projection not in PROJECTIONS:
            raise SceneError(
                f"projection must be one of {', '.join(PROJECTIONS)}; got {self.projection!r}"
            )
        self.center = np.asarray(self.center, dtype=np.float64).reshape(3)
        self.rotation = np.asarray(self.rotation, dtype=np.float64).reshape(3, 3)
        if not (0 < self.fov < 179):
            raise SceneError(f"fov must be in (0, 179) degrees; got {self.fov}")
        for name in ("distance", "ortho_height", "radius"):
            v = float(getattr(self, name))
            if not (np.isfinite(v) and v > 0):
                raise SceneError(f"camera {name} must be positive and finite; got {v}")
            setattr(self, name, v)
        if not np.all(np.isfinite(self.center)):
            raise SceneError(f"camera center must be finite; got {self.center}")
        r = self.rotation
        if not (
            np.all(np.isfinite(r))
            and np.allclose(r.T @ r, np.eye(3), atol=1e-6)
            and np.linalg.det(r) > 0
        ):
            raise SceneError(
                "camera rotation must be a proper rotation matrix (orthonormal columns"
                " right, up, back with determinant +1)"
            )

    # ------------------------------------------------------------------ construction
    @classmethod
    def fit(
        cls,
        lo: Sequence[float],
        hi: Sequence[float],
        view: View = "+z",
        projection: Projection = "perspective",
        fov: float = 30.0,
        zoom: float = 1.0,
    ) -> Camera:
        """A camera looking at the box [lo, hi] from ``view`` so that it fills the image."""
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        center = 0.5 * (lo + hi)
        radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-6)
        rot = view_rotation(view)
        distance = radius / np.sin(np.radians(fov) / 2) * 1.05
        # orthographic: the box's projected extent along the screen axes
        corners = np.array(
            [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
        )
        proj = (corners - center) @ rot
        height = 2 * max(np.abs(proj[:, 0]).max(), np.abs(proj[:, 1]).max()) * 1.1
        return cls(
            center=center,
            rotation=rot,
            distance=distance / zoom,
            fov=fov,
            projection=projection,
            ortho_height=max(height, 1e-6) / zoom,
            radius=radius,
        )

    @classmethod
    def framing(
        cls,
        lo: Sequence[float],
        hi: Sequence[float],
        view: View,
        size: tuple[int, int],
        fill: float = 0.95,
        fov: float = 30.0,
    ) -> Camera:
        """A perspective camera from ``view`` whose image of ``size`` (W, H) the box
        [lo, hi] fills: ``fill`` of the image's width or height, whichever it reaches
        first, corners projected in perspective (:meth:`fit` frames a square image)."""
        lo_a, hi_a = np.asarray(lo, float), np.asarray(hi, float)
        corners = np.array(
            [
                [x, y, z]
                for x in (lo_a[0], hi_a[0])
                for y in (lo_a[1], hi_a[1])
                for z in (lo_a[2], hi_a[2])
            ]
        )
        half = np.array(size, dtype=np.float64) / 2
        zoom = 1.0
        cam = cls.fit(lo, hi, view=view, projection="perspective", fov=fov)
        for _ in range(8):  # perspective: the reach is not linear in the zoom; converge
            xy = cam.project(corners, size)
            reach = float(np.max(np.abs(xy - half) / half))
            if abs(reach - fill) < 1e-4:
                break
            zoom *= fill / reach
            cam = cls.fit(lo, hi, view=view, projection="perspective", fov=fov, zoom=zoom)
        return cam

    # ------------------------------------------------------------------ matrices
    @property
    def eye(self) -> np.ndarray:
        """Eye position (mm)."""
        return self.center + self.rotation[:, 2] * self.distance

    def view_matrix(self) -> np.ndarray:
        """4x4 world -> camera matrix (camera looks along -z)."""
        m = np.eye(4)
        m[:3, :3] = self.rotation.T
        m[:3, 3] = -self.rotation.T @ self.eye
        return m

    def near_far(self) -> tuple[float, float]:
        """Near and far plane distances enclosing the scene sphere."""
        far = self.distance + 2.0 * self.radius
        near = max(self.distance - 2.0 * self.radius, far * 1e-4)
        return near, far

    def projection_matrix(self, aspect: float) -> np.ndarray:
        """4x4 camera -> clip matrix for width/height ``aspect``."""
        near, far = self.near_far()
        m = np.zeros((4, 4))
        if self.projection == "perspective":
            f = 1.0 / np.tan(np.radians(self.fov) / 2)
            m[0, 0] = f / aspect
            m[1, 1] = f
            m[2, 2] = (far + near) / (near - far)
            m[2, 3] = 2 * far * near / (near - far)
            m[3, 2] = -1.0
        else:
            h = self.ortho_height / 2
            w = h * aspect
            m[0, 0] = 1 / w
            m[1, 1] = 1 / h
            m[2, 2] = -2 / (far - near)
            m[2, 3] = -(far + near) / (far - near)
            m[3, 3] = 1.0
        return m

    def view_projection(self, aspect: float) -> np.ndarray:
        """4x4 world -> clip matrix."""
        return self.projection_matrix(aspect) @ self.view_matrix()

    # ------------------------------------------------------------------ interaction
    def orbit(self, d_azimuth: float, d_elevation: float) -> None:
        """Rotate about ``center``: degrees about the camera's up, then its right axis."""
        r = rotation_matrix(self.rotation[:, 1], -d_azimuth)
        rot = r @ self.rotation
        r2 = rotation_matrix(rot[:, 0], d_elevation)
        rot = r2 @ rot
        u, _, vt = np.linalg.svd(rot)  # re-orthonormalise against drift
        self.rotation = u @ vt

    def pan(self, dx: float, dy: float) -> None:
        """Move ``center`` by fractions of the visible height along screen right/up."""
        if self.projection == "perspective":
            h = 2 * self.distance * np.tan(np.radians(self.fov) / 2)
        else:
            h = self.ortho_height
        self.center = self.center + (self.rotation[:, 0] * dx + self.rotation[:, 1] * dy) * h

    def zoom(self, factor: float) -> None:
        """Magnify by ``factor`` (> 1 zooms in)."""
        if not (np.isfinite(factor) and factor > 0):
            raise SceneError(f"zoom factor must be positive and finite; got {factor}")
        self.distance /= factor
        self.ortho_height /= factor

    def project(self, points: np.ndarray, size: tuple[int, int]) -> np.ndarray:
        """World points (N, 3) -> pixel coordinates (N, 2), origin top-left, y down."""
        w, h = size
        p = np.c_[np.atleast_2d(points), np.ones(len(np.atleast_2d(points)))]
        clip = p @ self.view_projection(w / h).T
        ndc = clip[:, :2] / clip[:, 3:4]
        return np.c_[(ndc[:, 0] + 1) * 0.5 * w, (1 - ndc[:, 1]) * 0.5 * h]

    def ray(self, pixel: Sequence[float], size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        """The viewing ray through a pixel: ``(origin, unit direction)`` in world mm.

        ``pixel`` is ``(x, y)`` with the origin top-left and y down, as :meth:`project`
        returns; the inverse of :meth:`project` along the ray. Perspective rays start at
        the eye; orthographic rays are parallel, starting on the plane through the eye.
        """
        w, h = size
        x, y = float(pixel[0]), float(pixel[1])
        ndc = np.array([2.0 * x / w - 1.0, 1.0 - 2.0 * y / h])
        right, up, back = self.rotation[:, 0], self.rotation[:, 1], self.rotation[:, 2]
        if self.projection == "perspective":
            t = np.tan(np.radians(self.fov) / 2)
            d = ndc[0] * t * (w / h) * right + ndc[1] * t * up - back
            return self.eye.copy(), d / np.linalg.norm(d)
        half_h = self.ortho_height / 2
        origin = self.eye + ndc[0] * half_h * (w / h) * right + ndc[1] * half_h * up
        return origin, -back.copy()

    def point_on_view_plane(
        self, pixel: Sequence[float], size: tuple[int, int], through: Sequence[float]
    ) -> np.ndarray:
        """Where the ray through ``pixel`` meets the plane parallel to the image through
        the world point ``through``: what a drag in the view plane moves a point to."""
        origin, d = self.ray(pixel, size)
        back = self.rotation[:, 2]
        p = np.asarray(through, dtype=np.float64).reshape(3)
        denom = float(d @ back)  # never 0: every viewing ray runs against `back`
        return origin + d * float((p - origin) @ back) / denom

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict:
        """JSON-serialisable form."""
        return {
            "center": self.center.tolist(),
            "rotation": self.rotation.tolist(),
            "distance": self.distance,
            "fov": self.fov,
            "projection": self.projection,
            "ortho_height": self.ortho_height,
            "radius": self.radius,
        }

    @classmethod
    def from_dict(cls, d: dict) -> Camera:
        """Inverse of :meth:`to_dict`: a :class:`SceneError` for a key a camera does not
        have (a typo would otherwise be ignored) and for a value of the wrong JSON type
        (``"fov": "30"``); missing keys take their defaults."""
        fields = tuple(cls.__dataclass_fields__)
        if not isinstance(d, Mapping):
            raise SceneError(f"a camera must be an object with keys {', '.join(fields)}")
        unknown = sorted(str(k) for k in d if k not in fields)
        if unknown:
            raise SceneError(
                f"unknown camera key{'s' if len(unknown) > 1 else ''}"
                f" {', '.join(map(repr, unknown))}; a camera holds only {', '.join(fields)}"
            )
        for key, value in d.items():
            if key == "projection":
                ok = isinstance(value, str)
            elif key in CAMERA_ARRAYS:
                ok = _numbers_of_shape(value, CAMERA_ARRAYS[key])
            else:
                ok = _is_number(value)
            if not ok:
                expected = {
                    "projection": f"one of the strings {', '.join(PROJECTIONS)}",
                    "center": "[x, y, z] numbers",
                    "rotation": "a 3x3 list of numbers",
                }.get(key, "a number")
                raise SceneError(f"camera '{key}' must be {expected}; got {value!r:.60}")
        try:
            return cls(**dict(d))
        except (TypeError, ValueError) as exc:
            raise SceneError(f"invalid camera entry: {exc}") from exc


def _is_number(value: object) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)


def _numbers_of_shape(value: object, shape: tuple[int, ...]) -> bool:
    """Whether ``value`` is a (nested) list/array of numbers of ``shape``."""
    if not shape:
        return _is_number(value)
    if not isinstance(value, list | tuple | np.ndarray) or len(value) != shape[0]:
        return False
    return all(_numbers_of_shape(v, shape[1:]) for v in value)
