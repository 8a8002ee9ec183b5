"""Cutting and joining ChainMail links in the edit session (the GUI's *Cut selected* /
*Join selected*): what is cut and joined, the errors, and the scene JSON round trip.

Pure CPU: the ``fish`` sample at 32³ and a 5³ element grid. Oracles: the links around
the selection counted by hand (a block of 2³ elements inside the grid has 24), the
elements outside a cut-loose block exactly at rest after a drag, links left cut exactly
those whose elements are beyond the limits (computed from the positions here), and the
saved file read back (cuts and positions equal); after pulling, every link within its
limits and the held and fixed elements in place.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from voxwarp.cli.deformation import _deform_grid, _run_chainmail
from voxwarp.cli.main import build_parser
from voxwarp.deform.elements.grid import ElementGrid
from voxwarp.editing.session import EditorError, EditSession
from voxwarp.io.samples import load_sample
from voxwarp.scene import Scene

SHAPE = (5, 5, 5)


def block() -> tuple[list[int], np.ndarray]:
    """The flat indices of the 2x2x2 block [1:3]^3 and its mask."""
    mask = np.zeros(SHAPE, dtype=bool)
    mask[1:3, 1:3, 1:3] = True
    return [int(i) for i in np.flatnonzero(mask)], mask


@pytest.fixture
def session() -> EditSession:
    s = EditSession(Scene(load_sample("fish", shape=(32, 32, 32))))
    s.set_deformation("chainmail", resolution=SHAPE[0], anchor="corners")
    return s


def stretched_cuts(s: EditSession) -> int:
    """Cut links whose elements are beyond the limits now (mm excess > 1e-6), by hand."""
    m, x = s.model.model, s.model.positions()
    n = 0
    for i, j, k, axis in s.model.cuts:
        a = (i, j, k)
        b = tuple(v + (1 if c == axis else 0) for c, v in enumerate(a))
        d = x[b] - x[a]
        mn = 0.5 * (m.min_dist[a][axis] + m.min_dist[b][axis])
        mx = 0.5 * (m.max_dist[a][axis] + m.max_dist[b][axis])
        sh = 0.5 * (m.max_shear[a][axis] + m.max_shear[b][axis])
        far = max(mn - d[axis], d[axis] - mx, *(abs(d[c]) - sh for c in range(3) if c != axis))
        n += far > 1e-6
    return n


def test_cut_sets_the_selection_loose_and_join_restores_where_it_touches(
    session: EditSession,
) -> None:
    s = session
    sel, mask = block()
    assert s.cut_links(sel) == 24
    assert len(s.model.cuts) == 24
    s.model.move((2, 2, 2), 0.6 * s.model.grid.spacing * (1, 0, 0))
    u = s.model.displacements()
    assert not np.any(u[~mask])  # nothing outside followed
    assert u[2, 2, 2, 0] > 0
    x = s.model.positions()
    far = stretched_cuts(s)
    assert 0 < far < 24
    assert s.join_links(sel) == (24 - far, far)
    np.testing.assert_array_equal(s.model.positions(), x)  # joining moves nothing
    assert len(s.model.cuts) == far
    assert s.model.violation() <= 1e-6
    with pytest.raises(EditorError, match="stretched beyond their"):
        s.join_links(sel)
    held = x[2, 2, 2].copy()
    assert s.join_links(sel, pull=True) == (far, 0)  # a suture: the sides meet
    assert len(s.model.cuts) == 0
    assert s.model.violation() <= 1e-6
    x = s.model.positions()
    np.testing.assert_array_equal(x[2, 2, 2], held)
    g = s.model.grid
    np.testing.assert_array_equal(x[g.fixed], g.rest_positions[g.fixed])


def test_cut_and_join_errors(session: EditSession) -> None:
    s = session
    with pytest.raises(EditorError, match="select elements first"):
        s.cut_links([])
    with pytest.raises(EditorError, match="nothing to join"):
        s.join_links([0, 1])
    with pytest.raises(EditorError, match="nothing to"):
        s.cut_links(list(range(125)))  # the whole grid has no outside
    s.set_deformation("massspring", resolution=3)
    with pytest.raises(EditorError, match="only ChainMail"):
        s.cut_links([4])


def test_cuts_and_joins_are_saved_and_loaded(session: EditSession, tmp_path: Path) -> None:
    s = session
    sel, _ = block()
    s.cut_links(sel)
    s.model.move((2, 2, 2), (0.6 * s.model.grid.spacing[0], 0.0, 0.0))
    s.join_links(sel)
    cuts, x = s.model.cuts, s.model.positions()
    assert 0 < len(cuts) < 24
    path = s.save(tmp_path / "cut.json")
    raw = json.loads(path.read_text(encoding="utf-8"))
    (entry,) = [w for w in raw["warps"] if "model" in w]
    assert sorted(map(tuple, entry["model"]["cuts"])) == sorted(map(tuple, cuts.tolist()))
    loaded = EditSession.load(path)
    assert loaded.kind == "chainmail"
    np.testing.assert_array_equal(loaded.model.cuts, cuts)
    np.testing.assert_array_equal(loaded.model.positions(), x)
    loaded.model.reset()  # the joined links hold again once the sides touch: all of them
    assert loaded.join_links(sel) == (len(cuts), 0)


def test_the_overlay_does_not_draw_cut_links(session: EditSession) -> None:
    s = session
    from voxwarp.editing.session import DisplayOptions

    def links() -> int:
        (layer,) = [la for la in s.overlay_layers(DisplayOptions()) if la.name == "links"]
        return len(layer.positions) // 2

    whole = links()
    assert whole == 3 * 4 * 25
    s.cut_links(block()[0])
    assert links() == whole - 24


def test_cli_join_leaves_a_bridge_in_a_cut() -> None:
    """``render --cut PLANE --join DISK`` (no GL): the disk's links are linked again,
    the rest of the plane stays cut; the builder runs it for the CLI."""
    volume = load_sample("fish", shape=(32, 32, 32))
    rest = ElementGrid(volume, shape=6, margin=0.0, anchor="corners").rest_positions
    x = 0.5 * (rest[2, 0, 0, 0] + rest[3, 0, 0, 0])  # between element layers 2 and 3
    y, z = rest[2:4, 2:4, 2:4, 1].mean(), rest[2:4, 2:4, 2:4, 2].mean()
    # the disk reaches the 4 links around the axis through (x, y, z), half a cell's
    # diagonal away, and no others (the next are over twice as far)
    radius = 0.5 * float(np.hypot(*(rest[3, 3, 3, 1:] - rest[2, 2, 2, 1:]))) + 0.5
    argv = ["render", "in.npy", "-o", "x.png", "--chainmail", "6", "--grid-margin", "0"]
    argv += [f"--cut={x},0,0:1,0,0", f"--join={x},{y},{z}:1,0,0:{radius}"]
    args = build_parser(bench=False).parse_args(argv)
    cm, summary = _run_chainmail(args, _deform_grid(args, volume), None)
    assert ", 36 links cut, 4 joined again;" in summary
    assert len(cm.cuts) == 32
    joined = {(2, j, k, 0) for j in (2, 3) for k in (2, 3)}
    assert not joined & set(map(tuple, cm.cuts.tolist()))
