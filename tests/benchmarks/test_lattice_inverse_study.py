"""Tests of the lab's lattice inverse study (benchmarks.lattice_inverse): its test lattices and
the error table of its one bent lattice.

Oracles: the Bernstein certificate that the random lattices do not fold, checked against
the grid's own folded cells and dense samples of ``det J``, and refusing a folded lattice;
on the bent lattice, each Newton step helps, the seed alone is the least accurate and the
default's residual lies far below its tolerance (quadratic convergence).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from benchmarks.lattice_inverse import (
    _cell_dets,
    bent_grid,
    certified_nonfolding,
    format_error_table,
    inverse_error_table,
    random_lattice,
)
from voxwarp.deform.lattice.trilinear import TrilinearGrid
from voxwarp.deform.lattice.warp import DEFAULT_ITERATIONS, DEFAULT_TOLERANCE, LatticeWarp

#: the box of the random lattices (tests/deform/lattice/test_lattice_inverse_convergence.py's)
RANDOM_BOX = (np.array([-10.0, 0.0, 5.0]), np.array([70.0, 60.0, 85.0]))
#: the box of the bent lattice (tests/deform/lattice/test_lattice_warp.py's)
BOX = (np.array([-10.0, 0.0, 5.0]), np.array([54.0, 48.0, 61.0]))


def bent(**kw: Any) -> LatticeWarp:
    """The error study's bent lattice (4³ cells) on BOX: its surface leaves the box."""
    return LatticeWarp(bent_grid(4, *BOX), BOX, **kw)


def test_random_lattices_are_proven_nonfolding() -> None:
    rng = np.random.default_rng(0)
    t = np.linspace(0.0, 1.0, 9)
    f = np.stack(np.meshgrid(t, t, t, indexing="ij"), -1).reshape(-1, 3)
    for k in range(24):
        grid = random_lattice(rng, 1 + k % 4, RANDOM_BOX, 0.6, "one" if k % 2 else "all")
        assert certified_nonfolding(grid)
        assert len(grid.folded_cells()) == 0
        assert _cell_dets(np.asarray(grid.nodes), f).min() > 0.0
    # the certificate refuses a folded lattice (a node pushed past its neighbour)
    nodes = np.array(TrilinearGrid.from_box(*RANDOM_BOX, cells=2).nodes)
    nodes[1, 1, 1, 0] += 0.8 * (RANDOM_BOX[1][0] - RANDOM_BOX[0][0])
    assert not certified_nonfolding(TrilinearGrid(nodes))


def test_error_table_of_the_bent_lattice() -> None:
    rows = inverse_error_table(points=4000)
    by = {(r["inverse"], r["iterations"]): r for r in rows}
    assert bent().adaptive
    assert bent().iterations is None
    assert (bent().tolerance, bent().max_iterations) == (DEFAULT_TOLERANCE, 8)
    assert bent(inverse="baked").iterations == 0
    assert bent(iterations=DEFAULT_ITERATIONS).steps == 2  # the former default
    # the default iterates to a residual far below its tolerance (quadratic convergence)
    assert by["newton", None]["max"] < 1e-3 * DEFAULT_TOLERANCE
    assert by["newton", 1]["max"] > 0.01
    # each step helps; the seed alone is the least accurate
    assert by["baked", 0]["max"] > by["newton", 1]["max"] > by["newton", 2]["max"]
    assert by["newton", 3]["max"] < 1e-8
    assert by["baked", 0]["median"] < 0.05  # good almost everywhere, poor at the kinks
    assert "| newton k=2 |" in format_error_table(rows)
    assert "| newton tol=0.001 mm |" in format_error_table(rows)
