"""Tests of voxwarp.schemas: the published JSON Schemas of scene, camera, animation, wire
and lattice files.

Oracles: the checked-in ``docs/schemas/*.schema.json`` (equal to the generated ones), every
bundled JSON file and the JSON voxwarp itself writes (valid), and the loaders themselves:
each invalid document below is refused by its loader *and* by the schema.
"""

from __future__ import annotations

import copy
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest

import voxwarp.scene
import voxwarp.schemas
from voxwarp.animation.tracks import Animation, Track, save_animated_scene
from voxwarp.core.camera import Camera
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import warp_from_dict
from voxwarp.editing.families.lattice import LatticeFamily
from voxwarp.editing.session import EditSession
from voxwarp.errors import VoxwarpError
from voxwarp.inputs import load_lattice_file, load_wire_file
from voxwarp.io.samples import load_sample
from voxwarp.scene import Scene
from voxwarp.schemas import KINDS_WITH_SCHEMA, schema_text, schemas

ROOT = Path(__file__).resolve().parents[1]
PUBLISHED = ROOT / "docs" / "schemas"
#: folders that may hold example files of the five kinds
EXAMPLE_FOLDERS = ("sample_volumes", "docs", "tests", "notebooks")


def _validator(kind: str) -> jsonschema.Draft202012Validator:
    return jsonschema.Draft202012Validator(schemas()[kind])


def _kind_of(d: Any) -> str | None:
    """The file kind of a JSON document, or None for other JSON (TF files, schemas...)."""
    if not isinstance(d, dict) or "$schema" in d:
        return None
    if d.get("format") == voxwarp.scene.SCENE_FORMAT or "volume" in d:
        return "scene"
    if "wires" in d:
        return "wires"
    if "grid" in d:
        return "lattice"
    return None


def _examples() -> list[tuple[Path, str]]:
    out = []
    for folder in EXAMPLE_FOLDERS:
        for path in sorted((ROOT / folder).rglob("*.json")):
            if PUBLISHED in path.parents:
                continue
            kind = _kind_of(json.loads(path.read_text(encoding="utf-8")))
            if kind is not None:
                out.append((path, kind))
    return out


# ---------------------------------------------------------------------- published files
def test_published_schemas_are_the_generated_ones() -> None:
    names = sorted(p.name for p in PUBLISHED.glob("*.schema.json"))
    assert names == sorted(f"{k}.schema.json" for k in KINDS_WITH_SCHEMA)
    for kind, schema in schemas().items():
        text = (PUBLISHED / f"{kind}.schema.json").read_text(encoding="utf-8")
        assert text == schema_text(schema), (
            f"docs/schemas/{kind}.schema.json is stale: run python -m voxwarp.schemas"
        )


@pytest.mark.parametrize("kind", KINDS_WITH_SCHEMA)
def test_schemas_are_valid_draft_2020_12(kind: str) -> None:
    jsonschema.Draft202012Validator.check_schema(schemas()[kind])


def test_every_json_type_of_the_scene_loader_has_a_schema() -> None:
    assert set(voxwarp.schemas._SCENE_KINDS) == set(voxwarp.scene._JSON_TYPE_CHECKS)


def test_write_schemas_writes_every_kind(tmp_path: Path) -> None:
    paths = voxwarp.schemas.write_schemas(tmp_path)
    assert sorted(p.name for p in paths) == sorted(p.name for p in PUBLISHED.glob("*.json"))
    for p in paths:
        assert p.read_bytes() == (PUBLISHED / p.name).read_bytes()


# ---------------------------------------------------------------------- valid documents
def test_the_bundled_examples_are_found() -> None:
    kinds = [k for _, k in _examples()]
    assert kinds.count("scene") >= 8
    assert kinds.count("wires") >= 2
    assert kinds.count("lattice") >= 1


@pytest.mark.parametrize(
    ("path", "kind"), _examples(), ids=[str(p.relative_to(ROOT)) for p, _ in _examples()]
)
def test_every_example_file_validates(path: Path, kind: str) -> None:
    d = json.loads(path.read_text(encoding="utf-8"))
    errors = [f"{list(e.absolute_path)}: {e.message}" for e in _validator(kind).iter_errors(d)]
    assert not errors, errors
    if kind == "scene" and "animation" in d:
        _validator("animation").validate(d["animation"])
    if kind == "scene" and d.get("camera") is not None:
        _validator("camera").validate(d["camera"])


def test_what_voxwarp_writes_validates(tmp_path: Path) -> None:
    volume = load_sample("fish", shape=(24, 12, 10))
    session = EditSession(Scene(volume, view="-y"))
    session.set_deformation("lattice", resolution=2)
    bent = session.adapter(LatticeFamily).lattice_nodes.copy()
    bent[-1, :, :, 2] += 4.0
    tracks = [
        Track("lattice.nodes", [(0, "rest"), (3, bent.tolist())], "smooth"),
        Track("camera", [(0, {"view": "-y"}), (3, {"view": [-70.0, 25.0]})]),
        Track("step", [(0, 1.0), (3, 0.5)]),
    ]
    path = save_animated_scene(tmp_path / "s.json", session, Animation(4, 12.0, tracks))
    d = json.loads(path.read_text(encoding="utf-8"))
    _validator("scene").validate(d)
    camera = Camera.from_dict(
        {"center": [1.0, 2.0, 3.0], "rotation": np.eye(3).tolist(), "distance": 9.0}
    )
    _validator("camera").validate(camera.to_dict())


# ---------------------------------------------------------------------- invalid documents
def _small_scene() -> dict[str, Any]:
    return Scene(Volume(np.zeros((4, 4, 4), np.uint8))).to_dict()


def _animation() -> dict[str, Any]:
    return {"frames": 4, "fps": 12, "tracks": [{"target": "step", "keys": [[0, 1.0], [3, 2.0]]}]}


def _wire_file() -> dict[str, Any]:
    return json.loads((ROOT / "sample_volumes" / "fish_spine_wires.json").read_text())


def _lattice_file() -> dict[str, Any]:
    return json.loads((ROOT / "sample_volumes" / "fish_lattice_bend.json").read_text())


def _set(path: str, value: Any) -> Callable[[dict[str, Any]], None]:
    """A change of ``d`` at ``path`` (dot-separated keys and list indices); value
    ``_DROP`` deletes the entry."""

    def change(d: dict[str, Any]) -> None:
        *parents, last = path.split(".")
        target: Any = d
        for p in parents:
            target = target[int(p)] if isinstance(target, list) else target[p]
        key: Any = int(last) if isinstance(target, list) else last
        if value is _DROP:
            del target[key]
        else:
            target[key] = value

    return change


_DROP = object()

INVALID: list[tuple[str, str, Callable[[dict[str, Any]], None]]] = [
    ("scene", "string step", _set("step", "1")),
    ("scene", "integer jitter", _set("jitter", 1)),
    ("scene", "unknown key", _set("stepp", 1.0)),
    ("scene", "unknown mode", _set("mode", "mipp")),
    ("scene", "unknown view", _set("view", "sideways")),
    ("scene", "newer version", _set("version", 99)),
    ("scene", "other format", _set("format", "other-scene")),
    ("scene", "no volume", _set("volume", _DROP)),
    ("scene", "volume without a source", _set("volume", {"spacing": [1, 1, 1]})),
    ("scene", "camera fov a string", _set("camera", {"fov": "30"})),
    ("scene", "warp without a type", _set("warps", [{"grid": {}}])),
    ("scene", "lattice warp without its box", _set("warps", [{"type": "lattice", "grid": {}}])),
    ("camera", "fov a string", _set("fov", "30")),
    ("camera", "unknown key", _set("zoom", 2.0)),
    ("camera", "rotation not 3x3", _set("rotation", [[1.0, 0.0, 0.0]])),
    ("camera", "unknown projection", _set("projection", "fisheye")),
    ("animation", "no frames", _set("frames", 0)),
    ("animation", "too fast", _set("fps", 5000)),
    ("animation", "unknown key", _set("loop", True)),
    ("animation", "unknown interpolation", _set("tracks.0.interpolation", "cubic")),
    ("animation", "no keys", _set("tracks.0.keys", [])),
    ("animation", "unknown target", _set("tracks.0.target", "wobble")),
    ("animation", "a key not a pair", _set("tracks.0.keys.0", [0])),
    ("animation", "unknown track key", _set("tracks.0.ease", "in")),
    ("wires", "no wires", _set("wires", _DROP)),
    ("wires", "unknown key", _set("wires_", [])),
    ("wires", "propagate (a warp entry's, not a file's)", _set("propagate", "flagged")),
    ("wires", "field scale 3", _set("field_scale", 3)),
    ("wires", "a wire without a radius", _set("wires.0.radius", _DROP)),
    ("wires", "a wire of another kind", _set("wires.0.kind", "spline")),
    ("wires", "unknown wire key", _set("wires.0.colour", "red")),
    ("wires", "unknown ends", _set("wires.0.ends", "soft")),
    ("lattice", "no grid", _set("grid", _DROP)),
    ("lattice", "unknown key", _set("cells", 4)),
    ("lattice", "unknown inverse", _set("inverse", "exact")),
]


def _base(kind: str) -> dict[str, Any]:
    if kind == "scene":
        return _small_scene()
    if kind == "camera":
        return Camera.from_dict({}).to_dict()
    if kind == "animation":
        return _animation()
    return _wire_file() if kind == "wires" else _lattice_file()


def _load(kind: str, d: dict[str, Any], tmp_path: Path) -> None:
    """Read ``d`` as voxwarp reads a file of ``kind`` (raises on an invalid one)."""
    if kind == "scene":
        Scene.from_dict(d)
    elif kind == "camera":
        Camera.from_dict(d)
    elif kind == "animation":
        Animation.from_dict(d)
    else:
        path = tmp_path / f"{kind}.json"
        path.write_text(json.dumps(d))
        if kind == "wires":
            warp_from_dict(load_wire_file(path))
        else:
            load_lattice_file(path, Volume(np.zeros((4, 4, 4), np.uint8)))


@pytest.mark.parametrize("kind", KINDS_WITH_SCHEMA)
def test_the_valid_bases_load_and_validate(kind: str, tmp_path: Path) -> None:
    d = _base(kind)
    _load(kind, copy.deepcopy(d), tmp_path)
    _validator(kind).validate(d)


@pytest.mark.parametrize(("kind", "case", "change"), INVALID, ids=[c for _, c, _ in INVALID])
def test_invalid_documents_are_refused_by_loader_and_schema(
    kind: str, case: str, change: Callable[[dict[str, Any]], None], tmp_path: Path
) -> None:
    d = _base(kind)
    change(d)
    with pytest.raises(VoxwarpError):
        _load(kind, copy.deepcopy(d), tmp_path)
    assert not _validator(kind).is_valid(d), case


def test_check_says_which_schemas_are_stale_and_writes_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    from voxwarp.schemas import main

    assert main(["--check", str(tmp_path)]) == 1
    assert list(tmp_path.iterdir()) == []
    assert "stale; run python -m voxwarp.schemas" in capsys.readouterr().err
    main([str(tmp_path)])
    assert main(["--check", str(tmp_path)]) == 0
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exit_info:  # --help is help, not a folder
        main(["--help"])
    assert exit_info.value.code == 0
    assert not (tmp_path / "--help").exists()
