"""The two normal methods of GRAPP 2010 (section 4.2, Figure 5) and the linear fast path
(section 4.1), read back from the vertex shader by transform feedback (llvmpipe).

The scene: a tube along x bent by a lattice of four cells along its axis into a quarter
circle (nodes on the exact bend, so the lattice approximates a smoothly bent tube whose
normals are known). Every threshold below follows from that geometry: the cells turn the
axis by ``STEP`` each, so a per-cell (tangent-space) normal jumps by about ``STEP`` across
a cell face, and the direct normal, the z-edge interpolated between nodes, leans away
from the cell's chord normal by up to ``STEP / 2`` at the faces.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from voxwarp.core.camera import Camera
from voxwarp.core.mesh import Mesh, MeshInstance, torus_mesh, tube_mesh
from voxwarp.deform.lattice.trilinear import TrilinearGrid, carry_normals
from voxwarp.render.mesh_pass import MeshRenderer

LENGTH, RADIUS, CELLS = 2.0, 0.25, 4
BEND = LENGTH / (np.pi / 2)  # radius of the arc: the tube's length makes a quarter circle
STEP = (np.pi / 2) / CELLS  # the axis turns by this much per cell
BOX = (np.array([0.0, -0.3, -0.3]), np.array([LENGTH, 0.3, 0.3]))
FACES = LENGTH * np.arange(1, CELLS) / CELLS  # x of the inner cell faces
DELTA = 1e-3  # rings this far either side of each face
SECTIONS = 24


def bend(p: np.ndarray) -> np.ndarray:
    """The exact bend: local (x, y, z) about the line x = 0, z = BEND."""
    theta = p[:, 0] / BEND
    return np.c_[(BEND - p[:, 2]) * np.sin(theta), p[:, 1], BEND - (BEND - p[:, 2]) * np.cos(theta)]


def bend_normals(p: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Exact normals of the bent tube: its Jacobian's columns are orthogonal and only the
    x column is scaled, so for normals without x part the inverse transpose is a rotation."""
    theta = p[:, 0] / BEND
    return np.c_[-n[:, 2] * np.sin(theta), n[:, 1], n[:, 2] * np.cos(theta)]


def lattice() -> TrilinearGrid:
    lo, hi = BOX
    return TrilinearGrid.from_function(lambda u: bend(lo + u * (hi - lo)), (CELLS, 1, 1))


def tube() -> Mesh:
    """Open tube along x: 8 rings per cell, plus rings DELTA either side of each face."""
    xs = np.unique(np.r_[np.linspace(0.0, LENGTH, 8 * CELLS + 1), FACES - DELTA, FACES + DELTA])
    xs = xs[np.all(np.abs(xs[:, None] - FACES[None, :]) > DELTA / 2, axis=1)]  # none on a face
    return tube_mesh(LENGTH, RADIUS, sections=SECTIONS, ring_x=xs, phase=0.25)


def angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles (radians) between rows of unit vectors."""
    return np.arccos(np.clip(np.sum(a * b, axis=1), -1.0, 1.0))


@pytest.fixture(scope="module")
def renderer(gl_ctx: Any) -> Iterator[MeshRenderer]:
    r = MeshRenderer(gl_ctx)
    yield r
    r.release()


@pytest.fixture(scope="module")
def read_back(renderer: MeshRenderer) -> dict[str, Any]:
    mesh, grid = tube(), lattice()
    out: dict[str, Any] = {"mesh": mesh}
    for method in ("normal", "tangent"):
        inst = MeshInstance(mesh, grid, box=BOX, normal_method=method)
        pos, nrm = renderer.deformed_vertices(inst)
        out[method] = (inst, pos, nrm)
    assert renderer.program_uses["trilinear"] >= 2  # a bent lattice: the trilinear program
    return out


def test_shader_normals_match_the_cpu_reference(read_back: dict[str, Any]) -> None:
    for method in ("normal", "tangent"):
        inst, pos, nrm = read_back[method]
        np.testing.assert_allclose(pos, inst.world_vertices(), atol=1e-5)
        np.testing.assert_allclose(nrm, inst.world_normals(), atol=1e-4)


def axial_edges(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """(vertex, next vertex along the axis) pairs that stay within one cell."""
    v = mesh.vertices.astype(np.float64)
    a = np.arange(len(v) - SECTIONS)
    b = a + SECTIONS
    cell_a = np.floor(v[a, 0] / (LENGTH / CELLS))
    cell_b = np.floor(v[b, 0] / (LENGTH / CELLS))
    keep = cell_a == cell_b
    return a[keep], b[keep]


def test_tangent_normals_are_orthogonal_and_direct_ones_are_not(
    read_back: dict[str, Any],
) -> None:
    a, b = axial_edges(read_back["mesh"])
    lean = {}
    for method in ("normal", "tangent"):
        _, pos, nrm = read_back[method]
        e = pos[b] - pos[a]  # straight: a trilinear cell is linear along each axis
        lean[method] = np.abs(np.sum(nrm[a] * e, axis=1)) / np.linalg.norm(e, axis=1)
    assert lean["tangent"].max() < 1e-4
    # at a face the direct normal of the top/bottom line leans by STEP / 2 from the
    # chord's normal; the rings nearest a face lie DELTA inside the cell
    assert lean["normal"].max() > 0.9 * np.sin(STEP / 2)


def test_direct_normals_are_continuous_across_cell_faces(read_back: dict[str, Any]) -> None:
    x = read_back["mesh"].vertices[:, 0].astype(np.float64)
    jumps = {}
    for method in ("normal", "tangent"):
        _, _, nrm = read_back[method]
        jump = []
        for face in FACES:
            before = np.flatnonzero(np.isclose(x, face - DELTA, atol=1e-6))
            after = np.flatnonzero(np.isclose(x, face + DELTA, atol=1e-6))
            assert len(before) == len(after) == SECTIONS
            jump.append(angles(nrm[before], nrm[after]))
        jumps[method] = np.concatenate(jump)
    # the smooth bend turns a normal by 2 DELTA / BEND between the two rings; the direct
    # normal turns at most twice as fast as the arc (it is interpolated within a cell)
    assert jumps["normal"].max() < 2 * (2 * DELTA / BEND) + 1e-4
    # tangent space: the chord normals of neighbouring cells differ by STEP
    assert jumps["tangent"].max() > 0.9 * STEP


def test_direct_normals_are_closer_to_the_smooth_bend(read_back: dict[str, Any]) -> None:
    mesh = read_back["mesh"]
    exact = bend_normals(mesh.vertices.astype(np.float64), mesh.normals.astype(np.float64))
    err = {m: angles(read_back[m][2], exact) for m in ("normal", "tangent")}
    # tangent space: a cell's chord normal is off by up to STEP / 2 near the faces;
    # direct: the normalised mean of two node directions, exact at the faces
    assert err["tangent"].max() > 0.45 * STEP
    assert err["normal"].max() < 0.1 * err["tangent"].max()
    assert err["normal"].mean() < err["tangent"].mean()


def test_carry_normals_on_a_singular_jacobian() -> None:
    # a lattice flattened along z: J n vanishes for n = z, the tangent form stays defined
    jac = np.diag([2.0, 3.0, 0.0])[None]
    n = np.array([[0.0, 0.0, 1.0]])
    np.testing.assert_allclose(carry_normals(jac, n, "normal"), [[0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(carry_normals(jac, n, "tangent"), [[0, 0, 1]], atol=1e-12)
    shear = np.array([[[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]])
    m = np.array([[0.0, 1.0, 0.0]])
    direct = carry_normals(shear, m, "normal")
    tangent = carry_normals(shear, m, "tangent")
    np.testing.assert_allclose(direct, [[0.5 / np.sqrt(1.25), 1 / np.sqrt(1.25), 0]])
    np.testing.assert_allclose(tangent, [[0, 1, 0]], atol=1e-12)  # J^-T n for a shear


# ---------------------------------------------------------------------- fast path
def affine_lattice(box: tuple[np.ndarray, np.ndarray]) -> TrilinearGrid:
    lo, hi = box
    a = np.array([[1.3, 0.4, 0.0], [-0.2, 0.8, 0.3], [0.1, 0.0, 1.6]])
    t = np.array([0.5, -0.2, 0.3])
    return TrilinearGrid.from_function(lambda u: (lo + u * (hi - lo)) @ a.T + t, (3, 2, 2))


@pytest.mark.parametrize("method", ["normal", "tangent"])
def test_affine_lattice_takes_the_linear_program(gl_ctx: Any, method: str) -> None:
    torus = torus_mesh(1.0, 0.35, 48, 24)
    box = (np.array([-1.5, -1.5, -0.5]), np.array([1.5, 1.5, 0.5]))
    grid = affine_lattice(box)
    assert grid.is_linear
    inst = MeshInstance(torus, grid, box=box, normal_method=method)
    fast, slow = MeshRenderer(gl_ctx), MeshRenderer(gl_ctx, linear_fast_path=False)
    color = gl_ctx.texture((96, 96), 4, dtype="f4")
    depth = gl_ctx.depth_texture((96, 96))
    fbo = gl_ctx.framebuffer(color_attachments=[color], depth_attachment=depth)
    cam = Camera.fit(*MeshInstance(torus, grid, box=box).world_bounds(), (30.0, 35.0))
    images = []
    try:
        p_fast, n_fast = fast.deformed_vertices(inst)
        p_slow, n_slow = slow.deformed_vertices(inst)
        for r in (fast, slow):
            r.draw([inst], fbo, cam)
            images.append(np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32))
        assert fast.program_uses == {"linear": 2, "trilinear": 0}
        assert slow.program_uses == {"linear": 0, "trilinear": 2}
    finally:
        fast.release()
        slow.release()
        gl_ctx.detect_framebuffer(0).use()  # never release the bound framebuffer
        fbo.release()
        depth.release()
        color.release()
    # the same image: float rounding moves the coverage of a few edge pixels at most
    diff = np.abs(images[0] - images[1]).reshape(-1, 4).max(axis=1)
    assert np.mean(diff <= 1e-4) >= 0.995
    assert np.count_nonzero(images[0].reshape(-1, 4)[:, 3]) > 0.05 * 96 * 96
    # float32 arithmetic on coordinates of size ~2: a few ulps
    np.testing.assert_allclose(p_fast, p_slow, atol=2e-6 * 4)
    np.testing.assert_allclose(n_fast, n_slow, atol=1e-5)
    np.testing.assert_allclose(p_fast, inst.world_vertices(), atol=1e-5)
    np.testing.assert_allclose(n_fast, inst.world_normals(), atol=1e-5)
    # the direct transform of a shear is not the inverse transpose: the methods differ
    other = MeshInstance(
        torus, grid, box=box, normal_method=({"normal", "tangent"} - {method}).pop()
    )
    assert np.abs(other.world_normals() - n_fast).max() > 0.05


def test_bent_lattice_stays_on_the_trilinear_program(gl_ctx: Any) -> None:
    r = MeshRenderer(gl_ctx)
    try:
        r.deformed_vertices(MeshInstance(tube(), lattice(), box=BOX))
        assert r.program_uses == {"linear": 0, "trilinear": 1}
    finally:
        r.release()
    inst = MeshInstance(tube(), lattice(), box=BOX)
    assert inst.affine_matrix() is None
    grid = affine_lattice(BOX)
    m = MeshInstance(tube(), grid, box=BOX).affine_matrix()
    assert m is not None
    p = tube().vertices.astype(np.float64)
    np.testing.assert_allclose(p @ m[:3, :3].T + m[:3, 3], grid((p - BOX[0]) / (BOX[1] - BOX[0])))


def test_bench_fast_path_rows(gl_ctx: Any) -> None:
    from benchmarks.lattice import LatticeBenchReport, bench_fast_path, torus_for

    mesh = torus_for(2000)
    report = LatticeBenchReport(
        triangles_requested=2000,
        triangles=mesh.n_faces,
        vertices=mesh.n_vertices,
        objects=1,
        cells=(1,),
        frames=1,
        size=(48, 48),
    )
    bench_fast_path(report, gl_ctx, mesh, log=lambda _: None)
    assert [r.stage for r in report.fast_path] == ["frame", "vertex"]
    frame = report.fast_path[0]
    assert frame.changed is not None
    assert frame.changed < 1.0  # the same image through both programs
    assert all(r.speedup > 0 for r in report.fast_path)
    text = report.markdown("voxwarp bench lattice")
    assert "## 4. Linear fast path" in text
    assert f"| frame | {frame.trilinear_ms:.1f}" in text


def test_is_linear_tolerance_survives_the_quick_rejection() -> None:
    grid = affine_lattice(BOX)
    extent = float(np.ptp(grid.nodes.reshape(-1, 3), axis=0).max())
    for bump, linear in ((1e-12, True), (1e-7, False)):
        nodes = grid.nodes.copy()
        nodes[2, 1, 1, 0] += bump * extent  # an inner node: only the full fit sees it
        assert TrilinearGrid(nodes).is_linear is linear
        corner = grid.nodes.copy()
        corner[-1, -1, -1, 2] += bump * extent
        assert TrilinearGrid(corner).is_linear is linear


def test_bench_normals_study() -> None:
    from benchmarks.lattice_normals import markdown_lines, normals_study

    rows = {(r.scene, r.cells[0], r.method): r for r in normals_study()}
    assert len(rows) == 8
    # a bend keeps the cross-section: the direct normal is near exact, without seams
    bend = rows["bend", 4, "normal"], rows["bend", 4, "tangent"]
    assert bend[0].max_deg < 0.1 * bend[1].max_deg
    assert bend[1].seam_deg > 0.9 * 22.5 > 100 * bend[0].seam_deg  # 22.5 deg per cell
    # a non-uniform stretch: the direct normal stays off however fine the lattice,
    # the tangent-space normal converges (4x the cells: about 1/4 the max error)
    torus = {c: (rows["torus", c, "normal"], rows["torus", c, "tangent"]) for c in (12, 48)}
    assert torus[48][1].mean_deg < 0.5 * torus[48][0].mean_deg
    assert torus[48][1].max_deg < 0.6 * torus[12][1].max_deg
    assert torus[48][0].mean_deg > 0.9 * torus[12][0].mean_deg
    assert "| torus | 48x2x1 | tangent |" in "\n".join(markdown_lines(list(rows.values())))
