"""Editing handles drawn into a rendered frame with numpy (no second GL pass).

The desktop viewport draws :class:`~voxwarp.render.overlay.OverlayLayer` batches with
:class:`~voxwarp.render.overlay.OverlayRenderer`; the notebook viewer draws the same
layers into the RGBA array it sends to the browser: points as discs of the layer's size
with a dark ring (as the GL pass draws them), lines one pixel wide. Points behind the eye
are left out. Colours are straight RGBA over the (premultiplied, opaque) frame.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from voxwarp.core.camera import Camera
from voxwarp.render.overlay import OUTLINE_COLOR, OUTLINE_WIDTH, OverlayLayer


def draw_layers(
    image: np.ndarray, layers: Sequence[OverlayLayer], camera: Camera, scale: float = 1.0
) -> np.ndarray:
    """Draw ``layers`` into the (H, W, 4) uint8 ``image`` in place and return it;
    ``scale`` multiplies point sizes (device pixels per CSS pixel)."""
    h, w = image.shape[:2]
    for layer in layers:
        pos, col = layer.validated()
        if len(pos) == 0:
            continue
        xy, front = _project(camera, pos, (w, h))
        colors = np.broadcast_to(col, (len(pos), 4))
        if layer.kind == "points":
            _points(image, xy[front], colors[front], layer.size * scale)
        else:
            ok = front[0::2] & front[1::2]
            _lines(image, xy[0::2][ok], xy[1::2][ok], colors[0::2][ok])
    return image


def _project(
    camera: Camera, pos: np.ndarray, size: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    depth = (pos - camera.eye) @ -camera.rotation[:, 2]
    front = depth > 0 if camera.projection == "perspective" else np.ones(len(pos), bool)
    return camera.project(pos, size), front


def _blend(image: np.ndarray, rows: np.ndarray, cols: np.ndarray, rgba: np.ndarray) -> None:
    """Straight ``rgba`` (N, 4) in [0, 1] over the pixels (rows, cols)."""
    h, w = image.shape[:2]
    ok = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
    rows, cols, rgba = rows[ok], cols[ok], rgba[ok]
    a = rgba[:, 3:4]
    old = image[rows, cols, :3].astype(np.float32)
    new = old * (1 - a) + rgba[:, :3] * 255.0 * a
    image[rows, cols, :3] = np.clip(np.rint(new), 0, 255).astype(np.uint8)


def _points(image: np.ndarray, xy: np.ndarray, colors: np.ndarray, size: float) -> None:
    radius = size / 2
    outer = radius + OUTLINE_WIDTH
    r = int(np.ceil(outer))
    dy, dx = np.mgrid[-r : r + 1, -r : r + 1]
    for (x, y), c in zip(xy, colors, strict=True):
        cx, cy = int(np.floor(x)), int(np.floor(y))
        dist = np.hypot(cx + dx + 0.5 - x, cy + dy + 0.5 - y)
        ring, disc = (dist <= outer) & (dist > radius), dist <= radius
        for mask, rgba in ((ring, (*OUTLINE_COLOR[:3], OUTLINE_COLOR[3] * c[3])), (disc, c)):
            n = int(mask.sum())
            _blend(
                image, cy + dy[mask], cx + dx[mask], np.tile(np.asarray(rgba, np.float32), (n, 1))
            )


def _lines(image: np.ndarray, a: np.ndarray, b: np.ndarray, colors: np.ndarray) -> None:
    if len(a) == 0:
        return
    lim = max(image.shape[:2])
    a = np.clip(a, -lim, 2 * lim)  # far off-screen ends would make huge sample counts
    b = np.clip(b, -lim, 2 * lim)
    n = np.maximum(np.ceil(np.abs(b - a).max(axis=1)), 1).astype(int)
    seg = np.repeat(np.arange(len(a)), n + 1)
    first = np.repeat(np.cumsum(n + 1) - (n + 1), n + 1)  # index of each segment's start
    t = (np.arange(len(seg)) - first) / n[seg]
    p = a[seg] + (b[seg] - a[seg]) * t[:, None]
    cols, rows = np.floor(p[:, 0]).astype(int), np.floor(p[:, 1]).astype(int)
    _blend(image, rows, cols, colors[seg].astype(np.float32))
