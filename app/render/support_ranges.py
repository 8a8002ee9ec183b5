"""Per-pixel ray ranges through the chain's support, for warped rays on the map path.

A warped ray on the ``"map"`` path (:mod:`voxwarp.render.skipping.support`) marches
straight, then through the chain, then straight again. Where the chain starts and stops
used to be the box around every support brick; a drag's support is a blob, and the box
around it held 1.5x its samples on the bundled scans. This pass rasterises the support's
surface (:meth:`voxwarp.deform.support.SupportMap.boundary_triangles`) in the draw's
camera into an RGBA32F target that blends r by MIN and a by MAX: each pixel gets the
first and the last ray parameter at which its ray crosses the surface, and the
raycaster chains only between them (``u_support_ranges``). A ray that crosses none gets
(+big, -big): every sample straight.

A ray that starts inside a support brick crosses no surface before it; so when the
camera's near plane can reach the support's box the pass clears to (-big, +big) instead
(the box alone bounds those rays, as before), and so it does for a surface of more than
:data:`MAX_TRIANGLES` triangles (a scattered support, whose rasterisation would cost
more than it saves).

Use :meth:`SupportRanges.texture` once per draw (its triangles are kept per support map).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from voxwarp import shaders
from voxwarp.deform.identity import token
from voxwarp.deform.support import SupportMap
from voxwarp.render.float_target import FloatTarget

#: a ray parameter no ray reaches (the target's "no face" values)
FAR = 1e30
#: a surface of more triangles is not drawn (the box bounds the rays instead): the pass
#: costs about a microsecond per triangle on llvmpipe (a scattered support of 30 % of a
#: 32³ map has ~84k triangles, 63 ms at 512²; a drag's blob has 3-9k)
MAX_TRIANGLES = 1 << 14
#: the surface's rectangles are widened in their plane by this fraction of a brick (see
#: SupportMap.boundary_triangles): merged rows meet in T-junctions, where rasterisation
#: left pixels uncovered (a ray through a support brick drawn straight: 1-2 pixels off
#: by up to 44/255 per frame on the bundled scans); a twentieth of a brick is at least a
#: few pixels' 1/256 snapping steps wherever a brick covers a pixel or more
GROW = 0.05
#: the "too many triangles" mark of a map's cached surface
_OPEN = object()


class SupportRanges:
    """The range pass's program, triangles and float target on one context."""

    def __init__(self, ctx: Any) -> None:
        self.ctx = ctx
        self._target = FloatTarget(ctx, (4,))
        self._program: Any = None
        #: (map token, buffer, vertex array); buffer None: no surface or _OPEN
        self._mesh: tuple[int, Any, Any] | None = None
        #: what the target holds now (map, camera, size, box, bound): a draw that asks
        #: for the same again reads it without drawing the pass
        self._drawn: tuple | None = None
        self._drawn_fbo: Any = None

    def texture(
        self,
        smap: SupportMap,
        inv_view_proj: np.ndarray,
        size: tuple[int, int],
        box: tuple[np.ndarray, np.ndarray],
        bound: bool = True,
    ) -> Any:
        """The RGBA32F texture (at least ``size``; read at the pixel's offset in the
        viewport) of each ray's first (r) and last (a) crossing of ``smap``'s surface,
        for the camera ``inv_view_proj`` (clip -> deformed world) and the support's
        ``box`` (lo, hi). ``bound`` False: every range open (the box alone bounds the
        chained phase, for comparisons)."""
        w, h = size
        key = (
            token(smap),
            np.asarray(inv_view_proj, float).tobytes(),
            (int(w), int(h)),
            np.asarray(box, float).tobytes(),
            bool(bound),
        )
        fbo = self._target.framebuffer(w, h)
        if key == self._drawn and fbo is self._drawn_fbo:
            return self._target.textures[0]
        self._drawn, self._drawn_fbo = key, fbo
        fbo.use()
        fbo.viewport = (0, 0, w, h)
        vao = self._vao(smap) if bound else None
        if not bound or vao is _OPEN or _near_plane_reaches(inv_view_proj, box):
            fbo.clear(-FAR, 0.0, 0.0, FAR, viewport=(0, 0, w, h))
            return self._target.textures[0]
        fbo.clear(FAR, 0.0, 0.0, -FAR, viewport=(0, 0, w, h))
        if vao is not None:
            prog = self._program
            prog["u_view_proj"].write(np.linalg.inv(inv_view_proj).T.astype("f4").tobytes())
            prog["u_inv_view_proj"].write(np.asarray(inv_view_proj).T.astype("f4").tobytes())
            prog["u_viewport"].value = (0.0, 0.0, float(w), float(h))
            ctx = self.ctx
            ctx.disable(ctx.DEPTH_TEST | ctx.CULL_FACE)
            ctx.enable(ctx.BLEND)
            ctx.blend_func = (ctx.ONE, ctx.ONE)
            ctx.blend_equation = (ctx.MIN, ctx.MAX)
            try:
                vao.render(ctx.TRIANGLES)
            finally:
                ctx.blend_equation = ctx.FUNC_ADD
                ctx.blend_func = ctx.DEFAULT_BLENDING
                ctx.disable(ctx.BLEND)
        return self._target.textures[0]

    def _vao(self, smap: SupportMap) -> Any:
        """The vertex array of ``smap``'s surface (made once per map), None if empty,
        ``_OPEN`` if it has more than :data:`MAX_TRIANGLES` (the box bounds the rays)."""
        key = token(smap)
        if self._mesh is not None and self._mesh[0] == key:
            return self._mesh[2]
        self._drop_mesh()
        tris = smap.boundary_triangles(GROW)
        if len(tris) == 0 or len(tris) > MAX_TRIANGLES:
            self._mesh = (key, None, None if len(tris) == 0 else _OPEN)
            return self._mesh[2]
        if self._program is None:
            self._program = self.ctx.program(
                vertex_shader=shaders.source("support_ranges.vert.glsl"),
                fragment_shader=shaders.source("support_ranges.frag.glsl"),
            )
        buf = self.ctx.buffer(np.ascontiguousarray(tris, dtype="f4").tobytes())
        vao = self.ctx.vertex_array(self._program, [(buf, "3f", "in_position")])
        self._mesh = (key, buf, vao)
        return vao

    def _drop_mesh(self) -> None:
        if self._mesh is not None and self._mesh[1] is not None:
            self._mesh[2].release()
            self._mesh[1].release()
        self._mesh = None

    def release(self) -> None:
        """Free the target, the triangles and the program (idempotent)."""
        self._drawn = self._drawn_fbo = None
        self._drop_mesh()
        self._target.release()
        if self._program is not None:
            self._program.release()
            self._program = None


def _near_plane_reaches(inv_view_proj: np.ndarray, box: tuple[np.ndarray, np.ndarray]) -> bool:
    """Whether the box around the camera's near-plane rectangle touches ``box`` (a ray
    may then start inside a support brick, with no surface crossing before it)."""
    corners = np.array([[x, y, -1.0, 1.0] for x in (-1.0, 1.0) for y in (-1.0, 1.0)])
    p = corners @ np.asarray(inv_view_proj, float).T
    p = p[:, :3] / p[:, 3:]
    lo, hi = (np.asarray(b, float) for b in box)
    return bool(np.all(p.max(axis=0) >= lo) and np.all(p.min(axis=0) <= hi))
