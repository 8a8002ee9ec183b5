"""The warped grid and displacement glyphs drawn over slices (numpy, no GL).

:func:`draw_slice_overlays`: over a slice's RGBA, the rest-space grid lines carried by
the chain (:func:`voxwarp.core.warp_grid.grid_coverage` of the pull-back point of each
pixel centre, the point the slice shader samples) and arrows of the in-plane
displacement ``u = chain(x) - x`` with a legend arrow and its length in mm (top right;
:func:`voxwarp.core.warp_grid.slice_glyphs`). :func:`slice_overlay_layer` gives the same
as a premultiplied layer that :func:`composite` puts over any colouring of the slice
(the GUI keeps it while the window/level changes). The 3D counterparts are in
:mod:`voxwarp.render.warp_meshes`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from voxwarp.core.warp_grid import (
    SliceGlyphs,
    grid_coverage,
    pixel_points,
    pull_back,
    slice_glyphs,
)
from voxwarp.deform.warp import Warp
from voxwarp.render.bitmap_font import text_mask

#: Overlays these functions draw (the CLI's ``--overlay`` accepts them).
WARP_OVERLAYS: tuple[str, ...] = ("grid", "glyphs")
#: RGB (0..1) of grid lines and of glyph arrows.
GRID_RGB = (1.0, 0.85, 0.1)
GLYPH_RGB = (0.2, 0.9, 1.0)
#: Coverage opacity of slice grid lines (the anatomy stays readable under them).
GRID_ALPHA = 0.8
#: Fewest pixels between default glyphs on a slice.
MIN_GLYPH_PX = 20


def draw_slice_overlays(
    rgba: np.ndarray,
    warps: Sequence[Warp],
    pixel_to_world: np.ndarray,
    overlays: Sequence[str],
    spacing_mm: float,
    *,
    glyph_spacing_mm: float | None = None,
) -> tuple[np.ndarray, list[str]]:
    """``rgba`` (H, W, 4 uint8) with ``overlays`` (``"grid"``, ``"glyphs"``; others are
    left to their own modules) drawn over it, and one line per overlay saying what
    was drawn. ``spacing_mm``: grid spacing; glyphs every ``glyph_spacing_mm``
    (default the grid spacing)."""
    h, w = np.asarray(rgba).shape[:2]
    layer, notes = slice_overlay_layer(
        warps, pixel_to_world, (w, h), overlays, spacing_mm, glyph_spacing_mm=glyph_spacing_mm
    )
    return composite(rgba, layer), notes


def slice_overlay_layer(
    warps: Sequence[Warp],
    pixel_to_world: np.ndarray,
    size: tuple[int, int],
    overlays: Sequence[str],
    spacing_mm: float,
    *,
    glyph_spacing_mm: float | None = None,
    rest: np.ndarray | None = None,
) -> tuple[np.ndarray, list[str]]:
    """The overlays of a ``size`` (W, H) slice as a premultiplied (H, W, 4) float layer
    (colour 0..255, alpha 0..1; :func:`composite` puts it over a slice) and the notes
    of :func:`draw_slice_overlays`. ``rest``: the pixels' pull-back points if known."""
    w, h = (int(v) for v in size)
    m = np.asarray(pixel_to_world, dtype=np.float64)
    layer = np.zeros((h, w, 4))
    notes = []
    if "grid" in overlays:
        if rest is None:
            rest = pull_back(warps, pixel_points(m, (w, h)))
        cover = grid_coverage(rest, (m[:3, 0], m[:3, 1]), spacing_mm)
        _blend(layer, cover * GRID_ALPHA, GRID_RGB)
        notes.append(f"grid: rest-space lines every {spacing_mm:g} mm")
    if "glyphs" in overlays:
        glyphs = slice_glyphs(warps, m, (w, h), glyph_spacing_mm or glyph_default(m, spacing_mm))
        draw_glyphs(layer, glyphs)
        notes.append(glyph_note(glyphs))
    return layer, notes


def glyph_default(pixel_to_world: np.ndarray, spacing_mm: float) -> float:
    """Default glyph spacing on a slice: the grid spacing, doubled while that is under
    :data:`MIN_GLYPH_PX` pixels (glyphs stay on grid nodes)."""
    px = float(np.linalg.norm(np.asarray(pixel_to_world, dtype=np.float64)[:3, 0]))
    spacing = float(spacing_mm)
    while spacing < MIN_GLYPH_PX * px:
        spacing *= 2
    return spacing


def composite(rgba: np.ndarray, layer: np.ndarray) -> np.ndarray:
    """``layer`` (:func:`slice_overlay_layer`) over ``rgba`` (H, W, 4 uint8): a new
    contiguous uint8 RGBA, alpha kept."""
    out = np.array(rgba, dtype=np.uint8, copy=True)
    a = layer[..., 3:]
    rgb = layer[..., :3] + out[..., :3] * (1.0 - a)
    out[..., :3] = (rgb + 0.5).clip(0, 255).astype(np.uint8)
    return out


def glyph_note(glyphs: SliceGlyphs) -> str:
    """One line: the glyph spacing and the arrow scale (what the legend shows)."""
    if glyphs.px_per_mm <= 0:
        return "glyphs: no in-plane displacement on this plane"
    legend_px = glyphs.legend_mm * glyphs.px_per_mm
    return (
        f"glyphs: arrows of u = chain(x) - x every {glyphs.spacing_px:.3g} px;"
        f" legend: {legend_px:.3g} px = {glyphs.legend_mm:g} mm"
    )


def draw_glyphs(out: np.ndarray, glyphs: SliceGlyphs, rgb: Sequence[float] = GLYPH_RGB) -> None:
    """Arrows (a dark halo under them) and the legend arrow drawn into ``out``
    (H, W, 3 float colour in 0..255, or a premultiplied layer with alpha), in place."""
    if glyphs.px_per_mm <= 0:
        return
    width = 1.5 if glyphs.spacing_px >= 16 else 1.0
    for tail, head in zip(glyphs.tails, glyphs.heads(), strict=True):
        _arrow(out, tail, head, width, rgb)
    _legend(out, glyphs, width, rgb)


def _arrow(out: np.ndarray, tail: np.ndarray, head: np.ndarray, width: float, rgb: Any) -> None:
    """One arrow: a shaft and two barbs (a quarter of its length, at least 3 px and at
    most 0.6 of it); none when shorter than a pixel."""
    d = head - tail
    length = float(np.hypot(*d))
    if length < 1.0:  # under a pixel: no arrow (not a dot on every still glyph)
        return
    segments = [(tail, head)]
    if length >= 2:
        barb = min(max(3.0, length / 4), 0.6 * length) * d / length
        for angle in (0.5, -0.5):
            c, s = np.cos(angle), np.sin(angle)
            back = np.array([c * barb[0] - s * barb[1], s * barb[0] + c * barb[1]])
            segments.append((head, head - back))
    for a, b in segments:
        _segment(out, a, b, width + 1.5, (0.0, 0.0, 0.0), 0.6)
    for a, b in segments:
        _segment(out, a, b, width, rgb, 1.0)


def _segment(
    out: np.ndarray, a: np.ndarray, b: np.ndarray, width: float, rgb: Any, alpha: float
) -> None:
    """Antialiased segment from ``a`` to ``b`` (pixel (col, row) centres), in place."""
    h, w = out.shape[:2]
    pad = width + 1
    c0, c1 = int(max(0, min(a[0], b[0]) - pad)), int(min(w, max(a[0], b[0]) + pad + 1))
    r0, r1 = int(max(0, min(a[1], b[1]) - pad)), int(min(h, max(a[1], b[1]) + pad + 1))
    if c1 <= c0 or r1 <= r0:
        return
    cols, rows = np.meshgrid(np.arange(c0, c1, dtype=float), np.arange(r0, r1, dtype=float))
    d = b - a
    len2 = float(d @ d)
    t = ((cols - a[0]) * d[0] + (rows - a[1]) * d[1]) / len2 if len2 > 0 else 0 * cols
    t = np.clip(t, 0.0, 1.0)
    dist = np.hypot(cols - a[0] - t * d[0], rows - a[1] - t * d[1])
    cover = np.clip(width / 2 + 0.5 - dist, 0.0, 1.0) * alpha
    _blend(out[r0:r1, c0:c1], cover, rgb)


def _legend(out: np.ndarray, glyphs: SliceGlyphs, width: float, rgb: Any) -> None:
    """The legend, top right: an arrow of ``legend_mm`` and its length as text."""
    h, w = out.shape[:2]
    length = glyphs.legend_mm * glyphs.px_per_mm
    scale = 2 if h >= 384 else 1
    text = f"{glyphs.legend_mm:g} mm"
    x0 = w - 8 - 6 * scale * len(text) - 6 - length
    y = 8
    tail = np.array([x0, y + 3.5 * scale])
    _arrow(out, tail, tail + np.array([length, 0.0]), width, rgb)
    _text(out, text, int(x0 + length + 6), y, scale, rgb)


def _text(out: np.ndarray, text: str, x: int, y: int, scale: int, rgb: Any) -> None:
    """``text`` (digits, '.', 'm', ' ') at pixel (x, y) top left, over a dark box."""
    mask = text_mask(text, scale)
    gh, gw = 7 * scale, 6 * scale * len(text)
    h, w = out.shape[:2]
    if x + gw > w or y + gh > h or x < 0 or y < 0:
        return
    box = out[max(0, y - scale) : y + gh + scale, max(0, x - scale) : x + gw]
    _blend(box, np.full(box.shape[:2], 0.6), (0.0, 0.0, 0.0))
    _blend(out[y : y + gh, x : x + mask.shape[1]], mask.astype(float), rgb)


def _blend(region: np.ndarray, alpha: np.ndarray, rgb: Sequence[float]) -> None:
    """``region`` (h, w, 3 or 4; colour 0..255, premultiplied alpha 0..1) <- ``rgb``
    (0..1) over it with coverage ``alpha``."""
    a = np.asarray(alpha, dtype=np.float64)[..., None]
    col = np.asarray(rgb, dtype=np.float64) * 255.0
    region[..., :3] = region[..., :3] * (1 - a) + col * a
    if region.shape[-1] == 4:
        region[..., 3:] = region[..., 3:] * (1 - a) + a


__all__ = [
    "GLYPH_RGB",
    "GRID_ALPHA",
    "GRID_RGB",
    "MIN_GLYPH_PX",
    "WARP_OVERLAYS",
    "composite",
    "draw_glyphs",
    "draw_slice_overlays",
    "glyph_default",
    "glyph_note",
    "slice_overlay_layer",
]
