"""Tests of voxwarp.deform.elements.chainmail: the 3D ChainMail CPU solver (both variants) and its
API.

Oracles: :meth:`ChainMailModel.violation` (every link within its limits, to 1e-6 mm)
after every move of random drag sequences on heterogeneous, anisotropic materials, and
fixed and held elements exactly where they belong; for one drag, the least motion that
satisfies the constraints, computed independently by a brute-force monotone iteration
over all links (numpy) — both variants must reach it; in a homogeneous material the
closed form ``shift = max(0, 1 - 0.25 * manhattan distance)`` spacings of a drag by one
spacing (slack 0.25 spacings per link), so the touched count is exactly the 63 elements
of that octahedron; exact rigid translations of a rigid material; the smoothness energy
after each relaxation step; unmoved elements across a cut. The numba kernels compile
on the first run (a few seconds) and are cached in ``deform/__pycache__``.
"""

from __future__ import annotations

import itertools
import json
import sys
import types
from typing import Any, ClassVar

import numpy as np
import pytest

from voxwarp.deform import ChainMail, ChainMailError, MoveStats
from voxwarp.deform.elements.chainmail import LIMIT_BISECTIONS
from voxwarp.deform.elements.chainmail_model import ChainMailModel
from voxwarp.deform.elements.grid import ElementGrid
from voxwarp.deform.elements.offset_field import OffsetFieldWarp

VARIANTS = ("gibson", "enhanced")
TOL = 1e-6


def _grid(shape: tuple[int, int, int], spacing: float = 10.0) -> ElementGrid:
    hi = tuple(spacing * (n - 1) for n in shape)
    return ElementGrid(((0.0, 0.0, 0.0), hi), shape=shape, anchor="corners")


def _heterogeneous(cm: ChainMail, seed: int) -> None:
    """Random limits per element; along x (the 'fibres') much stiffer than across."""
    rng = np.random.default_rng(seed)
    shape = (*cm.grid.shape, 3)
    s = cm.grid.spacing
    mn = s * rng.uniform(0.5, 0.95, shape)
    mx = s * rng.uniform(1.05, 1.6, shape)
    sh = s * rng.uniform(0.05, 0.5, shape)
    mn[..., 0] = s[0] * rng.uniform(0.9, 0.98, cm.grid.shape)
    mx[..., 0] = s[0] * rng.uniform(1.02, 1.1, cm.grid.shape)
    cm.set_limits(mn, mx, sh)


def _least_motion(model: ChainMailModel, node: tuple[int, int, int], target: Any) -> np.ndarray:
    """Brute force: the least motion from rest satisfying every link, ``node`` at target.

    Per coordinate ``c`` with drag sign ``sign``, every link's bound pushes its ends in
    that direction only (``x_q >= x_p + lo`` and ``x_p >= x_q - hi`` for a drag up),
    repeated over all links at once until nothing changes: the least fixed point.
    """
    x = model.rest.copy()
    x[node] = target
    delta = np.asarray(target) - model.rest[node]
    for c in range(3):
        sign = 1.0 if delta[c] >= 0 else -1.0
        y = sign * x[..., c]  # a drag down is a drag up of -x
        while True:
            before = y.copy()
            for axis in range(3):
                mn, mx, sh, linked = model.link_limits(axis)
                lo, hi = (mn, mx) if axis == c else (-sh, sh)
                if sign < 0:
                    lo, hi = -hi, -lo
                a = [slice(None)] * 3
                b = [slice(None)] * 3
                a[axis] = slice(0, -1)
                b[axis] = slice(1, None)
                ya, yb = y[tuple(a)], y[tuple(b)]
                yb[...] = np.where(linked, np.maximum(yb, ya + lo), yb)
                ya[...] = np.where(linked, np.maximum(ya, yb - hi), ya)
            y[node] = sign * x[node][c]
            if np.array_equal(y, before):
                break
        x[..., c] = sign * y
    return x


# ---------------------------------------------------------------------- propagation
@pytest.mark.parametrize("variant", VARIANTS)
def test_random_drags_keep_every_link_and_the_fixed_and_held_elements(variant: str) -> None:
    g = _grid((7, 6, 5))
    g.fix((3, 2, 2))
    cm = ChainMail(g, variant=variant)
    _heterogeneous(cm, seed=1)
    rest = g.rest_positions
    rng = np.random.default_rng(7)
    limited = 0
    for n in range(60):
        m = 1 if n % 4 else int(rng.integers(2, 4))  # one element, or several at once
        idx = np.stack([rng.integers(0, s, m) for s in g.shape], axis=1)
        off = rng.uniform(-4.0, 4.0, (m, 3)) * (4.0 if n % 5 == 0 else 1.0)
        stats = cm.move(idx, off)
        assert isinstance(stats, MoveStats)
        assert 0.0 <= stats.fraction <= 1.0
        limited += stats.limited
        x = cm.positions()
        assert cm.model.violation(x) <= TOL, f"move {n}: {stats}"
        np.testing.assert_array_equal(x[g.fixed], rest[g.fixed])
        held = cm.held
        np.testing.assert_array_equal(x[held], rest[held] + cm.held_offsets[held])
        if n % 2 == 1:
            cm.release()
        if n % 11 == 10:
            cm.relax(2)
            assert cm.violation() <= TOL
    assert 10 < limited < 50  # both kinds of move were exercised (measured: 27)


@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("offset", [(14.0, -9.0, 6.0), (-3.0, 17.0, -11.0)])
def test_one_drag_gives_the_least_motion(variant: str, offset: tuple[float, ...]) -> None:
    g = _grid((7, 6, 6))
    g.fixed[:] = False
    cm = ChainMail(g, variant=variant)
    _heterogeneous(cm, seed=4)
    node = (3, 2, 3)
    stats = cm.move(node, offset)
    assert not stats.limited
    expected = _least_motion(cm.model, node, g.rest_positions[node] + offset)
    np.testing.assert_allclose(cm.positions(), expected, rtol=0, atol=1e-9)
    moved = np.any(expected != g.rest_positions, axis=-1)
    assert stats.touched == int(moved.sum()) > 20
    if variant == "gibson":
        assert stats.cleanup > 0  # heterogeneous: single sponsors are not enough


@pytest.mark.parametrize("variant", VARIANTS)
def test_homogeneous_drag_matches_the_closed_form(variant: str) -> None:
    """Drag by one spacing along x with 0.25 spacings of slack per link (stiffness 0.5):
    an element ``m`` links away (Manhattan) follows by ``max(0, 1 - 0.25 m)``."""
    g = _grid((24, 24, 24), spacing=1.0)
    cm = ChainMail(g, variant=variant)
    node = (12, 11, 13)
    stats = cm.move(node, (1.0, 0.0, 0.0))
    idx = np.stack(np.indices(g.shape), axis=-1)
    manhattan = np.abs(idx - np.asarray(node)).sum(axis=-1)
    expected = np.zeros((*g.shape, 3))
    expected[..., 0] = np.maximum(0.0, 1.0 - 0.25 * manhattan)
    np.testing.assert_allclose(cm.displacements(), expected, rtol=0, atol=1e-12)
    assert stats.touched == 63 == int((manhattan <= 3).sum())  # of 13,824 elements
    assert stats.checks < 200
    if variant == "gibson":
        assert stats.cleanup == 0  # Gibson's sponsors are exact in a homogeneous material


@pytest.mark.parametrize("variant", VARIANTS)
def test_move_within_the_slack_touches_only_the_moved_element(variant: str) -> None:
    g = _grid((6, 6, 6))
    cm = ChainMail(g, variant=variant)  # slack 2.5 mm along, 2.5 mm shear
    stats = cm.move((2, 3, 2), (2.0, -1.0, 1.5))
    assert stats.touched == 1
    assert stats.fraction == 1.0
    d = cm.displacements()
    np.testing.assert_array_equal(d[2, 3, 2], (2.0, -1.0, 1.5))
    d[2, 3, 2] = 0.0
    assert not np.any(d)


@pytest.mark.parametrize("variant", VARIANTS)
def test_rigid_material_translates_the_whole_body(variant: str) -> None:
    g = _grid((5, 4, 6))
    g.fixed[:] = False
    g.set_material(stiffness=1.0)  # min = max = spacing, shear 0
    cm = ChainMail(g, variant=variant)
    offset = np.array([13.3, -7.1, 4.7])
    stats = cm.move((1, 2, 3), offset)
    assert stats.touched == g.count
    np.testing.assert_allclose(
        cm.displacements(), np.broadcast_to(offset, (*g.shape, 3)), atol=1e-9
    )
    # one fixed element pins the whole rigid body: nothing moves
    cm.reset()
    cm.fix((4, 0, 0))
    stats = cm.move((1, 2, 3), offset)
    assert stats.fraction == 0.0
    assert stats.touched == 0
    assert not np.any(cm.displacements())


@pytest.mark.parametrize("variant", VARIANTS)
def test_fixed_elements_limit_a_move(variant: str) -> None:
    g = _grid((8, 3, 3))
    g.fix((2, 1, 1))
    cm = ChainMail(g, variant=variant)  # max_dist 12.5 mm along x
    stats = cm.move((3, 1, 1), (30.0, 0.0, 0.0))
    assert stats.limited
    assert stats.attempts == LIMIT_BISECTIONS + 2
    step = 30.0 * 2.0**-LIMIT_BISECTIONS
    assert 2.5 - step <= 30.0 * stats.fraction <= 2.5
    x = cm.positions()
    assert 12.5 - step <= x[3, 1, 1, 0] - x[2, 1, 1, 0] <= 12.5 + 1e-9  # the link is taut
    assert cm.violation() <= TOL
    # held where it stopped
    np.testing.assert_array_equal(cm.held_offsets[3, 1, 1], x[3, 1, 1] - g.rest_positions[3, 1, 1])
    # a fixed element is not dragged
    before = cm.positions()
    stats = cm.move((2, 1, 1), (5.0, 0.0, 0.0))
    assert stats.touched == 0
    np.testing.assert_array_equal(cm.positions(), before)
    assert not cm.held[2, 1, 1]


@pytest.mark.parametrize("variant", VARIANTS)
def test_held_elements_stay_until_released(variant: str) -> None:
    g = _grid((9, 3, 3))
    g.fixed[:] = False
    cm = ChainMail(g, variant=variant)
    cm.move((3, 1, 1), (0.0, 0.0, 0.0))  # hold an element at rest
    stats = cm.move((5, 1, 1), (20.0, 0.0, 0.0))  # would pull it along (2 links)
    assert stats.limited
    assert not np.any(cm.displacements()[3, 1, 1])
    cm.release((3, 1, 1))
    stats = cm.move((5, 1, 1), (20.0, 0.0, 0.0))
    assert not stats.limited
    assert cm.displacements()[3, 1, 1, 0] > 0.0
    cm.relax(3)  # relaxation leaves held elements where they are
    np.testing.assert_array_equal(cm.displacements()[5, 1, 1], (20.0, 0.0, 0.0))
    assert cm.violation() <= TOL


def test_move_arguments() -> None:
    g = _grid((4, 4, 4))
    cm = ChainMail(g)
    mask = np.zeros(g.shape, dtype=bool)
    mask[1:3, 1, 1] = True
    cm.move(mask, (1.0, 0.0, 0.0))
    assert cm.held.sum() == 2
    cm.move([(1, 2, 2), (1, 2, 2)], [(1.0, 0, 0), (2.0, 0, 0)])  # the last one wins
    assert cm.held_offsets[1, 2, 2, 0] == 2.0
    with pytest.raises(ChainMailError, match="one per selected element"):
        cm.move([(1, 1, 1), (2, 2, 2)], [(1.0, 0, 0)] * 3)
    with pytest.raises(ChainMailError, match="finite"):
        cm.move((1, 1, 1), (np.nan, 0, 0))
    with pytest.raises(ChainMailError, match="bool mask takes one"):
        cm.move(mask, [(1.0, 0, 0)] * 2)


# ---------------------------------------------------------------------- relaxation
@pytest.mark.parametrize("variant", VARIANTS)
def test_relaxation_lowers_the_smoothness_energy_monotonically(variant: str) -> None:
    g = _grid((10, 8, 7))
    cm = ChainMail(g, variant=variant)
    _heterogeneous(cm, seed=2)
    cm.move((4, 4, 3), (18.0, -6.0, 9.0))
    cm.move((7, 2, 5), (-5.0, 8.0, -4.0))
    cm.release((7, 2, 5))
    held = cm.positions()[4, 4, 3]
    energies = [cm.smoothness_energy()]
    for _ in range(6):
        cm.relax(1)
        energies.append(cm.smoothness_energy())
        assert cm.violation() <= TOL
        np.testing.assert_array_equal(cm.positions()[g.fixed], g.rest_positions[g.fixed])
        np.testing.assert_array_equal(cm.positions()[4, 4, 3], held)
    assert all(b <= a + 1e-9 for a, b in itertools.pairwise(energies))
    assert energies[1] < 0.95 * energies[0]
    # relaxing only around the displaced elements equals relaxing the whole grid
    # (a state set from outside relaxes everywhere)
    other = ChainMail.from_dict(cm.to_dict(include_positions=True))
    cm.relax(3)
    other.relax(3)
    np.testing.assert_array_equal(cm.positions(), other.positions())


def test_relax_steps_after_every_move() -> None:
    g = _grid((8, 6, 6))
    plain = ChainMail(g)
    smooth = ChainMail(g, relax_steps=4)
    for cm in (plain, smooth):
        cm.move((4, 3, 3), (15.0, 0.0, 0.0))
    assert smooth.smoothness_energy() < plain.smoothness_energy()
    plain.relax(4)
    np.testing.assert_array_equal(plain.positions(), smooth.positions())
    with pytest.raises(ChainMailError, match="relax_steps"):
        ChainMail(g, relax_steps=-1)


# ---------------------------------------------------------------------- cutting
@pytest.mark.parametrize("variant", VARIANTS)
def test_a_cut_lets_the_parts_move_independently(variant: str) -> None:
    g = _grid((8, 4, 4))  # x = 0, 10, ..., 70 mm
    drag = ((4, 2, 2), (15.0, 6.0, 0.0))
    whole = ChainMail(g, variant=variant)
    whole.move(*drag)
    assert np.any(whole.displacements()[:4])  # uncut, the left part follows
    cm = ChainMail(g, variant=variant)
    assert cm.cut((35.0, 0.0, 0.0), (2.0, 0.0, 0.0)) == 16  # all x links between i=3, 4
    assert cm.cut((35.0, 0.0, 0.0), (1.0, 0.0, 0.0)) == 0  # cut already
    cm.move(*drag)
    assert not np.any(cm.displacements()[:4])
    assert np.any(cm.displacements()[4:])
    assert cm.violation() <= TOL
    np.testing.assert_array_equal(cm.cuts[:, 0], 3)
    np.testing.assert_array_equal(cm.cuts[:, 3], 0)


def test_cut_disk_and_pairs() -> None:
    g = _grid((8, 4, 4))
    cm = ChainMail(g)
    # a disk of radius 8 mm around (35, 15, 15) meets the x links at y, z in {10, 20}
    assert cm.cut((35.0, 15.0, 15.0), (1.0, 0.0, 0.0), extent=8.0) == 4
    assert sorted(map(tuple, cm.cuts.tolist())) == [(3, j, k, 0) for j in (1, 2) for k in (1, 2)]
    assert cm.cut_pairs([[(0, 0, 1), (0, 0, 2)], [(5, 3, 3), (5, 2, 3)]]) == 2
    assert [5, 2, 3, 1] in cm.cuts.tolist()
    assert [0, 0, 1, 2] in cm.cuts.tolist()
    with pytest.raises(ChainMailError, match="not neighbours"):
        cm.cut_pairs([[(0, 0, 0), (1, 1, 0)]])
    with pytest.raises(ChainMailError, match="zero vector"):
        cm.cut((0, 0, 0), (0, 0, 0))


# ---------------------------------------------------------------------- limits
def test_default_limits_follow_the_stiffness() -> None:
    g = _grid((4, 3, 3), spacing=10.0)
    g.set_material(stiffness=0.5)
    g.set_material((1, 1, 1), stiffness=0.0)
    g.set_material((2, 1, 1), stiffness=1.0)
    m = ChainMail(g).model
    np.testing.assert_allclose(m.min_dist[0, 0, 0], 7.5)
    np.testing.assert_allclose(m.max_dist[0, 0, 0], 12.5)
    np.testing.assert_allclose(m.max_shear[0, 0, 0], 2.5)
    np.testing.assert_allclose(m.min_dist[1, 1, 1], 5.0)
    np.testing.assert_allclose(m.max_shear[1, 1, 1], 5.0)
    np.testing.assert_allclose(m.min_dist[2, 1, 1], 10.0)
    np.testing.assert_allclose(m.max_dist[2, 1, 1], 10.0)
    np.testing.assert_allclose(m.max_shear[2, 1, 1], 0.0)


def test_set_limits_forms() -> None:
    g = _grid((4, 3, 5))
    cm = ChainMail(g)
    cm.set_limits(min_dist=9.0)
    assert np.all(cm.model.min_dist == 9.0)
    cm.set_limits(max_shear=(1.0, 2.0, 3.0))
    np.testing.assert_array_equal(cm.model.max_shear[2, 1, 3], (1.0, 2.0, 3.0))
    per_element = np.linspace(10.5, 12.0, g.count).reshape(g.shape)
    cm.set_limits(max_dist=per_element)
    np.testing.assert_array_equal(cm.model.max_dist[..., 1], per_element)
    full = np.full((*g.shape, 3), 8.0)
    cm.set_limits(min_dist=full)
    np.testing.assert_array_equal(cm.model.min_dist, full)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"min_dist": 11.0, "max_dist": 10.5}, r"min_dist > max_dist"),
        ({"max_shear": -1.0}, r"max_shear must be >= 0"),
        ({"min_dist": np.nan}, r"min_dist has NaN"),
        ({"min_dist": (9.0, 10.5, 9.0)}, r"min_dist along axis 1 .* rest spacing .*min_dist <="),
        ({"max_dist": 9.0}, r"max_dist along axis 0 .*violate its own limits"),
        ({"max_dist": np.ones((2, 2))}, r"max_dist must be a number, 3 numbers"),
        ({"max_dist": "wide"}, r"max_dist must be"),
    ],
)
def test_impossible_limits_raise_and_change_nothing(kwargs: dict, match: str) -> None:
    g = _grid((4, 3, 3))
    cm = ChainMail(g)
    before = [a.copy() for a in (cm.model.min_dist, cm.model.max_dist, cm.model.max_shear)]
    with pytest.raises(ChainMailError, match=match):
        cm.set_limits(**kwargs)
    after = (cm.model.min_dist, cm.model.max_dist, cm.model.max_shear)
    for a, b in zip(before, after, strict=True):
        np.testing.assert_array_equal(a, b)


def test_tighter_limits_repair_the_deformation_or_refuse() -> None:
    g = _grid((8, 4, 4))
    cm = ChainMail(g)
    cm.move((4, 2, 2), (8.0, 0.0, 0.0))
    x = cm.positions()
    with pytest.raises(ChainMailError, match="release"):  # held element in the way
        cm.set_limits(max_dist=10.5, min_dist=9.5)
    np.testing.assert_array_equal(cm.positions(), x)
    cm.release()
    cm.set_limits(max_dist=10.5, min_dist=9.5)
    assert cm.violation() <= TOL


def test_bad_constructor_arguments(monkeypatch: pytest.MonkeyPatch) -> None:
    g = _grid((3, 3, 3))
    with pytest.raises(ChainMailError, match=r"unknown variant 'schill'.*gibson.*enhanced"):
        ChainMail(g, variant="schill")
    with pytest.raises(ChainMailError, match="unknown backend"):
        ChainMail(g, backend="cuda")
    with pytest.raises(ChainMailError, match="moderngl context"):
        ChainMail(g, backend="gpu")
    with pytest.raises(ChainMailError, match="ElementGrid"):
        ChainMail("grid")  # type: ignore[arg-type]
    with pytest.raises(ChainMailError, match="stretch"):
        ChainMail(g, stretch=1.5)
    monkeypatch.setitem(sys.modules, "voxwarp.deform.elements.chainmail_gpu", None)
    with pytest.raises(ChainMailError, match=r"deform\.elements\.chainmail_gpu.*backend=\"cpu\""):
        ChainMail(g, backend="gpu", ctx=object())


# ---------------------------------------------------------------------- state
def test_dict_round_trip() -> None:
    g = _grid((6, 5, 4))
    g.fix((2, 2, 2))
    cm = ChainMail(g, variant="gibson", relax_steps=1)
    _heterogeneous(cm, seed=5)
    cm.cut_pairs([[(0, 1, 1), (1, 1, 1)]])
    cm.move([(4, 1, 1), (1, 3, 2)], [(6.0, 1.0, 0.0), (-2.0, 0.0, 3.0)])
    d = json.loads(json.dumps(cm.to_dict(include_positions=True)))
    assert d["variant"] == "gibson"
    assert d["relax_steps"] == 1
    assert d["cuts"] == [[0, 1, 1, 0]]
    assert [h["index"] for h in d["held"]] == [[1, 3, 2], [4, 1, 1]]
    again = ChainMail.from_dict(d)
    np.testing.assert_array_equal(again.positions(), cm.positions())
    np.testing.assert_array_equal(again.held, cm.held)
    np.testing.assert_array_equal(again.cuts, cm.cuts)
    for name in ("min_dist", "max_dist", "max_shear"):
        np.testing.assert_array_equal(getattr(again.model, name), getattr(cm.model, name))
    assert again.to_dict(include_positions=True) == d
    # both continue alike
    for m in (cm, again):
        m.move((3, 3, 3), (0.0, 9.0, 0.0))
    np.testing.assert_array_equal(again.positions(), cm.positions())


def test_dict_is_compact_and_replays_the_drags() -> None:
    g = _grid((5, 4, 4))
    cm = ChainMail(g)
    d = cm.to_dict()
    assert d["limits"] == {"min_dist": 7.5, "max_dist": 12.5, "max_shear": 2.5}
    cm.set_limits(max_shear=(1.0, 2.0, 3.0))
    assert cm.to_dict()["limits"]["max_shear"] == [1.0, 2.0, 3.0]
    cm.move((2, 2, 2), (12.0, 0.0, 3.0))
    replayed = ChainMail.from_dict(json.loads(json.dumps(cm.to_dict())))  # no positions
    np.testing.assert_array_equal(replayed.positions(), cm.positions())
    with pytest.raises(ChainMailError, match="'grid'"):
        ChainMail.from_dict({"variant": "gibson"})
    with pytest.raises(ChainMailError, match="fixed and cannot be held"):
        ChainMail.from_dict({**d, "held": [{"index": [0, 0, 0], "offset": [1, 0, 0]}]})
    with pytest.raises(ChainMailError, match="'cuts'"):
        ChainMail.from_dict({**d, "cuts": [[0, 0, 0, 5]]})
    with pytest.raises(ChainMailError, match="expected 'chainmail'"):
        ChainMail.from_dict({**d, "type": "massspring"})


def test_set_state_repairs_small_violations() -> None:
    g = _grid((6, 5, 5))
    g.set_material(stiffness=1.0)  # rigid: no slack at all
    g.fixed[:] = False
    cm = ChainMail(g)
    cm.move((2, 2, 2), (3.1, 0.0, 0.0))
    noisy = cm.positions().astype(np.float32).astype(np.float64)  # saved in float32
    cm.release()
    cm.set_state(noisy)
    assert cm.violation() <= TOL
    np.testing.assert_allclose(cm.positions(), noisy, atol=1e-5)
    with pytest.raises(ChainMailError, match="shape"):
        cm.set_state(np.zeros((2, 3)))


# ---------------------------------------------------------------------- warp
def test_warp_follows_and_resumes() -> None:
    g = _grid((6, 5, 4))
    cm = ChainMail(g)
    w = cm.warp()
    assert cm.warp() is w
    assert w.inverse == "baked"
    cm.move((3, 2, 2), (9.0, 0.0, -4.0))
    np.testing.assert_array_equal(w.displacements, cm.displacements())
    cm.relax(2)
    np.testing.assert_array_equal(w.displacements, cm.displacements())
    entry = json.loads(json.dumps(w.to_dict()))
    assert entry["model"]["type"] == "chainmail"
    saved = OffsetFieldWarp.from_dict(entry)
    again = ChainMail.from_warp(saved)
    np.testing.assert_array_equal(again.positions(), cm.positions())
    np.testing.assert_array_equal(again.held, cm.held)
    with pytest.raises(ChainMailError, match="no ChainMail model"):
        ChainMail.from_warp(OffsetFieldWarp(g.lo, g.hi, np.zeros((*g.shape, 3))))


def test_zero_move_renders_like_no_warp(offscreen: Any, gl_ctx: Any) -> None:
    from tests.render.test_render import aligned_camera, grey_scene, phantom

    vol = phantom()
    grid = ElementGrid(vol, shape=(6, 5, 5), anchor="corners")
    cm = ChainMail(grid)
    try:
        stats = cm.move((3, 2, 2), (0.0, 0.0, 0.0))
        assert stats.touched == 0
        warp = cm.warp()
        cam, size = aligned_camera(vol, "+z")
        mip = grey_scene(vol, "mip", "+z", cam)
        r = offscreen(*size, dtype="f4")
        plain = r.render(mip)
        np.testing.assert_array_equal(r.render(mip.copy(warps=[warp])), plain)
        cm.move((3, 2, 2), (6.0, 0.0, 0.0))  # a drag changes the picture
        assert float(np.abs(r.render(mip.copy(warps=[warp])) - plain).max()) > 0.02
    finally:
        cm.close()


# ---------------------------------------------------------------------- GPU interface
class _FakeGpuSolver:
    """Stands in for voxwarp.deform.elements.chainmail_gpu.GpuChainMailSolver; records the calls."""

    instances: ClassVar[list[_FakeGpuSolver]] = []

    def __init__(self, model: ChainMailModel, ctx: Any) -> None:
        self.model = model
        self.ctx = ctx
        self.x = model.rest.copy()
        self.calls: list[str] = []
        self.revision = 0
        self.released = False
        _FakeGpuSolver.instances.append(self)

    def set_positions(self, x: np.ndarray, valid: bool = False) -> None:
        self.calls.append("set_positions")
        self.x = np.array(x, dtype=np.float64)
        self.revision += 1

    def enforce(self, held_mask: np.ndarray, held_targets: np.ndarray, max_passes: int) -> int:
        self.calls.append(f"enforce {int(held_mask.sum())} {max_passes}")
        self.x[held_mask] = held_targets[held_mask]
        self.revision += 1
        self.last_changed = ((0, 0, 0), self.x.shape[:3])
        return 3

    def relax(self, box: Any, steps: int) -> Any:
        self.calls.append(f"relax {box} {steps}")
        self.revision += 1
        return box

    def positions(self) -> np.ndarray:
        self.calls.append("positions")
        return self.x.copy()

    feasible = True  # the real solver checks; the fake's moves always are

    def snapshot(self) -> None:
        self.calls.append("snapshot")

    def restore(self) -> None:
        self.calls.append("restore")

    def displacement_texture(self) -> str:
        return "texture"

    def release(self) -> None:
        self.released = True


def test_gpu_backend_drives_the_solver_interface(monkeypatch: pytest.MonkeyPatch) -> None:
    fake = types.ModuleType("voxwarp.deform.elements.chainmail_gpu")
    fake.GpuChainMailSolver = _FakeGpuSolver  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "voxwarp.deform.elements.chainmail_gpu", fake)
    g = _grid((4, 4, 4))
    cm = ChainMail(g, backend="gpu", ctx="ctx")
    solver = _FakeGpuSolver.instances[-1]
    assert solver.ctx == "ctx"
    assert solver.calls == ["set_positions"]
    stats = cm.move((1, 2, 1), (2.0, 0.0, 0.0))
    assert stats.passes == 3
    assert stats.touched == -1
    assert solver.calls[-1] == f"enforce 1 {4 * 12}"
    np.testing.assert_array_equal(cm.displacements()[1, 2, 1], (2.0, 0.0, 0.0))
    w = cm.warp()
    assert w.gpu_owned
    cm.cut((15.0, 0.0, 0.0), (1.0, 0.0, 0.0))  # the model changed: a new solver
    assert solver.released
    assert _FakeGpuSolver.instances[-1] is not solver
    new = _FakeGpuSolver.instances[-1]
    assert not new.model.links[1, :, :, 0].any()
    np.testing.assert_array_equal(cm.displacements()[1, 2, 1], (2.0, 0.0, 0.0))
    cm.relax(1)  # relaxed on the GPU, over the box of displaced elements
    assert new.calls[-1] == "relax ((0, 0, 0), (4, 4, 4)) 1"
    cm.close()
    assert new.released


def test_cpu_warp_stays_current_through_local_updates() -> None:
    """The CPU warp is rewritten only in the box of displaced elements: after moves,
    relaxation, a cut and a reset its field still equals the displacements."""
    cm = ChainMail(_grid((12, 10, 8)))
    w = cm.warp()
    cm.move((6, 5, 4), (4.0, -2.0, 1.0))
    np.testing.assert_array_equal(w.displacements, cm.displacements())
    cm.relax(2)
    np.testing.assert_array_equal(w.displacements, cm.displacements())
    cm.move((2, 2, 2), (-3.0, 0.0, 2.0))
    np.testing.assert_array_equal(w.displacements, cm.displacements())
    cm.reset()
    np.testing.assert_array_equal(w.displacements, 0.0)
