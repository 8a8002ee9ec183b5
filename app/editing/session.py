"""The editing session behind the desktop GUI: a scene, one deformation model, picking
and dragging, snapshots for undo, save and load. No Qt here (``ui/`` drives it).

About the interaction (Knoche 2008, 3.2; Singh and Fiume, wires, section 8)
-----------------------------------------------------------------------------
The session holds a :class:`~voxwarp.scene.Scene` and one deformation family, through
its adapter (:mod:`voxwarp.editing.families`; the session never switches on the family):

* ``"massspring"`` / ``"chainmail"``: an :class:`~voxwarp.deform.elements.grid.ElementGrid` of
  elements over the volume, run by :class:`~voxwarp.deform.elements.massspring.MassSpring` or
  :class:`~voxwarp.deform.elements.chainmail.ChainMail` (CPU or GPU backend); the handles are the
  elements.
* ``"wires"``: :class:`~voxwarp.deform.wires.field.Wire` objects and their attribute field; the
  handles are the control points of the *modified* wires (the base wires stay where
  they were laid). Editing one needs a rebuild of the field (~0.2 s): the adapter
  hands out a :class:`~voxwarp.editing.state.BuildJob`
  (``session.family.build_job()``) that runs off the GUI thread and installs its result
  (``session.family.install(job)``) only if nothing changed meanwhile.
* ``"lattice"``: a :class:`~voxwarp.deform.lattice.trilinear.TrilinearGrid` over the volume's box
  (:class:`~voxwarp.deform.lattice.warp.LatticeWarp`); the handles are its nodes.

A family's own editing API lives on its adapter, reached through the typed accessor
:meth:`EditSession.adapter`: ``session.adapter(WiresFamily).add_wire_point(...)``,
``session.adapter(LatticeFamily).set_lattice_nodes(nodes)``. Models are built from
settings by the adapters' one builder (:mod:`voxwarp.editing.model_settings`).

Handles are picked in screen space (the nearest projected handle within a radius of
pixels), added to or removed from a selection (one of them the *reference*), and
dragged in the plane parallel to the image through the reference: every selected
handle moves by the reference's offset, so the selection keeps its shape.

The deformation grid can be placed relative to the volume (:class:`Placement`:
translation, rotation about the box centre, scale); the warp chain is then
``[placement^-1, model warp, placement]``, so outside the placed grid nothing moves.

Every edit is bracketed by :meth:`EditSession.snapshot` (an in-memory copy of the
whole state, velocities included) so that undo restores it exactly.

The element models can step on a worker thread (:meth:`EditSession.set_model_thread`,
the GUI's choice; :mod:`voxwarp.editing.model_worker`): drags and frames then post
steps, :meth:`EditSession.poll_model` shows the newest finished state, and snapshots,
saves and family switches first wait for the worker (:meth:`EditSession.wait_for_model`).
Without it (scripts, the notebook) every call steps the model before it returns.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Literal, TypeVar

import numpy as np

from voxwarp.animation.tracks import Animation, AnimationError
from voxwarp.core.camera import Camera
from voxwarp.deform.elements.chainmail import ChainMail
from voxwarp.deform.elements.grid import ElementGrid
from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.deform.lattice.trilinear import TrilinearGrid
from voxwarp.deform.lattice.warp import LatticeWarp
from voxwarp.deform.warp import AffineWarp, Warp, WarpError
from voxwarp.editing.common import (
    BACKENDS as BACKENDS,
)
from voxwarp.editing.common import (
    CHAINMAIL_VARIANTS as CHAINMAIL_VARIANTS,
)
from voxwarp.editing.common import (
    COLORS,
    WIRE_KINDS,
    DisplayOptions,
    EditorError,
    choice,
    resolution,
)
from voxwarp.editing.common import (
    INTEGRATORS as INTEGRATORS,
)
from voxwarp.editing.families import FAMILIES, Family
from voxwarp.editing.model_settings import FamilyOptions
from voxwarp.editing.model_worker import ModelWorker
from voxwarp.editing.state import DragState, Placement, Snapshot
from voxwarp.render.overlay import OverlayLayer, box_edges
from voxwarp.scene import Scene, read_scene_dict, write_scene_json

Deformation = Literal["none", "massspring", "chainmail", "wires", "lattice"]
#: the deformation families, in the order the GUI offers them
DEFORMATIONS: tuple[str, ...] = tuple(FAMILIES)
SelectMode = Literal["replace", "add", "remove", "toggle"]
#: pick radius in pixels around a handle
PICK_RADIUS_PX = 12.0
#: the session attributes that choose the deformation model
#: key of the editor's entry in scene JSON
EDITOR_KEY = "editor"
__all__ = [
    "BACKENDS",
    "CHAINMAIL_VARIANTS",
    "DEFORMATIONS",
    "INTEGRATORS",
    "WIRE_KINDS",
    "DisplayOptions",
    "EditSession",
    "EditorError",
    "Placement",
    "Snapshot",
]

F = TypeVar("F", bound=Family)


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
        #: the deformation family's adapter (its state and behaviour)
        self.family: Family = Family(self)
        self.backend: str = "cpu"
        self.resolution: tuple[int, int, int] = (8, 8, 8)
        self.placement = Placement()
        #: the families' settings, kept across family switches, saved and undone (the
        #: adapters read them: element integrator/variant/stiffness/steps, wire settings)
        self.options = FamilyOptions()
        self.running: bool = True
        #: build a family's field at once on model changes and undo (scripts, tests); the
        #: GUI sets False and builds it off its thread (``family.build_job()``)
        self.sync_builds = True
        #: GPU models: least seconds between element read-backs for the overlay while
        #: the simulation runs (never during a drag)
        self.gpu_readback_interval = 0.5
        self._last_readback = 0.0
        #: the running model came to rest (:meth:`advance` stops stepping until an edit)
        self.settled = False
        self.selection: list[int] = []
        self.reference: int | None = None
        #: last timings in ms: "step" (model), "field" (wire build)
        self.timings: dict[str, float] = {}
        self._drag: DragState | None = None
        self._handle_cache: np.ndarray | None = None
        self._released_warps: list[Warp] = []
        #: keyframes (:mod:`voxwarp.editing.keyframes`; saved in scene JSON for ``voxwarp
        #: animate``)
        self.animation: Any = None
        #: warps read from files (displacement fields, ITK transforms), last in the
        #: scene's chain: they map the registration's fixed space to the volume's, and
        #: the family's warp before them corrects what is displayed (:meth:`add_warps_front`)
        self.imported_warps: list[Warp] = []
        #: ``() -> context manager`` making the GL context of GPU models current (the
        #: GUI's viewport sets it; a headless caller's context is current already)
        self.gl_scope: Callable[[], Any] = contextlib.nullcontext
        #: the worker thread stepping a CPU element model (:meth:`set_model_thread`),
        #: or None: the model steps on the caller's thread
        self.model_worker: ModelWorker | None = None
        self._recover_from_scene(editor if isinstance(editor, dict) else {})

    # ------------------------------------------------------------------ properties
    @property
    def kind(self) -> str:
        """The deformation family: one of :data:`DEFORMATIONS`."""
        return self.family.kind

    @property
    def model(self) -> Any:
        """The element model (mass-spring or ChainMail), else None."""
        return self.family.model

    def adapter(self, cls: type[F]) -> F:
        """The active family's adapter as ``cls`` (e.g. ``session.adapter(WiresFamily)``
        for the wire editing API); an :class:`EditorError` when another family is active."""
        family = self.family
        if not isinstance(family, cls):
            raise EditorError(f"choose the {cls.kind} deformation first")
        return family

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

    @property
    def drag_state(self) -> DragState | None:
        """The drag in progress (for the family adapters), or None."""
        return self._drag

    def _touch(self) -> None:
        self._handle_cache = None
        self.settled = False

    def edited(self) -> None:
        """An adapter edited its state: forget cached handles, run the model again."""
        self._touch()

    def handles_moved(self, throttle: bool = False) -> None:
        """The handles moved (a running model): forget their cached positions; with
        ``throttle`` (a GPU model) at most every :attr:`gpu_readback_interval` s and
        never during a drag."""
        now = time.perf_counter()
        late = now - self._last_readback >= self.gpu_readback_interval
        if not throttle or (self._drag is None and late):
            self._handle_cache = None
            self._last_readback = now

    # ------------------------------------------------------------------ model thread
    def set_model_thread(self, on: bool, on_result: Callable[[], Any] | None = None) -> None:
        """Step CPU element models on a worker thread (``on``; the GUI does) or on the
        caller's thread (the default). ``on_result``: ``() -> None`` called on the worker
        thread when a step finished (to wake the GUI thread, which then calls
        :meth:`poll_model`; it must not block). GPU models always step on the thread
        whose GL context they use."""
        if self.model_worker is not None:
            self.wait_for_model()
            self.model_worker.close()
            self.model_worker = None
        if on:
            self.model_worker = ModelWorker(on_result=on_result)

    def wait_for_model(self) -> None:
        """Wait for the worker's steps and show their result: the model is then in one
        consistent state (snapshots, saves and scripts call this; nothing to wait for
        without a worker)."""
        if self.model_worker is not None:
            self.model_worker.wait_idle()
            self.family.poll()

    @property
    def model_busy(self) -> bool:
        """Whether the model worker has steps running, pending or not shown yet."""
        w = self.model_worker
        return w is not None and (not w.idle or w.has_result)

    def poll_model(self) -> bool:
        """Show the newest state the model worker finished (the field goes to the warp
        the renderer uploads, on this thread); whether anything changed."""
        return self.model_worker is not None and self.family.poll()

    # ------------------------------------------------------------------ models
    def set_deformation(self, kind: str, **settings: Any) -> None:
        """Switch the deformation family (and settings: ``backend``, ``resolution``,
        ``integrator``, ``variant``, ``stiffness``, ``margin``: mm the element grid's box
        reaches beyond the volume's, or ``"auto"`` (the default: 10 % of the volume box's
        largest side, resolved when the model is built; 0: the volume's box), and the
        element grid's boundary conditions
        ``anchor`` and ``fix_outside``, see
        :class:`~voxwarp.deform.elements.grid.ElementGrid`); builds a fresh model at rest,
        except from mass-spring to ChainMail or back on the same element grid: the new
        model continues the deformation (``from_model``; ``family.switch_note`` says how
        far ChainMail's limits moved elements).

        ``"wires"`` starts with one straight wire along the volume's longest axis
        through its centre (bend it by dragging its control points, or lay new ones);
        ``"lattice"`` starts with an undeformed lattice of ``resolution - 1`` cells
        per axis (at most 8).
        """
        kind = choice(kind, DEFORMATIONS, "deformation")
        backend, res, options = self._checked_settings(settings)
        if backend == "gpu" and FAMILIES[kind].uses_backend and self.ctx is None:
            raise EditorError("the GPU backend needs the viewport's OpenGL context; use cpu")
        now = (self.backend, self.resolution, self.options)
        # build the new family before closing the old: a refused setting leaves the
        # session as it was (the wire family builds its field after the switch)
        family = FAMILIES[kind](self)
        self.backend, self.resolution, self.options = backend, res, options
        if family.uses_backend:
            try:
                if not family.continue_from(self.family):
                    family.start()
            except EditorError:
                self.backend, self.resolution, self.options = now
                raise
        self._close_family()
        self.timings.clear()
        self.selection, self.reference = [], None
        self.family = family
        if not family.uses_backend:
            family.start()
        self.sync_warps()

    def _checked_settings(
        self, settings: dict[str, Any]
    ) -> tuple[str, tuple[int, int, int], FamilyOptions]:
        """The backend, resolution and family options ``settings`` ask for, checked."""
        settings = dict(settings)
        backend = choice(settings.pop("backend", self.backend), BACKENDS, "backend")
        res = resolution(settings.pop("resolution", self.resolution))
        return backend, res, self.options.with_model_settings(settings)

    def _close_family(self) -> None:
        self.family.close()
        self.family = Family(self)
        self._drag = None

    def release_warp(self, warp: Warp) -> None:
        """Hand over a warp that is no longer drawn (see :meth:`take_released_warps`)."""
        self._released_warps.append(warp)

    def take_released_warps(self) -> list[Warp]:
        """Warps no longer drawn, whose GPU textures the caller should release (with its
        context current)."""
        out, self._released_warps = self._released_warps, []
        return out

    def model_warp(self) -> Warp | None:
        """The warp of the current deformation in the grid frame (None for ``"none"``)."""
        return self.family.warp()

    def sync_warps(self) -> None:
        """Put the family's warp (placed by :attr:`placement`), then the imported warps,
        in the scene: the model acts in the displayed space (a correction drawn on top of
        a registration moves what is seen where it is dragged), the imported warps then
        carry that space to the volume's."""
        self.scene.warps = [*self._model_chain(), *self.imported_warps]
        self._touch()

    def _model_chain(self) -> list[Warp]:
        w = self.model_warp()
        if w is None:
            return []
        if self.placement.is_identity:
            return [w]
        m = self.placement_matrix
        # deformed world -> grid frame, the model, grid frame -> original world
        return [AffineWarp(m), w, AffineWarp(np.linalg.inv(m))]

    def add_warps_front(self, warps: Sequence[Warp]) -> int:
        """Put warps read from a file (:func:`voxwarp.io.fields.load_transform`) in the
        scene's chain: before earlier imported warps, after the model's (see
        :meth:`sync_warps`): a registration field maps the fixed space to the volume's,
        and the model corrects it in the displayed space. Returns how many imported
        warps there are now."""
        new = list(warps)
        if not new or not all(isinstance(w, Warp) for w in new):
            raise EditorError(
                "add_warps_front needs a non-empty list of warps (voxwarp.io.fields.load_transform)"
            )
        self.imported_warps = [*new, *self.imported_warps]
        self.sync_warps()
        return len(self.imported_warps)

    def field_view_warps(self) -> list[tuple[str, Warp]]:
        """The warps the field slice view offers, with a label each: ``("model", w)`` for
        :meth:`model_warp` (if any), then one per imported warp named by its file."""
        out: list[tuple[str, Warp]] = []
        w = self.model_warp()
        if w is not None:
            out.append(("model", w))
        for i, imp in enumerate(self.imported_warps):
            path = getattr(imp, "path", None)
            label = Path(path).name if path else f"imported {imp.kind} {i + 1}"
            part = getattr(imp, "part", None)
            out.append((label if part is None else f"{label} #{part}", imp))
        return out

    def remove_imported_warps(self) -> int:
        """Take every imported warp out of the chain; returns how many there were."""
        gone, self.imported_warps = self.imported_warps, []
        for w in gone:
            self.release_warp(w)
        self.sync_warps()
        return len(gone)

    def model_moved(self) -> None:
        """Call after moving the element model directly (``model.move``, ``settle``) so
        that the scene's warps show its new state."""
        self.sync_warps()

    def set_placement(self, placement: Placement) -> None:
        """Move/rotate/scale the deformation grid relative to the volume."""
        if not isinstance(placement, Placement):
            raise EditorError("set_placement needs a Placement")
        self.placement = placement
        self.sync_warps()

    def set_option(self, name: str, value: Any) -> None:
        """Set a run-time option: ``steps_per_frame`` (mass-spring steps per frame),
        ``relax_steps`` (ChainMail relaxation steps per frame), ``running``."""
        if name == "running":
            self.running = bool(value)
        else:
            self.family.option_changed(name, self.options.set_run_option(name, value))

    # ------------------------------------------------------------------ handles
    def _grid_to_world(self, p: np.ndarray) -> np.ndarray:
        if self.placement.is_identity:
            return p
        m = self.placement_matrix
        return p @ m[:3, :3].T + m[:3, 3]

    def handles(self) -> np.ndarray:
        """(N, 3) world positions of the pickable handles (elements, modified wire
        control points or lattice nodes); a GPU model is read back at most once per
        change, never during a drag."""
        if self._handle_cache is None:
            self._handle_cache = self._grid_to_world(self.family.handles())
        return self._handle_cache

    def fixed_handles(self) -> np.ndarray:
        """(N,) bool: handles that do not move (fixed elements)."""
        return self.family.fixed_handles(len(self.handles()))

    def anchored_handles(self) -> np.ndarray:
        """(N,) bool: handles anchored at rest by the region of influence of a drag."""
        return self.family.anchored_handles(len(self.handles()))

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
        depth = (pts - camera.eye) @ -camera.rotation[:, 2]
        return _nearest_on_screen(camera, size, pixel, radius, pts, depth, depth > 0)

    def pick_near_plane(
        self,
        camera: Camera,
        size: tuple[int, int],
        pixel: Sequence[float],
        max_distance: float,
        radius: float = PICK_RADIUS_PX,
    ) -> int | None:
        """:meth:`pick` among the handles within ``max_distance`` mm of the camera's view
        plane through its centre (a slice view's plane: ``SlicePlane.camera()``); ties:
        the one nearest the plane."""
        pts = self.handles()
        off = np.abs((pts - camera.center) @ camera.rotation[:, 2])
        return _nearest_on_screen(camera, size, pixel, radius, pts, off, off <= max_distance)

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
        self.family.set_fixed(list(indices), fixed)
        self._touch()

    def cut_links(self, indices: Sequence[int]) -> int:
        """Cut the links around elements ``indices`` (ChainMail): every link from one of
        them to an element not among them; how many were cut."""
        n = self.family.cut_links(list(indices))
        self._touch()
        return n

    def join_links(self, indices: Sequence[int], pull: bool = False) -> tuple[int, int]:
        """Join the cut links with an end among elements ``indices`` (ChainMail) where
        the two elements touch; ``(joined, left cut)``: links whose elements a drag
        pulled too far apart stay cut (drag them together first) unless ``pull``, which
        drags free elements until the sides meet and joins them all (a suture; held
        and fixed elements stay, and when they are in the way nothing changes)."""
        joined = self.family.join_links(list(indices), pull)
        self._touch()
        return joined

    # ------------------------------------------------------------------ dragging
    def begin_drag(self, camera: Camera, size: tuple[int, int], pixel: Sequence[float]) -> bool:
        """Start dragging the selection (the reference under the cursor defines the plane).

        Returns False when nothing is selected."""
        if not self.selection or self.reference is None:
            return False
        pts = self.handles()
        ref = pts[self.reference]
        self._drag = DragState(
            camera=camera,
            size=size,
            anchor=camera.point_on_view_plane(pixel, size, ref),
            start_world=pts[np.asarray(self.selection)].copy(),
            positions=self.family.handles().copy(),
            selection=list(self.selection),
        )
        self.family.begin_drag(self._drag)
        return True

    def drag_to(self, pixel: Sequence[float]) -> np.ndarray | None:
        """Move the selection so the reference follows the cursor in its view plane.

        Returns the world offset of the reference (None without a drag)."""
        if self._drag is None:
            return None
        d = self._drag
        ref_start = d.start_world[d.selection.index(self.reference)]
        hit = d.camera.point_on_view_plane(pixel, d.size, ref_start)
        delta_world = hit - d.anchor
        lin = self.placement_matrix[:3, :3]
        delta = np.linalg.solve(lin, delta_world) if not self.placement.is_identity else delta_world
        self.family.drag(d, np.asarray(d.selection), delta)
        self.sync_warps()
        return delta_world

    def end_drag(self) -> None:
        """Finish a drag (the elements stay held where they were dragged)."""
        self._drag = None
        self._touch()

    # ------------------------------------------------------------------ simulation
    def advance(self) -> bool:
        """One frame of the running model: ``steps_per_frame`` mass-spring steps or
        ``relax_steps`` ChainMail relaxation steps. Returns whether anything ran."""
        shown = self.poll_model()
        if not self.running or (self.settled and self._drag is None):
            return shown
        return self.family.advance() or shown

    def single_step(self) -> None:
        """One step of the model even when paused."""
        running, self.running = self.running, True
        self.settled = False
        try:
            with self.options.one_step():
                self.advance()
        finally:
            self.running = running

    def reset_model(self) -> None:
        """Back to rest: elements released, wires straightened, lattice undeformed."""
        self.family.reset()
        self.sync_warps()

    # ------------------------------------------------------------------ overlay
    def overlay_layers(self, display: DisplayOptions | None = None) -> list[OverlayLayer]:
        """The handles, links, wires and cells to draw over the frame (world mm)."""
        disp = display or DisplayOptions()
        layers: list[OverlayLayer] = []
        lo, hi = self.box
        if disp.grid_box and self.family.has_grid:
            edges = self._grid_to_world(box_edges(lo, hi))
            layers.append(OverlayLayer("lines", edges, COLORS["box"], name="grid box"))
        if disp.clip_box and self.scene.clip_box is not None:
            c0, c1 = self.scene.clip_box
            layers.append(OverlayLayer("lines", box_edges(c0, c1), COLORS["box"], name="clip"))
        pts = self.handles()
        layers += self.family.overlay(pts, disp, self._grid_to_world)
        if disp.selection and self.selection and len(pts):
            layers += self._selection_layers(pts)
        return layers

    def _selection_layers(self, pts: np.ndarray) -> list[OverlayLayer]:
        sel = np.asarray([i for i in self.selection if i < len(pts)], dtype=int)
        layers = [OverlayLayer("points", pts[sel], COLORS["selected"], 10.0, "selected")]
        if self.reference is not None and self.reference < len(pts):
            ref = pts[[self.reference]]
            layers.append(OverlayLayer("points", ref, COLORS["reference"], 12.0, "ref"))
        return layers

    # ------------------------------------------------------------------ snapshots
    def snapshot(self) -> Snapshot:
        """The whole editable state, copied (model state incl. velocities, wires,
        lattice, placement, selection, settings)."""
        return Snapshot(
            kind=self.kind,
            backend=self.backend,
            resolution=self.resolution,
            placement=Placement(**self.placement.to_dict()),
            state=self.family.snapshot(),
            selection=tuple(self.selection),
            reference=self.reference,
            options=self.options.copy(),
            look=scene_look(self.scene),
            animation=self.animation.to_dict() if self.animation is not None else None,
            imported=tuple(self.imported_warps),
        )

    def restore(self, snap: Snapshot) -> None:
        """Return to a :meth:`snapshot` exactly (a wire field is rebuilt synchronously
        when its wires differ from the drawn field's)."""
        family = FAMILIES[snap.kind](self)
        family.adopt(self.family, snap)
        self._close_family()
        self.backend, self.resolution = snap.backend, snap.resolution
        self.options = snap.options.copy()
        self.placement = Placement(**snap.placement.to_dict())
        self.family = family
        family.restore(snap.state)
        self.selection, self.reference = list(snap.selection), snap.reference
        if snap.look:
            set_scene_look(self.scene, snap.look)
        self.animation = _animation_from(snap.animation)
        for w in self.imported_warps:
            if w not in snap.imported:
                self.release_warp(w)
        self.imported_warps = list(snap.imported)
        self.sync_warps()

    # ------------------------------------------------------------------ files
    def to_dict(self, base_dir: str | os.PathLike | None = None) -> dict[str, Any]:
        """Scene JSON plus an ``"editor"`` entry (deformation, placement, settings).

        The warps carry the models (mass-spring/ChainMail state, wires, lattice), so
        the file also renders with ``voxwarp render`` and resumes in the GUI. A stale
        wire field (edited, not rebuilt yet) is rebuilt first, so the file holds the
        wires as they are."""
        self.family.before_save()
        d = self.scene.to_dict(base_dir=base_dir)
        n = len(self.imported_warps)
        model_index = {0: None, 1: 0, 3: 1}[len(self.scene.warps) - n]
        d[EDITOR_KEY] = {
            "imported_warps": n,
            "imported_at": "end",
            "deformation": self.kind,
            "backend": self.backend,
            "resolution": list(self.resolution),
            "placement": self.placement.to_dict(),
            "model_warp": model_index,
            **self.options.to_entry(),
        }
        if self.animation is not None:
            d["animation"] = self.animation.to_dict()
        return d

    def save(self, path: str | os.PathLike) -> Path:
        """Write the session as scene JSON, atomically (a failed save keeps the old file)."""
        return write_scene_json(path, self.to_dict, indent=1)

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

    def _read_editor_entry(self, entry: dict[str, Any]) -> None:
        if entry.get("placement") is not None:
            self.placement = Placement.from_dict(entry["placement"])
        if entry.get("resolution") is not None:
            self.resolution = resolution(entry["resolution"])
        if entry:  # a scene without an editor entry keeps the defaults ("auto" margin)
            self.options.read_entry(entry)

    def _recover_from_scene(self, entry: dict[str, Any]) -> None:
        """Take over the deformation saved in the scene's warps (see :meth:`to_dict`),
        with the settings of the scene's editor ``entry``."""
        warps = list(self.scene.warps)
        try:
            self._read_editor_entry(entry)
            self.imported_warps, warps, entry = _split_imported(warps, entry)
            if warps:
                self.family = self._resume(warps, entry)
        except (WarpError, KeyError, TypeError, ValueError) as exc:
            if isinstance(exc, EditorError):
                raise
            raise EditorError(f"cannot resume the scene's deformation: {exc}") from exc
        self.sync_warps()

    def _resume(self, warps: list[Warp], entry: dict[str, Any]) -> Family:
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
        for cls in FAMILIES.values():
            family = cls.resume(self, w)
            if family is not None:
                return family
        raise EditorError(
            f"the scene's {w.kind!r} warp is not editable (the editor takes"
            " mass-spring, ChainMail, wire and lattice warps)"
        )

    def close(self) -> None:
        """Release the model (GPU resources: call with the context current) and stop
        the model worker."""
        self._close_family()
        if self.model_worker is not None:
            self.model_worker.close()
            self.model_worker = None
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
    "interactive_downsample",
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


def _split_imported(
    warps: list[Warp], entry: dict[str, Any]
) -> tuple[list[Warp], list[Warp], dict[str, Any]]:
    """A saved chain split into (imported warps, model warps, the editor entry with its
    ``"model_warp"`` index counted in the model warps). Files with ``"imported_at":
    "end"`` hold the imported warps last; older files hold them first, and the session
    then moves them after the model. Without an editor entry (``voxwarp render
    --save-scene``) the displacement fields at the front are imported, else those at the
    end (a correction saved by ``render --displacement F --chainmail ...``)."""
    n = _imported_count(warps, entry)
    if "imported_warps" not in entry and n == 0:
        n = _imported_count(warps[::-1], entry)
        return warps[len(warps) - n :], warps[: len(warps) - n], entry
    if entry.get("imported_at") == "end":
        return warps[len(warps) - n :], warps[: len(warps) - n], entry
    return warps[:n], warps[n:], _shift(entry, n)


def _imported_count(warps: list[Warp], entry: dict[str, Any]) -> int:
    """How many warps of a saved scene are imported (the editor entry's
    ``"imported_warps"``; without one, the leading displacement fields)."""
    if "imported_warps" in entry:
        n = int(entry["imported_warps"])
        if not 0 <= n <= len(warps):
            raise EditorError(f"imported_warps must be 0..{len(warps)}; got {n}")
        return n
    n = 0
    while n < len(warps) and isinstance(warps[n], DisplacementFieldWarp):
        n += 1
    return n


def _shift(entry: dict[str, Any], n: int) -> dict[str, Any]:
    """The editor entry with its ``"model_warp"`` index (into the scene's whole chain)
    counted after the ``n`` imported warps."""
    if entry.get("model_warp") is None or n == 0:
        return entry
    return {**entry, "model_warp": int(entry["model_warp"]) - n}


def _animation_from(d: Any) -> Any:
    """An :class:`~voxwarp.animation.tracks.Animation` from its dict (None stays None)."""
    if d is None:
        return None
    try:
        return Animation.from_dict(d)
    except AnimationError as exc:
        raise EditorError(f"invalid animation in the scene: {exc}") from exc


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


def _nearest_on_screen(
    camera: Camera,
    size: tuple[int, int],
    pixel: Sequence[float],
    radius: float,
    points: np.ndarray,
    tie: np.ndarray,
    allowed: np.ndarray,
) -> int | None:
    """Index of the allowed point whose projection lies nearest ``pixel`` within
    ``radius`` pixels (ties broken by the smaller ``tie``), or None."""
    if len(points) == 0:
        return None
    xy = camera.project(points, size)
    d = np.hypot(xy[:, 0] - pixel[0], xy[:, 1] - pixel[1])
    ok = (d <= radius) & allowed & np.isfinite(d)
    if not np.any(ok):
        return None
    return int(np.argmin(np.where(ok, d + 1e-6 * tie, np.inf)))
