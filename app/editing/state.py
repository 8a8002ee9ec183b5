"""What the edit session and its family adapters share below both: the grid's
:class:`Placement`, the undo :class:`Snapshot`, the typed :class:`DragState` and the
:class:`SessionHost` protocol (what an adapter may ask of its session). The adapters
import this module, never :mod:`voxwarp.editing.session`."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from voxwarp.core.camera import Camera
from voxwarp.deform.warp import Warp, rotation_matrix
from voxwarp.editing.common import EditorError
from voxwarp.editing.model_settings import FamilyOptions


# ---------------------------------------------------------------------------- placement
@dataclass
class Placement:
    """Where the deformation grid sits relative to the volume.

    ``translate`` (mm), ``rotate`` (degrees about x, then y, then z, through the volume's
    box centre) and ``scale`` (per axis, about that centre) map the grid frame (the
    volume's box) to world space.
    """

    translate: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotate: tuple[float, float, float] = (0.0, 0.0, 0.0)
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)

    def __post_init__(self) -> None:
        for name in ("translate", "rotate", "scale"):
            v = np.asarray(getattr(self, name), dtype=np.float64).reshape(-1)
            if v.size == 1:
                v = np.repeat(v, 3)
            if v.size != 3 or not np.all(np.isfinite(v)):
                raise EditorError(f"placement {name} must be 3 finite numbers; got {v.tolist()}")
            setattr(self, name, (float(v[0]), float(v[1]), float(v[2])))
        if min(self.scale) <= 0:
            raise EditorError(f"placement scale must be positive; got {self.scale}")

    @property
    def is_identity(self) -> bool:
        """True when the grid sits exactly on the volume's box."""
        return (
            self.translate == (0.0, 0.0, 0.0)
            and self.rotate == (0.0, 0.0, 0.0)
            and self.scale == (1.0, 1.0, 1.0)
        )

    def matrix(self, center: Sequence[float]) -> np.ndarray:
        """4x4 grid frame -> world, about ``center`` (the volume's box centre)."""
        c = np.asarray(center, dtype=np.float64)
        r = np.eye(3)
        for axis, deg in zip(np.eye(3), self.rotate, strict=True):
            if deg:
                r = rotation_matrix(axis, deg) @ r
        m = np.eye(4)
        m[:3, :3] = r @ np.diag(self.scale)
        m[:3, 3] = c - m[:3, :3] @ c + np.asarray(self.translate)
        return m

    def to_dict(self) -> dict[str, Any]:
        """JSON form."""
        return {
            "translate": list(self.translate),
            "rotate": list(self.rotate),
            "scale": list(self.scale),
        }

    @classmethod
    def from_dict(cls, d: Any) -> Placement:
        """Inverse of :meth:`to_dict`; raises :class:`EditorError`."""
        if not isinstance(d, dict):
            raise EditorError(f"editor 'placement' must be an object; got {d!r:.60}")
        return cls(
            d.get("translate", (0, 0, 0)), d.get("rotate", (0, 0, 0)), d.get("scale", (1, 1, 1))
        )


# ---------------------------------------------------------------------------- snapshots
@dataclass
class Snapshot:
    """An in-memory copy of a session's whole editable state (for undo/redo)."""

    kind: str
    backend: str
    resolution: tuple[int, int, int]
    placement: Placement
    #: the family's own state (:meth:`Family.snapshot`: model, wires or lattice nodes)
    state: dict[str, Any] = field(default_factory=dict)
    #: the families' settings (a copy)
    options: FamilyOptions = field(default_factory=FamilyOptions)
    selection: tuple[int, ...] = ()
    reference: int | None = None
    #: the scene's look: mode, transfer function, sample distance, window, clip box, ...
    look: dict[str, Any] = field(default_factory=dict)
    #: the keyframes (``Animation.to_dict()``) or None
    animation: dict[str, Any] | None = None
    #: the imported warps (:attr:`EditSession.imported_warps`; warps are not edited in
    #: place, so holding them is a copy)
    imported: tuple[Warp, ...] = ()

    def same_as(self, other: Snapshot) -> bool:
        """True when both hold the same state (exact comparison of every array)."""
        return all(_same(getattr(self, f), getattr(other, f)) for f in self.__dataclass_fields__)


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return a is not None and b is not None and np.array_equal(a, b)
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    return bool(a == b)


# ---------------------------------------------------------------------------- dragging
@dataclass
class DragState:
    """A drag in progress (:meth:`EditSession.begin_drag
    <voxwarp.editing.session.EditSession.begin_drag>`).

    The session fills the camera, the anchor and the start; the family adapter keeps its
    own part (:attr:`start_offsets`) and updates :attr:`positions` (a GPU model's held
    elements are drawn from there, never read back during a drag).
    """

    #: the camera and viewport size of the view the drag started in
    camera: Camera
    size: tuple[int, int]
    #: where the cursor met the plane through the reference at the start (world mm)
    anchor: np.ndarray
    #: the selected handles at the start (world mm), in :attr:`selection` order
    start_world: np.ndarray
    #: every handle in the grid frame (start positions; element families: targets)
    positions: np.ndarray
    #: the dragged handles' indices
    selection: list[int]
    #: element families: the dragged elements' offsets from rest at the start
    start_offsets: np.ndarray | None = None


# ---------------------------------------------------------------------------- the host
class SessionHost(Protocol):
    """What a family adapter uses of its edit session (the session implements it)."""

    scene: Any
    ctx: Any
    backend: str
    resolution: tuple[int, int, int]
    placement: Placement
    options: FamilyOptions
    settled: bool
    sync_builds: bool
    selection: list[int]
    timings: dict[str, float]
    gl_scope: Callable[[], Any]
    model_worker: Any

    @property
    def volume(self) -> Any: ...

    @property
    def box(self) -> tuple[np.ndarray, np.ndarray]: ...

    @property
    def placement_matrix(self) -> np.ndarray: ...

    @property
    def drag_state(self) -> DragState | None: ...

    def handles_moved(self, throttle: bool = False) -> None: ...

    def edited(self) -> None: ...

    def select(self, indices: Sequence[int], mode: Any = "replace") -> None: ...

    def release_warp(self, warp: Warp) -> None: ...

    def sync_warps(self) -> None: ...

    def wait_for_model(self) -> None: ...

    def set_deformation(self, kind: str, **settings: Any) -> None: ...


class BuildJob(Protocol):
    """A field rebuild a family hands out
    (:meth:`~voxwarp.editing.families.base.Family.build_job`) to run off the GUI thread:
    ``run`` builds from a copy of the family's state (``progress(fraction, what)``
    reports) and returns the result for
    :meth:`~voxwarp.editing.families.base.Family.install`, or None once cancelled."""

    #: what is being built, for a progress bar ("wire field")
    label: str

    def run(self, progress: Callable[[float, str], None] | None = None) -> Any: ...

    def cancel(self) -> None: ...
