"""The GLSL of a warp chain evaluated at given points: the tests' CPU/GPU oracle.

:func:`gpu_warp` compiles ``warp_chain`` and ``warp_chain_jacobian`` (the composition the
raycaster includes) into a fragment shader that reads one point per pixel column and
writes ``warp(p)`` in row 0 and the Jacobian's three columns in rows 1-3.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from voxwarp.deform.warp import Warp, compose_glsl

VERTEX = """#version 430
void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""

FRAGMENT = """#version 430
uniform sampler2D u_points;
out vec4 frag;
{warps}
void main() {{
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec3 p = texelFetch(u_points, ivec2(px.x, 0), 0).xyz;
    frag = vec4(px.y == 0 ? warp_chain(p) : warp_chain_jacobian(p)[px.y - 1], 1.0);
}}
"""
#: the raycaster's form: the chain's Jacobian from the points warp_chain kept
KEPT = (
    "    frag = vec4(warp_chain(p), 1.0);\n"
    "    if (px.y > 0) frag.xyz = warp_chain_kept_jacobian()[px.y - 1];\n"
)


def _set(prog: Any, name: str, value: Any) -> None:
    v = np.asarray(value, dtype=np.float64)
    if v.ndim == 2:  # GLSL matrices are column-major
        prog[name].write(np.ascontiguousarray(v.T, dtype="f4").tobytes())
    elif isinstance(value, int | np.integer) and not isinstance(value, bool):
        prog[name].value = int(value)
    elif v.size == 1:
        prog[name].value = float(v.reshape(-1)[0])
    else:
        prog[name].value = tuple(float(c) for c in v.reshape(-1))


def gpu_warp(
    ctx: Any,
    warps: Warp | Sequence[Warp],
    points: np.ndarray,
    kept: bool = False,
    shading: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """``warp(p)`` (N, 3) and ``warp_jacobian(p)`` (N, 3, 3) of the GLSL of a warp or a
    chain at (N, 3) points, one pixel column a point; ``kept``: the Jacobian by
    ``warp_chain_kept_jacobian()`` after ``warp_chain(p)`` (as the raycaster shades);
    ``shading``: compiled as a shaded raycaster compiles it (``SHADING`` defined: warps
    may keep the Jacobian from their own fetches)."""
    chain = [warps] if isinstance(warps, Warp) else list(warps)
    n = len(points)
    frag = FRAGMENT.format(warps=compose_glsl(chain))
    if shading:
        frag = frag.replace("#version 430\n", "#version 430\n#define SHADING\n", 1)
    if kept:
        line = frag[frag.index("    frag = vec4(px.y") :]
        frag = frag.replace(line[: line.index("\n") + 1], KEPT)
    prog = ctx.program(vertex_shader=VERTEX, fragment_shader=frag)
    ctx.detect_framebuffer(0).use()
    fbo = ctx.simple_framebuffer((n, 4), components=4, dtype="f4")
    pts = ctx.texture((n, 1), 4, np.c_[points, np.ones(n)].astype("f4").tobytes(), dtype="f4")
    pts.filter = (ctx.NEAREST, ctx.NEAREST)
    vao = ctx.vertex_array(prog, [])
    try:
        unit = 1
        for i, warp in enumerate(chain):
            for name, value in warp.uniforms().items():
                if f"w{i}_{name}" in prog:
                    _set(prog, f"w{i}_{name}", value)
            for name, tex in warp.textures(ctx).items():
                tex.use(unit)
                prog[f"w{i}_{name}"].value = unit
                unit += 1
        pts.use(0)
        prog["u_points"].value = 0
        fbo.use()
        vao.render(mode=ctx.TRIANGLES, vertices=3)
        out = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(4, n, 4)
        assert np.all(out[..., 3] == 1.0), "every pixel was written"
        q = out[0, :, :3].astype(np.float64)
        jac = np.transpose(out[1:, :, :3], (1, 2, 0)).astype(np.float64)  # columns -> matrix
        return q, jac
    finally:
        ctx.detect_framebuffer(0).use()
        vao.release()
        pts.release()
        fbo.release()
        prog.release()
