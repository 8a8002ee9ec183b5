"""``python -m benchmarks.support_costs``: what a warped ray pays for, on this machine.

A lab study behind docs/benchmarks.md, section 'Cheaper inside the support'. For a
local ChainMail drag (``benchmarks.support``; ``--case``: its other deformations) on
each scan (``--volumes``), 512² dvr, frames of the undeformed scene and of variants of
the warped program (with a support map: three loops, straight, chain, straight) are
interleaved and their medians given as ratios to the undeformed frame of the same run.
``--box far`` moves the support's box out of every ray's reach (all samples straight:
the cost of the chain's mere presence), ``--box real`` keeps it. Variants are text
edits of the generated shader (throw-away programs, not what the app draws):

* ``current``: the program as shipped;
* ``seed``: the offset field's inverse from its baked seed alone (no correction; what
  ``OffsetFieldWarp(..., inverse="baked", iterations=0)`` draws);
* ``no-jacobian``: identity Jacobian (shading normals not rotated): the Jacobian's share;
* ``old``: the Jacobian as before issue 34's item 2: the chain warps the sample's point
  again (``warp_chain_jacobian(p)``) and the offset field's grad u by central
  differences at +-0.5 node spacing (6 trilinear lookups);
* ``kept-cd``: the kept points (no second warp), central differences;
* ``q-nodes``: grad u from the 8 nodes of the final q's cell, read again (the shipped
  program keeps grad u from the last fixed-point step's own 8 nodes);
* ``anew-analytic``: warped again (``warp_chain_jacobian(p)``), grad u as shipped;
* ``jacobian-v``: the offset field's Jacobian as ``I - grad v(p)``, v its baked
  inverse, by central differences (6 lookups; no second inverse, no matrix inverse);
* ``no-chain``: the middle loop straight too (no chain code at all);
* ``one-loop``: one straight loop for the whole ray (no chain, no phases);
* ``control``: ``current`` again, last in each round (how far identical programs
  differ: the noise of the machine).

The max difference (/255) to the first variant listed (``current`` by default) says
which variants change the image.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from benchmarks.support import WARPS
from voxwarp import shaders
from voxwarp.io.samples import load_sample, suggested_transfer_function
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.render.skipping.support import SupportCache
from voxwarp.scene import Scene

_CELLS = "march_cells(s, k, {}, n, t0, j, inv_du, exit_offset, exit_widen, {})"
_MIDDLE = "|| " + _CELLS.format("kio.y", "false")
_THREE = "finished = " + "\n        ".join(
    [_CELLS.format("kio.x", "true"), _MIDDLE, "|| " + _CELLS.format("n", "true") + ";"]
)
#: variant -> (old, new) text edits of the support-map program
VARIANTS: dict[str, list[tuple[str, str]]] = {
    "current": [],
    "seed": [("    w0_ITERATE   //", "    //")],
    "no-jacobian": [("    return warp_chain_kept_jacobian();", "    return mat3(1.0);")],
    "no-chain": [(_MIDDLE, _MIDDLE.replace("false)", "true)"))],
    "one-loop": [(_THREE, "finished = " + _CELLS.format("n", "true") + ";")],
}
_V = (
    "vec3 w0_v(vec3 p) {\n    vec3 s = (p - w0_lo) / w0_size;\n    vec3 v;\n"
    "    vec3 tc = (clamp(s, 0.0, 1.0) * (w0_inverse_shape - 1.0) + 0.5) / w0_inverse_shape;\n"
    "    v = textureLod(w0_inverse, tc, 0.0).xyz;\n    return v * w0_inside(s);\n}\n"
    "mat3 w0_warp_jacobian_at(vec3 p, vec3 q) {\n"
    "    vec3 h = 0.5 * w0_size / (w0_inverse_shape - 1.0);\n"
    "    mat3 g;\n"
    + "".join(
        f"    g[{i}] = (w0_v(p + e{i}) - w0_v(p - e{i})) / (2.0 * h.{c});\n".replace(
            f"e{i}", f"vec3({', '.join('h.' + c if j == i else '0.0' for j in range(3))})"
        )
        for i, c in enumerate("xyz")
    )
    + "    return mat3(1.0) - g;\n}\nmat3 w0_warp_jacobian_at_old(vec3 p, vec3 q) {"
)
VARIANTS["jacobian-v"] = [("mat3 w0_warp_jacobian_at(vec3 p, vec3 q) {", _V)]
#: the shaded program's Jacobian line (grad u kept by the last fixed-point step)
_KEPT = "    mat3 a = mat3(1.0) + (w0_ITERATIONS >= 1 ? w0_kept_grad : w0_grad_u(q));"
#: the offset field's grad u by central differences at +-0.5 node spacing (6 lookups)
_CD = [
    (
        _KEPT,
        "    vec3 h = 0.5 * w0_size / (w0_shape - 1.0);\n    mat3 a = mat3(1.0);\n"
        + "".join(
            f"    a[{i}] += (w0_offset(q + E) - w0_offset(q - E)) / (2.0 * h.{c});\n".replace(
                "E", f"vec3({', '.join('h.' + c if j == i else '0.0' for j in range(3))})"
            )
            for i, c in enumerate("xyz")
        ),
    )
]
#: the Jacobian warps the sample's point again instead of using the kept one
_ANEW = [
    ("    return warp_chain_kept_jacobian();", "    return warp_chain_jacobian(g_ro + t * g_rd);")
]
VARIANTS["kept-cd"] = _CD
#: grad u from the 8 nodes of the final q's cell (read again, as before the last step
#: kept it)
VARIANTS["q-nodes"] = [(_KEPT, "    mat3 a = mat3(1.0) + w0_grad_u(q);")]
VARIANTS["anew-analytic"] = _ANEW
VARIANTS["old"] = _ANEW + _CD
#: the shipped program again, timed last in each round: the noise of the interleaving
VARIANTS["control"] = []
_state: dict[str, Any] = {"variant": "current", "far": False}


def _with_defines(original: Any) -> Any:
    def edit(src: str, defines: Sequence[str]) -> str:
        warped = "vec3 warp_chain(vec3 p)" in src and not any("LINEAR_PATH" in d for d in defines)
        if warped:  # every raycast program with a warp chain
            for old, new in VARIANTS[_state["variant"]]:
                if old not in src:
                    raise RuntimeError(f"variant {_state['variant']}: shader text changed")
                src = src.replace(old, new)
        return original(src, defines)

    return edit


def _uniforms(original: Any) -> Any:
    def far(self: Any, scene: Any, box: Any = None) -> dict[str, Any]:
        u = original(self, scene, box)
        if _state["far"]:
            u["u_support_lo"], u["u_support_hi"] = np.full(3, 1e6), np.full(3, 1e6 + 1)
        return u

    return far


def _load() -> str:
    with open("/proc/loadavg") as f:
        return " ".join(f.read().split()[:3])


def measure(
    name: str, variants: Sequence[str], frames: int, far: bool, case: str = "chainmail drag"
) -> list[str]:
    """Markdown rows ``| scan | case | box | variant | cost | max diff |`` for one scan."""
    _state["far"] = far
    vol = load_sample(name)
    base = Scene(vol, transfer_function=suggested_transfer_function(name), jitter=False)
    warped = base.copy(warps=[WARPS[case](vol)])
    with OffscreenRenderer(8, 8) as r0:
        rs = {v: OffscreenRenderer(512, 512, ctx=r0.ctx) for v in ("undeformed", *variants)}

        def draw(v: str, image: bool = False) -> Any:
            _state["variant"] = "current" if v == "undeformed" else v
            r, scene = rs[v], base if v == "undeformed" else warped
            if image:
                return r.render(scene)[..., :3].astype(int)
            with r.current():
                t = time.perf_counter()
                r.renderer.draw(scene, r.framebuffer)
                r.ctx.finish()
                return (time.perf_counter() - t) * 1000

        try:
            for r in rs.values():
                r.renderer.warped_skip_maps = r.renderer.support_maps = "always"
            images = {v: draw(v, image=True) for v in rs}
            times: dict[str, list[float]] = {v: [] for v in rs}
            for _ in range(frames):
                for v in rs:
                    times[v].append(draw(v))
        finally:
            for r in rs.values():
                r.release()
    ref = statistics.median(times["undeformed"])
    box = "far" if far else "real"
    return [
        f"| {name} | {case} | {box} | {v} | {statistics.median(times[v]) / ref:.2f}x"
        f" | {np.abs(images[v] - images[variants[0]]).max()} |"
        for v in variants
    ]


def main(argv: Sequence[str] | None = None) -> int:
    """Print the table (module docstring)."""
    p = argparse.ArgumentParser(prog="python -m benchmarks.support_costs", description=__doc__)
    p.add_argument("--volumes", default="colin27,stent", help="bundled scans, comma-separated")
    p.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated")
    p.add_argument("--box", default="far,real", help="far, real or both")
    p.add_argument("--frames", type=int, default=5, help="timed frames per variant")
    p.add_argument("--case", default="chainmail drag", choices=sorted(WARPS), help="deformation")
    args = p.parse_args(argv)
    shaders.with_defines = _with_defines(shaders.with_defines)
    SupportCache.uniforms = _uniforms(SupportCache.uniforms)  # type: ignore[method-assign]
    print(f"load average before: {_load()}")
    print("| scan | deformation | support box | variant | cost | max diff (/255) |")
    print("|---|---|---|---|---|---|")
    for name in args.volumes.split(","):
        for box in args.box.split(","):
            rows = measure(name, args.variants.split(","), args.frames, box == "far", args.case)
            print("\n".join(rows), flush=True)
    print(f"load average after: {_load()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
