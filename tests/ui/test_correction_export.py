"""Deformation -> Export Corrected Field… in a real window (Xvfb, see conftest): the
imported field and a ChainMail correction dragged on top are written as one ITK field;
undo of the drag gives back the earlier export exactly and leaves the field imported."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PySide6.QtWidgets import QFileDialog

from tests.ui.test_add_displacement_field import action, smooth_field, window  # noqa: F401
from voxwarp.io.fields import load_displacement_field, save_displacement_field
from voxwarp.ui.correction_export import export_corrected_field


def _drag_centre_element(w: Any) -> None:
    """Hold the ChainMail element nearest the box centre 5 mm along +y (one edit)."""
    from voxwarp.editing.families.elements import ChainMailFamily

    s = w.session
    handles = s.handles()
    ref = int(np.argmin(np.linalg.norm(handles - np.mean(handles, axis=0), axis=1)))
    model = s.adapter(ChainMailFamily).model

    def move() -> None:
        model.move(tuple(int(i) for i in np.unravel_index(ref, model.grid.shape)), (0.0, 5.0, 0.0))
        s.model_moved()

    w.edit("Drag", move)


@pytest.mark.slow  # a window, a ChainMail model and four exports: ~12 s
def test_export_corrected_field_and_undo(
    window: Any,  # noqa: F811
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
) -> None:
    w = window
    field_path = save_displacement_field(smooth_field(w.session.volume), tmp_path / "reg.nii.gz")
    assert w.add_field(field_path)
    w.edit("ChainMail", lambda: w.session.set_deformation("chainmail", resolution=5))
    first = load_displacement_field(export_corrected_field(w, tmp_path / "a.nii.gz"))
    _drag_centre_element(w)
    dragged = load_displacement_field(export_corrected_field(w, tmp_path / "b.nii.gz"))
    assert np.abs(dragged.displacements - first.displacements).max() > 2.0
    w.undo_stack.undo()
    again = load_displacement_field(export_corrected_field(w, tmp_path / "c.nii.gz"))
    np.testing.assert_array_equal(again.displacements, first.displacements)
    np.testing.assert_array_equal(again.affine, first.affine)
    assert len(w.session.imported_warps) == 1
    # the menu action writes the same file through the save dialog
    out = tmp_path / "menu.h5"
    monkeypatch.setattr(
        QFileDialog, "getSaveFileName", staticmethod(lambda *a, **k: (str(out), ""))
    )
    action(w, "Export Corrected &Field…").trigger()
    assert not w.errors
    from_menu = load_displacement_field(out)
    np.testing.assert_allclose(from_menu.displacements, first.displacements, atol=1e-6)
