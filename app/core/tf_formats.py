"""Transfer functions from other tools: ParaView colour maps, 3D Slicer volume properties,
matplotlib colour maps.

Pure parsing: text (or a colour-map name) -> an :class:`ImportedMap` of colour and
opacity control points, still in the file's own units. Turning one into voxwarp control
points against a volume (normalised ranges, opacity unit distance) is
:func:`to_control_points`; :meth:`voxwarp.core.transfer_function.TransferFunction.load`
and ``.preset`` call these. Every problem is a one-line
:class:`~voxwarp.errors.SceneError`.

Formats
-------
* **ParaView colour map JSON** (Color Map Editor -> "Save to preset" -> Export, and
  ParaView's own ``Remoting/Views/ColorMaps.json``): a JSON list of objects with
  ``Name``, ``RGBPoints`` ``[x, r, g, b, ...]``, optional ``Points``
  ``[x, opacity, midpoint, sharpness, ...]``, ``ColorSpace``, ``NanColor``, ``Creator``...
  Categorical maps (``IndexedColors``) are rejected.
* **3D Slicer ``presets.xml``** (``<VolumeProperty name=... scalarOpacity="N x o ..."
  colorTransfer="N x r g b ..." .../>`` elements), the **``.vp``** file older Slicer
  saves (lines: interpolation, shade, diffuse, ambient, specular, specular power, scalar
  opacity, gradient opacity, colour transfer; the last three as ``N x ...``) and the
  **``.vp.json``** newer Slicer saves (``volumeProperties[].components[]`` with
  ``rgbTransferFunction``, ``scalarOpacity``, ``scalarOpacityUnitDistance``).
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from voxwarp.core import tf_curves
from voxwarp.core.input_files import not_regular
from voxwarp.core.json_input import JsonLimitError, parse_json_text
from voxwarp.errors import SceneError

#: Largest transfer-function file read (bytes); ParaView's full preset list is ~2 MB.
MAX_FILE_BYTES = 32 * 1024 * 1024
#: Most control points in one colour or opacity curve of a file (ParaView's largest
#: preset has 1,024; a TF texture has far fewer texels): counted before any parsing.
MAX_TF_POINTS = 65_536
#: How far (per channel) a matplotlib map's control points may let any of its colours
#: stray: the fewest points that keep every colour within it are kept.
COLORMAP_TOLERANCE = 1.0 / 255
#: Opacity at the top of the ramp that colour-only maps get (0 at the bottom, linear).
RAMP_OPACITY = 0.5
#: VTK's default scalar opacity unit distance (world units, mm), which Slicer keeps.
SLICER_UNIT_DISTANCE_MM = 1.0

_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


@dataclass(frozen=True)
class ImportedMap:
    """One colour/opacity map read from a file, in the file's units.

    ``colour`` is ``(n, 4)``: x, r, g, b; ``opacity`` ``(m, 2)``: x, opacity, or None
    (colour only: the default ramp applies). ``kind`` is ``"paraview"``, ``"slicer"``
    or ``"matplotlib"``; ``unit_distance`` the length (mm) an opacity refers to, None
    when the tool ties it to the data (voxwarp's reference sample is used as is).
    """

    name: str
    colour: np.ndarray
    opacity: np.ndarray | None
    kind: str
    unit_distance: float | None = None
    notes: tuple[str, ...] = ()
    #: Why this map of a several-map file cannot be used (e.g. categorical), else None.
    error: str | None = None


# ---------------------------------------------------------------------------- reading
def read_text(path: str) -> str:
    """The UTF-8 text of ``path`` (at most :data:`MAX_FILE_BYTES`), one-line errors."""
    cannot = f"cannot read transfer function file {path}"
    kind = not_regular(path)
    if kind is not None:
        raise SceneError(f"{cannot}: it is {kind}, not a regular file; give a TF file")
    try:
        size = os.path.getsize(path)
        if size > MAX_FILE_BYTES:
            raise SceneError(
                f"{cannot}: {size / 1e6:.0f} MB; a transfer function file is at most"
                f" {MAX_FILE_BYTES // (1024 * 1024)} MB"
            )
        with open(path, "rb") as fh:
            raw = fh.read(MAX_FILE_BYTES + 1)
    except FileNotFoundError as exc:
        raise SceneError(f"no such transfer function file: {path}") from exc
    except OSError as exc:
        raise SceneError(f"{cannot}: {exc.strerror}") from exc
    if len(raw) > MAX_FILE_BYTES:
        raise SceneError(f"{cannot}: it is larger than {MAX_FILE_BYTES} bytes")
    if b"\0" in raw:
        raise SceneError(f"{cannot}: a binary file, not JSON, XML or .vp text")
    if not raw.strip():
        raise SceneError(f"{cannot}: it is empty")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise SceneError(f"{cannot}: not UTF-8 text (byte {exc.start})") from exc


def file_kind(text: str, path: str = "") -> str:
    """``"json"``, ``"slicer-xml"`` or ``"slicer-vp"``: by suffix (.json, .xml, .vp),
    else by content."""
    by_suffix = {".json": "json", ".xml": "slicer-xml", ".vp": "slicer-vp"}
    kind = by_suffix.get(os.path.splitext(path)[1].lower())
    if kind:
        return kind
    head = text.lstrip()[:1]
    if head in "[{" and head:
        return "json"
    if head == "<":
        return "slicer-xml"
    if head and (head.isdigit() or head in "+-."):
        return "slicer-vp"
    raise SceneError(
        f"{path or 'text'}: not a transfer function file (voxwarp or ParaView JSON,"
        " Slicer presets.xml or .vp)"
    )


_TRAILING_COMMA = re.compile(r",(\s*[\]}])")


def parse_json(text: str, path: str = "") -> object:
    """JSON, also with trailing commas before ``]``/``}`` as ParaView's jsoncpp accepts
    (its own ColorMaps.json ends with one)."""
    try:
        return parse_json_text(text)
    except JsonLimitError as exc:
        raise SceneError(f"cannot read transfer function file {path}: {exc}") from exc
    except ValueError as exc:
        try:
            return parse_json_text(_TRAILING_COMMA.sub(r"\1", text))
        except ValueError:
            raise SceneError(f"cannot read transfer function file {path}: {exc}") from exc


def is_paraview(doc: object) -> bool:
    """Whether parsed JSON ``doc`` is a ParaView colour map (list or single object)."""
    items = doc if isinstance(doc, list) else [doc]
    return any(
        isinstance(m, dict) and bool({"RGBPoints", "IndexedColors", "Points"} & set(m))
        for m in items
    )


# ---------------------------------------------------------------------------- numbers
def _check_points(count: int, width: int, what: str) -> None:
    """Refuse a curve of more than :data:`MAX_TF_POINTS` points (``count`` numbers,
    ``width`` a point) before its numbers are parsed."""
    if count > MAX_TF_POINTS * width:
        raise SceneError(
            f"{what}: {count // width:,} points; a transfer function curve has at most"
            f" {MAX_TF_POINTS:,}: resample it to fewer points"
        )


def _numbers(values: Sequence[object], what: str) -> np.ndarray:
    """Finite floats from JSON numbers or strings; one-line errors."""
    out = np.empty(len(values))
    for i, v in enumerate(values):
        if isinstance(v, bool) or not isinstance(v, (int, float, str)):
            raise SceneError(f"{what}: entry {i + 1} is {v!r}, not a number")
        if isinstance(v, str) and not _NUMBER.match(v.strip()):
            raise SceneError(f"{what}: entry {i + 1} is {v[:20]!r}, not a number")
        f = float(v)
        if not math.isfinite(f):
            raise SceneError(f"{what}: entry {i + 1} is {v!r}; values must be finite")
        out[i] = f
    return out


def _rows(flat: np.ndarray, width: int, what: str, lo: int = 1) -> np.ndarray:
    """``flat`` as rows of ``width``: x non-decreasing, the rest within [0, 1]."""
    if flat.size % width or flat.size < width * lo:
        raise SceneError(
            f"{what}: {flat.size} numbers; expected groups of {width} (x then"
            f" {width - 1} values), at least {lo}"
        )
    rows = flat.reshape(-1, width)
    if np.any(np.diff(rows[:, 0]) < 0):
        i = int(np.nonzero(np.diff(rows[:, 0]) < 0)[0][0])
        raise SceneError(
            f"{what}: x values must not decrease (point {i + 2}: {rows[i + 1, 0]:g} after"
            f" {rows[i, 0]:g})"
        )
    vals = rows[:, 1:]
    if np.any(vals < 0) or np.any(vals > 1):
        bad = float(vals[(vals < 0) | (vals > 1)][0])
        raise SceneError(f"{what}: colour/opacity values must lie in [0, 1] (found {bad:g})")
    return rows


def vtk_string(text: str, width: int, what: str) -> np.ndarray:
    """Slicer/VTK ``"N v0 v1 ..."`` (N numbers follow) as rows of ``width``."""
    first = text.split(None, 1)
    if not first:
        raise SceneError(f"{what} is empty")
    head = first[0]
    if not head.isdigit() or not head.isascii():
        raise SceneError(f"{what}: starts with {head[:20]!r}; expected the count N")
    n = int(head) if len(head) < 13 else -1
    if n < 0:
        raise SceneError(f"{what}: count N {head[:20]}... is too large")
    _check_points(n, width, what)
    parts = text.split()
    if n != len(parts) - 1:
        raise SceneError(f"{what}: says {n} numbers but has {len(parts) - 1}")
    return _rows(_numbers(parts[1:], what), width, what)


# ---------------------------------------------------------------------------- ParaView
def paraview_maps(doc: object, path: str = "") -> list[ImportedMap]:
    """The maps of a ParaView colour-map JSON document (list of objects, or one)."""
    items = doc if isinstance(doc, list) else [doc]
    if not items:
        raise SceneError(f"{path}: the ParaView colour map list is empty")
    if len(items) == 1:
        return [_paraview_map(items[0], 0, path)]
    maps = []
    for i, m in enumerate(items):  # a bad map is an error only when it is picked
        try:
            maps.append(_paraview_map(m, i, path))
        except SceneError as exc:
            name = str(m.get("Name", f"map {i + 1}")) if isinstance(m, dict) else f"map {i + 1}"
            maps.append(ImportedMap(name, np.zeros((0, 4)), None, "paraview", error=str(exc)))
    if all(m.error for m in maps):
        raise SceneError(maps[0].error)
    return maps


def _paraview_map(m: object, i: int, path: str) -> ImportedMap:
    if not isinstance(m, dict):
        raise SceneError(f"{path}: colour map {i + 1} is not a JSON object")
    name = str(m.get("Name", f"map {i + 1}"))
    where = f"{path}: {name!r}"
    if "IndexedColors" in m and "RGBPoints" not in m:
        raise SceneError(
            f"{where} is a categorical (IndexedColors) map; voxwarp needs a continuous one"
            " with RGBPoints"
        )
    rgb = m.get("RGBPoints")
    if not isinstance(rgb, list):
        raise SceneError(f"{where} has no RGBPoints list [x, r, g, b, ...]")
    _check_points(len(rgb), 4, f"{where} RGBPoints")
    colour = _rows(_numbers(rgb, f"{where} RGBPoints"), 4, f"{where} RGBPoints")
    opacity = None
    notes: list[str] = []
    if "Points" in m:
        pts = m["Points"]
        if not isinstance(pts, list):
            raise SceneError(
                f"{where}: Points must be a list [x, opacity, midpoint, sharpness, ...]"
            )
        _check_points(len(pts), 4, f"{where} Points")
        rows = _rows(_numbers(pts, f"{where} Points"), 4, f"{where} Points")
        opacity = tf_curves.expand_opacity(rows)
    space = str(m.get("ColorSpace", "RGB"))
    if space not in ("RGB", "Step", *tf_curves.COLOUR_PATHS) and len(colour) < 64:
        notes.append(f"{space} colour space interpolated in RGB between the points")
    if m.get("UseLogScale"):
        notes.append("log scale ignored (linear in data value)")
    if space == "Step":
        colour = tf_curves.step(colour)
    elif space in tf_curves.COLOUR_PATHS:
        colour = tf_curves.subdivided(colour, space, hsv_wrap=bool(m.get("HSVWrap")))
    return ImportedMap(name, colour, opacity, "paraview", None, tuple(notes))


# ---------------------------------------------------------------------------- Slicer
def slicer_presets(text: str, path: str = "") -> list[ImportedMap]:
    """The ``VolumeProperty`` elements of a Slicer ``presets.xml`` (or MRML scene)."""
    import xml.etree.ElementTree as ET

    upper = text.upper()  # the whole file: a DTD may follow a long comment
    if "<!DOCTYPE" in upper or "<!ENTITY" in upper:
        raise SceneError(f"{path}: XML with a DTD or entities is not accepted")
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise SceneError(f"{path}: not well-formed XML ({exc})") from exc
    elems = [root] if root.tag == "VolumeProperty" else list(root.iter("VolumeProperty"))
    if not elems:
        raise SceneError(f"{path}: no <VolumeProperty> element (a Slicer presets.xml has them)")
    return [_slicer_element(e, i, path) for i, e in enumerate(elems)]


def _slicer_element(e: object, i: int, path: str) -> ImportedMap:
    attrs = e.attrib  # type: ignore[attr-defined]
    name = str(attrs.get("name") or f"preset {i + 1}")
    where = f"{path}: {name!r}"
    for key in ("scalarOpacity", "colorTransfer"):
        if key not in attrs:
            raise SceneError(f"{where} has no {key} attribute")
    return _slicer_map(name, attrs["scalarOpacity"], attrs["colorTransfer"], where)


def _slicer_map(name: str, opacity: str, colour: str, where: str) -> ImportedMap:
    o = vtk_string(opacity, 2, f"{where} scalarOpacity")
    c = vtk_string(colour, 4, f"{where} colorTransfer")
    # gradient opacity and the lighting attributes are not used (documented, not warned)
    return ImportedMap(name, c, o, "slicer", SLICER_UNIT_DISTANCE_MM)


def is_slicer_json(doc: object) -> bool:
    """Whether parsed JSON ``doc`` is a Slicer ``.vp.json`` volume property file."""
    return isinstance(doc, dict) and "volumeProperties" in doc


def slicer_json(doc: dict, path: str = "") -> list[ImportedMap]:
    """The volume properties of a Slicer ``.vp.json`` (vtkMRMLVolumePropertyJsonStorageNode:
    ``volumeProperties[].components[0]`` with ``rgbTransferFunction``, ``scalarOpacity``
    and ``scalarOpacityUnitDistance``)."""
    props = doc.get("volumeProperties")
    if not isinstance(props, list) or not props:
        raise SceneError(f"{path}: 'volumeProperties' must be a non-empty list")
    base = os.path.basename(path)
    stem = base[: -len(".vp.json")] if base.endswith(".vp.json") else os.path.splitext(base)[0]
    maps = []
    for i, prop in enumerate(props):
        name = stem if len(props) == 1 else f"{stem} {i + 1}"
        comps = prop.get("components") if isinstance(prop, dict) else None
        if not isinstance(comps, list) or not comps or not isinstance(comps[0], dict):
            raise SceneError(f"{path}: volume property {i + 1} has no 'components' list")
        maps.append(_slicer_component(comps[0], name, f"{path}: {name!r}"))
    return maps


def _slicer_component(comp: dict, name: str, where: str) -> ImportedMap:
    colour = _json_points(comp.get("rgbTransferFunction"), ("color",), 3, f"{where} colours")
    opacity = _json_points(comp.get("scalarOpacity"), ("y",), 1, f"{where} scalarOpacity")
    unit = _numbers([comp.get("scalarOpacityUnitDistance", 1.0)], f"{where} unit distance")[0]
    if unit <= 0:
        raise SceneError(f"{where}: scalarOpacityUnitDistance must be positive, not {unit:g}")
    (colour, sharp), opacity = tf_curves.expand_midpoints(colour), tf_curves.expand_opacity(opacity)
    notes = ("colour sharpness ignored (linear between points)",) if sharp else ()
    return ImportedMap(name, colour, opacity, "slicer", float(unit), notes)


def _json_points(tf: object, keys: tuple[str, ...], width: int, what: str) -> np.ndarray:
    """``{"points": [{"x", <keys>, "midpoint", "sharpness"}, ...]}`` as checked rows."""
    pts = tf.get("points") if isinstance(tf, dict) else None
    if not isinstance(pts, list) or not pts:
        raise SceneError(f"{what}: expected {{'points': [{{'x': ..., ...}}, ...]}}")
    _check_points(len(pts), 1, what)
    flat: list[object] = []
    for k, p in enumerate(pts):
        if not isinstance(p, dict):
            raise SceneError(f"{what}: point {k + 1} is not an object")
        vals = p.get(keys[0])
        vals = vals if isinstance(vals, list) else [vals]
        if len(vals) != width:
            raise SceneError(f"{what}: point {k + 1} needs {width} value(s) in {keys[0]!r}")
        flat += [p.get("x"), *vals, p.get("midpoint", 0.5), p.get("sharpness", 0.0)]
    return _rows(_numbers(flat, what), width + 3, what)


def slicer_vp(text: str, path: str = "") -> list[ImportedMap]:
    """A Slicer ``.vp`` file: six property lines, then scalar opacity, gradient opacity
    and colour transfer (vtkMRMLVolumePropertyStorageNode::WriteData)."""
    lines = text.splitlines()
    if len(lines) < 9:
        raise SceneError(
            f"{path}: a Slicer .vp file has 9 lines (6 properties, scalar opacity, gradient"
            f" opacity, colour transfer); this one has {len(lines)}"
        )
    name = os.path.splitext(os.path.basename(path))[0] or "slicer"
    return [_slicer_map(name, lines[6], lines[8], path or "vp")]


# ---------------------------------------------------------------------------- dispatch
def read_file(path: str) -> tuple[list[ImportedMap] | None, object]:
    """Read a transfer function file once: ``(maps, None)`` for a ParaView JSON or Slicer
    XML/.vp/.vp.json file; ``(None, doc)`` for voxwarp's own JSON (``doc`` parsed)."""
    text = read_text(path)
    kind = file_kind(text, path)
    if kind == "slicer-xml":
        return slicer_presets(text, path), None
    if kind == "slicer-vp":
        return slicer_vp(text, path), None
    doc = parse_json(text, path)
    if is_slicer_json(doc):
        return slicer_json(doc, path), None  # type: ignore[arg-type]
    if is_paraview(doc):
        return paraview_maps(doc, path), None
    return None, doc


def usable(maps: Sequence[ImportedMap]) -> list[ImportedMap]:
    """The maps of a file that can be used (not categorical or broken)."""
    return [m for m in maps if m.error is None]


def pick(maps: Sequence[ImportedMap], name: str | None, path: str = "") -> ImportedMap:
    """The map called ``name`` (exact, then case-insensitive); the first usable when None.
    Picking an unusable map raises its error."""
    good = usable(maps)
    if name is None:
        return good[0]
    for test in (lambda m: m.name == name, lambda m: m.name.lower() == name.lower()):
        hits = [m for m in maps if test(m)]
        if hits:
            if hits[0].error:
                raise SceneError(hits[0].error)
            return hits[0]
    shown = ", ".join(m.name for m in good[:40]) + (" ..." if len(good) > 40 else "")
    left = len(maps) - len(good)
    extra = f" ({left} categorical or broken maps left out)" if left else ""
    raise SceneError(f"{path} has no map {name!r}; names: {shown}{extra}")


# ---------------------------------------------------------------------------- matplotlib
def colormap_colours(name: str) -> np.ndarray | None:
    """``(n, 4)`` rows ``t, r, g, b`` (t in [0, 1]) of matplotlib colour map ``name``,
    or None when matplotlib has no such map. Requires matplotlib (ImportError otherwise).

    The map's ``N`` colours at ``t = i / (N - 1)`` (a listed map's own colours), thinned to
    the fewest that keep every one within :data:`COLORMAP_TOLERANCE` when interpolated
    (:func:`voxwarp.core.tf_curves.simplify`): viridis keeps 23 of 256, tab10 all 10.
    """
    import matplotlib

    try:
        cmap = matplotlib.colormaps[name]
    except KeyError:
        return None
    t = np.linspace(0.0, 1.0, max(int(getattr(cmap, "N", 256)), 2))
    rgb = np.asarray(cmap(t), dtype=np.float64)[:, :3]
    keep = tf_curves.simplify(t, rgb, COLORMAP_TOLERANCE)
    return np.column_stack([t[keep], rgb[keep]])


def colormap_names() -> list[str]:
    """matplotlib's colour-map names (empty without matplotlib)."""
    try:
        import matplotlib
    except ImportError:
        return []
    return sorted(matplotlib.colormaps)


# ---------------------------------------------------------------------------- conversion
def looks_normalised(xs: np.ndarray) -> bool:
    """The rule for ParaView ranges: first x 0 or -1 and last x 1 (ParaView's presets)."""
    return bool(xs.size) and float(xs[-1]) == 1.0 and float(xs[0]) in (0.0, -1.0)


def to_control_points(
    m: ImportedMap,
    window: tuple[float, float] | None = None,
    reference_mm: float | None = None,
) -> tuple[list[tuple[float, float, float, float, float]], bool]:
    """voxwarp control points ``(value, r, g, b, a)`` for ``m``, and whether it was mapped
    onto ``window``.

    ``window`` ``(lo, hi)``: the volume's default window; matplotlib maps always, and
    ParaView maps whose x run 0..1 or -1..1 (:func:`looks_normalised`), are stretched
    onto it. ``reference_mm``: voxwarp's reference sample distance; a Slicer opacity
    (per :attr:`ImportedMap.unit_distance` mm) becomes ``1 - (1 - a) ** (ref / unit)``.
    Colour and opacity points are merged: each x of either gets both, interpolated.
    """
    colour = m.colour
    opacity = m.opacity if m.opacity is not None else _ramp(colour[0, 0], colour[-1, 0])
    xs_all = np.concatenate([colour[:, 0], opacity[:, 0]])
    mapped = window is not None and (
        m.kind == "matplotlib" or (m.kind == "paraview" and looks_normalised(np.sort(xs_all)))
    )
    if mapped:
        lo, hi = window  # type: ignore[misc]
        x0, x1 = float(np.min(xs_all)), float(np.max(xs_all))
        scale = (hi - lo) / (x1 - x0) if x1 > x0 else 0.0
        colour = np.column_stack([lo + (colour[:, 0] - x0) * scale, colour[:, 1:]])
        opacity = np.column_stack([lo + (opacity[:, 0] - x0) * scale, opacity[:, 1]])
    a = opacity[:, 1]
    if m.unit_distance and reference_mm:
        a = 1.0 - np.power(1.0 - np.clip(a, 0.0, 1.0), reference_mm / m.unit_distance)
    return _merge(colour, np.column_stack([opacity[:, 0], a])), mapped


def _ramp(x0: float, x1: float) -> np.ndarray:
    return np.array([[x0, 0.0], [x1 if x1 > x0 else x0 + 1.0, RAMP_OPACITY]])


def _sides(rows: np.ndarray, x: float) -> tuple[np.ndarray, np.ndarray]:
    """Values of piecewise-linear ``rows`` (x, values...) just below and just above ``x``:
    equal unless ``x`` repeats in ``rows`` (a step: the first and the last of the run)."""
    hits = np.nonzero(rows[:, 0] == x)[0]
    if hits.size:
        return rows[hits[0], 1:], rows[hits[-1], 1:]
    v = np.array([np.interp(x, rows[:, 0], rows[:, c]) for c in range(1, rows.shape[1])])
    return v, v


def _merge(colour: np.ndarray, opacity: np.ndarray) -> list[tuple[float, ...]]:
    """Control points at every x of either list, colour and opacity interpolated; a step
    (repeated x) in either becomes two points at that x, as VTK draws it."""
    pts: list[tuple[float, ...]] = []
    for x in np.unique(np.concatenate([colour[:, 0], opacity[:, 0]])):
        (c0, c1), (a0, a1) = _sides(colour, x), _sides(opacity, x)
        pts.append((float(x), *map(float, c0), float(a0[0])))
        if not (np.array_equal(c0, c1) and np.array_equal(a0, a1)):
            pts.append((float(x), *map(float, c1), float(a1[0])))
    return pts
