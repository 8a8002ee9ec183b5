"""The offset-field families: a grid of elements run by a mass-spring model or by 3D
ChainMail (Knoche 2008). The handles are the elements; dragging one holds it at its
offset, the model moves the rest.

With the session's model worker (:meth:`EditSession.set_model_thread
<voxwarp.editing.session.EditSession.set_model_thread>`) a CPU model's moves and steps
run as worker jobs (:func:`stepped`): the worker never writes the warp the renderer
draws, it hands back copies of the positions and the field (:class:`SteppedState`),
which :meth:`ElementFamily.poll` writes into the warp on the GUI thread.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from voxwarp.core.modality_detection import detect_modality
from voxwarp.deform.elements.anchors import AnchorError
from voxwarp.deform.elements.chainmail import ChainMail, neighbour_pairs
from voxwarp.deform.elements.chainmail_model import ChainMailError
from voxwarp.deform.elements.grid import ElementGrid, ElementGridError
from voxwarp.deform.elements.massspring import MassSpring, MassSpringError
from voxwarp.deform.elements.materials import MaterialPresetError
from voxwarp.deform.elements.model import closed_on_error
from voxwarp.deform.elements.offset_field import OffsetFieldWarp
from voxwarp.deform.warp import Warp, WarpError
from voxwarp.editing.common import COLORS, DisplayOptions, EditorError
from voxwarp.editing.families.base import Family, ToWorld
from voxwarp.editing.keyframes import json_values, put_key, track
from voxwarp.editing.model_settings import (
    SETTLE_SPEED,
    BuildReport,
    Built,
    ChainMailSettings,
    ElementSettings,
    MassSpringSettings,
    SettingError,
    chainmail_at_rest,
    is_settled,
)
from voxwarp.editing.state import DragState, SessionHost
from voxwarp.render.overlay import OverlayLayer, grid_edges

if TYPE_CHECKING:
    from voxwarp.animation.tracks import Animation
    from voxwarp.editing.model_worker import ModelWorker


@dataclass(frozen=True)
class SteppedState:
    """A model's state after a worker job: copies of its ``(nx, ny, nz, 3)`` positions
    and displacements (mm), whether it came to rest (None: not checked) and the ms per
    model step (None: the job was a move)."""

    positions: np.ndarray
    displacements: np.ndarray
    settled: bool | None = None
    step_ms: float | None = None


def stepped(
    model: MassSpring | ChainMail,
    run: Callable[[], Any],
    steps: int = 0,
    at_rest: Callable[[np.ndarray], bool | None] | None = None,
) -> SteppedState:
    """Run ``run()`` (a move or ``steps`` steps of ``model``) with the model's warp left
    alone (another thread draws it), then ``at_rest(positions before)``; the state it
    left."""
    before = model.positions() if at_rest is not None else None
    model.defer_warp_updates = True
    try:
        t = time.perf_counter()
        run()
        ms = (time.perf_counter() - t) * 1000 / steps if steps else None
    finally:
        model.defer_warp_updates = False
    settled = at_rest(before) if at_rest is not None and before is not None else None
    return SteppedState(model.positions(), model.displacements(), settled, ms)


class ElementFamily(Family):
    """Shared by mass-spring and ChainMail: an element grid over the volume's box."""

    uses_backend = True
    has_grid = True
    handle_name = "elements"
    can_fix = True
    model_class: ClassVar[type[MassSpring] | type[ChainMail]]

    def __init__(self, session: SessionHost) -> None:
        super().__init__(session)
        self.model: MassSpring | ChainMail | None = None
        self._advances = 0
        #: the newest state a model worker handed back (None: read the model)
        self._shown: SteppedState | None = None

    # ---------------------------------------------------------------- life cycle
    def start(self) -> None:
        try:
            self.model = self._new_model()
        except (ValueError, WarpError) as exc:
            if isinstance(exc, EditorError):
                raise
            raise EditorError(str(exc)) from exc

    def continue_from(self, previous: Family) -> bool:
        """From the other element model on the same grid (mass-spring to ChainMail or
        back; Knoche 2008, §5): continue its deformation with ``from_model`` and say in
        :attr:`switch_note` how far that moved elements. False (a new model at rest)
        from any other family, the same model kind, or when the grid changed too."""
        old = previous.model if isinstance(previous, ElementFamily) else None
        if old is None or type(previous) is type(self):
            return False
        settings = self.settings()
        try:
            grid = self.grid(settings, self.session.volume)
            if not same_elements(grid, old.grid):
                self.switch_note = "the element grid changed: the new model starts at rest"
                return False
            previous._wait()
            kwargs = self.switch_settings(settings)
            model = self.model_class.from_model(
                old, backend=settings.backend, ctx=self._ctx(), grid=grid, **kwargs
            )
        except (ValueError, WarpError) as exc:
            self.switch_note = f"the deformation could not be kept ({exc}); starting at rest"
            return False
        with closed_on_error(model):
            model.warp(inverse=settings.inverse)
        self.model = model
        report = model.switch_report
        self.switch_note = f"{model.label}: {report.describe()}" if report is not None else ""
        return True

    def switch_settings(self, settings: Any) -> dict[str, Any]:
        """The model's constructor keywords in ``settings`` (:meth:`settings`), for
        :meth:`continue_from`."""
        raise NotImplementedError

    def _ctx(self) -> Any:
        return self.session.ctx if self.session.backend == "gpu" else None

    def _new_model(self) -> MassSpring | ChainMail:
        s = self.session
        return self.build(self.settings(), s.volume, self._ctx()).model

    def settings(self) -> ElementSettings:
        """The settings of a new model at rest from the session's."""
        raise NotImplementedError

    # ---------------------------------------------------------------- the builder
    @classmethod
    def grid(cls, settings: ElementSettings, volume: Any) -> ElementGrid:
        """The element grid of ``settings`` over ``volume``'s box padded by the settings'
        ``margin``, with its boundary conditions (``anchor``, ``fix_outside``), stiffness,
        fixed elements and materials set (no GL work); a :class:`SettingError` names a
        bad setting."""
        try:
            grid = ElementGrid(
                volume,
                settings.shape,
                margin=settings.margin,
                anchor=settings.grid_anchor(),
                fix_outside=settings.fix_outside,
            )
        except AnchorError as exc:
            raise SettingError("anchor", str(exc)) from exc
        except ElementGridError as exc:
            raise SettingError("margin", str(exc)) from exc
        if settings.stiffness is not None:
            grid.set_material(stiffness=settings.stiffness)
        for ranges in settings.fixed:
            mask = np.zeros(grid.shape, dtype=bool)
            mask[tuple(slice(lo, hi + 1) for lo, hi in ranges)] = True
            grid.fix(mask)
        if isinstance(settings.stiffness_from_volume, str):
            preset = material_preset(settings.stiffness_from_volume, volume)
            try:
                grid.materials_from_preset(volume, preset)
            except (ElementGridError, MaterialPresetError) as exc:
                raise SettingError("stiffness_from_volume", str(exc)) from exc
        elif settings.stiffness_from_volume:
            # the voxel centres span origin .. origin + spacing * (shape - 1)
            org = np.asarray(volume.origin, dtype=np.float64)
            n = np.maximum(np.asarray(volume.shape) - 1, 1)
            centres = (org, org + np.asarray(volume.spacing, dtype=np.float64) * n)
            try:
                grid.materials_from_volume(volume.data, centres, settings.stiffness_from_volume)
            except ElementGridError as exc:
                raise SettingError("stiffness_from_volume", str(exc)) from exc
        return grid

    @classmethod
    def build(cls, settings: ElementSettings, volume: Any, ctx: Any = None) -> Built:
        """The model of ``settings`` over ``volume``, dragged and run as they say, and
        its warp (``ctx``: the GL context of the GPU backend, current)."""
        return cls.build_on(settings, cls.grid(settings, volume), ctx)

    @classmethod
    def build_on(cls, settings: Any, grid: ElementGrid, ctx: Any = None) -> Built:
        """:meth:`build` on a grid from :meth:`grid` (the CLI checks it in between)."""
        raise NotImplementedError

    def _from_dict(self, model: dict[str, Any]) -> MassSpring | ChainMail:
        return self.model_class.from_dict(model, backend=self.session.backend, ctx=self._ctx())

    def close(self) -> None:
        self._wait()
        if self.model is not None:
            self.model.close()
        self.model = None

    # ---------------------------------------------------------------- the model worker
    def _worker(self) -> ModelWorker | None:
        """The session's model worker when it steps this model (a CPU one), else None."""
        w = self.session.model_worker
        return (
            w if w is not None and self.model is not None and self.model.backend == "cpu" else None
        )

    def _wait(self) -> None:
        """Before the GUI thread reads or changes the model itself: the worker's jobs
        done and shown."""
        if self._worker() is not None:
            self.session.wait_for_model()
        self._shown = None

    def _state(self) -> SteppedState:
        """The state shown: the worker's newest, or the model's (no job runs then)."""
        if self._shown is None:
            assert self.model is not None
            self._shown = SteppedState(self.model.positions(), self.model.displacements())
        return self._shown

    def _post(self, key: str, run: Callable[[], Any], steps: int = 0, check: bool = False) -> None:
        worker, model = self._worker(), self.model
        assert worker is not None
        assert model is not None
        self._state()  # what handles() shows until the job is done
        at_rest = (lambda before: self._at_rest_of(model, before)) if check else None
        worker.post(key, lambda: stepped(model, run, steps, at_rest))

    def poll(self) -> bool:
        worker = self._worker()
        state = worker.take() if worker is not None else None
        if state is None or self.model is None:
            return False
        self._shown = state
        self.model.show_field(state.displacements)
        s = self.session
        if state.step_ms is not None:
            s.timings["step"] = state.step_ms
        if state.settled is not None and s.drag_state is None:
            s.settled = state.settled
        s.handles_moved()
        return True

    @classmethod
    def resume(cls, session: SessionHost, warp: Warp) -> Family | None:
        state = getattr(warp, "model_state", None)
        if not isinstance(warp, OffsetFieldWarp) or state is None:
            return None
        if state.get("type") != cls.kind:
            return None
        family = cls(session)
        ctx = session.ctx if session.backend == "gpu" else None
        family.model = cls.model_class.from_warp(warp, backend=session.backend, ctx=ctx)
        session.resolution = family.model.grid.shape
        return family

    # ---------------------------------------------------------------- warp and handles
    def warp(self) -> Warp | None:
        return self.model.warp() if self.model is not None else None

    def handles(self) -> np.ndarray:
        if self.model is None:
            return np.zeros((0, 3))
        drag = self.session.drag_state
        if self.model.backend == "gpu" and drag is not None:
            # never read the GPU back while dragging: targets of the held elements
            return drag.positions.copy()
        if self._worker() is not None:
            pts = self._state().positions.reshape(-1, 3).copy()
            if drag is not None:  # the dragged elements follow the cursor at once
                sel = np.asarray(drag.selection, dtype=int)
                sel = sel[~self.model.grid.fixed.reshape(-1)[sel]]
                pts[sel] = drag.positions[sel]
            return pts
        with self.session.gl_scope():
            return self.model.positions().reshape(-1, 3)

    def fixed_handles(self, count: int) -> np.ndarray:
        if self.model is None:
            return super().fixed_handles(count)
        return self.model.grid.fixed.reshape(-1).copy()

    def anchored_handles(self, count: int) -> np.ndarray:
        if self.model is None:
            return super().anchored_handles(count)
        grid = self.model.grid
        return (grid.anchored & ~grid.fixed).reshape(-1)

    def set_fixed(self, indices: list[int], fixed: bool) -> None:
        if self.model is None:
            super().set_fixed(indices, fixed)
            return
        if not indices:
            raise EditorError("select elements first (click them, or Shift+drag a rectangle)")
        self._wait()
        ijk = np.array(np.unravel_index(np.asarray(indices, int), self.model.grid.shape)).T
        if fixed:
            self.model.fix(ijk)
        else:
            self.model.free(ijk)

    def begin_drag(self, drag: DragState) -> None:
        if self.model is None:
            return
        rest = self.model.grid.rest_positions.reshape(-1, 3)
        sel = np.asarray(drag.selection)
        drag.start_offsets = drag.positions[sel] - rest[sel]

    def drag(self, drag: DragState, selection: np.ndarray, delta: np.ndarray) -> None:
        if self.model is None or drag.start_offsets is None:
            return
        grid = self.model.grid
        ijk = np.array(np.unravel_index(selection, grid.shape)).T
        offsets = drag.start_offsets + delta
        if self._worker() is not None:  # the newest target wins
            model = self.model
            self._post("move", lambda: model.move(ijk, offsets))
        else:
            self.model.move(ijk, offsets)
        rest = grid.rest_positions.reshape(-1, 3)
        movable = ~grid.fixed.reshape(-1)[selection]
        drag.positions[selection[movable]] = rest[selection[movable]] + offsets[movable]

    # ---------------------------------------------------------------- running
    def _steps(self) -> int:
        """Model steps per frame."""
        raise NotImplementedError

    def _run(self, n: int) -> None:
        raise NotImplementedError

    def _at_rest(self, before: np.ndarray | None) -> bool | None:
        """Whether the model came to rest (None: cannot tell)."""
        raise NotImplementedError

    def _check_rest_now(self) -> bool:
        gpu = self.model is not None and self.model.backend == "gpu"
        return not gpu or (self.session.drag_state is None and self._advances % 30 == 0)

    def advance(self) -> bool:
        s, model = self.session, self.model
        n = self._steps()
        if model is None or n <= 0 or not self._may_run_now():
            return False
        worker = self._worker()
        if worker is not None:  # shown by poll() when done
            if not worker.pending("advance"):
                self._post("advance", lambda: self._run(n), n, check=s.drag_state is None)
            return False
        self._advances += 1
        check = self._check_rest_now()
        before = self._positions_before(check)
        t = time.perf_counter()
        self._run(n)
        s.timings["step"] = (time.perf_counter() - t) * 1000 / n
        if check and s.drag_state is None:
            # at rest: stop stepping (the field, and so the picture, holds still, and the
            # renderer can build its skip maps) until the next edit
            rest = self._at_rest(before)
            if rest is not None:
                s.settled = rest
        s.handles_moved(throttle=model.backend == "gpu")
        return True

    def _may_run_now(self) -> bool:
        return True

    def _positions_before(self, check: bool) -> np.ndarray | None:
        return None

    def _at_rest_of(self, model: Any, before: np.ndarray | None) -> bool | None:
        """:meth:`_at_rest` of ``model`` (a worker job's check)."""
        return self._at_rest(before) if model is self.model else None

    def reset(self) -> None:
        self._wait()
        if self.model is not None:
            self.model.reset()

    # ---------------------------------------------------------------- drawing
    def overlay(
        self, handles: np.ndarray, display: DisplayOptions, to_world: ToWorld
    ) -> list[OverlayLayer]:
        if self.model is None:
            return []
        layers = []
        if display.links:
            edges = grid_edges(handles.reshape(*self.model.grid.shape, 3))
            present = self._present_links()
            if present is not None:  # cut links are not drawn
                edges = edges.reshape(-1, 2, 3)[present].reshape(-1, 3)
            layers.append(OverlayLayer("lines", edges, COLORS["link"], name="links"))
        fixed = self.fixed_handles(len(handles))
        anchored = self.anchored_handles(len(handles))
        if display.elements:
            free = ~(fixed | anchored)
            layers.append(
                OverlayLayer("points", handles[free], COLORS["element"], 5.0, name="elements")
            )
        if display.fixed and np.any(fixed):
            layers.append(OverlayLayer("points", handles[fixed], COLORS["fixed"], 7.0, "fixed"))
        if display.fixed and np.any(anchored):
            layers.append(
                OverlayLayer("points", handles[anchored], COLORS["anchored"], 6.0, "anchored")
            )
        return layers

    def _present_links(self) -> np.ndarray | None:
        """(E,) bool in :func:`grid_edges`' order: which links exist (None: all)."""
        return None

    def boundary_text(self) -> str:
        """The boundary conditions of the model and its grid margin in one line (the
        panel shows it)."""
        if self.model is None:
            return ""
        grid = self.model.grid
        count = int(grid.anchored.sum())
        anchored = f"; {count} anchored now" if count else ""
        return f"{grid.describe_anchors()}{anchored}; {margin_phrase(grid.margin)}"

    # ---------------------------------------------------------------- undo and animation
    def before_save(self) -> None:
        self._wait()

    def snapshot(self) -> dict[str, Any]:
        self._wait()
        if self.model is None:
            return {}
        return {"model": self.model.to_dict(), "positions": self.model.positions()}

    def restore(self, state: dict[str, Any]) -> None:
        if "model" in state:
            self.model = self._from_dict(state["model"])

    def set_keys(self, animation: Animation, frame: int, interpolation: str) -> None:
        """The ``elements.drag`` key: held elements and offsets; others where they are."""
        self._wait()
        if self.model is None:
            return
        held = {tuple(h["index"]): h["offset"] for h in self.model.to_dict().get("held", [])}
        t = track(animation, "elements.drag", interpolation)
        old = [tuple(e) for e in (t.elements or [])]
        elements = old + [e for e in held if e not in old]
        if not elements:
            return
        disp = self.model.displacements()
        extra = len(elements) - len(old)
        if extra:  # elements held for the first time: earlier keys hold them at rest
            t.keys = [
                (f, None if v is None else _per_element(v, len(old)) + [[0.0, 0.0, 0.0]] * extra)
                for f, v in t.keys
            ]
        t.elements = [list(e) for e in elements]
        put_key(t, frame, [json_values(held[e] if e in held else disp[e]) for e in elements])


def same_elements(a: ElementGrid, b: ElementGrid) -> bool:
    """Whether two grids have the same elements (shape and rest positions)."""
    tol = 1e-9 * float(np.max(b.spacing))
    return a.shape == b.shape and np.allclose(a.rest_positions, b.rest_positions, rtol=0, atol=tol)


def _per_element(value: Any, count: int) -> list[list[float]]:
    """A drag key value (one offset or one per element) as ``count`` offsets."""
    return np.broadcast_to(np.asarray(value, dtype=np.float64), (count, 3)).tolist()


def margin_phrase(margin: float) -> str:
    """The grid margin in mm in use, in a few words (the boundary line ends with it)."""
    if margin <= 0.0:
        return "grid margin 0 mm (the volume's box)"
    return f"grid margin {margin:.1f} mm beyond the volume's box"


class MassSpringFamily(ElementFamily):
    """Elements joined by springs, integrated in time (``steps_per_frame`` per frame)."""

    kind = "massspring"
    model_class = MassSpring

    def settings(self) -> MassSpringSettings:
        s = self.session
        return MassSpringSettings(
            shape=s.resolution,
            backend=s.backend,
            stiffness=s.options.stiffness,
            anchor=s.options.anchor,
            fix_outside=s.options.fix_outside,
            integrator=s.options.integrator,
            margin=s.options.margin,
        )

    @classmethod
    def build_on(cls, settings: MassSpringSettings, grid: ElementGrid, ctx: Any = None) -> Built:
        """Drags, then ``settings.run``: fixed steps or until :func:`is_settled`."""
        try:
            ms = MassSpring(
                grid,
                backend=settings.backend,
                ctx=ctx if settings.backend == "gpu" else None,
                integrator=settings.integrator,
                shear=settings.shear,
                bend=settings.bend,
            )
        except MassSpringError as exc:
            raise SettingError("model", str(exc)) from exc
        report = BuildReport(settling=settings.run.settle)
        try:
            for d in settings.drags:
                ms.move(d.selection, d.offset)
            limit = settings.run.limit
            if settings.run.settle:
                report.steps = ms.settle(max_steps=limit, tol=SETTLE_SPEED)
                report.hit_limit = report.steps >= limit and limit > 0
            elif limit:
                ms.step(limit)
                report.steps = limit
            warp = ms.warp(inverse=settings.inverse)
        except BaseException:
            ms.close()
            raise
        return Built(ms, warp, report)

    def switch_settings(self, settings: MassSpringSettings) -> dict[str, Any]:
        s = settings
        return {"integrator": s.integrator, "shear": s.shear, "bend": s.bend}

    def _steps(self) -> int:
        return self.session.options.steps_per_frame

    def _run(self, n: int) -> None:
        assert isinstance(self.model, MassSpring)
        self.model.step(n)

    def _at_rest(self, before: np.ndarray | None) -> bool | None:
        assert isinstance(self.model, MassSpring)
        return is_settled(self.model)

    def snapshot(self) -> dict[str, Any]:
        state = super().snapshot()
        if isinstance(self.model, MassSpring):
            state["velocities"] = self.model.velocities()
        return state

    def restore(self, state: dict[str, Any]) -> None:
        super().restore(state)
        if isinstance(self.model, MassSpring):
            self.model.set_state(state["positions"], state["velocities"])


class ChainMailFamily(ElementFamily):
    """Elements joined by ChainMail links; ``relax_steps`` relaxation steps per frame
    (on the CPU: a GPU model relaxes between drags, never inside one)."""

    kind = "chainmail"
    model_class = ChainMail
    can_cut = True

    def settings(self) -> ChainMailSettings:
        s = self.session
        # relaxation runs on the CPU (a GPU model is read back for it): a GPU model relaxes
        # in advance() between drags, never inside a move
        return ChainMailSettings(
            shape=s.resolution,
            backend=s.backend,
            stiffness=s.options.stiffness,
            anchor=s.options.anchor,
            fix_outside=s.options.fix_outside,
            variant=s.options.variant,
            relax_steps=s.options.relax_steps if s.backend == "cpu" else 0,
            margin=s.options.margin,
        )

    @classmethod
    def build_on(cls, settings: ChainMailSettings, grid: ElementGrid, ctx: Any = None) -> Built:
        """Cuts first (through the rest state), then the joins (cut links linked again),
        then every drag at once (one move), then ``settings.relax`` relaxation steps."""
        try:
            cm = ChainMail(
                grid,
                variant=settings.variant,
                backend=settings.backend,
                ctx=ctx if settings.backend == "gpu" else None,
            )
        except ChainMailError as exc:
            raise SettingError("model", str(exc)) from exc
        report = BuildReport()
        try:
            report.cut = sum(cm.cut(c.point, c.normal, c.radius) for c in settings.cuts)
            report.joined = sum(cm.link(c.point, c.normal, c.radius) for c in settings.joins)
            if settings.warm_up and settings.backend == "cpu":  # no element: loads kernels
                cm.move(np.zeros(grid.shape, dtype=bool), (0.0, 0.0, 0.0))
            if settings.drags:
                stats = cm.move(
                    [d.selection for d in settings.drags], [d.offset for d in settings.drags]
                )
                report.touched, report.solve_ms = stats.touched, stats.seconds * 1000
                if stats.limited:
                    report.limited_fraction = stats.fraction
            t = time.perf_counter()
            cm.relax(settings.relax)
            report.relax_ms = (time.perf_counter() - t) * 1000
            # saved with the model: a resumed one relaxes alike
            steps = settings.relax_steps
            cm.relax_steps = settings.relax if steps is None else steps
            warp = cm.warp(inverse=settings.inverse)
            if settings.drags or settings.cuts or settings.relax:
                report.displaced = int(np.count_nonzero(np.any(cm.displacements() != 0.0, -1)))
        except BaseException:
            cm.close()
            raise
        return Built(cm, warp, report)

    def _from_dict(self, model: dict[str, Any]) -> ChainMail:
        restored = super()._from_dict(model)
        assert isinstance(restored, ChainMail)
        if self.session.backend == "gpu":
            restored.relax_steps = 0  # see settings()
        return restored

    def switch_settings(self, settings: ChainMailSettings) -> dict[str, Any]:
        return {"variant": settings.variant, "relax_steps": settings.relax_steps or 0}

    def _steps(self) -> int:
        return self.session.options.relax_steps

    def _may_run_now(self) -> bool:
        # a GPU model's relaxation reads it back: not during a drag
        gpu = self.model is not None and self.model.backend == "gpu"
        return not (gpu and self.session.drag_state is not None)

    def _positions_before(self, check: bool) -> np.ndarray | None:
        return self.model.positions() if check and self.model is not None else None

    def _run(self, n: int) -> None:
        assert isinstance(self.model, ChainMail)
        self.model.relax(n)

    def _at_rest(self, before: np.ndarray | None) -> bool | None:
        if before is None or self.model is None:
            return None
        return chainmail_at_rest(before, self.model.positions())

    # ---------------------------------------------------------------- cutting and joining
    def cut_links(self, indices: list[int]) -> int:
        """Cut the links around the selected elements (one end selected, the other not):
        the selection comes loose from its surroundings."""
        cm = self._chainmail(indices)
        n = cm.cut_pairs(neighbour_pairs(self._mask(indices)))
        if n == 0:
            raise EditorError(
                "the selected elements have no links left to unselected ones: nothing to"
                " cut (select the region to set loose, not the whole grid)"
            )
        return n

    def join_links(self, indices: list[int], pull: bool = False) -> tuple[int, int]:
        """Join the cut links with a selected end whose elements touch (within the
        link's limits, :meth:`ChainMail.link_pairs` with ``stretched="skip"``), or with
        ``pull`` all of them, dragging free elements until the sides meet
        (``stretched="pull"``); returns (joined, left cut: elements too far apart)."""
        cm = self._chainmail(indices)
        pairs = neighbour_pairs(self._mask(indices), boundary=False)
        low, axis = pairs[:, 0], np.argmax(pairs[:, 1] - pairs[:, 0], axis=1)
        cut = int(np.count_nonzero(~cm.model.links[low[:, 0], low[:, 1], low[:, 2], axis]))
        if cut == 0:
            raise EditorError("no cut links at the selected elements: nothing to join")
        n = cm.link_pairs(pairs, stretched="pull" if pull else "skip")
        if n == 0:
            raise EditorError(
                f"the {cut} cut link(s) at the selected elements are stretched beyond their"
                " limits: drag the two sides together first, or join pulling them"
            )
        return n, cut - n

    def _chainmail(self, indices: list[int]) -> ChainMail:
        if not indices:
            raise EditorError("select elements first (click them, or Shift+drag a rectangle)")
        self._wait()
        assert isinstance(self.model, ChainMail)
        return self.model

    def _mask(self, indices: list[int]) -> np.ndarray:
        assert self.model is not None
        mask = np.zeros(self.model.grid.count, dtype=bool)
        mask[np.asarray(indices, dtype=np.int64)] = True
        return mask.reshape(self.model.grid.shape)

    def _present_links(self) -> np.ndarray | None:
        if not isinstance(self.model, ChainMail):
            return None
        links = self.model.model.links
        parts = []
        for axis in range(3):
            idx: list[Any] = [slice(None)] * 3
            idx[axis] = slice(0, -1)
            parts.append(links[(*idx, axis)].reshape(-1))
        return np.concatenate(parts)

    def option_changed(self, name: str, value: Any) -> None:
        if name == "relax_steps" and isinstance(self.model, ChainMail):
            self.model.relax_steps = value if self.model.backend == "cpu" else 0

    def restore(self, state: dict[str, Any]) -> None:
        super().restore(state)
        if isinstance(self.model, ChainMail):
            self.model.set_state(state["positions"])


def material_preset(name: str, volume: Any) -> str:
    """The tissue preset ``name`` (``"ct"``, ``"mr"`` or ``"auto"``) for ``volume``:
    ``"auto"`` is ``"ct"`` for a CT in Hounsfield units, else ``"mr"`` (relative to the
    volume's histogram, which also suits other data without absolute units)."""
    if name != "auto":
        return name
    return "ct" if detect_modality(volume).kind == "CT" else "mr"
