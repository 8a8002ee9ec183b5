"""The support of warps and chains (voxwarp.deform.support, Warp.support_bricks).

Oracles: the CPU warps themselves. The support map is conservative: random deformed
points outside every support brick are moved by at most the tolerance (per axis) by the
chain's CPU reference (``chain_apply``), for an offset field (a local drag), a lattice
with one node moved, an imported displacement field with a local bump, and chains of
them; a warp that moves nothing has an empty support; the offset field's moved-cells
bound is checked against a brute-force scan of the cells each box touches.
"""

from __future__ import annotations

import numpy as np
import pytest

from voxwarp.deform.elements.field_support import boxes_touching, moved_cells
from voxwarp.deform.elements.offset_field import OffsetFieldWarp
from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.deform.lattice.trilinear import TrilinearGrid
from voxwarp.deform.lattice.warp import LatticeWarp
from voxwarp.deform.support import MAX_BRICKS, brick_shape, chain_support
from voxwarp.deform.warp import AffineWarp, IdentityWarp, Warp, chain_apply

LO = np.array([-40.0, -30.0, -20.0])
HI = np.array([40.0, 50.0, 60.0])
TOL = 1e-3


def local_drag(inverse: str = "baked") -> OffsetFieldWarp:
    """A 9³ offset field over [LO, HI]: one inner node moved 6 mm, its neighbours 3 mm."""
    u = np.zeros((9, 9, 9, 3))
    u[3, 5, 4] = (6.0, -2.0, 1.0)
    for d in ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0)):
        u[3 + d[0], 5 + d[1], 4 + d[2]] = (3.0, -1.0, 0.5)
    return OffsetFieldWarp(LO, HI, u, inverse=inverse)


def lattice_nudge() -> LatticeWarp:
    """A 4³-node lattice over [LO, HI] (nodes in world mm) with one inner node moved
    about a tenth of a cell."""
    t = np.linspace(0.0, 1.0, 4)
    unit = np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1)
    nodes = LO + unit * (HI - LO)
    nodes[1, 2, 1] += (3.0, -2.0, 1.5)
    return LatticeWarp(TrilinearGrid(nodes), (LO, HI))


def field_bump() -> DisplacementFieldWarp:
    """A 17³ displacement field (5 mm spacing) with a smooth local bump of 4 mm."""
    n = 17
    idx = np.stack(np.indices((n, n, n)), axis=-1).astype(float)
    r2 = np.sum((idx - (5.0, 9.0, 8.0)) ** 2, axis=-1)
    u = np.zeros((n, n, n, 3))
    u[..., 0] = 4.0 * np.clip(1.0 - r2 / 9.0, 0.0, None) ** 2
    affine = np.diag([5.0, 5.0, 5.0, 1.0])
    affine[:3, 3] = LO
    return DisplacementFieldWarp(u, affine)


def outside_points(warps: list[Warp], brick_mm: float, n: int = 40000) -> tuple:
    """Random points of [LO, HI] and the support map's verdict on them."""
    smap = chain_support(warps, LO, HI, brick_mm, TOL)
    p = LO + np.random.default_rng(7).random((n, 3)) * (HI - LO)
    return smap, p, ~smap.contains(p)


#: chains whose support is local (a part of the box is left out)
CHAINS = {
    "offset field, baked": lambda: [local_drag("baked")],
    "offset field, exact": lambda: [local_drag("exact")],
    "displacement field": lambda: [field_bump()],
    "offset field then field": lambda: [local_drag(), field_bump()],
    "identity then offset field": lambda: [IdentityWarp(), local_drag()],
    "lattice then offset field": lambda: [lattice_nudge(), local_drag()],
}


@pytest.mark.parametrize("name", list(CHAINS))
@pytest.mark.parametrize("brick_mm", [4.0, 10.0])
def test_points_outside_the_support_do_not_move(name: str, brick_mm: float) -> None:
    warps = CHAINS[name]()
    smap, p, outside = outside_points(warps, brick_mm)
    moved = np.abs(chain_apply(warps, p) - p).max(axis=1)
    if "lattice" not in name:  # a lattice's interval bound is not local (see below)
        assert outside.any(), "the support must leave something out (else the test is empty)"
    assert not outside.any() or moved[outside].max() <= TOL
    # and it is a support: the points that move lie in it, and some do
    assert (moved > TOL).any()
    assert smap.contains(p[moved > TOL]).all()


def test_a_lattice_support_holds_its_moved_points() -> None:
    """The lattice's support comes from its displacement intervals (the default), which
    cover its whole box today: conservative, and every moved point is in it."""
    warps: list[Warp] = [lattice_nudge()]
    smap, p, outside = outside_points(warps, 10.0)
    moved = np.abs(chain_apply(warps, p) - p).max(axis=1) > TOL
    assert moved.any()
    assert smap.contains(p[moved]).all()
    assert not (outside & moved).any()


def test_a_local_drag_has_a_local_support() -> None:
    smap, _, outside = outside_points([local_drag()], 5.0)
    assert 0.0 < smap.fraction < 0.5
    assert outside.mean() > 0.5


@pytest.mark.parametrize(
    "warp",
    [IdentityWarp(), OffsetFieldWarp(LO, HI, np.zeros((5, 5, 5, 3)), inverse="baked")],
    ids=["identity", "zero offset field"],
)
def test_a_warp_that_moves_nothing_has_no_support(warp: Warp) -> None:
    assert chain_support([warp], LO, HI, 5.0, TOL).fraction == 0.0


def test_a_translation_moves_everything() -> None:
    assert chain_support([AffineWarp.translation((0, 0, 0.01))], LO, HI, 5.0, TOL).fraction == 1


def test_displacements_below_the_tolerance_are_no_support() -> None:
    u = np.zeros((5, 5, 5, 3))
    u[2, 2, 2] = (0.5 * TOL, 0.0, 0.0)
    assert chain_support([OffsetFieldWarp(LO, HI, u)], LO, HI, 5.0, TOL).fraction == 0.0
    u[2, 2, 2] = (3 * TOL, 0.0, 0.0)
    assert chain_support([OffsetFieldWarp(LO, HI, u)], LO, HI, 5.0, TOL).fraction > 0.0


def test_brick_shape_is_capped() -> None:
    assert brick_shape(LO, HI, 1.0) == (MAX_BRICKS, MAX_BRICKS, MAX_BRICKS)
    assert brick_shape(LO, HI, 10.0) == (8, 8, 8)
    assert brick_shape(LO, LO, 10.0) == (1, 1, 1)


def test_boxes_touching_matches_a_brute_force_scan() -> None:
    rng = np.random.default_rng(1)
    cells = rng.random((6, 5, 7)) < 0.08
    grid_lo, spacing = np.array([1.0, -2.0, 0.5]), np.array([2.0, 3.0, 1.5])
    lo = grid_lo - 4.0 + rng.random((500, 3)) * 20.0
    hi = lo + rng.random((500, 3)) * 6.0
    got = boxes_touching(cells, grid_lo, spacing, lo, hi)
    idx = np.argwhere(cells)
    c_lo, c_hi = grid_lo + idx * spacing, grid_lo + (idx + 1) * spacing
    pairs = zip(lo, hi, strict=True)
    want = [bool(np.any(np.all((c_lo <= h) & (c_hi >= lw), axis=1))) for lw, h in pairs]
    assert got.tolist() == want


def test_moved_cells_are_dilated_by_one_cell() -> None:
    u = np.zeros((6, 6, 6, 3))
    u[3, 3, 3] = (1.0, 0.0, 0.0)
    cells = moved_cells(u, TOL)
    # the node touches cells 2..3 per axis; one more either side: 1..4
    assert cells.sum() == 4**3
    assert cells[1:5, 1:5, 1:5].all()


@pytest.mark.slow
def test_a_wire_support_is_local_and_holds_its_moved_points() -> None:
    """A bent wire on a real head (its influence region): the default interval bound."""
    from tests.model_scenes import padded_colin, wire_bend
    from voxwarp.deform.warp import chain_apply_carried
    from voxwarp.scene import Scene

    vol = padded_colin()
    warps = wire_bend(vol, 12.0, 20.0)
    lo, hi = Scene(vol, warps=warps).ray_bounds()
    tol = 1e-3 * float(np.min(vol.spacing))
    smap = chain_support(warps, lo, hi, 16.0, tol)
    assert 0.0 < smap.fraction < 0.6
    p = lo + np.random.default_rng(3).random((20000, 3)) * (hi - lo)
    q, _ = chain_apply_carried(warps, p)
    moved = np.abs(q - p).max(axis=1) > tol
    assert moved.any()
    assert smap.contains(p[moved]).all()


def test_the_support_surface_is_the_faces_between_support_and_the_rest() -> None:
    """One brick: its 6 faces; two neighbours: 10 (the shared face is inside); a full
    map: its outer faces only, each row of faces one rectangle. A random map: the
    rectangles' area is that of its brick faces between support and the rest, counted
    one by one, per axis."""
    from voxwarp.deform.support import SupportMap

    def surface(moved: np.ndarray) -> tuple[int, float]:
        smap = SupportMap(np.zeros(3), np.asarray(moved.shape, float) * 2.0, moved)
        tris = smap.boundary_triangles().astype(float)
        cross = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
        return len(tris), float(np.linalg.norm(cross, axis=1).sum() / 2.0)

    one = np.zeros((3, 3, 3), dtype=bool)
    one[1, 1, 1] = True
    assert surface(one) == (12, 6 * 4.0)
    two = one.copy()
    two[2, 1, 1] = True
    assert surface(two) == (20, 10 * 4.0)
    # rows: x faces 2 planes x 3 rows, y faces 2 x 2, z faces 2 x 2: 14 rectangles
    assert surface(np.ones((2, 3, 4), dtype=bool)) == (28, 4.0 * 2 * 26)
    assert surface(np.zeros((2, 2, 2), dtype=bool)) == (0, 0.0)
    moved = np.random.default_rng(3).random((7, 5, 6)) < 0.4
    faces = 0
    for axis in range(3):
        pad = [(0, 0)] * 3
        pad[axis] = (1, 1)
        faces += int(np.count_nonzero(np.diff(np.pad(moved, pad).astype(int), axis=axis)))
    count, area = surface(moved)
    assert area == pytest.approx(4.0 * faces)
    assert count < 2 * faces  # rows merged


def test_grown_surface_rectangles_widen_in_their_plane() -> None:
    """``grow`` widens each rectangle by that fraction of a brick on every side, in
    its own plane (the face planes stay where they are)."""
    from voxwarp.deform.support import SupportMap

    moved = np.zeros((3, 3, 3), dtype=bool)
    moved[1, 1, 1] = True
    smap = SupportMap(np.zeros(3), np.full(3, 6.0), moved)  # 2 mm bricks
    plain = smap.boundary_triangles().astype(float)
    grown = smap.boundary_triangles(0.1).astype(float)
    assert grown.shape == plain.shape == (12, 3, 3)
    for tris in (plain, grown):
        # each corner lies on one of the brick's face planes (2 or 4 mm along an axis)
        on_plane = np.isclose(tris, 2.0) | np.isclose(tris, 4.0)
        assert np.all(on_plane.any(axis=-1))
    area = np.linalg.norm(np.cross(grown[:, 1] - grown[:, 0], grown[:, 2] - grown[:, 0]), axis=1)
    assert area.sum() / 2.0 == pytest.approx(6 * (2.0 * 1.2) ** 2, rel=1e-6)
    assert grown.min() == pytest.approx(2.0 - 0.2)
    assert grown.max() == pytest.approx(4.0 + 0.2)
