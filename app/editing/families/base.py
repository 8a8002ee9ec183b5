"""The interface every deformation family's adapter implements for the edit session.

An adapter holds one family's editable state (an element model, wires, a lattice) and
answers the session's questions about it: its warp, its handles and how they drag, what
the overlay draws, what undo keeps, how it resumes from a scene's warp and what it keys
for animation. :class:`~voxwarp.editing.session.EditSession` only talks to this
interface, so adding a family is its warp, its shader, one adapter file registered in
:mod:`voxwarp.editing.families` and one panel in ``ui/`` (docs/reference/layout.md,
"Adding a deformation family"). A family's own editing API (the wires', the lattice's)
lives on its adapter: ``session.adapter(WiresFamily).set_wire_parameters(...)``; what
the GUI's shared code needs of it is generic (e.g. placing a new object by clicking
points: :meth:`Family.start_placing`, :meth:`Family.place_point`). Adapters
know their session through :class:`~voxwarp.editing.state.SessionHost` and never import
the session module.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from voxwarp.deform.warp import Warp
from voxwarp.editing.common import DisplayOptions, EditorError
from voxwarp.editing.model_settings import BuildReport, Built
from voxwarp.editing.state import BuildJob, DragState, SessionHost, Snapshot
from voxwarp.render.overlay import OverlayLayer

if TYPE_CHECKING:
    from voxwarp.animation.tracks import Animation
    from voxwarp.core.camera import Camera

#: maps (N, 3) grid-frame points to world mm (the session's placement)
ToWorld = Callable[[np.ndarray], np.ndarray]


class Family:
    """One deformation family in an edit session (the base is the family ``"none"``).

    Subclasses set :attr:`kind` and override what their family does; the defaults mean
    "nothing to edit". ``session`` gives the shared settings (box, resolution, backend,
    context, ...) and collects warps that are no longer drawn (:meth:`release`).
    """

    #: name of the family in the GUI, scene JSON and :meth:`EditSession.set_deformation`
    kind: ClassVar[str] = "none"
    #: whether the family runs on the CPU or GPU backend (``backend`` setting)
    uses_backend: ClassVar[bool] = False
    #: whether the overlay draws the grid's box
    has_grid: ClassVar[bool] = False
    #: what the handles are, for messages and undo ("Drag elements")
    handle_name: ClassVar[str] = ""
    #: whether handles can be fixed (:meth:`set_fixed`)
    can_fix: ClassVar[bool] = False
    #: whether the links between handles can be cut and joined (:meth:`cut_links`)
    can_cut: ClassVar[bool] = False
    #: the element model (mass-spring or ChainMail families), else None
    model: Any = None

    def __init__(self, session: SessionHost) -> None:
        self.session = session
        #: whether clicks in the viewport place points of a new object
        #: (:meth:`place_point`; the wire family's new wire); set by
        #: :meth:`start_placing`, cleared by :meth:`finish_placing` and
        #: :meth:`cancel_placing` (setting it False pauses, keeping the points)
        self.placing = False

    # ---------------------------------------------------------------- the builder
    @classmethod
    def build(cls, settings: Any, volume: Any, ctx: Any = None) -> Built:
        """The model and warp of ``settings`` (the family's settings dataclass in
        :mod:`voxwarp.editing.model_settings`) on ``volume``: the one builder that the
        editor, the CLI, the napari widget and the notebook viewer use (``ctx``: the GL
        context of a GPU backend, current). Nothing for the family ``"none"``."""
        return Built(None, None, BuildReport())

    # ---------------------------------------------------------------- life cycle
    #: one line on how :meth:`continue_from` went (empty: nothing to say); the GUI
    #: shows it in the status bar after a switch
    switch_note: str = ""

    def start(self) -> None:
        """Build the family's state at rest from the session's settings."""

    def continue_from(self, previous: Family) -> bool:
        """Build the family's state continuing ``previous``'s deformation instead of
        :meth:`start`'s rest state; whether it did (nothing here: False, start at
        rest). Called while ``previous`` is still open."""
        return False

    def close(self) -> None:
        """Give up the state; warps still drawn go to :meth:`release`."""

    def release(self, warp: Warp | None) -> None:
        """Hand a warp that is no longer drawn to the session (its GPU data is freed by
        the caller of :meth:`EditSession.take_released_warps`)."""
        if warp is not None:
            self.session.release_warp(warp)

    @classmethod
    def resume(cls, session: SessionHost, warp: Warp) -> Family | None:
        """An adapter taking over ``warp`` from a saved scene, or None if not ours."""
        return None

    # ---------------------------------------------------------------- state views
    @property
    def field_stale(self) -> bool:
        """Whether a field built off the GUI thread lags the edits."""
        return False

    def build_job(self) -> BuildJob | None:
        """A job rebuilding a stale field on any thread, for :meth:`install`; None for
        families with nothing to build off the GUI thread."""
        return None

    def install(self, job: BuildJob) -> bool:
        """Put a finished :meth:`build_job` in the scene (GUI thread); whether it is of
        the current state (False: dropped, or drawn until the next build)."""
        return False

    def rebuild_if_stale(self) -> None:
        """Rebuild a stale field on this thread and draw it (saving, scripts, notebook)."""

    # ---------------------------------------------------------------- the warp
    def warp(self) -> Warp | None:
        """The family's warp in the grid frame (None: nothing deforms)."""
        return None

    def before_save(self) -> None:
        """Bring the warp up to date before the scene is written."""

    # ---------------------------------------------------------------- handles
    def handles(self) -> np.ndarray:
        """(N, 3) handle positions in the grid frame."""
        return np.zeros((0, 3))

    def fixed_handles(self, count: int) -> np.ndarray:
        """(count,) bool: handles that do not move."""
        return np.zeros(count, dtype=bool)

    def anchored_handles(self, count: int) -> np.ndarray:
        """(count,) bool: handles held at rest by the current drag's region of influence
        (not fixed ones)."""
        return np.zeros(count, dtype=bool)

    def set_fixed(self, indices: list[int], fixed: bool) -> None:
        """Fix or free handles."""
        raise EditorError("only the elements of mass-spring and ChainMail can be fixed")

    def cut_links(self, indices: list[int]) -> int:
        """Cut the links around the handles ``indices``; how many were cut."""
        raise EditorError(f"only ChainMail's links can be cut; the model is {self.kind!r}")

    def join_links(self, indices: list[int], pull: bool = False) -> tuple[int, int]:
        """Join the cut links at the handles ``indices`` where they touch (``pull``: all,
        pulling the sides together); how many were joined and how many stay cut."""
        raise EditorError(f"only ChainMail's links can be joined; the model is {self.kind!r}")

    def begin_drag(self, drag: DragState) -> None:
        """Remember what the drag starting with ``drag`` needs (``drag.positions`` are
        the handles in the grid frame, ``drag.selection`` the dragged ones)."""

    def drag(self, drag: DragState, selection: np.ndarray, delta: np.ndarray) -> None:
        """Move the selected handles by ``delta`` (grid frame) from their start."""

    # ---------------------------------------------------------------- placing
    # A family may build a new object from points clicked in the viewport (the wire
    # family lays a new wire): the window starts placing, the viewport hands each click
    # to :meth:`place_point` while :attr:`placing`, the family's panel finishes it with
    # its options (:meth:`finish_placing`), Esc cancels. The defaults place nothing.
    def start_placing(self) -> None:
        """Let the next clicks place points of a new object (nothing here: the family
        places nothing, :attr:`placing` stays False)."""

    def place_point(self, camera: Camera, size: tuple[int, int], pixel: Sequence[float]) -> None:
        """Place a point of the new object under ``pixel`` (``size``: the view's pixels)
        seen by ``camera``."""

    def finish_placing(self, **options: Any) -> Any:
        """Stop placing and make the placed points the new object (``options``: the
        family's, from its panel, e.g. a wire's ``kind`` and ``radius``). Returns what
        was made (None here); an :class:`EditorError` when the points make none."""
        self.placing = False
        return None

    def cancel_placing(self) -> None:
        """Stop placing and drop the points placed."""
        self.placing = False

    # ---------------------------------------------------------------- running
    def advance(self) -> bool:
        """One frame of a running model; whether anything ran."""
        return False

    def poll(self) -> bool:
        """Show the newest state the session's model worker finished (GUI thread);
        whether anything changed (nothing here: no model steps on a worker)."""
        return False

    def reset(self) -> None:
        """Back to rest."""

    def option_changed(self, name: str, value: Any) -> None:
        """A run-time option of the session changed (``relax_steps``, ...)."""

    # ---------------------------------------------------------------- drawing
    def overlay(
        self, handles: np.ndarray, display: DisplayOptions, to_world: ToWorld
    ) -> list[OverlayLayer]:
        """The family's overlay layers (``handles``: world positions)."""
        return []

    # ---------------------------------------------------------------- undo and animation
    def snapshot(self) -> dict[str, Any]:
        """The family's state, copied (arrays and plain values only)."""
        return {}

    def adopt(self, previous: Family, snap: Snapshot) -> None:
        """Before :meth:`restore` and before ``previous`` closes: take over what of it
        can be kept for ``snap`` (a wire field still valid for it)."""

    def restore(self, state: dict[str, Any]) -> None:
        """Return to a :meth:`snapshot` (the session's settings are restored already)."""

    def set_keys(self, animation: Animation, frame: int, interpolation: str) -> None:
        """Key the family's state at ``frame`` (:func:`voxwarp.editing.keyframes.set_key`)."""
