"""Tests of the mass-spring model's saved state (MassSpring.to_dict / from_dict) and of
the offset-field warp entry that carries it in scene JSON.

Oracles: a JSON round trip rebuilds a model whose dict is equal and whose simulation
continues bit for bit like the original's (float64 CPU solver); a model saved with its
positions resumes exactly there; a warp entry written by a mass-spring warp loads as a
CPU field equal to the simulated one, keeps the model, and resumes the simulation at
``rest + displacements``. One GL test: a GPU simulation's warp, saved and loaded,
renders the same image as the live GPU-owned warp.
"""

from __future__ import annotations

import copy
import json
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from voxwarp.deform.elements.grid import ElementGrid
from voxwarp.deform.elements.massspring import MassSpring, MassSpringError
from voxwarp.deform.elements.offset_field import OffsetFieldWarp
from voxwarp.deform.warp import WarpError, warp_from_dict

BOX = ((0.0, -10.0, 5.0), (60.0, 30.0, 45.0))


def rich_model() -> MassSpring:
    """A 6x5x4 model with every setting away from its default and two held elements."""
    g = ElementGrid(BOX, shape=(6, 5, 4), anchor="corners")
    rng = np.random.default_rng(3)
    g.set_material(stiffness=rng.uniform(0.1, 0.9, g.shape), damping=1.5, mass=2.0)
    g.set_material((2, 2, 2), mass=3.0)
    g.fix((0, 2, 1))
    ms = MassSpring(
        g,
        integrator="semi-implicit",
        spring_constant=30.0,
        spring_damping=0.25,
        shear=True,
        bend=True,
        max_step=1.5,
    )
    ms.move((3, 2, 2), (4.0, -2.0, 1.5))
    ms.move((4, 1, 1), (0.0, 3.0, 0.0))
    return ms


def json_round_trip(d: dict[str, Any]) -> dict[str, Any]:
    return json.loads(json.dumps(d))


# ---------------------------------------------------------------------- MassSpring
def test_round_trip_preserves_everything() -> None:
    ms = rich_model()
    d = json_round_trip(ms.to_dict())
    assert set(d) == {
        "grid",
        "integrator",
        "dt",
        "spring_constant",
        "spring_damping",
        "shear",
        "bend",
        "max_step",
        "held",
    }
    assert d["held"] == [
        {"index": [3, 2, 2], "offset": [4.0, -2.0, 1.5]},
        {"index": [4, 1, 1], "offset": [0.0, 3.0, 0.0]},
    ]
    back = MassSpring.from_dict(d)
    assert back.to_dict() == ms.to_dict()
    assert back.dt == ms.dt
    assert back.integrator == "semi-implicit"
    np.testing.assert_array_equal(back.held, ms.held)
    np.testing.assert_array_equal(back.grid.fixed, ms.grid.fixed)
    for name in ("stiffness", "damping", "mass"):
        np.testing.assert_array_equal(getattr(back.model, name), getattr(ms.model, name))
    # the same model: the simulation continues identically
    ms.step(40)
    back.step(40)
    np.testing.assert_array_equal(back.positions(), ms.positions())


def test_positions_resume_the_simulation_exactly() -> None:
    ms = rich_model()
    ms.step(25)
    d = json_round_trip(ms.to_dict(include_positions=True))
    assert np.asarray(d["positions"]).shape == (6, 5, 4, 3)
    back = MassSpring.from_dict(d)
    np.testing.assert_array_equal(back.positions(), ms.positions())
    # velocities restart at 0: the original, stopped the same way, continues alike
    ms.set_state(ms.positions())
    ms.step(10)
    back.step(10)
    np.testing.assert_array_equal(back.positions(), ms.positions())
    # the positions argument overrides the dict's
    rest = MassSpring.from_dict(d, positions=ms.grid.rest_positions)
    held = rest.held
    np.testing.assert_array_equal(rest.displacements()[~held & ~rest.grid.pinned()], 0.0)


def test_only_the_grid_is_required() -> None:
    g = ElementGrid(BOX, shape=4, anchor="corners")
    ms = MassSpring.from_dict({"type": "massspring", "grid": g.to_dict()})
    default = MassSpring(ElementGrid(BOX, shape=4, anchor="corners"))
    assert ms.to_dict() == default.to_dict()
    assert not ms.held.any()


def test_materials_are_those_the_solver_runs() -> None:
    ms = MassSpring(ElementGrid(BOX, shape=3, anchor="corners"))
    ms.grid.set_material(stiffness=0.9)  # after construction: not simulated
    assert ms.to_dict()["grid"]["stiffness"] == 0.5


BAD = [
    ("not a dict", "must be an object"),
    ({"type": "wire", "grid": {}}, "expected 'massspring'"),
    ({}, "needs the key 'grid'"),
    ({"grid": {"lo": [0, 0, 0], "hi": [1, 1, 1]}}, r"'grid'.*\['shape'\]"),
    ({"held": [{"index": [1, 1, 1]}]}, r"'held'\[0\] needs the keys \['offset'\]"),
    ({"held": [{"offset": [1, 0, 0]}]}, r"needs the keys \['index'\]"),
    ({"held": {"index": [1, 1, 1]}}, "'held' must be a list"),
    ({"held": [[1, 1, 1]]}, r"'held'\[0\] must be an object"),
    ({"held": [{"index": [1, 1], "offset": [0, 0, 1]}]}, "3 integers"),
    ({"held": [{"index": [1.5, 1, 1], "offset": [0, 0, 1]}]}, "3 integers"),
    (
        {"held": [{"index": [4, 1, 1], "offset": [0, 0, 1]}]},
        r"\(4, 1, 1\) is outside .*\(3, 3, 3\)",
    ),
    ({"held": [{"index": [-1, 1, 1], "offset": [0, 0, 1]}]}, "outside the grid"),
    ({"held": [{"index": [0, 0, 0], "offset": [0, 0, 1]}]}, "fixed"),
    ({"held": [{"index": [1, 1, 1], "offset": [0, 1]}]}, r"'offset' must be 3 finite"),
    ({"held": [{"index": [1, 1, 1], "offset": ["a", 0, 0]}]}, "'offset' must be 3"),
    ({"shear": "yes"}, "'shear' must be true or false"),
    ({"integrator": "rk4"}, "unknown integrator"),
    ({"dt": -1}, "dt must be > 0"),
    ({"positions": [[0, 0, 0]]}, r"positions must have shape \(4, 4, 4, 3\)"),
]


@pytest.mark.parametrize(("entry", "pattern"), BAD)
def test_bad_entries_raise_clear_errors(entry: Any, pattern: str) -> None:
    if isinstance(entry, dict) and "grid" not in entry and entry:
        entry = {"grid": ElementGrid(BOX, shape=4, anchor="corners").to_dict(), **entry}
    with pytest.raises(MassSpringError, match=pattern):
        MassSpring.from_dict(entry)


def test_rigid_elements_cannot_be_held() -> None:
    g = ElementGrid(BOX, shape=4, anchor="corners")
    g.set_material((1, 1, 1), stiffness=1.0)
    d = {"grid": g.to_dict(), "held": [{"index": [1, 1, 1], "offset": [1, 0, 0]}]}
    with pytest.raises(MassSpringError, match="rigid"):
        MassSpring.from_dict(d)


# ---------------------------------------------------------------------- warp entries
def test_warp_entry_carries_field_and_model() -> None:
    ms = rich_model()
    ms.step(30)
    w = ms.warp(inverse="approx")
    d = json_round_trip(w.to_dict())
    assert d["type"] == "offset_field"
    assert d["inverse"] == "approx"
    assert d["model"] == {"type": "massspring", **json_round_trip(ms.to_dict())}
    back = warp_from_dict(d)
    assert isinstance(back, OffsetFieldWarp)
    assert not back.gpu_owned
    np.testing.assert_array_equal(back.displacements, w.displacements)
    np.testing.assert_array_equal(back.texture_data(), w.texture_data())
    assert back.model_state == d["model"]
    assert back.to_dict() == d  # a loaded entry saves the same entry again
    # resume: positions rest + displacements (float32 field), velocities 0
    resumed = MassSpring.from_warp(back)
    np.testing.assert_allclose(resumed.positions(), ms.positions(), atol=1e-5)
    np.testing.assert_array_equal(resumed.held, ms.held)
    assert resumed.to_dict() == ms.to_dict()


def test_entries_without_a_model_still_load() -> None:
    u = np.zeros((3, 3, 3, 3))
    u[1, 1, 1] = (1.0, 0.0, 0.0)
    d = json_round_trip(OffsetFieldWarp(*BOX, u).to_dict())
    assert "model" not in d
    w = warp_from_dict(d)
    assert w.model_state is None
    with pytest.raises(MassSpringError, match="no mass-spring model"):
        MassSpring.from_warp(w)


def test_a_gpu_owned_field_with_a_model_source_saves_the_field() -> None:
    ms = rich_model()
    field = np.full((6, 5, 4, 3), 0.25)
    calls: list[int] = []

    def source() -> tuple[dict[str, Any], np.ndarray]:
        calls.append(1)
        return {"type": "massspring", **ms.to_dict()}, field

    w = OffsetFieldWarp(*BOX, shape=(6, 5, 4), texture_source=lambda ctx: None, model_source=source)
    d = json_round_trip(w.to_dict())
    assert calls == [1]
    back = warp_from_dict(d)
    np.testing.assert_array_equal(back.displacements, field)
    assert back.model_state is not None
    assert back.model_state["type"] == "massspring"


@pytest.mark.parametrize(
    ("model", "pattern"), [(3, "'model' must be an object"), ({"grid": {}}, "'type' string")]
)
def test_bad_model_entries(model: Any, pattern: str) -> None:
    d = OffsetFieldWarp(*BOX, np.zeros((2, 2, 2, 3))).to_dict()
    d["model"] = model
    with pytest.raises(WarpError, match=pattern):
        warp_from_dict(d)


def test_resuming_checks_the_field_against_the_grid() -> None:
    ms = rich_model()
    state = copy.deepcopy({"type": "massspring", **ms.to_dict()})
    w = OffsetFieldWarp(*BOX, np.zeros((3, 3, 3, 3)), model_state=state)
    with pytest.raises(MassSpringError, match="inconsistent"):
        MassSpring.from_warp(w)


def test_bad_warp_settings() -> None:
    ms = MassSpring(ElementGrid(BOX, shape=3, anchor="corners"))
    with pytest.raises(MassSpringError, match="inverse must be one of"):
        ms.warp(inverse="newton")
    with pytest.raises(MassSpringError, match="iterations"):
        ms.warp(iterations=-1)
    assert ms.warp(inverse="baked", iterations=0).steps == 0  # the baked seed alone
    assert ms.warp(iterations=3).iterations == 3
    assert ms.warp().iterations == 3


# ---------------------------------------------------------------------- GL
def test_saved_gpu_warp_renders_like_the_live_one(
    offscreen: Callable[..., Any], gl_ctx: Any
) -> None:
    from tests.render.test_render import phantom
    from voxwarp.scene import Scene

    vol = phantom()
    grid = ElementGrid(vol, shape=6, anchor="corners")
    ms = MassSpring(grid, backend="gpu", ctx=gl_ctx, integrator="semi-implicit", shear=True)
    try:
        ms.move((3, 3, 3), (4.0, 2.0, 0.0))
        ms.step(200)
        live = ms.warp()
        assert live.gpu_owned
        d = json_round_trip(live.to_dict())
        saved = warp_from_dict(d)
        assert not saved.gpu_owned
        assert d["model"]["held"] == [{"index": [3, 3, 3], "offset": [4.0, 2.0, 0.0]}]
        r = offscreen(96, 96)
        for mode in ("mip", "dvr"):  # dvr: also with empty-space skipping
            kw = {"mode": mode, "view": "+z", "projection": "orthographic", "jitter": False}
            a = r.render(Scene(vol, warps=[live], **kw))
            b = r.render(Scene(vol, warps=[saved], **kw))
            np.testing.assert_array_equal(a, b)
        assert np.abs(saved.displacements).max() > 1.0  # the drag moved the field
        saved.release()
    finally:
        ms.close()
