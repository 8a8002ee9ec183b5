"""Fuzz the JSON inputs: scene JSON (``Scene.load`` and ``load_input``), wire files,
lattice files, camera JSON (``render --camera``), transfer function JSON and animated
scenes (``voxwarp animate``'s reader).

Each case starts from a valid document (a tiny embedded volume, a wire and a lattice
laid through it, a two-key animation) and breaks it: keys dropped, added or replaced by
wrong types, NaN, huge or negative numbers, deep nesting; or the text itself truncated
or damaged. The reader must accept it or raise a one-line VoxwarpError (the camera
option: a one-line argparse error) within the per-case time limit. Sizes and counts the
generator can state stay small (memory bombs are tests/app's business).
"""

from __future__ import annotations

import argparse
import copy
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.fuzz._mutate import bad_value, edited_dict, json_text, json_value, mutated_bytes
from tests.fuzz._support import fuzz_settings, outcome

BOX = ((-0.5, -0.5, -0.5), (7.5, 5.5, 4.5))  # world box of the (8, 6, 5) volume, 1 mm
WIRE = {
    "kind": "catmull-rom",
    "base": [[0.5, 2.5, 2.0], [3.5, 2.5, 2.0], [6.5, 2.5, 2.0]],
    "modified": [[0.5, 2.5, 2.0], [3.5, 3.0, 2.0], [6.5, 3.5, 2.0]],
    "radius": 2.0,
}
WIRE_FILE = {"wires": [WIRE], "field_scale": 2, "description": "fuzz"}
LATTICE_FILE = {
    "grid": {
        "nodes": [
            [[[x, y, z] for z in (BOX[0][2], BOX[1][2])] for y in (BOX[0][1], BOX[1][1])]
            for x in (BOX[0][0], BOX[1][0])
        ]
    },
    "inverse": "newton",
    "iterations": 4,
}
CAMERA = {
    "center": [3.5, 2.5, 2.0],
    "rotation": np.eye(3).tolist(),
    "distance": 30.0,
    "fov": 30.0,
    "projection": "perspective",
    "ortho_height": 10.0,
    "radius": 6.0,
}


def _scene() -> dict[str, Any]:
    from voxwarp.core.volume import Volume
    from voxwarp.scene import Scene

    vol = Volume(np.arange(8 * 6 * 5, dtype=np.uint8).reshape(8, 6, 5))
    return Scene(vol).to_dict()


SCENE = _scene()


def _write(tmp: str, name: str, text: str, damage: bytes | None) -> Path:
    path = Path(tmp) / name
    path.write_bytes(damage if damage is not None else text.encode("utf-8"))
    return path


def documents(base: dict[str, Any], values: dict[str, st.SearchStrategy] | None = None) -> Any:
    """Edited copies of ``base`` (mostly), sometimes a bad JSON value instead."""
    return st.one_of(
        edited_dict(base, values),
        edited_dict(base, values),
        edited_dict(base, values),
        bad_value,
    )


@st.composite
def text_and_damage(draw: st.DrawFn, doc: Any) -> tuple[str, bytes | None]:
    """The document's JSON text and, a quarter of the time, damaged bytes of it."""
    text = json_text(doc)
    if draw(st.integers(0, 3)) == 0:
        return text, draw(mutated_bytes(text.encode("utf-8"), keep=0.0))
    return text, None


# ---------------------------------------------------------------------------- scene JSON
def _volume_entries() -> st.SearchStrategy:
    vol = SCENE["volume"]
    emb = vol["embedded"]
    return st.one_of(
        edited_dict(vol),
        edited_dict(vol, {"embedded": edited_dict(emb)}).map(lambda d: d),
        st.fixed_dictionaries(
            {"sample": st.sampled_from(["fish", "tubes", "nope", "head", ""])},
            optional={
                "shape": st.one_of(
                    st.lists(st.integers(-2, 12), max_size=4), st.just([8, 8, 8]), bad_value
                ),
                "spacing": bad_value,
            },
        ),
        st.fixed_dictionaries(
            {"path": st.sampled_from(["missing.npy", ".", "", "scene.json", "/", "v.raw"])}
        ),
    )


SCENE_VALUES: dict[str, st.SearchStrategy] = {
    "volume": _volume_entries(),
    "warps": st.one_of(
        st.lists(
            st.one_of(
                st.just({"type": "wires", **WIRE_FILE}).flatmap(edited_dict),
                st.just({"type": "lattice", **LATTICE_FILE, "box": BOX}).flatmap(edited_dict),
                st.fixed_dictionaries({"type": st.sampled_from(["offset_field", "zzz", ""])}),
                json_value,
            ),
            max_size=2,
        ),
        bad_value,
    ),
    "mode": st.sampled_from(["dvr", "mip", "iso", "flm", "xray", "DVR", "", "nope"]),
    "view": st.one_of(st.sampled_from(["+x", "anterior", "up", ""]), bad_value),
    "step": st.one_of(st.sampled_from([0, -1, "1", 1e-9, 1e9, 0.5]), bad_value),
    "format": st.sampled_from(["voxwarp-scene", "voxwarp", "", None]),
    "version": st.sampled_from([0, 1, 2, "1", 99, None]),
    "camera": st.one_of(st.just(CAMERA).flatmap(edited_dict), bad_value),
}


@fuzz_settings(120)
@given(doc=documents(SCENE, SCENE_VALUES), data=st.data(), via=st.sampled_from(["load", "input"]))
def test_scene_json(doc, data, via) -> None:
    """Scene JSON: every key of a valid scene replaced, dropped or added; broken text."""
    from voxwarp.inputs import load_input
    from voxwarp.scene import Scene

    text, damage = data.draw(text_and_damage(doc))
    with tempfile.TemporaryDirectory() as tmp:
        path = _write(tmp, "scene.json", text, damage)
        Path(tmp, "v.raw").write_bytes(bytes(8))
        if via == "load":
            outcome("scene JSON", lambda: Scene.load(path))
        else:
            outcome("scene JSON", lambda: load_input(str(path)))


# ---------------------------------------------------------------------------- wires
WIRE_VALUES: dict[str, st.SearchStrategy] = {
    "wires": st.one_of(
        st.lists(
            st.one_of(
                edited_dict(
                    WIRE,
                    {
                        "radius": st.one_of(st.sampled_from([0, -1, 1e-9, 50.0]), bad_value),
                        "base": st.lists(
                            st.lists(st.floats(-2, 9), min_size=3, max_size=3), max_size=5
                        ),
                        "kind": st.sampled_from(["catmull-rom", "polyline", "bezier", "", "x"]),
                    },
                ),
                st.just(WIRE),
                json_value,
            ),
            max_size=3,
        ),
        bad_value,
    ),
    "field_scale": st.one_of(st.sampled_from([0, 1, 2, 3, 4, -1, 2.5, "2"]), bad_value),
}


@fuzz_settings(50)
@given(doc=documents(WIRE_FILE, WIRE_VALUES), data=st.data())
def test_wire_file(doc, data) -> None:
    """Wire files (``--wires``): read, then built into the warp on a tiny volume."""
    from voxwarp.core.volume import Volume
    from voxwarp.deform.warp import warp_from_dict
    from voxwarp.errors import InputError
    from voxwarp.inputs import load_wire_file

    text, damage = data.draw(text_and_damage(doc))
    vol = Volume(np.zeros((8, 6, 5), np.uint8))

    def load() -> None:
        entry = load_wire_file(path)
        try:
            warp = warp_from_dict(entry)
        except Exception as exc:  # only a VoxwarpError may escape: see below
            from voxwarp.errors import VoxwarpError

            if isinstance(exc, VoxwarpError):
                raise InputError(f"--wires {path}: {exc}") from exc
            raise
        warp.bind_volume(vol)

    with tempfile.TemporaryDirectory() as tmp:
        path = _write(tmp, "wires.json", text, damage)
        outcome("wire file", load)


# ---------------------------------------------------------------------------- lattice
LATTICE_VALUES: dict[str, st.SearchStrategy] = {
    "grid": st.one_of(
        edited_dict(
            LATTICE_FILE["grid"],
            {
                "nodes": st.one_of(
                    hnp_nodes := st.lists(
                        st.lists(
                            st.lists(
                                st.lists(st.floats(-3, 10), min_size=3, max_size=3),
                                min_size=1,
                                max_size=3,
                            ),
                            min_size=1,
                            max_size=3,
                        ),
                        min_size=1,
                        max_size=3,
                    ),
                    bad_value,
                )
            },
        ),
        bad_value,
    ),
    "inverse": st.sampled_from(["newton", "baked", "fixed-point", "", 3]),
    "iterations": st.one_of(st.sampled_from([0, 1, 4, 64, -1, 1.5, "4"]), bad_value),
    "box": st.one_of(st.just([list(BOX[0]), list(BOX[1])]), bad_value),
}


@fuzz_settings(100)
@given(doc=documents(LATTICE_FILE, LATTICE_VALUES), data=st.data())
def test_lattice_file(doc, data) -> None:
    """Lattice files (``--lattice``): folded, degenerate, ragged or mistyped grids."""
    from voxwarp.core.volume import Volume
    from voxwarp.inputs import load_lattice_file

    text, damage = data.draw(text_and_damage(doc))
    vol = Volume(np.zeros((8, 6, 5), np.uint8))
    with tempfile.TemporaryDirectory() as tmp:
        path = _write(tmp, "lattice.json", text, damage)
        outcome("lattice file", lambda: load_lattice_file(path, vol))


# ---------------------------------------------------------------------------- camera
CAMERA_VALUES: dict[str, st.SearchStrategy] = {
    "rotation": st.one_of(
        st.lists(st.lists(st.floats(-2, 2), min_size=3, max_size=3), min_size=3, max_size=3),
        bad_value,
    ),
    "projection": st.sampled_from(["perspective", "orthographic", "fisheye", ""]),
    "fov": st.one_of(st.sampled_from([0, 179, 1e-9, 178.9, -30]), bad_value),
}


@fuzz_settings(100)
@given(
    doc=documents(CAMERA, CAMERA_VALUES),
    in_scene=st.booleans(),
    data=st.data(),
)
def test_camera_json(doc, in_scene, data) -> None:
    """``render --camera FILE``: a camera JSON, or a scene JSON's ``camera``, broken."""
    from voxwarp.cli.render_options import camera_arg

    if in_scene:
        doc = {**copy.deepcopy(SCENE), "camera": doc}
    text, damage = data.draw(text_and_damage(doc))

    with tempfile.TemporaryDirectory() as tmp:
        path = _write(tmp, "camera.json", text, damage)
        outcome("camera JSON", lambda: camera_arg(str(path)), also=(argparse.ArgumentTypeError,))


# ---------------------------------------------------------------------------- TF
TF = {"name": "ramp", "points": [[0, 0, 0, 0, 0], [100, 1, 1, 1, 0.5], [255, 1, 1, 1, 1]]}


@fuzz_settings(80)
@given(
    doc=st.one_of(
        documents(
            TF,
            {
                "points": st.one_of(
                    st.lists(st.lists(st.floats(-1e3, 1e3), max_size=6), max_size=5), bad_value
                )
            },
        ),
        st.fixed_dictionaries(
            {"preset": st.one_of(st.sampled_from(["ct-bone", "mri", ""]), json_value)}
        ),
    ),
    data=st.data(),
)
def test_transfer_function_json(doc, data) -> None:
    """``render --tf FILE.json``: control points of every wrong shape and value."""
    from voxwarp.core.transfer_function import TransferFunction

    text, damage = data.draw(text_and_damage(doc))
    with tempfile.TemporaryDirectory() as tmp:
        path = _write(tmp, "tf.json", text, damage)
        outcome("transfer function JSON", lambda: TransferFunction.load(str(path)))


# ---------------------------------------------------------------------------- animation
ANIMATION = {
    "frames": 3,
    "fps": 24,
    "tracks": [
        {
            "target": "camera",
            "interpolation": "smooth",
            "keys": [[0, {"view": [0.0, 10.0], "zoom": 1.0}], [2, {"view": [30.0, 10.0]}]],
        },
        {
            "target": "wires[0].modified",
            "interpolation": "linear",
            "keys": [[0, WIRE["base"]], [2, WIRE["modified"]]],
        },
    ],
}
TRACK_VALUES: dict[str, st.SearchStrategy] = {
    "target": st.sampled_from(
        [
            "camera",
            "wires[0].modified",
            "wires[5].modified",
            "wires[-1].radius",
            "lattice.nodes",
            "elements.drag",
            "mode",
            "",
            "wires[x]",
        ]
    ),
    "interpolation": st.sampled_from(["smooth", "linear", "step", "cubic", ""]),
    "keys": st.one_of(
        st.lists(st.tuples(st.integers(-3, 5), json_value).map(list), max_size=4), bad_value
    ),
}


@fuzz_settings(60)
@given(
    anim=documents(
        ANIMATION,
        {
            # small counts only: large valid ones are the bounds tests' business
            "frames": st.one_of(st.sampled_from([0, 1, 2, 5, -1, 2.5, "3", None]), json_value),
            "fps": st.one_of(st.sampled_from([0, -24, 1e9, "24"]), bad_value),
            "tracks": st.one_of(
                st.lists(
                    st.one_of(
                        *(
                            st.just(t).flatmap(lambda t: edited_dict(t, TRACK_VALUES))
                            for t in ANIMATION["tracks"]
                        ),
                        json_value,
                    ),
                    max_size=3,
                ),
                bad_value,
            ),
            "relax_steps": st.sampled_from([0, 1, 2, -1, "2", None]),
            "steps_per_frame": st.sampled_from([0, 1, 2, -1, 1.5, None]),
        },
    ),
    data=st.data(),
)
def test_animation_json(anim, data) -> None:
    """Animated scenes (``voxwarp animate``): tracks, keys, targets and counts broken;
    read and evaluated into per-frame scenes as ``animate`` does before rendering."""
    from voxwarp.animation.tracks import load_animated_scene

    scene = {**copy.deepcopy(SCENE), "warps": [{"type": "wires", **WIRE_FILE}]}
    scene["warps"][0].pop("description")
    scene["animation"] = anim
    text, damage = data.draw(text_and_damage(scene))
    with tempfile.TemporaryDirectory() as tmp:
        path = _write(tmp, "anim.json", text, damage)
        outcome("animation JSON", lambda: load_animated_scene(path))


@pytest.mark.parametrize("name", ["scene", "wires", "lattice", "camera", "animation"])
def test_valid_bases_load(name: str, tmp_path: Path) -> None:
    """The fuzz starts from documents that load: the mutations, not the bases, fail."""
    from voxwarp.animation.tracks import load_animated_scene
    from voxwarp.cli.render_options import camera_arg
    from voxwarp.core.volume import Volume
    from voxwarp.inputs import load_lattice_file, load_wire_file
    from voxwarp.scene import Scene

    vol = Volume(np.zeros((8, 6, 5), np.uint8))
    path = tmp_path / f"{name}.json"
    if name == "scene":
        path.write_text(json_text(SCENE))
        assert Scene.load(path).volume.shape == (8, 6, 5)
    elif name == "wires":
        path.write_text(json_text(WIRE_FILE))
        assert load_wire_file(path)["type"] == "wires"
    elif name == "lattice":
        path.write_text(json_text(LATTICE_FILE))
        assert load_lattice_file(path, vol) is not None
    elif name == "camera":
        path.write_text(json_text(CAMERA))
        assert camera_arg(str(path)).distance == 30.0
    else:
        scene = {**SCENE, "warps": [{"type": "wires", "wires": [WIRE], "field_scale": 2}]}
        path.write_text(json_text({**scene, "animation": ANIMATION}))
        assert len(load_animated_scene(path)) == 3
