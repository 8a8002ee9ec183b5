"""Keyframing an editing session (voxwarp.editing.keyframes): Set Key stores the deformation and the
view at a frame; the saved scene animates between the keys."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from voxwarp.animation.tracks import AnimationError, load_animated_scene
from voxwarp.editing.families.lattice import LatticeFamily
from voxwarp.editing.families.wires import WiresFamily
from voxwarp.editing.keyframes import delete_keys, key_frames, set_key
from voxwarp.editing.session import EditSession
from voxwarp.io.samples import load_sample
from voxwarp.scene import Scene


@pytest.fixture
def session() -> EditSession:
    return EditSession(Scene(load_sample("fish", shape=(32, 32, 32)), jitter=False))


def test_lattice_keys_interpolate_the_nodes(session: EditSession, tmp_path: Path) -> None:
    session.set_deformation("lattice", resolution=3)
    rest = session.adapter(LatticeFamily).lattice_nodes.copy()
    anim = set_key(None, session, 0, frames=11, interpolation="linear")
    moved = rest.copy()
    moved[1, 1, 2] += (6.0, -3.0, 2.0)
    session.adapter(LatticeFamily).set_lattice_nodes(moved)
    anim = set_key(anim, session, 10)
    assert key_frames(anim) == [0, 10]
    session.animation = anim
    path = session.save(tmp_path / "bend.json")
    states = load_animated_scene(path)
    assert len(states) == 11
    nodes = [np.asarray(states.scene(i).warps[0].grid.nodes) for i in (0, 5, 10)]
    np.testing.assert_allclose(nodes[0], rest, atol=1e-6)
    np.testing.assert_allclose(nodes[1], 0.5 * (rest + moved), atol=1e-6)  # linear midpoint
    np.testing.assert_allclose(nodes[2], moved, atol=1e-6)


def test_wire_keys_and_the_camera(session: EditSession, tmp_path: Path) -> None:
    session.set_deformation("wires")
    cam0 = session.scene.resolved_camera()
    anim = set_key(None, session, 0, cam0, frames=9, interpolation="linear")
    w = session.adapter(WiresFamily).wires[0]
    pts = w.modified.control_points.copy()
    pts[2, 1] += 8.0
    session.adapter(WiresFamily).set_wire_points(0, pts)
    cam1 = session.scene.copy(camera=None, view=(-60, 20)).resolved_camera()
    anim = set_key(anim, session, 8, cam1)
    assert {t.target for t in anim.tracks} == {"camera", "wires[0].modified"}
    session.animation = anim
    path = session.save(tmp_path / "wire.json")
    states = load_animated_scene(path)
    mid = states.scene(4).warps[0].wires[0].modified.control_points
    np.testing.assert_allclose(mid[2], 0.5 * (pts[2] + w.modified.control_points[2]), atol=1e-5)
    np.testing.assert_allclose(states.scene(8).camera.rotation, cam1.rotation, atol=1e-6)


def test_element_drag_keys_hold_offsets(session: EditSession, tmp_path: Path) -> None:
    session.set_deformation("massspring", resolution=4)
    ms = session.model
    ms.move((2, 2, 2), (0.0, 0.0, 0.0))
    anim = set_key(None, session, 0, frames=7, interpolation="linear")
    ms.move((2, 2, 2), (4.0, 0.0, 0.0))
    ms.move((1, 2, 2), (2.0, 0.0, 0.0))  # a second element, held from this key on
    anim = set_key(anim, session, 6)
    (track,) = [t for t in anim.tracks if t.target == "elements.drag"]
    assert track.elements == [[2, 2, 2], [1, 2, 2]]
    assert track.keys[0][1][1] == [0.0, 0.0, 0.0]  # the earlier key holds the new one at rest
    session.animation = anim
    path = session.save(tmp_path / "drag.json")
    states = load_animated_scene(path)
    held = {tuple(h["index"]): h["offset"] for h in states.scene(3).warps[0].model_state["held"]}
    np.testing.assert_allclose(held[(2, 2, 2)], (2.0, 0.0, 0.0), atol=1e-9)
    np.testing.assert_allclose(held[(1, 2, 2)], (1.0, 0.0, 0.0), atol=1e-9)


def test_keys_replace_delete_undo_and_save(session: EditSession, tmp_path: Path) -> None:
    session.set_deformation("lattice", resolution=3)
    anim = set_key(None, session, 3, frames=10)
    anim = set_key(anim, session, 3)  # the same frame again: replaced, not added
    assert [len(t.keys) for t in anim.tracks] == [1]
    anim = set_key(anim, session, 7)
    assert key_frames(delete_keys(anim, 3)) == [7]
    assert delete_keys(delete_keys(anim, 3), 7).tracks == []
    with pytest.raises(AnimationError, match=r"frame must be 0\.\.9"):
        set_key(anim, session, 10)
    before = session.snapshot()
    session.animation = anim
    assert not session.snapshot().same_as(before)
    session.restore(before)
    assert session.animation is None
    session.animation = anim
    path = session.save(tmp_path / "keys.json")
    assert EditSession.load(path).animation.to_dict() == anim.to_dict()
