"""A lattice read from a file whose cells fold (turn inside out) renders with one warning
naming the first folded cell (issue 17, finding 8)."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from voxwarp.deform.lattice.trilinear import TrilinearGrid
from voxwarp.deform.lattice.warp import FoldedLatticeWarning, LatticeWarp

BOX = [[0.0, 0.0, 0.0], [10.0, 10.0, 10.0]]


def _grid(fold: tuple[int, int, int] | None = None, mirror: bool = False) -> TrilinearGrid:
    """A 2x2x2-cell lattice over BOX; ``fold``: push that node deep into the
    neighbouring cell (through the cell's opposite faces), ``mirror``: flip x."""
    nodes = TrilinearGrid.from_function(lambda u: u * 10.0, (2, 2, 2)).nodes.copy()
    if mirror:
        nodes[..., 0] = 10.0 - nodes[..., 0]
    if fold is not None:
        nodes[fold] = [2.0, 2.0, 2.0]
    return TrilinearGrid(nodes)


def _entry(grid: TrilinearGrid) -> dict:
    return {"type": "lattice", "grid": grid.to_dict(), "box": BOX}


def _folds_reported(entry: dict) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        LatticeWarp.from_dict(entry)
    return [str(w.message) for w in caught if issubclass(w.category, FoldedLatticeWarning)]


def test_regular_and_mirrored_lattices_do_not_warn() -> None:
    assert _folds_reported(_entry(_grid())) == []
    assert _folds_reported(_entry(_grid(mirror=True))) == []  # reversed but invertible


def test_folded_lattice_warns_once_naming_the_cell() -> None:
    grid = _grid(fold=(2, 2, 2))  # the far corner pushed into cell (0, 0, 0)'s space
    # the oracle: det J of cell (1, 1, 1) at its far corner, whose three edges now point back
    n = grid.nodes
    edges = [n[2, 2, 2] - n[1, 2, 2], n[2, 2, 2] - n[2, 1, 2], n[2, 2, 2] - n[2, 2, 1]]
    assert np.linalg.det(np.stack(edges, axis=1)) < 0
    msgs = _folds_reported(_entry(grid))
    assert len(msgs) == 1
    assert "cell (1, 1, 1)" in msgs[0]
    assert "\n" not in msgs[0]
    assert [tuple(c) for c in grid.folded_cells()] == [(1, 1, 1)]


def test_folded_lattice_file_warns_and_still_builds(tmp_path: Path) -> None:
    from voxwarp.core.volume import Volume
    from voxwarp.inputs import load_lattice_file

    path = tmp_path / "fold.json"
    path.write_text(json.dumps({"grid": _grid(fold=(2, 2, 2)).to_dict(), "box": BOX}))
    vol = Volume(np.zeros((11, 11, 11), np.uint8))
    with pytest.warns(FoldedLatticeWarning, match=r"cell \(1, 1, 1\)"):
        warp = load_lattice_file(path, vol)
    assert isinstance(warp, LatticeWarp)
