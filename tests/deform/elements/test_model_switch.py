"""Switching element models while keeping the deformation (Knoche 2008, §5):
``MassSpring.from_model`` keeps positions exactly, ``ChainMail.from_model`` projects
them onto the limits with the least movement (deform/elements/limits_projection.py).

Oracles: an independent per-link check of the limits; analytic projections (one
over-stretched link with two free ends or one fixed end, a chain of over-stretched
links); the variational inequality of a Euclidean projection onto a convex set,
``(y - x*) . (z - x*) <= 0`` for feasible states ``z``; CPU/GLSL agreement.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from voxwarp.deform.elements import limits_projection
from voxwarp.deform.elements.chainmail import ChainMail, ChainMailError
from voxwarp.deform.elements.chainmail_model import ChainMailModel
from voxwarp.deform.elements.grid import ElementGrid
from voxwarp.deform.elements.limits_projection import project_onto_limits
from voxwarp.deform.elements.massspring import MassSpring, MassSpringError
from voxwarp.deform.elements.switching import SwitchReport, movement_report

BOX = ((0.0, 0.0, 0.0), (90.0, 90.0, 90.0))  # 10 mm spacing on a 10^3 grid
DRAG = (8.0, 6.0, 0.0)


def _grid(shape: Any = 10, anchor: str = "shell") -> ElementGrid:
    return ElementGrid(BOX, shape=shape, anchor=anchor)


def _dragged_massspring(backend: str = "cpu", ctx: Any = None) -> MassSpring:
    """A mass-spring with one element dragged about a spacing and settled: beyond the
    ChainMail's default slack (a quarter spacing at stiffness 0.5), within what its
    links allow between the drag and the fixed shell."""
    ms = MassSpring(_grid(), backend=backend, ctx=ctx)
    ms.move((5, 5, 5), DRAG)
    ms.settle(max_steps=3000)
    return ms


def _link_excess(model: ChainMailModel, x: np.ndarray) -> float:
    """Largest excess (mm) over any present link's limits, link by link (independent of
    ``ChainMailModel.violation``)."""
    worst = 0.0
    for idx in np.ndindex(*model.shape):
        for a in range(3):
            if not model.links[(*idx, a)]:
                continue
            nb = list(idx)
            nb[a] += 1
            nb_t = tuple(nb)
            d = x[nb_t] - x[idx]
            mn = 0.5 * (model.min_dist[(*idx, a)] + model.min_dist[(*nb_t, a)])
            mx = 0.5 * (model.max_dist[(*idx, a)] + model.max_dist[(*nb_t, a)])
            sh = 0.5 * (model.max_shear[(*idx, a)] + model.max_shear[(*nb_t, a)])
            worst = max(worst, mn - d[a], d[a] - mx)
            worst = max(worst, *(abs(d[j]) - sh for j in range(3) if j != a))
    return worst


def _model(shape: tuple[int, int, int], links: np.ndarray | None = None) -> ChainMailModel:
    """Spacing 10 mm, limits [8, 12] mm along a link and 2 mm across."""
    rest = np.stack(np.indices(shape, dtype=np.float64), -1) * 10.0
    return ChainMailModel(
        rest=rest,
        spacing=np.full(3, 10.0),
        min_dist=8.0,
        max_dist=12.0,
        max_shear=2.0,
        links=np.ones((*shape, 3), bool) if links is None else links,
        fixed=np.zeros(shape, bool),
    )


# ---------------------------------------------------------------------- the projection
def test_one_overstretched_link_moves_both_ends_half_the_excess() -> None:
    links = np.zeros((3, 3, 3, 3), bool)
    links[1, 1, 1, 0] = True  # the only link: (1,1,1) -> (2,1,1)
    m = _model((3, 3, 3), links)
    y = m.rest.copy()
    y[2, 1, 1] += (5.0, 3.0, 0.0)  # gap 15 mm (max 12), shear 3 mm (max 2)
    x, before, _ = project_onto_limits(m, y)
    assert before == pytest.approx(3.0)
    np.testing.assert_allclose(x[1, 1, 1] - y[1, 1, 1], (1.5, 0.5, 0.0), atol=1e-6)
    np.testing.assert_allclose(x[2, 1, 1] - y[2, 1, 1], (-1.5, -0.5, 0.0), atol=1e-6)
    others = np.ones((3, 3, 3), bool)
    others[1, 1, 1] = others[2, 1, 1] = False
    assert np.array_equal(x[others], y[others])  # within limits: not moved at all


def test_a_fixed_end_makes_the_free_end_take_the_whole_excess() -> None:
    links = np.zeros((3, 3, 3, 3), bool)
    links[1, 1, 1, 0] = True
    m = _model((3, 3, 3), links)
    m.fixed[1, 1, 1] = True
    y = m.rest.copy()
    y[2, 1, 1, 0] += 5.0
    x, _, _ = project_onto_limits(m, y)
    np.testing.assert_array_equal(x[1, 1, 1], y[1, 1, 1])
    np.testing.assert_allclose(x[2, 1, 1, 0], 22.0, atol=1e-6)  # 12 mm from its partner


def test_a_chain_of_overstretched_links_keeps_its_centre() -> None:
    """Five elements in a row, each gap 1 mm too long, no other link: the least-squares
    projection closes every gap to 12 mm and keeps the mean, so element i moves
    ``-(i - 2)`` mm: more than the 1 mm violation at the ends (the movement is least in
    sum, not bounded by the violation)."""
    links = np.zeros((5, 2, 2, 3), bool)
    links[:4, 0, 0, 0] = True
    m = _model((5, 2, 2), links)
    y = m.rest.copy()
    y[:, 0, 0, 0] = np.arange(5) * 13.0
    x, before, _ = project_onto_limits(m, y)
    assert before == pytest.approx(1.0)
    np.testing.assert_allclose(x[:, 0, 0, 0] - y[:, 0, 0, 0], -(np.arange(5) - 2.0), atol=1e-5)


def test_the_box_around_the_violations_gives_the_whole_grids_projection() -> None:
    """A row of 16 elements folded over in the middle: the correction
    reaches elements far beyond the first box (violated links + 2), which must grow;
    the result is the projection iterated on the whole grid."""
    links = np.zeros((16, 2, 2, 3), bool)
    links[:15, 0, 0, 0] = True
    m = _model((16, 2, 2), links)
    y = m.rest.copy()
    y[8:, 0, 0, 0] -= 20.0  # element 8 10 mm left of element 7 (gap at least 8 mm)
    x, _, _ = project_onto_limits(m, y)
    full, _, _ = limits_projection._hildreth(m, y, 1e-9, 100000)
    np.testing.assert_allclose(x, full, atol=1e-5)
    moved = np.flatnonzero(np.abs(x[:, 0, 0, 0] - y[:, 0, 0, 0]) > 1e-6)
    assert moved.min() <= 3  # beyond the first box (elements 5..10) and its ring
    assert _link_excess(m, x) <= 1e-9


def test_projection_is_the_nearest_feasible_state() -> None:
    """Variational inequality of the Euclidean projection x* of y onto the (convex)
    limits: (y - x*) . (z - x*) <= 0 for every feasible z; feasible states z from random
    ChainMail drags, the rest state and the propagation's repair of y."""
    rng = np.random.default_rng(3)
    grid = _grid(6, anchor="corners")
    cm = ChainMail(grid)
    model = cm.model
    y = model.rest + rng.normal(0.0, 2.0, model.rest.shape)
    y[model.fixed] = model.rest[model.fixed]
    x, before, _ = project_onto_limits(model, y)
    assert before > 1.0
    assert _link_excess(model, x) <= 1e-9
    feasible = [model.rest.copy()]
    repaired = ChainMail(_grid(6, anchor="corners"))
    repaired.set_state(y)  # the propagation's own repair: feasible, not least
    feasible.append(repaired.positions())
    for _ in range(6):
        cm.reset()
        cm.move(tuple(rng.integers(1, 5, 3)), rng.normal(0.0, 8.0, 3))
        cm.release()
        feasible.append(cm.positions())
    scale = float(np.sum((y - x) ** 2))
    for z in feasible:
        assert _link_excess(model, z) <= 1e-6
        assert float(np.sum((y - x) * (z - x))) <= 1e-6 * scale
        assert np.sum((y - x) ** 2) <= np.sum((y - z) ** 2)
    # the propagation's repair moved strictly more
    assert np.sum((y - x) ** 2) < 0.9 * np.sum((y - feasible[1]) ** 2)


def test_cut_links_bind_nothing() -> None:
    m = _model((3, 3, 3))
    m.links[1, 1, 1, 0] = False  # cut (1,1,1) -> (2,1,1)
    y = m.rest.copy()
    y[2:, :, :, 0] += 4.0  # opens the cut layer by 4 mm: only cut links stretch
    x, before, _sweeps = project_onto_limits(m, y)
    assert before > 0  # the uncut links of that layer are violated
    m2 = _model((3, 3, 3))
    m2.links[1, :, :, 0] = False  # the whole layer cut: nothing to restore
    x2, before2, sweeps2 = project_onto_limits(m2, y)
    assert before2 == 0.0
    assert sweeps2 == 0
    np.testing.assert_array_equal(x2, y)
    assert _link_excess(m, x) <= 1e-9


# ---------------------------------------------------------------------- ChainMail -> mass-spring
def test_chainmail_to_massspring_keeps_positions_held_and_fixed() -> None:
    cm = ChainMail(_grid(), relax_steps=2)
    cm.move((4, 5, 5), (12.0, -6.0, 3.0))
    cm.fix((2, 2, 2))
    ms = MassSpring.from_model(cm, integrator="semi-implicit")
    np.testing.assert_array_equal(ms.positions(), cm.positions())
    np.testing.assert_array_equal(ms.held, cm.held)
    np.testing.assert_array_equal(ms.held_offsets, cm.held_offsets)
    np.testing.assert_array_equal(ms.grid.fixed, cm.grid.fixed)
    np.testing.assert_array_equal(ms.grid.anchored, cm.grid.anchored)
    assert ms.grid is not cm.grid  # a copy: undoing the switch keeps the old model's
    assert ms.integrator == "semi-implicit"
    assert ms.switch_report == SwitchReport(0.0, 0.0, 0)
    np.testing.assert_array_equal(ms.velocities(), 0.0)


def test_chainmail_cuts_are_counted_as_joined_and_kept_by_a_chainmail() -> None:
    cm = ChainMail(_grid())
    cut = cm.cut((45.0, 45.0, 45.0), (1.0, 0.0, 0.0), extent=15.0)
    assert cut > 0
    report = MassSpring.from_model(cm).switch_report
    assert report is not None
    assert report.cuts_joined == cut
    assert f"{cut} cut link(s)" in report.describe()
    again = ChainMail.from_model(cm, variant="gibson")
    np.testing.assert_array_equal(again.cuts, cm.cuts)


# ---------------------------------------------------------------------- mass-spring -> ChainMail
def test_massspring_to_chainmail_satisfies_every_link_and_keeps_pins() -> None:
    ms = _dragged_massspring()
    y = ms.positions()
    cm = ChainMail.from_model(ms, variant="gibson")
    x = cm.positions()
    report = cm.switch_report
    assert report is not None
    assert report.violation_before > 2.0  # the drag broke the limits
    assert _link_excess(cm.model, x) <= 1e-9
    fixed = cm.grid.constrained()
    np.testing.assert_array_equal(x[fixed], cm.model.rest[fixed])
    np.testing.assert_array_equal(cm.held, ms.held)
    np.testing.assert_array_equal(x[5, 5, 5], y[5, 5, 5])  # the held element stays
    dist = np.linalg.norm(x - y, axis=-1)
    assert report.moved == int(np.count_nonzero(dist > 1e-9))
    assert report.max_mm == pytest.approx(dist.max())
    assert report.rms_mm == pytest.approx(np.sqrt(np.mean(dist**2)))
    assert cm.variant == "gibson"


def test_state_within_limits_does_not_move_and_round_trips() -> None:
    cm = ChainMail(_grid())
    cm.move((5, 4, 5), (8.0, 4.0, -3.0))
    cm.relax(3)
    ms = MassSpring.from_model(cm)
    back = ChainMail.from_model(ms)
    np.testing.assert_array_equal(back.positions(), cm.positions())
    assert back.switch_report is not None
    assert back.switch_report.moved == 0
    assert back.switch_report.sweeps == 0
    assert "no element moved" in back.switch_report.describe()


def test_held_elements_beyond_the_limits_are_released() -> None:
    """Two held elements 20 mm further apart than the links between them allow."""
    ms = MassSpring(_grid(anchor="none"))
    ms.move([(3, 5, 5), (6, 5, 5)], [(-10.0, 0, 0), (10.0, 0, 0)])
    ms.settle(max_steps=500)
    cm = ChainMail.from_model(ms)
    assert cm.switch_report is not None
    assert cm.switch_report.released == 2
    assert not cm.held.any()
    assert _link_excess(cm.model, cm.positions()) <= 1e-9


def test_anchors_too_close_to_a_held_element_are_freed_first() -> None:
    """Region of influence 15 mm: elements two links (20 mm) from the held one are
    anchored, and a drag of 8 mm towards them needs a link shorter than 7.5 mm."""
    grid = ElementGrid(BOX, shape=10, anchor="shell", fix_outside=15.0)
    ms = MassSpring(grid)
    ms.move((5, 5, 5), (8.0, 0.0, 0.0))
    ms.step(50)
    assert ms.grid.anchored[7, 5, 5]
    cm = ChainMail.from_model(ms)
    report = cm.switch_report
    assert report is not None
    assert report.anchors_freed == int(ms.grid.anchored.sum())
    assert report.released == 0
    assert cm.held[5, 5, 5]
    assert not cm.grid.anchored.any()
    np.testing.assert_array_equal(cm.positions()[5, 5, 5], ms.positions()[5, 5, 5])
    assert _link_excess(cm.model, cm.positions()) <= 1e-9
    assert "anchored element(s) freed" in report.describe()


def test_switch_on_another_grid_is_refused() -> None:
    ms = MassSpring(_grid())
    with pytest.raises(ChainMailError, match="switch on the same grid"):
        ChainMail.from_model(ms, grid=_grid(8))
    with pytest.raises(MassSpringError, match="switch on the same grid"):
        MassSpring.from_model(ChainMail(_grid()), grid=_grid(8))


def test_given_grid_takes_materials_and_the_old_constraints() -> None:
    ms = MassSpring(_grid())
    ms.fix((3, 3, 3))
    grid = _grid()
    grid.set_material(stiffness=0.9)  # stiffer: tighter limits
    grid.anchor, grid.fix_outside = "corners", None  # replaced by the model's
    cm = ChainMail.from_model(ms, grid=grid)
    assert cm.grid is grid
    assert grid.fixed[3, 3, 3]
    assert (grid.anchor, grid.fix_outside) == (ms.grid.anchor, ms.grid.fix_outside)
    np.testing.assert_array_equal(grid.fixed, ms.grid.fixed)
    np.testing.assert_allclose(cm.model.max_dist, 10.0 * (1 + 0.5 * 0.1))


def test_switched_chainmail_round_trips_through_scene_json() -> None:
    ms = _dragged_massspring()
    cm = ChainMail.from_model(ms)
    warp = cm.warp()
    again = ChainMail.from_warp(type(warp).from_dict(warp.to_dict()))
    np.testing.assert_allclose(again.positions(), cm.positions(), atol=1e-9)
    np.testing.assert_array_equal(again.held, cm.held)
    back = MassSpring.from_model(cm)
    warp2 = back.warp()
    again2 = MassSpring.from_warp(type(warp2).from_dict(warp2.to_dict()))
    np.testing.assert_allclose(again2.positions(), cm.positions(), atol=1e-4)  # float32 field


def test_movement_report_counts() -> None:
    a = np.zeros((2, 1, 1, 3))
    b = a.copy()
    b[1, 0, 0] = (3.0, 4.0, 0.0)
    r = movement_report(a, b, violation_before=2.0)
    assert (r.max_mm, r.moved) == (5.0, 1)
    assert r.rms_mm == pytest.approx(np.sqrt(25.0 / 2))
    assert "1 element(s) moved up to 5 mm" in r.describe()


# ---------------------------------------------------------------------- GLSL backends
def test_gpu_switches_agree_with_the_cpu(gl_ctx: Any) -> None:
    ms_cpu = _dragged_massspring()
    cm_cpu = ChainMail.from_model(ms_cpu)
    ms_gpu = MassSpring(_grid(), backend="gpu", ctx=gl_ctx)
    ms_gpu.move((5, 5, 5), DRAG)
    ms_gpu.set_state(ms_cpu.positions())  # the same state on both backends
    cm_gpu = ChainMail.from_model(ms_gpu, ctx=gl_ctx)
    assert cm_gpu.backend == "gpu"
    x = cm_gpu.positions()
    assert _link_excess(cm_gpu.model, x) <= 1e-4  # float32 positions
    np.testing.assert_allclose(x, cm_cpu.positions(), atol=1e-4)
    back = MassSpring.from_model(cm_gpu, ctx=gl_ctx)
    assert back.backend == "gpu"
    np.testing.assert_allclose(back.positions(), x, atol=1e-5)
    to_cpu = MassSpring.from_model(cm_gpu, backend="cpu")
    np.testing.assert_array_equal(to_cpu.positions(), x)
    for m in (ms_cpu, cm_cpu, ms_gpu, cm_gpu, back, to_cpu):
        m.close()
