"""The editor's grid margin (FamilyOptions.margin, the Model group's Margin row): new
element models get a padded grid, by default ``"auto"`` (10 % of the volume box's
largest side, resolved when the model is built); the scene's editor entry keeps what
was chosen, and entries saved before the margin load with 0.

Oracles: the volume's box and the documented fraction (grid.lo = box lo - margin), and
the offset field's bound (content moves at most as far as the farthest dragged element,
so a drag across a face grows the deformed box by exactly that drag)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from voxwarp.core.camera import Camera
from voxwarp.core.volume import Volume
from voxwarp.deform.elements.grid import ElementGrid
from voxwarp.deform.elements.margin import AUTO_MARGIN_FRACTION, auto_margin
from voxwarp.editing.model_settings import FamilyOptions
from voxwarp.editing.session import EDITOR_KEY, EditorError, EditSession
from voxwarp.scene import Scene

SIZE = (320, 240)


@pytest.fixture
def volume() -> Volume:
    """Box (-1, -1, -1) .. (23, 19, 15) mm: the largest side is 24 mm."""
    return Volume(np.zeros((12, 10, 8), np.float32), spacing=(2.0, 2.0, 2.0))


def box(volume: Volume) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = (np.asarray(b, dtype=np.float64) for b in volume.bounds)
    return lo, hi


def test_auto_margin_is_the_documented_fraction_of_the_largest_side() -> None:
    assert AUTO_MARGIN_FRACTION == 0.1
    assert auto_margin((24.0, 20.0, 16.0)) == pytest.approx(2.4)
    assert auto_margin((100.0, 217.0, 181.0)) == pytest.approx(21.7)  # a head MRI
    grid = ElementGrid(((0, 0, 0), (50, 200, 10)), shape=3, margin="auto")
    assert grid.margin == pytest.approx(20.0)
    np.testing.assert_allclose(grid.lo, (-20.0, -20.0, -20.0))
    np.testing.assert_allclose(grid.hi, (70.0, 220.0, 30.0))
    assert grid.to_dict()["margin"] == pytest.approx(20.0)  # saved resolved, in mm


@pytest.mark.parametrize("kind", ["massspring", "chainmail"])
def test_a_new_model_gets_the_auto_margin(volume: Volume, kind: str) -> None:
    session = EditSession(Scene(volume))
    assert session.options.margin == "auto"
    session.set_deformation(kind, resolution=4)
    lo, hi = box(volume)
    margin = 0.1 * 24.0  # 10 % of the largest side (x: 12 voxels of 2 mm)
    grid = session.model.grid
    assert grid.margin == pytest.approx(margin)
    np.testing.assert_allclose(grid.lo, lo - margin)
    np.testing.assert_allclose(grid.hi, hi + margin)
    np.testing.assert_allclose(session.model.warp().lo, lo - margin)  # the field covers it
    assert "grid margin 2.4 mm beyond the volume's box" in session.family.boundary_text()


@pytest.mark.parametrize("kind", ["massspring", "chainmail"])
def test_a_typed_margin_and_0_are_used(volume: Volume, kind: str) -> None:
    session = EditSession(Scene(volume))
    session.set_deformation(kind, resolution=4, margin=6.0)
    grid = session.model.grid
    lo, hi = box(volume)
    np.testing.assert_allclose(grid.lo, lo - 6.0)
    np.testing.assert_allclose(grid.hi, hi + 6.0)
    assert grid.shape == (4, 4, 4)
    np.testing.assert_allclose(session.model.warp().lo, lo - 6.0)
    session.set_deformation(kind, margin=0.0)
    np.testing.assert_allclose(session.model.grid.lo, lo)
    np.testing.assert_allclose(session.model.grid.hi, hi)
    assert "grid margin 0 mm (the volume's box)" in session.family.boundary_text()
    session.set_deformation(kind, margin="auto")
    assert session.model.grid.margin == pytest.approx(2.4)


def test_margin_in_the_editor_entry() -> None:
    options = FamilyOptions().with_model_settings({"margin": 12.5})
    entry = options.to_entry()
    assert entry["margin"] == 12.5
    again = FamilyOptions()
    again.read_entry(entry)
    assert again.margin == 12.5
    assert FamilyOptions().to_entry()["margin"] == "auto"  # what the user chose
    zero = FamilyOptions()
    zero.read_entry(FamilyOptions(margin=0.0).to_entry())
    assert zero.margin == 0.0
    old = FamilyOptions()
    old.read_entry({"integrator": "semi-implicit"})  # an entry from before the margin
    assert old.margin == 0.0


@pytest.mark.parametrize("margin", ["auto", 0.0, 7.5])
def test_a_saved_scene_keeps_the_margin_setting(
    volume: Volume, tmp_path: Path, margin: float | str
) -> None:
    session = EditSession(Scene(volume))
    session.set_deformation("chainmail", resolution=4, margin=margin)
    built = session.model.grid.margin
    path = session.save(tmp_path / "s.json")
    loaded = EditSession.load(path)
    assert loaded.options.margin == margin
    assert loaded.model.grid.margin == pytest.approx(built)  # the saved model as it was


def test_an_old_editor_entry_loads_as_margin_0(volume: Volume, tmp_path: Path) -> None:
    session = EditSession(Scene(volume))
    session.set_deformation("chainmail", resolution=4, margin=0.0)
    d = session.to_dict(base_dir=tmp_path)
    del d[EDITOR_KEY]["margin"]  # as saved before the margin
    d[EDITOR_KEY]["deformation"] = "chainmail"
    path = tmp_path / "old.json"
    path.write_text(json.dumps(d))
    loaded = EditSession.load(path)
    assert loaded.options.margin == 0.0
    lo, _ = box(volume)
    np.testing.assert_allclose(loaded.model.grid.lo, lo)  # renders as before
    loaded.set_deformation("massspring", resolution=4)  # a new model: as before, too
    np.testing.assert_allclose(loaded.model.grid.lo, lo)


@pytest.mark.parametrize("bad", [-1.0, "wide", float("nan")])
def test_bad_margin_is_refused(bad: object) -> None:
    with pytest.raises(EditorError, match="margin must be 'auto' or a number of mm >= 0"):
        FamilyOptions().with_model_settings({"margin": bad})


def drag_x_faces(session: EditSession) -> tuple[float, np.ndarray]:
    """Select the middle elements just inside the -x and +x faces of the volume's box,
    drag them with the mouse (view along z) and return the x offset and the scene's
    deformed box."""
    grid = session.model.grid
    rest = grid.rest_positions
    inside = np.flatnonzero(
        (rest[:, 0, 0, 0] >= grid.volume_lo[0]) & (rest[:, 0, 0, 0] <= grid.volume_hi[0])
    )
    mid = grid.shape[1] // 2, grid.shape[2] // 2
    picks = [int(np.ravel_multi_index((i, *mid), grid.shape)) for i in (inside[0], inside[-1])]
    session.select(picks)
    handles = session.handles()
    cam = Camera.fit(handles.min(axis=0), handles.max(axis=0), "+z", "orthographic")
    pixel = cam.project(handles[session.reference], SIZE)[0]
    assert session.begin_drag(cam, SIZE, pixel)
    delta = session.drag_to(pixel + np.array([12.0, 0.0]))
    session.end_drag()
    assert delta is not None
    return float(delta[0]), np.stack(session.scene.deformed_bounds())


def test_a_drag_across_a_face_carries_content_beyond_the_box(volume: Volume) -> None:
    """Two elements on the x faces dragged along x: one pushes content out of the box;
    with the auto margin the deformed box grows by the drag, with 0 it stays the box."""
    lo, hi = box(volume)
    session = EditSession(Scene(volume))
    session.set_deformation("chainmail", resolution=9)
    dx, bounds = drag_x_faces(session)
    assert 1.0 < abs(dx) < session.model.grid.margin  # the drag stays inside the grid
    grown = bounds[1, 0] - hi[0] if dx > 0 else lo[0] - bounds[0, 0]
    assert grown == pytest.approx(abs(dx), rel=1e-6)
    np.testing.assert_allclose(bounds[:, 1:], np.stack((lo, hi))[:, 1:])  # only along x
    session.set_deformation("chainmail", resolution=9, margin=0.0)
    _, cut = drag_x_faces(session)
    np.testing.assert_allclose(cut, np.stack((lo, hi)))  # the box: content is cut off
