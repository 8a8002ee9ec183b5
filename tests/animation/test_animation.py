"""Tests of voxwarp.animation.tracks: interpolation, validation, evaluation into per-frame scenes.

Pure CPU (no GL context). Oracles: closed forms (the linear midpoint, smoothstep's
values and slopes, rotations about one axis), the key values themselves, the editor's
own models stepped here by hand, and the scene JSON read back by ``Scene.from_dict``.
"""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from voxwarp.animation.tracks import (
    TARGETS,
    Animation,
    AnimationError,
    Track,
    evaluate,
    interpolate,
    interpolate_camera,
    key_weights,
    load_animated_scene,
    save_animated_scene,
    slerp_rotation,
)
from voxwarp.core.camera import Camera, view_rotation
from voxwarp.core.volume import Volume
from voxwarp.deform.elements.chainmail import ChainMail
from voxwarp.deform.elements.massspring import MassSpring
from voxwarp.deform.warp import rotation_matrix
from voxwarp.editing.families.lattice import LatticeFamily
from voxwarp.editing.families.wires import WiresFamily
from voxwarp.editing.session import EditSession
from voxwarp.io.samples import load_sample
from voxwarp.scene import Scene

ROOT = Path(__file__).resolve().parents[2]
BUNDLED = sorted((ROOT / "sample_volumes").glob("*anim*.json"))


@pytest.fixture(scope="module")
def volume() -> Volume:
    """The fish phantom, small (box about 96 x 48 x 40 mm)."""
    return load_sample("fish", shape=(48, 24, 20))


def _rot_z(deg: float) -> np.ndarray:
    return rotation_matrix(np.array([0.0, 0.0, 1.0]), deg)


# ---------------------------------------------------------------------- interpolation
def test_linear_midpoint_is_exact_and_ends_clamp() -> None:
    keys = [(0.0, [0.0, 2.0]), (10.0, [10.0, -4.0])]
    assert interpolate(keys, 5.0).tolist() == [5.0, -1.0]
    assert interpolate(keys, 2.5).tolist() == [2.5, 0.5]
    assert interpolate(keys, -3.0).tolist() == [0.0, 2.0]
    assert interpolate(keys, 99.0).tolist() == [10.0, -4.0]


def test_interpolation_hits_every_key_exactly() -> None:
    keys = [(0.0, 1.25), (3.0, -7.5), (4.0, 2.0), (9.0, 0.1)]
    for mode in ("linear", "smooth"):
        for f, v in keys:
            assert float(interpolate(keys, f, mode)) == v


def test_smooth_is_smoothstep_with_zero_slope_at_the_keys() -> None:
    keys = [(0.0, 0.0), (10.0, 10.0), (20.0, 0.0)]
    for t in (0.1, 0.25, 0.5, 0.8):
        expected = 10.0 * (3 * t**2 - 2 * t**3)
        assert float(interpolate(keys, 10 * t, "smooth")) == pytest.approx(expected, abs=1e-12)
    eps = 1e-4
    for f in (0.0, 10.0, 20.0):  # the ends and the interior key: flat there
        left = float(interpolate(keys, max(f - eps, 0.0), "smooth"))
        right = float(interpolate(keys, min(f + eps, 20.0), "smooth"))
        centre = float(interpolate(keys, f, "smooth"))
        assert abs(right - centre) / eps < 1e-3
        assert abs(centre - left) / eps < 1e-3
    # while linear has slope 1 at the start
    assert float(interpolate(keys, eps, "linear")) / eps == pytest.approx(1.0)


def test_smooth_never_overshoots_its_two_keys() -> None:
    keys = [(0.0, 0.0), (1.0, 10.0), (2.0, 10.0), (3.0, -5.0)]
    f = np.linspace(0.0, 3.0, 301)
    v = np.array([float(interpolate(keys, x, "smooth")) for x in f])
    assert v.max() <= 10.0
    assert v.min() >= -5.0
    assert np.all(v[100:201] == 10.0)  # constant between equal keys
    assert np.all(np.diff(v[:101]) >= 0)  # monotone between keys


def test_key_weights_names_the_segment() -> None:
    assert key_weights([0, 4, 8], 6.0) == (1, 2, 0.5)
    assert key_weights([0, 4, 8], 4.0) == (1, 2, 0.0)  # on a key: that key, t = 0
    assert key_weights([0, 4, 8], 8.0) == (2, 2, 0.0)
    assert key_weights([0, 4, 8], 1.0, "smooth")[2] == pytest.approx(3 / 16 - 2 / 64)


def test_slerp_between_rotations_about_one_axis_turns_by_the_fraction() -> None:
    r0, r1 = _rot_z(10.0), _rot_z(100.0)
    for t in (0.0, 0.25, 0.5, 0.9, 1.0):
        r = slerp_rotation(r0, r1, t)
        np.testing.assert_allclose(r, _rot_z(10.0 + 90.0 * t), atol=1e-12)
        np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
        assert np.linalg.det(r) == pytest.approx(1.0)


def test_slerp_takes_the_shorter_way_round() -> None:
    r = slerp_rotation(_rot_z(170.0), _rot_z(-170.0), 0.5)  # -170 is +190 degrees
    np.testing.assert_allclose(r, _rot_z(180.0), atol=1e-12)


# Rotations of interpolate_camera as the hand-written quaternion slerp (Shepperd's method,
# normalised lerp within about 3.6 degrees) gave them before scipy's Slerp replaced it:
# pair -> (interpolation, frame) -> rotation, keys at frames 0 and 8.
_OLD_SLERP_ROTATIONS: dict[tuple[str, str, float], list[list[float]]] = {
    ("ab", "linear", 2.0): [
        [0.8626328917221622, -0.19824469112003476, 0.4653638754370416],
        [0.4839186419449515, 0.055591375663923914, -0.8733454911602548],
        [0.14726588911629956, 0.9785748011238155, 0.14388925084338722],
    ],
    ("ab", "linear", 5.0): [
        [0.24634457993612136, -0.46739454391946067, 0.8490327957449084],
        [0.9508322768726778, -0.05310987824378066, -0.3051185377686032],
        [0.18770276820871756, 0.8824520843350365, 0.4313304877463847],
    ],
    ("ab", "smooth", 2.0): [
        [0.9455352215628542, -0.12137985884674354, 0.3020431668659777],
        [0.3093999588919283, 0.046739171016886405, -0.9497826674194088],
        [0.10116723887582053, 0.9915051082868906, 0.0817484557606063],
    ],
    ("ab", "smooth", 5.0): [
        [0.12589170304933162, -0.49632055427559535, 0.8589628551380464],
        [0.9770324247452205, -0.08802651625403524, -0.19405920084513661],
        [0.1719270778551591, 0.8636650044083897, 0.4738394665500567],
    ],
    ("cd", "linear", 2.0): [
        [-0.9961946980917458, -0.08715574274765812, 0.0],
        [0.08715574274765812, -0.9961946980917458, 0.0],
        [0.0, 0.0, 1.0],
    ],
    ("cd", "linear", 5.0): [
        [-0.9990482215818579, 0.04361938736533597, 0.0],
        [-0.04361938736533597, -0.9990482215818579, 0.0],
        [0.0, 0.0, 1.0],
    ],
    ("cd", "smooth", 2.0): [
        [-0.9928096670090554, -0.11970365530496249, 0.0],
        [0.11970365530496249, -0.9928096670090554, 0.0],
        [0.0, 0.0, 1.0],
    ],
    ("cd", "smooth", 5.0): [
        [-0.9979471752662019, 0.06404244981423471, 0.0],
        [-0.06404244981423471, -0.9979471752662019, 0.0],
        [0.0, 0.0, 1.0],
    ],
    ("eg", "linear", 2.0): [
        [0.9411956583315785, -0.27174363235455823, 0.20076386879251265],
        [0.28983727594484177, 0.9547658910242911, -0.0664563526644747],
        [-0.17362340340708735, 0.1207372834353253, 0.9773829455121456],
    ],
    ("eg", "linear", 5.0): [
        [0.9368644151002364, -0.2808838313744322, 0.20830108254954263],
        [0.30031016518974407, 0.9514341654617203, -0.06772616537106159],
        [-0.17916158182657485, 0.12600516681699717, 0.9757170827308602],
    ],
    ("eg", "smooth", 2.0): [
        [0.9422551871183703, -0.2694474720193789, 0.19887991897346247],
        [0.2872151067521881, 0.9555809131679771, -0.06612564436271409],
        [-0.17222846687424875, 0.11942854856114152, 0.9777904565839886],
    ],
    ("eg", "smooth", 5.0): [
        [0.9361742452197728, -0.28230546452435246, 0.20947889460964406],
        [0.3019441583028839, 0.9509032655536713, -0.06791689647007554],
        [-0.1800208539418469, 0.12683297780566993, 0.9754516327768357],
    ],
}


def _camera_pairs() -> dict[str, tuple[Camera, Camera]]:
    axis = np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0)
    z = np.array([0.0, 0.0, 1.0])
    return {
        "ab": (
            Camera(center=[0, 0, 0], rotation=view_rotation("-y"), distance=100.0, fov=30.0),
            Camera(
                center=[10, -20, 4], rotation=view_rotation((30.0, 40.0)), distance=60.0, fov=40.0
            ),
        ),
        # across +-180 degrees: the shorter way round
        "cd": (
            Camera(center=[0, 0, 0], rotation=rotation_matrix(z, 170.0), distance=50.0),
            Camera(center=[0, 0, 0], rotation=rotation_matrix(z, -170.0), distance=50.0),
        ),
        # two degrees apart: the old code's normalised-lerp branch
        "eg": (
            Camera(center=[0, 0, 0], rotation=rotation_matrix(axis, 20.0), distance=50.0),
            Camera(center=[0, 0, 0], rotation=rotation_matrix(axis, 22.0), distance=50.0),
        ),
    }


@pytest.mark.parametrize("key", sorted(_OLD_SLERP_ROTATIONS))
def test_camera_rotations_match_the_old_quaternion_slerp(key: tuple[str, str, float]) -> None:
    pair, mode, frame = key
    a, b = _camera_pairs()[pair]
    r = interpolate_camera([(0.0, a), (8.0, b)], frame, mode).rotation
    # the old code blended keys closer than about 3.6 degrees by normalised lerp (an
    # approximation of slerp, 1.3e-7 off at 2 degrees); elsewhere it was exact slerp
    atol = 2e-7 if pair == "eg" else 1e-12
    np.testing.assert_allclose(r, _OLD_SLERP_ROTATIONS[key], atol=atol, rtol=0.0)


def test_camera_interpolation_hits_its_keys_and_stays_a_rotation() -> None:
    a = Camera(center=[0, 0, 0], rotation=view_rotation("-y"), distance=100.0, fov=30.0)
    b = Camera(center=[10, -20, 4], rotation=view_rotation((30.0, 40.0)), distance=60.0, fov=40.0)
    keys = [(0.0, a), (8.0, b)]
    for mode in ("linear", "smooth"):
        c0, c1 = interpolate_camera(keys, 0.0, mode), interpolate_camera(keys, 8.0, mode)
        assert c0.to_dict() == a.to_dict()
        assert c1.to_dict() == b.to_dict()
        for f in np.linspace(0.0, 8.0, 17):
            r = interpolate_camera(keys, f, mode).rotation
            np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
            assert np.linalg.det(r) == pytest.approx(1.0)
    mid = interpolate_camera(keys, 4.0)
    np.testing.assert_allclose(mid.center, [5, -10, 2])
    assert mid.distance == 80.0
    assert mid.fov == 35.0
    # the mid rotation is half the way: equal angles to both keys
    angle = lambda r, s: math.degrees(math.acos((np.trace(r.T @ s) - 1) / 2))  # noqa: E731
    assert angle(mid.rotation, a.rotation) == pytest.approx(angle(mid.rotation, b.rotation))


# ---------------------------------------------------------------------- validation
def _anim(**track: Any) -> dict[str, Any]:
    return {"frames": 10, "fps": 12, "tracks": [track]}


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        ([], "'animation' must be an object"),
        ({"tracks": []}, "animation needs 'frames'"),
        ({"frames": 0}, "'frames' must be an integer 1..100000"),
        ({"frames": 2.5}, "'frames' must be an integer"),
        ({"frames": 3, "fps": -1}, "'fps' must be in (0, 1000]"),
        ({"frames": 3, "fps": "fast"}, "'fps' must be a number"),
        ({"frames": 3, "colour": 1}, "unknown keys ['colour']"),
        ({"frames": 3, "tracks": {}}, "'tracks' must be a list"),
        ({"frames": 3, "steps_per_frame": -2}, "'steps_per_frame' must be an integer 0..10000"),
        (_anim(target="wobble", keys=[[0, 1]]), "unknown animation target 'wobble'; targets:"),
        (_anim(target="wires[x].twist", keys=[[0, 1]]), "unknown animation target"),
        (_anim(keys=[[0, 1]]), "needs a 'target'"),
        (_anim(target="step", keys=[]), "needs 'keys'"),
        (_anim(target="step", keys=[[0, 1], [0, 2]]), "must increase strictly"),
        (_anim(target="step", keys=[[5, 1], [2, 2]]), "must increase strictly"),
        (_anim(target="step", keys=[[10, 1]]), "outside the animation's frames 0..9"),
        (_anim(target="step", keys=[[-1, 1]]), "outside the animation's frames"),
        (_anim(target="step", keys=[[0]]), "must be [frame, value]"),
        (_anim(target="step", keys=[["a", 1]]), "frame must be a number"),
        (_anim(target="step", keys=[[0, "x"]]), "must be a number"),
        (_anim(target="step", keys=[[0, 1]], interpolation="cubic"), "linear, smooth"),
        (_anim(target="window", keys=[[0, [1, 2, 3]]]), "must have shape 2"),
        (_anim(target="clip_box", keys=[[0, [1, 2, 3]]]), "must have shape 2x3"),
        (_anim(target="background", keys=[[0, [1, 2]]]), "must have shape 4"),
        (_anim(target="wires[0].modified", keys=[[0, [[1, 2]]]]), "must have shape Nx3"),
        (_anim(target="wires[0].twist", keys=[[0, [1, 2, 3]]]), "must have shape Nx2"),
        (_anim(target="lattice.nodes", keys=[[0, "bent"]]), "must be numbers"),
        (_anim(target="camera", keys=[[0, [1, 2]]]), "must be a camera object"),
        (_anim(target="elements.drag", keys=[[0, [0, 0, 1]]]), "needs 'elements'"),
        (
            _anim(target="elements.drag", elements=[[1, 2]], keys=[[0, [0, 0, 1]]]),
            "integer [i, j, k] indices",
        ),
        (
            _anim(target="elements.drag", elements=[[1, 1, 1]], keys=[[0, [0, 1]]]),
            "offset must be [dx, dy, dz]",
        ),
        (_anim(target="step", elements=[[1, 1, 1]], keys=[[0, 1]]), "elements.drag tracks only"),
        (_anim(target="step", keys=[[0, 1]], speed=2), "unknown keys ['speed']"),
        (
            {"frames": 3, "tracks": [{"target": "step", "keys": [[0, 1]]}] * 2},
            "more than one track keys step",
        ),
    ],
)
def test_bad_animation_entries_name_the_problem(entry: Any, message: str) -> None:
    with pytest.raises(AnimationError) as err:
        Animation.from_dict(entry)
    assert message in str(err.value)


def test_unknown_target_error_lists_every_target() -> None:
    with pytest.raises(AnimationError) as err:
        Animation.from_dict(_anim(target="colour", keys=[[0, 1]]))
    for target in TARGETS:
        assert target in str(err.value)


def test_round_trip_of_the_json_form() -> None:
    d = {
        "frames": 12,
        "fps": 12.5,
        "steps_per_frame": 3,
        "tracks": [
            {"target": "step", "interpolation": "smooth", "keys": [[0, 1.0], [11, 0.5]]},
            {
                "target": "elements.drag",
                "interpolation": "linear",
                "elements": [[1, 1, 1]],
                "keys": [[0, [0, 0, 0]], [4.5, [0, 0, 3]], [6, None]],
            },
        ],
    }
    a = Animation.from_dict(d)
    assert a.to_dict() == d
    assert Animation.from_dict(json.loads(json.dumps(a.to_dict()))) == a


def test_a_scene_without_an_animation_entry_is_refused(volume: Volume) -> None:
    with pytest.raises(AnimationError, match="no 'animation' entry"):
        evaluate(Scene(volume).to_dict())


# ---------------------------------------------------------------------- evaluation
def _scene_with(volume: Volume, tracks: list[dict[str, Any]], frames: int = 5, **kw: Any) -> dict:
    d = Scene(volume, **kw).to_dict()
    d["animation"] = {"frames": frames, "tracks": tracks}
    return d


def test_scalar_tracks_and_the_held_fitted_camera(volume: Volume) -> None:
    d = _scene_with(
        volume,
        [
            {"target": "step", "keys": [[0, 1.0], [4, 0.5]]},
            {"target": "window", "keys": [[0, [0, 100]], [4, [100, 300]]]},
            {"target": "background", "keys": [[0, [0, 0, 0]], [4, [1, 0.5, 0]]]},
            {"target": "zoom", "keys": [[0, 1.0], [4, 2.0]]},
        ],
    )
    states = evaluate(d)
    assert len(states) == 5
    assert [s["step"] for s in states.scenes] == [1.0, 0.875, 0.75, 0.625, 0.5]
    assert states.scenes[2]["window"] == [50.0, 200.0]
    assert states.scenes[4]["background"] == [1.0, 0.5, 0.0, 1.0]  # alpha 1 added
    base = Scene.from_dict(d)
    for i, z in enumerate([1.0, 1.25, 1.5, 1.75, 2.0]):
        expected = base.copy(zoom=z).resolved_camera()
        assert states.scenes[i]["camera"] == expected.to_dict()
    scene = states.scene(2)  # a frame is complete scene JSON
    assert scene.step == 0.75
    assert scene.camera is not None


def test_view_keys_fit_the_camera_and_slerp_between_them(volume: Volume) -> None:
    d = _scene_with(
        volume,
        [{"target": "camera", "keys": [[0, {"view": "-y"}], [4, {"view": [-60, 30], "zoom": 2}]]}],
    )
    states = evaluate(d)
    base = Scene.from_dict(d)
    first = base.copy(view="-y").resolved_camera()
    last = base.copy(view=(-60.0, 30.0), zoom=2.0).resolved_camera()
    assert states.scenes[0]["camera"] == first.to_dict()
    assert states.scenes[4]["camera"] == last.to_dict()
    mid = Camera.from_dict(states.scenes[2]["camera"])
    assert mid.distance == pytest.approx(0.5 * (first.distance + last.distance))


def test_transfer_function_keys_blend_point_by_point(volume: Volume) -> None:
    a = [[0, 0, 0, 0, 0], [100, 1, 0, 0, 0.5]]
    b = [[50, 0, 1, 0, 0], [300, 0, 0, 1, 1.0]]
    states = evaluate(
        _scene_with(volume, [{"target": "transfer_function", "keys": [[0, a], [4, b]]}])
    )
    assert states.scenes[2]["transfer_function"]["points"] == [
        [25.0, 0.0, 0.5, 0.0, 0.0],
        [200.0, 0.5, 0.0, 0.5, 0.75],
    ]
    with pytest.raises(AnimationError, match="same number of control"):
        evaluate(
            _scene_with(volume, [{"target": "transfer_function", "keys": [[0, a], [4, "hot"]]}])
        )


def test_frames_option_scales_the_keys(volume: Volume) -> None:
    d = _scene_with(volume, [{"target": "step", "keys": [[0, 1.0], [4, 2.0]]}])
    states = evaluate(d, frames=9)
    assert [s["step"] for s in states.scenes] == [1 + i / 8 for i in range(9)]
    assert [s["step"] for s in evaluate(d, frames=1).scenes] == [1.0]


@pytest.mark.parametrize(
    ("tracks", "kw", "message"),
    [
        (
            [{"target": "wires[0].twist", "keys": [[0, 1.0]]}],
            {},
            "needs a scene with exactly one wires warp; this scene has 0",
        ),
        (
            [{"target": "lattice.nodes", "keys": [[0, "rest"]]}],
            {},
            "exactly one lattice warp",
        ),
        (
            [{"target": "elements.drag", "elements": [[1, 1, 1]], "keys": [[0, [0, 0, 1]]]}],
            {},
            "exactly one mass-spring or ChainMail model",
        ),
        (
            [{"target": "zoom", "keys": [[0, 1.0]]}],
            {"camera": Camera()},
            "zoom and fov tracks refit the camera",
        ),
        (
            [{"target": "camera", "keys": [[0, {"view": "-y", "roll": 3}]]}],
            {},
            "a view key takes view, zoom, fov and projection",
        ),
        (
            [{"target": "camera", "keys": [[0, {"distance": -4}]]}],
            {},
            "distance must be positive",
        ),
        (
            [
                {
                    "target": "camera",
                    "keys": [
                        [0, {"view": "-y"}],
                        [4, {"view": "+x", "projection": "orthographic"}],
                    ],
                }
            ],
            {},
            "same projection",
        ),
        ([{"target": "step", "keys": [[0, 500.0]]}], {}, "frame 0: step must be between"),
    ],
)
def test_tracks_that_do_not_fit_the_scene_are_refused(
    volume: Volume, tracks: list, kw: dict, message: str
) -> None:
    with pytest.raises(AnimationError) as err:
        evaluate(_scene_with(volume, tracks, **kw))
    assert message in str(err.value)


# ---------------------------------------------------------------------- the editor's files
def test_an_editor_lattice_file_with_an_animation_evaluates(volume: Volume, tmp_path: Path) -> None:
    session = EditSession(Scene(volume))
    session.set_deformation("lattice", resolution=3)
    rest = session.adapter(LatticeFamily).lattice_nodes.copy()
    bent = rest.copy()
    bent[-1, :, :, 2] += 8.0
    anim = Animation(5, 10.0, [Track("lattice.nodes", [(0, "rest"), (4, bent.tolist())])])
    path = save_animated_scene(tmp_path / "lat.json", session, anim)
    raw = json.loads(path.read_text())
    assert "editor" in raw
    assert raw["animation"]["frames"] == 5
    Scene.load(path)  # still an ordinary scene file
    states = load_animated_scene(path)
    nodes = [np.asarray(s["warps"][0]["grid"]["nodes"]) for s in states.scenes]
    np.testing.assert_allclose(nodes[0], rest, atol=1e-12)
    np.testing.assert_allclose(nodes[2], 0.5 * (rest + bent), atol=1e-12)
    np.testing.assert_allclose(nodes[4], bent, atol=1e-12)
    assert states.scene(4).warps[0].kind == "lattice"


def test_wire_tracks_change_only_their_wire_field(volume: Volume, tmp_path: Path) -> None:
    session = EditSession(Scene(volume))
    session.set_deformation("wires")
    base = np.asarray(session.adapter(WiresFamily).wires[0].base.control_points)
    moved = base.copy()
    moved[-1, 2] += 6.0
    anim = Animation(
        3,
        tracks=[
            Track("wires[0].modified", [(0, base.tolist()), (2, moved.tolist())]),
            Track("wires[0].twist", [(0, 0.0), (2, 1.0)], "smooth"),
        ],
    )
    states = load_animated_scene(save_animated_scene(tmp_path / "w.json", session, anim))
    wires = [s["warps"][0]["wires"][0] for s in states.scenes]
    np.testing.assert_allclose(wires[1]["modified"], 0.5 * (base + moved))
    assert wires[1]["twist"] == [[0.0, 0.5]]
    assert wires[2]["twist"] == [[0.0, 1.0]]
    assert wires[0]["base"] == wires[2]["base"] == base.tolist()
    bad = Animation(3, tracks=[Track("wires[3].scale", [(0, 2.0)])])
    bad_file = save_animated_scene(tmp_path / "bad.json", session, bad)
    with pytest.raises(AnimationError, match="no wire 3; the scene's wire warp has 1"):
        load_animated_scene(bad_file)
    keys = [(0, base.tolist()), (2, [[0, 0, 0]] * 7)]
    bad = Animation(3, tracks=[Track("wires[0].modified", keys)])
    bad_file = save_animated_scene(tmp_path / "bad.json", session, bad)
    with pytest.raises(AnimationError, match="same shape"):
        load_animated_scene(bad_file)


@pytest.mark.parametrize("kind", ["massspring", "chainmail"])
def test_element_drags_step_the_model_frame_by_frame(
    volume: Volume, tmp_path: Path, kind: str
) -> None:
    session = EditSession(Scene(volume))
    session.set_deformation(kind, resolution=5, anchor="corners")
    session.set_option("steps_per_frame", 7)
    session.set_option("relax_steps", 2)
    path = tmp_path / "m.json"
    session.save(path)
    raw = json.loads(path.read_text())
    keys = [(0, [0.0, 0.0, 0.0]), (3, [0.0, 0.0, 6.0]), (4, None)]
    anim = Animation(6, tracks=[Track("elements.drag", keys, "smooth", elements=[[2, 2, 2]])])
    raw["animation"] = anim.to_dict()
    states = evaluate(raw)
    # the oracle: the same model stepped here by hand with the editor's per-frame physics
    warp = Scene.from_dict(raw).warps[0]
    model = (MassSpring if kind == "massspring" else ChainMail).from_warp(warp)
    if isinstance(model, ChainMail):
        model.relax_steps = 0
    for i, s in enumerate(states.scenes):
        if i < 4:
            t = i / 3
            model.move([[2, 2, 2]], [0.0, 0.0, 6.0 * (3 * t * t - 2 * t**3)])
        else:
            model.release([[2, 2, 2]])
        if isinstance(model, MassSpring):
            model.step(7)
        else:
            model.relax(2)
        np.testing.assert_array_equal(
            np.asarray(s["warps"][0]["displacements"]), model.displacements().astype(np.float64)
        )
    model.close()
    held = [s["warps"][0]["model"]["held"] for s in states.scenes]
    assert held[3] == [{"index": [2, 2, 2], "offset": [0.0, 0.0, 6.0]}]
    assert held[4] == []
    assert states.scenes[0] != states.scenes[3]
    assert evaluate(raw).scenes == states.scenes  # deterministic: same plan, same frames


def test_drag_of_an_element_outside_the_grid_is_refused(volume: Volume) -> None:
    session = EditSession(Scene(volume))
    session.set_deformation("chainmail", resolution=4)
    d = session.to_dict()
    d["animation"] = _anim(target="elements.drag", elements=[[9, 0, 0]], keys=[[0, [0, 0, 1]]])
    with pytest.raises(AnimationError, match=r"outside the grid of shape \(4, 4, 4\)"):
        evaluate(d)


# ---------------------------------------------------------------------- bundled scenes
def test_the_bundled_animated_scenes_are_small_and_cover_every_family() -> None:
    names = {p.name for p in BUNDLED}
    assert {
        "fish_swim_anim.json",
        "fish_chainmail_poke_anim.json",
        "fish_lattice_bend_anim.json",
        "fish_massspring_jiggle_anim.json",
    } <= names
    for p in BUNDLED:
        assert p.stat().st_size < 300_000, p.name
        volume = json.loads(p.read_text())["volume"]
        assert volume.get("sample") == "fish" or p.name.startswith("lattice_"), p.name


@pytest.mark.parametrize("path", BUNDLED, ids=lambda p: p.stem)
def test_bundled_animated_scenes_load_and_evaluate(path: Path) -> None:
    states = load_animated_scene(path)
    assert len(states) == states.animation.frames >= 24
    first, last = states.scenes[0], states.scenes[-1]
    assert first != last or "meshes" in first  # a mesh sway may loop back to its start
    middle = copy.deepcopy(states.scenes[len(states) // 2])
    moved = (middle["warps"], middle.get("meshes")) != (first["warps"], first.get("meshes"))
    assert moved  # the deformation moves
    Scene.from_dict(middle, base_dir=states.base_dir)  # every frame is valid scene JSON
