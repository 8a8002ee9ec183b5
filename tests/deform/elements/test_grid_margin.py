"""The element grid's margin: the grid's box padded beyond the volume's box (spacing
grows, the element count stays), saved with the grid, absent in old files (margin 0);
and the folds of an offset field (det J <= 0)."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from voxwarp.deform.elements.anchors import anchor_mask
from voxwarp.deform.elements.folds import corner_dets, fold_summary, folded_cells
from voxwarp.deform.elements.grid import (
    MAX_MARGIN_FACTOR,
    ElementGrid,
    ElementGridError,
    default_margin,
)
from voxwarp.deform.elements.offset_field import OffsetFieldWarp

BOX = ((-10.0, 0.0, 5.0), (30.0, 20.0, 35.0))


def test_margin_pads_the_box_and_keeps_the_element_count() -> None:
    plain = ElementGrid(BOX, shape=(5, 3, 4))
    padded = ElementGrid(BOX, shape=(5, 3, 4), margin=10.0)
    assert padded.shape == plain.shape
    np.testing.assert_array_equal(padded.lo, np.asarray(BOX[0]) - 10.0)
    np.testing.assert_array_equal(padded.hi, np.asarray(BOX[1]) + 10.0)
    np.testing.assert_array_equal(padded.volume_lo, BOX[0])
    np.testing.assert_array_equal(padded.volume_hi, BOX[1])
    # the spacing grows with the box: (size + 2 margin) / (n - 1)
    np.testing.assert_allclose(padded.spacing, [60 / 4, 40 / 2, 50 / 3])
    np.testing.assert_array_equal(padded.rest_positions[0, 0, 0], padded.lo)
    np.testing.assert_array_equal(padded.rest_positions[-1, -1, -1], padded.hi)
    # the anchor's elements are those of the padded grid (its shell: the margin's faces)
    np.testing.assert_array_equal(padded.fixed, anchor_mask(padded.shape, padded.anchor))
    assert padded.fixed[-1, -1, -1]


def test_margin_zero_is_the_grid_of_before() -> None:
    a, b = ElementGrid(BOX, shape=6), ElementGrid(BOX, shape=6, margin=0.0)
    np.testing.assert_array_equal(a.rest_positions, b.rest_positions)
    np.testing.assert_array_equal(a.lo, BOX[0])
    assert "margin" not in a.to_dict()  # files stay as they were


def test_margin_is_saved_and_old_files_load_with_none() -> None:
    grid = ElementGrid(BOX, shape=(4, 4, 4), margin=7.5)
    d = json.loads(json.dumps(grid.to_dict()))
    assert d["margin"] == 7.5
    assert d["lo"] == list(BOX[0])  # the volume's box; the margin pads it
    again = ElementGrid.from_dict(d)
    np.testing.assert_array_equal(again.rest_positions, grid.rest_positions)
    del d["margin"]  # a file from before the margin
    old = ElementGrid.from_dict(d)
    assert old.margin == 0.0
    np.testing.assert_array_equal(old.lo, BOX[0])


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), "wide", True, 1e9])
def test_bad_margin_is_a_one_line_error(bad: object) -> None:
    with pytest.raises(ElementGridError, match="margin") as info:
        ElementGrid(BOX, shape=4, margin=bad)  # type: ignore[arg-type]
    assert "\n" not in str(info.value)
    assert "give a margin in mm" in str(info.value)


def test_largest_allowed_margin() -> None:
    most = MAX_MARGIN_FACTOR * 40.0  # the box's largest side is 40 mm
    assert ElementGrid(BOX, shape=2, margin=most).margin == most


def test_default_margin_is_the_largest_drag_component() -> None:
    assert default_margin([]) == 0.0
    assert default_margin([(0.0, 15.0, 0.0), (-20.0, 3.0, 1.0)]) == 20.0
    assert default_margin(np.full((2, 2, 3), -4.0)) == 4.0


def test_settings_margin_pads_the_builders_grid() -> None:
    from voxwarp.editing import model_settings as ms
    from voxwarp.editing.families.elements import ChainMailFamily

    vol = SimpleNamespace(bounds=BOX)
    grid = ChainMailFamily.grid(ms.ChainMailSettings(shape=(3, 3, 3), margin=5.0), vol)
    np.testing.assert_array_equal(grid.lo, np.asarray(BOX[0]) - 5.0)
    assert ChainMailFamily.grid(ms.ChainMailSettings(shape=(3, 3, 3)), vol).margin == 0.0
    with pytest.raises(ms.SettingError, match="margin") as info:
        ChainMailFamily.grid(ms.ChainMailSettings(shape=(3, 3, 3), margin=-1.0), vol)
    assert info.value.setting == "margin"


# ---------------------------------------------------------------------- folds
def _fold_field(push: float) -> tuple[np.ndarray, np.ndarray]:
    """A 5³ node field over 0..40 mm (10 mm spacing): node (2, 2, 2) pushed along +x."""
    u = np.zeros((5, 5, 5, 3))
    u[2, 2, 2, 0] = push
    return u, np.full(3, 10.0)


def test_corner_dets_are_the_trilinear_jacobians() -> None:
    u, h = _fold_field(4.0)
    dets = corner_dets(u, h)
    # at node (2, 2, 2), the corner of 8 cells: du_x/dx = +-0.4 along x, the rest 0
    assert dets.shape == (8, 4, 4, 4)
    np.testing.assert_allclose(dets[7, 1, 1, 1], 1.4)  # cell (1,1,1), its corner (+,+,+)
    np.testing.assert_allclose(dets[6, 2, 1, 1], 0.6)  # cell (2,1,1), its corner (-,+,+)
    assert not folded_cells(u, h).any()


def test_a_folded_field_is_found_and_said_in_one_line() -> None:
    u, h = _fold_field(15.0)  # past its +x neighbour, 10 mm away: det 1 - 1.5 < 0
    folded = folded_cells(u, h)
    assert folded.sum() == 4  # the 4 cells on the +x side of the node
    assert folded[2, 1:3, 1:3].all()
    line = fold_summary(u, np.zeros(3), h)
    assert line is not None
    assert "\n" not in line
    assert "in 4 of 64 cells" in line
    assert "det J <= 0" in line
    warp = OffsetFieldWarp(np.zeros(3), np.full(3, 40.0), u)
    assert warp.fold_summary() == line
    smooth = OffsetFieldWarp(np.zeros(3), np.full(3, 40.0), _fold_field(4.0)[0])
    assert smooth.fold_summary() is None


@pytest.mark.parametrize("kind", ["massspring", "chainmail"])
def test_a_saved_model_keeps_its_margin(kind: str) -> None:
    """Scene JSON of a padded model: the grid entry has "margin", the warp spans the padded
    box, and the resumed model has the same grid; without the key it is the plain box."""
    from voxwarp.deform.elements.chainmail import ChainMail
    from voxwarp.deform.elements.massspring import MassSpring
    from voxwarp.deform.warp import warp_from_dict

    cls = MassSpring if kind == "massspring" else ChainMail
    model = cls(ElementGrid(BOX, shape=4, margin=8.0))
    model.move((1, 2, 2), (0.0, 3.0, 0.0))
    d = json.loads(json.dumps(model.warp().to_dict()))
    assert d["model"]["grid"]["margin"] == 8.0
    warp = warp_from_dict(d)
    np.testing.assert_array_equal(warp.lo, np.asarray(BOX[0]) - 8.0)
    resumed = cls.from_warp(warp)
    np.testing.assert_array_equal(resumed.grid.rest_positions, model.grid.rest_positions)
    assert resumed.grid.margin == 8.0
    model.close()
    resumed.close()
