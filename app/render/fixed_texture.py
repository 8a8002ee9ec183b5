"""The raycaster's side of a fixed/moving comparison (``Scene(fixed=...)``).

:class:`FixedTexture` keeps the fixed volume as a one-component 3D texture (linear
filtering, clamped), uploaded once per volume; :func:`compare_uniforms` gives the
uniforms of ``shaders/compare.glsl`` (the fixed image's world -> texture map, the look,
blend weight and checker size, and the value range the modes' early exits see).
See :mod:`voxwarp.core.comparison` for what the looks mean.
"""

from __future__ import annotations

import weakref
from typing import Any

import numpy as np

from voxwarp.core.comparison import COMPARE_SHOWS, Comparison
from voxwarp.core.volume import Volume
from voxwarp.render import gradients
from voxwarp.render.gradients import MAX_VOXELS
from voxwarp.render.volume_texture import upload_volume_texture

_FORMATS = {
    # dtype: (moderngl dtype, value = texel * scale + offset); int16 goes through float
    np.dtype(np.uint8): ("f1", 255.0, 0.0),
    np.dtype(np.uint16): ("nu2", 65535.0, 0.0),
    np.dtype(np.float32): ("f4", 1.0, 0.0),
}


class FixedTexture:
    """The fixed volume's texture on ``ctx``, remade when the volume changes."""

    def __init__(self, ctx: Any) -> None:
        self.ctx = ctx
        self._entry: tuple[weakref.ref, Any, tuple[float, float]] | None = None
        self._gradient: Any = None

    def get(self, volume: Volume) -> tuple[Any, tuple[float, float]]:
        """``(texture, value_map)`` of ``volume`` (uploaded on first use)."""
        if self._entry is not None and self._entry[0]() is volume:
            return self._entry[1], self._entry[2]
        self.release()
        data = volume.data
        fmt = _FORMATS.get(data.dtype)
        if fmt is None:  # int16 and others: exact in float32 for CT/MR ranges
            data, fmt = data.astype(np.float32, order="F"), _FORMATS[np.dtype(np.float32)]
        tex = upload_volume_texture(self.ctx, data, fmt[0], False)
        tex.repeat_x = tex.repeat_y = tex.repeat_z = False
        tex.filter = (self.ctx.LINEAR, self.ctx.LINEAR)
        self._entry = (weakref.ref(volume), tex, (fmt[1], fmt[2]))
        return tex, self._entry[2]

    def gradient(self, volume: Volume) -> Any:
        """``volume``'s RGBA16F gradient texture (:mod:`voxwarp.render.gradients`),
        made on the GPU on first use."""
        texture, value_map = self.get(volume)
        if self._gradient is None:
            self._gradient = gradients.gradient_texture(
                self.ctx, texture, volume.shape, value_map[0], False
            )
        return self._gradient

    def release(self) -> None:
        """Free the textures (idempotent)."""
        if self._gradient is not None:
            self._gradient.release()
            self._gradient = None
        if self._entry is not None:
            self._entry[1].release()
            self._entry = None


def uses_gradient_texture(scene: Any) -> bool:
    """Whether a comparison scene shades the fixed image from a gradient texture (shaded,
    and the fixed volume small enough: :data:`voxwarp.render.gradients.MAX_VOXELS`)."""
    cmp = scene.comparison
    return bool(cmp is not None and scene.use_shading() and cmp.fixed.data.size <= MAX_VOXELS)


def fixed_world_to_tex(volume: Volume) -> np.ndarray:
    """4x4 world mm -> ``volume``'s normalised texture coordinates ([0, 1] per axis)."""
    scale = np.diag([*(1.0 / np.asarray(volume.shape, np.float64)), 1.0])
    return scale @ volume.world_to_texel_matrix()


def value_limits(moving: Volume, comparison: Comparison) -> tuple[float, float]:
    """The range of the compared values (for the modes' early exits and windows)."""
    m_lo, m_hi = (float(v) for v in moving.value_range)
    f_lo, f_hi = (float(v) for v in comparison.fixed.value_range)
    if comparison.show == "difference":
        return 0.0, max(m_hi - f_lo, f_hi - m_lo, 0.0)
    return min(m_lo, f_lo), max(m_hi, f_hi)


def compare_uniforms(moving: Volume, comparison: Comparison, unit: int, value_map: Any) -> dict:
    """The uniforms of ``shaders/compare.glsl`` (the fixed texture on ``unit``)."""
    fixed = comparison.fixed
    return {
        "u_fixed": unit,
        "u_fixed_world_to_tex": fixed_world_to_tex(fixed),
        "u_fixed_value_map": tuple(float(v) for v in value_map),
        "u_fixed_outside": float(fixed.value_range[0]),
        "u_fixed_step": float(min(fixed.spacing)),
        "u_fixed_direction": fixed.direction,
        "u_fixed_spacing": tuple(float(s) for s in fixed.spacing),
        "u_compare": COMPARE_SHOWS.index(comparison.show),
        "u_blend": float(comparison.blend),
        "u_checker_mm": comparison.cell_mm,
        "u_value_limits": value_limits(moving, comparison),
    }
