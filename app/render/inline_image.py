"""Rendered images that show themselves in Jupyter: PNG bytes in memory, no new dependency.

:class:`RenderedImage` is what :meth:`voxwarp.render.offscreen.OffscreenRenderer.render`
returns: a plain ``numpy.ndarray`` subclass (same dtype, shape and values as before; every
array operation works as on any array) with one addition, ``_repr_png_``, so a notebook
cell ending in ``r.render(scene)`` shows the picture instead of a wall of numbers.
Arithmetic on it (``img / 255``, ``img.mean()``) gives plain arrays or scalars again.

:func:`png_bytes` is a small PNG encoder (zlib, filter type 0, 8 bits per channel):
grey, RGB or RGBA; float images are taken as [0, 1]; RGBA is un-premultiplied as
:func:`voxwarp.io.images.write_image` does (the raycaster writes premultiplied colour).
"""

from __future__ import annotations

import struct
import zlib
from typing import Any

import numpy as np

from voxwarp.errors import RenderError

#: the largest image (pixels per side) that shows inline; bigger ones stay text
MAX_INLINE_PX = 4096
_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_COLOR_TYPES = {1: 0, 3: 2, 4: 6}  # channels -> PNG colour type (grey, RGB, RGBA)


def _chunk(kind: bytes, data: bytes) -> bytes:
    crc = zlib.crc32(data, zlib.crc32(kind)) & 0xFFFFFFFF
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)


def _as_u8(image: np.ndarray) -> np.ndarray:
    """(H, W, C) uint8 of an (H, W) or (H, W, 1|3|4) uint8 or float [0, 1] image."""
    a = np.asarray(image)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3 or a.shape[2] not in _COLOR_TYPES or min(a.shape[:2]) < 1:
        raise RenderError(f"a PNG needs an (H, W) or (H, W, 1|3|4) image; got shape {a.shape}")
    if a.dtype == np.uint8:
        return a
    if a.dtype.kind not in "fiub":
        raise RenderError(f"a PNG needs a numeric image; got dtype {a.dtype}")
    f = np.nan_to_num(np.asarray(a, np.float32), nan=0.0)
    return np.clip(np.rint(f * 255.0), 0, 255).astype(np.uint8)


def _unpremultiply(a: np.ndarray) -> np.ndarray:
    """Straight RGBA of premultiplied RGBA8 (PNG stores straight alpha)."""
    alpha = a[..., 3:4].astype(np.float32)
    if np.all(alpha == 255):
        return a
    rgb = a[..., :3].astype(np.float32) * 255.0 / np.maximum(alpha, 1.0)
    out = a.copy()
    out[..., :3] = np.clip(np.rint(rgb), 0, 255).astype(np.uint8)
    return out


def png_bytes(image: np.ndarray, level: int = 6) -> bytes:
    """Encode an (H, W) or (H, W, 1|3|4) image, row 0 at the top, as PNG bytes.

    uint8 is taken as is, floats as [0, 1] (clipped); RGBA as premultiplied (the
    renderer's), stored straight. Raises :class:`~voxwarp.errors.RenderError` for another
    shape or dtype."""
    a = _as_u8(image)
    h, w, c = a.shape
    if c == 4:
        a = _unpremultiply(a)
    rows = np.zeros((h, 1 + w * c), np.uint8)  # each row: filter byte 0 (none), pixels
    rows[:, 1:] = np.ascontiguousarray(a).reshape(h, w * c)
    header = struct.pack(">IIBBBBB", w, h, 8, _COLOR_TYPES[c], 0, 0, 0)
    return b"".join(
        (
            _SIGNATURE,
            _chunk(b"IHDR", header),
            _chunk(b"IDAT", zlib.compress(rows.tobytes(), level)),
            _chunk(b"IEND", b""),
        )
    )


def is_image(a: Any) -> bool:
    """Whether ``a`` looks like a picture :func:`png_bytes` can show inline."""
    shape = getattr(a, "shape", ())
    dtype = getattr(a, "dtype", None)
    return (
        len(shape) in (2, 3)
        and (len(shape) == 2 or shape[2] in _COLOR_TYPES)
        and 0 < min(shape[:2])
        and max(shape[:2]) <= MAX_INLINE_PX
        and dtype is not None
        and (dtype == np.uint8 or dtype.kind == "f")
    )


class RenderedImage(np.ndarray):
    """An image array (row 0 at the top) that Jupyter shows as a picture.

    Behaves as the ``numpy.ndarray`` it views (no copy: ``np.asarray(img)`` is the
    plain array); results of arithmetic and reductions are plain arrays. Views and
    slices that are still images (``img[..., :3]``, ``img[::2, ::2]``) show inline too;
    anything else falls back to the text form.
    """

    def __array_wrap__(
        self, obj: np.ndarray, context: Any = None, return_scalar: bool = False
    ) -> Any:
        """ufunc results are plain arrays (or scalars)."""
        out = np.asarray(obj)
        return out[()] if return_scalar else out

    def _repr_png_(self) -> bytes | None:
        """PNG bytes for IPython's display (None when this array is not an image)."""
        if not is_image(self):
            return None
        return png_bytes(np.asarray(self))


def rendered(image: np.ndarray) -> RenderedImage:
    """``image`` viewed as a :class:`RenderedImage` (no copy)."""
    return np.asarray(image).view(RenderedImage)
