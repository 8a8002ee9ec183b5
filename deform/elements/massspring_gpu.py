"""GPU solver of the mass-spring model: fragment shaders ping-ponging between framebuffers.

About this technique (Knoche 2008, 3.5)
---------------------------------------
:class:`GpuSpringSolver` integrates exactly the physics of
:mod:`voxwarp.deform.elements.spring_model`
(the same as :class:`voxwarp.deform.elements.massspring.CpuSpringSolver`, to float32 round-off) on a
``moderngl`` context. One draw call is one integration step: one fragment per *block*
of elements (default 2 x 2 x 1) reads the previous state of the block's elements and
of their spring neighbours with ``imageLoad`` and writes the new positions and
velocities into the colour attachments (MRT, two per element: 8 for a block of 4) of
the other framebuffer of a ping-pong pair. ``step(n)`` never reads back.

Block atlas
-----------
The ``(nx, ny, nz)`` element grid is cut into blocks of ``block = (sx, sy, sz)``
elements (:data:`DEFAULT_BLOCK`; at most :data:`MAX_BLOCK` = 4, the 8 draw buffers of
GL holding a position and a velocity each), giving a ``(bx, by, bz) = ceil(n / s)``
block grid (the last block along an axis may hold padding elements). Element
``(i, j, k)`` is element ``e = ex + sx * (ey + sy * ez)`` of block
``(I, J, K) = (i // sx, j // sy, k // sz)``, ``(ex, ey, ez)`` its remainders. Each of
the ``sx * sy * sz`` elements of a block has its own textures, and in each of them the
block grid is tiled by z-slices: ``tiles_x`` tiles per row, slice ``K`` being the
``bx x by`` tile at column ``K % tiles_x`` and row ``K // tiles_x``, so block
``(I, J, K)`` is texel

    ``(u, v) = (I + (K % tiles_x) * bx,  J + (K // tiles_x) * by)``

of every texture (``u`` = column/x, ``v`` = row/y). The atlas is
``(tiles_x * bx) x (tiles_y * by)`` texels with ``tiles_y = ceil(bz / tiles_x)``;
:func:`~voxwarp.deform.elements.gpu_grid.atlas_layout` makes it as square as possible
within ``GL_MAX_TEXTURE_SIZE`` (128³ elements in 2 x 2 x 1 blocks: 11 x 12 tiles, 704 x
768 texels), except that an atlas fitting in one 64 x 64 llvmpipe raster tile is laid
out as one row instead, so that both rasterizer threads get work. The step draw covers
only the used tiles.
Textures (RGBA32F, ``NEAREST``), per element of a block:

* position ``(x, y, z, stiffness)`` and velocity ``(vx, vy, vz, 1 / mass)``, two of
  each (ping-pong), at image units / colour attachments ``2e`` and ``2e + 1``. The
  stiffness rides in the position (a neighbour's spring constant needs it) and the
  inverse mass in the velocity, which is **0 for pinned elements**: a pinned element
  sits at its target with zero velocity, so with no acceleration it stays there
  exactly, and the step needs no pin test and no target fetch;
* rest ``(x, y, z, 0)`` (for the displacement texture) and target
  ``(x, y, z, 1 / mass or -1 when pinned)`` (for the pin pass).

plus one damping texture per solver holding the damping of block element ``e`` in
channel ``e``. Padding elements have zero state and inverse mass 0 and are never a
spring's end.

The grid, block and atlas sizes are compile-time constants (``massspring_config.glsl``,
generated per solver), and ``main()`` of the step (``massspring_pass.glsl``) is
generated too: unrolled over the block's elements and the spring offsets, it loads
each distinct neighbour texel once (a 2 x 2 x 1 block with the 6 structural springs:
8 own + 32 neighbour + 1 damping loads for 4 elements, 10.25 per element instead of
17), evaluates a spring between two elements of the same block once (+F on one end,
-F on the other), clamps neighbours outside the grid into it and weights them 0 (no
branches). :meth:`~GpuSpringSolver.set_constraints` writes the targets and runs one
draw of the pin program (the same shader file with ``MS_PIN_PASS``): pinned elements
go to their targets at rest, and every element's inverse mass is set from the target's
``w``. :meth:`~GpuSpringSolver.set_state` keeps the given state of pinned elements
(as the CPU solver does); the next :meth:`~GpuSpringSolver.step` then runs one step,
the pin pass, and the remaining steps, matching the CPU solver step by step.

Performance
-----------
On llvmpipe every texel fetch is a per-lane gather and both sides of every branch run,
so the step's cost is its loads and its memory traffic; blocks of elements per fragment
cut the loads per element. Measurements (steps/s against a taichi CPU kernel, block
shapes, what was tried): docs/benchmarks.md, section 'voxwarp.deform.elements.massspring_gpu:
step throughput'.

Displacement texture
--------------------
After every :meth:`GpuSpringSolver.step` (and :meth:`~GpuSpringSolver.set_state`,
:meth:`~GpuSpringSolver.set_constraints`) a compute shader (one invocation per block,
8 x 8 x 1 groups) writes the ``(nx, ny, nz)`` RGBA16F texture of
:meth:`~GpuSpringSolver.displacement_texture` with ``imageStore``:
``(x - rest, stiffness)`` per element; a ``glMemoryBarrier`` follows, so the raycaster
can sample it at once. Nothing is read back to the CPU.

The model's scalar parameters (``dt``, ``spring_constant``, ``spring_damping``,
``max_step``, ``integrator``) are read at every :meth:`~GpuSpringSolver.step`; its
per-element arrays (``rest``, ``stiffness``, ``damping``, ``mass``) and springs
(``shear``, ``bend``, ``spacing``) are uploaded once, at construction.

The solver draws on the context it is given and does not make it current: the caller
does (as for :class:`voxwarp.render.raycaster.Renderer`). GL state it changes (enable flags, bound
framebuffer) is restored after each call; image units from 0 up to twice the block
size (at most 12) are left bound to its textures.
"""

from __future__ import annotations

import math
from typing import Any

import moderngl
import numpy as np

from voxwarp import shaders
from voxwarp.deform.elements.gpu_grid import GpuGridSolver, GpuSolverError
from voxwarp.deform.elements.spring_model import INTEGRATORS, SpringModel

#: Most springs per element the shaders accept (structural + shear + bend).
MAX_SPRINGS = 24
#: Most elements per block (one fragment writes 2 colour attachments per element).
MAX_BLOCK = 4
#: Elements per fragment along x, y, z by default (see module doc).
DEFAULT_BLOCK = (2, 2, 1)
#: Work-group size of the displacement compute shader.
_GROUP = (8, 8, 1)
#: GL_RGBA16F, the image format of the displacement texture.
_GL_RGBA16F = 0x881A


def block_shape(shape: tuple[int, int, int], block: tuple[int, int, int]) -> tuple[int, int, int]:
    """Blocks per axis of a grid: ``ceil(n / b)`` (the last block may hold padding)."""
    return tuple(-(-int(n) // int(b)) for n, b in zip(shape, block, strict=True))  # type: ignore[return-value]


class GpuSpringSolver(GpuGridSolver):
    """Mass-spring solver on the GPU (see module doc for the technique and layout).

    Parameters
    ----------
    model
        The model: grid, materials, springs and integrator.
    ctx
        A ``moderngl.Context`` (OpenGL 4.3+, for the compute shader); the caller owns it
        and makes it current.
    block
        Elements per fragment along x, y, z (at most 4 in all; default
        :data:`DEFAULT_BLOCK`, the fastest measured on llvmpipe).

    Raises
    ------
    ValueError
        If ``ctx`` is None or too old, or the model is inconsistent (array shapes,
        non-positive mass, unknown integrator, more than 24 springs) or too large for
        the context's textures, or ``block`` is not 1 to 4 elements.
    """

    def __init__(
        self, model: SpringModel, ctx: Any, *, block: tuple[int, int, int] = DEFAULT_BLOCK
    ) -> None:
        self._setup(
            model,
            ctx,
            "GpuSpringSolver",
            "use voxwarp.deform.elements.massspring.CpuSpringSolver without a GL context",
            "compute shaders",
        )
        shape = _check_model(model)
        self.shape: tuple[int, int, int] = shape
        nx, ny, nz = shape
        blk = tuple(int(b) for b in block)
        if len(blk) != 3 or min(blk) < 1 or math.prod(blk) > MAX_BLOCK:
            raise GpuSolverError(
                f"block must be 3 sizes >= 1 with at most {MAX_BLOCK} elements; got {block}"
            )
        # no longer than the grid (a 1-element-thick grid gets 1 along that axis)
        bs = tuple(min(b, n) for b, n in zip(blk, shape, strict=True))
        #: elements per fragment along x, y, z
        self.block: tuple[int, int, int] = bs  # type: ignore[assignment]
        #: blocks per axis
        self.blocks: tuple[int, int, int] = block_shape(shape, self.block)
        self._n_block = math.prod(self.block)
        info = ctx.info
        max_2d = int(info.get("GL_MAX_TEXTURE_SIZE", 16384))
        max_3d = int(info.get("GL_MAX_3D_TEXTURE_SIZE", 2048))
        if max(shape) > max_3d:
            raise GpuSolverError(
                f"a grid of {nx}x{ny}x{nz} elements exceeds GL_MAX_3D_TEXTURE_SIZE {max_3d}"
            )
        #: tiles per row and per column of the block atlas, its size in texels (w, h)
        self._set_atlas(self.blocks, max_2d)
        self._n_springs = len(model.offsets)
        self._pinned = np.zeros(shape, bool)
        self._pin_pending = False

        self._create_or_release(model)

    # ------------------------------------------------------------------ setup
    def _create(self, model: SpringModel) -> None:
        ctx = self.ctx
        config = _config_glsl(self.shape, self.block, self.tiles[0], model)
        frag = "massspring_step.frag.glsl"
        self._make_programs(
            shaders.source("massspring_step.vert.glsl"),
            shaders.source(
                frag, {"massspring_config.glsl": config, "massspring_pass.glsl": _step_glsl(self)}
            ),
            shaders.source(
                frag,
                {
                    "massspring_config.glsl": config + "#define MS_PIN_PASS\n",
                    "massspring_pass.glsl": _pin_glsl(self),
                },
            ),
            shaders.source(
                "massspring_displacement.comp.glsl",
                {"massspring_config.glsl": config, "massspring_pass.glsl": _disp_glsl(self)},
            ),
        )
        e = self._n_block
        #: per ping-pong side: position textures (one per element of a block)
        self._pos = [[self._atlas_texture() for _ in range(e)] for _ in range(2)]
        #: per ping-pong side: velocity textures
        self._vel = [[self._atlas_texture() for _ in range(e)] for _ in range(2)]
        self._fbo = [
            self._keep(ctx.framebuffer(color_attachments=self._state_list(i))) for i in range(2)
        ]
        self._cur = 0  # index of the textures holding the current state
        #: bumped whenever the displacement texture changes (set_state,
        #: set_constraints, step): lets a renderer tell one field state from the next
        #: without reading anything back
        self.revision = 0
        self._scope = self._keep(ctx.scope(self._fbo[0], enable_only=moderngl.NOTHING))

        inv_mass = 1.0 / np.asarray(model.mass, np.float64)
        self._inv_mass = inv_mass
        damping = np.zeros((*self.shape, 4), np.float32)
        self._damping = self._atlas_texture(self._to_atlas(damping)[0])  # filled below
        self._damping.write(self._packed(np.asarray(model.damping, np.float32)).tobytes())
        rest4 = np.zeros((*self.shape, 4), np.float32)
        rest4[..., :3] = model.rest
        self._rest = [self._atlas_texture(a) for a in self._to_atlas(rest4)]
        rest4[..., 3] = inv_mass  # target = rest, nothing pinned
        self._target = [self._atlas_texture(a) for a in self._to_atlas(rest4)]

        self._make_displacement()

        self._vbo = self._keep(ctx.buffer(self._tile_triangles().tobytes()))
        self._vao = self._keep(ctx.vertex_array(self._prog, [(self._vbo, "2f", "in_ndc")]))
        self._pin_vao = self._keep(ctx.vertex_array(self._pin_prog, [(self._vbo, "2f", "in_ndc")]))
        self._groups = tuple(-(-n // g) for n, g in zip(self.blocks, _GROUP, strict=True))

        self.set_state(np.asarray(model.rest, np.float64), np.zeros((*self.shape, 3)))

    def _state_list(self, side: int) -> list[Any]:
        """The state textures of one side in image-unit/attachment order (p0 v0 p1 v1 ...)."""
        return [t for pv in zip(self._pos[side], self._vel[side], strict=True) for t in pv]

    def _tile_triangles(self) -> np.ndarray:
        """NDC triangles covering the used tiles of the atlas (at most two rectangles)."""
        bx, by, bz = self.blocks
        tx, _ = self.tiles
        w, h = self.atlas_size
        rows, rem = divmod(bz, tx)
        rects = []
        if rows:
            rects.append((0, 0, w, rows * by))
        if rem:
            rects.append((0, rows * by, rem * bx, (rows + 1) * by))
        tris = []
        for x0, y0, x1, y1 in rects:
            a, b = 2.0 * x0 / w - 1.0, 2.0 * x1 / w - 1.0
            c, d = 2.0 * y0 / h - 1.0, 2.0 * y1 / h - 1.0
            tris += [(a, c), (b, c), (b, d), (a, c), (b, d), (a, d)]
        return np.array(tris, np.float32)

    def _block_atlas(self, blocks: np.ndarray) -> np.ndarray:
        """(bx, by, bz, 4) per-block values -> (height, width, 4) float32 atlas."""
        bx, by, bz = self.blocks
        tx, ty = self.tiles
        padded = np.zeros((bx, by, tx * ty, 4), np.float32)
        padded[:, :, :bz] = blocks
        tiles = padded.reshape(bx, by, ty, tx, 4)  # k = row * tx + column
        return np.ascontiguousarray(tiles.transpose(2, 1, 3, 0, 4)).reshape(ty * by, tx * bx, 4)

    def _split(self, grid: np.ndarray) -> list[np.ndarray]:
        """(nx, ny, nz, c) -> one (bx, by, bz, c) array per element of a block (padded 0)."""
        sx, sy, sz = self.block
        bx, by, bz = self.blocks
        padded = np.zeros((bx * sx, by * sy, bz * sz, grid.shape[3]), np.float32)
        nx, ny, nz = self.shape
        padded[:nx, :ny, :nz] = grid
        g = padded.reshape(bx, sx, by, sy, bz, sz, grid.shape[3])
        return [g[:, ex, :, ey, :, ez] for ex, ey, ez in _block_elements(self.block)]

    def _to_atlas(self, grid: np.ndarray) -> list[np.ndarray]:
        """(nx, ny, nz, 4) -> one (height, width, 4) float32 atlas per element of a block."""
        return [self._block_atlas(b) for b in self._split(grid)]

    def _packed(self, scalars: np.ndarray) -> np.ndarray:
        """(nx, ny, nz) -> atlas holding the scalar of block element e in channel e."""
        parts = self._split(scalars[..., None])
        blocks = np.zeros((*self.blocks, 4), np.float32)
        for e, part in enumerate(parts):
            blocks[..., e] = part[..., 0]
        return self._block_atlas(blocks)

    def _from_atlas(self, atlases: list[np.ndarray]) -> np.ndarray:
        """One (height, width, 4) atlas per block element -> (nx, ny, nz, 4)."""
        bx, by, bz = self.blocks
        sx, sy, sz = self.block
        tx, ty = self.tiles
        out = np.zeros((bx, sx, by, sy, bz, sz, 4), np.float32)
        for (ex, ey, ez), atlas in zip(_block_elements(self.block), atlases, strict=True):
            tiles = atlas.reshape(ty, by, tx, bx, 4).transpose(3, 1, 0, 2, 4)
            out[:, ex, :, ey, :, ez] = tiles.reshape(bx, by, ty * tx, 4)[:, :, :bz]
        nx, ny, nz = self.shape
        return out.reshape(bx * sx, by * sy, bz * sz, 4)[:nx, :ny, :nz]

    # ------------------------------------------------------------------ public API
    def set_state(self, positions: np.ndarray, velocities: np.ndarray) -> None:
        """Upload a new state (and update the displacement texture).

        As in the CPU solver, pinned elements keep the given state until the next step,
        which puts them back at their targets.

        Parameters
        ----------
        positions, velocities
            ``(nx, ny, nz, 3)`` element positions (world mm) and velocities (mm/s).

        Raises
        ------
        ValueError
            On a wrong shape or non-finite values.
        """
        self._check_alive()
        x = self._check_grid("positions", positions, 3)
        v = self._check_grid("velocities", velocities, 3)
        pos4 = np.zeros((*self.shape, 4), np.float32)
        pos4[..., :3] = x
        pos4[..., 3] = self.model.stiffness
        vel4 = np.zeros((*self.shape, 4), np.float32)
        vel4[..., :3] = v
        vel4[..., 3] = np.where(self._pinned, 0.0, self._inv_mass)
        for tex, data in zip(self._pos[self._cur], self._to_atlas(pos4), strict=True):
            tex.write(data.tobytes())
        for tex, data in zip(self._vel[self._cur], self._to_atlas(vel4), strict=True):
            tex.write(data.tobytes())
        self._pin_pending = bool(self._pinned.any())
        self._update_displacement()

    def set_constraints(self, pinned: np.ndarray, targets: np.ndarray) -> None:
        """Pin elements at targets.

        Pinned elements move to their targets at once, at rest (one GPU pass, no
        readback), and stay there: their inverse mass is 0 from then on.

        Parameters
        ----------
        pinned
            ``(nx, ny, nz)`` bool.
        targets
            ``(nx, ny, nz, 3)`` target positions (world mm); ignored where not pinned.

        Raises
        ------
        ValueError
            On a wrong shape or non-finite targets.
        """
        self._check_alive()
        p = self._check_grid("pinned", pinned, None).astype(bool)
        t = self._check_grid("targets", targets, 3)
        target4 = np.zeros((*self.shape, 4), np.float32)
        target4[..., :3] = t
        target4[..., 3] = np.where(p, -1.0, self._inv_mass)
        for tex, data in zip(self._target, self._to_atlas(target4), strict=True):
            tex.write(data.tobytes())
        self._pinned = p.copy()
        self._pin()
        self._update_displacement()

    def step(self, n: int = 1) -> None:
        """Advance ``n`` integration steps on the GPU (no readback).

        One draw per step; the displacement texture is updated once at the end.

        Parameters
        ----------
        n
            Number of steps, >= 0.

        Raises
        ------
        ValueError
            If ``n`` is negative or ``model.integrator`` is unknown.
        """
        self._check_alive()
        n = int(n)
        if n < 0:
            raise GpuSolverError(f"step count must be >= 0; got {n}")
        if n == 0:
            return
        m = self.model
        if m.integrator not in INTEGRATORS:
            raise GpuSolverError(f"integrator must be one of {INTEGRATORS}; got {m.integrator!r}")
        prog = self._prog
        prog["u_dt"].value = float(m.dt)
        prog["u_half_k"].value = 0.5 * float(m.spring_constant)
        prog["u_spring_damping"].value = float(m.spring_damping)
        prog["u_max_step"].value = float(m.max_step)
        prog["u_semi_implicit"].value = int(m.integrator == "semi-implicit")
        if self._pin_pending:  # pinned elements given a state by set_state: one step, re-pin
            self._passes(self._vao, 1, self._damping)
            self._pin()
            n -= 1
        self._passes(self._vao, n, self._damping)
        self._update_displacement()

    def _pin(self) -> None:
        """Move the pinned elements to their targets, at rest, with inverse mass 0."""
        self._passes(self._pin_vao, 1, None)
        self._pin_pending = False

    def _passes(self, vao: Any, n: int, damping: Any) -> None:
        """``n`` ping-pong draws of a program (one per step)."""
        if n <= 0:
            return
        bound = self.ctx.fbo
        units = len(self._state_list(0))
        with self._scope:  # blending etc. off; the bound framebuffer is restored after
            if damping is not None:
                damping.bind_to_image(units, read=True, write=False)
            else:
                for i, tex in enumerate(self._target):
                    tex.bind_to_image(units + i, read=True, write=False)
            for _ in range(n):
                src, dst = self._cur, 1 - self._cur
                for i, tex in enumerate(self._state_list(src)):
                    tex.bind_to_image(i, read=True, write=False)
                self._fbo[dst].use()
                vao.render(moderngl.TRIANGLES)
                self._cur = dst
        self.ctx.fbo = bound  # moderngl's record of the bound framebuffer, as GL has it

    def _update_displacement(self) -> None:
        self.revision += 1
        self._disp.bind_to_image(0, read=False, write=True, format=_GL_RGBA16F)
        e = self._n_block
        for i, tex in enumerate(self._pos[self._cur]):
            tex.bind_to_image(1 + i, read=True, write=False)
        for i, tex in enumerate(self._rest):
            tex.bind_to_image(1 + e + i, read=True, write=False)
        self._comp.run(*self._groups)
        self.ctx.memory_barrier()

    def _read(self, textures: list[list[Any]]) -> np.ndarray:
        raws = [self._read_atlas(t) for t in textures[self._cur]]
        return self._from_atlas(raws)

    def positions(self) -> np.ndarray:
        """Read back the element positions.

        Returns
        -------
        numpy.ndarray
            ``(nx, ny, nz, 3)`` float64, world mm.
        """
        self._check_alive()
        return self._read(self._pos)[..., :3].astype(np.float64)

    def velocities(self) -> np.ndarray:
        """Read back the element velocities.

        Returns
        -------
        numpy.ndarray
            ``(nx, ny, nz, 3)`` float64, mm/s.
        """
        self._check_alive()
        return self._read(self._vel)[..., :3].astype(np.float64)

    def max_speed(self) -> float:
        """Largest element speed (mm/s); reads the velocities back.

        Returns
        -------
        float
            ``max |v|`` over all elements.
        """
        self._check_alive()
        v = self._read(self._vel)[..., :3]
        return float(np.sqrt(np.max(np.einsum("...i,...i->...", v, v))))


def _block_elements(block: tuple[int, int, int]) -> list[tuple[int, int, int]]:
    """Coordinates of the elements within a block, in texture order (x fastest)."""
    sx, sy, sz = block
    return [(ex, ey, ez) for ez in range(sz) for ey in range(sy) for ex in range(sx)]


def _config_glsl(
    shape: tuple[int, int, int], block: tuple[int, int, int], tiles_x: int, model: SpringModel
) -> str:
    """``massspring_config.glsl``: grid, block and atlas constants (see module doc)."""
    nx, ny, nz = shape
    sx, sy, sz = block
    bx, by, bz = block_shape(shape, block)
    e = sx * sy * sz
    return (
        f"#define NX {nx}\n#define NY {ny}\n#define NZ {nz}\n"
        f"#define SX {sx}\n#define SY {sy}\n#define SZ {sz}\n"
        f"#define BX {bx}\n#define BY {by}\n#define BZ {bz}\n#define TX {tiles_x}\n"
        f"#define MS_E {e}\n#define MS_STATE {2 * e}\n#define MS_REST_BINDING {1 + e}\n"
        f"#define MS_SPRINGS {len(model.offsets)}\n"
        f"#define MS_MIN_LENGTH {model.min_length!r}\n"
    )


def _ivec3(v: Any) -> str:
    return "ivec3({}, {}, {})".format(*(int(c) for c in v))


def _inside(coords: list[tuple[int, int, int]], offset: Any) -> str:
    """GLSL test that the elements at ``base + c`` (c in coords) are inside the grid,
    checked only along the axes of ``offset`` (along the others they share the own
    element's coordinate)."""
    terms = []
    for a, (axis, n) in enumerate(zip("xyz", ("NX", "NY", "NZ"), strict=True)):
        if offset[a] == 0:
            continue
        lo = min(c[a] for c in coords)
        hi = max(c[a] for c in coords)
        if lo < 0:
            terms.append(f"base.{axis} >= {-lo}")
        if hi > 0:
            terms.append(f"base.{axis} < {n} - {hi}")
    return " && ".join(terms) or "true"


def _step_glsl(solver: GpuSpringSolver) -> str:
    """``massspring_pass.glsl`` of the step: ``main()`` unrolled over the block's
    elements and springs (each distinct neighbour texel is loaded once; a spring
    between two elements of the block is evaluated once, +F / -F)."""
    block = solver.block
    elems = _block_elements(block)
    index = {c: i for i, c in enumerate(elems)}
    offsets = [tuple(int(c) for c in o) for o in solver.model.offsets.tolist()]
    lengths = [float(x) for x in solver.model.rest_lengths()]
    lines = [
        "void main() {",
        "    ivec2 t = ivec2(gl_FragCoord.xy);",
        "    ivec3 b = ms_block(t);",
        "    ivec3 base = b * ivec3(SX, SY, SZ);",
        "    const ivec3 blast = ivec3(BX - 1, BY - 1, BZ - 1);",
    ]
    for i in range(len(elems)):
        lines.append(f"    vec4 p{i} = imageLoad(u_state[{2 * i}], t);")
        lines.append(f"    vec4 v{i} = imageLoad(u_state[{2 * i + 1}], t);")
        lines.append(f"    vec3 f{i} = vec3(0.0);")
    loaded: dict[tuple[tuple[int, int, int], int], str] = {}
    texels: dict[tuple[int, int, int], str] = {}
    body: list[str] = []
    for i, c in enumerate(elems):
        for o, length in zip(offsets, lengths, strict=True):
            n = tuple(c[a] + o[a] for a in range(3))
            bo = tuple(n[a] // block[a] for a in range(3))
            ec = tuple(n[a] - bo[a] * block[a] for a in range(3))
            j = index[ec]
            if bo == (0, 0, 0):  # inside the block: once per pair
                if j > i:
                    cond = _inside([c, n], o)
                    body.append(
                        f"    {{ vec3 F = ms_spring(p{i}, v{i}, p{j}, v{j}, {length!r}, {cond});"
                        f" f{i} += F; f{j} -= F; }}"
                    )
                continue
            if bo not in texels:
                name = "t_" + "_".join(str(x).replace("-", "m") for x in bo)
                texels[bo] = name
                lines.append(
                    f"    ivec2 {name} = ms_texel(clamp(b + {_ivec3(bo)}, ivec3(0), blast));"
                )
            tn = texels[bo]
            key = (bo, j)
            if key not in loaded:
                name = f"{tn}_{j}"
                loaded[key] = name
                lines.append(f"    vec4 p{name} = imageLoad(u_state[{2 * j}], {tn});")
                lines.append(f"    vec4 v{name} = imageLoad(u_state[{2 * j + 1}], {tn});")
            name = loaded[key]
            cond = _inside([n], o)
            body.append(f"    f{i} += ms_spring(p{i}, v{i}, p{name}, v{name}, {length!r}, {cond});")
    lines += body
    lines.append("    vec4 damping = imageLoad(u_damping, t);")
    for i in range(len(elems)):
        lines.append(
            f"    ms_integrate(p{i}, v{i}, f{i}, damping[{i}],"
            f" ms_out[{2 * i}], ms_out[{2 * i + 1}]);"
        )
    lines.append("}")
    return "\n".join(lines) + "\n"


def _pin_glsl(solver: GpuSpringSolver) -> str:
    """``massspring_pass.glsl`` of the pin pass: pinned elements (target ``w`` < 0) go
    to their target at rest; every element's velocity ``w`` becomes the target's ``w``
    clamped at 0 (its inverse mass, 0 when pinned)."""
    lines = ["void main() {", "    ivec2 t = ivec2(gl_FragCoord.xy);"]
    for i in range(solver._n_block):
        lines.append(
            f"    ms_pin(imageLoad(u_state[{2 * i}], t), imageLoad(u_state[{2 * i + 1}], t),"
            f" imageLoad(u_target[{i}], t), ms_out[{2 * i}], ms_out[{2 * i + 1}]);"
        )
    lines.append("}")
    return "\n".join(lines) + "\n"


def _disp_glsl(solver: GpuSpringSolver) -> str:
    """``massspring_pass.glsl`` of the displacement shader: one store per block element."""
    lines = []
    for i, c in enumerate(_block_elements(solver.block)):
        lines.append(
            f"    MS_DISPLACE(base + {_ivec3(c)}, imageLoad(u_pos[{i}], t),"
            f" imageLoad(u_rest[{i}], t));"
        )
    return "\n".join(lines) + "\n"


def _check_model(model: SpringModel) -> tuple[int, int, int]:
    """Validate the model's arrays; return the grid shape."""
    rest = np.asarray(model.rest)
    if rest.ndim != 4 or rest.shape[3] != 3 or min(rest.shape[:3]) < 1:
        raise GpuSolverError(f"model.rest must have shape (nx, ny, nz, 3); got {rest.shape}")
    shape = tuple(int(n) for n in rest.shape[:3])
    for name in ("stiffness", "damping", "mass"):
        a = np.asarray(getattr(model, name))
        if a.shape != shape:
            raise GpuSolverError(f"model.{name} must have shape {shape}; got {a.shape}")
    if not np.all(np.asarray(model.mass) > 0):
        raise GpuSolverError("model.mass must be > 0 everywhere")
    if np.asarray(model.spacing).shape != (3,):
        raise GpuSolverError(f"model.spacing must have shape (3,); got {np.shape(model.spacing)}")
    if model.integrator not in INTEGRATORS:
        raise GpuSolverError(
            f"model.integrator must be one of {INTEGRATORS}; got {model.integrator!r}"
        )
    if len(model.offsets) > MAX_SPRINGS:
        raise GpuSolverError(f"at most {MAX_SPRINGS} springs per element; got {len(model.offsets)}")
    if not math.isfinite(float(model.dt)):
        raise GpuSolverError(f"model.dt must be finite; got {model.dt}")
    return shape  # type: ignore[return-value]
