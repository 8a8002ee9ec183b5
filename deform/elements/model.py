"""What mass-spring and 3D ChainMail have in common: a grid of elements that can be
fixed, held at offsets and read back, with an offset-field warp for the raycaster.

:class:`ElementModel` names the interface (a ``typing.Protocol``; the edit session and
the animation code use only these methods). :class:`ElementWarpMixin` is the one
implementation both models share of the warp, its scene-JSON snapshot, resuming from a
saved warp and releasing GPU resources. The functions at the end are the parts of their
save/load (``to_dict``/``from_dict``) they share: the entry's type check, the ``"held"``
list, and closing a model whose set-up from an entry fails.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any, ClassVar, Protocol, runtime_checkable

import numpy as np

from voxwarp.deform.elements.offset_field import element_model_warp, saved_model, texture_field

if TYPE_CHECKING:
    from typing import Self

    from voxwarp.deform.elements.grid import ElementGrid, Selection


@runtime_checkable
class ElementModel(Protocol):
    """An element model over an :class:`~voxwarp.deform.elements.grid.ElementGrid`."""

    grid: ElementGrid
    #: ``"cpu"`` or ``"gpu"``
    backend: str

    def fix(self, sel: Selection) -> None:
        """Fix elements at rest."""

    def free(self, sel: Selection) -> None:
        """Free fixed elements."""

    def move(self, sel: Selection, offsets: Any) -> Any:
        """Hold elements at ``offsets`` (mm) from rest; the model moves the rest."""

    def release(self, sel: Selection = None) -> None:
        """Stop holding elements (all by default)."""

    def reset(self) -> None:
        """Back to rest, nothing held."""

    def positions(self) -> np.ndarray:
        """(nx, ny, nz, 3) element positions (mm)."""

    def displacements(self) -> np.ndarray:
        """(nx, ny, nz, 3) positions minus rest positions (mm)."""

    def warp(self, inverse: str | None = None, iterations: int | None = None) -> Any:
        """The offset-field warp of the current displacements."""

    def to_dict(self, include_positions: bool = False) -> dict[str, Any]:
        """JSON form (:meth:`from_dict` reads it back)."""

    def close(self) -> None:
        """Free GPU resources; idempotent."""


class ElementWarpMixin:
    """The warp side shared by :class:`~voxwarp.deform.elements.massspring.MassSpring` and
    :class:`~voxwarp.deform.elements.chainmail.ChainMail`.

    A model sets :attr:`model_type` (its ``"type"`` in scene JSON), :attr:`label` (its
    name in messages) and :attr:`error` (its exception class), and keeps ``grid``,
    ``backend``, ``_warp`` and ``_solver`` (the GPU solver, or None).
    """

    model_type: ClassVar[str]
    label: ClassVar[str]
    error: ClassVar[type[Exception]]
    grid: ElementGrid
    backend: str
    _warp: Any
    _solver: Any
    #: while True, changes of a CPU model's field are not written into its warp: a
    #: worker thread steps the model while the GUI thread draws the warp
    #: (:mod:`voxwarp.editing.model_worker`); the GUI thread then writes the field the
    #: worker hands it with :meth:`show_field`
    defer_warp_updates: bool = False

    def show_field(self, displacements: np.ndarray) -> None:
        """Write ``(nx, ny, nz, 3)`` displacements (a copy of :meth:`displacements` taken
        after a step) into this CPU model's warp, if it has one; the texture follows on
        the next draw. Call it on the thread that draws the warp."""
        if self._warp is not None and self.backend == "cpu":
            self._warp.update(displacements)

    def displacements(self) -> np.ndarray:  # pragma: no cover - the models define it
        raise NotImplementedError

    def to_dict(self, include_positions: bool = False) -> dict[str, Any]:  # pragma: no cover
        raise NotImplementedError

    def warp(self, inverse: str | None = None, iterations: int | None = None) -> Any:
        """The offset-field warp of the current displacements (one object, kept current).

        ``inverse`` and ``iterations``: the warp's inverse mode (``"approx"``,
        ``"exact"`` or ``"baked"``) and fixed-point iterations (see
        :class:`voxwarp.deform.elements.offset_field.OffsetFieldWarp`); ``None`` keeps the
        current setting (``"baked"`` when first made). CPU backend: built from
        :meth:`displacements` and kept current by every change of the model. GPU
        backend: reads the solver's displacement texture (no read-back). Its
        ``to_dict()`` also writes this model and the field rendered, so a saved scene
        renders the same image and resumes (:meth:`from_warp`).
        """
        self._warp = element_model_warp(
            self._warp,
            self.grid,
            displacements=self.displacements,
            solver=(lambda: self._solver) if self.backend == "gpu" else None,
            model_source=self._model_snapshot,
            inverse=inverse,
            iterations=iterations,
            error=self.error,
        )
        return self._warp

    def _model_snapshot(self) -> tuple[dict[str, Any], np.ndarray | None]:
        """The warp's ``model_source``: this model's dict and, on the GPU, the field
        read from the displacement texture the renderer samples (so the saved
        displacements are bit for bit the rendered ones)."""
        model = {"type": self.model_type, **self.to_dict()}
        if self.backend != "gpu":
            return model, None
        return model, self._rendered_field()

    def _rendered_field(self) -> np.ndarray:
        """(nx, ny, nz, 3) float64 field the GPU warp renders (a read-back)."""
        field = texture_field(self._solver.displacement_texture(), self.grid.shape)
        return self.displacements().astype(np.float64) if field is None else field

    @classmethod
    def from_warp(cls, warp: Any, backend: str = "cpu", ctx: Any = None) -> Self:
        """Resume the model behind a warp loaded from scene JSON: the model of
        ``warp.model_state`` with positions ``rest + displacements`` (the saved field);
        its :meth:`warp` is a new warp, to put in the scene in place of ``warp``.
        Raises the model's error when the warp carries no such model or the model and
        the field do not fit together."""
        state, positions = saved_model(warp, cls.model_type, cls.label, cls.__name__, cls.error)
        return cls.from_dict(state, backend=backend, ctx=ctx, positions=positions)  # type: ignore[attr-defined]

    @classmethod
    def _from_entry(cls, d: Any, backend: str, ctx: Any, positions: Any) -> Self:
        """The models' ``from_dict``: check the entry's type, read its grid and options
        (:meth:`_entry_parts`) and its ``"held"`` list (:meth:`_entry_held`), make the
        model and resume it (:meth:`_resume`; closed again if that fails).
        ``positions`` (else the entry's) are the element positions to resume from."""
        check_entry(d, cls.model_type, cls.error)
        grid, kwargs, extra = cls._entry_parts(d)
        held = cls._entry_held(d.get("held", []), grid)
        if positions is None:
            positions = d.get("positions")
        model = cls(grid, backend=backend, ctx=ctx, **kwargs)  # type: ignore[call-arg]
        with closed_on_error(model):
            model._resume(extra, held, positions)
        return model

    @classmethod
    def _entry_parts(cls, d: Mapping[str, Any]) -> tuple[ElementGrid, dict[str, Any], Any]:
        """An entry's grid, constructor keywords and what :meth:`_resume` needs besides."""
        raise NotImplementedError  # pragma: no cover - the models define it

    @classmethod
    def _entry_held(cls, held: Any, grid: ElementGrid) -> list[tuple[Any, np.ndarray]]:
        """An entry's ``"held"`` list checked: (element, offset) pairs."""
        raise NotImplementedError  # pragma: no cover - the models define it

    def _resume(self, extra: Any, held: list[tuple[Any, np.ndarray]], positions: Any) -> None:
        """Set a new model up as its entry says (held elements, positions, extras)."""
        raise NotImplementedError  # pragma: no cover - the models define it

    def close(self) -> None:
        """Free the solver's and the warp's GPU resources; idempotent."""
        if self._warp is not None:
            self._warp.release()
        if self._solver is not None:
            self._solver.release()


# ---------------------------------------------------------------------- arguments
#: where a model runs
BACKENDS: tuple[str, ...] = ("cpu", "gpu")


def check_grid_and_backend(
    grid: Any, grid_type: type, backend: str, error: type[Exception]
) -> None:
    """Raise ``error`` unless ``grid`` is a ``grid_type`` (the models pass
    :class:`~voxwarp.deform.elements.grid.ElementGrid`) and ``backend`` one of
    :data:`BACKENDS`."""
    if not isinstance(grid, grid_type):
        raise error(
            f"grid must be a voxwarp.deform.elements.grid.ElementGrid; got {type(grid).__name__}"
        )
    if backend not in BACKENDS:
        raise error(f"unknown backend {backend!r}; valid backends: {BACKENDS}")


def check_gpu_context(backend: str, ctx: Any, error: type[Exception]) -> None:
    """Raise ``error`` when the GPU backend is asked for without a moderngl context."""
    if backend == "gpu" and ctx is None:
        raise error('backend="gpu" needs a moderngl context: pass ctx=..., or use backend="cpu"')


# ---------------------------------------------------------------------- save / load
#: how a held element is written in a model's ``"held"`` list
HELD_FORM = 'each held element is {"index": [i, j, k], "offset": [dx, dy, dz]} (mm)'


def check_entry(d: Any, model_type: str, error: type[Exception]) -> None:
    """Raise ``error`` unless ``d`` is a mapping whose ``"type"`` (if any) is
    ``model_type`` (the start of a model's ``from_dict``)."""
    if not isinstance(d, Mapping):
        raise error(f"a {model_type} entry must be an object; got {d!r:.80}")
    kind = d.get("type", model_type)
    if kind != model_type:
        raise error(f"a {model_type} entry has 'type' {kind!r}; expected {model_type!r}")


def held_entries(indices: np.ndarray, offsets: np.ndarray) -> list[dict[str, Any]]:
    """A model's ``"held"`` list: ``{"index": [i, j, k], "offset": [dx, dy, dz]}`` per
    held element (``indices`` (k, 3) grid indices, ``offsets`` (k, 3) mm from rest)."""
    return [
        {"index": [int(v) for v in idx], "offset": off.tolist()}
        for idx, off in zip(indices, offsets, strict=True)
    ]


def held_items(held: Any, model_type: str, error: type[Exception]) -> list[tuple[str, Any]]:
    """A ``"held"`` list's entries, each with its place in messages (``error`` unless
    it is a list)."""
    if not isinstance(held, list | tuple):
        raise error(f"{model_type} 'held' must be a list; {HELD_FORM}; got {held!r:.80}")
    return [(f"{model_type} 'held'[{n}]", entry) for n, entry in enumerate(held)]


def held_index(raw: Any, where: str, error: type[Exception]) -> Any:
    """``raw`` checked to be 3 integers ``[i, j, k]`` (``error`` naming ``where``)."""
    ok = (
        isinstance(raw, list | tuple)
        and len(raw) == 3
        and all(isinstance(v, int) and not isinstance(v, bool) for v in raw)
    )
    if not ok:
        raise error(f"{where} 'index' must be 3 integers [i, j, k]; got {raw!r:.80}")
    return raw


@contextmanager
def closed_on_error(model: Any) -> Iterator[None]:
    """Close ``model`` (free its GPU resources) when the block raises, then re-raise:
    a model half set up from a saved entry is not handed out."""
    try:
        yield
    except BaseException:
        model.close()
        raise
