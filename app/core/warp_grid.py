"""A rest-space grid and displacement glyphs carried by a warp chain (numpy only).

A warp chain maps each deformed point ``x`` to the rest (original) point
``q = chain(x)`` it shows. To see the deformation, draw what the chain does to a
regular grid of the rest space:

* **slices** (:func:`line_coverage`, :func:`grid_coverage`): each pixel samples the rest
  point ``q`` of its centre; a grid line lies where ``q . e / N`` crosses an integer
  (``e`` one of the plane's two in-plane directions, ``N`` the spacing in mm). The
  distance to the line in pixels is ``|s - round(s)| / |grad s|`` (``grad`` over pixel
  columns and rows), so lines keep a constant, antialiased pixel width and bend exactly
  as the anatomy does;
* **glyphs** (:func:`slice_glyphs`): arrows of the displacement ``u(x) = q - x`` (the
  vector an exported field holds, ITK's convention: it points from the deformed point
  to the rest point shown there) at regular points of the plane, in-plane component;
* **3D** (:func:`lattice_lines`): rest-space polylines of a lattice every ``N`` mm (or
  of one plane of it), moved by the chain's forward map when drawn as meshes.

:func:`nice_spacing` gives the default spacing: about 1/16 of the box's largest side,
rounded to 1, 2 or 5 times a power of ten.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from voxwarp.deform.warp import Warp, chain_apply_carried
from voxwarp.errors import InputError

#: Planes of :func:`lattice_lines`: one plane (normal to z, y or x) or the whole lattice.
GRID_PLANES: tuple[str, ...] = ("axial", "coronal", "sagittal", "all")
#: Axis normal to each named plane (world RAS: x right, y anterior, z superior).
PLANE_AXIS = {"axial": 2, "coronal": 1, "sagittal": 0}
#: Default line width in pixels of slice grid lines.
LINE_WIDTH_PX = 1.5
#: A family of lines denser than this many lines per pixel is not drawn there (it
#: would alias into a flat tint; also where the chain tears).
MAX_LINES_PER_PIXEL = 0.5
#: Grid cells per box side of the default spacing.
CELLS_PER_SIDE = 16
#: Fewest pixels between the default grid lines of a slice.
MIN_CELL_PX = 12


def nice_number(value: float) -> float:
    """``value`` rounded (in log scale) to 1, 2 or 5 times a power of ten (> 0)."""
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise InputError(f"a spacing must be a positive number of mm; got {value}")
    k = math.floor(math.log10(v))
    candidates = [m * 10.0**e for e in (k, k + 1) for m in (1, 2, 5)]
    return min(candidates, key=lambda c: abs(math.log(c / v)))


def nice_spacing(lo: Sequence[float], hi: Sequence[float], at_least_mm: float = 0.0) -> float:
    """Default grid spacing in mm: :func:`nice_number` of the box's largest side / 16
    (rounded up to :func:`nice_ceil` of ``at_least_mm`` when smaller, e.g. a slice's
    12 pixels)."""
    side = float(np.max(np.asarray(hi, float) - np.asarray(lo, float)))
    spacing = nice_number(max(side / CELLS_PER_SIDE, 1e-6))
    return spacing if spacing >= at_least_mm else nice_ceil(at_least_mm)


def nice_ceil(value: float) -> float:
    """The smallest 1, 2 or 5 times a power of ten that is >= ``value`` (> 0)."""
    v = nice_number(value)
    k = math.floor(math.log10(v))
    steps = [m * 10.0**e for e in (k, k + 1) for m in (1, 2, 5)]
    return min(c for c in steps if c >= value * (1 - 1e-12))


def check_spacing(spacing: float) -> float:
    """``spacing`` as a float; :class:`InputError` unless finite and > 0."""
    s = float(spacing)
    if not (math.isfinite(s) and s > 0):
        raise InputError(f"the grid spacing must be a positive number of mm; got {spacing}")
    return s


def pixel_points(pixel_to_world: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(H, W, 3) world centres of the pixels of a slice (``pixel_to_world``: 4x4,
    ``(col, row, 0, 1)`` -> world mm of pixel ``[row, col]``)."""
    w, h = (int(v) for v in size)
    m = np.asarray(pixel_to_world, dtype=np.float64)
    cols, rows = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    return cols[..., None] * m[:3, 0] + rows[..., None] * m[:3, 1] + m[:3, 3]


def pull_back(warps: Sequence[Warp], points: np.ndarray) -> np.ndarray:
    """Rest points ``q = chain(x)`` of ``points`` (..., 3); NaN where not carried."""
    p = np.asarray(points, dtype=np.float64)
    flat = p.reshape(-1, 3)
    q, ok = chain_apply_carried(list(warps), flat)
    q = np.array(q, dtype=np.float64)
    q[~np.asarray(ok, bool)] = np.nan
    return q.reshape(p.shape)


def line_coverage(s: np.ndarray, width_px: float = LINE_WIDTH_PX) -> np.ndarray:
    """Antialiased coverage (H, W) in [0, 1] of the lines ``s = integer`` of a
    (H, W) map ``s`` (grid units per pixel position), ``width_px`` pixels wide; 0
    where ``s`` is NaN or its lines are denser than :data:`MAX_LINES_PER_PIXEL`."""
    s = np.asarray(s, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        d_row, d_col = np.gradient(s) if min(s.shape) > 1 else (np.zeros_like(s),) * 2
        slope = np.hypot(d_row, d_col)
        dist = np.abs(s - np.round(s)) / np.maximum(slope, 1e-12)
        cover = np.clip(width_px / 2 + 0.5 - dist, 0.0, 1.0)
        cover[~(slope <= MAX_LINES_PER_PIXEL)] = 0.0
    return np.nan_to_num(cover, nan=0.0)


def grid_coverage(
    rest: np.ndarray,
    directions: Sequence[np.ndarray],
    spacing: float,
    width_px: float = LINE_WIDTH_PX,
) -> np.ndarray:
    """Coverage (H, W) of the rest-space grid lines every ``spacing`` mm along each of
    ``directions`` (world unit vectors), from the pixels' rest points ``rest`` (H, W, 3)."""
    n = check_spacing(spacing)
    cover = np.zeros(rest.shape[:2])
    for e in directions:
        e = np.asarray(e, dtype=np.float64)
        cover = np.maximum(cover, line_coverage(rest @ (e / np.linalg.norm(e)) / n, width_px))
    return cover


@dataclass(frozen=True)
class SliceGlyphs:
    """Arrows of the in-plane displacement on a slice (:func:`slice_glyphs`).

    Attributes: ``tails`` (n, 2) pixel positions ``(col, row)`` of the glyph centres,
    ``vectors_mm`` (n, 2) in-plane ``u`` (mm along the plane's right and up),
    ``px_per_mm`` (arrow pixels per mm of ``u``), ``legend_mm`` (a round length of
    ``u`` for the legend arrow) and ``spacing_px`` (pixels between glyphs).
    """

    tails: np.ndarray
    vectors_mm: np.ndarray
    px_per_mm: float
    legend_mm: float
    spacing_px: float

    def heads(self) -> np.ndarray:
        """(n, 2) pixel positions of the arrow tips (image rows grow downwards)."""
        d = self.vectors_mm * self.px_per_mm
        return self.tails + np.stack([d[:, 0], -d[:, 1]], axis=1)


def slice_glyphs(
    warps: Sequence[Warp],
    pixel_to_world: np.ndarray,
    size: tuple[int, int],
    spacing_mm: float,
    *,
    fill: float = 0.9,
) -> SliceGlyphs:
    """Glyphs every ``spacing_mm`` on a slice (``pixel_to_world``/``size`` as in
    :func:`pixel_points`): ``u = chain(x) - x`` at each glyph centre ``x``, projected on
    the plane; the longest arrow spans ``fill`` of the glyph spacing."""
    m = np.asarray(pixel_to_world, dtype=np.float64)
    px_mm = float(np.linalg.norm(m[:3, 0]))
    step = max(check_spacing(spacing_mm) / px_mm, 4.0)
    w, h = (int(v) for v in size)
    cols = np.arange(step / 2, w, step)
    rows = np.arange(step / 2, h, step)
    cc, rr = np.meshgrid(cols, rows)
    tails = np.stack([cc.ravel(), rr.ravel()], axis=1)
    x = tails[:, :1] * m[:3, 0] + tails[:, 1:] * m[:3, 1] + m[:3, 3]
    u = pull_back(warps, x) - x
    right, up = m[:3, 0] / px_mm, -m[:3, 1] / px_mm  # rows grow downwards
    vec = np.stack([u @ right, u @ up], axis=1)
    keep = np.all(np.isfinite(vec), axis=1)
    tails, vec = tails[keep], vec[keep]
    longest = float(np.max(np.hypot(vec[:, 0], vec[:, 1]), initial=0.0))
    if longest <= 1e-9:
        return SliceGlyphs(tails, vec, 0.0, 0.0, step)
    px_per_mm = fill * step / longest
    return SliceGlyphs(tails, vec, px_per_mm, _legend_length(longest), step)


def _legend_length(longest: float) -> float:
    """A round length (1, 2 or 5 x 10^k mm) not above ``longest``."""
    k = math.floor(math.log10(longest))
    fits = [m * 10.0**e for e in (k - 1, k) for m in (1, 2, 5) if m * 10.0**e <= longest]
    return max(fits)


def lattice_lines(
    lo: Sequence[float],
    hi: Sequence[float],
    spacing: float,
    plane: str = "all",
    *,
    samples_per_cell: int = 4,
) -> list[np.ndarray]:
    """Rest-space polylines (each (n, 3), world mm) of the lattice of lines at
    multiples of ``spacing`` inside the box ``lo..hi``, sampled ``samples_per_cell``
    times per cell so that they bend under the warp. ``plane``: ``"all"`` (the 3D
    lattice) or ``axial``/``coronal``/``sagittal`` (the lines of the plane through the
    box centre normal to z/y/x)."""
    n = check_spacing(spacing)
    if plane not in GRID_PLANES:
        raise InputError(f"--grid-plane must be one of {', '.join(GRID_PLANES)}; got {plane!r}")
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    ticks = [np.arange(math.ceil(lo[i] / n), math.floor(hi[i] / n) + 1) * n for i in range(3)]
    if plane != "all":
        k = PLANE_AXIS[plane]
        ticks[k] = np.array([(lo[k] + hi[k]) / 2])
    lines = []
    for along in range(3):
        if plane != "all" and along == PLANE_AXIS[plane]:
            continue
        count = max(2, math.ceil((hi[along] - lo[along]) / n * samples_per_cell) + 1)
        t = np.linspace(lo[along], hi[along], count)
        a, b = (ax for ax in range(3) if ax != along)
        for va in ticks[a]:
            for vb in ticks[b]:
                p = np.empty((count, 3))
                p[:, along], p[:, a], p[:, b] = t, va, vb
                lines.append(p)
    return lines


__all__ = [
    "GRID_PLANES",
    "LINE_WIDTH_PX",
    "SliceGlyphs",
    "check_spacing",
    "grid_coverage",
    "lattice_lines",
    "line_coverage",
    "nice_ceil",
    "nice_number",
    "nice_spacing",
    "pixel_points",
    "pull_back",
    "slice_glyphs",
]
