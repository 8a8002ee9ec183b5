"""Surface meshes of label volumes (segmentations) and iso-surfaces, in world space.

:func:`mesh_from_labels` runs scikit-image's marching cubes (Lorensen and Cline 1987,
with Lewiner et al.'s topology-consistent tables) on a label volume and maps the
vertices through the volume's full index -> world affine (spacing, direction, origin),
so the mesh lies on the anatomy in patient RAS+ mm whatever the scan's orientation and
follows the volume's warps like any other mesh. A label's mask is padded by one empty
voxel so its surface is closed; faces are turned outward (positive enclosed volume),
whichever side of the level the inside lies on (a mask is high inside, a distance field
low), and vertex normals follow the faces.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from voxwarp.core.extras import require
from voxwarp.core.mesh import Mesh
from voxwarp.core.orientation import compose_affine
from voxwarp.core.volume import Volume
from voxwarp.errors import MeshError


def mesh_from_labels(
    labels: Volume | np.ndarray,
    level: float | None = None,
    *,
    label: float | None = None,
    step_size: int = 1,
    smooth: float = 0.0,
    spacing: Sequence[float] = (1.0, 1.0, 1.0),
    origin: Sequence[float] = (0.0, 0.0, 0.0),
    name: str | None = None,
) -> Mesh:
    """A world-space :class:`~voxwarp.core.mesh.Mesh` of a label or iso-surface.

    Parameters
    ----------
    labels
        A :class:`~voxwarp.core.volume.Volume` (its affine places the mesh) or a 3-D
        numpy array indexed ``[i, j, k]`` (placed by ``spacing`` and ``origin``).
    level
        Iso level of a continuous volume (default: halfway between its minimum and
        maximum). Not with ``label``.
    label
        Mesh the voxels equal to this value (the surface at half-way between them and
        the rest).
    step_size
        Marching-cubes step in voxels (>= 1; larger is coarser and faster).
    smooth
        Gaussian sigma in voxels applied to a label's mask before meshing (0: none);
        smooths the voxel staircase.
    spacing, origin
        Voxel size and the world position of voxel ``[0, 0, 0]`` (mm) of a numpy array.
    name
        Name of the mesh (default from the label or the volume).

    Raises
    ------
    MeshError
        Input not 3-D, no voxel equal to ``label``, ``level`` outside the values, bad
        ``step_size``/``smooth``; :class:`~voxwarp.errors.MissingExtraError` without the
        ``segmentation`` extra.
    """
    require("segmentation", "voxwarp.mesh_from_labels")
    data, affine, base_name = _grid(labels, spacing, origin)
    if isinstance(step_size, bool) or not isinstance(step_size, int | np.integer) or step_size < 1:
        raise MeshError(f"step_size must be an integer >= 1; got {step_size!r}")
    if not (isinstance(smooth, int | float) and np.isfinite(smooth) and smooth >= 0):
        raise MeshError(f"smooth must be a Gaussian sigma >= 0 (voxels); got {smooth!r}")
    if label is not None:
        if level is not None:
            raise MeshError("give level (iso-surface) or label (segmentation), not both")
        field, shift, level = _label_mask(data, label, float(smooth))
        default_name = f"{base_name} label {label:g}"
    else:
        field, shift, level = _continuous(data, level)
        default_name = f"{base_name} level {level:g}"
    from skimage.measure import marching_cubes

    try:
        verts, faces, _, _ = marching_cubes(field, level=level, step_size=int(step_size))
    except (ValueError, RuntimeError) as exc:
        raise MeshError(f"marching cubes found no surface at level {level:g}: {exc}") from exc
    world = (verts + shift) @ affine[:3, :3].T + affine[:3, 3]
    faces = np.asarray(faces, dtype=np.int64)
    if _signed_volume(world, faces) < 0:
        faces = faces[:, ::-1]
    return Mesh(world, faces, name=name or default_name)


def _grid(
    labels: Any, spacing: Sequence[float], origin: Sequence[float]
) -> tuple[np.ndarray, np.ndarray, str]:
    """The voxel array, its 4x4 index -> world affine and a name."""
    if isinstance(labels, Volume):
        return np.asarray(labels.data), labels.affine, labels.name or "volume"
    try:
        data = np.asarray(labels)
    except (TypeError, ValueError) as exc:
        raise MeshError(f"labels must be a Volume or a 3-D array; got {type(labels)}") from exc
    if not (np.issubdtype(data.dtype, np.number) or data.dtype == np.bool_):
        raise MeshError(f"labels must hold numbers; got dtype {data.dtype}")
    if data.ndim != 3:
        raise MeshError(f"labels must be a 3-D volume; got {data.ndim}-D shape {data.shape}")
    try:
        s = np.asarray(spacing, dtype=np.float64).reshape(3)
        o = np.asarray(origin, dtype=np.float64).reshape(3)
    except (TypeError, ValueError) as exc:
        raise MeshError("spacing and origin must be three numbers each") from exc
    if not (np.all(np.isfinite(s)) and np.all(s > 0) and np.all(np.isfinite(o))):
        raise MeshError(f"spacing must be finite and > 0, origin finite; got {s}, {o}")
    return data, compose_affine(s, o, np.eye(3)), "labels"


def _label_mask(data: np.ndarray, label: float, smooth: float) -> tuple[np.ndarray, Any, float]:
    """The label's mask cropped to its box plus a margin of empty voxels (a closed
    surface), the index of its first voxel, and the level 0.5."""
    mask = data == label
    if data.ndim != 3:
        raise MeshError(f"labels must be a 3-D volume; got shape {data.shape}")
    if not np.any(mask):
        found = np.unique(data)
        shown = ", ".join(f"{v:g}" for v in found[:8]) + (" ..." if len(found) > 8 else "")
        raise MeshError(f"no voxel has label {label:g}; the volume holds {shown}")
    idx = np.argwhere(mask)
    pad = 1 + int(np.ceil(3 * smooth))
    lo = idx.min(axis=0) - pad
    hi = idx.max(axis=0) + pad + 1
    field = np.zeros(hi - lo, dtype=np.float32)
    src_lo, src_hi = np.maximum(lo, 0), np.minimum(hi, data.shape)
    field[tuple(slice(a - b, c - b) for a, b, c in zip(src_lo, lo, src_hi, strict=True))] = mask[
        tuple(slice(a, c) for a, c in zip(src_lo, src_hi, strict=True))
    ]
    if smooth > 0:
        from scipy import ndimage

        field = ndimage.gaussian_filter(field, smooth)
    return field, lo.astype(np.float64), 0.5


def _continuous(data: np.ndarray, level: float | None) -> tuple[np.ndarray, Any, float]:
    """The volume as float32, no shift, and the level (checked inside the values)."""
    field = np.asarray(data, dtype=np.float32)
    finite = field[np.isfinite(field)]
    if finite.size == 0:
        raise MeshError("the volume has no finite values to mesh")
    vmin, vmax = float(finite.min()), float(finite.max())
    if level is None:
        level = 0.5 * (vmin + vmax)
    level = float(level)
    if not (vmin < level < vmax):
        raise MeshError(
            f"level {level:g} lies outside the volume's values ({vmin:g} .. {vmax:g});"
            " pick a level between them"
        )
    field = np.where(np.isfinite(field), field, vmin).astype(np.float32)
    return field, 0.0, level


def _signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Volume enclosed by the triangles (positive when they face outward)."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


__all__ = ["mesh_from_labels"]
