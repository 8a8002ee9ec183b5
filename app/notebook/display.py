"""Inline pictures of scenes in Jupyter (IPython's ``image/png`` formatter).

A :class:`~voxwarp.scene.Scene` sits below the renderer in voxwarp's layers, so it
cannot render itself; instead, ``import voxwarp`` in a running IPython (or importing
:mod:`voxwarp.notebook`, or ``%load_ext voxwarp.notebook``) registers :func:`scene_png`
with IPython: a cell that ends with a scene then shows a small render of it
(:data:`PREVIEW_PX`), drawn by one
:class:`~voxwarp.render.offscreen.OffscreenRenderer` shared by all previews, made on
first use on a thread of its own (:mod:`voxwarp.notebook.gl_thread`). A scene that
cannot be drawn (no OpenGL here, a bad warp) shows its text form instead, with one
warning line saying why. Images returned by
:meth:`~voxwarp.render.offscreen.OffscreenRenderer.render` show themselves
(:class:`~voxwarp.render.inline_image.RenderedImage`); :func:`side_by_side` puts a few of
them in one picture.
"""

from __future__ import annotations

import sys
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from voxwarp.errors import VoxwarpError
from voxwarp.notebook.gl_thread import GLThread, SameThread
from voxwarp.render.inline_image import RenderedImage, png_bytes, rendered
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.scene import Scene

#: side (pixels) of a scene's inline preview
PREVIEW_PX = 256
_shared: dict[str, Any] = {}


def _gl() -> GLThread | SameThread:
    """The thread previews render on (their context is current there only)."""
    if "gl" not in _shared:
        _shared["gl"] = GLThread("voxwarp-preview")
    return _shared["gl"]


def preview_renderer() -> Any:
    """The renderer shared by scene previews (made on first use, on the previews' thread;
    raises :class:`~voxwarp.errors.RenderError` without OpenGL)."""
    if "renderer" not in _shared:
        _shared["renderer"] = _gl().run(OffscreenRenderer, PREVIEW_PX, PREVIEW_PX)
    return _shared["renderer"]


def preview(scene: Scene, size: int = PREVIEW_PX) -> RenderedImage:
    """A ``size`` x ``size`` render of ``scene`` (shows inline)."""
    r = preview_renderer()

    def draw() -> RenderedImage:
        if r.size != (size, size):
            r.resize(size, size)
        return r.render(scene)

    return _gl().run(draw)


def scene_png(scene: Scene) -> bytes | None:
    """PNG bytes of a preview of ``scene``; None (IPython then shows the text form) when
    it cannot be drawn, with a one-line warning naming the reason."""
    try:
        return png_bytes(preview(scene))
    except Exception as exc:  # a display hook must never break the notebook
        warnings.warn(f"voxwarp: no picture of the scene ({exc})", stacklevel=2)
        return None


def side_by_side(images: Sequence[np.ndarray], gap: int = 4) -> RenderedImage:
    """RGBA images of one height side by side, ``gap`` black pixels apart (shows inline);
    images of other heights are padded at the bottom."""
    if not images:
        raise VoxwarpError("side_by_side needs at least one image")
    arrays = [_rgba_u8(np.asarray(a)) for a in images]
    h = max(a.shape[0] for a in arrays)
    parts: list[np.ndarray] = []
    for i, a in enumerate(arrays):
        if i:
            parts.append(_black(h, gap))
        pad = _black(h - a.shape[0], a.shape[1])
        parts.append(np.concatenate([a, pad], axis=0))
    return rendered(np.concatenate(parts, axis=1))


def _black(h: int, w: int) -> np.ndarray:
    out = np.zeros((h, w, 4), np.uint8)
    out[..., 3] = 255
    return out


def _rgba_u8(a: np.ndarray) -> np.ndarray:
    if a.ndim == 2:
        a = np.repeat(a[:, :, None], 3, axis=2)
    if a.ndim != 3 or a.shape[2] not in (3, 4):
        raise VoxwarpError(
            f"side_by_side needs (H, W), (H, W, 3) or (H, W, 4) images; got {a.shape}"
        )
    if a.dtype != np.uint8:
        a = np.clip(np.rint(np.asarray(a, np.float32) * 255.0), 0, 255).astype(np.uint8)
    if a.shape[2] == 3:
        a = np.concatenate([a, np.full((*a.shape[:2], 1), 255, np.uint8)], axis=2)
    return a


def register(ipython: Any = None) -> bool:
    """Show scenes inline in ``ipython`` (default: the running IPython, if any);
    returns whether a shell was found."""
    if ipython is None:
        if "IPython" not in sys.modules:
            return False
        from IPython import get_ipython

        ipython = get_ipython()
    if ipython is None:
        return False
    formatter = ipython.display_formatter.formatters["image/png"]
    formatter.for_type(Scene, scene_png)
    return True
