"""GPU solver of the mass-spring model: fragment shaders ping-ponging between framebuffers.

About this technique (Knoche 2008, 3.5)
---------------------------------------
:class:`GpuSpringSolver` integrates exactly the physics of :mod:`deform.spring_model`
(the same as :class:`deform.massspring.CpuSpringSolver`, to float32 round-off) on a
``moderngl`` context. One draw call is one integration step: one fragment per element
reads the previous state of the element and of its spring neighbours with
``texelFetch`` and writes the new position and velocity into two colour attachments
(MRT) of the other framebuffer of a ping-pong pair. ``step(n)`` never reads back.

Element atlas
-------------
State and per-element constants live in 2D RGBA32F textures in which the
``(nx, ny, nz)`` element grid is tiled by z-slices: ``tiles_x`` tiles per row, slice
``k`` being the ``nx x ny`` tile at column ``k % tiles_x`` and row ``k // tiles_x``, so
element ``(i, j, k)`` is texel

    ``(u, v) = (i + (k % tiles_x) * nx,  j + (k // tiles_x) * ny)``

(``u`` = column/x, ``v`` = row/y of the texture). The atlas is
``(tiles_x * nx) x (tiles_y * ny)`` texels with ``tiles_y = ceil(nz / tiles_x)``;
``tiles_x`` is chosen to make it as square as possible within ``GL_MAX_TEXTURE_SIZE``
(128³ elements: 11 x 12 tiles, 1408 x 1536 texels). Tiles past slice ``nz - 1`` are
unused; the step draw covers only the used tiles. ``nx, ny, nz, tiles_x``, the spring
offsets and rest lengths (``model.offsets``, ``model.rest_lengths()``, at most 24) are
compile-time constants of the shaders (one program per solver, generated as
``massspring_config.glsl``), so the spring loop unrolls and the atlas arithmetic
folds; neighbours outside the grid are clamped into it and weighted 0 (no branches).
The step reads its inputs with ``imageLoad`` (unfiltered, like ``texelFetch``); on
llvmpipe this, the constant tables and the branch-free loop together make a step about
twice as fast as ``texelFetch`` with uniform arrays. Textures:

* position ``(x, y, z, stiffness)`` and velocity ``(vx, vy, vz, 0)``, two of each
  (ping-pong); carrying the stiffness in the position's ``w`` saves one fetch per
  spring;
* material ``(damping, mass, 0, 0)`` and rest ``(x, y, z, 0)``, from the model;
* target ``(x, y, z, pinned)`` from :meth:`GpuSpringSolver.set_constraints`.

Displacement texture
--------------------
After every :meth:`GpuSpringSolver.step` (and :meth:`~GpuSpringSolver.set_state`) a
compute shader (one invocation per element, 8 x 8 x 1 groups) writes the
``(nx, ny, nz)`` RGBA16F texture of :meth:`~GpuSpringSolver.displacement_texture` with
``imageStore``: ``(x - rest, stiffness)``; a ``glMemoryBarrier`` follows, so the
raycaster can sample it at once. Nothing is read back to the CPU.
:meth:`~GpuSpringSolver.set_constraints` moves the pinned elements to their targets at
once (as the CPU solver does) with one more draw of the step program that only pins.

The model's scalar parameters (``dt``, ``spring_constant``, ``spring_damping``,
``max_step``, ``integrator``) are read at every :meth:`~GpuSpringSolver.step`; its
per-element arrays (``rest``, ``stiffness``, ``damping``, ``mass``) and springs
(``shear``, ``bend``, ``spacing``) are uploaded once, at construction.

The solver draws on the context it is given and does not make it current: the caller
does (as for :class:`app.render.Renderer`). GL state it changes (enable flags, bound
framebuffer) is restored after each call; image units 0-3 are left bound to its
textures.
"""

from __future__ import annotations

import math
from typing import Any

import moderngl
import numpy as np

import shaders
from deform.spring_model import INTEGRATORS, SpringModel

#: Most springs per element the shaders accept (structural + shear + bend).
MAX_SPRINGS = 24
#: Work-group size of the displacement compute shader.
_GROUP = (8, 8, 1)
#: GL_RGBA16F, the image format of the displacement texture.
_GL_RGBA16F = 0x881A


def atlas_layout(shape: tuple[int, int, int], max_size: int) -> tuple[int, int]:
    """Tiles per row and per column of the z-slice atlas of a grid (see module doc).

    Parameters
    ----------
    shape
        Elements per axis ``(nx, ny, nz)``.
    max_size
        Largest texture side allowed (``GL_MAX_TEXTURE_SIZE``).

    Returns
    -------
    tuple of int
        ``(tiles_x, tiles_y)`` with ``tiles_x * tiles_y >= nz``, minimising the longer
        atlas side, then the atlas area.

    Raises
    ------
    ValueError
        If no arrangement fits within ``max_size``.
    """
    nx, ny, nz = (int(n) for n in shape)
    best: tuple[tuple[int, int], tuple[int, int]] | None = None
    for tx in range(1, nz + 1):
        ty = -(-nz // tx)
        w, h = tx * nx, ty * ny
        if w > max_size or h > max_size:
            continue
        key = (max(w, h), w * h)
        if best is None or key < best[0]:
            best = (key, (tx, ty))
    if best is None:
        raise ValueError(
            f"a grid of {nx}x{ny}x{nz} elements does not fit in a 2D atlas of at most"
            f" {max_size}x{max_size} texels"
        )
    return best[1]


class GpuSpringSolver:
    """Mass-spring solver on the GPU (see module doc for the technique and layout).

    Parameters
    ----------
    model
        The model: grid, materials, springs and integrator.
    ctx
        A ``moderngl.Context`` (OpenGL 4.3+, for the compute shader); the caller owns it
        and makes it current.

    Raises
    ------
    ValueError
        If ``ctx`` is None or too old, or the model is inconsistent (array shapes,
        non-positive mass, unknown integrator, more than 24 springs) or too large for
        the context's textures.
    """

    def __init__(self, model: SpringModel, ctx: Any) -> None:
        if ctx is None:
            raise ValueError(
                "GpuSpringSolver needs a moderngl.Context (OpenGL 4.3+); got None"
                " (use deform.massspring.CpuSpringSolver without a GL context)"
            )
        if getattr(ctx, "version_code", 0) < 430:
            raise ValueError(
                "GpuSpringSolver needs an OpenGL 4.3+ context (compute shaders); got"
                f" version {getattr(ctx, 'version_code', None)}"
            )
        self.model = model
        self.ctx = ctx
        self._released = False
        self._objects: list[Any] = []
        shape = _check_model(model)
        self.shape: tuple[int, int, int] = shape
        nx, ny, nz = shape
        info = ctx.info
        max_2d = int(info.get("GL_MAX_TEXTURE_SIZE", 16384))
        max_3d = int(info.get("GL_MAX_3D_TEXTURE_SIZE", 2048))
        if max(shape) > max_3d:
            raise ValueError(
                f"a grid of {nx}x{ny}x{nz} elements exceeds GL_MAX_3D_TEXTURE_SIZE {max_3d}"
            )
        tx, ty = atlas_layout(shape, max_2d)
        #: tiles per row and per column of the atlas
        self.tiles: tuple[int, int] = (tx, ty)
        #: atlas size in texels (width, height)
        self.atlas_size: tuple[int, int] = (tx * nx, ty * ny)
        self._n_springs = len(model.offsets)

        try:
            self._create(model)
        except Exception:
            self.release()
            raise

    # ------------------------------------------------------------------ setup
    def _create(self, model: SpringModel) -> None:
        ctx = self.ctx
        tx, _ = self.tiles
        extra = {"massspring_config.glsl": _config_glsl(self.shape, tx, model)}
        self._prog = self._keep(
            ctx.program(
                vertex_shader=shaders.source("massspring_step.vert.glsl"),
                fragment_shader=shaders.source("massspring_step.frag.glsl", extra),
            )
        )
        self._comp = self._keep(
            ctx.compute_shader(shaders.source("massspring_displacement.comp.glsl", extra))
        )
        self._pos = [self._state_texture() for _ in range(2)]
        self._vel = [self._state_texture() for _ in range(2)]
        self._fbo = [
            self._keep(ctx.framebuffer(color_attachments=[self._pos[i], self._vel[i]]))
            for i in range(2)
        ]
        self._cur = 0  # index of the textures holding the current state
        self._scope = self._keep(ctx.scope(self._fbo[0], enable_only=moderngl.NOTHING))

        material = np.zeros((*self.shape, 4), np.float32)
        material[..., 0] = model.damping
        material[..., 1] = model.mass
        self._material = self._state_texture(self._to_atlas(material))
        rest4 = np.zeros((*self.shape, 4), np.float32)
        rest4[..., :3] = model.rest
        self._rest = self._state_texture(self._to_atlas(rest4))
        rest4[..., 3] = 0.0  # target = rest, nothing pinned
        self._target = self._state_texture(self._to_atlas(rest4))

        self._disp = self._keep(ctx.texture3d(self.shape, 4, dtype="f2"))
        self._disp.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self._disp.repeat_x = self._disp.repeat_y = self._disp.repeat_z = False

        self._vbo = self._keep(ctx.buffer(self._tile_triangles().tobytes()))
        self._vao = self._keep(ctx.vertex_array(self._prog, [(self._vbo, "2f", "in_ndc")]))
        self._groups = tuple(-(-n // g) for n, g in zip(self.shape, _GROUP, strict=True))

        self.set_state(np.asarray(model.rest, np.float64), np.zeros((*self.shape, 3)))

    def _keep(self, obj: Any) -> Any:
        self._objects.append(obj)
        return obj

    def _state_texture(self, data: np.ndarray | None = None) -> Any:
        w, h = self.atlas_size
        tex = self._keep(
            self.ctx.texture((w, h), 4, None if data is None else data.tobytes(), dtype="f4")
        )
        if data is None:
            tex.write(np.zeros((h, w, 4), np.float32).tobytes())
        tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        tex.repeat_x = tex.repeat_y = False
        return tex

    def _tile_triangles(self) -> np.ndarray:
        """NDC triangles covering the used tiles of the atlas (at most two rectangles)."""
        nx, ny, nz = self.shape
        tx, _ = self.tiles
        w, h = self.atlas_size
        rows, rem = divmod(nz, tx)
        rects = []
        if rows:
            rects.append((0, 0, w, rows * ny))
        if rem:
            rects.append((0, rows * ny, rem * nx, (rows + 1) * ny))
        tris = []
        for x0, y0, x1, y1 in rects:
            a, b = 2.0 * x0 / w - 1.0, 2.0 * x1 / w - 1.0
            c, d = 2.0 * y0 / h - 1.0, 2.0 * y1 / h - 1.0
            tris += [(a, c), (b, c), (b, d), (a, c), (b, d), (a, d)]
        return np.array(tris, np.float32)

    def _to_atlas(self, grid: np.ndarray) -> np.ndarray:
        """(nx, ny, nz, 4) -> (height, width, 4) float32 atlas (rows = texture y)."""
        nx, ny, nz = self.shape
        tx, ty = self.tiles
        padded = np.zeros((nx, ny, tx * ty, 4), np.float32)
        padded[:, :, :nz] = grid
        tiles = padded.reshape(nx, ny, ty, tx, 4)  # k = row * tx + column
        return np.ascontiguousarray(tiles.transpose(2, 1, 3, 0, 4)).reshape(ty * ny, tx * nx, 4)

    def _from_atlas(self, atlas: np.ndarray) -> np.ndarray:
        """(height, width, 4) atlas -> (nx, ny, nz, 4)."""
        nx, ny, nz = self.shape
        tx, ty = self.tiles
        tiles = atlas.reshape(ty, ny, tx, nx, 4).transpose(3, 1, 0, 2, 4)  # (nx, ny, ty, tx)
        return tiles.reshape(nx, ny, ty * tx, 4)[:, :, :nz]

    def _check_alive(self) -> None:
        if self._released:
            raise RuntimeError("GpuSpringSolver used after release()")

    def _check_grid(self, name: str, array: Any, channels: int | None) -> np.ndarray:
        a = np.asarray(array)
        want = self.shape if channels is None else (*self.shape, channels)
        if a.shape != want:
            raise ValueError(f"{name} must have shape {want}; got {a.shape}")
        if channels is not None:
            a = a.astype(np.float64, copy=False)
            if not np.all(np.isfinite(a)):
                raise ValueError(f"{name} must be finite")
        return a

    # ------------------------------------------------------------------ public API
    def set_state(self, positions: np.ndarray, velocities: np.ndarray) -> None:
        """Upload a new state (and update the displacement texture).

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
        self._pos[self._cur].write(self._to_atlas(pos4).tobytes())
        self._vel[self._cur].write(self._to_atlas(vel4).tobytes())
        self._update_displacement()

    def set_constraints(self, pinned: np.ndarray, targets: np.ndarray) -> None:
        """Pin elements at targets.

        Pinned elements move to their targets at once, at rest (one GPU pass, no
        readback), and are set there with zero velocity after every integration step.

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
        target4[..., 3] = p
        self._target.write(self._to_atlas(target4).tobytes())
        self._passes(1, pin_only=True)
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
            raise ValueError(f"step count must be >= 0; got {n}")
        if n == 0:
            return
        m = self.model
        if m.integrator not in INTEGRATORS:
            raise ValueError(f"integrator must be one of {INTEGRATORS}; got {m.integrator!r}")
        prog = self._prog
        prog["u_dt"].value = float(m.dt)
        prog["u_spring_constant"].value = float(m.spring_constant)
        prog["u_spring_damping"].value = float(m.spring_damping)
        prog["u_max_step"].value = float(m.max_step)
        prog["u_semi_implicit"].value = int(m.integrator == "semi-implicit")
        self._passes(n, pin_only=False)
        self._update_displacement()

    def _passes(self, n: int, pin_only: bool) -> None:
        """``n`` ping-pong draws of the step program (one per step)."""
        self._prog["u_pin_only"].value = pin_only
        bound = self.ctx.fbo
        with self._scope:  # blending etc. off; the bound framebuffer is restored after
            self._material.bind_to_image(2, read=True, write=False)
            self._target.bind_to_image(3, read=True, write=False)
            for _ in range(n):
                src, dst = self._cur, 1 - self._cur
                self._pos[src].bind_to_image(0, read=True, write=False)
                self._vel[src].bind_to_image(1, read=True, write=False)
                self._fbo[dst].use()
                self._vao.render(moderngl.TRIANGLES)
                self._cur = dst
        self.ctx.fbo = bound  # moderngl's record of the bound framebuffer, as GL has it

    def _update_displacement(self) -> None:
        self._disp.bind_to_image(0, read=False, write=True, format=_GL_RGBA16F)
        self._pos[self._cur].bind_to_image(1, read=True, write=False)
        self._rest.bind_to_image(2, read=True, write=False)
        self._comp.run(*self._groups)
        self.ctx.memory_barrier()

    def _read(self, textures: list[Any]) -> np.ndarray:
        w, h = self.atlas_size
        raw = np.frombuffer(textures[self._cur].read(), np.float32).reshape(h, w, 4)
        return self._from_atlas(raw)

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

    def displacement_texture(self) -> moderngl.Texture3D:
        """The offset field as a 3D texture, kept up to date on the GPU.

        Returns
        -------
        moderngl.Texture3D
            Size ``(nx, ny, nz)``, RGBA16F; texel ``(i, j, k)`` holds the element's
            displacement ``x - rest`` (world mm) in xyz and its stiffness in a. Linear
            filtering, clamped to edge. Owned by the solver (freed by :meth:`release`);
            the same object for the solver's lifetime.
        """
        self._check_alive()
        return self._disp

    def release(self) -> None:
        """Free all GPU objects (textures, framebuffers, programs); idempotent."""
        if self._released:
            return
        self._released = True
        for obj in reversed(self._objects):
            try:
                obj.release()
            except Exception:  # context already gone: nothing left to free
                pass
        self._objects.clear()


def _config_glsl(shape: tuple[int, int, int], tiles_x: int, model: SpringModel) -> str:
    """``massspring_config.glsl``: grid and atlas constants and the spring tables."""
    nx, ny, nz = shape
    offsets = ", ".join(f"ivec3({a}, {b}, {c})" for a, b, c in model.offsets.tolist())
    lengths = ", ".join(repr(float(x)) for x in model.rest_lengths())
    m = len(model.offsets)
    return (
        f"#define NX {nx}\n#define NY {ny}\n#define NZ {nz}\n#define TX {tiles_x}\n"
        f"#define M {m}\n"
        f"const ivec3 MS_OFFSET[M] = ivec3[M]({offsets});\n"
        f"const float MS_REST_LENGTH[M] = float[M]({lengths});\n"
    )


def _check_model(model: SpringModel) -> tuple[int, int, int]:
    """Validate the model's arrays; return the grid shape."""
    rest = np.asarray(model.rest)
    if rest.ndim != 4 or rest.shape[3] != 3 or min(rest.shape[:3]) < 1:
        raise ValueError(f"model.rest must have shape (nx, ny, nz, 3); got {rest.shape}")
    shape = tuple(int(n) for n in rest.shape[:3])
    for name in ("stiffness", "damping", "mass"):
        a = np.asarray(getattr(model, name))
        if a.shape != shape:
            raise ValueError(f"model.{name} must have shape {shape}; got {a.shape}")
    if not np.all(np.asarray(model.mass) > 0):
        raise ValueError("model.mass must be > 0 everywhere")
    if np.asarray(model.spacing).shape != (3,):
        raise ValueError(f"model.spacing must have shape (3,); got {np.shape(model.spacing)}")
    if model.integrator not in INTEGRATORS:
        raise ValueError(f"model.integrator must be one of {INTEGRATORS}; got {model.integrator!r}")
    if len(model.offsets) > MAX_SPRINGS:
        raise ValueError(f"at most {MAX_SPRINGS} springs per element; got {len(model.offsets)}")
    if not math.isfinite(float(model.dt)):
        raise ValueError(f"model.dt must be finite; got {model.dt}")
    return shape  # type: ignore[return-value]
