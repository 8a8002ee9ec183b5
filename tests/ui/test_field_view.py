"""Tests of voxwarp.ui.field_view.FieldSliceView against a fake window over a real EditSession.

The fake window is the one of the panel tests (``tests/ui/test_panels.py``): the view
uses only ``window.session``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import voxwarp.render.field_views
from tests.ui.test_panels import FakeWindow, make_panel, make_session
from voxwarp.core.volume import Volume
from voxwarp.editing.session import EditSession
from voxwarp.scene import Scene
from voxwarp.ui.field_view import FieldSliceView
from voxwarp.ui.panels import DisplayPanel

TF = [(0.0, 0.0, 0.0, 0.0, 0.0), (100.0, 1.0, 1.0, 1.0, 1.0)]


def cylinder_session() -> EditSession:
    """A 24 x 24 x 32 volume with a bright cylinder along z (the default wire runs
    along the longest axis, z, through the centre: the cylinder's axis)."""
    x, y, _ = np.meshgrid(np.arange(24), np.arange(24), np.arange(32), indexing="ij")
    data = (((x - 11.5) ** 2 + (y - 11.5) ** 2) <= 16).astype(np.float32) * 100.0
    return EditSession(Scene(Volume(data, spacing=(1.0, 1.0, 1.0)), transfer_function=TF))


@pytest.fixture
def window() -> FakeWindow:
    return FakeWindow(make_session())


def make_view(qtbot: Any, window: FakeWindow, shown: bool = True) -> FieldSliceView:
    view = FieldSliceView(window)
    qtbot.addWidget(view)
    view.resize(290, 500)
    if shown:
        view.show_check.setChecked(True)
    return view


def image_of(view: FieldSliceView) -> np.ndarray:
    assert view.slice is not None
    return view.slice.image.copy()


def combo_items(view: FieldSliceView) -> list[str]:
    return [view.view_combo.itemText(i) for i in range(view.view_combo.count())]


def test_folded_by_default_and_computes_nothing(qtbot: Any, window: FakeWindow) -> None:
    window.session.set_deformation("lattice", resolution=3)
    view = make_view(qtbot, window, shown=False)
    view.refresh()
    assert not view.show_check.isChecked()
    assert view.body.isHidden()
    assert view.computations == 0
    view.show_check.setChecked(True)
    assert not view.body.isHidden()
    assert view.computations == 1
    assert view.slice is not None


def test_no_deformation(qtbot: Any, window: FakeWindow) -> None:
    view = make_view(qtbot, window)
    assert combo_items(view) == ["no deformation"]
    assert not view.view_combo.isEnabled()
    assert view.slice is None
    assert view.image_label.pixmap().isNull()


def test_switching_to_wires_lists_the_wire_views(qtbot: Any) -> None:
    window = FakeWindow(cylinder_session())
    view = make_view(qtbot, window)
    window.session.set_deformation("lattice", resolution=3)
    view.refresh()
    assert combo_items(view) == ["displacement"]
    assert view.view_combo.isEnabled()
    window.session.set_deformation("wires")
    view.refresh()
    assert combo_items(view) == list(voxwarp.render.field_views.VIEWS["wires"])
    assert view.view_combo.currentText() == "attribute t"
    assert view.slice is not None
    assert view.title_label.text().startswith("attribute t, z = ")
    assert "t: 0 (dark)" in view.legend_label.text()
    assert not view.image_label.pixmap().isNull()
    # the straight default wire sweeps the cylinder in place: swept, nothing vacated
    view.view_combo.setCurrentText("swept / vacated")
    view.axis_combo.setCurrentText("x")
    colors = {tuple(c) for c in image_of(view).reshape(-1, 3)}
    assert voxwarp.render.field_views.SWEPT_COLOR in colors
    assert voxwarp.render.field_views.VACATED_COLOR not in colors
    window.session.set_deformation("none")
    view.refresh()
    assert combo_items(view) == ["no deformation"]
    assert view.title_label.text() == "no deformation"


def test_moving_the_slider_changes_the_image(qtbot: Any) -> None:
    window = FakeWindow(cylinder_session())
    window.session.set_deformation("wires")
    view = make_view(qtbot, window)
    view.view_combo.setCurrentText("attribute t")
    view.axis_combo.setCurrentText("z")
    view.slider.setValue(20)
    low = image_of(view)
    title = view.title_label.text()
    view.slider.setValue(80)
    high = image_of(view)
    assert view.position_label.text() == "80 %"
    assert view.title_label.text() != title
    assert not np.array_equal(low, high)
    # z slices across the wire: t near 0.2 low down, near 0.8 high up (brighter)
    assert high.astype(int).sum() > low.astype(int).sum()


def test_refresh_without_change_does_not_recompute(
    qtbot: Any, window: FakeWindow, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls: list[tuple[Any, ...]] = []
    real = voxwarp.render.field_views.field_slice

    def counting(*args: Any, **kwargs: Any) -> Any:
        calls.append(args)
        return real(*args, **kwargs)

    monkeypatch.setattr(voxwarp.render.field_views, "field_slice", counting)
    window.session.set_deformation("lattice", resolution=3)
    view = make_view(qtbot, window)
    assert len(calls) == 1
    view.refresh()
    view.refresh()
    assert len(calls) == 1
    view.slider.setValue(30)
    assert len(calls) == 2
    view.refresh()
    assert len(calls) == 2
    view.axis_combo.setCurrentText("y")
    assert len(calls) == 3
    # a new warp (the lattice warp is rebuilt after an edit) recomputes
    window.session.set_deformation("lattice", resolution=4)
    view.refresh()
    assert len(calls) == 4
    view.refresh()
    assert len(calls) == 4


def test_revision_change_recomputes(
    qtbot: Any, window: FakeWindow, monkeypatch: pytest.MonkeyPatch
) -> None:
    window.session.set_deformation("massspring", resolution=4)
    warp = window.session.model_warp()
    view = make_view(qtbot, window)
    assert combo_items(view) == ["offset |d|", "displacement"]
    before = view.computations
    view.refresh()
    assert view.computations == before
    u = warp.displacements
    u[1, 1, 1] = (0.0, 0.0, 3.0)
    warp.update(u)  # the revision changes
    view.refresh()
    assert view.computations == before + 1
    assert "3 mm" in view.legend_label.text()


def test_errors_show_in_the_title(
    qtbot: Any, window: FakeWindow, monkeypatch: pytest.MonkeyPatch
) -> None:
    def failing(*_args: Any, **_kwargs: Any) -> Any:
        raise voxwarp.render.field_views.FieldViewError("cannot read the field")

    monkeypatch.setattr(voxwarp.render.field_views, "field_slice", failing)
    window.session.set_deformation("lattice", resolution=3)
    view = make_view(qtbot, window)
    assert view.title_label.text() == "cannot read the field"
    assert view.slice is None


def test_display_panel_embeds_and_refreshes_the_view(qtbot: Any, window: FakeWindow) -> None:
    panel = make_panel(qtbot, window, DisplayPanel)
    assert isinstance(panel.field_view, FieldSliceView)
    panel.field_view.show_check.setChecked(True)
    assert combo_items(panel.field_view) == ["no deformation"]
    window.session.set_deformation("massspring", resolution=3)
    panel.refresh()
    assert combo_items(panel.field_view) == ["offset |d|", "displacement"]
    assert panel.field_view.slice is not None
    panel.resize(290, panel.sizeHint().height())
    image = panel.grab().toImage()
    assert image.width() == 290


def test_a_wire_field_being_built_shows_no_field_yet(qtbot: Any) -> None:
    window = FakeWindow(cylinder_session())
    window.session.sync_builds = False  # as the GUI: fields are built off its thread
    window.session.set_deformation("wires")
    view = make_view(qtbot, window)
    assert window.session.family.field_stale
    assert view.title_label.text() == "no wires field yet"
    assert not view.view_combo.isEnabled()
    window.request_field_build()
    view.refresh()
    assert combo_items(view) == list(voxwarp.render.field_views.VIEWS["wires"])
    assert view.slice is not None
