"""EditSession.set_deformation between mass-spring and ChainMail keeps the deformation
on the same grid (``Family.continue_from``), and the switched model's positions survive
a scene JSON round trip; a changed grid starts at rest."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from voxwarp.core.volume import Volume
from voxwarp.deform.elements.chainmail import ChainMail
from voxwarp.deform.elements.massspring import MassSpring
from voxwarp.editing.session import EditSession
from voxwarp.io.samples import load_sample
from voxwarp.scene import Scene


@pytest.fixture(scope="module")
def volume() -> Volume:
    return load_sample("fish", shape=(24, 24, 24))


@pytest.fixture
def session(volume: Volume) -> EditSession:
    return EditSession(Scene(volume))


def test_chainmail_to_massspring_and_back_keeps_positions(session: EditSession) -> None:
    s = session
    s.set_deformation("chainmail", resolution=5)
    s.model.move((2, 2, 2), (4.0, -3.0, 2.0))
    x = s.model.positions()
    s.set_deformation("massspring")
    assert isinstance(s.model, MassSpring)
    np.testing.assert_array_equal(s.model.positions(), x)
    assert "no element moved" in s.family.switch_note
    s.set_deformation("chainmail", variant="gibson")
    assert isinstance(s.model, ChainMail)
    assert s.model.variant == "gibson"
    np.testing.assert_array_equal(s.model.positions(), x)  # within the limits: kept


def test_a_changed_grid_starts_at_rest(session: EditSession) -> None:
    s = session
    s.set_deformation("massspring", resolution=5)
    s.model.move((2, 2, 2), (4.0, 0.0, 0.0))
    s.set_deformation("chainmail", resolution=4)
    np.testing.assert_array_equal(s.model.displacements(), 0.0)
    assert "grid changed" in s.family.switch_note


def test_switched_model_positions_survive_scene_json(session: EditSession, tmp_path: Path) -> None:
    s = session
    s.set_deformation("massspring", resolution=6)
    s.model.move((3, 3, 2), (6.0, 3.0, 0.0))
    s.model.step(20)
    s.set_deformation("chainmail")
    report = s.model.switch_report
    assert report is not None
    assert report.moved > 0
    x = s.model.positions()
    loaded = EditSession.load(s.save(tmp_path / "switched.json"))
    assert loaded.kind == "chainmail"
    np.testing.assert_allclose(loaded.model.positions(), x, atol=1e-9)
    np.testing.assert_array_equal(loaded.model.held, s.model.held)
