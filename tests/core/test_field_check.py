"""``voxwarp.core.field_check`` and ``export_chain`` on warps with known answers.

Oracles: a quadratic displacement ``u_x = c x^2`` has trilinear error exactly ``c h^2 / 4``
at the middle of a cell edge (``c h^2/4`` along x anywhere on the cell's mid-plane); a step
(``u_x = d`` for ``x > x0``, 0 below) is a tear in the cells that straddle ``x0`` and
nowhere else; a warp that carries nothing in a slab leaves exactly the nodes in it
outside, filled from the nearest carried node.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pytest

from voxwarp.core.field_check import check_field, fill_outside, sample_carried
from voxwarp.core.field_grid import chain_field, export_chain
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import IdentityWarp, Warp, chain_apply_carried


class _Map(Warp):
    """A test warp: ``p + u(p)`` with a given ``u``, not carrying ``gone(p)``."""

    kind = "test-map"

    def __init__(self, u: Any, gone: Any = None) -> None:
        self.u, self.gone = u, gone

    def apply(self, points: np.ndarray) -> np.ndarray:
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        return p + self.u(p)

    def carried(self, points: np.ndarray) -> np.ndarray | None:
        return None if self.gone is None else ~self.gone(np.atleast_2d(points))

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.kind}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Warp:
        raise NotImplementedError


def _quadratic(c: float) -> _Map:
    return _Map(lambda p: np.c_[c * (p[:, 0] - 20.0) ** 2, np.zeros((len(p), 2))])


def _step(x0: float, d: float) -> _Map:
    return _Map(lambda p: np.c_[np.where(p[:, 0] > x0, d, 0.0), np.zeros((len(p), 2))])


@pytest.fixture
def volume() -> Volume:
    """40 mm cube of 1 mm voxels at the origin (the grid the checks run on)."""
    return Volume(np.zeros((40, 40, 40), np.float32), (1.0, 1.0, 1.0), (0.0, 0.0, 0.0))


def test_the_default_warp_carries_every_point() -> None:
    assert IdentityWarp().carried(np.zeros((3, 3))) is None
    q, ok = chain_apply_carried([IdentityWarp()], np.ones((4, 3)))
    assert ok.all()
    np.testing.assert_allclose(q, 1.0)


def test_points_sent_far_or_to_nan_are_not_carried() -> None:
    far = _Map(lambda p: np.where(p[:, :1] > 0, 1e20, np.nan) * np.ones((1, 3)))
    _, ok = chain_apply_carried([far], np.array([[1.0, 0, 0], [-1.0, 0, 0]]))
    assert not ok.any()


def test_a_quadratic_map_measures_its_analytic_error(volume: Volume) -> None:
    """``u_x = c (x - 20)^2`` at spacing h: trilinear misses by ``c h^2 / 4`` at most."""
    c, h = 0.02, 4.0
    export = export_chain(volume, [_quadratic(c)], spacing=h)
    exact = c * h * h / 4.0  # 0.08 mm
    assert export.check.max_error == pytest.approx(exact, rel=0.05)
    assert not export.check.torn.any()
    assert not export.outside.any()


def test_a_coarse_smooth_map_gets_a_spacing_that_meets_the_tolerance(volume: Volume) -> None:
    """``c h^2 / 4`` = 0.72 mm at h = 6 (over 0.5 mm): not torn; the needed spacing
    was tried and meets it; the default spacing (1 mm voxels) meets it at once."""
    warps = [_quadratic(0.08)]
    export = export_chain(volume, warps, spacing=6.0)
    assert export.check.max_error == pytest.approx(0.08 * 36 / 4, rel=0.1)
    assert not export.check.met
    assert not export.check.torn.any()
    assert export.needed_met
    h = float(export.needed_spacing[0])
    assert h < 6.0
    assert 0.08 * h * h / 4 <= 0.5
    assert export_chain(volume, warps).check.met


def test_a_step_is_torn_in_the_cells_that_straddle_it(volume: Volume) -> None:
    """A 3 mm jump at x = 18.3: the nodes at x = 18 and 19 (spacing 1) border the tear,
    no others, and the rest interpolates exactly (the map is constant on each side)."""
    export = export_chain(volume, [_step(18.3, 3.0)], spacing=1.0)
    x = np.indices(export.field.shape)[0] * export.field.spacing[0] + export.field.affine[0, 3]
    torn_x = np.unique(x[export.check.torn])
    np.testing.assert_allclose(torn_x, [18.0, 19.0])
    assert export.check.max_error < 1e-5
    assert export.check.met


def test_a_smooth_map_is_not_torn_at_any_spacing(volume: Volume) -> None:
    """Coarse cells over the parabola's vertex too (no change between their corners)."""
    for h in (2.0, 5.0, 8.0, 10.0):
        assert not export_chain(volume, [_quadratic(0.05)], spacing=h).check.torn.any()


def test_outside_nodes_take_their_nearest_carried_vector(volume: Volume) -> None:
    """Nodes with 10 < x < 14 are not carried: their vectors are those of the carried
    node nearest to each (x = 10 or 14 on the same row), within the carried range."""
    warp = _Map(
        lambda p: np.c_[p[:, 0] * 0.1, np.zeros((len(p), 2))],
        gone=lambda p: (p[:, 0] > 10.5) & (p[:, 0] < 13.5),
    )
    field, outside = chain_field([warp], np.eye(4), (20, 4, 4))
    assert outside[11:14].all()
    assert not outside[:11].any()
    assert not outside[14:].any()
    u = field.displacements[:, 0, 0, 0]
    np.testing.assert_allclose(u[[11, 12, 13]], [1.0, 1.0, 1.4], atol=1e-6)  # x 10, 10|14, 14
    carried = field.displacements[~outside]
    assert np.abs(field.displacements).max() <= np.abs(carried).max()


def test_fill_outside_without_carried_nodes_is_zero() -> None:
    u = np.ones((3, 3, 3, 3), np.float32)
    np.testing.assert_array_equal(fill_outside(u, np.ones((3, 3, 3), bool)), 0.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fill_outside_takes_the_nearest_carried_node(seed: int) -> None:
    """Each node's vector is its own index, so a filled node names the node it copied:
    that node is carried and as near as the whole grid's distance transform says (the
    fill crops the grid to the outside nodes' box grown by one node)."""
    from scipy import ndimage

    rng = np.random.default_rng(seed)
    shape = (23, 19, 17)
    outside = np.zeros(shape, bool)
    outside[4:15, 3:12, 5:16] = rng.random((11, 9, 11)) < 0.8  # a cluster off the edges
    outside[0:3, 15:19, 0:4] = True  # and one at a corner
    u = np.indices(shape).transpose(1, 2, 3, 0).astype(np.float32)
    filled = fill_outside(u.copy(), outside)
    src = filled[outside].astype(int)
    assert not outside[src[:, 0], src[:, 1], src[:, 2]].any()
    dist = np.linalg.norm(src - np.argwhere(outside), axis=1)
    np.testing.assert_allclose(dist, ndimage.distance_transform_edt(outside)[outside], atol=1e-9)
    np.testing.assert_array_equal(filled[~outside], u[~outside])


def test_in_cell_trilinear_equals_the_field_at_the_points() -> None:
    """The check's in-cell interpolation is the field's own (ITK's trilinear) at the
    same world points, on an oblique grid."""
    from voxwarp.core.field_check import _in_cells
    from voxwarp.deform.fields.displacement import DisplacementFieldWarp

    rng = np.random.default_rng(3)
    u = rng.normal(size=(7, 5, 6, 3)).astype(np.float32)
    a = np.eye(4)
    a[:3, :3] = np.array([[0.9, 0.2, 0.0], [-0.1, 1.1, 0.3], [0.0, -0.2, 1.4]])
    a[:3, 3] = (4.0, -2.0, 7.0)
    field = DisplacementFieldWarp(u, a)
    base = rng.integers(0, [6, 4, 5], size=(500, 3))
    offset = rng.random((500, 3))
    p = (base + offset) @ a[:3, :3].T + a[:3, 3]
    np.testing.assert_allclose(_in_cells(u, base, offset), field.displacement_at(p), atol=1e-9)


def test_sample_carried_is_exact_on_the_nodes() -> None:
    a = np.diag([2.0, 2.0, 2.0, 1.0])
    u, outside = sample_carried([_quadratic(0.01)], a, (5, 3, 2))
    x = np.arange(5) * 2.0
    np.testing.assert_allclose(u[:, 1, 1, 0], 0.01 * (x - 20.0) ** 2, rtol=1e-6)
    assert not outside.any()


def test_check_counts_only_points_carried_into_the_volume(volume: Volume) -> None:
    """A shift of 100 mm sends everything out of the volume: nothing is checked."""
    shift = _Map(lambda p: np.tile([100.0, 0.0, 0.0], (len(p), 1)))
    field, _ = chain_field([shift], volume.affine, volume.shape)
    check = check_field([shift], field, np.linalg.inv(volume.affine), volume.shape)
    assert check.checked == 0
    assert check.max_error == 0.0


def test_the_default_spacing_stops_at_the_node_cap(
    volume: Volume, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``u_x = 3 (x - 20)^2`` misses by ``3 / 4`` mm on the 1 mm voxel grid; a finer grid
    would be over :data:`MAX_AUTO_NODES` (patched to 50^3), so the default keeps the
    voxel grid, says ``capped`` and reports the error it measured (not met)."""
    from voxwarp.core import field_grid

    monkeypatch.setattr(field_grid, "MAX_AUTO_NODES", 50**3)
    export = export_chain(volume, [_quadratic(3.0)])
    assert export.capped
    assert not export.refined
    assert export.field.shape == volume.shape
    assert export.check.max_error == pytest.approx(0.75, rel=0.02)
    assert not export.check.met
    monkeypatch.setattr(field_grid, "MAX_AUTO_NODES", 1 << 25)
    finer = export_chain(volume, [_quadratic(3.0)])
    assert finer.refined
    assert finer.check.met
    assert finer.field.spacing[0] < 0.82  # 3 h^2 / 4 <= 0.5
