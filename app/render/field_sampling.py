"""A warp chain's pull-back field sampled on the GPU (``voxwarp export-field --sampler gpu``).

:class:`GpuFieldSampler` draws ``shaders/field_sample.frag.glsl`` over runs of planes of
an export grid (first index ``i`` fixed in a plane, one fragment per node ``(j, k)``;
whole planes stacked in the target's rows, about :data:`DRAW_NODES` nodes a draw) into
an RGBA32F target: each fragment maps its node's world point through the same GLSL
warp chain as the raycaster (``warp_chain``) and writes ``chain(p) - p``; the planes are
read back into the ``(nx, ny, nz, 3)`` float32 field. Nodes the chain sends to NaN or farther than
:data:`~voxwarp.deform.warp.FAR_MM` (a wire's vacated space) are *outside*, as on the CPU
(:func:`voxwarp.core.field_check.sample_carried`, whose drop-in this is: same arguments,
same results within the GLSL chain's float32 and half-float textures).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from voxwarp import shaders
from voxwarp.core.field_check import sample_carried
from voxwarp.deform import gl_programs
from voxwarp.deform.warp import FAR_MM, Warp, compose_glsl
from voxwarp.errors import RenderError
from voxwarp.render.float_target import FloatTarget
from voxwarp.render.gl_uniforms import bind_warps, set_uniform, warp_textures

#: Largest plane (nodes a side) one draw samples; the CPU path takes larger grids.
MAX_PLANE_SIDE = 16384
#: About how many nodes one draw samples (whole planes, stacked in the target's rows).
DRAW_NODES = 1 << 18
#: :class:`FieldSampler` by default samples grids of fewer nodes on the CPU: there a
#: context's start and the chain's shader compile (about 1 s on llvmpipe) cost more than
#: the CPU's sampling (256³ colin27, ``voxwarp bench exports``: a 6³ mass-spring's
#: grids of under a million nodes took 1 s longer on the GPU; a wire's 16.7M nodes 7 s
#: less).
GPU_MIN_NODES = 1 << 22


class GpuFieldSampler:
    """Samples warp chains on export grids with the GPU of ``ctx`` (current when called).

    Call it as :func:`~voxwarp.core.field_check.sample_carried`:
    ``sampler(warps, affine, shape) -> (u, outside)``. GPU resources (one program per
    chain signature, the target) are freed by :meth:`release`.
    """

    def __init__(self, ctx: Any) -> None:
        self.ctx = ctx
        self._programs = gl_programs.KeyedPrograms(ctx, shaders.read("upscale.vert.glsl"))
        self._target = FloatTarget(ctx, (4,))

    def __call__(
        self, warps: Sequence[Warp], affine: np.ndarray, shape: Sequence[int]
    ) -> tuple[np.ndarray, np.ndarray]:
        """``chain(p) - p`` at every node (float32 ``(nx, ny, nz, 3)``) and the bool
        mask of the nodes the chain does not carry (their vectors are 0)."""
        nx, ny, nz = (int(v) for v in shape)
        if not (1 <= ny <= MAX_PLANE_SIDE and 1 <= nz <= MAX_PLANE_SIDE):
            raise RenderError(
                f"a {ny}x{nz} plane of nodes is over the GPU sampler's {MAX_PLANE_SIDE}"
                " a side; use --sampler cpu or a coarser --spacing"
            )
        chain = list(warps)
        prog = self._program(chain)
        textures = warp_textures(self.ctx, chain)  # first: may run GPU passes
        set_uniform(prog, "u_index_to_world", np.asarray(affine, dtype=np.float64))
        bind_warps(prog, chain, textures, 0)
        per = max(1, min(DRAW_NODES // (ny * nz), MAX_PLANE_SIDE // ny, nx))
        fbo = self._target.framebuffer(nz, ny * per)
        set_uniform(prog, "u_rows", float(ny))
        vao = self.ctx.vertex_array(prog, [])
        u = np.empty((nx, ny, nz, 3), dtype=np.float32)
        outside = np.empty((nx, ny, nz), dtype=bool)
        try:
            with self.ctx.scope(fbo, enable_only=0):  # no blending or depth: data
                for i0 in range(0, nx, per):
                    m = min(per, nx - i0)
                    fbo.viewport = (0, 0, nz, ny * m)
                    set_uniform(prog, "u_plane", float(i0))
                    vao.render(self.ctx.TRIANGLES, vertices=3)
                    raw = fbo.read(viewport=(0, 0, nz, ny * m), components=4, dtype="f4")
                    u[i0 : i0 + m], outside[i0 : i0 + m] = _planes(raw, m, ny, nz)
        finally:
            vao.release()
        return u, outside

    def _program(self, chain: list[Warp]) -> Any:
        def fragment() -> str:
            return shaders.source(
                "field_sample.frag.glsl", extra={"warps.glsl": compose_glsl(chain)}
            )

        try:
            return self._programs.get(tuple(w.signature() for w in chain), fragment)
        except Exception as exc:
            raise RenderError(f"field sampling shader failed to compile/link: {exc}") from exc

    def release(self) -> None:
        """Free the programs and the target; idempotent."""
        self._programs.release()
        self._target.release()


def _planes(raw: bytes, m: int, ny: int, nz: int) -> tuple[np.ndarray, np.ndarray]:
    """``m`` read-back planes: their ``(m, ny, nz, 3)`` vectors (0 where not carried) and
    their not-carried mask (NaN, or farther than :data:`FAR_MM`, as on the CPU)."""
    d = np.frombuffer(raw, dtype=np.float32).reshape(m, ny, nz, 4)[..., :3]
    with np.errstate(invalid="ignore"):
        ok = np.all(np.abs(d) < FAR_MM, axis=-1)
    return np.where(ok[..., None], d, np.float32(0.0)), ~ok


class FieldSampler:
    """``export-field``'s sampler: the GPU (:class:`GpuFieldSampler`) for grids of at
    least ``min_nodes`` nodes, the CPU (:func:`~voxwarp.core.field_check.sample_carried`)
    below; called as either.

    ``ctx``: a context current while sampling (an element model's), else one is opened
    on the first large grid and kept until :meth:`release`. With ``required`` a context
    that does not open raises :class:`RenderError`; without it the CPU samples, with a
    note from ``log``.
    """

    def __init__(
        self,
        ctx: Any = None,
        *,
        min_nodes: int = GPU_MIN_NODES,
        required: bool = False,
        log: Any = None,
    ) -> None:
        self._ctx, self.min_nodes, self.required, self._log = ctx, int(min_nodes), required, log
        self._renderer: Any = None
        self._gpu: GpuFieldSampler | None = None
        self._failed = False

    def __call__(
        self, warps: Sequence[Warp], affine: np.ndarray, shape: Sequence[int]
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(u, outside)`` as :func:`~voxwarp.core.field_check.sample_carried`."""
        if int(np.prod(shape)) < self.min_nodes or self._failed:
            return sample_carried(warps, affine, shape)
        if self._gpu is None and not self._open():
            return sample_carried(warps, affine, shape)
        assert self._gpu is not None
        if self._renderer is None:
            return self._gpu(warps, affine, shape)
        with self._renderer.current():
            return self._gpu(warps, affine, shape)

    def _open(self) -> bool:
        if self._ctx is None:
            from voxwarp.render.offscreen import OffscreenRenderer  # deferred: it is large

            try:
                self._renderer = OffscreenRenderer(16, 16)
            except RenderError:
                if self.required:
                    raise
                self._failed = True
                if self._log:
                    self._log("no OpenGL context: the CPU samples the chain")
                return False
            self._ctx = self._renderer.ctx
        self._gpu = GpuFieldSampler(self._ctx)
        return True

    def release(self) -> None:
        """Free the GPU sampler and the context it opened; idempotent."""
        if self._gpu is not None:
            if self._renderer is None:
                self._gpu.release()
            else:
                with self._renderer.current():
                    self._gpu.release()
            self._gpu = None
        if self._renderer is not None:
            self._renderer.release()
            self._renderer = None
