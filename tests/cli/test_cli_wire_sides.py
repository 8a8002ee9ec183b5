"""``voxwarp slice --wires`` with ``--sides``, ``--side-falloff`` and ``--vacated``.

Volume: a cube filled everywhere with 100, a wire file bending its middle 15 mm (radius
35 mm, smooth ends, no ``sides`` key). The slice through the wire is drawn with
``--window 50,100`` so every in-volume value is white and only empty samples are black.
Oracle: with the default (smooth sides) no pixel inside the volume's box (less the
largest move at its faces, where content from beyond the face may show) is black; with
``--sides rigid`` the vacated crescent is (> 0 black pixels: the count can fail);
``--vacated rest`` fills it again. Commands run in a subprocess (see test_cli_slice.py).
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.cli.test_cli_slice import slice_cli
from tests.deform.wires.test_wire_sides import BEND, CENTRE, SIZE, SPACING, filled, spine
from voxwarp.io.volumes import save_volume


@pytest.fixture(autouse=True)
def _keep_warning_state(monkeypatch: pytest.MonkeyPatch) -> None:
    """main() replaces warnings.formatwarning for good; undo it after each test."""
    monkeypatch.setattr(warnings, "formatwarning", warnings.formatwarning)


@pytest.fixture(scope="module")
def bent(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The filled cube and a wire file without ``sides`` (the default applies)."""
    folder = tmp_path_factory.mktemp("wire_sides")
    vol = save_volume(filled(), folder / "filled.npz")
    d = spine().to_dict()
    del d["sides"]
    path = folder / "bend.json"
    path.write_text(json.dumps({"wires": [d]}))
    return vol, path


def black_inside(grey: np.ndarray, doc: dict[str, Any]) -> int:
    """Black pixels whose centre lies inside the volume's box, away from its faces by
    the wire's largest move (and a voxel)."""
    h, w = grey.shape
    cols, rows = np.meshgrid(np.arange(w), np.arange(h))
    pix = np.stack([cols, rows, np.zeros_like(cols), np.ones_like(cols)], -1).astype(float)
    world = (pix @ np.asarray(doc["pixel_to_world"]).T)[..., :3]
    margin = 1.2 * BEND + SPACING
    lo, hi = -0.5 * SPACING + margin, (SIZE - 0.5) * SPACING - margin
    inside = np.all((world >= lo) & (world <= hi), axis=-1)
    assert inside.sum() > 1000  # the slice does cross the volume
    return int(np.sum((grey == 0) & inside))


@pytest.mark.slow  # three subprocess slices
def test_default_sides_leave_no_black_pixel_and_rigid_does(
    gl_ctx: Any, bent: tuple[Path, Path]
) -> None:
    vol, wires = bent
    args = ["--wires", str(wires), "--plane", "y", "--at", str(CENTRE), "--window", "50,100"]
    smooth, doc, err = slice_cli(vol, "sides_smooth", *args)
    assert "sides: smooth, falloff 35 mm" in err
    assert black_inside(smooth, doc) == 0
    rigid, doc_r, err_r = slice_cli(vol, "sides_rigid", *args, "--sides", "rigid")
    assert "sides: rigid, vacated empty" in err_r
    assert black_inside(rigid, doc_r) > 100
    rest, doc_rest, _ = slice_cli(vol, "sides_rest", *args, "--sides", "rigid", "--vacated", "rest")
    assert black_inside(rest, doc_rest) == 0


def test_a_narrow_side_falloff_warns_in_one_line(gl_ctx: Any, bent: tuple[Path, Path]) -> None:
    vol, wires = bent
    args = ["--wires", str(wires), "--plane", "y", "--side-falloff", "5"]
    _, _, err = slice_cli(vol, "sides_narrow", *args)
    assert "faded at seams" not in err  # a gentle bend has no seam
    lines = [ln for ln in err.splitlines() if "side_falloff 5 mm" in ln]
    assert len(lines) == 1, err
    assert "folds" in lines[0]


def test_the_wires_line_counts_the_voxels_faded_at_seams(gl_ctx: Any) -> None:
    # the bundled MRI's midline wire reaches 75 mm, past its bend's ~45 mm radius of
    # curvature: the closest point jumps, the weight is faded there and the line says so
    wires = Path(__file__).resolve().parents[2] / "sample_volumes" / "colin27_midline_wires.json"
    args = ["--wires", str(wires), "--plane", "coronal", "--at", "-20", "--pixel", "2"]
    _, _, err = slice_cli(Path("sample:colin27"), "sides_seams", *args)
    line = next(ln for ln in err.splitlines() if ln.startswith("wires:"))
    faded = int(line.split("; ")[-1].split(" voxels faded at seams")[0])
    assert faded > 0, line
