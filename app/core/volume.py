"""The :class:`Volume`: a scalar 3D image with its geometry in world units.

Axis order (kept everywhere in voxwarp)
---------------------------------------
``Volume.data`` is indexed ``data[i, j, k]`` with ``i`` along world x, ``j`` along
world y and ``k`` along world z, so ``data.shape == (nx, ny, nz)``. This is the
order NIfTI and NRRD use, and the order of :class:`deform.ElementGrid` indices.
The array is stored Fortran-contiguous, so ``data.T`` is a C-contiguous
``(nz, ny, nx)`` array with x varying fastest: exactly the memory layout of an
OpenGL 3D texture, uploaded without a copy.

Geometry
--------
Voxel ``(i, j, k)`` has its centre at ``origin + direction @ (spacing * (i, j, k))``
(millimetres), ITK's (spacing, origin, direction) triple; :attr:`Volume.affine` is the
same map as a 4x4 matrix. ``direction`` is the identity unless the scan is oblique
(files with a patient orientation are stored in the closest RAS axis order, see
:mod:`voxwarp.core.orientation`). The voxels fill the *volume box* from index
``-1/2`` to ``shape - 1/2``; :attr:`Volume.bounds` is its axis-aligned bounding box in
world space (the box itself when ``direction`` is the identity).

World space is patient RAS+ mm when :attr:`Volume.space` is ``"RAS"``; arrays without
an orientation have ``space == ""`` and their index axes run along +x, +y, +z.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from voxwarp.core import limits
from voxwarp.core.orientation import axis_code, compose_affine, obliquity_degrees
from voxwarp.errors import VolumeError

#: dtypes the GPU path supports natively.
SUPPORTED_DTYPES: tuple[np.dtype, ...] = (
    np.dtype(np.uint8),
    np.dtype(np.uint16),
    np.dtype(np.int16),
    np.dtype(np.float32),
)

NanPolicy = Literal["raise", "mask"]


def short_repr(value: object, limit: int = 80) -> str:
    """``repr(value)`` on one line (an array's repr spans several), cut to ``limit``
    characters, for error messages."""
    text = " ".join(repr(value).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def parse_triple(
    value: object, what: str, *, positive: bool = False, where: str = ""
) -> tuple[float, float, float]:
    """Parse one number or three numbers into a finite ``(x, y, z)`` tuple.

    Raises :class:`VolumeError` naming ``what`` (and ``where`` it came from) otherwise.
    """
    suffix = f" in {where}" if where else ""
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError, OverflowError) as exc:
        raise VolumeError(
            f"{what}{suffix} must be one number or three numbers (x, y, z);"
            f" got {short_repr(value)}."
        ) from exc
    if arr.size == 1:
        arr = np.repeat(arr, 3)
    if arr.size != 3:
        raise VolumeError(
            f"{what}{suffix} must be one number or three numbers (x, y, z);"
            f" got {short_repr(value)}."
        )
    if not np.all(np.isfinite(arr)):
        raise VolumeError(f"{what}{suffix} must be finite; got {short_repr(value)}.")
    if positive and np.any(arr <= 0):
        raise VolumeError(
            f"{what}{suffix} must be positive in every axis; got {short_repr(value)}."
        )
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def coerce_dtype(data: np.ndarray) -> np.ndarray:
    """Return ``data`` in one of :data:`SUPPORTED_DTYPES`.

    bool and int8 widen to uint8/int16; wider integers narrow to the smallest supported
    integer type that holds their value range (lossless), else become float32 with a
    warning that says whether that was exact (values within +-2**24) or rounded;
    float16/float64 become float32. Anything else raises
    :class:`VolumeError` naming the supported dtypes.
    """
    dt = data.dtype
    if dt in SUPPORTED_DTYPES:
        return data
    if dt == np.bool_:
        return data.astype(np.uint8)
    if dt.kind in "iu":
        if data.size == 0:
            raise VolumeError("the volume is empty (a dimension is 0).")
        lo, hi = int(data.min()), int(data.max())
        for target in (np.uint8, np.int16, np.uint16):
            info = np.iinfo(target)
            if info.min <= lo and hi <= info.max:
                return data.astype(target)
        exact = max(abs(lo), abs(hi)) <= 1 << 24  # float32 holds every integer up to 2**24
        warnings.warn(
            f"volume dtype {dt} with values in [{lo}, {hi}] does not fit a 16-bit integer;"
            " converted to float32"
            + (
                " (exact: every value is within +-2**24)."
                if exact
                else " with LOSS: integers beyond +-2**24 are rounded to the nearest float32"
                " (24 significant bits)."
            ),
            stacklevel=3,
        )
        return data.astype(np.float32)
    if dt.kind == "f":
        if dt.itemsize > 4 and data.size:  # finite values float32 cannot hold
            limit = float(np.finfo(np.float32).max)
            ends = [float(np.fmax.reduce(data, axis=None)), float(np.fmin.reduce(data, axis=None))]
            big = [abs(v) for v in ends if math.isfinite(v) and abs(v) > limit]
            if big:
                raise VolumeError(
                    f"volume values reach {max(big):.3g}, beyond float32's range"
                    f" (+-{limit:.3g}) that voxwarp draws in; rescale the data (e.g."
                    " array / 1e30) or convert it to float32 yourself"
                )
        return data.astype(np.float32)
    raise VolumeError(
        f"unsupported volume dtype {dt}; voxwarp reads uint8, uint16, int16 and float32"
        " (integers and floats of other widths are converted). Convert the data to one"
        " of these, e.g. array.astype(np.float32)."
    )


@dataclass(eq=False)
class Volume:
    """A scalar volume: voxel data plus spacing and origin in millimetres.

    Parameters
    ----------
    data
        Array of shape ``(nx, ny, nz)``, indexed ``data[i, j, k]`` with ``i`` along x
        (see the module docstring). Stored Fortran-contiguous.
    spacing
        Voxel size ``(sx, sy, sz)`` in mm.
    origin
        World position ``(x, y, z)`` in mm of the centre of voxel ``(0, 0, 0)``.
    name
        Human-readable name (file stem for loaded files).
    source
        Path the volume was loaded from, or ``None`` for in-memory arrays; a scene
        JSON refers to the volume by this path.
    units
        Unit of the voxel values, e.g. ``"HU"`` for CT; empty when unknown.
    direction
        3x3 rotation whose columns are the world directions of the index axes i, j, k
        (identity unless the scan is oblique).
    space
        ``"RAS"`` when world coordinates are patient RAS+ mm (read from the file),
        ``""`` when the data carries no patient orientation.
    file_axes
        Axis code of the file's voxel axes before voxwarp's lossless reorientation
        (e.g. ``"LAS"``); ``""`` when unknown.
    spacing_source
        ``"file"`` (stated by the file), ``"given"`` (passed by the user) or
        ``"assumed"`` (nobody said; 1 mm).
    modality
        ``"CT"``, ``"MR"`` or another DICOM modality when the file says; ``""`` otherwise.
    padding_value
        Value the file marks as outside the scanned field of view (DICOM
        PixelPaddingValue, in stored units after rescaling), or ``None``.
    frame_choice
        ``{"frame_index": t}`` and/or ``{"channel": c}``: the volume that was read from a
        4-D or multi-channel file (a scene saves it beside the file's path); empty
        otherwise.
    """

    data: np.ndarray
    spacing: tuple[float, float, float] = (1.0, 1.0, 1.0)
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    name: str = "volume"
    source: str | None = None
    units: str = ""
    direction: np.ndarray | None = None
    space: str = ""
    file_axes: str = ""
    spacing_source: str = "file"
    modality: str = ""
    padding_value: float | None = None
    frame_choice: dict[str, int] = field(default_factory=dict)
    _range: tuple[float, float] | None = field(default=None, repr=False)
    _window: tuple[float, float] | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        data = np.asarray(self.data)
        if data.ndim != 3:
            raise VolumeError(
                f"a volume needs a 3D array (nx, ny, nz); got {data.ndim}D with shape"
                f" {data.shape}. For a single image, add an axis: array[..., None]."
            )
        if min(data.shape) < 1:
            raise VolumeError(f"the volume is empty: shape {data.shape}.")
        data = coerce_dtype(data)
        self.data = np.asfortranarray(data)
        self.spacing = parse_triple(
            1.0 if self.spacing is None else self.spacing, "spacing", positive=True
        )
        if not all(limits.spacing_in_range(v) for v in self.spacing):
            given = ", ".join(f"{v:g}" for v in self.spacing)
            raise VolumeError(
                f"spacing ({given}) mm is outside {limits.MIN_SPACING_MM:g} to"
                f" {limits.MAX_SPACING_MM:g} mm per axis (a unit or header error?); give the"
                " voxel size (the CLI's --spacing SX SY SZ)"
            )
        self.origin = parse_triple(0.0 if self.origin is None else self.origin, "origin")
        self.direction = _rotation(self.direction)
        if self.space not in ("", "RAS"):
            raise VolumeError(f"space must be 'RAS' or '' (no orientation); got {self.space!r}.")

    # ------------------------------------------------------------------ geometry
    @property
    def shape(self) -> tuple[int, int, int]:
        """Number of voxels ``(nx, ny, nz)``."""
        return tuple(int(s) for s in self.data.shape)  # type: ignore[return-value]

    @property
    def dtype(self) -> np.dtype:
        """The voxel dtype (one of :data:`SUPPORTED_DTYPES`)."""
        return self.data.dtype

    @property
    def affine(self) -> np.ndarray:
        """4x4 index -> world matrix (mm): ``direction * spacing`` and ``origin``."""
        return compose_affine(self.spacing, self.origin, self.direction)

    @property
    def is_oblique(self) -> bool:
        """Whether the index axes are rotated against the world axes."""
        return not np.allclose(self.direction, np.eye(3), atol=1e-9)

    @property
    def obliquity(self) -> float:
        """Largest angle (degrees) between an index axis and its world axis."""
        return obliquity_degrees(self.direction)

    @property
    def orientation(self) -> str:
        """Axis code of the stored axes (``"RAS"`` for oriented volumes), ``""`` unknown."""
        return axis_code(self.direction) if self.space else ""

    def corners(self) -> np.ndarray:
        """The 8 corners (8, 3) of the volume box in world mm."""
        n = np.asarray(self.shape, dtype=np.float64)
        idx = np.array([[a, b, c] for a in (0, 1) for b in (0, 1) for c in (0, 1)], float)
        return self.index_to_world(idx * n - 0.5)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lo, hi)`` corners of the axis-aligned box holding all voxels, in mm."""
        if not self.is_oblique:
            sp = np.asarray(self.spacing)
            org = np.asarray(self.origin)
            return org - 0.5 * sp, org + (np.asarray(self.shape) - 0.5) * sp
        c = self.corners()
        return c.min(axis=0), c.max(axis=0)

    @property
    def size_mm(self) -> np.ndarray:
        """Extent of :attr:`bounds` in mm per axis."""
        lo, hi = self.bounds
        return hi - lo

    @property
    def center(self) -> np.ndarray:
        """Centre of the volume box in mm."""
        return self.index_to_world((np.asarray(self.shape, dtype=np.float64) - 1.0) / 2.0)

    def world_to_index(self, points: np.ndarray) -> np.ndarray:
        """Map world points (..., 3) in mm to continuous voxel indices (i, j, k)."""
        rel = np.asarray(points, float) - np.asarray(self.origin)
        if self.is_oblique:
            rel = rel @ self.direction  # direction^T applied to each row
        return rel / np.asarray(self.spacing)

    def index_to_world(self, indices: np.ndarray) -> np.ndarray:
        """Map continuous voxel indices (..., 3) to world points in mm."""
        scaled = np.asarray(indices, float) * np.asarray(self.spacing)
        if self.is_oblique:
            scaled = scaled @ self.direction.T
        return np.asarray(self.origin) + scaled

    def world_to_texel_matrix(self) -> np.ndarray:
        """4x4 world mm -> texel coordinates (voxel i spans [i, i + 1], centre i + 1/2)."""
        m = np.eye(4)
        m[:3, :3] = self.direction.T / np.asarray(self.spacing)[:, None]
        m[:3, 3] = -(m[:3, :3] @ np.asarray(self.origin)) + 0.5
        return m

    def with_geometry(self, data: np.ndarray | None = None, **changes: object) -> Volume:
        """The same voxels (or ``data``) with some geometry fields changed (``spacing``,
        ``origin``...); name, source, units and the other fields are kept."""
        kw = {name: getattr(self, name) for name in _GEOMETRY_FIELDS}
        kw.update(changes)
        voxels = self.data if data is None else data
        return Volume(voxels, name=self.name, source=self.source, units=self.units, **kw)

    # ------------------------------------------------------------------ values
    @property
    def value_range(self) -> tuple[float, float]:
        """``(min, max)`` of the voxel values (computed once)."""
        if self._range is None:
            self._range = (float(self.data.min()), float(self.data.max()))
        return self._range

    def default_window(self) -> tuple[float, float]:
        """A ``(level, window)`` from the 0.5 and 99.5 percentiles of the values (cached)."""
        if self._window is not None:
            return self._window
        sample = self.data[:: max(1, self.shape[0] // 64), :: max(1, self.shape[1] // 64), ::]
        lo, hi = np.percentile(sample, [0.5, 99.5])
        if hi <= lo:
            lo, hi = self.value_range
        if hi <= lo:
            hi = lo + 1.0
        self._window = (float(0.5 * (lo + hi)), float(hi - lo))
        return self._window

    @property
    def nbytes(self) -> int:
        """Bytes of voxel data."""
        return int(self.data.nbytes)

    def texture_array(self) -> np.ndarray:
        """The data as a C-contiguous ``(nz, ny, nx)`` array (x fastest), for GL upload."""
        return np.ascontiguousarray(self.data.T)

    def downsample(self, factor: int | Sequence[int]) -> Volume:
        """Return a volume reduced by an integer ``factor`` per axis (block mean).

        Spacing grows by the factor; the box keeps its position up to half a new voxel.
        """
        f = np.asarray(factor, dtype=int).reshape(-1)
        if f.size == 1:
            f = np.repeat(f, 3)
        if f.size != 3 or np.any(f < 1):
            raise VolumeError(
                f"downsample factor must be a positive integer (or three); got {factor}."
            )
        if np.all(f == 1):
            return self
        n = np.asarray(self.shape) // f
        if np.any(n < 1):
            raise VolumeError(
                f"downsample factor {tuple(f)} is larger than the volume {self.shape}."
            )
        d = self.data[: n[0] * f[0], : n[1] * f[1], : n[2] * f[2]].astype(np.float32)
        d = d.reshape(n[0], f[0], n[1], f[1], n[2], f[2]).mean(axis=(1, 3, 5))
        if self.dtype.kind in "iu":
            d = np.rint(d).astype(self.dtype)
        sp = np.asarray(self.spacing) * f
        org = self.index_to_world(0.5 * (f - 1))
        return self.with_geometry(d, spacing=tuple(sp), origin=tuple(org))

    def __repr__(self) -> str:
        extra = f", orientation={self.orientation!r}" if self.space else ""
        if self.is_oblique:
            extra += f", oblique={self.obliquity:.1f} deg"
        return (
            f"Volume(name={self.name!r}, shape={self.shape}, dtype={self.dtype},"
            f" spacing={self.spacing}, origin={self.origin}{extra})"
        )


#: Volume fields that describe geometry and provenance (copied by with_geometry).
_GEOMETRY_FIELDS = (
    "spacing",
    "origin",
    "direction",
    "space",
    "file_axes",
    "spacing_source",
    "modality",
    "padding_value",
    "frame_choice",
)


def _rotation(value: object) -> np.ndarray:
    """``value`` as a 3x3 proper rotation (identity for ``None``); raises VolumeError."""
    if value is None:
        return np.eye(3)
    try:
        m = np.asarray(value, dtype=np.float64).reshape(3, 3)
    except (TypeError, ValueError) as exc:
        raise VolumeError(
            f"direction must be a 3x3 rotation matrix; got {short_repr(value)}."
        ) from exc
    if not (np.all(np.isfinite(m)) and np.allclose(m.T @ m, np.eye(3), atol=1e-5)):
        raise VolumeError(
            f"direction must be a 3x3 rotation matrix (orthonormal columns); got"
            f" {short_repr(m.tolist())}."
        )
    if np.linalg.det(m) < 0:
        raise VolumeError(
            "direction must be a proper rotation (determinant +1); a mirrored grid is"
            " stored with its axes flipped (voxwarp.core.orientation.to_closest_ras)."
        )
    u, _, vt = np.linalg.svd(m)
    return u @ vt


def check_finite(data: np.ndarray, policy: NanPolicy = "raise", what: str = "volume") -> np.ndarray:
    """Reject or mask NaN/Inf voxels.

    ``policy="raise"`` raises :class:`VolumeError` with the count of bad voxels;
    ``policy="mask"`` replaces them by the minimum finite value (background) with a
    warning. Integer arrays pass through unchanged.
    """
    if data.dtype.kind != "f":
        return data
    bad = ~np.isfinite(data)
    nbad = int(bad.sum())
    if nbad == 0:
        return data
    if policy == "raise":
        raise VolumeError(
            f"{what} has {nbad} NaN/Inf voxel(s) of {data.size}. Pass nan_policy='mask'"
            " (CLI: --nan mask) to replace them by the minimum finite value, or clean the data."
        )
    if policy != "mask":
        raise VolumeError(f"nan_policy must be 'raise' or 'mask'; got {policy!r}.")
    finite = data[~bad]
    if finite.size == 0:
        raise VolumeError(f"{what} has no finite voxel at all; nothing to render.")
    fill = finite.min()
    warnings.warn(
        f"{what}: {nbad} NaN/Inf voxel(s) replaced by the minimum finite value {fill}.",
        stacklevel=3,
    )
    out = np.array(data, copy=True)
    out[bad] = fill
    return out
