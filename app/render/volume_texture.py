"""Upload a volume's voxels to a GPU texture slab by slab, without a full-volume copy.

The texture is allocated empty and written in slabs of z layers, each converted on its
own (int16 stored as uint16 + 32768; slice pairs interleave layer k with layer k + 1),
so the extra host memory of an upload is one slab, whatever the volume's size.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: bytes of texels per uploaded slab
SLAB_BYTES = 4 * 1024**2


def _texels(layers: np.ndarray) -> np.ndarray:
    """Texture values of (z, y, x) layers: int16 as uint16 + 32768 (exact), else as is."""
    if layers.dtype == np.int16:
        return np.ascontiguousarray(layers).view(np.uint16) ^ np.uint16(0x8000)
    return np.ascontiguousarray(layers)


def upload_volume_texture(ctx: Any, data: np.ndarray, fmt: str, slice_pairs: bool) -> Any:
    """A texture holding ``data`` (nx, ny, nz), written slab by slab.

    Parameters
    ----------
    ctx
        The moderngl context.
    data
        The voxels, (nx, ny, nz) (a Volume's F-ordered array: ``data.T`` needs no copy).
    fmt
        The moderngl texel dtype ("f1", "nu2", "f4").
    slice_pairs
        True: a 2D texture array with two components per texel, layer k holding
        ``(v[k], v[k + 1])`` (the last layer repeated); False: a one-component 3D texture.

    Returns
    -------
    moderngl.Texture3D or moderngl.TextureArray
    """
    t = np.asarray(data).T  # (nz, ny, nx), x fastest
    nz, ny, nx = t.shape
    comps = 2 if slice_pairs else 1
    if slice_pairs:
        tex = ctx.texture_array((nx, ny, nz), 2, dtype=fmt, alignment=1)
    else:
        tex = ctx.texture3d((nx, ny, nz), 1, dtype=fmt, alignment=1)
    step = max(1, SLAB_BYTES // max(1, nx * ny * t.dtype.itemsize * comps))
    for k0 in range(0, nz, step):
        k1 = min(k0 + step, nz)
        layers = _texels(t[k0:k1])
        if slice_pairs:
            pairs = np.empty((k1 - k0, ny, nx, 2), dtype=layers.dtype)
            pairs[..., 0] = layers
            pairs[:-1, :, :, 1] = layers[1:]
            pairs[-1, :, :, 1] = _texels(t[min(k1, nz - 1)])
            layers = pairs
        tex.write(layers, viewport=(0, 0, k0, nx, ny, k1 - k0), alignment=1)
    return tex
