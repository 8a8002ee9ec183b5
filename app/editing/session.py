"""The editing session behind the desktop GUI: a scene, one deformation model, picking
and dragging, snapshots for undo, save and load. No Qt here (``ui/`` drives it).

About the interaction (Knoche 2008, 3.2; Singh and Fiume, wires, section 8)
-----------------------------------------------------------------------------
The session holds a :class:`~voxwarp.scene.Scene` and at most one deformation family:

* ``"massspring"`` / ``"chainmail"``: an :class:`~voxwarp.deform.elements.ElementGrid` of
  elements over the volume, run by :class:`~voxwarp.deform.massspring.MassSpring` or
  :class:`~voxwarp.deform.chainmail.ChainMail` (CPU or GPU backend); the handles are the
  elements.
* ``"wires"``: :class:`~voxwarp.deform.wires.Wire` objects and their attribute field; the
  handles are the control points of the *modified* wires (the base wires stay where
  they were laid). Editing one needs a rebuild of the field (~0.2 s): the session
  hands out a :class:`WireBuild` job that runs off the GUI thread and installs its
  result only if nothing changed meanwhile.
* ``"lattice"``: a :class:`~voxwarp.deform.trilinear.TrilinearGrid` over the volume's box
  (:class:`~voxwarp.deform.lattice_warp.LatticeWarp`); the handles are its nodes.

Handles are picked in screen space (the nearest projected handle within a radius of
pixels), added to or removed from a selection (one of them the *reference*), and
dragged in the plane parallel to the image through the reference: every selected
handle moves by the reference's offset, so the selection keeps its shape.

The deformation grid can be placed relative to the volume (:class:`Placement`:
translation, rotation about the box centre, scale); the warp chain is then
``[placement^-1, model warp, placement]``, so outside the placed grid nothing moves.

Every edit is bracketed by :meth:`EditSession.snapshot` (an in-memory copy of the
whole state, velocities included) so that undo restores it exactly.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from voxwarp.core.camera import Camera
from voxwarp.core.files import atomic_write_text
from voxwarp.deform.chainmail import ChainMail
from voxwarp.deform.elements import ElementGrid
from voxwarp.deform.lattice_warp import LatticeWarp
from voxwarp.deform.massspring import MassSpring
from voxwarp.deform.offset_field import OffsetFieldWarp
from voxwarp.deform.trilinear import TrilinearGrid
from voxwarp.deform.warp import AffineWarp, Warp, WarpError, rotation_matrix
from voxwarp.deform.wires import Wire, WireDeformer, WireFieldWarp
from voxwarp.errors import VoxwarpError
from voxwarp.render.overlay import OverlayLayer, box_edges, grid_edges, polyline_segments
from voxwarp.scene import Scene, read_scene_dict

Deformation = Literal["none", "massspring", "chainmail", "wires", "lattice"]
DEFORMATIONS: tuple[str, ...] = ("none", "massspring", "chainmail", "wires", "lattice")
BACKENDS: tuple[str, ...] = ("cpu", "gpu")
INTEGRATORS: tuple[str, ...] = ("semi-implicit", "explicit")
CHAINMAIL_VARIANTS: tuple[str, ...] = ("enhanced", "gibson")
WIRE_KINDS: tuple[str, ...] = ("catmull-rom", "bezier")
SelectMode = Literal["replace", "add", "remove", "toggle"]
#: pick radius in pixels around a handle
PICK_RADIUS_PX = 12.0
#: the session attributes that choose the deformation model
MODEL_SETTINGS = ("kind", "backend", "resolution", "integrator", "variant", "stiffness")
#: mass-spring elements slower than this (mm/s) count as at rest
SETTLED_SPEED = 1e-3
#: key of the editor's entry in scene JSON
EDITOR_KEY = "editor"


class EditorError(VoxwarpError, ValueError):
    """An edit the session cannot make (names the problem and the fix)."""


def _choice(value: Any, allowed: Sequence[str], what: str) -> str:
    if not isinstance(value, str) or value not in allowed:
        raise EditorError(f"{what} must be one of {', '.join(allowed)}; got {value!r}")
    return value


def _resolution(value: Any) -> tuple[int, int, int]:
    try:
        r = np.broadcast_to(np.asarray(value, dtype=np.int64), (3,))
    except (TypeError, ValueError) as exc:
        raise EditorError(f"grid resolution must be 1 or 3 integers; got {value!r}") from exc
    if np.any(r < 2) or np.any(r > 64):
        raise EditorError(
            f"grid resolution must be 2..64 elements per axis here; got {tuple(r.tolist())}"
        )
    return (int(r[0]), int(r[1]), int(r[2]))


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


# ---------------------------------------------------------------------------- display
@dataclass
class DisplayOptions:
    """What the viewport draws besides the volume (every feature can be toggled)."""

    volume: bool = True
    elements: bool = True
    links: bool = True
    fixed: bool = True
    wires_base: bool = True
    wires_modified: bool = True
    lattice_cells: bool = True
    grid_box: bool = True
    clip_box: bool = False
    selection: bool = True


COLORS = {
    "element": (0.30, 0.80, 1.00, 0.9),
    "fixed": (1.00, 0.30, 0.25, 0.95),
    "selected": (1.00, 0.85, 0.10, 1.0),
    "reference": (1.00, 1.00, 1.00, 1.0),
    "link": (0.30, 0.80, 1.00, 0.35),
    "wire_base": (0.55, 0.55, 0.60, 0.8),
    "wire_modified": (0.20, 1.00, 0.40, 0.95),
    "lattice": (1.00, 0.55, 0.10, 0.6),
    "box": (0.80, 0.80, 0.80, 0.5),
    "pending": (1.00, 0.40, 1.00, 1.0),
}


# ---------------------------------------------------------------------------- snapshots
@dataclass
class Snapshot:
    """An in-memory copy of a session's whole editable state (for undo/redo)."""

    kind: str
    backend: str
    resolution: tuple[int, int, int]
    placement: Placement
    model: dict[str, Any] | None = None
    positions: np.ndarray | None = None
    velocities: np.ndarray | None = None
    wires: list[dict[str, Any]] = field(default_factory=list)
    wire_settings: dict[str, Any] = field(default_factory=dict)
    lattice_nodes: np.ndarray | None = None
    selection: tuple[int, ...] = ()
    reference: int | None = None
    settings: dict[str, Any] = field(default_factory=dict)
    #: the scene's look: mode, transfer function, sample distance, window, clip box, ...
    look: dict[str, Any] = field(default_factory=dict)
    #: the keyframes (``Animation.to_dict()``) or None
    animation: dict[str, Any] | None = None

    def same_as(self, other: Snapshot) -> bool:
        """True when both hold the same state (exact comparison of every array)."""

        def eq(a: Any, b: Any) -> bool:
            if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
                return a is not None and b is not None and np.array_equal(a, b)
            return bool(a == b)

        return all(eq(getattr(self, f), getattr(other, f)) for f in self.__dataclass_fields__)


# ---------------------------------------------------------------------------- wire builds
@dataclass
class WireBuild:
    """A rebuild of the wire field, to run off the GUI thread.

    :meth:`run` builds a new attribute field from a copy of the wires (nothing shared
    with the field being drawn); :meth:`EditSession.install_wire_build` puts it in the
    scene on the GUI thread, unless the wires changed again meanwhile. :meth:`cancel`
    makes :meth:`run` stop at its next check and return ``None``.
    """

    generation: int
    volume: Any
    wires: list[Wire]
    settings: dict[str, Any]
    warp: WireFieldWarp | None = None
    seconds: float = 0.0
    _cancel: threading.Event = field(default_factory=threading.Event)

    def cancel(self) -> None:
        """Ask :meth:`run` to stop; its result is then dropped."""
        self._cancel.set()

    @property
    def cancelled(self) -> bool:
        """Whether :meth:`cancel` was called."""
        return self._cancel.is_set()

    def run(self, progress: Callable[[float, str], None] | None = None) -> WireFieldWarp | None:
        """Build the field (thread-safe: touches only this job's objects)."""
        t0 = time.perf_counter()
        if progress:
            progress(0.05, "laying the wires")
        if self.cancelled:
            return None
        deformer = WireDeformer(self.volume, self.wires, **self.settings)
        if progress:
            progress(0.2, "propagating the attribute field")
        deformer.build()
        if self.cancelled:
            return None
        self.warp = deformer.warp()
        self.seconds = time.perf_counter() - t0
        if progress:
            progress(1.0, "done")
        return self.warp


# ---------------------------------------------------------------------------- session
class EditSession:
    """A scene being edited (see the module docstring).

    Parameters
    ----------
    scene
        The scene; its warps are replaced by the session's deformation (a scene loaded
        with :meth:`load` keeps its model: the session resumes it).
    ctx
        The moderngl context of the GPU backends (the GUI's); the caller makes it
        current around calls that create, step or restore a GPU model.
    editor
        The ``"editor"`` entry of the scene's JSON (placement, settings, which warp is
        the model's), as :meth:`load` passes it.
    """

    def __init__(self, scene: Scene, ctx: Any = None, editor: Any = None) -> None:
        if not isinstance(scene, Scene):
            raise EditorError(
                f"EditSession needs an voxwarp.scene.Scene; got {type(scene).__name__}"
            )
        self.scene = scene
        self.ctx = ctx
        self.kind: str = "none"
        self.backend: str = "cpu"
        self.resolution: tuple[int, int, int] = (8, 8, 8)
        self.placement = Placement()
        #: mass-spring integrator and ChainMail variant of the next model
        self.integrator: str = "semi-implicit"
        self.variant: str = "enhanced"
        #: mass-spring steps and ChainMail relaxation steps per frame while running
        self.steps_per_frame: int = 10
        self.relax_steps: int = 1
        #: element stiffness of new mass-spring/ChainMail models (0..1)
        self.stiffness: float = 0.5
        self.running: bool = True
        self.model: MassSpring | ChainMail | None = None
        self.wires: list[Wire] = []
        self.wire_settings: dict[str, Any] = {"field_scale": 2}
        self._wire_warp: WireFieldWarp | None = None
        #: changes with every edit of the wires; the drawn field is of `_wire_built`
        self.wire_generation = 0
        self._wire_built = -1
        #: rebuild wire fields at once on model changes and undo (scripts, tests); the
        #: GUI sets False and builds them off its thread (:meth:`wire_build`)
        self.sync_wires = True
        #: GPU models: least seconds between element read-backs for the overlay while
        #: the simulation runs (never during a drag)
        self.gpu_readback_interval = 0.5
        self._last_readback = 0.0
        #: the running model came to rest (:meth:`advance` stops stepping until an edit)
        self.settled = False
        self._advances = 0
        self.lattice_nodes: np.ndarray | None = None
        self._lattice_warp: LatticeWarp | None = None
        self.selection: list[int] = []
        self.reference: int | None = None
        #: control points of the wire being laid (:meth:`add_wire_point`)
        self.pending_wire: list[np.ndarray] = []
        #: last timings in ms: "step" (model), "field" (wire build)
        self.timings: dict[str, float] = {}
        self._drag: dict[str, Any] | None = None
        self._handle_cache: np.ndarray | None = None
        self._released_warps: list[Warp] = []
        #: keyframes (:mod:`voxwarp.editing.keyframes`; saved in scene JSON for ``voxwarp animate``)
        self.animation: Any = None
        #: ``() -> context manager`` making the GL context of GPU models current (the
        #: GUI's viewport sets it; a headless caller's context is current already)
        self.gl_scope: Callable[[], Any] = contextlib.nullcontext
        self._recover_from_scene(editor if isinstance(editor, dict) else {})

    # ------------------------------------------------------------------ properties
    @property
    def volume(self) -> Any:
        """The scene's volume."""
        return self.scene.volume

    @property
    def box(self) -> tuple[np.ndarray, np.ndarray]:
        """The grid frame's box: the volume's bounds (mm)."""
        lo, hi = self.volume.bounds
        return np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)

    @property
    def placement_matrix(self) -> np.ndarray:
        """4x4 grid frame -> world of :attr:`placement`."""
        lo, hi = self.box
        return self.placement.matrix(0.5 * (lo + hi))

    @property
    def dragging(self) -> bool:
        """Whether a drag is in progress."""
        return self._drag is not None

    def _touch(self) -> None:
        self._handle_cache = None
        self.settled = False

    # ------------------------------------------------------------------ models
    def set_deformation(self, kind: str, **settings: Any) -> None:
        """Switch the deformation family (and settings: ``backend``, ``resolution``,
        ``integrator``, ``variant``, ``stiffness``); builds a fresh model at rest.

        ``"wires"`` starts with one straight wire along the volume's longest axis
        through its centre (bend it by dragging its control points, or lay new ones);
        ``"lattice"`` starts with an undeformed lattice of ``resolution - 1`` cells
        per axis (at most 8).
        """
        kind = _choice(kind, DEFORMATIONS, "deformation")
        backend = _choice(settings.pop("backend", self.backend), BACKENDS, "backend")
        resolution = _resolution(settings.pop("resolution", self.resolution))
        integrator = _choice(settings.pop("integrator", self.integrator), INTEGRATORS, "integrator")
        variant = _choice(settings.pop("variant", self.variant), CHAINMAIL_VARIANTS, "variant")
        stiffness_value = settings.pop("stiffness", self.stiffness)
        try:
            stiffness = float(stiffness_value)
        except (TypeError, ValueError) as exc:
            raise EditorError(
                f"stiffness must be a number in (0, 1]; got {stiffness_value!r}"
            ) from exc
        if settings:
            raise EditorError(f"unknown deformation settings: {', '.join(sorted(settings))}")
        if not 0.0 < stiffness <= 1.0:
            raise EditorError(f"stiffness must be in (0, 1]; got {stiffness}")
        if backend == "gpu" and kind in ("massspring", "chainmail") and self.ctx is None:
            raise EditorError("the GPU backend needs the viewport's OpenGL context; use cpu")
        settings_now = {name: getattr(self, name) for name in MODEL_SETTINGS}
        wanted = dict(
            zip(
                MODEL_SETTINGS,
                (kind, backend, resolution, integrator, variant, stiffness),
                strict=True,
            )
        )
        new_model = None
        if kind in ("massspring", "chainmail"):
            # build the new model before closing the old: a refused setting leaves the
            # session as it was
            self._set_settings(wanted)
            try:
                new_model = self._new_element_model()
            except (ValueError, WarpError) as exc:
                self._set_settings(settings_now)
                if isinstance(exc, EditorError):
                    raise
                raise EditorError(str(exc)) from exc
        self._close_model()
        self.timings.clear()
        self._set_settings(wanted)
        self.selection, self.reference = [], None
        if new_model is not None:
            self.model = new_model
        elif kind == "wires":
            self.wires = [self._default_wire()]
            self.wire_generation += 1
            self._refresh_wire_field()
        elif kind == "lattice":
            cells = tuple(min(r - 1, 8) for r in resolution)
            lo, hi = self.box
            u = np.stack(
                np.meshgrid(*(np.linspace(0.0, 1.0, c + 1) for c in cells), indexing="ij"), -1
            )
            self.lattice_nodes = lo + u * (hi - lo)
            self._lattice_warp = None
        self._sync_warps()

    def _set_settings(self, values: dict[str, Any]) -> None:
        for name, value in values.items():
            setattr(self, name, value)

    def _new_element_model(self, model: dict[str, Any] | None = None) -> MassSpring | ChainMail:
        ctx = self.ctx if self.backend == "gpu" else None
        cls = MassSpring if self.kind == "massspring" else ChainMail
        if model is not None:
            restored = cls.from_dict(model, backend=self.backend, ctx=ctx)
            if isinstance(restored, ChainMail) and self.backend == "gpu":
                restored.relax_steps = 0  # see below
            return restored
        grid = ElementGrid(self.box, shape=self.resolution)
        grid.set_material(stiffness=self.stiffness)
        if self.kind == "massspring":
            return MassSpring(grid, backend=self.backend, ctx=ctx, integrator=self.integrator)
        cm = ChainMail(grid, variant=self.variant, backend=self.backend, ctx=ctx)
        # relaxation runs on the CPU (a GPU model is read back for it): a GPU model relaxes
        # in advance() between drags, never inside a move
        cm.relax_steps = self.relax_steps if self.backend == "cpu" else 0
        return cm

    def _default_wire(self) -> Wire:
        lo, hi = self.box
        c = 0.5 * (lo + hi)
        axis = int(np.argmax(hi - lo))
        pts = np.repeat(c[None], 4, axis=0)
        pts[:, axis] = lo[axis] + (hi[axis] - lo[axis]) * np.array([0.1, 0.37, 0.63, 0.9])
        others = [a for a in range(3) if a != axis]
        radius = 0.3 * float(min(hi[others[0]] - lo[others[0]], hi[others[1]] - lo[others[1]]))
        return Wire(pts, pts.copy(), radius=radius, name="wire 1")

    def _refresh_wire_field(self) -> None:
        """After a change of the wires: rebuild the field now (:attr:`sync_wires`) or
        leave it stale for an off-thread :meth:`wire_build` (the GUI)."""
        if self.sync_wires:
            self._wire_warp = self._replace_warp(self._wire_warp, self._build_wires_now())
            self._wire_built = self.wire_generation

    def _build_wires_now(self) -> WireFieldWarp:
        job = self.wire_build()
        warp = job.run()
        assert warp is not None
        self.timings["field"] = job.seconds * 1000
        return warp

    def _close_model(self) -> None:
        if self.model is not None:
            self.model.close()
        self.model = None
        for w in (self._wire_warp, self._lattice_warp):
            if w is not None:
                self._released_warps.append(w)
        self._wire_warp = None
        self._lattice_warp = None
        self.wires = []
        self.lattice_nodes = None
        self.pending_wire = []
        self._drag = None

    def take_released_warps(self) -> list[Warp]:
        """Warps no longer drawn, whose GPU textures the caller should release (with its
        context current)."""
        out, self._released_warps = self._released_warps, []
        return out

    def model_warp(self) -> Warp | None:
        """The warp of the current deformation in the grid frame (None for ``"none"``)."""
        if self.kind in ("massspring", "chainmail") and self.model is not None:
            return self.model.warp()
        if self.kind == "wires":
            return self._wire_warp
        if self.kind == "lattice" and self.lattice_nodes is not None:
            if self._lattice_warp is None:
                self._lattice_warp = LatticeWarp(TrilinearGrid(self.lattice_nodes), self.box)
            return self._lattice_warp
        return None

    def _sync_warps(self) -> None:
        w = self.model_warp()
        if w is None:
            self.scene.warps = []
        elif self.placement.is_identity:
            self.scene.warps = [w]
        else:
            m = self.placement_matrix
            # deformed world -> grid frame, the model, grid frame -> original world
            self.scene.warps = [AffineWarp(m), w, AffineWarp(np.linalg.inv(m))]
        self._touch()

    def set_placement(self, placement: Placement) -> None:
        """Move/rotate/scale the deformation grid relative to the volume."""
        if not isinstance(placement, Placement):
            raise EditorError("set_placement needs a Placement")
        self.placement = placement
        self._sync_warps()

    def set_option(self, name: str, value: Any) -> None:
        """Set a run-time option: ``steps_per_frame`` (mass-spring steps per frame),
        ``relax_steps`` (ChainMail relaxation steps per frame), ``running``."""
        if name == "running":
            self.running = bool(value)
        elif name in ("steps_per_frame", "relax_steps"):
            v = int(value)
            if not 0 <= v <= 10000:
                raise EditorError(f"{name} must be 0..10000; got {value!r}")
            setattr(self, name, v)
            if name == "relax_steps" and isinstance(self.model, ChainMail):
                self.model.relax_steps = v if self.model.backend == "cpu" else 0
        else:
            raise EditorError(f"unknown option {name!r}")

    # ------------------------------------------------------------------ handles
    def _grid_to_world(self, p: np.ndarray) -> np.ndarray:
        if self.placement.is_identity:
            return p
        m = self.placement_matrix
        return p @ m[:3, :3].T + m[:3, 3]

    def _handles_grid(self) -> np.ndarray:
        """(N, 3) handle positions in the grid frame."""
        if self.kind in ("massspring", "chainmail") and self.model is not None:
            if self.model.backend == "gpu" and self._drag is not None:
                # never read the GPU back while dragging: targets of the held elements
                return self._drag["positions"].copy()
            with self.gl_scope():
                return self.model.positions().reshape(-1, 3)
        if self.kind == "wires":
            if not self.wires:
                return np.zeros((0, 3))
            return np.concatenate([w.modified.control_points for w in self.wires])
        if self.kind == "lattice" and self.lattice_nodes is not None:
            return self.lattice_nodes.reshape(-1, 3)
        return np.zeros((0, 3))

    def handles(self) -> np.ndarray:
        """(N, 3) world positions of the pickable handles (elements, modified wire
        control points or lattice nodes); a GPU model is read back at most once per
        change, never during a drag."""
        if self._handle_cache is None:
            self._handle_cache = self._grid_to_world(self._handles_grid())
        return self._handle_cache

    def fixed_handles(self) -> np.ndarray:
        """(N,) bool: handles that do not move (fixed elements)."""
        n = len(self.handles())
        if self.kind in ("massspring", "chainmail") and self.model is not None:
            return self.model.grid.fixed.reshape(-1).copy()
        return np.zeros(n, dtype=bool)

    def _wire_point(self, index: int) -> tuple[int, int]:
        """Handle index -> (wire, control point)."""
        handle = index
        for w, wire in enumerate(self.wires):
            n = len(wire.modified.control_points)
            if index < n:
                return w, index
            index -= n
        raise EditorError(f"handle {handle} is not a wire control point")

    # ------------------------------------------------------------------ picking
    def pick(
        self,
        camera: Camera,
        size: tuple[int, int],
        pixel: Sequence[float],
        radius: float = PICK_RADIUS_PX,
    ) -> int | None:
        """The handle nearest ``pixel`` on screen within ``radius`` pixels (ties: the
        one nearest the eye), or None."""
        pts = self.handles()
        if len(pts) == 0:
            return None
        xy = camera.project(pts, size)
        d = np.hypot(xy[:, 0] - pixel[0], xy[:, 1] - pixel[1])
        depth = (pts - camera.eye) @ -camera.rotation[:, 2]
        ok = (d <= radius) & (depth > 0) & np.isfinite(d)
        if not np.any(ok):
            return None
        key = np.where(ok, d + 1e-6 * depth, np.inf)
        return int(np.argmin(key))

    def pick_rect(
        self,
        camera: Camera,
        size: tuple[int, int],
        corner0: Sequence[float],
        corner1: Sequence[float],
    ) -> list[int]:
        """Handles whose projection lies in the screen rectangle (rubber band)."""
        pts = self.handles()
        if len(pts) == 0:
            return []
        xy = camera.project(pts, size)
        x0, x1 = sorted((float(corner0[0]), float(corner1[0])))
        y0, y1 = sorted((float(corner0[1]), float(corner1[1])))
        depth = (pts - camera.eye) @ -camera.rotation[:, 2]
        inside = (xy[:, 0] >= x0) & (xy[:, 0] <= x1) & (xy[:, 1] >= y0) & (xy[:, 1] <= y1)
        return [int(i) for i in np.flatnonzero(inside & (depth > 0))]

    def select(self, indices: Sequence[int], mode: SelectMode = "replace") -> None:
        """Change the selection; the reference becomes the last index added (or stays)."""
        n = len(self.handles())
        idx = [int(i) for i in indices]
        bad = [i for i in idx if not 0 <= i < n]
        if bad:
            raise EditorError(f"no handle {bad[0]}: there are {n} handles")
        sel = list(self.selection)
        if mode == "replace":
            sel = list(dict.fromkeys(idx))
        elif mode == "add":
            sel += [i for i in idx if i not in sel]
        elif mode == "remove":
            sel = [i for i in sel if i not in idx]
        elif mode == "toggle":
            for i in idx:
                if i in sel:
                    sel.remove(i)
                else:
                    sel.append(i)
        else:
            raise EditorError(f"select mode must be replace, add, remove or toggle; got {mode!r}")
        self.selection = sel
        if (idx and mode in ("replace", "add")) or (mode == "toggle" and idx and idx[-1] in sel):
            self.reference = idx[-1]
        if self.reference not in sel:
            self.reference = sel[-1] if sel else None

    def set_reference(self, index: int) -> None:
        """Make a selected handle the reference of drags."""
        if index not in self.selection:
            raise EditorError(f"handle {index} is not selected; select it first")
        self.reference = int(index)

    def set_fixed(self, indices: Sequence[int], fixed: bool) -> None:
        """Fix or free elements (mass-spring and ChainMail)."""
        if self.kind not in ("massspring", "chainmail") or self.model is None:
            raise EditorError("only the elements of mass-spring and ChainMail can be fixed")
        indices = list(indices)
        if not indices:
            raise EditorError("select elements first (click them, or Shift+drag a rectangle)")
        grid = self.model.grid
        ijk = np.array(np.unravel_index(np.asarray(indices, int), grid.shape)).T
        if fixed:
            self.model.fix(ijk)
        else:
            self.model.free(ijk)
        self._touch()

    # ------------------------------------------------------------------ dragging
    def begin_drag(self, camera: Camera, size: tuple[int, int], pixel: Sequence[float]) -> bool:
        """Start dragging the selection (the reference under the cursor defines the plane).

        Returns False when nothing is selected."""
        if not self.selection or self.reference is None:
            return False
        pts = self.handles()
        ref = pts[self.reference]
        self._drag = {
            "camera": camera,
            "size": size,
            "anchor": camera.point_on_view_plane(pixel, size, ref),
            "start_world": pts[np.asarray(self.selection)].copy(),
            "positions": self._handles_grid().copy(),
            "selection": list(self.selection),
        }
        if self.kind in ("massspring", "chainmail") and self.model is not None:
            rest = self.model.grid.rest_positions.reshape(-1, 3)
            sel = np.asarray(self.selection)
            self._drag["start_offsets"] = self._drag["positions"][sel] - rest[sel]
        return True

    def drag_to(self, pixel: Sequence[float]) -> np.ndarray | None:
        """Move the selection so the reference follows the cursor in its view plane.

        Returns the world offset of the reference (None without a drag)."""
        if self._drag is None:
            return None
        d = self._drag
        cam: Camera = d["camera"]
        ref_start = d["start_world"][d["selection"].index(self.reference)]
        hit = cam.point_on_view_plane(pixel, d["size"], ref_start)
        delta_world = hit - d["anchor"]
        lin = self.placement_matrix[:3, :3]
        delta = np.linalg.solve(lin, delta_world) if not self.placement.is_identity else delta_world
        sel = np.asarray(d["selection"])
        if self.kind in ("massspring", "chainmail") and self.model is not None:
            ijk = np.array(np.unravel_index(sel, self.model.grid.shape)).T
            offsets = d["start_offsets"] + delta
            self.model.move(ijk, offsets)
            rest = self.model.grid.rest_positions.reshape(-1, 3)
            movable = ~self.model.grid.fixed.reshape(-1)[sel]
            d["positions"][sel[movable]] = rest[sel[movable]] + offsets[movable]
        elif self.kind == "wires":
            start = d["positions"]
            for h in sel:
                w, k = self._wire_point(int(h))
                pts = self.wires[w].modified.control_points.copy()
                pts[k] = start[h] + delta
                self.wires[w] = _with_modified(self.wires[w], pts)
            self.wire_generation += 1
        elif self.kind == "lattice" and self.lattice_nodes is not None:
            nodes = d["positions"].copy()
            nodes[sel] += delta
            self.lattice_nodes = nodes.reshape(self.lattice_nodes.shape)
            self._drop_lattice_warp()
        self._sync_warps()
        return delta_world

    def _drop_lattice_warp(self) -> None:
        if self._lattice_warp is not None:
            self._released_warps.append(self._lattice_warp)
        self._lattice_warp = None

    def set_wire_points(self, wire: int, points: np.ndarray) -> None:
        """Move the modified control points of wire ``wire``; its attribute field is then
        stale (rebuild it with :meth:`wire_build` and :meth:`install_wire_build`)."""
        self.wires[wire] = _with_modified(self._wire(wire), points)
        self.wire_generation += 1

    def set_lattice_nodes(self, nodes: np.ndarray) -> None:
        """Move every node of the lattice (shape of :attr:`lattice_nodes`); the scene's
        warps follow."""
        if self.lattice_nodes is None:
            raise EditorError("no lattice to move: set_deformation('lattice') first")
        self.lattice_nodes = np.asarray(nodes, dtype=np.float64).reshape(self.lattice_nodes.shape)
        self._drop_lattice_warp()
        self._sync_warps()

    def model_moved(self) -> None:
        """Call after moving the element model directly (``model.move``, ``settle``) so
        that the scene's warps show its new state."""
        self._sync_warps()

    def end_drag(self) -> None:
        """Finish a drag (the elements stay held where they were dragged)."""
        self._drag = None
        self._touch()

    # ------------------------------------------------------------------ simulation
    def advance(self) -> bool:
        """One frame of the running model: ``steps_per_frame`` mass-spring steps or
        ``relax_steps`` ChainMail relaxation steps. Returns whether anything ran."""
        if not self.running or self.model is None or (self.settled and self._drag is None):
            return False
        n = self.steps_per_frame if isinstance(self.model, MassSpring) else self.relax_steps
        if n <= 0:
            return False
        gpu = self.model.backend == "gpu"
        if gpu and isinstance(self.model, ChainMail) and self._drag is not None:
            return False  # its relaxation reads the GPU back: not during a drag
        self._advances += 1
        check = not gpu or (self._drag is None and self._advances % 30 == 0)
        before = self.model.positions() if check and isinstance(self.model, ChainMail) else None
        t = time.perf_counter()
        if isinstance(self.model, MassSpring):
            self.model.step(n)
        else:
            self.model.relax(n)
        self.timings["step"] = (time.perf_counter() - t) * 1000 / n
        if check and self._drag is None:
            # at rest: stop stepping (the field, and so the picture, holds still, and the
            # renderer can build its skip maps) until the next edit
            if isinstance(self.model, MassSpring):
                speed = np.sqrt(np.max(np.sum(self.model.velocities() ** 2, axis=-1)))
                self.settled = bool(speed < SETTLED_SPEED)
            elif before is not None:
                self.settled = bool(np.max(np.abs(self.model.positions() - before)) < 1e-4)
        now = time.perf_counter()
        if self.model.backend != "gpu" or (
            self._drag is None and now - self._last_readback >= self.gpu_readback_interval
        ):
            self._handle_cache = None  # GPU: read back at most every gpu_readback_interval
            self._last_readback = now
        return True

    def single_step(self) -> None:
        """One step of the model even when paused."""
        running, self.running = self.running, True
        self.settled = False
        steps, relax = self.steps_per_frame, self.relax_steps
        self.steps_per_frame = self.relax_steps = 1
        try:
            self.advance()
        finally:
            self.running, self.steps_per_frame, self.relax_steps = running, steps, relax

    def reset_model(self) -> None:
        """Back to rest: elements released, wires straightened, lattice undeformed."""
        if self.model is not None:
            self.model.reset()
        elif self.kind == "wires":
            self.wires = [_with_modified(w, w.base.control_points) for w in self.wires]
            self.wire_generation += 1
            self._refresh_wire_field()
        elif self.kind == "lattice":
            self.set_deformation("lattice")
            return
        self._sync_warps()

    def _replace_warp(self, old: Any, new: Any) -> Any:
        if old is not None and old is not new:
            self._released_warps.append(old)
        return new

    # ------------------------------------------------------------------ wires
    def wire_build(self) -> WireBuild:
        """A job rebuilding the field of the current wires (run it on any thread)."""
        wires = [Wire.from_dict(w.to_dict()) for w in self.wires]
        return WireBuild(self.wire_generation, self.volume, wires, dict(self.wire_settings))

    @property
    def wire_field_stale(self) -> bool:
        """Whether the drawn field lags the wires (a rebuild is due)."""
        return self.kind == "wires" and (
            self._wire_warp is None or self._wire_built != self.wire_generation
        )

    def install_wire_build(self, job: WireBuild) -> bool:
        """Put a finished :class:`WireBuild` in the scene (GUI thread). Returns False
        when it was cancelled (dropped) or when the wires changed while it ran (then it
        is drawn meanwhile, and the field stays stale for the next build)."""
        if job.warp is None or job.cancelled or self.kind != "wires":
            return False
        self._wire_warp = self._replace_warp(self._wire_warp, job.warp)  # type: ignore[assignment]
        self._wire_built = job.generation
        self.timings["field"] = job.seconds * 1000
        self._sync_warps()
        return job.generation == self.wire_generation

    def set_wire_parameters(
        self,
        wire: int,
        *,
        kind: str | None = None,
        radius: float | None = None,
        beta: tuple[float, float] | Literal["keep"] | None = "keep",
    ) -> None:
        """Change a wire's curve kind, influence radius (mm) or β (value range or None);
        the field is then stale (rebuild it with :meth:`wire_build`)."""
        w = self._wire(wire)
        d = w.to_dict()
        if kind is not None:
            kind = _choice(kind, WIRE_KINDS, "wire kind")
            if kind != w.kind:
                d["base"] = _resampled(w.base.control_points, kind)
                d["modified"] = _resampled(w.modified.control_points, kind)
                d["kind"] = kind
        if radius is not None:
            d["radius"] = radius
        if beta != "keep":
            d["beta"] = None if beta is None else [float(beta[0]), float(beta[1])]
        self.wires[wire] = self._wire_from(d)
        self.wire_generation += 1
        self._touch()

    def set_wire_settings(self, **settings: Any) -> None:
        """Change how the wire field is built: ``field_scale`` (1, 2, 4, 8 or 16),
        ``layout`` (``"float"``/``"packed"``), ``masks`` (bool); the field is then stale."""
        allowed = {"field_scale", "layout", "masks"}
        unknown = set(settings) - allowed
        if unknown:
            raise EditorError(
                f"unknown wire settings {sorted(unknown)}; allowed: {sorted(allowed)}"
            )
        if "field_scale" in settings and settings["field_scale"] not in (1, 2, 4, 8, 16):
            raise EditorError(
                f"field_scale must be 1, 2, 4, 8 or 16; got {settings['field_scale']!r}"
            )
        if "layout" in settings and settings["layout"] not in ("float", "packed"):
            raise EditorError(f"layout must be 'float' or 'packed'; got {settings['layout']!r}")
        if "masks" in settings and not isinstance(settings["masks"], bool):
            raise EditorError(f"masks must be true or false; got {settings['masks']!r}")
        self.wire_settings.update(settings)
        self.wire_generation += 1
        self._touch()

    def set_wire_key(
        self, handle: int, *, twist: float | None = None, scale: float | None = None
    ) -> None:
        """Set the twist (radians) or scale at the control point of ``handle``: a key
        at that point's fraction of the wire's length (replacing a key there)."""
        if handle is None:
            raise EditorError("select a control point of a wire first (click it)")
        w, k = self._wire_point(int(handle))
        wire = self.wires[w]
        t = _length_fraction(wire.modified, k)
        d = wire.to_dict()
        for name, value in (("twist", twist), ("scale", scale)):
            if value is None:
                continue
            keys = [tuple(x) for x in (d.get(name) or []) if abs(float(x[0]) - t) > 1e-6]
            keys.append((t, float(value)))
            d[name] = sorted(keys)
        self.wires[w] = self._wire_from(d)
        self.wire_generation += 1
        self._touch()

    def _wire(self, wire: int) -> Wire:
        if self.kind != "wires" or not 0 <= wire < len(self.wires):
            raise EditorError(f"no wire {wire}: there are {len(self.wires)} wires")
        return self.wires[wire]

    @staticmethod
    def _wire_from(d: dict[str, Any]) -> Wire:
        try:
            return Wire.from_dict(d)
        except (WarpError, TypeError, ValueError) as exc:
            raise EditorError(str(exc)) from exc

    def add_wire_point(self, camera: Camera, size: tuple[int, int], pixel: Sequence[float]) -> None:
        """Lay a control point of a new wire where the cursor meets the plane parallel
        to the image through the volume's centre (the slice plane of the view)."""
        lo, hi = self.box
        p = camera.point_on_view_plane(pixel, size, 0.5 * (lo + hi))
        m = np.linalg.inv(self.placement_matrix)
        self.pending_wire.append(p @ m[:3, :3].T + m[:3, 3])

    def finish_wire(self, kind: str = "catmull-rom", radius: float | None = None) -> int:
        """Make the laid points a wire (base = modified; then bend it by dragging).
        Returns its index. Needs 2+ points (Bézier: 3k + 1, extra points are dropped)."""
        kind = _choice(kind, WIRE_KINDS, "wire kind")
        pts = np.asarray(self.pending_wire, dtype=np.float64).reshape(-1, 3)
        if kind == "bezier":
            pts = pts[: 3 * ((len(pts) - 1) // 3) + 1]
        if len(pts) < (4 if kind == "bezier" else 2):
            raise EditorError(
                f"a {kind} wire needs at least {4 if kind == 'bezier' else 2} control points;"
                f" {len(self.pending_wire)} laid: click more points first"
            )
        if self.kind != "wires":
            raise EditorError("choose the wires deformation before laying a wire")
        if radius is None:
            radius = (
                self.wires[-1].radius if self.wires else 0.1 * float(np.max(np.ptp(self.box, 0)))
            )
        wire = self._wire_from(
            {
                "base": pts.tolist(),
                "modified": pts.tolist(),
                "kind": kind,
                "radius": radius,
                "name": f"wire {len(self.wires) + 1}",
            }
        )
        self.wires.append(wire)
        self.pending_wire = []
        self.wire_generation += 1
        self._touch()
        return len(self.wires) - 1

    def remove_wire(self, wire: int) -> None:
        """Delete a wire (the last one cannot go: switch the deformation off instead)."""
        self._wire(wire)
        if len(self.wires) == 1:
            raise EditorError("a wire field needs a wire: choose deformation 'none' instead")
        del self.wires[wire]
        self.selection, self.reference = [], None
        self.wire_generation += 1
        self._touch()

    # ------------------------------------------------------------------ overlay
    def overlay_layers(self, display: DisplayOptions | None = None) -> list[OverlayLayer]:
        """The handles, links, wires and cells to draw over the frame (world mm)."""
        disp = display or DisplayOptions()
        layers: list[OverlayLayer] = []
        lo, hi = self.box
        if disp.grid_box and self.kind != "none":
            edges = self._grid_to_world(box_edges(lo, hi))
            layers.append(OverlayLayer("lines", edges, COLORS["box"], name="grid box"))
        if disp.clip_box and self.scene.clip_box is not None:
            c0, c1 = self.scene.clip_box
            layers.append(OverlayLayer("lines", box_edges(c0, c1), COLORS["box"], name="clip"))
        pts = self.handles()
        if self.kind in ("massspring", "chainmail") and self.model is not None:
            shape = self.model.grid.shape
            if disp.links:
                layers.append(
                    OverlayLayer(
                        "lines", grid_edges(pts.reshape(*shape, 3)), COLORS["link"], name="links"
                    )
                )
            fixed = self.fixed_handles()
            if disp.elements:
                layers.append(
                    OverlayLayer("points", pts[~fixed], COLORS["element"], 5.0, name="elements")
                )
            if disp.fixed and np.any(fixed):
                layers.append(OverlayLayer("points", pts[fixed], COLORS["fixed"], 7.0, "fixed"))
        elif self.kind == "wires":
            for wire in self.wires:
                t = np.linspace(0.0, 1.0, 96)
                if disp.wires_base:
                    seg = polyline_segments(self._grid_to_world(wire.base.evaluate(t)))
                    layers.append(OverlayLayer("lines", seg, COLORS["wire_base"], name="base"))
                if disp.wires_modified:
                    seg = polyline_segments(self._grid_to_world(wire.modified.evaluate(t)))
                    layers.append(OverlayLayer("lines", seg, COLORS["wire_modified"], name="wire"))
            if disp.wires_modified and len(pts):
                layers.append(OverlayLayer("points", pts, COLORS["wire_modified"], 8.0, "points"))
        elif self.kind == "lattice" and self.lattice_nodes is not None:
            if disp.lattice_cells:
                nodes = pts.reshape(self.lattice_nodes.shape)
                layers.append(
                    OverlayLayer("lines", grid_edges(nodes), COLORS["lattice"], name="cells")
                )
                layers.append(OverlayLayer("points", pts, COLORS["lattice"], 7.0, "nodes"))
        if self.pending_wire:
            p = self._grid_to_world(np.asarray(self.pending_wire))
            layers.append(OverlayLayer("points", p, COLORS["pending"], 8.0, "new wire"))
            if len(p) > 1:
                layers.append(OverlayLayer("lines", polyline_segments(p), COLORS["pending"]))
        if disp.selection and self.selection and len(pts):
            sel = np.asarray([i for i in self.selection if i < len(pts)], dtype=int)
            layers.append(OverlayLayer("points", pts[sel], COLORS["selected"], 10.0, "selected"))
            if self.reference is not None and self.reference < len(pts):
                layers.append(
                    OverlayLayer("points", pts[[self.reference]], COLORS["reference"], 12.0, "ref")
                )
        return layers

    # ------------------------------------------------------------------ snapshots
    def snapshot(self) -> Snapshot:
        """The whole editable state, copied (model state incl. velocities, wires,
        lattice, placement, selection, settings)."""
        snap = Snapshot(
            kind=self.kind,
            backend=self.backend,
            resolution=self.resolution,
            placement=Placement(**self.placement.to_dict()),
            selection=tuple(self.selection),
            reference=self.reference,
            settings={
                "integrator": self.integrator,
                "variant": self.variant,
                "steps_per_frame": self.steps_per_frame,
                "relax_steps": self.relax_steps,
                "stiffness": self.stiffness,
            },
            wire_settings=dict(self.wire_settings),
            look=scene_look(self.scene),
            animation=self.animation.to_dict() if self.animation is not None else None,
        )
        if self.model is not None:
            snap.model = self.model.to_dict()
            snap.positions = self.model.positions()
            if isinstance(self.model, MassSpring):
                snap.velocities = self.model.velocities()
        snap.wires = [w.to_dict() for w in self.wires]
        if self.lattice_nodes is not None:
            snap.lattice_nodes = self.lattice_nodes.copy()
        return snap

    def restore(self, snap: Snapshot) -> None:
        """Return to a :meth:`snapshot` exactly (a wire field is rebuilt synchronously
        when its wires differ from the drawn field's)."""
        same_wires = (
            snap.kind == "wires"
            and self.kind == "wires"
            and snap.wires == [w.to_dict() for w in self.wires]
            and snap.wire_settings == self.wire_settings
        )
        keep_field = self._wire_warp if same_wires and not self.wire_field_stale else None
        drawn = self._wire_warp if snap.kind == "wires" else None
        self._wire_warp = None  # keep the drawn field out of _close_model's release list
        self._close_model()
        s = snap.settings
        self.kind, self.backend, self.resolution = snap.kind, snap.backend, snap.resolution
        self.integrator, self.variant = s["integrator"], s["variant"]
        self.steps_per_frame, self.relax_steps = s["steps_per_frame"], s["relax_steps"]
        self.stiffness = s["stiffness"]
        self.placement = Placement(**snap.placement.to_dict())
        self.wire_settings = dict(snap.wire_settings)
        if snap.model is not None:
            self.model = self._new_element_model(snap.model)
            if isinstance(self.model, MassSpring):
                self.model.set_state(snap.positions, snap.velocities)
            else:
                self.model.set_state(snap.positions)
        self.wires = [Wire.from_dict(w) for w in snap.wires]
        if self.kind == "wires":
            self.wire_generation += 1
            if keep_field is not None:
                self._wire_warp = keep_field
                self._wire_built = self.wire_generation
            else:
                self._wire_warp = drawn  # drawn until the rebuilt field replaces it
                self._refresh_wire_field()
        elif drawn is not None:
            self._released_warps.append(drawn)
        if snap.lattice_nodes is not None:
            self.lattice_nodes = snap.lattice_nodes.copy()
        self.selection, self.reference = list(snap.selection), snap.reference
        if snap.look:
            set_scene_look(self.scene, snap.look)
        self.animation = _animation_from(snap.animation)
        self._sync_warps()

    # ------------------------------------------------------------------ files
    def to_dict(self, base_dir: str | os.PathLike | None = None) -> dict[str, Any]:
        """Scene JSON plus an ``"editor"`` entry (deformation, placement, settings).

        The warps carry the models (mass-spring/ChainMail state, wires, lattice), so
        the file also renders with ``voxwarp render`` and resumes in the GUI. A stale
        wire field (edited, not rebuilt yet) is rebuilt first, so the file holds the
        wires as they are."""
        if self.wire_field_stale:
            self._wire_warp = self._replace_warp(self._wire_warp, self._build_wires_now())
            self._wire_built = self.wire_generation
            self._sync_warps()
        d = self.scene.to_dict(base_dir=base_dir)
        model_index = {0: None, 1: 0, 3: 1}[len(self.scene.warps)]
        d[EDITOR_KEY] = {
            "deformation": self.kind,
            "backend": self.backend,
            "resolution": list(self.resolution),
            "placement": self.placement.to_dict(),
            "model_warp": model_index,
            "integrator": self.integrator,
            "variant": self.variant,
            "steps_per_frame": self.steps_per_frame,
            "relax_steps": self.relax_steps,
            "stiffness": self.stiffness,
            "wire_settings": dict(self.wire_settings),
        }
        if self.animation is not None:
            d["animation"] = self.animation.to_dict()
        return d

    def save(self, path: str | os.PathLike) -> Path:
        """Write the session as scene JSON, atomically (a failed save keeps the old file)."""
        path = Path(path)
        text = json.dumps(self.to_dict(base_dir=path.parent.resolve()), indent=1)
        atomic_write_text(path, text)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike, ctx: Any = None) -> EditSession:
        """Open a scene JSON (from :meth:`save`, ``voxwarp render`` or ``demo``)."""
        raw = read_scene_dict(path)
        scene = Scene.from_dict(raw, base_dir=Path(path).parent.resolve())
        editor = raw.get(EDITOR_KEY)
        session = cls(scene, ctx, editor=editor if isinstance(editor, dict) else None)
        if raw.get("animation") is not None:
            session.animation = _animation_from(raw["animation"])
        return session

    def _recover_from_scene(self, entry: dict[str, Any]) -> None:
        """Take over the deformation saved in the scene's warps (see :meth:`to_dict`),
        with the settings of the scene's editor ``entry``."""
        warps = list(self.scene.warps)
        try:
            if entry.get("placement") is not None:
                self.placement = Placement.from_dict(entry["placement"])
            if entry.get("resolution") is not None:
                self.resolution = _resolution(entry["resolution"])
            for key in ("integrator", "variant"):
                if key in entry:
                    setattr(self, key, str(entry[key]))
            for key in ("steps_per_frame", "relax_steps"):
                if key in entry:
                    setattr(self, key, int(entry[key]))
            if "stiffness" in entry:
                self.stiffness = float(entry["stiffness"])
            if isinstance(entry.get("wire_settings"), dict):
                self.wire_settings = dict(entry["wire_settings"])
            if not warps:
                self._sync_warps()
                return
            index = entry.get("model_warp", 0 if len(warps) == 1 else None)
            if len(warps) == 3 and index is None:
                index = 1
            if index is None or not 0 <= int(index) < len(warps):
                raise EditorError(
                    f"the scene has {len(warps)} warps; the editor takes over one model warp"
                    " (optionally between two placement warps)"
                )
            w = warps[int(index)]
            backend = entry.get("backend", "cpu")
            self.backend = backend if backend in BACKENDS and self.ctx is not None else "cpu"
            if isinstance(w, OffsetFieldWarp) and w.model_state is not None:
                kind = w.model_state.get("type")
                cls = MassSpring if kind == "massspring" else ChainMail
                ctx = self.ctx if self.backend == "gpu" else None
                self.model = cls.from_warp(w, backend=self.backend, ctx=ctx)
                self.kind = "massspring" if cls is MassSpring else "chainmail"
                self.resolution = self.model.grid.shape
            elif isinstance(w, WireFieldWarp):
                self.kind = "wires"
                self.wires = list(w.wires)
                self._wire_warp = w
                self._wire_built = self.wire_generation
                spec = w.to_dict()
                self.wire_settings = {
                    k: spec[k] for k in ("field_scale", "layout", "masks") if k in spec
                } or self.wire_settings
            elif isinstance(w, LatticeWarp):
                self.kind = "lattice"
                self.lattice_nodes = np.asarray(w.grid.nodes, dtype=np.float64).copy()
                self._lattice_warp = w
            else:
                raise EditorError(
                    f"the scene's {w.kind!r} warp is not editable (the editor takes"
                    " mass-spring, ChainMail, wire and lattice warps)"
                )
        except (WarpError, KeyError, TypeError, ValueError) as exc:
            if isinstance(exc, EditorError):
                raise
            raise EditorError(f"cannot resume the scene's deformation: {exc}") from exc
        self._sync_warps()

    def close(self) -> None:
        """Release the model (GPU resources: call with the context current)."""
        self._close_model()
        self.kind = "none"
        self.scene.warps = []


# ---------------------------------------------------------------------------- helpers
#: scene attributes that make its look (undoable edits of the Volume and TF panels)
LOOK_KEYS = (
    "mode",
    "step",
    "window",
    "clip_box",
    "jitter",
    "shading",
    "iso_value",
    "flm_threshold",
    "background",
    "projection",
)


def scene_look(scene: Scene) -> dict[str, Any]:
    """The scene's look (see :data:`LOOK_KEYS`) and transfer function, as plain values."""
    look: dict[str, Any] = {k: getattr(scene, k) for k in LOOK_KEYS}
    look["window"] = scene._window  # None: the volume's default window
    look["transfer_function"] = scene.transfer_function
    return look


def set_scene_look(scene: Scene, look: dict[str, Any]) -> None:
    """Set what :func:`scene_look` returned."""
    for k in LOOK_KEYS:
        if k in look:
            v = look[k]
            setattr(scene, k, tuple(v) if k == "background" else v)
    if "transfer_function" in look:
        scene.transfer_function = look["transfer_function"]


def _animation_from(d: Any) -> Any:
    """An :class:`~voxwarp.animation.tracks.Animation` from its dict (None stays None)."""
    if d is None:
        return None
    from voxwarp.animation.tracks import Animation, AnimationError

    try:
        return Animation.from_dict(d)
    except AnimationError as exc:
        raise EditorError(f"invalid animation in the scene: {exc}") from exc


def _with_modified(wire: Wire, points: np.ndarray) -> Wire:
    d = wire.to_dict()
    d["modified"] = np.asarray(points, dtype=np.float64).tolist()
    return Wire.from_dict(d)


def _resampled(points: np.ndarray, kind: str) -> list[list[float]]:
    """Control points for a curve of another kind through about the same places."""
    p = np.asarray(points, dtype=np.float64)
    if kind == "bezier":
        n = 3 * max(1, math.ceil((len(p) - 1) / 3)) + 1
    else:
        n = max(2, len(p))
    s = np.linspace(0.0, 1.0, len(p))
    t = np.linspace(0.0, 1.0, n)
    return np.stack([np.interp(t, s, p[:, a]) for a in range(3)], axis=1).tolist()


def _length_fraction(curve: Any, k: int) -> float:
    """Fraction of the curve's length at (the point closest to) control point ``k``."""
    t, _ = curve.closest_point(curve.control_points[k])
    t = float(np.asarray(t).reshape(-1)[0])
    total = curve.arc_length()
    if total <= 0:
        return 0.0
    return float(np.clip(curve.arc_length(t1=t) / total, 0.0, 1.0))


def warm_up_kernels() -> None:
    """Compile the numba kernels the editor uses (ChainMail's move and relaxation,
    the lattice's grid evaluation) on tiny inputs: the first compile of a fresh install
    takes seconds; run this on a worker thread at start so the first drag does not."""
    grid = ElementGrid(((0.0, 0.0, 0.0), (1.0, 1.0, 1.0)), shape=3)
    cm = ChainMail(grid)
    cm.move((1, 1, 1), (0.01, 0.0, 0.0))
    cm.relax(1)
    cm.close()
    lo, hi = np.zeros(3), np.ones(3)
    u = np.stack(np.meshgrid(*(np.linspace(0.0, 1.0, 3),) * 3, indexing="ij"), -1)
    LatticeWarp(TrilinearGrid(u), (lo, hi)).apply(np.full((1, 3), 0.5))
