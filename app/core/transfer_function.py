"""Transfer functions: data value -> colour and opacity.

A :class:`TransferFunction` is a piecewise-linear list of control points
``(value, r, g, b, a)`` with ``value`` in data units and components in [0, 1].
Opacity ``a`` is the opacity of one *reference* sample distance (one voxel of the
smallest spacing); the raycaster corrects it for the actual sample distance
``d`` by ``1 - (1 - a) ** (d / reference)``, so changing the sample distance changes
quality, not brightness.

Presets
-------
``ct-bone``, ``ct-skin``, ``ct-soft`` and ``ct-muscle`` are defined in Hounsfield units.
On a volume whose values are not HU (:func:`voxwarp.core.modality_detection.is_hu`), they
are rescaled from [-1000, 2000] HU onto the volume's 0.5-99.5 percentile range, with a
warning. ``mri``, ``grayscale`` and ``hot`` are relative: defined on [0, 1] and mapped
onto the volume's percentile range.

Any other name is looked up as a **matplotlib colour map** (``viridis``, ``magma_r``...;
needs matplotlib, the ``teach`` extra): its colours (the fewest control points that keep
every colour of the map within 1/255, see
:func:`~voxwarp.core.tf_formats.colormap_colours`) over the same percentile range, with
opacity rising linearly from 0 to :data:`~voxwarp.core.tf_formats.RAMP_OPACITY`. Preset
names win (``hot`` is voxwarp's).

Files
-----
:meth:`TransferFunction.load` reads voxwarp's JSON, ParaView colour-map JSON and 3D Slicer
``presets.xml`` / ``.vp`` files (see :mod:`voxwarp.core.tf_formats` and
docs/transfer-functions.md for the conversion rules); ``FILE:NAME`` picks one map of a
file holding several.
"""

from __future__ import annotations

import importlib.util
import os
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from voxwarp.core import tf_formats
from voxwarp.core.modality_detection import is_hu
from voxwarp.core.volume import Volume
from voxwarp.errors import SceneError

ControlPoint = tuple[float, float, float, float, float]

_HU_PRESETS: dict[str, list[ControlPoint]] = {
    "ct-bone": [
        (-1000, 0, 0, 0, 0),
        (150, 0.55, 0.25, 0.15, 0.0),
        (300, 0.9, 0.75, 0.55, 0.25),
        (700, 1.0, 0.95, 0.85, 0.6),
        (2000, 1.0, 1.0, 1.0, 0.85),
    ],
    "ct-skin": [
        (-1000, 0, 0, 0, 0),
        (-600, 0.8, 0.55, 0.45, 0.0),
        (-400, 0.9, 0.65, 0.55, 0.35),
        (100, 1.0, 0.8, 0.7, 0.5),
        (400, 1.0, 0.95, 0.9, 0.6),
        (2000, 1.0, 1.0, 1.0, 0.9),
    ],
    "ct-soft": [
        (-1000, 0, 0, 0, 0),
        (-100, 0.75, 0.45, 0.3, 0.0),
        (40, 0.85, 0.35, 0.3, 0.08),
        (200, 0.95, 0.8, 0.6, 0.15),
        (600, 1.0, 0.95, 0.9, 0.6),
        (2000, 1.0, 1.0, 1.0, 0.85),
    ],
    "ct-muscle": [
        (-1000, 0, 0, 0, 0),
        (-50, 0.6, 0.1, 0.1, 0.0),
        (40, 0.8, 0.25, 0.2, 0.12),
        (120, 0.9, 0.5, 0.4, 0.2),
        (500, 1.0, 0.95, 0.9, 0.7),
        (2000, 1.0, 1.0, 1.0, 0.85),
    ],
}

_RELATIVE_PRESETS: dict[str, list[ControlPoint]] = {
    "mri": [
        (0.0, 0, 0, 0, 0),
        (0.2, 0.6, 0.4, 0.35, 0.0),
        (0.45, 0.85, 0.7, 0.6, 0.08),
        (0.75, 1.0, 0.9, 0.8, 0.35),
        (1.0, 1.0, 1.0, 1.0, 0.7),
    ],
    "grayscale": [(0.0, 0, 0, 0, 0), (1.0, 1, 1, 1, 0.5)],
    "hot": [
        (0.0, 0, 0, 0, 0),
        (0.3, 0.8, 0.0, 0.0, 0.05),
        (0.6, 1.0, 0.6, 0.0, 0.3),
        (1.0, 1.0, 1.0, 0.8, 0.8),
    ],
}

PRESETS: tuple[str, ...] = (*_HU_PRESETS, *_RELATIVE_PRESETS)

#: Number of entries of the GPU lookup table.
TABLE_SIZE = 4096
#: Keys of a transfer function entry (scene JSON, tf.json).
_TF_KEYS = {"name", "points", "preset"}


def _points(points: Iterable[Sequence[float]]) -> list[ControlPoint]:
    try:
        arr = np.asarray([tuple(p) for p in points], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise SceneError(
            "transfer function control points must be (value, r, g, b, a) number tuples"
        ) from exc
    if arr.ndim != 2 or arr.shape[1] != 5 or arr.shape[0] < 1:
        raise SceneError(
            "a transfer function needs at least one control point (value, r, g, b, a);"
            f" got an array of shape {arr.shape}"
        )
    if not np.all(np.isfinite(arr)):
        raise SceneError("transfer function control points contain NaN/Inf")
    if np.any(arr[:, 1:] < 0) or np.any(arr[:, 1:] > 1):
        raise SceneError("transfer function colour and opacity components must lie in [0, 1]")
    order = np.argsort(arr[:, 0], kind="stable")
    return [tuple(float(x) for x in row) for row in arr[order]]  # type: ignore[misc]


@dataclass(eq=False)
class TransferFunction:
    """Piecewise-linear colour + opacity over data values (see module docstring).

    Parameters
    ----------
    points
        Control points ``(value, r, g, b, a)``; sorted by value on construction.
    name
        Preset name or ``"custom"``.
    """

    points: list[ControlPoint]
    name: str = "custom"

    def __post_init__(self) -> None:
        self.points = _points(self.points)

    # ------------------------------------------------------------------ construction
    @classmethod
    def preset(cls, name: str, volume: Volume | None = None) -> TransferFunction:
        """A named preset resolved to the data units of ``volume`` (see module docstring)."""
        if name in _HU_PRESETS:
            pts = _HU_PRESETS[name]
            if volume is not None and not is_hu(volume):
                lo, hi = _percentile_range(volume)
                warnings.warn(
                    f"preset {name!r} is in Hounsfield units but volume {volume.name!r} is"
                    f" not (values {volume.value_range[0]:g}..{volume.value_range[1]:g});"
                    f" rescaled from [-1000, 2000] HU to [{lo:g}, {hi:g}].",
                    stacklevel=2,
                )
                pts = [
                    (lo + (v + 1000.0) / 3000.0 * (hi - lo), r, g, b, a) for v, r, g, b, a in pts
                ]
            return cls(list(pts), name=name)
        if name in _RELATIVE_PRESETS:
            lo, hi = _percentile_range(volume) if volume is not None else (0.0, 1.0)
            pts = [(lo + v * (hi - lo), r, g, b, a) for v, r, g, b, a in _RELATIVE_PRESETS[name]]
            return cls(pts, name=name)
        tf = _colormap(name, volume)
        if tf is not None:
            return tf
        raise SceneError(_unknown_name(name))

    @classmethod
    def coerce(cls, tf: Any, volume: Volume | None = None) -> TransferFunction:
        """Accept a TransferFunction, a preset or matplotlib colour-map name, a list of
        points or a dict (:meth:`from_dict`). Files: :meth:`load`."""
        if isinstance(tf, TransferFunction):
            return tf
        if isinstance(tf, str):
            return cls.preset(tf, volume)
        if isinstance(tf, Mapping):
            return cls.from_dict(tf, volume)
        if tf is None:
            raise SceneError("transfer_function must be a preset name or control points, not None")
        try:
            points = list(tf)
        except TypeError:
            raise SceneError(
                f"transfer_function must be a preset name, a file, control points"
                f" [(value, r, g, b, a), ...] or a TransferFunction; got {type(tf).__name__}"
            ) from None
        return cls(points)

    # ------------------------------------------------------------------ evaluation
    @property
    def value_range(self) -> tuple[float, float]:
        """``(first, last)`` control point values (a non-empty interval)."""
        lo, hi = self.points[0][0], self.points[-1][0]
        if hi <= lo:
            hi = lo + 1.0
        return lo, hi

    def __call__(self, values: np.ndarray | float) -> np.ndarray:
        """RGBA (..., 4) at data ``values``, linear between points, clamped outside."""
        v = np.asarray(values, dtype=np.float64)
        pts = np.asarray(self.points)
        out = np.empty((*v.shape, 4))
        for c in range(4):
            out[..., c] = np.interp(v, pts[:, 0], pts[:, c + 1])
        return out

    def table(self, size: int = TABLE_SIZE) -> np.ndarray:
        """RGBA float32 table (size, 4) sampling :attr:`value_range` uniformly."""
        lo, hi = self.value_range
        return self(np.linspace(lo, hi, size)).astype(np.float32)

    def gpu_table(self, ratio: float = 1.0, size: int = TABLE_SIZE) -> np.ndarray:
        """The raycaster's (2, size, 4) float32 table over :attr:`value_range`.

        Row 0 is premultiplied colour with opacity corrected for a sample distance of
        ``ratio`` reference distances (``1 - (1 - a) ** ratio``); row 1 is the straight
        colour and opacity.
        """
        straight = self.table(size)
        a = 1.0 - np.power(np.clip(1.0 - straight[:, 3], 0.0, 1.0), ratio)
        premul = np.concatenate([straight[:, :3] * a[:, None], a[:, None]], axis=1)
        return np.stack([premul, straight]).astype(np.float32)

    def visible_ranges(self, lo: np.ndarray, hi: np.ndarray, size: int = TABLE_SIZE) -> np.ndarray:
        """True where the table has non-zero opacity anywhere in ``[lo, hi]`` (conservative).

        Used for empty-space skipping: a block whose value range is invisible is skipped.
        """
        alpha = self.table(size)[:, 3]
        tlo, thi = self.value_range
        scale = (size - 1) / (thi - tlo)
        # prefix count of visible entries answers "any visible in [i0, i1]" in O(1)
        csum = np.concatenate([[0], np.cumsum(alpha > 0)])
        lo, hi = np.asarray(lo), np.asarray(hi)
        if lo.dtype.kind in "ui" and lo.dtype.itemsize <= 2 and lo.dtype == hi.dtype:
            # integer data: per possible value, a lookup table (two gathers per element
            # instead of float arithmetic on every element)
            info = np.iinfo(lo.dtype)
            values = np.arange(info.min, info.max + 1, dtype=np.float64)
            i0 = np.clip(np.floor((values - tlo) * scale), 0, size - 1).astype(np.int64)
            i1 = np.clip(np.ceil((values - tlo) * scale), 0, size - 1).astype(np.int64)
            before_lo = csum[i0].astype(np.int32)  # visible entries below lo's index
            through_hi = csum[i1 + 1].astype(np.int32)  # visible entries up to hi's index
            if info.min:
                lo = lo.astype(np.int32) - info.min
                hi = hi.astype(np.int32) - info.min
            return through_hi[hi] > before_lo[lo]
        i0 = np.clip(np.floor((lo - tlo) * scale), 0, size - 1).astype(np.int64)
        i1 = np.clip(np.ceil((hi - tlo) * scale), 0, size - 1).astype(np.int64)
        return (csum[i1 + 1] - csum[i0]) > 0

    def first_visible_value(self) -> float:
        """Lowest data value with non-zero opacity (the FLM threshold default)."""
        pts = np.asarray(self.points)
        nz = np.nonzero(pts[:, 4] > 0)[0]
        if nz.size == 0:
            return float(pts[-1, 0])
        i = int(nz[0])
        return float(pts[i - 1, 0]) if i > 0 else float(pts[0, 0])

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict[str, Any]:
        """``{"name": ..., "points": [[value, r, g, b, a], ...]}`` (resolved data units)."""
        return {"name": self.name, "points": [list(p) for p in self.points]}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], volume: Volume | None = None) -> TransferFunction:
        """Inverse of :meth:`to_dict`; ``{"preset": name}`` is resolved against ``volume``.

        Unknown keys are an error listing the allowed ones (as for scenes and cameras).
        """
        unknown = set(d) - _TF_KEYS if isinstance(d, Mapping) else set()
        if unknown:
            raise SceneError(
                f"unknown transfer function keys {sorted(unknown)}; an entry has 'points' or"
                f" 'preset' (allowed keys: {', '.join(sorted(_TF_KEYS))})"
            )
        if "points" in d:
            return cls(d["points"], name=str(d.get("name", "custom")))
        if "preset" in d:
            return cls.preset(str(d["preset"]), volume)
        raise SceneError("a transfer function entry needs 'points' or 'preset'")

    @classmethod
    def load(
        cls, path: str, volume: Volume | None = None, name: str | None = None
    ) -> TransferFunction:
        """Read a transfer function file: voxwarp JSON (``to_dict`` form or a bare list of
        points), ParaView colour-map JSON, or a Slicer ``presets.xml``, ``.vp`` or ``.vp.json``.

        ``path`` may end in ``:NAME`` (an existing file, then a map name) to pick a map of
        a file holding several, as ``name`` does; without either the first is taken, with
        a warning naming the others. ``volume`` resolves ``{"preset": ...}``, stretches
        normalised ParaView maps onto its default window and converts Slicer opacities to
        its reference sample distance (see :func:`voxwarp.core.tf_formats.to_control_points`).
        """
        spec = file_spec(path)
        if spec is not None:
            path, name = spec[0], name if name is not None else spec[1]
        maps, doc = tf_formats.read_file(path)
        if maps is None:
            return cls._from_voxwarp_json(doc, path, volume)
        good = tf_formats.usable(maps)
        if name is None and len(good) > 1:
            warnings.warn(
                f"{path} holds {len(good)} maps; using the first, {good[0].name!r} (pick one"
                f" with {path}:NAME; names: {', '.join(m.name for m in good[:12])}"
                + (" ...)" if len(good) > 12 else ")"),
                stacklevel=2,
            )
        return cls._from_imported(tf_formats.pick(maps, name, path), volume)

    @classmethod
    def _from_voxwarp_json(cls, d: Any, path: str, volume: Volume | None) -> TransferFunction:
        if not isinstance(d, Mapping | list):
            raise SceneError(f"{path}: expected a JSON object or list of control points")
        try:
            return cls(d) if isinstance(d, list) else cls.from_dict(d, volume)
        except SceneError as exc:  # name the file: the message is about its content
            raise SceneError(f"{path}: {exc}") from exc

    @classmethod
    def _from_imported(cls, m: tf_formats.ImportedMap, volume: Volume | None) -> TransferFunction:
        window = _percentile_range(volume) if volume is not None else None
        ref = float(min(volume.spacing)) if volume is not None else None
        pts, _mapped = tf_formats.to_control_points(m, window, ref)
        for note in m.notes:
            warnings.warn(f"{m.kind} map {m.name!r}: {note}", stacklevel=3)
        if m.kind == "slicer" and m.name.upper().startswith("CT") and volume is not None:
            if not is_hu(volume):
                lo, hi = volume.value_range
                warnings.warn(
                    f"Slicer preset {m.name!r} is in Hounsfield units but volume"
                    f" {volume.name!r} is not (values {lo:g}..{hi:g}); its points are kept,"
                    " so it may show little or a haze (try a voxwarp preset or a colour map)",
                    stacklevel=3,
                )
        return cls(pts, name=m.name)

    @staticmethod
    def map_names(path: str) -> list[str]:
        """Names of the usable maps in a ParaView / Slicer file (categorical ParaView maps
        left out); ``[]`` for voxwarp JSON."""
        maps, _doc = tf_formats.read_file(path)
        return [m.name for m in tf_formats.usable(maps or [])]


#: File suffixes ``--tf`` treats as a file even before it exists (so a typo says so).
TF_FILE_SUFFIXES = (".json", ".xml", ".vp")


def file_spec(spec: str) -> tuple[str, str | None] | None:
    """``(path, map name or None)`` when ``spec`` names a file, else None (a name).

    A file is: an existing path; ``EXISTING:NAME``; or a path ending in
    :data:`TF_FILE_SUFFIXES` (``FILE.json:NAME`` too). Preset names are never files.
    """
    if spec in PRESETS or not spec:
        return None
    if os.path.exists(spec):
        return spec, None
    parts = spec.split(":")
    for i in range(1, len(parts)):  # the shortest existing file: a map name may hold ':'
        head = ":".join(parts[:i])
        if os.path.isfile(head):
            return head, ":".join(parts[i:]) or None
    head, sep, tail = spec.rpartition(":")
    if sep and head and (os.path.exists(head) or head.lower().endswith(TF_FILE_SUFFIXES)):
        return head, tail or None
    if spec.lower().endswith(TF_FILE_SUFFIXES) or os.sep in spec or "/" in spec:
        return spec, None
    return None


def _colormap(name: str, volume: Volume | None) -> TransferFunction | None:
    """matplotlib colour map ``name`` as a ramp over the volume's window, None if unknown."""
    if not colormaps_available():
        return None
    colours = tf_formats.colormap_colours(name)
    if colours is None:
        return None
    m = tf_formats.ImportedMap(name, colours, None, "matplotlib")
    window = _percentile_range(volume) if volume is not None else (0.0, 1.0)
    pts, _ = tf_formats.to_control_points(m, window)
    return TransferFunction(pts, name=name)


def colormaps_available() -> bool:
    """Whether matplotlib colour-map names work here (matplotlib, of the ``teach`` extra)."""
    return importlib.util.find_spec("matplotlib") is not None


def _unknown_name(name: str) -> str:
    import difflib

    have_mpl = colormaps_available()
    known = list(dict.fromkeys([*PRESETS, *(tf_formats.colormap_names() if have_mpl else [])]))
    by_lower = {k.lower(): k for k in reversed(known)}  # the first spelling of each name
    close = [by_lower[k] for k in difflib.get_close_matches(name.lower(), list(by_lower), n=3)]
    hint = f" (did you mean {', '.join(close)}?)" if close else ""
    maps = (
        "a matplotlib colour-map name (viridis, magma, ...)"
        if have_mpl
        else "a matplotlib colour-map name (needs matplotlib: pip install 'voxwarp[teach]')"
    )
    return (
        f"unknown transfer function preset {name!r}{hint}; presets: {', '.join(PRESETS)};"
        f" or {maps}, a transfer function file (voxwarp or ParaView .json, Slicer .xml/.vp),"
        " or a list of (value, r, g, b, a) control points"
    )


def _percentile_range(volume: Volume) -> tuple[float, float]:
    level, window = volume.default_window()
    return level - window / 2, level + window / 2
