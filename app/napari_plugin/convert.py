"""Between napari Image layers and voxwarp volumes, without Qt and without a viewer.

Axis order: napari indexes a volume ``data[z, y, x]`` and its world axes follow the data
axes, so napari's world point is ``(z, y, x)``; voxwarp indexes ``data[i, j, k]`` along
``(x, y, z)`` (:mod:`voxwarp.core.volume`). Reversing the axes of the array, of the
spacing and of the 4x4 index -> world affine (``P @ A @ P`` with ``P`` the axis
reversal) is the whole conversion: a voxel maps to the same world point in both.

* :func:`volume_to_layer_data` gives napari's ``(data, kwargs, "image")`` tuple:
  ``scale`` = spacing in zyx, ``translate`` = origin in zyx, and for an oblique volume
  an ``affine`` that carries the rotation and the origin.
* :func:`layer_to_volume` reads any object shaped like a napari Image layer (``data``,
  ``data_to_world``, ``rgb``, ``multiscale``, ``name``, ``metadata``) and returns a
  :class:`~voxwarp.core.volume.Volume`; 2D, RGB, 4D, multiscale and sheared layers are
  refused with one line saying what to do.
* :func:`layer_scene_options` turns the layer's display (contrast limits, colormap,
  gamma, opacity, rendering) into :class:`~voxwarp.scene.Scene` arguments.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from voxwarp.core.modality import display_defaults
from voxwarp.core.orientation import shear_of, split_affine, to_closest_ras
from voxwarp.core.transfer_function import TransferFunction
from voxwarp.core.volume import Volume
from voxwarp.errors import VolumeError

#: napari's ``(data, kwargs, layer_type)`` tuple.
LayerData = tuple[Any, dict[str, Any], str]
#: Key of the voxwarp entry in a layer's ``metadata``.
METADATA_KEY = "voxwarp"
#: napari Image ``rendering`` -> voxwarp compositing mode.
RENDERING_MODES: dict[str, str] = {
    "mip": "mip",
    "attenuated_mip": "mip",
    "minip": "minip",
    "average": "average",
    "iso": "iso",
    "translucent": "dvr",
    "additive": "dvr",
}
#: Control points a napari colormap becomes, evenly spaced over the contrast limits.
TF_SAMPLES = 9
#: Opacity of the top of the contrast range (a ramp rising with the square of the value).
TF_MAX_OPACITY = 0.85
#: Largest |cosine| between two voxel axes of a layer taken as orthogonal.
SHEAR_TOLERANCE = 1e-5
_REVERSE = np.eye(4)[[2, 1, 0, 3]]  # swaps x and z: napari <-> voxwarp axis order


def napari_affine(affine: np.ndarray) -> np.ndarray:
    """A 4x4 index -> world matrix in the other axis order (xyz <-> zyx; its own inverse)."""
    m = np.asarray(affine, dtype=np.float64)
    if m.shape != (4, 4):
        raise VolumeError(f"an affine must be a 4x4 matrix; got shape {m.shape}")
    return _REVERSE @ m @ _REVERSE


def volume_to_layer_data(
    volume: Volume,
    *,
    window: tuple[float, float] | None = None,
    name: str | None = None,
    metadata: Mapping[str, Any] | None = None,
) -> LayerData:
    """napari Image layer data for ``volume``: zyx data, scale, translate or affine.

    ``window`` is ``(level, width)`` for the contrast limits (default: voxwarp's MIP
    window for the volume's modality, :func:`voxwarp.core.modality.display_defaults`).
    The data is a view of the volume's voxels (no copy).
    """
    level, width = window if window is not None else display_defaults(volume, "mip").window
    kwargs: dict[str, Any] = {
        "name": name or volume.name,
        "scale": tuple(reversed(volume.spacing)),
        "contrast_limits": (float(level - width / 2), float(level + width / 2)),
        "colormap": "gray",
        "metadata": {METADATA_KEY: {**volume_metadata(volume), **(metadata or {})}},
    }
    if volume.is_oblique:  # rotation and origin in the affine; napari applies it last
        affine = np.eye(4)
        affine[:3, :3] = volume.direction
        affine[:3, 3] = volume.origin
        kwargs["affine"] = napari_affine(affine)
    else:
        kwargs["translate"] = tuple(reversed(volume.origin))
    return volume.data.T, kwargs, "image"


def volume_metadata(volume: Volume) -> dict[str, Any]:
    """What a layer keeps of a voxwarp volume: its source, patient space, units, modality."""
    return {
        "source": volume.source,
        "space": volume.space,
        "units": volume.units,
        "modality": volume.modality,
    }


def layer_to_volume(layer: Any) -> Volume:
    """The :class:`Volume` of a napari Image layer (zyx data and its data -> world map).

    Raises :class:`~voxwarp.errors.VolumeError` in one line for a layer voxwarp cannot
    render: not an image, RGB, multiscale, not 3D, or sheared.
    """
    check_layer(layer)
    matrix = napari_affine(layer_affine(layer))  # now index (x, y, z) -> world (x, y, z)
    if not np.all(np.isfinite(matrix)) or np.any(np.linalg.norm(matrix[:3, :3], axis=0) <= 0):
        raise VolumeError(f"layer {layer.name!r} has a degenerate scale/affine; fix its scale")
    if shear_of(matrix) > SHEAR_TOLERANCE:
        raise VolumeError(
            f"layer {layer.name!r} is sheared (its affine is not a rotation and scale);"
            " voxwarp needs orthogonal voxel axes: remove the layer's shear"
        )
    # a dask or zarr array is read here; a mirrored or turned grid is reordered as the
    # file readers do it (a view: every voxel keeps its world place)
    volume_data, matrix = to_closest_ras(np.asarray(layer.data).T, matrix)
    spacing, origin, direction = split_affine(matrix)
    meta = (getattr(layer, "metadata", None) or {}).get(METADATA_KEY, {})
    return Volume(
        volume_data,
        tuple(spacing),
        tuple(origin),
        name=str(layer.name),
        source=meta.get("source"),
        units=str(meta.get("units", "")),
        direction=direction,
        space=str(meta.get("space", "")),
        modality=str(meta.get("modality", "")),
        spacing_source="given",
    )


def check_layer(layer: Any) -> None:
    """Raise :class:`VolumeError` (one line, with the fix) unless ``layer`` is a
    single-scale, single-channel 3D image layer."""
    name = getattr(layer, "name", "?")
    if not hasattr(layer, "data_to_world") or not hasattr(layer, "rgb"):
        kind = type(layer).__name__
        raise VolumeError(f"layer {name!r} is a {kind}, not an image; select an Image layer")
    if layer.rgb:
        raise VolumeError(
            f"layer {name!r} is RGB; voxwarp renders scalar volumes: select a single-channel"
            " image layer (or split the channels)"
        )
    if getattr(layer, "multiscale", False):
        raise VolumeError(
            f"layer {name!r} is multiscale; add one level as its own layer"
            " (viewer.add_image(layer.data[k])) and select that"
        )
    shape = tuple(np.shape(layer.data))
    if len(shape) != 3:
        hint = (
            "a single image has no depth to render"
            if len(shape) < 3
            else "add one time point or channel as its own 3D layer (layer.data[t])"
        )
        raise VolumeError(
            f"layer {name!r} has {len(shape)} dimensions {shape}; voxwarp needs a 3D"
            f" (z, y, x) volume: {hint}"
        )


def layer_affine(layer: Any) -> np.ndarray:
    """The layer's full 4x4 data -> world matrix (napari's zyx order), measured through
    its public ``data_to_world`` (scale, translate, rotate, shear and affine composed)."""
    base = np.asarray(layer.data_to_world(np.zeros(3)), dtype=np.float64)
    m = np.eye(4)
    for axis in range(3):
        unit = np.zeros(3)
        unit[axis] = 1.0
        m[:3, axis] = np.asarray(layer.data_to_world(unit), dtype=np.float64) - base
    m[:3, 3] = base
    return m


def colormap_transfer_function(
    colormap: Any,
    contrast_limits: tuple[float, float],
    *,
    gamma: float = 1.0,
    opacity: float = 1.0,
) -> TransferFunction:
    """A voxwarp transfer function with a napari colormap's colours over the contrast
    limits and an opacity ramp (transparent at the low limit, ``TF_MAX_OPACITY * opacity``
    at the high one, rising with the square of the value as voxwarp's ``ramp``).

    ``colormap`` is a napari ``Colormap`` (anything with ``map(values) -> RGBA`` and a
    ``name``) or a colormap name napari knows (``"gray"``, ``"viridis"``, ...).
    """
    cmap = _colormap(colormap)
    lo, hi = (float(v) for v in contrast_limits)
    if not hi > lo:
        raise VolumeError(f"contrast limits must rise; got ({lo:g}, {hi:g}): widen them")
    t = np.linspace(0.0, 1.0, TF_SAMPLES)
    rgba = np.clip(np.asarray(cmap.map(t ** float(gamma)), dtype=np.float64), 0.0, 1.0)
    alpha = TF_MAX_OPACITY * float(np.clip(opacity, 0.0, 1.0)) * t**2
    points = [(lo + f * (hi - lo), *rgba[i, :3], alpha[i]) for i, f in enumerate(t)]
    return TransferFunction(points, name=f"napari:{getattr(cmap, 'name', 'colormap')}")


def _colormap(colormap: Any) -> Any:
    if not isinstance(colormap, str):
        return colormap
    from napari.utils.colormaps import ensure_colormap

    try:
        return ensure_colormap(colormap)
    except (KeyError, ValueError) as exc:
        raise VolumeError(f"unknown colormap {colormap!r}; use a napari colormap name") from exc


def layer_scene_options(layer: Any) -> dict[str, Any]:
    """:class:`~voxwarp.scene.Scene` keyword arguments that draw like the layer: the
    mode from its ``rendering``, the window from its contrast limits, the transfer
    function from its colormap (:func:`colormap_transfer_function`), the iso value."""
    lo, hi = (float(v) for v in layer.contrast_limits)
    rendering = str(getattr(layer, "rendering", "mip"))
    mode = RENDERING_MODES.get(rendering, "dvr")
    options: dict[str, Any] = {
        "mode": mode,
        "window": (0.5 * (lo + hi), max(hi - lo, 1e-6)),
        "transfer_function": colormap_transfer_function(
            layer.colormap,
            (lo, hi) if hi > lo else (lo, lo + 1.0),
            gamma=float(getattr(layer, "gamma", 1.0)),
            opacity=float(getattr(layer, "opacity", 1.0)),
        ),
    }
    if mode == "iso":
        options["iso_value"] = float(getattr(layer, "iso_threshold", 0.5 * (lo + hi)))  # data units
    return options
