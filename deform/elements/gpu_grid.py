"""What the GPU solvers of the element models share: their set-up and their GPU objects.

:class:`~voxwarp.deform.elements.massspring_gpu.GpuSpringSolver` and
:class:`~voxwarp.deform.elements.chainmail_gpu.GpuChainMailSolver` check the context they
are given (:meth:`GpuGridSolver._setup`), lay their state out as a 2D atlas of z-slice
tiles (:func:`atlas_layout`, :meth:`GpuGridSolver._set_atlas`), create the atlas
textures, the pass and pin programs, the displacement compute shader and the
displacement array texture the offset-field warp samples; each keeps them
(:meth:`GpuGridSolver._keep`) and frees all of them, once, in
:meth:`GpuGridSolver.release`.
"""

from __future__ import annotations

from typing import Any

import moderngl
import numpy as np

from voxwarp.deform import gl_programs
from voxwarp.errors import VoxwarpError

#: llvmpipe's raster tile (pixels): each is shaded by one thread
RASTER_TILE = 64


class GpuSolverError(VoxwarpError, ValueError):
    """A GPU solver cannot be set up or driven as asked (context, sizes, inputs)."""


def require_compute_context(ctx: Any, owner: str, without: str, needs: str) -> None:
    """A :class:`GpuSolverError` unless ``ctx`` is a moderngl context of OpenGL 4.3+.

    ``owner`` names the solver, ``without`` what to use without a GL context, ``needs``
    the features it needs (in the messages)."""
    if ctx is None:
        raise GpuSolverError(
            f"{owner} needs a moderngl.Context (OpenGL 4.3+); got None ({without})"
        )
    if getattr(ctx, "version_code", 0) < 430:
        raise GpuSolverError(
            f"{owner} needs an OpenGL 4.3+ context ({needs}); got"
            f" version {getattr(ctx, 'version_code', None)}"
        )


def atlas_layout(shape: tuple[int, int, int], max_size: int) -> tuple[int, int]:
    """Tiles per row and per column of the z-slice atlas of a grid.

    Parameters
    ----------
    shape
        Cells per axis ``(nx, ny, nz)`` (the mass-spring solver passes its block grid).
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
        raise GpuSolverError(
            f"a grid of {nx}x{ny}x{nz} elements does not fit in a 2D atlas of at most"
            f" {max_size}x{max_size} texels"
        )
    return best[1]


class GpuGridSolver:
    """Base of the GPU solvers on an ``(nx, ny, nz)`` element grid (see module doc).

    Subclasses set :attr:`shape` and call :meth:`_init_objects` before making any GPU
    object.
    """

    #: elements per axis
    shape: tuple[int, int, int]
    #: tiles per row and per column of the atlas, and its size in texels (width, height)
    tiles: tuple[int, int]
    atlas_size: tuple[int, int]

    def _setup(self, model: Any, ctx: Any, owner: str, without: str, needs: str) -> None:
        """Check ``ctx`` (:func:`require_compute_context`), keep ``model`` and ``ctx``,
        start owning GPU objects."""
        require_compute_context(ctx, owner, without, needs)
        self.model = model
        self.ctx = ctx
        self._init_objects()

    def _set_atlas(self, cells: tuple[int, int, int], max_2d: int) -> None:
        """:attr:`tiles` and :attr:`atlas_size` of an atlas of ``cells`` (per axis, one
        texel each) in z-slice tiles; small atlases go in one row (at least two raster
        tiles, so two llvmpipe threads)."""
        cx, cy, cz = cells
        tx, ty = atlas_layout(cells, max_2d)
        if tx * cx <= RASTER_TILE and ty * cy <= RASTER_TILE and cz * cx <= max_2d:
            tx, ty = cz, 1  # one row: at least two raster tiles, so two threads
        self.tiles = (tx, ty)
        self.atlas_size = (tx * cx, ty * cy)

    def _atlas_texture(self, data: np.ndarray | None = None) -> Any:
        """An owned RGBA32F texture of the atlas' size (zeros without ``data``), nearest
        filtering, clamped."""
        w, h = self.atlas_size
        if data is None:
            data = np.zeros((h, w, 4), np.float32)
        tex = self._keep(self.ctx.texture((w, h), 4, data.tobytes(), dtype="f4"))
        tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        tex.repeat_x = tex.repeat_y = False
        return tex

    def _read_atlas(self, tex: Any) -> np.ndarray:
        """An atlas texture read back, (height, width, 4) float32."""
        w, h = self.atlas_size
        return np.frombuffer(tex.read(), np.float32).reshape(h, w, 4)

    def _make_programs(self, vertex: str, fragment: str, pin_fragment: str, compute: str) -> None:
        """The owned pass program (``_prog``), pin program (``_pin_prog``) and
        displacement compute shader (``_comp``) from their sources."""
        ctx = self.ctx
        keep = self._keep
        self._prog = keep(
            gl_programs.program(ctx, vertex_shader=vertex, fragment_shader=fragment)
        ).program
        self._pin_prog = keep(
            gl_programs.program(ctx, vertex_shader=vertex, fragment_shader=pin_fragment)
        ).program
        self._comp = keep(gl_programs.compute_shader(ctx, compute)).program

    def _make_displacement(self) -> None:
        """The owned displacement texture (``_disp``): z-slices as layers of a 2D array
        (the offset-field warp samples it with two bilinear fetches, cheaper than one 3D
        trilinear fetch on llvmpipe), RGBA16F, linear, clamped."""
        self._disp = self._keep(self.ctx.texture_array(self.shape, 4, dtype="f2"))
        self._disp.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self._disp.repeat_x = self._disp.repeat_y = False

    def displacement_texture(self) -> moderngl.TextureArray:
        """The offset field as a 2D array texture (z-slices as layers), kept up to date
        on the GPU.

        Returns
        -------
        moderngl.TextureArray
            Size ``(nx, ny, nz)``, RGBA16F; texel ``(i, j)`` of layer ``k`` holds the
            element's displacement ``x - rest`` (world mm) in xyz (and what the solver
            stores in a: the stiffness for mass-spring, 0 for ChainMail). Linear
            filtering, clamped to edge. Owned by the solver (freed by :meth:`release`);
            the same object for the solver's lifetime.
        """
        self._check_alive()
        return self._disp

    def _init_objects(self) -> None:
        self._released = False
        self._objects: list[Any] = []

    def _keep(self, obj: Any) -> Any:
        """Own a GPU object: it is freed by :meth:`release`."""
        self._objects.append(obj)
        return obj

    def _check_alive(self) -> None:
        if self._released:
            raise RuntimeError(f"{type(self).__name__} used after release()")

    def _check_grid(self, name: str, array: Any, channels: int | None) -> np.ndarray:
        """``array`` checked to be ``shape`` (+ ``channels``) and, with channels,
        finite float64; ``ValueError`` naming ``name`` otherwise."""
        a = np.asarray(array)
        want = self.shape if channels is None else (*self.shape, channels)
        if a.shape != want:
            raise ValueError(f"{name} must have shape {want}; got {a.shape}")
        if channels is not None:
            a = a.astype(np.float64, copy=False)
            if not np.all(np.isfinite(a)):
                raise ValueError(f"{name} must be finite")
        return a

    def _create_or_release(self, model: Any) -> None:
        """Run the subclass's ``_create(model)``; on failure free what it made, re-raise."""
        try:
            self._create(model)  # type: ignore[attr-defined]
        except Exception:
            self.release()
            raise

    def release(self) -> None:
        """Free all GPU objects (textures, framebuffers, programs, buffers); idempotent."""
        if self._released:
            return
        self._released = True
        for obj in reversed(self._objects):
            try:
                obj.release()
            except Exception:  # context already gone: nothing left to free
                pass
        self._objects.clear()
