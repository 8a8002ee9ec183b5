"""The ``det J`` overlay: a colour map on ``log2(det J)`` over slices and 3D renders.

How to read it
--------------
``det J`` is the Jacobian determinant of the warp chain at the point a pixel (or a ray
sample) shows (:mod:`voxwarp.core.jacobian`): the chain pulls a deformed point back to
the original volume, so ``det J < 1`` means the picture shows that neighbourhood
*enlarged* (expansion, warm :data:`EXPANSION_RGB`), ``det J > 1`` *shrunk*
(compression, blue :data:`COMPRESSION_RGB`), ``det J = 1`` unchanged volume
(transparent: the grey image shows through), and ``det J <= 0`` a fold (solid
:data:`FOLD_RGB`, whatever the opacity). The colour's opacity grows with
``|log2 det J|`` up to :attr:`JacobianOverlay.log2_range` (default 1: ``det J`` 0.5
and 2 at full strength), times :attr:`JacobianOverlay.opacity`.

The same map runs on the CPU (:func:`detj_rgba`, slices) and in GLSL
(``shaders/jacobian_overlay.glsl``, the raycaster); :func:`draw_legend` draws the
colour bar with its ticks, ``det J`` and the fold swatch into an image.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from voxwarp.core.jacobian import point_determinant
from voxwarp.errors import RenderError
from voxwarp.render.bitmap_font import text_mask

#: colour (RGB in [0, 1]) of ``det J < 1`` (the picture shows the region enlarged)
EXPANSION_RGB: tuple[float, float, float] = (1.0, 0.35, 0.1)
#: colour of ``det J > 1`` (the picture shows the region shrunk)
COMPRESSION_RGB: tuple[float, float, float] = (0.15, 0.5, 1.0)
#: solid colour of folds, ``det J <= 0``
FOLD_RGB: tuple[float, float, float] = (0.1, 1.0, 0.1)
#: default strength of the colour at full ``|log2 det J|``
DEFAULT_OPACITY = 0.6


@dataclass(frozen=True)
class JacobianOverlay:
    """How the ``det J`` overlay is drawn: ``opacity`` (0..1) of the colour at
    ``|log2 det J| >= log2_range`` (> 0); folds are always opaque."""

    opacity: float = DEFAULT_OPACITY
    log2_range: float = 1.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.opacity) and 0.0 <= self.opacity <= 1.0):
            raise RenderError(f"overlay opacity must be in 0..1; got {self.opacity}")
        if not (math.isfinite(self.log2_range) and self.log2_range > 0):
            raise RenderError(f"det J overlay log2 range must be > 0; got {self.log2_range}")

    def uniforms(self) -> dict[str, Any]:
        """The uniforms of ``shaders/jacobian_overlay.glsl``."""
        return {
            "u_detj_opacity": float(self.opacity),
            "u_detj_range": float(self.log2_range),
            "u_detj_expansion": EXPANSION_RGB,
            "u_detj_compression": COMPRESSION_RGB,
            "u_detj_fold": FOLD_RGB,
        }


def detj_rgba(det: np.ndarray, overlay: JacobianOverlay) -> np.ndarray:
    """``(..., 4)`` float32 colour and opacity of ``det J`` values (NaN: opacity 0)."""
    shape = np.shape(det)
    d = np.asarray(det, dtype=np.float32).reshape(-1)
    out = np.empty((d.size, 4), dtype=np.float32)
    with np.errstate(invalid="ignore", divide="ignore"):
        pos = d > 0
        level = np.log2(np.where(pos, d, np.float32(1)))
        level *= np.float32(1.0 / overlay.log2_range)
        np.clip(level, -1.0, 1.0, out=level)
        expand = level < 0
        for k in range(3):
            out[:, k] = np.where(expand, EXPANSION_RGB[k], COMPRESSION_RGB[k])
        np.abs(level, out=level)
        level *= np.float32(overlay.opacity)
        out[:, 3] = np.where(pos, level, np.float32(0))
        fold = d <= 0
    out[fold] = (*FOLD_RGB, 1.0)
    return out.reshape(*shape, 4)


def blend_detj(rgba: np.ndarray, det: np.ndarray, overlay: JacobianOverlay) -> np.ndarray:
    """Blend the overlay of ``det`` (H, W) over ``rgba`` (H, W, 4) uint8, in place."""
    c = detj_rgba(det, overlay)
    a = c[..., 3:4]
    rgb = rgba[..., :3].astype(np.float32)
    rgb *= 1 - a
    c[..., :3] *= a * np.float32(255)
    rgb += c[..., :3]
    rgb += np.float32(0.5)
    np.clip(rgb, 0, 255, out=rgb)
    rgba[..., :3] = rgb.astype(np.uint8)
    return rgba


# ---------------------------------------------------------------- the legend
def _put(img: np.ndarray, mask: np.ndarray, x: int, y: int, rgb: tuple[int, ...]) -> None:
    h, w = img.shape[:2]
    mh, mw = mask.shape
    x0, y0, x1, y1 = max(x, 0), max(y, 0), min(x + mw, w), min(y + mh, h)
    if x1 <= x0 or y1 <= y0:
        return
    sub = mask[y0 - y : y1 - y, x0 - x : x1 - x]
    img[y0:y1, x0:x1, :3][sub] = rgb


def _tick_text(v: float) -> str:
    return f"{v:.3g}"


def legend_ticks(overlay: JacobianOverlay) -> list[float]:
    """``det J`` values the colour bar labels: ``2^-r``, 1, ``2^r`` (r the log2 range)."""
    r = overlay.log2_range
    return [2.0**-r, 1.0, 2.0**r]


def _legend_box(w: int, h: int) -> tuple[int, int, int]:
    """Scale, width and height of the legend of a (W, H) image."""
    s = 2 if min(w, h) >= 480 else 1
    bar_w = min(max(w // 3, 60), 96 * s)
    return s, bar_w + 12 * s + 24 * s + text_mask("<=0 fold", s).shape[1], 32 * s


def legend_fits(width: int, height: int) -> bool:
    """Whether an image of ``width`` x ``height`` pixels holds the legend."""
    _, box_w, box_h = _legend_box(int(width), int(height))
    return box_w <= width and box_h <= height


#: corners the legend may sit in
LEGEND_CORNERS: tuple[str, ...] = ("bottom-right", "top-right")


def draw_legend(
    rgba: np.ndarray, overlay: JacobianOverlay, corner: str = "bottom-right"
) -> np.ndarray:
    """Draw the colour bar (``det J`` from ``2^-r`` to ``2^r``, ticks and labels) and the
    fold swatch in a corner (:data:`LEGEND_CORNERS`) of ``rgba`` (H, W, 3|4), uint8 or
    float in [0, 1], in place (nothing on an image too small to hold it)."""
    if corner not in LEGEND_CORNERS:
        raise RenderError(f"legend corner must be one of {', '.join(LEGEND_CORNERS)}")
    h, w = rgba.shape[:2]
    s, box_w, box_h = _legend_box(w, h)
    if not legend_fits(w, h):
        return rgba
    rows = slice(h - box_h, h) if corner == "bottom-right" else slice(0, box_h)
    region = rgba[rows, w - box_w :]
    if rgba.dtype == np.uint8:
        _draw_legend_u8(region, overlay, s)
        return rgba
    tmp = (np.clip(region[..., :3], 0, 1) * 255 + 0.5).astype(np.uint8)
    _draw_legend_u8(tmp, overlay, s)
    region[..., :3] = tmp / 255.0
    return rgba


def _draw_legend_u8(box: np.ndarray, overlay: JacobianOverlay, s: int) -> None:
    """The legend filling ``box`` (its (h, w, 3|4) uint8 region of the image)."""
    pad, bar_h = 4 * s, 6 * s
    bar_w = box.shape[1] - 12 * s - 24 * s - text_mask("<=0 fold", s).shape[1]
    box[..., :3] = (box[..., :3].astype(np.float32) * 0.35).astype(np.uint8)  # backdrop
    grey = np.full((bar_h, bar_w, 4), 128, np.uint8)
    det = np.broadcast_to(
        2.0 ** (np.linspace(-1.0, 1.0, bar_w) * overlay.log2_range), grey.shape[:2]
    )
    bar = blend_detj(grey, det, JacobianOverlay(opacity=1.0, log2_range=overlay.log2_range))
    bx, by = pad, pad + 8 * s
    box[by : by + bar_h, bx : bx + bar_w, :3] = bar[..., :3]
    white = (235, 235, 235)
    _put(box, text_mask("det J", s), bx, pad, white)
    for v in legend_ticks(overlay):
        tx = bx + round((np.log2(v) / overlay.log2_range + 1) / 2 * (bar_w - 1))
        box[by + bar_h : by + bar_h + 2 * s, tx : tx + s, :3] = white
        m = text_mask(_tick_text(v), s)
        x = min(max(tx - m.shape[1] // 2, bx), bx + bar_w - m.shape[1])
        _put(box, m, x, by + bar_h + 3 * s, white)
    fx = bx + bar_w + 3 * pad
    box[by : by + bar_h, fx : fx + 4 * s + bar_h, :3] = [round(c * 255) for c in FOLD_RGB]
    _put(box, text_mask("<=0 fold", s), fx, by + bar_h + 3 * s, white)


def pixel_centres(pixel_to_world: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """World points (H*W, 3) of the pixel centres of a (W, H) image, row by row."""
    w, h = int(size[0]), int(size[1])
    cols, rows = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    pix = np.stack([cols.ravel(), rows.ravel(), np.zeros(w * h), np.ones(w * h)], axis=1)
    return (pix @ np.asarray(pixel_to_world, dtype=np.float64).T)[:, :3]


def slice_detj(warps: Any, pixel_to_world: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``det J`` (H, W) float32 of the chain ``warps`` at the pixel centres of a slice
    (the points its pixels pull back from); NaN where ``values`` is NaN (no volume)."""
    h, w = values.shape
    det = point_determinant(warps, pixel_centres(pixel_to_world, (w, h))).reshape(h, w)
    return np.where(np.isfinite(values), det, np.nan).astype(np.float32)


#: render modes whose 3D image the overlay tints (the sample a pixel shows)
DETJ_MODES: tuple[str, ...] = ("dvr", "mip", "minip", "iso")


def check_detj_mode(mode: str) -> None:
    """:class:`RenderError` unless the 3D overlay draws in ``mode`` (:data:`DETJ_MODES`)."""
    if mode not in DETJ_MODES:
        raise RenderError(
            f"the jacobian overlay colours the {', '.join(DETJ_MODES)} modes; got mode"
            f" {mode!r}: pick one of those (--mode) or drop --overlay jacobian"
        )
