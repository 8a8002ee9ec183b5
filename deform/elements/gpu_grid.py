"""What the GPU solvers of the element models share: ownership of their GPU objects.

:class:`~voxwarp.deform.elements.massspring_gpu.GpuSpringSolver` and
:class:`~voxwarp.deform.elements.chainmail_gpu.GpuChainMailSolver` create textures, framebuffers and
programs on a context they are given; each keeps them (:meth:`GpuGridSolver._keep`)
and frees all of them, once, in :meth:`GpuGridSolver.release`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from voxwarp.errors import VoxwarpError


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


class GpuGridSolver:
    """Base of the GPU solvers on an ``(nx, ny, nz)`` element grid (see module doc).

    Subclasses set :attr:`shape` and call :meth:`_init_objects` before making any GPU
    object.
    """

    #: elements per axis
    shape: tuple[int, int, int]

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
