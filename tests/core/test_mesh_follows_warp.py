"""Meshes follow the scene's warp chain (voxwarp.core.mesh_warp, voxwarp.render.mesh_pass).

Oracle: a bright sphere's volume rendered (MIP, orthographic) through a non-trivial
offset-field warp, and the mesh of the same sphere (``mesh_from_labels``) drawn through
the same warp and camera, cover the same pixels (IoU), while the undeformed mesh does
not (its centroid lies pixels away): the test fails if the mesh does not move. Baked
normals are the Jacobian-carried ones (checked against the normals of the deformed
triangles); an unchanged scene is not re-baked; where the chain has no forward map
(a fold or tear) the other vertices are drawn exactly and one warning line counts the
vertices left at their nearest estimate.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.render.test_mesh_render import render_target
from voxwarp import mesh_from_labels
from voxwarp.core import mesh_warp
from voxwarp.core.camera import Camera, view_rotation
from voxwarp.core.mesh import MeshInstance, vertex_normals
from voxwarp.core.mesh_warp import mesh_instances_bounds
from voxwarp.core.volume import Volume
from voxwarp.deform.elements.offset_field import OffsetFieldWarp
from voxwarp.deform.warp import AffineWarp, Warp
from voxwarp.render.mesh_pass import MeshRenderer
from voxwarp.scene import Scene

SIZE = 128
N = 48
CENTER = np.array([23.5, 23.5, 23.5])
RADIUS = 9.0
SHIFT = 7.0  # mm: the field's peak displacement along +x
#: silhouettes of the volume's MIP and of the mesh through the same warp; measured on
#: llvmpipe: IoU 0.995 (a few edge pixels differ), centroids 0.03 px apart, moved 13 px
MIN_IOU = 0.97


def sphere_labels() -> np.ndarray:
    i, j, k = np.meshgrid(*(np.arange(N, dtype=float),) * 3, indexing="ij")
    r2 = (i - CENTER[0]) ** 2 + (j - CENTER[1]) ** 2 + (k - CENTER[2]) ** 2
    return np.where(r2 <= RADIUS**2, 1, 0).astype(np.uint8)


def bulge_warp() -> OffsetFieldWarp:
    """A smooth field pushing the middle of the box +x by up to SHIFT (and a little +y)."""
    lo, hi = np.full(3, -8.0), np.full(3, N + 7.0)
    shape = (9, 9, 9)
    s = np.stack(np.meshgrid(*(np.linspace(0, 1, n) for n in shape), indexing="ij"), -1)
    bump = np.prod(np.sin(np.pi * s), axis=-1)
    u = np.zeros((*shape, 3))
    u[..., 0] = SHIFT * bump
    u[..., 1] = 0.3 * SHIFT * bump * s[..., 0]
    return OffsetFieldWarp(lo, hi, u)


def camera() -> Camera:
    return Camera(
        center=CENTER,
        rotation=view_rotation("+z"),
        distance=120.0,
        projection="orthographic",
        ortho_height=60.0,
        radius=60.0,
    )


@pytest.fixture(scope="module")
def renderer(gl_ctx: Any) -> Iterator[MeshRenderer]:
    r = MeshRenderer(gl_ctx)
    yield r
    r.release()


@pytest.fixture(scope="module")
def target(gl_ctx: Any) -> Iterator[Any]:
    with render_target(gl_ctx, SIZE) as fbo:
        yield fbo


def draw(r: MeshRenderer, fbo: Any, inst: MeshInstance, warps: list) -> np.ndarray:
    r.draw([inst], fbo, camera(), warps=warps)
    img = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32)
    return img.reshape(SIZE, SIZE, 4)[::-1].copy()


def centroid(mask: np.ndarray) -> np.ndarray:
    return np.argwhere(mask).mean(axis=0)


def save(name: str, img: np.ndarray) -> None:
    from voxwarp.io.images import write_image

    out = Path("/tmp/mesh_follows_warp")
    out.mkdir(exist_ok=True)
    write_image(out / name, np.clip(img, 0, 1))


def test_mesh_silhouette_follows_the_warped_volume(
    offscreen: Any, renderer: MeshRenderer, target: Any
) -> None:
    labels = sphere_labels()
    vol = Volume(labels.astype(np.float32) * 200.0, name="sphere")
    mesh = mesh_from_labels(vol, label=200.0)
    warp = bulge_warp()
    scene = Scene(vol, "mip", "grayscale", camera=camera(), warps=[warp], jitter=False)
    mip = offscreen(SIZE, SIZE, "f4").render(scene)
    inst = MeshInstance(mesh, color=(1.0, 0.6, 0.2))
    moved = draw(renderer, target, inst, [warp])
    still = draw(renderer, target, inst, [])
    save("mip.png", mip)
    save("mesh_warped.png", moved)
    save("mesh_unwarped.png", still)
    vol_mask = mip[..., :3].max(axis=-1) > 0.5 * mip[..., :3].max()
    moved_mask, still_mask = moved[..., 3] > 0.5, still[..., 3] > 0.5
    iou = (vol_mask & moved_mask).sum() / (vol_mask | moved_mask).sum()
    assert iou >= MIN_IOU, f"IoU {iou:.3f}"
    still_iou = (vol_mask & still_mask).sum() / (vol_mask | still_mask).sum()
    assert still_iou < iou - 0.1, f"unmoved IoU {still_iou:.3f} vs {iou:.3f}"
    shift = centroid(moved_mask) - centroid(still_mask)  # (row, column) pixels
    px = SHIFT * SIZE / 60.0
    assert shift[1] > 0.4 * px, f"centroid moved {shift} px"
    np.testing.assert_allclose(centroid(moved_mask), centroid(vol_mask), atol=1.0)


def test_mixed_scene_moves_meshes_and_bounds_follow(offscreen: Any) -> None:
    vol = Volume(np.zeros((N, N, N), np.float32), name="empty")
    mesh = mesh_from_labels(sphere_labels(), label=1)
    inst = MeshInstance(mesh, color=(1.0, 1.0, 1.0))
    warp = bulge_warp()
    clear_tf = [(0, 0, 0, 0, 0), (1, 0, 0, 0, 0)]  # the (empty) volume shows nothing
    kw: dict[str, Any] = {"camera": camera(), "jitter": False, "meshes": [inst]}
    moved = offscreen(SIZE, SIZE, "f4").render(Scene(vol, "dvr", clear_tf, warps=[warp], **kw))
    still = offscreen(SIZE, SIZE, "f4").render(Scene(vol, "dvr", clear_tf, **kw))
    save("scene_warped.png", moved)
    a, b = moved[..., :3].max(-1) > 0.05, still[..., :3].max(-1) > 0.05
    assert centroid(a)[1] - centroid(b)[1] > 0.4 * SHIFT * SIZE / 60.0
    lo, hi = mesh_instances_bounds([inst], [warp])  # type: ignore[misc]
    lo0, hi0 = mesh_instances_bounds([inst])  # type: ignore[misc]
    assert hi[0] > hi0[0] + 0.5 * SHIFT
    assert lo[0] > lo0[0]


def test_baked_normals_and_cache() -> None:
    mesh = mesh_from_labels(sphere_labels(), label=1, smooth=1.0)
    inst = MeshInstance(mesh, np.diag([1.0, 1.2, 0.9, 1.0]))
    warp = bulge_warp()
    p, n, key = mesh_warp.warped_geometry(inst, [warp])
    # the Jacobian-carried normals agree with the deformed triangles' vertex normals
    tri = vertex_normals(p, mesh.faces.astype(np.int64))
    cos = np.einsum("ij,ij->i", n, tri)
    assert np.median(cos) > 0.999
    assert cos.min() > 0.9
    again = mesh_warp.warped_geometry(inst, [warp])
    assert again[0] is p
    assert again[2] == key
    warp.update(warp.displacements * 0.5)
    assert mesh_warp.warped_geometry(inst, [warp])[2] != key  # revision changed


def test_affine_chain_goes_into_the_matrix(renderer: MeshRenderer, target: Any) -> None:
    mesh = mesh_from_labels(sphere_labels(), label=1)
    inst = MeshInstance(mesh)
    shift = AffineWarp.translation((6.0, 0.0, 0.0))
    a = draw(renderer, target, inst, [shift])
    b = draw(renderer, target, MeshInstance(mesh, shift.forward_matrix), [])
    np.testing.assert_allclose(a, b, atol=1e-6)
    assert not renderer._baked  # nothing baked for an affine chain


class Squash(Warp):
    """Deformed x -> c + 10 tanh((x - c) / 10): original points with |x - c| >= 10 have
    no deformed point (the base class's Newton forward map fails there)."""

    kind = "test_squash"
    centre = 0.0

    def apply(self, points: np.ndarray) -> np.ndarray:
        q = np.atleast_2d(np.asarray(points, dtype=np.float64)).copy()
        q[:, 0] = self.centre + 10.0 * np.tanh((q[:, 0] - self.centre) / 10.0)
        return q

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.kind}

    @classmethod
    def from_dict(cls, d: Any) -> Squash:
        return cls()


def test_no_forward_map_warns_once_and_draws_the_rest(renderer: MeshRenderer, target: Any) -> None:
    from voxwarp.core.mesh_warp import MeshWarpWarning

    mesh = mesh_from_labels(sphere_labels(), label=1)
    squash = Squash()
    squash.centre = float(np.median(mesh.vertices[:, 0])) + 3.0
    # vertices beyond 10 mm have no deformed point; just inside, Newton may not reach
    # the far-away solution within its steps
    off = np.abs(mesh.vertices[:, 0] - squash.centre)
    far = off > 10.0 + Squash.forward_tolerance
    assert 0 < far.sum() < len(far)
    with pytest.warns(MeshWarpWarning, match=r"vertices have no forward map") as caught:
        image = draw(renderer, target, MeshInstance(mesh), [squash])
    assert len(caught) == 1
    assert "\n" not in str(caught[0].message)
    counted = int(str(caught[0].message).split(": ", 1)[1].split(" of ")[0])
    assert int(far.sum()) <= counted <= int((off > 9.5).sum())  # those, no others
    assert image[..., 3].max() > 0  # the mesh is drawn
