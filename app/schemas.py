"""JSON Schemas of voxwarp's files, built from the rules of the loaders that read them.

Five file kinds have a schema (draft 2020-12, each file self-contained: what it refers to
sits in its ``$defs``):

==========================  ==============================================================
``scene.schema.json``       scene JSON (:meth:`voxwarp.scene.Scene.from_dict`), with its
                            ``"animation"`` entry and its ``"wires"``/``"lattice"`` warps
``camera.schema.json``      a camera object (:meth:`voxwarp.core.camera.Camera.from_dict`)
``animation.schema.json``   the ``"animation"`` entry (:meth:`voxwarp.animation.tracks.
                            Animation.from_dict`)
``wires.schema.json``       a wire file, ``--wires`` (:func:`voxwarp.inputs.read_wire_file`,
                            :meth:`voxwarp.deform.wires.wire.Wire.from_dict`)
``lattice.schema.json``     a lattice file, ``--lattice`` (:func:`voxwarp.inputs.
                            load_lattice_file`, :meth:`voxwarp.deform.lattice.warp.
                            LatticeWarp.from_dict`)
==========================  ==============================================================

The key lists, enumerations and limits come from the constants the loaders check
(``SCENE_KEYS`` and its JSON types, ``MODES``, ``WIRE_KEYS``, ``LATTICE_KEYS``,
``ANIMATION_KEYS``, ``MAX_FRAMES``, ...), so a schema changes with its loader. A schema
checks the structure an editor can check: keys, JSON types, names and ranges. The
loaders check more (a Bézier wire's point count, a key frame inside the animation's
frames, a lattice's node grid shape, files the scene names), so a document the schema
accepts may still be refused, with a message naming the problem; one the schema refuses
is refused by the loader too. JSON Schema counts ``2.0`` as an integer where the scene
loader wants ``2`` (``"seed"``, ``"version"``).

``python -m voxwarp.schemas [FOLDER]`` writes the files (default ``docs/schemas``); the
tests check the checked-in copies against :func:`schemas`.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from voxwarp.animation.targets import EXTRA_KEYS, TARGET_FAMILIES
from voxwarp.animation.tracks import (
    ANIMATION_KEYS,
    INTERPOLATIONS,
    MAX_FPS,
    MAX_FRAMES,
    MAX_PHYSICS_STEPS,
    SCALAR_TARGETS,
    TRACK_KEYS,
)
from voxwarp.core.camera import CAMERA_ARRAYS, PROJECTIONS, VIEW_NAMES, Camera
from voxwarp.core.modes import MODES
from voxwarp.core.scene_seal import SEAL_KEY
from voxwarp.deform.lattice.warp import INVERSE_MODES, LATTICE_KEYS, LATTICE_REQUIRED
from voxwarp.deform.wires.constants import (
    ENDS,
    FIELD_SCALES,
    LAYOUTS,
    MAX_WIRES,
    PROPAGATE_MODES,
    SIDES,
    VACATED,
    WIRE_KEYS,
)
from voxwarp.deform.wires.curves import KINDS
from voxwarp.deform.wires.warp import SPEC_KEYS
from voxwarp.inputs import FILE_NOTES, WIRE_FILE_KEYS
from voxwarp.scene import FRAMES, SCENE_FORMAT, SCENE_KEYS, SCENE_TYPES, SCENE_VERSION

DIALECT = "https://json-schema.org/draft/2020-12/schema"
#: where the published schemas live (their ``$id`` is this plus the file name)
BASE_URL = "https://voxwarp.github.io/voxwarp/schemas/"
#: the file kinds, in the order :func:`schemas` lists them
KINDS_WITH_SCHEMA: tuple[str, ...] = ("scene", "camera", "animation", "wires", "lattice")

_NUMBER: dict[str, Any] = {"type": "number"}


def _numbers(*shape: int) -> dict[str, Any]:
    """An array of numbers of ``shape`` (nested lists)."""
    schema: dict[str, Any] = _NUMBER
    for n in reversed(shape):
        schema = {"type": "array", "items": schema, "minItems": n, "maxItems": n}
    return schema


def _points() -> dict[str, Any]:
    """A list of [x, y, z] points."""
    return {"type": "array", "items": _numbers(3)}


def _one_of(*schemas: dict[str, Any]) -> dict[str, Any]:
    return schemas[0] if len(schemas) == 1 else {"anyOf": list(schemas)}


def _object(
    keys: Sequence[str], properties: dict[str, Any], required: Sequence[str] = ()
) -> dict[str, Any]:
    """A closed object: exactly ``keys`` (those without a rule take any value)."""
    out: dict[str, Any] = {
        "type": "object",
        "properties": {k: properties.get(k, {}) for k in keys},
        "additionalProperties": False,
    }
    if required:
        out["required"] = list(required)
    return out


# ---------------------------------------------------------------------------- parts
def camera_schema() -> dict[str, Any]:
    """A camera object: :meth:`Camera.from_dict`'s keys and JSON types."""
    props: dict[str, Any] = {}
    for key in Camera.__dataclass_fields__:
        if key == "projection":
            props[key] = {"enum": list(PROJECTIONS)}
        elif key in CAMERA_ARRAYS:
            props[key] = _numbers(*CAMERA_ARRAYS[key])
        else:
            props[key] = _NUMBER
    return _object(tuple(Camera.__dataclass_fields__), props)


def wire_schema() -> dict[str, Any]:
    """One wire: :meth:`Wire.from_dict`'s keys."""
    positive = {"type": "number", "exclusiveMinimum": 0}
    props = {
        "kind": {"enum": list(KINDS)},
        "base": _points(),
        "modified": _one_of(_points(), {"type": "null"}),
        "radius": positive,
        "beta": _one_of(_numbers(2), {"type": "null"}),
        "initial_normal": _one_of(_numbers(3), {"type": "null"}),
        "ends": {"enum": list(ENDS)},
        "falloff": _one_of(positive, {"type": "null"}),
        "sides": {"enum": list(SIDES)},
        "side_falloff": _one_of(positive, {"type": "null"}),
        "vacated": {"enum": list(VACATED)},
    }
    return _object(WIRE_KEYS, props, required=("base", "radius"))


def _wire_field_properties() -> dict[str, Any]:
    return {
        "wires": {
            "type": "array",
            "items": {"$ref": "#/$defs/wire"},
            "minItems": 1,
            "maxItems": MAX_WIRES,
        },
        "field_scale": {"enum": list(FIELD_SCALES)},
        "layout": {"enum": list(LAYOUTS)},
        "propagate": {"enum": list(PROPAGATE_MODES)},
    }


def wires_warp_schema() -> dict[str, Any]:
    """A ``"wires"`` warp entry of scene JSON (:meth:`WireFieldWarp.from_dict`)."""
    props = {"type": {"const": "wires"}, **_wire_field_properties()}
    return _object(("type", *SPEC_KEYS), props, required=("type", "wires"))


def _lattice_properties() -> dict[str, Any]:
    return {
        "grid": {"type": "object", "required": ["nodes"]},
        "box": _numbers(2, 3),
        "inverse": {"enum": list(INVERSE_MODES)},
        "iterations": {"type": "integer"},
        "max_iterations": {"type": "integer"},
        "tolerance": _NUMBER,
    }


def lattice_warp_schema() -> dict[str, Any]:
    """A ``"lattice"`` warp entry of scene JSON (:meth:`LatticeWarp.from_dict`)."""
    props = {**_lattice_properties(), "type": {"const": "lattice"}}
    return _object(LATTICE_KEYS, props, required=LATTICE_REQUIRED)


def warp_entry_schema() -> dict[str, Any]:
    """Any warp entry: a ``"type"``; wires and lattice entries checked in full (other
    kinds, registered by plugins too, are checked by their own loaders)."""
    return {
        "type": "object",
        "required": ["type"],
        "properties": {"type": {"type": "string"}},
        "allOf": [
            {
                "if": {"properties": {"type": {"const": kind}}},
                "then": {"$ref": f"#/$defs/{kind}_warp"},
            }
            for kind in ("wires", "lattice")
        ],
    }


def _target_schema() -> dict[str, Any]:
    fixed = ["camera", "transfer_function", *SCALAR_TARGETS]
    fixed += [n for f in TARGET_FAMILIES if f.pattern is None for n in f.names]
    patterns = [
        {"type": "string", "pattern": f.pattern} for f in TARGET_FAMILIES if f.pattern is not None
    ]
    return _one_of({"enum": fixed}, *patterns)


def track_schema() -> dict[str, Any]:
    """A track entry (:meth:`voxwarp.animation.tracks.Track.from_dict`)."""
    key = {
        "type": "array",
        "prefixItems": [{"type": "number", "minimum": 0, "maximum": MAX_FRAMES - 1}, {}],
        "minItems": 2,
        "maxItems": 2,
    }
    props = {
        "target": _target_schema(),
        "keys": {"type": "array", "items": key, "minItems": 1},
        "interpolation": {"enum": list(INTERPOLATIONS)},
        "elements": {"type": "array"},
    }
    return _object((*TRACK_KEYS, *EXTRA_KEYS), props, required=("target", "keys"))


def animation_schema_body() -> dict[str, Any]:
    """The ``"animation"`` entry (:meth:`Animation.from_dict`)."""
    steps = {"type": "integer", "minimum": 0, "maximum": MAX_PHYSICS_STEPS}
    props = {
        "frames": {"type": "integer", "minimum": 1, "maximum": MAX_FRAMES},
        "fps": {"type": "number", "exclusiveMinimum": 0, "maximum": MAX_FPS},
        "tracks": {"type": "array", "items": {"$ref": "#/$defs/track"}},
        "steps_per_frame": _one_of(steps, {"type": "null"}),
        "relax_steps": _one_of(steps, {"type": "null"}),
    }
    return _object(ANIMATION_KEYS, props, required=("frames",))


#: the scene loader's JSON type names (:data:`voxwarp.scene.SCENE_TYPES`) as schemas
_SCENE_KINDS: dict[str, dict[str, Any]] = {
    "str": {"type": "string"},
    "int": {"type": "integer"},
    "number": _NUMBER,
    "bool": {"type": "boolean"},
    "null": {"type": "null"},
    "list": {"type": "array"},
    "object": {"type": "object"},
    "pair": _numbers(2),
    "rgba": {"type": "array", "items": _NUMBER, "minItems": 3, "maxItems": 4},
    "box": _numbers(2, 3),
}


def _scene_properties() -> dict[str, Any]:
    # what the scene checks of a value beyond its JSON type, by entry and type name
    values: dict[tuple[str, str], dict[str, Any]] = {
        ("format", "str"): {"const": SCENE_FORMAT},
        ("version", "int"): {"type": "integer", "maximum": SCENE_VERSION},
        ("mode", "str"): {"enum": list(MODES)},
        ("projection", "str"): {"enum": list(PROJECTIONS)},
        ("frame", "str"): {"enum": list(FRAMES)},
        ("view", "str"): {"enum": list(VIEW_NAMES)},
        ("camera", "object"): {"$ref": "#/$defs/camera"},
        ("warps", "list"): {"type": "array", "items": {"$ref": "#/$defs/warp"}},
        ("meshes", "list"): {"type": "array", "items": {"type": "object"}},
    }
    props = {
        key: _one_of(*(values.get((key, k), _SCENE_KINDS[k]) for k in kinds))
        for key, (kinds, _expected) in SCENE_TYPES.items()
    }
    props["volume"] = {
        **props["volume"],
        "anyOf": [{"required": [k]} for k in ("path", "sample", "embedded")],
    }
    props["animation"] = {"$ref": "#/$defs/animation"}
    props["description"] = {"type": "string"}
    props[SEAL_KEY] = {
        "type": "string",
        "description": "HMAC-SHA256 of the absolute paths the scene names, under the saving"
        " user's key: they reopen without --allow-dir (voxwarp.core.scene_seal)",
    }
    return props


# ---------------------------------------------------------------------------- documents
def _document(kind: str, title: str, body: dict[str, Any], defs: Sequence[str]) -> dict[str, Any]:
    parts = {
        "camera": camera_schema,
        "animation": animation_schema_body,
        "track": track_schema,
        "warp": warp_entry_schema,
        "wires_warp": wires_warp_schema,
        "lattice_warp": lattice_warp_schema,
        "wire": wire_schema,
    }
    doc: dict[str, Any] = {
        "$schema": DIALECT,
        "$id": f"{BASE_URL}{kind}.schema.json",
        "title": title,
        **body,
    }
    if defs:
        doc["$defs"] = {name: parts[name]() for name in defs}
    return doc


def schemas() -> dict[str, dict[str, Any]]:
    """Every published schema by file kind (:data:`KINDS_WITH_SCHEMA`)."""
    scene = _object(SCENE_KEYS, _scene_properties(), required=("volume",))
    scene["description"] = (
        "voxwarp scene JSON (voxwarp.scene.Scene.to_dict), with the optional 'editor' and"
        " 'animation' entries; generated by voxwarp.schemas"
    )
    wires = _object(
        sorted({*WIRE_FILE_KEYS, *FILE_NOTES}),
        {**_wire_field_properties(), "description": {"type": "string"}},
        required=("wires",),
    )
    lattice = _object(
        (*LATTICE_KEYS, *sorted(set(FILE_NOTES) - set(LATTICE_KEYS))),
        {**_lattice_properties(), "description": {"type": "string"}},
        required=[k for k in LATTICE_REQUIRED if k != "box"],  # a file's box: the volume's
    )
    return {
        "scene": _document(
            "scene",
            "voxwarp scene",
            scene,
            ("camera", "warp", "wires_warp", "lattice_warp", "wire", "animation", "track"),
        ),
        "camera": _document("camera", "voxwarp camera", camera_schema(), ()),
        "animation": _document(
            "animation", "voxwarp scene animation entry", animation_schema_body(), ("track",)
        ),
        "wires": _document("wires", "voxwarp wire file (--wires)", wires, ("wire",)),
        "lattice": _document("lattice", "voxwarp lattice file (--lattice)", lattice, ()),
    }


def schema_text(schema: dict[str, Any]) -> str:
    """A schema as its file holds it (two-space indent, a final newline)."""
    return json.dumps(schema, indent=2) + "\n"


def write_schemas(folder: str | os.PathLike) -> list[Path]:
    """Write ``KIND.schema.json`` for every kind into ``folder``; returns the files."""
    from voxwarp.core.files import atomic_write_text

    paths = []
    for kind, schema in schemas().items():
        path = Path(folder) / f"{kind}.schema.json"
        atomic_write_text(path, schema_text(schema))
        paths.append(path)
    return paths


def stale_schemas(folder: str | os.PathLike) -> list[Path]:
    """The ``KIND.schema.json`` files in ``folder`` that are missing or differ from
    what :func:`schemas` gives now."""
    out = []
    for kind, schema in schemas().items():
        path = Path(folder) / f"{kind}.schema.json"
        try:
            same = path.read_text(encoding="utf-8") == schema_text(schema)
        except OSError:
            same = False
        if not same:
            out.append(path)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m voxwarp.schemas [FOLDER] [--check]``: write the schemas (default
    docs/schemas), or with ``--check`` only say which are stale (exit status 1)."""
    import argparse

    p = argparse.ArgumentParser(
        prog="python -m voxwarp.schemas",
        description="Write the JSON Schemas of voxwarp's file formats.",
    )
    p.add_argument("folder", nargs="?", default="docs/schemas", help="default: docs/schemas")
    p.add_argument("--check", action="store_true", help="write nothing; exit 1 if any is stale")
    args = p.parse_args(sys.argv[1:] if argv is None else argv)
    if args.check:
        stale = stale_schemas(args.folder)
        for path in stale:
            print(f"{path}: stale; run python -m voxwarp.schemas {args.folder}", file=sys.stderr)
        return 1 if stale else 0
    for path in write_schemas(args.folder):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
