"""GPU solver of the 3D ChainMail model: fragment shaders ping-ponging between framebuffers.

About this technique (Gibson 1997; Knoche 2008, 3.5.3.2)
--------------------------------------------------------
:class:`GpuChainMailSolver` enforces the link constraints of
:class:`~voxwarp.deform.elements.chainmail_model.ChainMailModel` on a ``moderngl`` context as the
thesis does: every *pass* is one draw, one fragment per element, that reads the
previous positions with ``imageLoad`` and writes the new ones into the other
framebuffer of a ping-pong pair; passes repeat until none changes anything. It writes
the same offset texture as :class:`voxwarp.deform.elements.massspring_gpu.GpuSpringSolver`. The
thesis
drew every pass over the whole grid, which loses ChainMail's locality (a drag that
moves 300 elements costs a full-grid pass per step of its wave); here a pass covers
only the box that can still change, so the cost follows the affected region (see
"Locality").

Measurements (growing box vs full-grid passes, cost of the per-pass sync, what was
tried): docs/benchmarks.md, section 'voxwarp.deform.elements.chainmail_gpu: growing box vs full
grid'.

The iteration
-------------
The constraints separate by coordinate: for each coordinate ``c`` a link ``a -> b``
is a *difference constraint* ``x_b,c - x_a,c in [l, h]`` (``[min, max]`` along the
link's axis, ``[-shear, shear]`` across). Given its 6 neighbours, an element's
feasible values are therefore an interval per coordinate, ``[lo, hi]`` = the
intersection over its present links of ``[x_n + l, x_n + h]`` (neighbour ``n`` before
it) or ``[x_n - h, x_n - l]`` (after it); absent links (cuts, faces) are stored as
``(-1e30, 1e30)`` limits, so the shader has no branch per link. A plain Jacobi
"clamp into [lo, hi]" can oscillate when intervals conflict (e.g. two held elements
pulled apart), so a pass clamps in one direction only, per coordinate:

* **lowering phase**: ``x > hi -> hi`` (every constraint read as an upper bound on its
  free end);
* **raising phase**: ``x < lo -> lo`` (every constraint read as a lower bound).

Held and fixed elements never move. Each coordinate runs the lowering phase until a
pass changes nothing, then the raising phase until a pass changes nothing (the three
coordinates step their phases independently within the same passes).

*Termination and correctness.* Each phase is a monotone Bellman-Ford relaxation. The
lowering phase converges to ``y``, the greatest vector below the start that meets
every constraint as an upper bound on its free end: values only decrease, bounded
below by any solution, and with no negative cycle (any feasible configuration) it
ends after at most as many passes as elements -- in practice after the hop distance
the wave travels, about ``nx + ny + nz`` at most for uniform limits. The raising phase
then converges to the *least* vector above ``y`` that meets every constraint as a
lower bound on its free end. That vector satisfies all constraints if some solution
``z >= y`` exists, and one does: the greatest solution of the whole system (the
shortest-path solution from the held and fixed elements) is also the greatest of the
constraints that ``y`` meets, so it is ``>= y``. Hence for feasible configurations both
phases terminate with every link satisfied. Both results are unique (independent of
the update order), which the tests' numpy oracle checks.

When the previous enforce converged, the rest of the grid satisfies every link, so a
coordinate in which the held elements (held before too, so their positions are known
without a readback) only moved up needs only the raising phase, only down only the
lowering phase, neither if they did not move; newly held elements, an upload
(:meth:`~GpuChainMailSolver.set_positions`) or an unconverged enforce run both phases.
This is ChainMail's behaviour: a push moves each element the least needed, away from
the disturbance. In an *infeasible* configuration (a drag beyond what the fixed
elements allow) the phases still end (or stop at ``max_passes``), held and fixed
elements in place. With one phase, the free elements follow the held ones and the
violation is left at the links of fixed elements; where both phases run, the raising
phase has the last word (an element pushed down out of reach of a fixed one is
pulled back up, leaving the violation at the held element instead).

*Float32.* Moves smaller than ``max(1e-6 mm, 2^-19 x the largest coordinate)`` (8 to
16 ulp of the coordinates) count as round-off: without this threshold, zero-weight
cycles (rigid material: ``min = max``) can creep by an ulp per round trip and never
settle. Links are satisfied to about that threshold (the tests ask for 1e-4 mm).
Coordinates are stored relative to the centre of the rest box, halving their
magnitude.

Layout
------
One element per texel of 2D RGBA32F textures: z-slice ``k`` is the ``nx x ny`` tile at
column ``k % tiles_x``, row ``k // tiles_x`` (``massspring_atlas.glsl`` with blocks of
one element; one row of tiles when the atlas fits one 64 x 64 llvmpipe raster tile,
so that both threads get work). Textures: the position ``(x - origin, w)``, two of
them (ping-pong; ``w`` 0 free, 1 fixed, 2 held), the targets ``(target - origin, 1
if held)`` (read by the pin pass only), the rest positions (for the displacement
texture) and the link limits, five per element: ``(min, max, shear)`` of its 3
forward and 3 backward links packed in 18 floats (each link mean of its two
elements' limits, :meth:`~voxwarp.deform.elements.chainmail_model.ChainMailModel.link_limits`). A
constraint pass loads 12 texels per element (own position, 6 neighbours, 5 limits).
Grid and atlas sizes are compile-time constants (``chainmail_config.glsl``, generated
per solver).

:meth:`~GpuChainMailSolver.enforce` first uploads the targets of the bounding box of
the held elements (old and new: released elements become free) as per-slice
sub-rectangles, and runs the *pin pass* over that box twice, once into each buffer:
held elements go to their targets, so both buffers agree again.

Convergence detection
---------------------
Every fragment that moves its element does ``atomicOr`` of one bit per changed
coordinate and ``atomicMin``/``atomicMax`` of its indices into a 64-byte SSBO
(nothing for unchanged elements); after the draw a ``glMemoryBarrier`` and a 64-byte
read give the CPU the changed coordinates and the bounding box of the changes: that
is the only readback during ``enforce``. On llvmpipe a barrier is a ``glFinish``, so
this is a sync per pass, but a ping-pong pass already flushes a scene (the next pass
reads what this one rendered), so the sync adds little; a flag read every N passes
would save little and cannot steer the box. Changes are counted as such only above the
float32 threshold above, so "no bit set" is an exact fixed point.

Locality
--------
An element can change in a pass only if a linked neighbour changed in the previous
pass (with its neighbours unchanged, its interval and hence its clamp are the same as
last time), or if its coordinate just entered a new phase. So with ``local`` (the
default) pass ``k + 1`` is drawn over the bounding box of pass ``k``'s changes grown
by one element on each face and clipped to the grid (it grows by one per pass behind
a spreading wave and stops growing, or shrinks, on faces where nothing changed); the
first pass covers the held elements' box grown by one (or the whole grid after
:meth:`~GpuChainMailSolver.set_positions` or an unconverged enforce), and a
coordinate entering its raising phase adds the union of everything covered so far.
An infeasible drag leaves violated links behind, which a later enforce must revisit
although they are away from its held elements (the full passes would): so an element
still violating a link in the direction its coordinate's last phase does not move
(or in either, for a coordinate done) records its indices in a second box of the
same record, and the next enforce's first box includes the union of those boxes.
The box is drawn as one quad per z-slice (instanced, no vertex buffer; the vertex
shader places the quads from the box uniforms). Ping-pong stays consistent although
a pass writes only its box: every element changed by a pass lies in the next pass's
box, which copies it into the other buffer, so outside the box both buffers always
agree. ``local=False`` draws every pass over the whole grid (the thesis' scheme,
same passes and result) for comparison; :func:`benchmarks.chainmail.gpu_enforce_table`
times both.

Relaxation
----------
:meth:`~GpuChainMailSolver.relax` runs the CPU's relaxation rule
(:func:`voxwarp.deform.elements.chainmail_cpu.relax_sweep`, red-black Gauss-Seidel of
constrained Laplacian smoothing) as one draw per half-sweep of
``chainmail_relax.frag.glsl``: elements of the half-sweep's colour move to ``rest +``
the mean displacement of their linked neighbours, clamped into their links' interval
(no move where it is empty), the others are copied; held and fixed elements never
move. Each draw covers the previous one's box grown by one element
(:func:`~voxwarp.deform.elements.chainmail_model.relax_boxes`), and a last copy draw
over the last box makes both ping-pong buffers agree again, so the constraint passes
of the next :meth:`~GpuChainMailSolver.enforce` (which write only their box) find the
same state in both. Nothing is read back; the displacement texture is updated over the
last box. Positions are float32 (relative to the rest box centre, like the constraint
passes), so the result agrees with the CPU's float64 to a few ulp of the coordinates.

The solver draws on the context it is given and does not make it current. GL state it
changes (enable flags, bound framebuffer) is restored after each call; image units 0
to 6 and SSBO binding 0 are left bound to its objects.
"""

from __future__ import annotations

import math
from typing import Any

import moderngl
import numpy as np

from voxwarp import shaders
from voxwarp.deform import gl_programs
from voxwarp.deform.elements.chainmail_model import Box, ChainMailModel, relax_boxes
from voxwarp.deform.elements.chainmail_model import grow_box as _grow
from voxwarp.deform.elements.chainmail_model import union_box as _union
from voxwarp.deform.elements.gpu_grid import GpuGridSolver, GpuSolverError

#: Violations below this many mm count as float32 round-off in :attr:`GpuChainMailSolver.feasible`.
CHECK_TOL_MM = 1e-4
#: Limit of an absent link (cut, or past a face): its interval is (-BIG, BIG).
_BIG = 1e30
#: Work-group size of the displacement compute shader.
_GROUP = (8, 8, 1)
#: GL_RGBA16F, the image format of the displacement texture.
_GL_RGBA16F = 0x881A
#: GL_SHADER_STORAGE_BARRIER_BIT
_SSBO_BARRIER = 0x2000
#: Moves below twice this fraction of the coordinates' magnitude count as float32
#: round-off (8-16 ulp): see the module doc, "Float32".
_REL_TOL = 2.0**-20
#: ... and never below this (mm).
_ABS_TOL = 1e-6
#: The pass record's reset value: empty box of changes (lo > hi), no coordinate
#: changed, empty box of violations.
_RESET = np.array(([2**30] * 3 + [-1] * 3 + [0, 0]) * 2, np.int32).tobytes()


def _volume(box: Box | None) -> int:
    return 0 if box is None else math.prod(h - lo for lo, h in zip(*box, strict=True))


class GpuChainMailSolver(GpuGridSolver):
    """ChainMail constraint enforcement on the GPU (see the module doc).

    Parameters
    ----------
    model
        Grid, limits, links and fixed elements; uploaded once, at construction.
    ctx
        A ``moderngl.Context`` (OpenGL 4.3+); the caller owns it and makes it current.
    local
        Restrict each pass to the box that can still change (default); False runs every
        pass over the whole grid (the thesis' scheme, kept for comparison). Both give the
        same result; the attribute can be changed between calls.

    Raises
    ------
    ValueError
        If ``ctx`` is None or older than OpenGL 4.3, or the grid does not fit the
        context's textures.
    """

    def __init__(self, model: ChainMailModel, ctx: Any, *, local: bool = True) -> None:
        self._setup(
            model,
            ctx,
            "GpuChainMailSolver",
            "use the CPU ChainMail of voxwarp.deform.elements.chainmail without a GL context",
            "compute shaders, SSBOs",
        )
        #: restrict passes to the box that can still change (see the module doc)
        self.local = bool(local)
        shape = model.shape
        if len(shape) != 3 or min(shape) < 1:
            raise GpuSolverError(
                f"model.rest must have shape (nx, ny, nz, 3); got {model.rest.shape}"
            )
        #: elements per axis (nx, ny, nz)
        self.shape: tuple[int, int, int] = shape
        nx, ny, nz = shape
        info = ctx.info
        max_2d = int(info.get("GL_MAX_TEXTURE_SIZE", 16384))
        max_3d = int(info.get("GL_MAX_ARRAY_TEXTURE_LAYERS", 2048))
        if nz > max_3d or max(nx, ny) > max_2d:
            raise GpuSolverError(
                f"a grid of {nx}x{ny}x{nz} elements exceeds the context's textures"
            )
        #: tiles (z-slices) per row and per column of the atlas, its size in texels (w, h)
        self._set_atlas(shape, max_2d)
        #: world origin of the stored coordinates (the rest box's centre, float64)
        rest = np.asarray(model.rest, np.float64)
        flat = rest.reshape(-1, 3)
        self._origin = 0.5 * (flat.min(axis=0) + flat.max(axis=0))
        self._magnitude = float(np.abs(flat - self._origin).max(initial=0.0))
        self._fixed = np.asarray(model.fixed, bool).copy()
        self._held_box: Box | None = None  # bounding box of the held elements
        self._held_flat = np.zeros(0, np.int64)  # their flat indices (sorted)
        self._held_rel = np.zeros((0, 3), np.float32)  # and targets - origin, as stored
        self._dirty = True  # the state may violate constraints anywhere: check all
        self._violated: Box | None = None  # else it may only here (infeasible drags)
        self._check_box: Box | None = None  # where feasible checks (the last enforce's)
        #: bumped whenever the displacement texture changes (set_positions, enforce)
        self.revision = 0
        #: passes of the last :meth:`enforce`
        self.last_passes = 0
        #: whether the last :meth:`enforce` ran until nothing changed
        self.converged = True
        #: elements shaded by the constraint passes of the last :meth:`enforce`
        self.last_elements = 0
        #: box of the elements the last :meth:`enforce` moved or pinned (None: none)
        self.last_changed: Box | None = None
        self._create_or_release(model)

    # ------------------------------------------------------------------ setup
    def _create(self, model: ChainMailModel) -> None:
        ctx = self.ctx
        nx, ny, nz = self.shape
        w, h = self.atlas_size
        config = (
            f"#define NX {nx}\n#define NY {ny}\n#define NZ {nz}\n"
            f"#define BX {nx}\n#define BY {ny}\n#define BZ {nz}\n#define TX {self.tiles[0]}\n"
            f"#define CM_ATLAS_W {w}.0\n#define CM_ATLAS_H {h}.0\n"
        )
        cfg = {"chainmail_config.glsl": config}
        self._make_programs(
            shaders.source("chainmail_box.vert.glsl", cfg),
            shaders.source("chainmail_pass.frag.glsl", cfg),
            shaders.source(
                "chainmail_pass.frag.glsl",
                {"chainmail_config.glsl": config + "#define CM_PIN_PASS\n"},
            ),
            shaders.source("chainmail_displacement.comp.glsl", cfg),
        )
        self._vao = self._keep(ctx.vertex_array(self._prog, []))
        self._pin_vao = self._keep(ctx.vertex_array(self._pin_prog, []))
        self._relax_prog = self._keep(
            gl_programs.program(
                ctx,
                vertex_shader=shaders.source("chainmail_box.vert.glsl", cfg),
                fragment_shader=shaders.source("chainmail_relax.frag.glsl", cfg),
            )
        ).program
        self._relax_vao = self._keep(ctx.vertex_array(self._relax_prog, []))
        self._pos = [self._atlas_texture() for _ in range(2)]
        self._fbo = [self._keep(ctx.framebuffer(color_attachments=[t])) for t in self._pos]
        self._cur = 0
        self._scope = self._keep(ctx.scope(self._fbo[0], enable_only=moderngl.NOTHING))
        self._links = [self._atlas_texture(a) for a in self._to_atlas(_link_data(model))]
        self._target = self._atlas_texture()
        rest4 = np.zeros((*self.shape, 4), np.float32)
        rest4[..., :3] = np.asarray(model.rest, np.float64) - self._origin
        self._rest = self._atlas_texture(self._to_atlas(rest4)[0])
        self._changes = self._keep(ctx.buffer(_RESET))
        self._make_displacement()
        self.set_positions(np.asarray(model.rest, np.float64))

    def _to_atlas(self, grid: np.ndarray) -> list[np.ndarray]:
        """(nx, ny, nz, 4c) -> c (height, width, 4) float32 atlases (z-slice tiles)."""
        nx, ny, nz = self.shape
        tx, ty = self.tiles
        out = []
        for c in range(grid.shape[3] // 4):
            padded = np.zeros((nx, ny, tx * ty, 4), np.float32)
            padded[:, :, :nz] = grid[..., 4 * c : 4 * c + 4]
            tiles = padded.reshape(nx, ny, ty, tx, 4)  # k = row * tx + column
            out.append(
                np.ascontiguousarray(tiles.transpose(2, 1, 3, 0, 4)).reshape(ty * ny, tx * nx, 4)
            )
        return out

    def _from_atlas(self, atlas: np.ndarray) -> np.ndarray:
        nx, ny, nz = self.shape
        tx, ty = self.tiles
        tiles = atlas.reshape(ty, ny, tx, nx, 4).transpose(3, 1, 0, 2, 4)
        return tiles.reshape(nx, ny, ty * tx, 4)[:, :, :nz]

    # ------------------------------------------------------------------ public API
    def set_positions(self, x: np.ndarray, valid: bool = False) -> None:
        """Upload element positions (and update the displacement texture).

        Clears the held elements (the next :meth:`enforce` holds its own); the next
        :meth:`enforce` checks every link, since ``x`` may violate any -- unless
        ``valid``.

        Parameters
        ----------
        x
            ``(nx, ny, nz, 3)`` positions, world mm.
        valid
            ``x`` is known to satisfy every link (e.g. the rest state): the next
            :meth:`enforce` starts from its held elements, as after a converged one.

        Raises
        ------
        ValueError
            On a wrong shape or non-finite values.
        """
        self._check_alive()
        x = self._check_grid("positions", x, 3)
        pos4 = np.zeros((*self.shape, 4), np.float32)
        rel = x - self._origin
        pos4[..., :3] = rel
        pos4[..., 3] = np.where(self._fixed, 1.0, 0.0)
        data = self._to_atlas(pos4)[0].tobytes()
        for tex in self._pos:
            tex.write(data)
        self._held_box = None
        self._held_flat = np.zeros(0, np.int64)
        self._held_rel = np.zeros((0, 3), np.float32)
        self._magnitude = max(self._magnitude, float(np.abs(rel).max(initial=0.0)))
        self._dirty = not valid
        if valid:
            self._violated = None
        self._update_displacement(((0, 0, 0), self.shape))

    def enforce(
        self, held_mask: np.ndarray, held_targets: np.ndarray, max_passes: int | None = None
    ) -> int:
        """Hold elements at targets and move the others until every link is satisfied.

        Held elements are placed at their targets (where not fixed: fixed elements never
        move) and kept there; then constraint passes run until a pass changes nothing
        in either phase of every coordinate (see the module doc), or ``max_passes``.
        Nothing is read back but the 64-byte record of each pass.

        Parameters
        ----------
        held_mask
            ``(nx, ny, nz)`` bool: the held elements.
        held_targets
            ``(nx, ny, nz, 3)`` world mm; only read where held.
        max_passes
            Most constraint passes; default ``4 * (nx + ny + nz)`` (each of the two
            monotone phases of a coordinate needs at most about ``nx + ny + nz``).

        Returns
        -------
        int
            Constraint passes drawn (0 when nothing can have changed). :attr:`converged`
            says whether they ended because nothing changed any more.

        Raises
        ------
        ValueError
            On a wrong shape, non-finite targets or a negative ``max_passes``.
        """
        self._check_alive()
        mask = np.asarray(held_mask)
        if mask.shape != self.shape:
            raise GpuSolverError(f"held_mask must have shape {self.shape}; got {mask.shape}")
        targets = np.asarray(held_targets)
        if targets.shape != (*self.shape, 3):
            raise GpuSolverError(
                f"held_targets must have shape {(*self.shape, 3)}; got {targets.shape}"
            )
        if max_passes is None:
            max_passes = 4 * sum(self.shape)
        max_passes = int(max_passes)
        if max_passes < 0:
            raise GpuSolverError(f"max_passes must be >= 0; got {max_passes}")
        # O(held) from here on, but for one scan of the mask (a drag holds few elements)
        flat = np.flatnonzero(mask)
        flat = flat[~self._fixed.reshape(-1)[flat]]
        idx = np.unravel_index(flat, self.shape)
        rel = targets[idx].astype(np.float64) - self._origin
        if not np.all(np.isfinite(rel)):
            raise GpuSolverError("held_targets must be finite where held")
        held_box: Box | None = None
        if rel.size:
            held_box = (
                tuple(int(i.min()) for i in idx),  # type: ignore[assignment]
                tuple(int(i.max()) + 1 for i in idx),
            )
            self._magnitude = max(self._magnitude, float(np.abs(rel).max()))
        tol = self._round_off()
        self._prog["u_tol"].value = tol

        bound = self.ctx.fbo
        with self._scope:
            pin_box = _union(held_box, self._held_box)
            if pin_box is not None:
                self._pin(pin_box, idx, rel)
            self._held_box = held_box
            rel32 = rel.astype(np.float32)
            was_dirty = self._dirty
            if self._dirty:
                start: Box | None = ((0, 0, 0), self.shape)
                phase, then = [0, 0, 0], [1, 1, 1]
                moved_held = pin_box
            else:
                start = _union(_grow(held_box, self.shape), self._violated)
                phase, then = self._start_phases(flat, rel32)
                moved_held = self._moved_held(flat, rel32)
            self._held_flat, self._held_rel = flat, rel32
            solved = self._solve(start, phase, then, max_passes)
            passes, elements, converged, touched, violated = solved
        self.ctx.fbo = bound  # moderngl's record of the bound framebuffer, as GL has it
        self.last_passes, self.last_elements, self.converged = passes, elements, converged
        self._dirty = not converged
        self._violated = violated
        # where a link can be violated now: at changed or held elements (all others
        # were satisfied before); checked by feasible
        self._check_box = (
            ((0, 0, 0), self.shape) if was_dirty else _grow(_union(pin_box, touched), self.shape)
        )
        self.last_changed = _union(moved_held, touched)
        self._update_displacement(_union(pin_box, touched))
        return passes

    def _round_off(self) -> float:
        """Moves below this (mm) are float32 round-off: 8-16 ulp of the largest
        coordinate expected (module doc: Float32)."""
        return max(_ABS_TOL, 2.0 * self._magnitude * _REL_TOL)

    def relax(self, box: Box | None, steps: int) -> Box | None:
        """Relax on the GPU: ``steps`` red-black steps of the CPU's rule (module doc,
        "Relaxation"), nothing read back.

        Parameters
        ----------
        box
            ``((i0, j0, k0), (i1, j1, k1))`` (half-open) holding every element that
            may be off the rule's fixed point; ``None``: none is, nothing runs.
        steps
            Red-black steps (>= 0); each half-sweep covers the previous one's box
            grown by one element
            (:func:`~voxwarp.deform.elements.chainmail_model.relax_boxes`).

        Returns
        -------
        tuple or None
            The last half-sweep's box: every element the relaxation changed lies in it.
        """
        self._check_alive()
        boxes = relax_boxes(box, steps, self.shape)
        if not boxes:
            return box
        prog = self._relax_prog
        bound = self.ctx.fbo
        with self._scope:
            for i, tex in enumerate(self._links):
                tex.bind_to_image(1 + i, read=True, write=False)
            self._rest.bind_to_image(6, read=True, write=False)
            for n, b in enumerate(boxes):
                prog["u_colour"].value = n % 2
                self._draw(self._relax_vao, prog, b)
            prog["u_colour"].value = -1  # copy: both buffers agree again
            self._draw(self._relax_vao, prog, boxes[-1])
        self.ctx.fbo = bound
        self._update_displacement(boxes[-1])
        return boxes[-1]

    def _pin(self, box: Box, idx: tuple[np.ndarray, ...], rel: np.ndarray) -> None:
        """Upload the targets of ``box`` and run the pin pass into both buffers.

        ``idx``: indices of the held elements, ``rel``: their targets - origin.
        """
        (x0, y0, z0), (x1, y1, z1) = box
        nx, ny, _ = self.shape
        tx = self.tiles[0]
        sub = np.zeros((x1 - x0, y1 - y0, z1 - z0, 4), np.float32)
        local = (idx[0] - x0, idx[1] - y0, idx[2] - z0)
        sub[local] = np.concatenate([rel, np.ones((len(rel), 1))], axis=1)
        for k in range(z0, z1):
            data = np.ascontiguousarray(sub[:, :, k - z0].transpose(1, 0, 2))
            col, row = k % tx, k // tx
            viewport = (col * nx + x0, row * ny + y0, x1 - x0, y1 - y0)
            self._target.write(data.tobytes(), viewport=viewport)
        self._target.bind_to_image(1, read=True, write=False)
        for _ in range(2):  # src -> dst, then back: both buffers agree again
            self._draw(self._pin_vao, self._pin_prog, box)

    def _draw(self, vao: Any, prog: Any, box: Box) -> None:
        """One ping-pong draw over ``box``: reads the current buffer, writes the other."""
        lo, hi = box
        src, dst = self._cur, 1 - self._cur
        self._pos[src].bind_to_image(0, read=True, write=False)
        prog["u_box_lo"].value = lo
        prog["u_box_hi"].value = hi
        self._fbo[dst].use()
        vao.render(moderngl.TRIANGLES, vertices=6, instances=hi[2] - lo[2])
        self._cur = dst

    def _moved_held(self, flat: np.ndarray, rel32: np.ndarray) -> Box | None:
        """Box of the held elements that are newly held or have a new target (held
        elements whose target stayed do not move; released ones do not either)."""
        _, new, old = np.intersect1d(flat, self._held_flat, return_indices=True)
        same = np.zeros(len(flat), bool)
        same[new] = np.all(rel32[new] == self._held_rel[old], axis=1)
        idx = np.unravel_index(flat[~same], self.shape)
        if idx[0].size == 0:
            return None
        return (
            tuple(int(i.min()) for i in idx),  # type: ignore[return-value]
            tuple(int(i.max()) + 1 for i in idx),
        )

    def _start_phases(self, flat: np.ndarray, rel32: np.ndarray) -> tuple[list[int], list[int]]:
        """Phases per coordinate after a converged enforce (see the module doc).

        Returns the first phase and the one after the lowering phase (1 raising, 2
        done). Where the elements held before and now moved only up along a coordinate,
        it needs only the raising phase, only down only the lowering phase, not at all
        neither; newly held elements (position unknown without a readback) need both.
        """
        _, new, old = np.intersect1d(flat, self._held_flat, return_indices=True)
        step = rel32[new] - self._held_rel[old]
        unknown = len(new) < len(flat)
        phase, then = [], []
        for c in range(3):
            down = unknown or bool((step[:, c] < 0).any())
            up = unknown or bool((step[:, c] > 0).any())
            phase.append(0 if down else 1 if up else 2)
            then.append(1 if up else 2)
        return phase, then

    def _solve(
        self, start: Box | None, phase: list[int], then: list[int], max_passes: int
    ) -> tuple[int, int, bool, Box | None, Box | None]:
        """Constraint passes from the box ``start``; ``phase`` per coordinate: 0
        lowering, 1 raising, 2 done; ``then``: the phase after 0 (see the module doc).

        Returns (passes, elements shaded, converged, box of everything that changed,
        box of the elements reported as violating a link at the end of their phases).
        """
        full: Box = ((0, 0, 0), self.shape)
        box = start
        region = start  # where a coordinate entering a new phase can find violations
        touched: Box | None = None
        violated: Box | None = None
        passes = elements = 0
        if start is None or phase == [2, 2, 2]:
            return 0, 0, True, None, self._violated
        for i, tex in enumerate(self._links):
            tex.bind_to_image(1 + i, read=True, write=False)
        self._changes.bind_to_storage_buffer(0)
        prog = self._prog
        prog["u_report_pinned"].value = 0
        while phase != [2, 2, 2]:
            draw = box if self.local else full  # the thesis' scheme: always everything
            if draw is None:
                flags, changed = 0, None
            else:
                if passes >= max_passes:
                    return passes, elements, False, touched, None
                prog["u_lower"].value = tuple(int(p == 0) for p in phase)
                prog["u_raise"].value = tuple(int(p == 1) for p in phase)
                last = [p == 2 or p == 1 or then[c] == 2 for c, p in enumerate(phase)]
                prog["u_report_below"].value = tuple(
                    int(last[c] and p != 1) for c, p in enumerate(phase)
                )
                prog["u_report_above"].value = tuple(
                    int(last[c] and p != 0) for c, p in enumerate(phase)
                )
                self._changes.write(_RESET)
                self._draw(self._vao, prog, draw)
                self.ctx.memory_barrier(_SSBO_BARRIER)  # the SSBO atomics, then read
                record = np.frombuffer(self._changes.read(64), np.int32)
                passes += 1
                elements += _volume(draw)
                flags = int(record[6])
                changed = None
                if flags:
                    changed = (
                        tuple(int(v) for v in record[0:3]),
                        tuple(int(v) + 1 for v in record[3:6]),
                    )
                if record[11] >= 0:
                    report = (
                        tuple(int(v) for v in record[8:11]),
                        tuple(int(v) + 1 for v in record[11:14]),
                    )
                    violated = _union(violated, report)  # type: ignore[arg-type]
            entering = False
            for c in range(3):
                if phase[c] < 2 and not flags >> c & 1:
                    phase[c] = then[c] if phase[c] == 0 else 2
                    entering |= phase[c] == 1
            touched = _union(touched, changed)
            box = _grow(changed, self.shape)
            region = _union(region, box)
            if entering:
                box = _union(box, region)
        return passes, elements, True, touched, violated

    def _update_displacement(self, box: Box | None) -> None:
        self.revision += 1
        if box is None:
            return
        lo, hi = box
        self._disp.bind_to_image(0, read=False, write=True, format=_GL_RGBA16F)
        self._pos[self._cur].bind_to_image(1, read=True, write=False)
        self._rest.bind_to_image(2, read=True, write=False)
        self._comp["u_lo"].value = lo
        self._comp["u_hi"].value = hi
        size = [h - v for v, h in zip(lo, hi, strict=True)]
        self._comp.run(*(-(-n // g) for n, g in zip(size, _GROUP, strict=True)))
        self.ctx.memory_barrier()

    @property
    def feasible(self) -> bool:
        """False when the last :meth:`enforce` left violated links (a drag beyond what
        fixed and held elements allow, or an unconverged run).

        One check pass over the elements the enforce changed or held (grown by one):
        every element there, held and fixed ones included, tests its links; nothing
        moves, and a 64-byte record is read back.
        """
        self._check_alive()
        if not self.converged:
            return False
        # (the phases' own violation report is conservative -- it marks where the next
        # enforce must look -- so it is no verdict; the check pass below is)
        box = getattr(self, "_check_box", None)
        if box is None:
            return True
        prog = self._prog
        prog["u_lower"].value = (0, 0, 0)
        prog["u_raise"].value = (0, 0, 0)
        prog["u_report_below"].value = (1, 1, 1)
        prog["u_report_above"].value = (1, 1, 1)
        prog["u_report_pinned"].value = 1
        tol = prog["u_tol"].value
        # float32 leftovers below twice the solve's move tolerance (8-16 ulp of the
        # coordinates) are no violation; a blocked drag leaves millimetres
        prog["u_tol"].value = max(2.0 * tol, CHECK_TOL_MM)
        bound = self.ctx.fbo
        with self._scope:
            for i, tex in enumerate(self._links):
                tex.bind_to_image(1 + i, read=True, write=False)
            self._changes.bind_to_storage_buffer(0)
            self._changes.write(_RESET)
            cur = self._cur
            self._draw(self._vao, prog, box)  # writes x unchanged into the other buffer
            self._cur = cur  # ... which stays the other one
            self.ctx.memory_barrier(_SSBO_BARRIER)
            record = np.frombuffer(self._changes.read(64), np.int32)
        self.ctx.fbo = bound
        prog["u_report_pinned"].value = 0
        prog["u_tol"].value = tol
        return bool(record[11] < 0)

    def snapshot(self) -> None:
        """Remember the current state on the GPU (a texture copy, no read-back), for
        :meth:`restore`."""
        self._check_alive()
        if getattr(self, "_snap", None) is None:
            self._snap = self._atlas_texture()
            self._snap_fbo = self._keep(self.ctx.framebuffer([self._snap]))
        self.ctx.copy_framebuffer(self._snap_fbo, self._fbo[self._cur])
        self._snap_state = (
            self._held_box,
            self._held_flat.copy(),
            self._held_rel.copy(),
            self._dirty,
            self._violated,
        )

    def restore(self) -> None:
        """Go back to the state of the last :meth:`snapshot` (GPU copy)."""
        self._check_alive()
        if getattr(self, "_snap", None) is None:
            raise GpuSolverError("restore() needs a snapshot() first")
        # both ping-pong buffers: a pass writes only its box into the other one
        for fbo in self._fbo:
            self.ctx.copy_framebuffer(fbo, self._snap_fbo)
        (
            self._held_box,
            self._held_flat,
            self._held_rel,
            self._dirty,
            self._violated,
        ) = self._snap_state
        self._held_flat, self._held_rel = self._held_flat.copy(), self._held_rel.copy()
        self._update_displacement(((0, 0, 0), self.shape))

    def positions(self) -> np.ndarray:
        """Read back the element positions.

        Returns
        -------
        numpy.ndarray
            ``(nx, ny, nz, 3)`` float64, world mm.
        """
        self._check_alive()
        raw = self._read_atlas(self._pos[self._cur])
        return self._from_atlas(raw)[..., :3].astype(np.float64) + self._origin


def _link_data(model: ChainMailModel) -> np.ndarray:
    """(nx, ny, nz, 20) float32: the packed link limits of the pass shader.

    Per element ``fx fy fz`` (forward links, to ``e + e_i``) and ``bx by bz`` (backward,
    from ``e - e_i``), each ``(min, max, shear)``, absent links ``(-BIG, BIG, BIG)``,
    in the order of ``chainmail_pass.frag.glsl``.
    """
    shape = model.shape
    absent = np.array([-_BIG, _BIG, _BIG])
    fwd = [np.broadcast_to(absent, (*shape, 3)).copy() for _ in range(3)]
    bwd = [np.broadcast_to(absent, (*shape, 3)).copy() for _ in range(3)]
    for axis in range(3):
        if shape[axis] < 2:
            continue
        mn, mx, sh, linked = model.link_limits(axis)
        lim = np.where(linked[..., None], np.stack([mn, mx, sh], axis=-1), absent)
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[axis] = slice(0, -1)
        hi[axis] = slice(1, None)
        fwd[axis][tuple(lo)] = lim
        bwd[axis][tuple(hi)] = lim
    fx, fy, fz = fwd
    bx, by, bz = bwd
    zero = np.zeros((*shape, 2))
    packed = np.concatenate([fx, bx, fy, by, fz, bz, zero], axis=-1)
    return packed.astype(np.float32)
