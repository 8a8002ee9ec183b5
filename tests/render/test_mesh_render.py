"""GL tests of voxwarp.render.mesh_pass and of meshes depth-composited with volumes (llvmpipe).

Oracles: the vertex stage read back by transform feedback against the CPU lattice
(``MeshInstance.local_to_world``, ``TrilinearGrid.jacobian``); images of the same surface
placed by a lattice and by a matrix; a tile bent into a quarter circle whose image
centroid and per-band shading are predicted from the arc; and depth compositing checked
against ``volume + (1 - volume.a) * mesh`` built from separate renders.

Images are float32 (``f4``) framebuffers; colours are premultiplied RGBA.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import pytest

from benchmarks.lattice import bench_mesh_throughput, bend_grid
from voxwarp.core.camera import Camera, view_rotation
from voxwarp.core.mesh import MeshInstance, box_mesh, tile_mesh, torus_mesh, uv_sphere
from voxwarp.core.volume import Volume
from voxwarp.deform.elements.offset_field import OffsetFieldWarp
from voxwarp.deform.lattice.trilinear import TrilinearGrid
from voxwarp.deform.warp import rotation_matrix
from voxwarp.errors import RenderError
from voxwarp.render.mesh_pass import MESH_LIGHT, MeshRenderer
from voxwarp.scene import Scene

SIZE = 128
#: tolerance of "the same image" for two placements of one surface: float rounding of
#: positions moves a few edge pixels' coverage, so compare the fraction of equal pixels
#: and the worst interior difference. Measured on llvmpipe (LLVM 15): identity lattice
#: vs plain mesh and rigid lattice vs 4x4: < 2e-6 on all but <= 0.1 % of the pixels.
SAME = 1e-4


@pytest.fixture(scope="module")
def mesh_renderer(gl_ctx: Any) -> Iterator[MeshRenderer]:
    r = MeshRenderer(gl_ctx)
    yield r
    r.release()


@contextmanager
def render_target(ctx: Any, size: int) -> Iterator[Any]:
    """A size x size float colour + depth framebuffer, released (and never left bound
    for later modules) at the end."""
    color = ctx.texture((size, size), 4, dtype="f4")
    depth = ctx.depth_texture((size, size))
    fbo = ctx.framebuffer(color_attachments=[color], depth_attachment=depth)
    try:
        yield fbo
    finally:
        if ctx.fbo is fbo:
            ctx.detect_framebuffer(0).use()
        fbo.release()
        depth.release()
        color.release()


@pytest.fixture(scope="module")
def target(gl_ctx: Any) -> Iterator[Any]:
    with render_target(gl_ctx, SIZE) as fbo:
        yield fbo


def draw(renderer: MeshRenderer, fbo: Any, instances: list, cam: Camera, clear: Any = None) -> Any:
    renderer.draw(instances, fbo, cam, clear=clear or (0.0, 0.0, 0.0, 0.0))
    img = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32)
    return img.reshape(fbo.size[1], fbo.size[0], 4)[::-1].copy()


def ortho(view: str, center: Any, height: float, radius: float = 10.0) -> Camera:
    return Camera(
        center=np.asarray(center, float),
        rotation=view_rotation(view),
        distance=3 * radius,
        projection="orthographic",
        ortho_height=height,
        radius=radius,
    )


def assert_same_image(a: np.ndarray, b: np.ndarray, fraction: float = 0.995) -> None:
    diff = np.abs(a - b).max(axis=-1)
    assert np.mean(diff <= SAME) >= fraction, f"max diff {diff.max()}"
    assert np.count_nonzero(a[..., 3]) > 0.05 * a[..., 3].size  # something was drawn


def on_cell_face(u: np.ndarray, cells: Any, eps: float = 1e-4) -> np.ndarray:
    g = u * np.asarray(cells, float)
    return np.any(np.abs(g - np.round(g)) < eps, axis=1)


# ---------------------------------------------------------------------- vertex stage
def test_vertex_stage_matches_cpu_lattice(gl_ctx: Any, mesh_renderer: MeshRenderer) -> None:
    torus = torus_mesh(0.6, 0.2, 64, 32)
    box = (np.array([-0.9, -0.9, -0.25]), np.array([0.9, 0.9, 0.25]))
    grid = bend_grid(box, (4, 3, 2))
    lo, hi = box
    u = (torus.vertices.astype(np.float64) - lo) / (hi - lo)
    jac = grid.jacobian(u) / (hi - lo)  # d world / d local
    n0 = torus.normals.astype(np.float64)
    expected = {  # direct: J n; tangent space: cof(J) n, the direction of J^-T n (det J > 0)
        "normal": np.einsum("nij,nj->ni", jac, n0),
        "tangent": np.einsum("nji,nj->ni", np.linalg.inv(jac), n0),
    }
    for v in expected.values():
        v /= np.linalg.norm(v, axis=1, keepdims=True)
    interior = ~on_cell_face(u, grid.shape)  # J jumps across cell faces: either cell is right
    assert interior.mean() > 0.9
    hardware = MeshRenderer(gl_ctx, position="hardware")
    try:
        cases = ((mesh_renderer, "normal"), (mesh_renderer, "tangent"), (hardware, "normal"))
        for renderer, method in cases:
            inst = MeshInstance(torus, grid, box=box, normal_method=method)
            pos, nrm = renderer.deformed_vertices(inst)
            # float32 arithmetic; hardware filtering: within 1/256 of a cell on any GPU
            tol = 1e-5 if renderer is mesh_renderer else 1.2 / 256 / 2
            np.testing.assert_allclose(pos, inst.local_to_world(torus.vertices), atol=tol)
            np.testing.assert_allclose(nrm[interior], expected[method][interior], atol=2e-4)
            # the CPU reference of the shader (baking, picking) agrees everywhere
            np.testing.assert_allclose(nrm[interior], inst.world_normals()[interior], atol=2e-4)
    finally:
        hardware.release()


def test_vertex_stage_linear_and_mirrored(mesh_renderer: MeshRenderer) -> None:
    ball = uv_sphere(1.0, rows=8, cols=12)
    m = np.eye(4)
    m[:3, :3] = rotation_matrix((1, 1, 0), 30) @ np.array([[2, 0.5, 0], [0, 1, 0], [0, 0, 0.5]])
    m[:3, 3] = (1, 2, 3)
    inst = MeshInstance(ball, m)
    pos, nrm = mesh_renderer.deformed_vertices(inst)
    np.testing.assert_allclose(pos, inst.local_to_world(ball.vertices), atol=1e-5)
    expected = ball.normals @ np.linalg.inv(m[:3, :3])  # rows: (A^-T n)^T
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    np.testing.assert_allclose(nrm, expected, atol=1e-5)
    # a mirrored lattice (det J < 0): J^-T n keeps the geometric outward normal, the
    # tangent cross product follows the (now reversed) winding: opposite directions
    mirror = TrilinearGrid.from_function(lambda u: u * [-2.0, 2.0, 2.0], (2, 2, 2))
    a = mesh_renderer.deformed_vertices(MeshInstance(ball, mirror, normal_method="normal"))[1]
    b = mesh_renderer.deformed_vertices(MeshInstance(ball, mirror, normal_method="tangent"))[1]
    np.testing.assert_allclose(a, -b, atol=1e-5)
    outward = mesh_renderer.deformed_vertices(MeshInstance(ball, mirror))[0]
    outward -= outward.mean(axis=0)
    assert np.min(np.sum(outward * a, axis=1)) > 0


# ---------------------------------------------------------------------- images
def test_identity_lattice_equals_plain_mesh(mesh_renderer: MeshRenderer, target: Any) -> None:
    torus = torus_mesh(1.0, 0.35, 48, 24)
    cam = ortho((20.0, 30.0), (0, 0, 0), 3.2)
    plain = draw(mesh_renderer, target, [MeshInstance(torus)], cam)
    # the identity of the instance box: u -> lo + u (hi - lo), sampled on 3 x 3 x 2 cells
    inst = MeshInstance(torus)
    inst.transform = TrilinearGrid.from_box(*inst.box, cells=(3, 3, 2))
    ident = draw(mesh_renderer, target, [inst], cam)
    assert_same_image(ident, plain)


@pytest.mark.parametrize("method", ["normal", "tangent"])
def test_rigid_lattice_equals_matrix(mesh_renderer: MeshRenderer, target: Any, method: str) -> None:
    torus = torus_mesh(1.0, 0.35, 48, 24)
    box = (np.array([-1.5, -1.5, -0.5]), np.array([1.5, 1.5, 0.5]))
    m = np.eye(4)
    m[:3, :3] = rotation_matrix((0.3, 1.0, 0.2), 50)
    m[:3, 3] = (0.4, -0.3, 0.2)
    grid = TrilinearGrid.from_function(
        lambda u: (box[0] + u * (box[1] - box[0])) @ m[:3, :3].T + m[:3, 3], (2, 3, 2)
    )
    cam = ortho("+z", (0.4, -0.3, 0.2), 3.6)
    by_matrix = draw(mesh_renderer, target, [MeshInstance(torus, m)], cam)
    inst = MeshInstance(torus, grid, box=box, normal_method=method)
    by_grid = draw(mesh_renderer, target, [inst], cam)
    assert_same_image(by_grid, by_matrix)


def test_normal_methods_agree_only_on_conformal_lattices(
    mesh_renderer: MeshRenderer, target: Any
) -> None:
    ball = uv_sphere(1.0, rows=24, cols=48)
    box = (np.array([-1.0, -1.0, -1.0]), np.array([1.0, 1.0, 1.0]))
    similar = 1.3 * rotation_matrix((0.2, 1.0, 0.4), 35)
    shear = np.array([[1.5, 0.6, 0.0], [0.0, 0.7, 0.3], [0.2, 0.0, 1.2]])

    def grid(a: np.ndarray) -> TrilinearGrid:
        return TrilinearGrid.from_function(lambda u: (2 * u - 1) @ a.T, (2, 2, 2))

    cam = ortho((30.0, 20.0), (0, 0, 0), 5.0)
    diffs = {}
    for name, g in (("similar", grid(similar)), ("shear", grid(shear)), ("bent", None)):
        g = bend_grid(box, (4, 4, 4)) if g is None else g
        a, b = (
            draw(mesh_renderer, target, [MeshInstance(ball, g, box, normal_method=m)], cam)
            for m in ("normal", "tangent")
        )
        assert np.isfinite(a).all()
        diffs[name] = float(np.abs(a - b).max())
    # a rotation times a uniform scale carries n and J^-T n alike: float rounding only;
    # a shear (J n is not orthogonal to the surface) or a bent lattice: visibly different
    assert diffs["similar"] < 1e-4
    assert diffs["shear"] > 0.05
    assert diffs["bent"] > 0.05


def test_singular_lattice_keeps_normals(mesh_renderer: MeshRenderer, target: Any) -> None:
    # a lattice that squashes the tile's box flat: det J = 0 everywhere. "normal" cannot
    # invert J and falls back to the cofactor form; both methods match the flat tile.
    tile = tile_mesh(6, 6, size=(2.0, 2.0))
    flat = TrilinearGrid.from_function(lambda u: np.c_[2 * u[:, :2] - 1, 0 * u[:, 2]], (2, 2, 1))
    cam = ortho((10.0, 50.0), (0, 0, 0), 3.5)
    plain = draw(mesh_renderer, target, [MeshInstance(tile)], cam)
    for method in ("normal", "tangent"):
        img = draw(mesh_renderer, target, [MeshInstance(tile, flat, normal_method=method)], cam)
        assert_same_image(img, plain)


def bend_tile(radius: float) -> TrilinearGrid:
    """Lattice over the 2 x 1 tile's default box bending it about the line x = -1, z = R
    (a quarter circle when R = 4 / pi): 16 cells along x, exact at the nodes."""

    def f(u: np.ndarray) -> np.ndarray:
        x0, y0, z0 = -1 + 2 * u[:, 0], -0.5 + u[:, 1], -0.1 + 0.2 * u[:, 2]
        theta = (x0 + 1) / radius
        return np.c_[-1 + (radius - z0) * np.sin(theta), y0, radius - (radius - z0) * np.cos(theta)]

    return TrilinearGrid.from_function(f, (16, 1, 1))


@pytest.mark.parametrize("method", ["normal", "tangent"])
def test_bent_tile_silhouette_and_shading(
    mesh_renderer: MeshRenderer, target: Any, method: str
) -> None:
    tile = tile_mesh(32, 4, size=(2.0, 1.0))
    radius = 4 / np.pi  # the tile's length 2 becomes a quarter circle
    grid = bend_tile(radius)
    gray = 0.6
    cam = ortho("+z", (0, 0, 0), 2.5)  # looks down -z: x right, y up, headlight +z
    flat = draw(mesh_renderer, target, [MeshInstance(tile, color=(gray,) * 3)], cam)
    inst = MeshInstance(tile, grid, color=(gray,) * 3, normal_method=method)
    bent = draw(mesh_renderer, target, [inst], cam)
    px = 2.5 / SIZE
    x_of_column = (np.arange(SIZE) + 0.5) * px - 1.25

    def centroid(img: np.ndarray) -> float:
        cover = img[..., 3]
        return float((cover.sum(axis=0) * x_of_column).sum() / cover.sum())

    # the silhouette: x in [-1, -1 + R sin(pi/2)]; its centroid moves left by (1 - R) / 2
    assert centroid(flat) == pytest.approx(0.0, abs=0.5 * px)
    assert centroid(bent) == pytest.approx((-1 + (-1 + radius)) / 2, abs=0.5 * px)
    columns = np.flatnonzero(bent[SIZE // 2, :, 3] > 0.5)
    assert columns.size * px == pytest.approx(radius, abs=1.5 * px)
    # shading over the first half of cell i (u in [i/16, i/16 + 1/32]), whose vertices lie
    # at its start and middle. Tangent space: both carry cell i's chord normal, at the
    # cell's mid angle. Direct: J n is the z-edge direction interpolated between the cell's
    # nodes, which lie on the arc: the radial direction at the node angle at the start,
    # the mean of the two nodes' directions (mid angle) at the middle; fragments
    # interpolate those two linearly (the tile's centre line is straight in each cell).
    light_a, light_d, light_s, shininess = MESH_LIGHT
    row = bent[SIZE // 2]
    step = (np.pi / 2) / 16
    for i in (0, 4, 8):
        u0, u1 = i / 16, i / 16 + 1 / 32
        ends = inst.local_to_world(np.array([[-1 + 2 * u0, 0, 0], [-1 + 2 * u1, 0, 0]]))
        # pixel centres inside the band (shading is evaluated at pixel centres)
        inside = (x_of_column > ends[0, 0] + 0.1 * px) & (x_of_column < ends[1, 0] - 0.1 * px)
        assert inside.sum() >= 2
        mid = np.array([np.sin((i + 0.5) * step), np.cos((i + 0.5) * step)])  # (x, z)
        if method == "tangent":
            c = np.full(inside.sum(), mid[1])
        else:
            start = np.array([np.sin(i * step), np.cos(i * step)])
            s = (x_of_column[inside] - ends[0, 0]) / (ends[1, 0] - ends[0, 0])
            n = (1 - s)[:, None] * start + s[:, None] * mid
            c = n[:, 1] / np.linalg.norm(n, axis=1)
        expected = gray * (light_a + light_d * c) + light_s * c**shininess
        np.testing.assert_allclose(row[inside, :3], np.repeat(expected[:, None], 3, 1), atol=2e-3)


# ---------------------------------------------------------------------- depth compositing
def bright_volume() -> Volume:
    """32³: a uniform cube of value 200 in [8, 24)³, zero elsewhere."""
    a = np.zeros((32, 32, 32), np.uint8)
    a[8:24, 8:24, 8:24] = 200
    return Volume(a, name="cube")


#: white, per-voxel opacity 0.06 at 200 (through the 16-voxel cube: alpha ~ 0.63)
TF = [(0, 0, 0, 0, 0), (100, 1, 1, 1, 0), (200, 1, 0.9, 0.8, 0.06), (255, 1, 0.9, 0.8, 0.06)]
BG = (0.1, 0.1, 0.15, 1.0)


def vol_camera(projection: str) -> Camera:
    cam = ortho("-y", (15.5, 15.5, 15.5), 40.0, radius=60.0)
    if projection == "perspective":
        cam = Camera(center=cam.center, rotation=cam.rotation, distance=90.0, fov=28.0, radius=60.0)
    return cam


def vol_scene(meshes: list | None = None, **kw: Any) -> Scene:
    kw.setdefault("camera", vol_camera("orthographic"))
    kw.setdefault("background", BG)
    return Scene(bright_volume(), "dvr", TF, jitter=False, meshes=meshes, **kw)


def test_mesh_in_front_blocks_volume(
    offscreen: Any, mesh_renderer: MeshRenderer, target: Any
) -> None:
    front = MeshInstance(box_mesh((4, -12, 4), (14, -4, 14)), color=(0.2, 0.5, 1.0))
    scene = vol_scene([front])
    mixed = offscreen(SIZE, SIZE, "f4").render(scene)
    volume = offscreen(SIZE, SIZE, "f4").render(vol_scene())
    mesh_only = draw(mesh_renderer, target, [front], scene.camera, clear=BG)
    on_box = mesh_only[..., 2] > 0.5  # blue box pixels
    behind_box = on_box & (np.abs(volume - np.array(BG)).max(axis=-1) > 0.05)
    assert behind_box.sum() > 100  # the box hides part of the bright cube
    np.testing.assert_array_equal(mixed[on_box], mesh_only[on_box])  # exactly the mesh
    # away from the box the volume is unchanged
    np.testing.assert_allclose(mixed[~on_box], volume[~on_box], atol=1e-6)


@pytest.mark.parametrize("projection", ["orthographic", "perspective"])
def test_volume_composited_over_mesh_behind(
    offscreen: Any, mesh_renderer: MeshRenderer, target: Any, projection: str
) -> None:
    back = MeshInstance(box_mesh((-2, 40, -2), (33, 44, 33)), color=(0.9, 0.3, 0.2))
    cam = vol_camera(projection)
    mixed = offscreen(SIZE, SIZE, "f4").render(vol_scene([back], camera=cam))
    over_nothing = offscreen(SIZE, SIZE, "f4").render(
        vol_scene(camera=cam, background=(0, 0, 0, 0))
    )
    mesh_only = draw(mesh_renderer, target, [back], cam, clear=BG)
    # front to back, premultiplied: out = volume + (1 - volume.a) * (mesh over background)
    expected = over_nothing + (1 - over_nothing[..., 3:]) * mesh_only
    np.testing.assert_allclose(mixed, expected, atol=1e-5)
    seen_through = (over_nothing[..., 3] > 0.3) & (mesh_only[..., 0] > 0.5)
    assert seen_through.sum() > 100
    assert (mixed[seen_through, 0] > over_nothing[seen_through, 0] + 0.1).all()


def test_meshes_beyond_the_camera_range_are_not_clipped(
    offscreen: Any, mesh_renderer: MeshRenderer, target: Any
) -> None:
    # this camera's far plane lies at y = 35.5 (eye at y = -14.5, far = 50): the mesh
    # pass widens its depth range to the meshes, and depth converts back exactly
    cam = ortho("-y", (15.5, 15.5, 15.5), 40.0, radius=10.0)
    assert cam.eye[1] + cam.near_far()[1] < 40
    back = MeshInstance(box_mesh((-2, 40, -2), (33, 44, 33)), color=(0.9, 0.3, 0.2))
    mixed = offscreen(SIZE, SIZE, "f4").render(vol_scene([back], camera=cam))
    over_nothing = offscreen(SIZE, SIZE, "f4").render(
        vol_scene(camera=cam, background=(0, 0, 0, 0))
    )
    wide = Camera(**{**vars(cam), "radius": 40.0})
    mesh_only = draw(mesh_renderer, target, [back], wide, clear=BG)
    assert (mesh_only[..., 0] > 0.5).mean() > 0.5
    expected = over_nothing + (1 - over_nothing[..., 3:]) * mesh_only
    np.testing.assert_allclose(mixed, expected, atol=1e-5)


@pytest.mark.parametrize("projection", ["orthographic", "perspective"])
def test_rays_stop_at_the_mesh_surface(
    offscreen: Any, mesh_renderer: MeshRenderer, target: Any, projection: str
) -> None:
    # a box filling the back half of the volume (y > 15.5): the volume in front of it
    # must equal the volume clipped at y = 15.5, composited over the box
    wall = MeshInstance(box_mesh((-2, 15.5, -2), (33, 44, 33)), color=(0.3, 0.9, 0.3))
    cam = vol_camera(projection)
    mixed = offscreen(SIZE, SIZE, "f4").render(vol_scene([wall], camera=cam))
    clipped = vol_scene(
        camera=cam, background=(0, 0, 0, 0), clip_box=((-9, -9, -9), (40, 15.5, 40))
    )
    front_half = offscreen(SIZE, SIZE, "f4").render(clipped)
    mesh_only = draw(mesh_renderer, target, [wall], cam, clear=BG)
    expected = front_half + (1 - front_half[..., 3:]) * mesh_only
    diff = np.abs(mixed - expected).max(axis=-1)
    # perspective rays meet the plane at varying sample phases: a sample within depth
    # precision of y = 15.5 may land on either side on a handful of pixels
    assert np.mean(diff < 1e-5) > 0.995
    whole = offscreen(SIZE, SIZE, "f4").render(vol_scene(camera=cam, background=(0, 0, 0, 0)))
    assert whole[..., 3].max() > front_half[..., 3].max() + 0.1  # the clip mattered


def test_compositing_on_warped_rays(
    offscreen: Any, mesh_renderer: MeshRenderer, target: Any
) -> None:
    # a non-affine warp (an offset field) takes the warped ray path of the raycaster
    lo, hi = np.array([-4.0] * 3), np.array([36.0] * 3)
    x = np.stack(np.meshgrid(*[np.linspace(0, 1, 9)] * 3, indexing="ij"), axis=-1)
    bump = np.prod(np.sin(np.pi * x), axis=-1)[..., None] * np.array([3.0, 0.0, 2.0])
    warp = OffsetFieldWarp(lo, hi, bump)
    front = MeshInstance(box_mesh((4, -12, 4), (14, -4, 14)), color=(0.2, 0.5, 1.0))
    back = MeshInstance(box_mesh((-2, 40, -2), (33, 44, 33)), color=(0.9, 0.3, 0.2))
    r = offscreen(SIZE, SIZE, "f4")
    mixed = r.render(vol_scene([front, back], warps=[warp]))
    over_nothing = r.render(vol_scene(warps=[warp], background=(0, 0, 0, 0)))
    meshes = draw(mesh_renderer, target, [front, back], vol_camera("orthographic"), clear=BG)
    on_front = meshes[..., 2] > 0.5
    np.testing.assert_array_equal(mixed[on_front], meshes[on_front])
    expected = over_nothing + (1 - over_nothing[..., 3:]) * meshes
    np.testing.assert_allclose(mixed[~on_front], expected[~on_front], atol=1e-5)
    assert (over_nothing[~on_front, 3] > 0.3).sum() > 100


def test_no_meshes_is_bit_identical(offscreen: Any) -> None:
    r = offscreen(SIZE, SIZE, "f4")
    for projection in ("orthographic", "perspective"):
        cam = vol_camera(projection)
        before = r.render(Scene(bright_volume(), "dvr", TF, background=BG, camera=cam))
        r.render(vol_scene([MeshInstance(box_mesh((0, -9, 0), (9, -5, 9)))], camera=cam))
        plain = Scene(bright_volume(), "dvr", TF, background=BG, camera=cam, meshes=[])
        np.testing.assert_array_equal(r.render(plain), before)
        np.testing.assert_array_equal(r.render(plain.copy(meshes=None)), before)


def test_mesh_only_scene_with_empty_volume(
    offscreen: Any, mesh_renderer: MeshRenderer, target: Any
) -> None:
    empty = Volume(np.zeros((2, 2, 2), np.uint8), name="empty")
    torus = MeshInstance(torus_mesh(5.0, 1.5), color=(0.8, 0.7, 0.2))
    scene = Scene(empty, "dvr", [(0, 0, 0, 0, 0), (1, 0, 0, 0, 0)], view=(30.0, 40.0),
                  background=BG, meshes=[torus])  # fmt: skip
    img = offscreen(SIZE, SIZE, "f4").render(scene)
    cam = scene.resolved_camera()  # framed on the mesh, not on the 2-voxel volume
    np.testing.assert_array_equal(img, draw(mesh_renderer, target, [torus], cam, clear=BG))
    assert (img[..., 0] > 0.3).mean() > 0.1


# ---------------------------------------------------------------------- resources
def test_translucent_instance_blends(mesh_renderer: MeshRenderer, target: Any) -> None:
    cam = ortho("+z", (0, 0, 0), 3.0)
    back = MeshInstance(tile_mesh(1, 1, size=(2, 2), center=(0, 0, -1)), color=(1, 0, 0))
    glass = MeshInstance(tile_mesh(1, 1, size=(1, 1)), color=(0, 0, 1, 0.5))
    # drawn in any order: opaque first, the translucent one blended over it
    img = draw(mesh_renderer, target, [glass, back], cam)
    red = draw(mesh_renderer, target, [back], cam)[SIZE // 2, SIZE // 2]
    blue = draw(mesh_renderer, target, [glass], cam)[SIZE // 2, SIZE // 2]
    np.testing.assert_allclose(img[SIZE // 2, SIZE // 2], blue + 0.5 * red, atol=1e-6)


def test_release_and_caches(gl_ctx: Any, target: Any) -> None:
    r = MeshRenderer(gl_ctx)
    with pytest.raises(RenderError, match="position must be one of exact, hardware"):
        MeshRenderer(gl_ctx, position="fast")
    nodes = TrilinearGrid.identity((2, 2, 2)).nodes.copy()
    nodes[1, 1, 1] += 0.1  # not one affine map: drawn by the trilinear program
    inst = MeshInstance(box_mesh(), TrilinearGrid(nodes))
    cam = ortho("+z", (0, 0, 0), 3.0)
    draw(r, target, [inst], cam)
    prog = r._program(False)
    draw(r, target, [inst], cam)
    assert r._program(False) is prog
    assert len(r._meshes) == 1
    assert len(r._grids) == 1
    with pytest.raises(RenderError, match="MeshInstance"):
        r.draw([inst.mesh], target, cam)
    r.release()
    r.release()
    with pytest.raises(RenderError, match="released"):
        r.draw([inst], target, cam)


def test_bench_mesh_throughput_smoke(gl_ctx: Any) -> None:
    result = bench_mesh_throughput(triangles=4000, cells=(2, 2, 2), size=32, frames=1, ctx=gl_ctx)
    assert result["triangles"] == pytest.approx(4000, rel=0.1)
    assert set(result["ratio"]) == {"lattice_normal", "lattice_tangent", "lattice_hardware"}
    assert all(v > 0 for v in result["ratio"].values())
    assert result["vertex_stage_ratio"] > 0
