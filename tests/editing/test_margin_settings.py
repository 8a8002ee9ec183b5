"""The editor's grid margin (FamilyOptions.margin, the Model group's Margin row): new
element models get a padded grid; the scene's editor entry keeps it, and entries saved
before the margin load with 0."""

from __future__ import annotations

import numpy as np
import pytest

from voxwarp.core.volume import Volume
from voxwarp.editing.model_settings import FamilyOptions
from voxwarp.editing.session import EditorError, EditSession
from voxwarp.scene import Scene


@pytest.fixture
def volume() -> Volume:
    return Volume(np.zeros((12, 10, 8), np.float32), spacing=(2.0, 2.0, 2.0))


@pytest.mark.parametrize("kind", ["massspring", "chainmail"])
def test_new_models_get_the_margin(volume: Volume, kind: str) -> None:
    session = EditSession(Scene(volume))
    session.set_deformation(kind, resolution=4, margin=6.0)
    grid = session.model.grid
    lo, hi = (np.asarray(b) for b in volume.bounds)
    np.testing.assert_allclose(grid.lo, lo - 6.0)
    np.testing.assert_allclose(grid.hi, hi + 6.0)
    assert grid.shape == (4, 4, 4)
    np.testing.assert_allclose(session.model.warp().lo, lo - 6.0)  # the field covers it
    session.set_deformation(kind, margin=0.0)
    np.testing.assert_allclose(session.model.grid.lo, lo)


def test_margin_in_the_editor_entry() -> None:
    options = FamilyOptions().with_model_settings({"margin": 12.5})
    entry = options.to_entry()
    assert entry["margin"] == 12.5
    again = FamilyOptions()
    again.read_entry(entry)
    assert again.margin == 12.5
    assert "margin" not in FamilyOptions().to_entry()  # 0: the entry of before
    old = FamilyOptions(margin=3.0)
    old.read_entry({"integrator": "semi-implicit"})  # an entry from before the margin
    assert old.margin == 3.0  # missing keys stay


@pytest.mark.parametrize("bad", [-1.0, "wide", float("nan")])
def test_bad_margin_is_refused(bad: object) -> None:
    with pytest.raises(EditorError, match="margin must be a number of mm >= 0"):
        FamilyOptions().with_model_settings({"margin": bad})
