"""Upload a volume's voxels to a GPU texture slab by slab, without a full-volume copy.

The texture is allocated empty and written in slabs of z layers, each converted on its
own (int16 stored as uint16 + 32768; slice pairs interleave layer k with layer k + 1),
so the extra host memory of an upload is one slab, whatever the volume's size.

Layouts (:data:`LAYOUTS`; the raycaster's ``sampling``, whose shaders read each through
``shaders/volume_sample.glsl``):

* ``"texture3d"``: a one-component 3D texture, one hardware-trilinear fetch per sample;
* ``"slice_layers"``: a one-component 2D array texture (layer k = slice k), two bilinear
  fetches and a lerp across z per sample; each voxel stored once, like ``texture3d``;
* ``"slice_pairs"``: a two-component 2D array texture whose layer k holds slices
  ``(k, k + 1)``: one bilinear fetch and a lerp, at twice the memory (each voxel twice).
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: bytes of texels per uploaded slab
SLAB_BYTES = 4 * 1024**2
#: the texture layouts, and the texel copies of each voxel they store
LAYOUTS: dict[str, int] = {"texture3d": 1, "slice_layers": 1, "slice_pairs": 2}


def _texels(layers: np.ndarray) -> np.ndarray:
    """Texture values of (z, y, x) layers: int16 as uint16 + 32768 (exact), else as is."""
    if layers.dtype == np.int16:
        return np.ascontiguousarray(layers).view(np.uint16) ^ np.uint16(0x8000)
    return np.ascontiguousarray(layers)


def layout_name(layout: str | bool) -> str:
    """``layout`` as a :data:`LAYOUTS` name (True: "slice_pairs", False: "texture3d")."""
    if layout is True or layout is False:
        return "slice_pairs" if layout else "texture3d"
    if layout not in LAYOUTS:
        raise ValueError(f"texture layout must be one of {', '.join(LAYOUTS)}; got {layout!r}")
    return str(layout)


def upload_volume_texture(ctx: Any, data: np.ndarray, fmt: str, layout: str | bool) -> Any:
    """A texture holding ``data`` (nx, ny, nz), written slab by slab.

    Parameters
    ----------
    ctx
        The moderngl context.
    data
        The voxels, (nx, ny, nz) (a Volume's F-ordered array: ``data.T`` needs no copy).
    fmt
        The moderngl texel dtype ("f1", "nu2", "f4").
    layout
        One of :data:`LAYOUTS` (True / False: "slice_pairs" / "texture3d").

    Returns
    -------
    moderngl.Texture3D or moderngl.TextureArray
    """
    layout = layout_name(layout)
    t = np.asarray(data).T  # (nz, ny, nx), x fastest
    nz, ny, nx = t.shape
    pairs = layout == "slice_pairs"
    comps = 2 if pairs else 1
    if layout == "texture3d":
        tex = ctx.texture3d((nx, ny, nz), 1, dtype=fmt, alignment=1)
    else:
        tex = ctx.texture_array((nx, ny, nz), comps, dtype=fmt, alignment=1)
    step = max(1, SLAB_BYTES // max(1, nx * ny * t.dtype.itemsize * comps))
    for k0 in range(0, nz, step):
        k1 = min(k0 + step, nz)
        layers = _texels(t[k0:k1])
        if pairs:
            pairs_ = np.empty((k1 - k0, ny, nx, 2), dtype=layers.dtype)
            pairs_[..., 0] = layers
            pairs_[:-1, :, :, 1] = layers[1:]
            pairs_[-1, :, :, 1] = _texels(t[min(k1, nz - 1)])
            layers = pairs_
        tex.write(layers, viewport=(0, 0, k0, nx, ny, k1 - k0), alignment=1)
    return tex


def layout_defines(layout: str) -> list[str]:
    """The shader defines that make ``shaders/volume_sample.glsl`` read ``layout``."""
    return {"slice_pairs": ["#define SLICE_PAIRS"], "slice_layers": ["#define SLICE_LAYERS"]}.get(
        layout_name(layout), []
    )
