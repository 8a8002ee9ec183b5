"""Tests of voxwarp.deform.elements.grid: grid geometry, constraints, materials, serialisation.

Oracles are hand-computed positions, explicit index lists and a step-function volume
whose halves must map to the two stiffnesses.
"""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from voxwarp.deform.elements.grid import MAX_ELEMENTS_PER_AXIS, ElementGrid, ElementGridError

BOX = ((-10.0, 0.0, 5.0), (30.0, 20.0, 35.0))


def test_rest_positions_span_the_box_faces_included() -> None:
    g = ElementGrid(BOX, shape=(5, 3, 4), anchor="corners")
    assert g.shape == (5, 3, 4)
    np.testing.assert_allclose(g.spacing, [10.0, 10.0, 10.0])
    assert g.rest_positions.shape == (5, 3, 4, 3)
    assert g.rest_positions.dtype == np.float64
    np.testing.assert_array_equal(g.rest_positions[0, 0, 0], BOX[0])
    np.testing.assert_array_equal(g.rest_positions[-1, -1, -1], BOX[1])
    np.testing.assert_allclose(g.rest_positions[2, 1, 3], [10.0, 10.0, 35.0])
    # index runs along x, y, z
    np.testing.assert_allclose(g.rest_positions[1, 0, 0] - g.rest_positions[0, 0, 0], [10, 0, 0])
    np.testing.assert_allclose(g.rest_positions[0, 1, 0] - g.rest_positions[0, 0, 0], [0, 10, 0])


def test_volume_like_object_and_int_shape() -> None:
    vol = SimpleNamespace(bounds=(np.zeros(3), np.array([6.0, 9.0, 12.0])))
    g = ElementGrid(vol, shape=4, anchor="corners")
    assert g.shape == (4, 4, 4)
    np.testing.assert_allclose(g.spacing, [2.0, 3.0, 4.0])


def test_default_materials_and_corners_fixed() -> None:
    g = ElementGrid(BOX, shape=(3, 4, 5), anchor="corners")
    assert g.fixed.dtype == bool
    assert int(g.fixed.sum()) == 8
    for i in (0, 2):
        for j in (0, 3):
            for k in (0, 4):
                assert g.fixed[i, j, k]
    assert g.stiffness.dtype == np.float32
    assert np.all(g.stiffness == 0.5)
    assert g.damping.dtype == np.float32
    assert np.all(g.damping == 1.0)
    assert g.mass.dtype == np.float32
    assert np.all(g.mass == 1.0)


@pytest.mark.parametrize(
    ("shape", "match"),
    [
        ((1, 4, 4), r"out of range.*\[2, 128\]"),
        ((4, 4, MAX_ELEMENTS_PER_AXIS + 1), "out of range"),
        ((4, 4), "3 ints"),
        ((4.0, 4, 4), "3 ints"),
        ("abc", "3 ints"),
        (True, "must be ints"),
    ],
)
def test_bad_shape(shape: object, match: str) -> None:
    with pytest.raises(ElementGridError, match=match):
        ElementGrid(BOX, shape=shape, anchor="corners")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("bounds", "match"),
    [
        (((0, 0, 0), (1, 1, np.nan)), "finite"),
        (((0, 0, 0), (1, 0, 1)), "empty.*hi > lo"),
        (((0, 0), (1, 1)), "3-vectors"),
        (42, "bad bounds"),
    ],
)
def test_bad_bounds(bounds: object, match: str) -> None:
    with pytest.raises(ElementGridError, match=match):
        ElementGrid(bounds, shape=3, anchor="corners")


def test_fix_and_free_by_mask_index_and_list() -> None:
    g = ElementGrid(BOX, shape=(4, 4, 4), anchor="corners")
    g.free(g.corner_mask())
    assert not g.fixed.any()
    g.fix((1, 2, 3))
    assert g.fixed[1, 2, 3]
    assert int(g.fixed.sum()) == 1
    g.fix([[0, 0, 1], [3, 3, 2]])
    assert g.fixed[0, 0, 1]
    assert g.fixed[3, 3, 2]
    assert int(g.fixed.sum()) == 3
    face = np.zeros(g.shape, dtype=bool)
    face[:, :, 0] = True
    g.fix(face)
    assert int(g.fixed.sum()) == 3 + 16
    g.free(np.array([[1, 2, 3]]))
    assert not g.fixed[1, 2, 3]
    g.free(face)
    assert int(g.fixed.sum()) == 2
    assert g.fixed[0, 0, 1]
    assert g.fixed[3, 3, 2]


def test_pinned_includes_rigid_elements() -> None:
    g = ElementGrid(BOX, shape=(3, 3, 3), anchor="corners")
    g.set_material((1, 1, 1), stiffness=1.0)
    p = g.pinned()
    assert p[1, 1, 1]
    assert int(p.sum()) == 9
    assert not g.fixed[1, 1, 1]


@pytest.mark.parametrize(
    "sel",
    [(4, 0, 0), [[0, 0, 0], [1, 4, 2]], (-1, 0, 0)],
)
def test_index_out_of_range_names_index_and_shape(sel: object) -> None:
    g = ElementGrid(BOX, shape=(4, 4, 4), anchor="corners")
    with pytest.raises(ElementGridError, match=r"outside the grid of shape \(4, 4, 4\)"):
        g.fix(sel)
    assert int(g.fixed.sum()) == 8  # nothing changed


def test_bad_selection_shapes() -> None:
    g = ElementGrid(BOX, shape=(4, 4, 4), anchor="corners")
    with pytest.raises(ElementGridError, match="grid shape"):
        g.fix(np.ones((4, 4), dtype=bool))
    with pytest.raises(ElementGridError, match=r"\(m, 3\)"):
        g.fix([[1, 2], [3, 1]])
    with pytest.raises(ElementGridError, match="integers"):
        g.fix((0.5, 1, 1))


def test_set_material_values_and_validation() -> None:
    g = ElementGrid(BOX, shape=(3, 3, 3), anchor="corners")
    g.set_material([[0, 1, 2]], stiffness=0.9, damping=2.5, mass=3.0)
    assert g.stiffness[0, 1, 2] == pytest.approx(0.9)
    assert g.damping[0, 1, 2] == 2.5
    assert g.mass[0, 1, 2] == 3.0
    assert np.sum(g.stiffness != 0.5) == 1
    with pytest.raises(ElementGridError, match=r"stiffness must be in \[0, 1\]"):
        g.set_material(stiffness=1.5)
    with pytest.raises(ElementGridError, match=r"stiffness must be in \[0, 1\]"):
        g.set_material(stiffness=-0.1)
    with pytest.raises(ElementGridError, match="mass must be > 0"):
        g.set_material(mass=0.0)
    with pytest.raises(ElementGridError, match="damping must be >= 0"):
        g.set_material(damping=-1.0)
    with pytest.raises(ElementGridError, match="finite"):
        g.set_material(mass=np.nan)
    with pytest.raises(ElementGridError, match="grid shape"):
        g.set_material(stiffness=np.zeros((2, 2, 2)))
    # a failed call changes nothing, not even the valid properties given with it
    with pytest.raises(ElementGridError):
        g.set_material(damping=5.0, stiffness=2.0)
    assert np.all(g.damping[g.damping != 2.5] == 1.0)
    # arrays of the grid shape give per-element values
    s = np.linspace(0, 1, 27).reshape(3, 3, 3)
    g.set_material(stiffness=s)
    np.testing.assert_allclose(g.stiffness, s, rtol=1e-6)


def test_materials_from_volume_step_function() -> None:
    # 'bone' (1000) for x >= 50 mm, 'soft tissue' (40) below, on a 101-voxel axis
    lo, hi = np.zeros(3), np.array([100.0, 40.0, 40.0])
    xs = np.linspace(lo[0], hi[0], 101)
    data = np.where(xs >= 50.0, 1000.0, 40.0)[:, None, None] * np.ones((1, 5, 7))
    g = ElementGrid((lo, hi), shape=(9, 3, 3), anchor="corners")  # element x: 0, 12.5, ..., 100
    s = g.materials_from_volume(data, (lo, hi), [(40.0, 0.1), (1000.0, 0.9)])
    x = g.rest_positions[..., 0]
    assert np.all(np.isclose(s[x > 50.5], 0.9))
    assert np.all(np.isclose(s[x < 49.0], 0.1))
    np.testing.assert_array_equal(s, g.stiffness)
    # a callable mapping works the same way
    g.materials_from_volume(data, (lo, hi), lambda v: np.where(v > 500, 1.0, 0.2))
    assert np.all(g.pinned()[x > 50.5])
    assert not np.any(g.pinned()[(x < 49.0) & ~g.fixed])


def test_materials_from_volume_trilinear_between_voxels() -> None:
    # a linear ramp is reproduced exactly by trilinear sampling at any position
    lo, hi = np.zeros(3), np.array([10.0, 10.0, 10.0])
    n = 6
    ramp = np.linspace(0.0, 1.0, n)[None, None, :] * np.ones((n, n, 1))
    g = ElementGrid((lo, hi), shape=(4, 4, 7), anchor="corners")
    s = g.materials_from_volume(ramp, (lo, hi), lambda v: v)
    np.testing.assert_allclose(s, g.rest_positions[..., 2] / 10.0, atol=1e-6)


def test_materials_from_volume_errors() -> None:
    g = ElementGrid(BOX, shape=3, anchor="corners")
    with pytest.raises(ElementGridError, match="3-D"):
        g.materials_from_volume(np.zeros((4, 4)), BOX, [(0, 0), (1, 1)])
    with pytest.raises(ElementGridError, match=r"\[0, 1\]"):
        g.materials_from_volume(np.zeros((4, 4, 4)), BOX, [(0, 0), (1, 2)])
    with pytest.raises(ElementGridError, match="pairs"):
        g.materials_from_volume(np.zeros((4, 4, 4)), BOX, [0, 1, 2])
    with pytest.raises(ElementGridError, match=r"\[0, 1\]"):
        g.materials_from_volume(np.zeros((4, 4, 4)), BOX, lambda v: v - 1)


def test_to_dict_from_dict_round_trip_through_json() -> None:
    g = ElementGrid(BOX, shape=(4, 3, 5), anchor="corners")
    g.free((0, 0, 0))
    g.fix([[1, 1, 1], [2, 0, 4]])
    rng = np.random.default_rng(1)
    g.set_material(stiffness=rng.uniform(0, 1, g.shape).astype(np.float32), mass=2.0)
    g.set_material((3, 2, 4), damping=0.25)
    d = json.loads(json.dumps(g.to_dict()))
    h = ElementGrid.from_dict(d)
    assert h.shape == g.shape
    np.testing.assert_array_equal(h.lo, g.lo)
    np.testing.assert_array_equal(h.hi, g.hi)
    np.testing.assert_array_equal(h.rest_positions, g.rest_positions)
    np.testing.assert_array_equal(h.fixed, g.fixed)
    for name in ("stiffness", "damping", "mass"):
        np.testing.assert_array_equal(getattr(h, name), getattr(g, name))
    assert d["mass"] == 2.0  # uniform values stay one number


def test_from_dict_errors() -> None:
    with pytest.raises(ElementGridError, match="needs the keys"):
        ElementGrid.from_dict({"lo": [0, 0, 0], "shape": [2, 2, 2]})
    with pytest.raises(ElementGridError, match="stiffness"):
        ElementGrid.from_dict({"lo": [0, 0, 0], "hi": [1, 1, 1], "shape": 2, "stiffness": 3})


def test_materials_from_a_volume_object_take_its_voxel_centres() -> None:
    from voxwarp.core.volume import Volume

    data = np.zeros((20, 10, 10), np.float32)
    data[10:] = 1000.0  # the upper half in x is "bone"
    vol = Volume(data, spacing=(2.0, 1.0, 1.0), origin=(5.0, 0.0, 0.0))
    grid = ElementGrid(vol, shape=(6, 3, 3), anchor="corners")
    points = [(100.0, 0.2), (400.0, 0.95)]
    s = grid.materials_from_volume(vol, mapping=points)
    lo = np.asarray(vol.origin)
    hi = lo + np.asarray(vol.spacing) * (np.asarray(vol.shape) - 1)
    expected = ElementGrid(vol, shape=(6, 3, 3), anchor="corners").materials_from_volume(
        data, (lo, hi), points
    )
    np.testing.assert_array_equal(s, expected)
    assert s[0, 0, 0] == pytest.approx(0.2)
    assert s[-1, 0, 0] == pytest.approx(0.95)
    with pytest.raises(ElementGridError, match="needs a mapping"):
        grid.materials_from_volume(vol)
    with pytest.raises(ElementGridError, match="needs bounds"):
        grid.materials_from_volume(data, mapping=points)
