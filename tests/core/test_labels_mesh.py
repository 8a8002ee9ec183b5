"""voxwarp.mesh_from_labels: marching cubes of a label volume, in world space.

Oracles: a sphere label's mesh encloses 4/3 pi r^3 (trimesh's volume, so the mesh is
closed and faces outward) within a few %; through an oblique affine the
vertices are nibabel's ``apply_affine`` of the index-space vertices; normals point away
from the centre; bad input is a one-line MeshError.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import voxwarp
from voxwarp import mesh_from_labels
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import rotation_matrix
from voxwarp.errors import MeshError

N = 40
C = (N - 1) / 2
R = 11.0


def sphere(value: int = 3) -> np.ndarray:
    i, j, k = np.meshgrid(*(np.arange(N, dtype=float),) * 3, indexing="ij")
    inside = (i - C) ** 2 + (j - 0.8 * C) ** 2 + (k - C) ** 2 <= R**2
    return np.where(inside, value, 1).astype(np.int16)


def test_exported_from_the_top_level() -> None:
    assert voxwarp.mesh_from_labels is mesh_from_labels
    assert "mesh_from_labels" in voxwarp.__all__


@pytest.mark.parametrize(("smooth", "tol"), [(0.0, 0.02), (1.0, 0.05)])
def test_sphere_label_encloses_the_sphere_volume(smooth: float, tol: float) -> None:
    spacing = (0.5, 0.5, 0.5)
    mesh = mesh_from_labels(sphere(), label=3, smooth=smooth, spacing=spacing)
    tm = mesh.to_trimesh()
    assert tm.is_watertight
    expected = 4.0 / 3.0 * np.pi * (R * 0.5) ** 3
    # measured: -0.8 % (smooth 0), -2.9 % (smooth 1, sigma 1 voxel) at r = 11 voxels
    assert tm.volume == pytest.approx(expected, rel=tol)
    centre = np.array([C, 0.8 * C, C]) * 0.5
    v = mesh.vertices.astype(float)
    outward = np.einsum("ij,ij->i", mesh.normals, v - centre)
    assert (outward > 0).all()


def test_oblique_affine_places_the_mesh_in_world_space() -> None:
    nib_affines = pytest.importorskip("nibabel.affines")
    labels = sphere()
    direction = rotation_matrix((1.0, 2.0, 0.5), 35.0)
    vol = Volume(labels, spacing=(0.8, 1.1, 1.3), origin=(-20.0, 15.0, 4.0), direction=direction)
    world = mesh_from_labels(vol, label=3)
    index = mesh_from_labels(labels, label=3)  # unit spacing, zero origin: index space
    expected = nib_affines.apply_affine(vol.affine, index.vertices.astype(float))
    np.testing.assert_allclose(world.vertices, expected, atol=1e-4)
    assert world.to_trimesh().volume > 0  # outward faces
    vox = np.prod(vol.spacing)
    assert world.to_trimesh().volume == pytest.approx(index.to_trimesh().volume * vox, rel=1e-5)


def test_iso_level_of_a_continuous_volume() -> None:
    i, j, k = np.meshgrid(*(np.arange(N, dtype=float),) * 3, indexing="ij")
    dist = np.sqrt((i - C) ** 2 + (j - C) ** 2 + (k - C) ** 2)
    mesh = mesh_from_labels(Volume(dist.astype(np.float32)), level=R)
    r = np.linalg.norm(mesh.vertices - C, axis=1)
    np.testing.assert_allclose(r, R, atol=0.05)
    # the inside of a distance field is where it is low: faces still outward
    assert mesh.to_trimesh().volume == pytest.approx(4 / 3 * np.pi * R**3, rel=0.02)


@pytest.mark.parametrize(
    ("args", "kw", "pattern"),
    [
        ((np.zeros((4, 4)),), {"label": 1}, "3-D"),
        ((sphere(),), {"label": 7}, "no voxel has label 7"),
        ((sphere(),), {"label": 3, "level": 0.5}, "not both"),
        ((sphere(),), {"level": 99.0}, "outside the volume's values"),
        ((sphere(),), {"label": 3, "step_size": 0}, "step_size"),
        ((sphere(),), {"label": 3, "smooth": -1.0}, "smooth"),
        ((sphere(),), {"label": 3, "spacing": (1, 0, 1)}, "spacing"),
        ((np.array([["a"]]),), {"label": 1}, "numbers"),
    ],
)
def test_bad_input_is_a_one_line_error(args: tuple, kw: dict[str, Any], pattern: str) -> None:
    with pytest.raises(MeshError, match=pattern) as info:
        mesh_from_labels(*args, **kw)
    assert "\n" not in str(info.value)
