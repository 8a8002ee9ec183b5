"""File › Export… (:mod:`voxwarp.ui.export_dialog`): the dialog writes the three kinds.

A small scene (a 24 x 20 x 16 blob, a settled 4³ mass-spring push) in the dialog: its
estimate names the grid of the choice, and each kind it writes (deformed volume,
displacement field, det J) reads back with the grid and values the CLI gives (the
field equals ``Scene.export_field`` at the same spacing; det J is near 1 where the
push is gentle; the volume has the input's shape); a bad spacing and a failing export
are one line, and a failed export leaves no file (atomic).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from voxwarp.core.volume import Volume
from voxwarp.deform.elements.grid import ElementGrid
from voxwarp.deform.elements.massspring import MassSpring
from voxwarp.scene import Scene
from voxwarp.ui.export_dialog import ExportDialog, ExportError, parse_spacing, run_export

nib = pytest.importorskip("nibabel")


@pytest.fixture(scope="module")
def scene() -> Scene:
    idx = np.indices((24, 20, 16)).astype(float)
    r = np.sqrt(((idx[0] - 12) / 9) ** 2 + ((idx[1] - 10) / 8) ** 2 + ((idx[2] - 8) / 6) ** 2)
    vol = Volume((1000 * (r < 1)).astype(np.int16), (1.0, 1.0, 1.5), name="blob")
    ms = MassSpring(ElementGrid(vol, shape=4, anchor="corners"))
    ms.fix([(i, j, 0) for i in range(4) for j in range(4)])
    ms.move([(2, 2, 3)], np.array([[2.0, 0.0, 0.0]]))
    ms.settle(max_steps=1000)
    return Scene(vol, warps=[ms.warp()])


def test_dialog_estimate_follows_the_choice(qtbot: Any, scene: Scene, tmp_path: Path) -> None:
    dialog = ExportDialog(scene, str(tmp_path))
    qtbot.addWidget(dialog)
    assert "24x20x16 nodes" in dialog.estimate.text()  # the volume, input grid
    dialog.kind.setCurrentIndex(1)  # the field: its default spacing, and why
    assert "default spacing" in dialog.estimate.text()
    assert dialog.path.text().endswith("field.nii.gz")
    dialog.spacing.setText("2")
    assert "12x10x12 nodes" in dialog.estimate.text()
    dialog.spacing.setText("2 x")
    assert "give one positive number or three" in dialog.estimate.text()
    with pytest.raises(ExportError):
        dialog.choice()


def _recorder(steps: list[float]) -> Any:
    """A progress callback that records the fractions in ``steps``."""
    return lambda fraction, _text: steps.append(fraction)


def test_dialog_writes_the_three_kinds(qtbot: Any, scene: Scene, tmp_path: Path) -> None:
    dialog = ExportDialog(scene, str(tmp_path))
    qtbot.addWidget(dialog)
    written = {}
    for index, kind in enumerate(("volume", "field", "jacobian")):
        dialog.kind.setCurrentIndex(index)
        dialog.spacing.setText("" if kind == "volume" else "2")
        got_kind, out, grid, spacing = dialog.choice()
        assert got_kind == kind
        steps: list[float] = []
        written[kind] = run_export(scene, kind, out, grid, spacing, _recorder(steps))
        assert written[kind].is_file()
        assert steps[-1] == 1.0
    assert nib.load(written["volume"]).shape == (24, 20, 16)
    field = np.asarray(nib.load(written["field"]).get_fdata()).reshape(12, 10, 12, 3)
    ref = scene.export_field(spacing=2.0).field
    lps = np.array([-1.0, -1.0, 1.0])  # ITK's vectors are LPS
    np.testing.assert_allclose(field * lps, ref.displacements, atol=1e-5)
    assert np.abs(ref.displacements).max() > 0.5
    detj = np.asarray(nib.load(written["jacobian"]).get_fdata())
    assert detj.shape == (12, 10, 12)
    assert 0.5 < np.nanmedian(detj) < 1.5
    assert not list(tmp_path.glob(".*part*"))  # no temporary file left


def test_failed_export_is_one_line_and_writes_nothing(scene: Scene, tmp_path: Path) -> None:
    out = tmp_path / "f.txt"
    with pytest.raises(ExportError) as info:
        run_export(scene, "field", out, "input", None)
    assert "\n" not in str(info.value)
    assert "cannot write a displacement field as .txt" in str(info.value)
    assert not list(tmp_path.iterdir())
    assert parse_spacing(" ") is None
    assert parse_spacing("1, 2, 3") == [1.0, 2.0, 3.0]


def test_file_menu_opens_the_dialog_on_the_window_scene(
    qtbot: Any, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    from PySide6.QtWidgets import QDialog

    from tests.ui.test_main_window import _session
    from tests.ui.windows import shown_window

    w = shown_window(qtbot, monkeypatch, _session(), (1000, 700))
    seen: list[Any] = []

    def refuse(dialog: ExportDialog) -> int:
        seen.append((dialog.scene, dialog.estimate.text()))
        return QDialog.DialogCode.Rejected

    monkeypatch.setattr(ExportDialog, "exec", refuse)
    act = next(a for a in w.actions() if a.text() == "Export Volume, Field or det &J…")
    act.trigger()
    w.close()
    assert len(seen) == 1
    assert seen[0][0] is w.session.scene
    assert "nodes, about" in seen[0][1]
