"""Tests of the one model builder (voxwarp.editing.model_settings and the adapters'
``build``): the CLI, the editor, the napari widget and a direct call build the same model
from the same settings, and "settled" means one thing.

Pure CPU, small grids on a 32³ fish. Oracles: exact equality of element positions and
of wire fields built by the different callers, and the settle rule read off the model's
velocities.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from voxwarp.cli.deform_options import (
    MASSSPRING_SETTLE_MAX_STEPS,
    MASSSPRING_SETTLE_TOL,
    MASSSPRING_STEPS,
)
from voxwarp.cli.deformation import _deform_grid, _run_chainmail, _run_massspring, _wire_warp
from voxwarp.cli.main import build_parser
from voxwarp.core.volume import Volume
from voxwarp.deform.elements.grid import ElementGrid
from voxwarp.deform.elements.massspring import MassSpring
from voxwarp.deform.wires.field import Wire
from voxwarp.editing import model_settings as msets
from voxwarp.editing.families import FAMILIES
from voxwarp.editing.families.elements import ChainMailFamily, MassSpringFamily
from voxwarp.editing.families.wires import WireBuild, WiresFamily
from voxwarp.editing.session import EditSession
from voxwarp.io.samples import load_sample
from voxwarp.napari_plugin.deformed_view import PUSH_GRID, push_warps
from voxwarp.scene import Scene


@pytest.fixture(scope="module")
def volume() -> Volume:
    return load_sample("fish", shape=(32, 32, 32))


def _render_args(*extra: str) -> argparse.Namespace:
    return build_parser(bench=False).parse_args(["render", "in.npy", "-o", "x.png", *extra])


def test_the_cli_constants_are_the_builders() -> None:
    assert MASSSPRING_SETTLE_TOL == msets.SETTLE_SPEED
    assert MASSSPRING_SETTLE_MAX_STEPS == msets.SETTLE_MAX_STEPS
    assert MASSSPRING_STEPS == msets.FIXED_STEPS
    assert msets.SettleRule().limit == 0  # a model at rest
    assert msets.SettleRule(steps=None).limit == msets.FIXED_STEPS
    assert msets.SettleRule(settle=True, steps=None).limit == msets.SETTLE_MAX_STEPS


def test_cli_and_builder_give_the_same_mass_spring(volume: Volume) -> None:
    args = _render_args(
        "--massspring", "5", "--drag", "2,2,2:3,0,1", "--fix", "0..4,0..4,0..0", "--steps", "60"
    )
    cli_model, summary = _run_massspring(args, _deform_grid(args, volume), None)
    settings = msets.MassSpringSettings(
        shape=(5, 5, 5),
        shear=True,
        fixed=(((0, 4), (0, 4), (0, 0)),),
        drags=(msets.Drag((2, 2, 2), (3.0, 0.0, 1.0)),),
        run=msets.SettleRule(steps=60),
        margin=3.0,  # the CLI's default grid margin: the largest drag offset component
    )
    built = MassSpringFamily.build(settings, volume)
    np.testing.assert_array_equal(built.model.positions(), cli_model.positions())
    assert built.report.steps == 60
    assert "60 steps" in summary


def test_editor_and_builder_give_the_same_mass_spring(volume: Volume) -> None:
    """The editor's model is the builder's at rest, with the session's settings (its
    default margin "auto"); the CLI with the same settings (no shear springs, the
    resolved margin) gives the same positions."""
    session = EditSession(Scene(volume))
    session.set_deformation("massspring", resolution=5, stiffness=0.5)
    session.model.move((2, 2, 2), (3.0, 0.0, 1.0))
    session.model.step(40)
    settings = msets.MassSpringSettings(
        shape=(5, 5, 5),
        stiffness=0.5,
        drags=(msets.Drag((2, 2, 2), (3.0, 0.0, 1.0)),),
        run=msets.SettleRule(steps=40),
        margin="auto",
    )
    built = MassSpringFamily.build(settings, volume)
    np.testing.assert_array_equal(built.model.positions(), session.model.positions())
    margin = session.model.grid.margin
    assert margin > 0.0
    args = _render_args(
        "--massspring", "5", "--no-shear", "--drag", "2,2,2:3,0,1", "--steps", "40",
        "--grid-margin", repr(margin),  # the editor's margin, resolved
    )  # fmt: skip
    cli_model, _ = _run_massspring(args, _deform_grid(args, volume), None)
    np.testing.assert_array_equal(cli_model.positions(), session.model.positions())


def test_settling_stops_by_the_one_rule(volume: Volume) -> None:
    settings = msets.MassSpringSettings(
        shape=(4, 4, 4),
        shear=True,
        drags=(msets.Drag((1, 1, 1), (2.0, 0.0, 0.0)),),
        run=msets.SettleRule(settle=True, steps=None),
    )
    built = MassSpringFamily.build(settings, volume)
    assert not built.report.hit_limit
    assert 0 < built.report.steps < msets.SETTLE_MAX_STEPS
    assert msets.is_settled(built.model)
    assert msets.max_speed(built.model) < msets.SETTLE_SPEED
    stopped = MassSpringFamily.build(
        msets.MassSpringSettings(
            shape=(4, 4, 4),
            drags=settings.drags,
            run=msets.SettleRule(settle=True, steps=50),
        ),
        volume,
    )
    assert stopped.report.steps == 50
    assert stopped.report.hit_limit
    assert not msets.is_settled(stopped.model)


def test_cli_and_builder_give_the_same_chainmail(volume: Volume) -> None:
    args = _render_args(
        "--chainmail", "6", "--drag", "3,3,3:0,4,0", "--relax", "3", "--cut", "48,24,20:1,0,0"
    )
    cli_model, summary = _run_chainmail(args, _deform_grid(args, volume), None)
    settings = msets.ChainMailSettings(
        shape=(6, 6, 6),
        cuts=(msets.Cut((48.0, 24.0, 20.0), (1.0, 0.0, 0.0)),),
        drags=(msets.Drag((3, 3, 3), (0.0, 4.0, 0.0)),),
        margin=4.0,  # the CLI's default grid margin: the largest drag offset component
        relax=3,
    )
    built = ChainMailFamily.build(settings, volume)
    np.testing.assert_array_equal(built.model.positions(), cli_model.positions())
    assert built.model.relax_steps == cli_model.relax_steps == 3
    assert f"{built.report.displaced} elements displaced" in summary
    assert built.report.cut > 0


def test_editor_chainmail_is_the_builders_at_rest(volume: Volume) -> None:
    session = EditSession(Scene(volume))
    session.set_deformation("chainmail", resolution=5, variant="gibson", stiffness=0.7)
    settings = msets.ChainMailSettings(
        shape=(5, 5, 5),
        stiffness=0.7,
        variant="gibson",
        relax_steps=session.options.relax_steps,
        margin="auto",  # the editor's default
    )
    built = ChainMailFamily.build(settings, volume)
    assert built.model.to_dict() == session.model.to_dict()


def test_napari_push_is_the_builders_and_as_before(volume: Volume) -> None:
    """The push through the builder equals the model made directly (as the widget did
    before the builder: MassSpring, one move, ``settle()`` with its defaults)."""
    (warp,) = push_warps(volume, direction=(0.0, 0.0, 1.0))
    block = np.zeros((PUSH_GRID,) * 3, dtype=bool)
    block[2:5, 2:5, 2:5] = True
    offset = (0.0, 0.0, 0.2 * float(volume.size_mm[2]))
    direct = MassSpring(
        ElementGrid(volume, shape=PUSH_GRID, anchor="corners"),
        integrator="semi-implicit",
        shear=True,
    )
    direct.move(block, offset)
    direct.settle()
    np.testing.assert_array_equal(warp.displacements, direct.warp().displacements)


def test_cli_wires_and_editor_wire_build_give_the_same_field(
    volume: Volume, tmp_path: Path
) -> None:
    lo, hi = (np.asarray(b, dtype=np.float64) for b in volume.bounds)
    c = 0.5 * (lo + hi)
    base = np.array([[lo[0] + 10, c[1], c[2]], [c[0], c[1], c[2]], [hi[0] - 10, c[1], c[2]]])
    bent = base.copy()
    bent[1, 1] += 4.0
    wire = Wire(base, bent, radius=8.0, name="w")
    path = tmp_path / "w.json"
    path.write_text(json.dumps({"wires": [wire.to_dict()], "field_scale": 2}))
    args = _render_args("--wires", str(path), "--field-scale", "4")
    cli_warp, _ = _wire_warp(args, volume)
    job = WireBuild(0, volume, [wire], {"field_scale": 4})
    editor_warp = job.run()
    assert editor_warp is not None
    assert cli_warp.to_dict() == editor_warp.to_dict()
    np.testing.assert_array_equal(cli_warp.apply(base), editor_warp.apply(base))
    built = WiresFamily.build(msets.WireSettings.of([wire], field_scale=4), volume)
    assert built.model is None
    assert built.warp.to_dict() == cli_warp.to_dict()


def test_every_family_has_a_builder(volume: Volume) -> None:
    assert FAMILIES["none"].build(None, volume) == (None, None, msets.BuildReport())
    for name in ("massspring", "chainmail", "wires", "lattice"):
        assert FAMILIES[name].build.__func__ is not FAMILIES["none"].build.__func__  # type: ignore[attr-defined]


def test_family_options_keep_the_editor_entry_and_check_settings() -> None:
    """The options save under the editor entry's keys, in its order, and read back;
    model settings are checked with the session's messages."""
    options = msets.FamilyOptions(integrator="explicit", stiffness=0.3, relax_steps=4)
    entry = options.to_entry()
    assert list(entry) == [
        "integrator",
        "variant",
        "steps_per_frame",
        "relax_steps",
        "stiffness",
        "anchor",
        "fix_outside",
        "wire_settings",
        "margin",
    ]
    assert entry["margin"] == "auto"
    again = msets.FamilyOptions()
    again.read_entry(entry)
    assert again == options
    assert options.copy() == options
    assert options.copy().wire_settings is not options.wire_settings
    with pytest.raises(msets.EditorError, match=r"stiffness must be in \(0, 1\]"):
        options.with_model_settings({"stiffness": 2})
    with pytest.raises(msets.EditorError, match="unknown deformation settings: bogus"):
        options.with_model_settings({"bogus": 1})
    with pytest.raises(
        msets.EditorError, match="anchor must be one of default, shell, corners, none"
    ):
        options.with_model_settings({"anchor": "box"})
    with pytest.raises(msets.EditorError, match="fix_outside must be >= 0"):
        options.with_model_settings({"fix_outside": -1})
    bounds = options.with_model_settings({"anchor": "corners", "fix_outside": 40})
    assert (bounds.anchor, bounds.fix_outside) == ("corners", 40.0)
    assert (options.anchor, options.fix_outside) == ("default", "default")
    with options.one_step():
        assert (options.steps_per_frame, options.relax_steps) == (1, 1)
    assert (options.steps_per_frame, options.relax_steps) == (10, 4)
