"""Bundled samples: volumes as :class:`~voxwarp.core.volume.Volume` objects, and the
bundled JSON files (scenes, wire files, lattice files, animations) by name.

Wraps :mod:`sample_volumes` (generators and bundled real scans, numpy only). A sample
volume's ``source`` is ``"sample:NAME"`` so scene JSON can refer to it by name. The
JSON files beside them (package data, found through :mod:`importlib.resources`, so
they work after ``pip install``) are named by their stem: ``sample:fish_spine_wires``
is ``fish_spine_wires.json`` (:func:`sample_file`, :func:`resolve_sample_path`).
"""

from __future__ import annotations

import importlib.resources
from collections.abc import Sequence
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Any

from voxwarp import sample_volumes
from voxwarp.core.json_input import parse_json_text
from voxwarp.core.volume import Volume
from voxwarp.errors import VolumeError

#: The sample `make run` and `voxwarp demo` render by default.
DEFAULT_SAMPLE = "stent"

#: Transfer functions that suit each sample (presets or control points in its units).
#: The stent CT is stored as 0..32 (not HU): soft tissue 0..6, contrast-filled vessels
#: and bone around 10..20, the stent graft's metal at the top of the range.
SUGGESTED_TRANSFER_FUNCTIONS: dict[str, Any] = {
    "stent": [
        (0.0, 0.0, 0.0, 0.0, 0.0),
        (4.0, 0.7, 0.2, 0.15, 0.0),
        (6.0, 0.85, 0.35, 0.25, 0.03),
        (10.0, 0.95, 0.7, 0.55, 0.25),
        (20.0, 1.0, 0.95, 0.9, 0.7),
        (32.0, 1.0, 1.0, 1.0, 0.95),
    ],
    "colin27": "mri",
    "fish": "ct-bone",
    "tubes": "ct-soft",
    "head": "ct-bone",
}


#: The modality of the bundled real scans (their files carry none); the phantoms are HU.
SAMPLE_MODALITIES: dict[str, str] = {"stent": "CT", "colin27": "MR"}


def suggested_transfer_function(name: str) -> Any:
    """A transfer function (preset name or points) that shows sample ``name`` well."""
    return SUGGESTED_TRANSFER_FUNCTIONS.get(name, "ct-bone")


def sample_names() -> list[str]:
    """Names accepted by :func:`load_sample`."""
    return list(sample_volumes.names())


def bundled_dir() -> Path:
    """The folder of the bundled sample files (scenes, wire and lattice files, volumes)."""
    return Path(sample_volumes.__file__).resolve().parent


def load_sample(
    name: str,
    spacing: Sequence[float] | None = None,
    origin: Sequence[float] | None = None,
    **kwargs: Any,
) -> Volume:
    """Generate or load the bundled sample ``name`` (see ``sample_volumes/README.md``).

    ``kwargs`` go to the generator (``shape``, ``seed``) for synthetic phantoms.
    """
    if name not in sample_volumes.names():
        raise VolumeError(f"unknown sample {name!r}; {_names_text()}")
    try:
        s = sample_volumes.get(name, **kwargs)
    except (TypeError, ValueError, OverflowError) as exc:  # e.g. a shape over the limits
        raise VolumeError(f"sample {name!r}: {exc}") from exc
    spacing = s.spacing if spacing is None else spacing
    origin = s.origin if origin is None else origin
    return Volume(
        s.data,
        spacing,
        origin,
        name=name,
        source=f"sample:{name}",
        units=s.units,
        modality=SAMPLE_MODALITIES.get(name, ""),
        space="RAS" if s.axes == "RAS" else "",
        file_axes=s.axes,
        spacing_source="file" if s.axes or s.units == "HU" else "assumed",
    )


#: kinds of bundled JSON files, in the order ``voxwarp samples`` lists them
FILE_KINDS: tuple[str, ...] = ("scene", "animation", "wires", "lattice")
#: the prefix that names a bundled sample
PREFIX = "sample:"


def _root() -> Traversable:
    return importlib.resources.files("voxwarp.sample_volumes")


def json_kind(d: object) -> str:
    """What a bundled JSON holds: ``animation`` (a scene with an ``animation`` entry),
    ``scene``, ``wires``, ``lattice``, or ``""``."""
    if not isinstance(d, dict):
        return ""
    if d.get("format") == "voxwarp-scene":
        return "animation" if d.get("animation") else "scene"
    if "wires" in d:
        return "wires"
    return "lattice" if d.get("type") == "lattice" else ""


def sample_files(root: Traversable | None = None) -> dict[str, str]:
    """The bundled JSON files by name (their stem) -> kind (:data:`FILE_KINDS`); ``root``
    (default the installed ``voxwarp.sample_volumes``) is any importlib Traversable,
    e.g. a ``zipfile.Path``."""
    out = {}
    for item in sorted((root or _root()).iterdir(), key=lambda t: t.name):
        if item.name.endswith(".json") and item.is_file():
            kind = json_kind(parse_json_text(item.read_text(encoding="utf-8")))
            if kind:
                out[item.name[: -len(".json")]] = kind
    return out


def _names_text() -> str:
    files = ", ".join(sample_files())
    return f"volumes: {', '.join(sample_volumes.names())}; files: {files} (voxwarp samples)"


def sample_file(name: str) -> Path:
    """The path of the bundled JSON file ``name`` (``fish_spine_wires``); a
    :class:`VolumeError` listing every sample name otherwise."""
    if name not in sample_files():
        raise VolumeError(f"unknown sample file {name!r}; {_names_text()}")
    return Path(str(_root().joinpath(f"{name}.json")))


def resolve_sample_path(spec: str | Path) -> str | Path:
    """``spec`` with ``sample:NAME`` of a bundled JSON file replaced by its path; other
    specs unchanged; ``sample:NAME`` naming nothing bundled is a :class:`VolumeError`
    listing the names (a volume sample's name is kept: :func:`load_sample` loads it)."""
    text = str(spec)
    if not text.startswith(PREFIX):
        return spec
    name = text[len(PREFIX) :]
    if name in sample_volumes.names():
        return spec
    if name not in sample_files():
        raise VolumeError(f"unknown sample {name!r}; {_names_text()}")
    return sample_file(name)
