"""One loader for every JSON file voxwarp reads: size, depth and strictness limits.

:func:`read_json` (a path) and :func:`parse_json_text` (text) are used by every JSON
reader: scenes, transfer functions, wires, lattices, cameras, animations, tours, the
napari reader, sidecars and manifests. They refuse, before or while parsing:

* files over :data:`MAX_JSON_BYTES` (checked on the file's size, before reading);
* nesting deeper than :data:`MAX_JSON_DEPTH` (counted without recursion, before
  ``json`` recurses, so ``[[[[...`` is one line instead of a ``RecursionError``);
* ``NaN``/``Infinity`` (not JSON) and duplicate keys (which JSON leaves undefined);
* FIFOs, sockets, devices and folders (:mod:`voxwarp.core.input_files`).

A UTF-8 byte-order mark (as Windows editors write) is accepted. Size and file-kind
problems raise :class:`JsonFileError` (an ``OSError``); content problems raise
:class:`JsonLimitError` (a ``ValueError``), so callers' ``except OSError`` /
``except ValueError`` wrap them in their own one-line errors.
"""

from __future__ import annotations

import json
import os
import re
from typing import Any

from voxwarp.core.input_files import not_regular

#: Largest JSON file read (bytes).
MAX_JSON_BYTES = 32 * 1024 * 1024
#: Deepest nesting of arrays and objects accepted (voxwarp's own files nest < 10 deep).
MAX_JSON_DEPTH = 64
_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"', re.S)


class JsonFileError(OSError):
    """A JSON file that is too large or not a regular file."""


class JsonLimitError(ValueError):
    """JSON text too deep, with NaN/Infinity, or with a duplicate key."""


def json_depth(text: str | bytes) -> int:
    """The deepest nesting of ``[``/``{`` in JSON ``text`` (strings skipped), without
    recursion."""
    import numpy as np  # loaded when used: the CLI's --help stays light

    raw = text.encode("utf-8", "surrogatepass") if isinstance(text, str) else text
    codes = np.frombuffer(_STRING.sub(b'""', raw), dtype=np.uint8)
    if codes.size == 0:
        return 0
    step = np.isin(codes, (91, 123)).astype(np.int32) - np.isin(codes, (93, 125))
    return int(max(0, np.cumsum(step).max()))


def _no_constant(name: str) -> Any:
    raise JsonLimitError(f"{name} is not a JSON number; write a finite number or null")


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise JsonLimitError(f"duplicate key {key!r:.60} in one object; keep only one")
        out[key] = value
    return out


def parse_json_text(text: str) -> Any:
    """``text`` parsed strictly (depth, NaN, duplicate keys; a leading BOM dropped)."""
    text = text.removeprefix("\ufeff")
    depth = json_depth(text)
    if depth > MAX_JSON_DEPTH:
        raise JsonLimitError(
            f"nested {depth} levels deep; voxwarp reads JSON nested at most"
            f" {MAX_JSON_DEPTH} deep: flatten it"
        )
    return json.loads(text, parse_constant=_no_constant, object_pairs_hook=_no_duplicates)


def read_json_text(path: str | os.PathLike[str]) -> str:
    """The UTF-8 text of the JSON file ``path`` (BOM dropped), within the size limit."""
    kind = not_regular(path)
    if kind is not None:
        raise JsonFileError(f"it is {kind}, not a regular file; give a JSON file")
    size = os.path.getsize(path)  # FileNotFoundError for a missing file, as before
    if size > MAX_JSON_BYTES:
        raise JsonFileError(
            f"it is {size / 2**20:.1f} MiB; voxwarp reads JSON files of at most"
            f" {MAX_JSON_BYTES >> 20} MiB"
        )
    with open(path, "rb") as fh:  # read(n) allocates n bytes: the size, not the limit
        raw = fh.read(size + 1)
    if len(raw) > size:
        raise JsonFileError("it grew while being read; read it once it is complete")
    return raw.decode("utf-8-sig")


def read_json(path: str | os.PathLike[str]) -> Any:
    """The JSON of the file ``path``, by :func:`read_json_text` and :func:`parse_json_text`."""
    return parse_json_text(read_json_text(path))
