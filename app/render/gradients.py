"""Precomputed data gradients for shading: one texture fetch per shaded sample.

About this technique
--------------------
Shading needs the data gradient at every sample. Computed on the fly it takes six
volume fetches (central differences at ``u +- 1`` texel per axis). Because trilinear
filtering is linear in the voxel values, those six fetches equal one trilinear fetch of
a per-voxel gradient texture ``g[i] = (v[i + 1] - v[i - 1]) / 2`` per axis (edges
replicated, as clamp-to-edge sampling replicates them), except within half a voxel of
the volume's faces, where the texture clamps one step earlier. VTK's fixed-point
raycaster keeps encoded normals per voxel for the same reason.

The texture is RGBA16F (8 bytes per voxel; half floats keep 11 significant bits, and
``g`` of 16-bit data stays below 32768), built on the GPU by ``gradient.comp.glsl``
from the volume texture, so no host copy is made. It costs memory, so the renderer
makes it only for scenes that shade and volumes of at most :data:`MAX_VOXELS` voxels
(``Renderer.gradient_texture``); larger volumes keep the six-fetch path.
"""

from __future__ import annotations

from typing import Any

from voxwarp import shaders
from voxwarp.deform import gl_programs
from voxwarp.render.volume_texture import layout_defines

#: volumes up to this many voxels get a gradient texture by default (128 MiB of RGBA16F)
MAX_VOXELS = 1 << 24
_GROUP = (8, 8, 1)


def gradient_texture(
    ctx: Any, volume_texture: Any, shape: tuple, scale: float, layout: str | bool
) -> Any:
    """An RGBA16F 3D texture (linear filtering, clamped) of the gradient of the volume in
    ``volume_texture`` (``shape`` voxels, ``scale`` data units per texel value; ``layout``:
    its :data:`voxwarp.render.volume_texture.LAYOUTS` name, True/False for slice pairs /
    a 3D texture). ``ctx`` must be current."""
    defines = layout_defines(layout)
    src = shaders.with_defines(shaders.read("gradient.comp.glsl"), defines)
    hold = gl_programs.compute_shader(ctx, src)
    try:
        prog = hold.program
        nx, ny, nz = (int(s) for s in shape)
        tex = ctx.texture3d((nx, ny, nz), 4, dtype="f2")
        tex.filter = (ctx.LINEAR, ctx.LINEAR)
        tex.repeat_x = tex.repeat_y = tex.repeat_z = False
        volume_texture.use(0)
        prog["u_volume"] = 0
        prog["u_size"] = (nx, ny, nz)
        prog["u_scale"] = float(scale)
        tex.bind_to_image(0, read=False, write=True)
        prog.run(-(-nx // _GROUP[0]), -(-ny // _GROUP[1]), -(-nz // _GROUP[2]))
        ctx.memory_barrier()
    finally:
        hold.release()
    return tex
