"""What a fragment shader pays for on this rasteriser: small probes behind the raycaster's
design choices (a lab study, docs/benchmarks.md 'Per-ray ranges through the support').

``python -m benchmarks.rasteriser_probes [--rounds N]`` draws one full-screen quad at
512² per probe, each fragment running a 200-iteration loop, interleaved per round,
median ms:

* ``masking``: a texture fetch in the loop body always, under an ``if`` that no
  fragment takes, in an inner loop of zero trips for every fragment, and not at all.
  On llvmpipe the three cost alike: a branch runs both sides, and a loop runs its body
  once with every lane masked before it tests whether any lane is left.
* ``discard``: a costly loop in every fragment, and the same after ``discard`` at the
  start for all but a 60x60 corner (a SIMD group whose lanes all discarded skips the rest).
* ``fetch``: one RGBA trilinear lookup of a 61³ node grid as a ``sampler3D`` and as two
  bilinear ``sampler2DArray`` layers and a lerp (the offset field's layout), half and
  single floats.
* ``jacobian``: an offset field's Jacobian for shading from the 8 nodes of its cell
  (``texelFetch``, the gradient, a 3x3 inverse: the shipped form) against 3 trilinear
  lookups of a precomputed Jacobian field.
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any

import numpy as np

from voxwarp.render.context import create_context

SIZE = 512
NODES = 61

VERTEX = """#version 430
in vec2 pos;
void main() { gl_Position = vec4(pos, 0.0, 1.0); }
"""
LOOP = """#version 430
uniform sampler3D t3;
uniform sampler2DArray ta;
uniform sampler3D j0, j1, j2;
uniform vec3 SH;
uniform float thr;
out vec4 o;
#define TRI(F, S, OUT) { vec3 g_ = (S) * (SH - 1.0); vec2 tc_ = (g_.xy + 0.5) / SH.xy; \\
    float z_ = clamp(g_.z, 0.0, SH.z - 1.0); float l_ = min(floor(z_), SH.z - 2.0); \\
    OUT = mix(textureLod(F, vec3(tc_, l_), 0.0).xyz, \\
              textureLod(F, vec3(tc_, l_ + 1.0), 0.0).xyz, z_ - l_); }
mat3 grad_u(vec3 s) {
    vec3 x = clamp(s, 0.0, 1.0) * (SH - 1.0);
    vec3 i0 = min(floor(x), SH - 2.0);
    vec3 f = x - i0;
    ivec3 i = ivec3(i0);
    vec3 u000 = texelFetch(ta, i, 0).xyz;
    vec3 u100 = texelFetch(ta, i + ivec3(1, 0, 0), 0).xyz;
    vec3 u010 = texelFetch(ta, i + ivec3(0, 1, 0), 0).xyz;
    vec3 u110 = texelFetch(ta, i + ivec3(1, 1, 0), 0).xyz;
    vec3 u001 = texelFetch(ta, i + ivec3(0, 0, 1), 0).xyz;
    vec3 u101 = texelFetch(ta, i + ivec3(1, 0, 1), 0).xyz;
    vec3 u011 = texelFetch(ta, i + ivec3(0, 1, 1), 0).xyz;
    vec3 u111 = texelFetch(ta, i + ivec3(1, 1, 1), 0).xyz;
    vec3 dx = mix(mix(u100 - u000, u110 - u010, f.y), mix(u101 - u001, u111 - u011, f.y), f.z);
    vec3 dy = mix(mix(u010 - u000, u110 - u100, f.x), mix(u011 - u001, u111 - u101, f.x), f.z);
    vec3 dz = mix(mix(u001 - u000, u101 - u100, f.x), mix(u011 - u010, u111 - u110, f.x), f.y);
    return mat3(dx, dy, dz);
}
void main() {
    vec2 p = gl_FragCoord.xy * (512.0 / SIDE);
    PREFIX
    vec3 acc = vec3(0.3, 0.2, 0.1);
    for (int i = 0; i < 200; i++) {
        vec3 s = fract(vec3(p / 512.0, 0.3) + acc * 0.001 + float(i) * 0.0037);
        vec3 v = vec3(0.0);
        BODY
        acc += v * 0.5;
    }
    o = vec4(acc, 1.0);
}
"""
FETCH3 = "v = textureLod(t3, s, 0.0).xyz;"
ZERO_TRIPS = "int n = s.x < thr ? 2 : 0; for (int c = 0; c < n; ++c) { FETCH }"
JACOBIAN_NODES = (
    "mat3 a = mat3(1.0) + grad_u(s);"
    " v = transpose(abs(determinant(a)) > 1e-6 ? inverse(a) : mat3(1.0)) * s;"
)
JACOBIAN_FIELD = (
    "v = transpose(mat3(textureLod(j0, s, 0.0).xyz, textureLod(j1, s, 0.0).xyz,"
    " textureLod(j2, s, 0.0).xyz)) * s;"
)
PROBES: dict[str, dict[str, tuple[str, str]]] = {
    "masking": {
        "no fetch": ("", "v = s;"),
        "fetch always": ("", FETCH3),
        "fetch under an if no lane takes": ("", f"if (s.x < thr) {{ {FETCH3} }}"),
        "fetch in a loop of 0 trips": (
            "",
            f"int n = s.x < thr ? 2 : 0; for (int c = 0; c < n; ++c) {{ {FETCH3} }}",
        ),
    },
    "discard": {
        "every fragment": ("", FETCH3),
        "all but 60x60 discard first": ("if (p.x > 60.0 || p.y > 60.0) discard;", FETCH3),
    },
    "fetch": {
        "sampler3D": ("", FETCH3),
        "sampler2DArray, 2 layers": ("", "TRI(ta, s, v)"),
    },
    "jacobian": {
        "8 texelFetch + inverse (shipped)": ("", JACOBIAN_NODES),
        "3 trilinear lookups of a J field": ("", JACOBIAN_FIELD),
    },
}


def _textures(ctx: Any, dtype: str) -> list[Any]:
    rng = np.random.default_rng(0)
    data = rng.random((NODES, NODES, NODES, 4)).astype(dtype).tobytes()
    out = [ctx.texture3d((NODES,) * 3, 4, data, dtype=dtype)]
    out.append(ctx.texture_array((NODES,) * 3, 4, data, dtype=dtype))
    out += [ctx.texture3d((NODES,) * 3, 4, data, dtype=dtype) for _ in range(3)]
    for t in out:
        t.filter = (ctx.LINEAR, ctx.LINEAR)
    return out


def run_probe(
    ctx: Any, name: str, rounds: int, dtype: str = "f2", size: int = SIZE
) -> dict[str, float]:
    """Median ms of each variant of probe ``name`` (textures of ``dtype``), drawn at
    ``size``² pixels."""
    target = ctx.framebuffer([ctx.texture((size, size), 4)])
    target.use()
    quad = ctx.buffer(np.array([-1, -1, 1, -1, -1, 1, 1, 1], "f4").tobytes())
    textures = _textures(ctx, dtype)
    for unit, tex in enumerate(textures):
        tex.use(unit)
    vaos = {}
    for label, (prefix, body) in PROBES[name].items():
        prog = ctx.program(
            vertex_shader=VERTEX,
            fragment_shader=LOOP.replace("PREFIX", prefix)
            .replace("BODY", body)
            .replace("SIDE", f"{float(size)}"),
        )
        for uniform, value in (("t3", 0), ("ta", 1), ("j0", 2), ("j1", 3), ("j2", 4)):
            if uniform in prog:
                prog[uniform].value = value
        for uniform, value in (("SH", (float(NODES),) * 3), ("thr", -1.0)):
            if uniform in prog:
                prog[uniform].value = value
        vaos[label] = ctx.vertex_array(prog, [(quad, "2f", "pos")])
    times: dict[str, list[float]] = {k: [] for k in vaos}
    try:
        for _ in range(rounds):
            for label, vao in vaos.items():
                ctx.finish()
                t = time.perf_counter()
                vao.render(ctx.TRIANGLE_STRIP)
                ctx.finish()
                times[label].append((time.perf_counter() - t) * 1000)
    finally:
        for vao in vaos.values():
            prog = vao.program
            vao.release()
            prog.release()
        ctx.detect_framebuffer(0).use()  # never delete the bound framebuffer
        for obj in (*textures, quad, target, *target.color_attachments):
            obj.release()
    return {k: statistics.median(v) for k, v in times.items()}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.rasteriser_probes")
    parser.add_argument("--rounds", type=int, default=7)
    args = parser.parse_args(argv)
    ctx = create_context()
    print(f"{ctx.info['GL_RENDERER']}, {SIZE}x{SIZE}, 200 loop iterations per fragment,")
    print(f"median of {args.rounds} interleaved draws\n")
    print("| probe | variant | ms |\n|---|---|---:|")
    for name in PROBES:
        for dtype in ("f2", "f4") if name == "fetch" else ("f2",):
            for label, ms in run_probe(ctx, name, args.rounds, dtype).items():
                what = (
                    f"{label} ({'half' if dtype == 'f2' else 'float'})"
                    if name == "fetch"
                    else label
                )
                print(f"| {name} | {what} | {ms:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
