"""Joining ChainMail elements (:meth:`ChainMail.link_pairs`, :meth:`ChainMail.link`), the
inverse of cutting (Knoche 2008, 2.4.2.2: links are removed to cut and added to connect
tissues).

Oracles: a model cut and linked again moves bit for bit as one never cut (the same
random drags, relaxation included, on heterogeneous limits; both CPU variants, and the
GPU backend against its own uncut run); which links count as stretched, computed here
from the positions and the mean link limits independently of the model's code;  a
skipping join leaves every link within its limits and moves nothing; a pull (suture)
leaves every link within its limits, held and fixed elements in place, and for one gap
equals dragging the end back to touch; refused joins change nothing; the GPU's joins
equal the CPU's to 1e-4 mm.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

from voxwarp.deform import ChainMail, ChainMailError
from voxwarp.deform.elements.chainmail import neighbour_pairs
from voxwarp.deform.elements.grid import ElementGrid

TOL = 1e-6
#: GPU positions are float32 (see test_chainmail_backends.py)
GPU_TOL = 5e-4
#: the drag that pulls the two sides of a cut apart
PULL = (6.0, 0.0, 0.0)


def _grid(shape: tuple[int, int, int], spacing: float = 10.0) -> ElementGrid:
    hi = tuple(spacing * (n - 1) for n in shape)
    return ElementGrid(((0.0, 0.0, 0.0), hi), shape=shape, anchor="corners")


def _pairs(cuts: np.ndarray) -> np.ndarray:
    """(m, 2, 3) element pairs of ``[i, j, k, axis]`` links."""
    hi = cuts[:, :3].copy()
    hi[np.arange(len(cuts)), cuts[:, 3]] += 1
    return np.stack([cuts[:, :3], hi], axis=1)


def _heterogeneous(cm: ChainMail, seed: int) -> None:
    rng = np.random.default_rng(seed)
    shape = (*cm.grid.shape, 3)
    s = cm.grid.spacing
    cm.set_limits(
        s * rng.uniform(0.6, 0.95, shape),
        s * rng.uniform(1.05, 1.5, shape),
        s * rng.uniform(0.1, 0.5, shape),
    )


def _excess(x: np.ndarray, cm: ChainMail, pair: np.ndarray) -> float:
    """How far the link of ``pair`` is beyond its limits (mean of both ends'), by hand."""
    a, b = (tuple(int(v) for v in p) for p in pair)
    axis = int(np.argmax(np.abs(np.subtract(b, a))))
    m = cm.model
    d = x[b] - x[a]
    mn = 0.5 * (m.min_dist[a][axis] + m.min_dist[b][axis])
    mx = 0.5 * (m.max_dist[a][axis] + m.max_dist[b][axis])
    sh = 0.5 * (m.max_shear[a][axis] + m.max_shear[b][axis])
    return max(mn - d[axis], d[axis] - mx, *(abs(d[j]) - sh for j in range(3) if j != axis))


def _drags(seed: int, shape: tuple[int, int, int], n: int) -> list[tuple[Any, Any]]:
    rng = np.random.default_rng(seed)
    return [
        (tuple(int(v) for v in rng.integers(1, np.asarray(shape) - 1)), rng.uniform(-12, 12, 3))
        for _ in range(n)
    ]


# ---------------------------------------------------------------------- the inverse
@pytest.mark.parametrize("variant", ["gibson", "enhanced"])
def test_cut_then_linked_moves_exactly_as_the_uncut_model(variant: str) -> None:
    shape = (8, 6, 5)
    uncut = ChainMail(_grid(shape), variant=variant, relax_steps=1)
    joined = ChainMail(_grid(shape), variant=variant, relax_steps=1)
    for cm in (uncut, joined):
        _heterogeneous(cm, seed=7)
    for step, (idx, off) in enumerate(_drags(1, shape, 8)):
        if step % 3 == 1:  # cut through the deformed state and join it again
            assert joined.cut((35.0, 0.0, 0.0), (1.0, 0.2, 0.1)) > 0
            cut = joined.cuts
            assert not joined.model.links.all()
            assert joined.link_pairs(_pairs(cut)) == len(cut)
            assert len(joined.cuts) == 0
        for cm in (uncut, joined):
            cm.move(idx, off)
            if step % 4 == 3:
                cm.release()
        np.testing.assert_array_equal(joined.positions(), uncut.positions())
    assert joined.to_dict(include_positions=True) == uncut.to_dict(include_positions=True)
    assert joined.violation() <= TOL


def test_link_plane_is_the_inverse_of_cut_plane_and_a_disk_leaves_a_bridge() -> None:
    cm = ChainMail(_grid((8, 4, 4)))
    assert cm.cut((35.0, 0.0, 0.0), (1.0, 0.0, 0.0)) == 16
    # a disk of radius 8 mm around (35, 15, 15) meets the x links at y, z in {10, 20}
    assert cm.link((35.0, 15.0, 15.0), (1.0, 0.0, 0.0), extent=8.0) == 4
    assert len(cm.cuts) == 12
    assert [3, 1, 1, 0] not in cm.cuts.tolist()
    # the 4 joined links carry a drag across the cut: the other side follows
    cm.move((4, 2, 2), (25.0, 0.0, 0.0))
    assert cm.positions()[3, 2, 2, 0] > 30.0 + 1.0
    assert cm.violation() <= TOL
    cm.reset()
    assert cm.link_pairs(_pairs(cm.cuts)) == 12
    assert len(cm.cuts) == 0


def test_link_pairs_counts_and_checks_its_input() -> None:
    cm = ChainMail(_grid((5, 4, 4)))
    pairs = [[(0, 0, 1), (0, 0, 2)], [(2, 3, 3), (2, 2, 3)]]
    assert cm.link_pairs(pairs) == 0  # linked already: ignored
    assert cm.cut_pairs(pairs) == 2
    assert cm.link_pairs(pairs[:1]) == 1
    assert cm.cuts.tolist() == [[2, 2, 3, 1]]
    assert cm.link_pairs(pairs) == 1
    assert cm.link_pairs([]) == 0
    with pytest.raises(ChainMailError, match="not neighbours"):
        cm.link_pairs([[(0, 0, 0), (1, 1, 0)]])
    with pytest.raises(ChainMailError, match=r"\(m, 2, 3\)"):
        cm.link_pairs([[0, 1, 2]])
    with pytest.raises(ChainMailError, match="stretched must be one of"):
        cm.link_pairs(pairs, stretched="force")
    with pytest.raises(ChainMailError, match="zero vector"):
        cm.link((0, 0, 0), (0, 0, 0))


def test_neighbour_pairs_around_and_inside_a_selection() -> None:
    mask = np.zeros((5, 5, 5), dtype=bool)
    mask[1:3, 1:3, 1:3] = True  # a 2x2x2 block: 24 faces outside, 12 links inside
    around = neighbour_pairs(mask)
    assert around.shape == (24, 2, 3)
    assert np.all(mask[tuple(around[:, 0].T)] != mask[tuple(around[:, 1].T)])
    assert np.all(np.abs(around[:, 1] - around[:, 0]).sum(axis=1) == 1)
    assert neighbour_pairs(mask, boundary=False).shape == (36, 2, 3)
    cm = ChainMail(_grid((5, 5, 5)))
    assert cm.cut_pairs(around) == 24
    cm.move((1, 1, 1), (20.0, 0.0, 0.0))  # the block comes loose: its outside stays
    assert not np.any(cm.displacements()[~mask])
    assert np.all(cm.displacements()[mask][:, 0] >= 20.0 - 3 * 2.5)  # within the slack
    with pytest.raises(ChainMailError, match="bool array"):
        neighbour_pairs(np.zeros(5, dtype=bool))


# ---------------------------------------------------------------------- stretched links
def _pulled_apart() -> tuple[ChainMail, np.ndarray]:
    """A block cut across x between i = 3 and 4, its right part dragged by ``PULL`` near
    the middle: the middle links of the cut gape (stretch limit 12.5 mm, shear 2.5 mm
    per link), those further out touch."""
    cm = ChainMail(_grid((8, 5, 5)))
    assert cm.cut((35.0, 0.0, 0.0), (1.0, 0.0, 0.0)) == 25
    cm.move((4, 2, 2), PULL)
    return cm, _pairs(cm.cuts)


def test_a_stretched_join_is_refused_and_changes_nothing() -> None:
    cm, pairs = _pulled_apart()
    x, before = cm.positions(), cm.to_dict(include_positions=True)
    far = [p for p in pairs if _excess(x, cm, p) > TOL]
    assert 0 < len(far) < len(pairs)
    with pytest.raises(ChainMailError, match=rf"{len(far)} of the links .* beyond their limits"):
        cm.link_pairs(pairs)
    assert cm.to_dict(include_positions=True) == before
    with pytest.raises(ChainMailError, match=r"\(3, 2, 2\)-\(4, 2, 2\), 3.5 mm too far"):
        cm.link_pairs([[(3, 2, 2), (4, 2, 2)]])  # 16 mm apart, at most 12.5 mm


def test_skip_joins_only_the_touching_links() -> None:
    cm, pairs = _pulled_apart()
    x = cm.positions()
    touching = {tuple(map(tuple, p)) for p in pairs if _excess(x, cm, p) <= TOL}
    assert cm.link_pairs(pairs, stretched="skip") == len(touching)
    left = {tuple(map(tuple, p)) for p in _pairs(cm.cuts)}
    assert left == {tuple(map(tuple, p)) for p in pairs} - touching
    np.testing.assert_array_equal(cm.positions(), x)  # nothing moved
    assert cm.violation() <= TOL


def test_pull_joins_all_within_the_limits_held_and_fixed_staying() -> None:
    cm, pairs = _pulled_apart()
    held = cm.positions()[4, 2, 2]
    assert cm.link_pairs(pairs, stretched="pull") == len(pairs)
    assert len(cm.cuts) == 0
    assert cm.violation() <= TOL
    x = cm.positions()
    np.testing.assert_array_equal(x[4, 2, 2], held)
    g = cm.grid
    np.testing.assert_array_equal(x[g.fixed], g.rest_positions[g.fixed])
    # the held element's link was closed from the left: (3, 2, 2) moved up to 12.5 mm
    assert x[4, 2, 2, 0] - x[3, 2, 2, 0] == pytest.approx(12.5, abs=TOL)
    # and the pull moved nothing it did not have to: the far left face stays at rest
    np.testing.assert_array_equal(x[0], g.rest_positions[0])


def test_a_pull_is_the_least_motion_for_a_single_gap() -> None:
    """One stretched link, both ends free: the upper end moves to the nearest position
    within the limits and its tissue follows as a drag there would move it."""
    cm = ChainMail(_grid((6, 3, 3)))
    cm.cut_pairs([[(2, 1, 1), (3, 1, 1)]])
    cm.move((3, 1, 1), (2.5 + 2.0, 0.0, 0.0))  # its link to (2, 1, 1): 2 mm too long
    cm.release()
    reference = ChainMail(_grid((6, 3, 3)))
    reference.cut_pairs([[(2, 1, 1), (3, 1, 1)]])
    reference.move((3, 1, 1), (2.5 + 2.0, 0.0, 0.0))
    reference.move((3, 1, 1), (2.5, 0.0, 0.0))  # dragged back to touch
    reference.release()
    assert cm.link_pairs([[(3, 1, 1), (2, 1, 1)]], stretched="pull") == 1
    np.testing.assert_allclose(cm.positions(), reference.positions(), atol=1e-12)
    assert cm.violation() <= TOL


def test_a_pull_against_fixed_elements_is_refused_and_changes_nothing() -> None:
    g = _grid((8, 3, 3))
    left = np.zeros(g.shape, dtype=bool)
    left[:4] = True
    g.fix(left)  # the whole left part is fixed
    cm = ChainMail(g)
    cm.cut((35.0, 0.0, 0.0), (1.0, 0.0, 0.0))
    cm.move((4, 1, 1), (10.0, 0.0, 0.0))  # the right part follows, 7.5 mm too far
    before = cm.to_dict(include_positions=True)
    with pytest.raises(ChainMailError, match="held or fixed elements are in the way"):
        cm.link_pairs(_pairs(cm.cuts), stretched="pull")
    assert cm.to_dict(include_positions=True) == before
    cm.release()  # now the right part can be pulled back
    assert cm.link_pairs(_pairs(cm.cuts), stretched="pull") == 9
    assert cm.violation() <= TOL
    np.testing.assert_array_equal(cm.positions()[:4], g.rest_positions[:4])


@pytest.mark.parametrize("seed", range(12))
def test_a_pull_joins_all_within_the_limits_or_changes_nothing(seed: int) -> None:
    """Random pieces cut loose and random drags: a pull ends with every link present and
    within its limits, held and fixed elements in place, or refuses leaving the model
    as it was; with nothing held (only the corners fixed) it always joins."""
    rng = np.random.default_rng(seed)
    shape = (6, 5, 5)
    cm = ChainMail(_grid(shape), variant=("gibson", "enhanced")[seed % 2])
    pairs = neighbour_pairs(rng.random(shape) < 0.3)
    cm.cut_pairs(pairs)
    for idx, off in _drags(seed, shape, 3):
        cm.move(idx, off)
    if seed % 3 == 0:
        cm.release()
    before = cm.to_dict(include_positions=True)
    try:
        cm.link_pairs(pairs, stretched="pull")
    except ChainMailError:
        assert seed % 3 != 0
        assert cm.to_dict(include_positions=True) == before
        return
    assert len(cm.cuts) == 0
    assert cm.violation() <= TOL
    x, g, held = cm.positions(), cm.grid, cm.held
    np.testing.assert_array_equal(x[held], g.rest_positions[held] + cm.held_offsets[held])
    np.testing.assert_array_equal(x[g.fixed], g.rest_positions[g.fixed])


# ---------------------------------------------------------------------- never linked
def test_regions_never_linked_join_where_they_touch() -> None:
    """A model loaded with cuts (two tissues side by side): joined, it is the model
    that was never cut, and the saved entry says so."""
    d = ChainMail(_grid((6, 4, 4))).to_dict()
    d["cuts"] = [[2, j, k, 0] for j in range(4) for k in range(4)]
    separate = ChainMail.from_dict(json.loads(json.dumps(d)))
    separate.move((4, 2, 2), (6.0, 0.0, 0.0))
    assert not np.any(separate.displacements()[:3])  # never linked: the left stays
    separate.reset()
    assert separate.link_pairs(_pairs(separate.cuts)) == 16
    assert separate.to_dict()["cuts"] == []
    whole = ChainMail(_grid((6, 4, 4)))
    for cm in (separate, whole):
        cm.move((4, 2, 2), (6.0, 0.0, 0.0))
    np.testing.assert_array_equal(separate.positions(), whole.positions())
    again = ChainMail.from_dict(json.loads(json.dumps(separate.to_dict(include_positions=True))))
    np.testing.assert_array_equal(again.cuts, np.zeros((0, 4)))
    np.testing.assert_array_equal(again.positions(), whole.positions())


# ---------------------------------------------------------------------- GPU (GLSL)
@pytest.mark.gl
def test_gpu_cut_then_linked_moves_as_the_uncut_gpu_model(gl_ctx: Any) -> None:
    shape = (7, 5, 5)
    uncut = ChainMail(_grid(shape), backend="gpu", ctx=gl_ctx)
    joined = ChainMail(_grid(shape), backend="gpu", ctx=gl_ctx)
    cpu = ChainMail(_grid(shape))
    try:
        for step, (idx, off) in enumerate(_drags(4, shape, 5)):
            if step in (1, 3):
                joined.cut((30.0, 0.0, 0.0), (1.0, 0.0, 0.0))
                assert len(joined.cuts) > 0
                joined.link_pairs(_pairs(joined.cuts))
                assert len(joined.cuts) == 0
            for cm in (uncut, joined, cpu):
                cm.move(idx, off)
            np.testing.assert_allclose(joined.positions(), uncut.positions(), atol=1e-12)
            np.testing.assert_allclose(joined.positions(), cpu.positions(), atol=1e-4)
            assert joined.violation() <= GPU_TOL
    finally:
        for cm in (uncut, joined):
            cm.close()


@pytest.mark.gl
def test_gpu_joins_stretched_links_as_the_cpu(gl_ctx: Any) -> None:
    cpu, pairs = _pulled_apart()
    gpu = ChainMail(_grid((8, 5, 5)), backend="gpu", ctx=gl_ctx)
    try:
        gpu.cut((35.0, 0.0, 0.0), (1.0, 0.0, 0.0))
        gpu.move((4, 2, 2), PULL)
        with pytest.raises(ChainMailError, match="beyond their limits"):
            gpu.link_pairs(pairs)
        assert gpu.link_pairs(pairs, stretched="skip") == cpu.link_pairs(pairs, stretched="skip")
        np.testing.assert_array_equal(gpu.cuts, cpu.cuts)
        assert gpu.violation() <= GPU_TOL
        np.testing.assert_allclose(gpu.positions(), cpu.positions(), atol=1e-4)
        rest = _pairs(gpu.cuts)
        assert gpu.link_pairs(rest, stretched="pull") == cpu.link_pairs(rest, stretched="pull")
        assert len(gpu.cuts) == 0
        assert gpu.violation() <= GPU_TOL
        np.testing.assert_allclose(gpu.positions(), cpu.positions(), atol=1e-4)
        for cm in (gpu, cpu):  # the GPU solver drags the joined model as the CPU
            cm.release()
            assert cm.move((2, 2, 2), (-4.0, 6.0, 0.0)).fraction == 1.0
        np.testing.assert_allclose(gpu.positions(), cpu.positions(), atol=1e-4)
    finally:
        gpu.close()
