"""Setting uniforms and binding a warp chain's data on a moderngl program.

Shared by the raycaster (:mod:`voxwarp.render.raycaster`) and the slice views
(:mod:`voxwarp.render.slices`): both compile the chain with
:func:`voxwarp.deform.warp.compose_glsl`, whose warp ``i`` reads uniforms and samplers
named ``w{i}_...``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from voxwarp.deform.warp import Warp


def set_uniform(prog: Any, name: str, value: Any) -> None:
    """Set ``prog``'s uniform ``name`` (skipped when the variant does not use it);
    2D arrays are written as column-major GLSL matrices."""
    if name not in prog:
        return  # optimised out or not used by this variant
    u = prog[name]
    if isinstance(value, np.ndarray) and value.ndim == 2:
        u.write(np.ascontiguousarray(value.T, dtype="f4").tobytes())
    elif isinstance(value, np.ndarray):
        u.value = tuple(float(v) for v in value)
    else:
        u.value = value


def warp_textures(ctx: Any, warps: Sequence[Warp]) -> list[dict[str, Any]]:
    """Each warp's textures by uniform name. Make them before binding anything else:
    making them may run GPU passes (an offset field bakes its inverse) that bind texture
    units of their own."""
    return [w.textures(ctx) for w in warps]


def bind_warps(
    prog: Any, warps: Sequence[Warp], textures: Sequence[dict[str, Any]], unit: int
) -> int:
    """Set each warp's uniforms on ``prog`` and bind its ``textures`` (from
    :func:`warp_textures`) from texture unit ``unit`` on; returns the next free unit."""
    for i, warp in enumerate(warps):
        for name, value in warp.uniforms().items():
            set_uniform(prog, f"w{i}_{name}", value)
        for name, tex in textures[i].items():
            tex.use(unit)
            set_uniform(prog, f"w{i}_{name}", unit)
            unit += 1
    return unit
