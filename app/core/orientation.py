"""Patient orientation: axis codes, RAS/LPS, anatomical views and lossless reorientation.

World space
-----------
voxwarp's world space is **patient RAS+ in millimetres**, as nibabel and 3D Slicer use
internally: x grows towards the patient's Right, y towards Anterior and z towards
Superior. DICOM and ITK use LPS+ (x towards Left, y towards
Posterior); their coordinates become RAS by negating x and y. Volumes without a
patient orientation (NumPy arrays, TIFF stacks, raw files without an ``affine``) keep an
unnamed world: their index axes run along +x, +y, +z.

Axis codes
----------
An axis code such as ``"LAS"`` names, for each voxel index axis ``i, j, k``, the
anatomical direction the index *grows towards* (nibabel's ``aff2axcodes`` convention):
``"LAS"`` means i grows towards the patient's left, j towards anterior, k towards
superior. voxwarp stores every oriented volume in the closest RAS axis order (a lossless
permutation and flip of the array, like nibabel's ``as_closest_canonical``); what is left
of an oblique acquisition stays in :attr:`Volume.direction` as a rotation, which the
raycaster applies when it maps world points to texels: nothing is resampled.

Anatomical views
----------------
A view names the side the camera sits on: ``"anterior"`` looks at the patient's face
(head up, the patient's right on the image's left), ``"posterior"`` at the back,
``"left"``/``"right"`` from the patient's sides (head up), ``"superior"`` from above the
head and ``"inferior"`` from the feet (both with anterior up). ``"inferior"`` is the
radiological axial view (patient's right on the image's left) and ``"superior"`` the
neurological one (patient's right on the image's right). In RAS world space these are the
axis views ``+y``, ``-y``, ``-x``, ``+x``, ``+z`` and ``-z`` of :mod:`voxwarp.core.camera`.
"""

from __future__ import annotations

import numpy as np

from voxwarp.errors import VolumeError

#: Anatomical view name -> the camera's axis view in RAS world space.
ANATOMICAL_VIEWS: dict[str, str] = {
    "anterior": "+y",
    "posterior": "-y",
    "left": "-x",
    "right": "+x",
    "superior": "+z",
    "inferior": "-z",
}

#: Letters for the positive and negative end of each RAS world axis.
_LETTERS = (("R", "L"), ("A", "P"), ("S", "I"))

#: Patient spaces files use, with the signs that take their x and y to RAS.
PATIENT_SPACES: dict[str, tuple[float, float]] = {
    "RAS": (1.0, 1.0),
    "LPS": (-1.0, -1.0),  # DICOM, ITK
    "LAS": (-1.0, 1.0),
}


def affine_to_ras(affine: np.ndarray, space: str) -> np.ndarray:
    """A 4x4 index -> world ``affine`` in patient ``space`` (a key of
    :data:`PATIENT_SPACES`) as the same map into RAS (x and y negated as needed)."""
    fx, fy = PATIENT_SPACES[space]
    return np.diag([fx, fy, 1.0, 1.0]) @ np.asarray(affine, dtype=np.float64)


def axis_letters(axis: int, sign: float) -> str:
    """Letter of the RAS world axis ``axis`` (0, 1, 2) towards ``sign`` (+ or -)."""
    return _LETTERS[axis][0 if sign >= 0 else 1]


def axis_assignment(linear: np.ndarray) -> list[tuple[int, float]]:
    """For each index axis, the world axis it runs closest to and the sign.

    ``linear`` is the 3x3 index -> world matrix (columns per index axis). Axes are
    assigned greedily by the largest remaining absolute cosine, so every world axis is
    taken once, even for a 45-degree oblique (nibabel's ``io_orientation`` does the same).
    """
    m = np.asarray(linear, dtype=np.float64).reshape(3, 3)
    norms = np.linalg.norm(m, axis=0)
    if np.any(norms <= 0) or not np.all(np.isfinite(m)):
        raise VolumeError(f"the voxel axes are degenerate or not finite: {m.tolist()}")
    cos = np.abs(m / norms)
    out: list[tuple[int, float]] = [(0, 1.0)] * 3
    free_world, free_index = {0, 1, 2}, {0, 1, 2}
    for _ in range(3):
        best = max(
            ((w, i) for w in free_world for i in free_index), key=lambda wi: cos[wi[0], wi[1]]
        )
        w, i = best
        out[i] = (w, 1.0 if m[w, i] >= 0 else -1.0)
        free_world.discard(w)
        free_index.discard(i)
    return out


def axis_code(linear: np.ndarray) -> str:
    """Axis code (e.g. ``"LAS"``) of a 3x3 index -> RAS world matrix."""
    return "".join(axis_letters(w, s) for w, s in axis_assignment(linear))


def to_closest_ras(data: np.ndarray, affine: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Permute and flip ``data``'s axes to the closest RAS order; returns (data, affine).

    Lossless (a view of the same voxels); the returned 4x4 affine maps the new indices
    to the same world points, so voxel values sit at exactly the same places.
    """
    a = np.asarray(affine, dtype=np.float64)
    assignment = axis_assignment(a[:3, :3])
    perm = [0, 0, 0]  # new axis w <- old index axis i
    for i, (w, _) in enumerate(assignment):
        perm[w] = i
    out = np.transpose(data, perm)
    new = np.eye(4)
    new[:3, 3] = a[:3, 3]
    shape = data.shape
    for w in range(3):
        i = perm[w]
        sign = assignment[i][1]
        col = a[:3, i]
        if sign < 0:  # index n-1-k: world = origin + col * (n - 1) - col * k
            new[:3, 3] += col * (shape[i] - 1)
            col = -col
        new[:3, w] = col
    flips = tuple(w for w in range(3) if assignment[perm[w]][1] < 0)
    if flips:
        out = np.flip(out, axis=flips)
    return out, new


def split_affine(affine: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(spacing, origin, direction)`` of a 4x4 affine (ITK's geometry triple).

    ``direction`` is the nearest rotation to the normalised columns (a shear in the file
    is dropped, as ITK does; :func:`shear_of` measures it).
    """
    a = np.asarray(affine, dtype=np.float64)
    linear = a[:3, :3]
    spacing = np.linalg.norm(linear, axis=0)
    if np.any(spacing <= 0) or not np.all(np.isfinite(a)):
        raise VolumeError(f"the affine is degenerate or not finite: {a.tolist()}")
    u, _, vt = np.linalg.svd(linear / spacing)
    return spacing, a[:3, 3].copy(), u @ vt


def shear_of(affine: np.ndarray) -> float:
    """Largest |cosine| between two voxel axes (0 for an orthogonal grid)."""
    linear = np.asarray(affine, dtype=np.float64)[:3, :3]
    n = linear / np.linalg.norm(linear, axis=0)
    g = np.abs(n.T @ n - np.eye(3))
    return float(g.max())


def compose_affine(spacing: np.ndarray, origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """The 4x4 index -> world matrix of ``(spacing, origin, direction)``."""
    a = np.eye(4)
    a[:3, :3] = np.asarray(direction, float) * np.asarray(spacing, float)
    a[:3, 3] = origin
    return a


def obliquity_degrees(direction: np.ndarray) -> float:
    """Largest angle (degrees) between an index axis and its closest world axis."""
    d = np.asarray(direction, dtype=np.float64)
    cos = np.clip(np.abs(d).max(axis=0), 0.0, 1.0)
    return float(np.degrees(np.arccos(cos)).max())


def file_axes_order(file_axes: str) -> list[tuple[int, float]]:
    """For each file index axis, the stored (closest-RAS) axis it became and its sign,
    from the file's axis code (e.g. ``"LIA"`` -> ``[(0, -1), (2, -1), (1, 1)]``)."""
    order = []
    for letter in file_axes.upper():
        for w, pair in enumerate(_LETTERS):
            if letter in pair:
                order.append((w, 1.0 if letter == pair[0] else -1.0))
    if len(order) != 3 or len({w for w, _ in order}) != 3:
        raise VolumeError(f"not an axis code like 'LPS' or 'RAS': {file_axes!r}")
    return order


def grid_in_file_order(
    affine: np.ndarray, shape: tuple[int, int, int], file_axes: str
) -> tuple[np.ndarray, tuple[int, int, int]]:
    """A stored (closest-RAS) grid ``(affine, shape)`` re-indexed in the file's axis order.

    The inverse of :func:`to_closest_ras` for a file of axis code ``file_axes``: the same
    voxel centres, indexed as the file indexes them (its axis order, flips and origin).
    """
    a = np.asarray(affine, dtype=np.float64)
    out = np.eye(4)
    out[:3, 3] = a[:3, 3]
    new_shape = [0, 0, 0]
    for i, (w, sign) in enumerate(file_axes_order(file_axes)):
        new_shape[i] = int(shape[w])
        out[:3, i] = sign * a[:3, w]
        if sign < 0:
            out[:3, 3] += a[:3, w] * (shape[w] - 1)
    return out, (new_shape[0], new_shape[1], new_shape[2])


def data_in_file_order(data: np.ndarray, file_axes: str) -> np.ndarray:
    """Stored (closest-RAS) voxels ``data`` in the file's axis order (a view; lossless)."""
    order = file_axes_order(file_axes)
    out = np.transpose(data, [w for w, _ in order])
    flips = tuple(i for i, (_, sign) in enumerate(order) if sign < 0)
    return np.flip(out, axis=flips) if flips else out
