"""The wire family (Singh and Fiume's wires, as a sweep-based attribute field): curves
laid through the object; the handles are the control points of the *modified* wires
(the base wires stay where they were laid). Editing one makes the attribute field
stale: :meth:`WiresFamily.build_job` hands out a :class:`WireBuild` that can run off
the GUI thread, and its result is installed only if nothing changed meanwhile."""

from __future__ import annotations

import itertools
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, Literal

import numpy as np

from voxwarp.core.camera import Camera
from voxwarp.deform.warp import Warp, WarpError
from voxwarp.deform.wires.field import (
    DEFAULT_ENDS,
    DEFAULT_SIDES,
    ENDS,
    SIDES,
    VACATED,
    Wire,
    WireDeformer,
    WireFieldWarp,
)
from voxwarp.editing.common import COLORS, WIRE_KINDS, DisplayOptions, EditorError, choice
from voxwarp.editing.families.base import Family, ToWorld
from voxwarp.editing.keyframes import json_values, put_key, track
from voxwarp.editing.model_settings import BuildReport, Built, WireSettings
from voxwarp.editing.state import DragState, SessionHost, Snapshot
from voxwarp.render.overlay import OverlayLayer, polyline_segments

if TYPE_CHECKING:
    from voxwarp.animation.tracks import Animation

#: how the field may be built (``FamilyOptions.wire_settings``)
WIRE_SETTINGS = ("field_scale", "layout", "masks")
#: wire generations: unique over every adapter, so that a build of one adapter's wires
#: is never taken for another's (undo makes a new adapter)
_GENERATIONS = itertools.count(1)


@dataclass
class WireBuild:
    """A rebuild of the wire field, to run off the GUI thread.

    :meth:`run` builds a new attribute field from a copy of the wires (nothing shared
    with the field being drawn); :meth:`WiresFamily.install` puts it in the
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
    #: what is being built, for a progress bar (:class:`~voxwarp.editing.state.BuildJob`)
    label: ClassVar[str] = "wire field"

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
        if progress:
            progress(0.2, "propagating the attribute field")
        built = WiresFamily.build(WireSettings.of(self.wires, **self.settings), self.volume)
        if self.cancelled:
            return None
        self.warp = built.warp
        self.seconds = time.perf_counter() - t0
        if progress:
            progress(1.0, "done")
        return self.warp


class WiresFamily(Family):
    """Wires and their attribute field (see the module docstring)."""

    kind = "wires"
    has_grid = True
    handle_name = "wire points"

    def __init__(self, session: SessionHost) -> None:
        super().__init__(session)
        self._wires: list[Wire] = []
        #: changes with every edit of the wires or their settings (a field is of the
        #: generation it was built from; see :attr:`field_stale`)
        self.generation = 0
        #: control points of the wire being laid (:meth:`add_wire_point`), grid frame
        self.pending_wire: list[np.ndarray] = []
        #: the field drawn, and the wire generation it was built from
        self.field: WireFieldWarp | None = None
        self.built = -1
        #: a kept field that restore() installs (see adopt)
        self._kept: WireFieldWarp | None = None
        self._drawn: WireFieldWarp | None = None

    @property
    def wires(self) -> list[Wire]:
        return self._wires

    @wires.setter
    def wires(self, value: list[Wire]) -> None:
        self._wires = list(value)

    # ---------------------------------------------------------------- the builder
    @classmethod
    def build(cls, settings: WireSettings, volume: Any, ctx: Any = None) -> Built:
        """The wire field of ``settings`` on ``volume``, built (no model: ``model`` is
        None); a :class:`~voxwarp.deform.warp.WarpError` names a bad entry."""
        WireFieldWarp.from_dict(settings.entry)  # checks every key and wire first
        spec = {k: v for k, v in settings.entry.items() if k != "type"}
        wires = [Wire.from_dict(w) for w in spec.pop("wires")]
        deformer = WireDeformer(volume, wires, **spec)
        deformer.build()
        return Built(None, deformer.warp(), BuildReport())

    # ---------------------------------------------------------------- life cycle
    def start(self) -> None:
        self._wires = [self._default_wire()]
        self.changed()
        self.refresh_field()

    def _default_wire(self) -> Wire:
        lo, hi = self.session.box
        c = 0.5 * (lo + hi)
        axis = int(np.argmax(hi - lo))
        pts = np.repeat(c[None], 4, axis=0)
        pts[:, axis] = lo[axis] + (hi[axis] - lo[axis]) * np.array([0.1, 0.37, 0.63, 0.9])
        others = [a for a in range(3) if a != axis]
        radius = 0.3 * float(min(hi[others[0]] - lo[others[0]], hi[others[1]] - lo[others[1]]))
        return Wire(pts, pts.copy(), radius=radius, name="wire 1")

    def close(self) -> None:
        self.release(self.field)
        self.field = None
        self._wires = []

    @classmethod
    def resume(cls, session: SessionHost, warp: Warp) -> Family | None:
        if not isinstance(warp, WireFieldWarp):
            return None
        family = cls(session)
        family._wires = list(warp.wires)
        family.field = warp
        family.built = family.generation
        spec = warp.to_dict()
        settings = {k: spec[k] for k in WIRE_SETTINGS if k in spec}
        session.options.wire_settings = settings or session.options.wire_settings
        return family

    # ---------------------------------------------------------------- the field
    def changed(self) -> None:
        """The wires or their settings changed: the field is stale from now on."""
        self.generation = next(_GENERATIONS)

    @property
    def field_stale(self) -> bool:
        return self.field is None or self.built != self.generation

    def warp(self) -> Warp | None:
        return self.field

    def build_job(self) -> WireBuild:
        """A job rebuilding the field of the current wires (run it on any thread)."""
        s = self.session
        wires = [Wire.from_dict(w.to_dict()) for w in self._wires]
        return WireBuild(self.generation, s.volume, wires, dict(s.options.wire_settings))

    def _install(self, warp: WireFieldWarp, generation: int) -> None:
        if self.field is not None and self.field is not warp:
            self.release(self.field)
        self.field = warp
        self.built = generation

    def build_now(self) -> None:
        """Rebuild the field of the current wires on this thread and draw it."""
        job = self.build_job()
        warp = job.run()
        assert warp is not None
        self.session.timings["field"] = job.seconds * 1000
        self._install(warp, job.generation)

    def refresh_field(self) -> None:
        """After a change of the wires: rebuild the field now (the session's
        ``sync_builds``) or leave it stale for an off-thread :meth:`build_job` (the GUI)."""
        if self.session.sync_builds:
            self.build_now()

    def install(self, job: Any) -> bool:
        """Put a finished :class:`WireBuild` in the scene (GUI thread). Returns False
        when it was cancelled (dropped) or when the wires changed while it ran (then it
        is drawn meanwhile, and the field stays stale for the next build)."""
        if not isinstance(job, WireBuild) or job.warp is None or job.cancelled:
            return False
        self._install(job.warp, job.generation)
        self.session.timings["field"] = job.seconds * 1000
        self.session.sync_warps()
        return job.generation == self.generation

    def before_save(self) -> None:
        self.rebuild_if_stale()

    def rebuild_if_stale(self) -> None:
        """Rebuild a stale field on this thread and draw it (saving, scripts)."""
        if self.field_stale:
            self.build_now()
            self.session.sync_warps()

    # ---------------------------------------------------------------- handles
    def handles(self) -> np.ndarray:
        if not self._wires:
            return np.zeros((0, 3))
        return np.concatenate([w.modified.control_points for w in self._wires])

    def point(self, handle: int) -> tuple[int, int]:
        """Handle index -> (wire, control point)."""
        index = handle
        for w, wire in enumerate(self._wires):
            n = len(wire.modified.control_points)
            if index < n:
                return w, index
            index -= n
        raise EditorError(f"handle {handle} is not a wire control point")

    def drag(self, drag: DragState, selection: np.ndarray, delta: np.ndarray) -> None:
        start = drag.positions
        for h in selection:
            w, k = self.point(int(h))
            pts = self._wires[w].modified.control_points.copy()
            pts[k] = start[h] + delta
            self._wires[w] = with_modified(self._wires[w], pts)
        self.changed()

    def reset(self) -> None:
        self._wires = [with_modified(w, w.base.control_points) for w in self._wires]
        self.changed()
        self.refresh_field()

    # ---------------------------------------------------------------- editing the wires
    def wire(self, index: int) -> Wire:
        """Wire ``index`` (an :class:`EditorError` when there is none)."""
        if not 0 <= index < len(self._wires):
            raise EditorError(f"no wire {index}: there are {len(self._wires)} wires")
        return self._wires[index]

    def _edited(self) -> None:
        self.changed()
        self.session.edited()

    def set_wire_points(self, wire: int, points: np.ndarray) -> None:
        """Move the modified control points of wire ``wire``; its attribute field is then
        stale (rebuild it with :meth:`build_job` and :meth:`install`)."""
        self._wires[wire] = with_modified(self.wire(wire), points)
        self._edited()

    def set_wire_parameters(
        self,
        wire: int,
        *,
        kind: str | None = None,
        radius: float | None = None,
        beta: tuple[float, float] | Literal["keep"] | None = "keep",
        ends: str | None = None,
        sides: str | None = None,
        side_falloff: float | Literal["keep"] | None = "keep",
        vacated: str | None = None,
    ) -> None:
        """Change a wire's curve kind, influence radius (mm), β (value range or None),
        ends (``"smooth"``/``"rigid"``), sides (``"smooth"``/``"rigid"``), side falloff
        (mm, or None for the default) or what a rigid sweep's vacated place shows
        (``"empty"``/``"rest"``), see :class:`voxwarp.deform.wires.field.Wire`; the
        field is then stale (rebuild it with :meth:`build_job`)."""
        w = self.wire(wire)
        d = w.to_dict()
        if ends is not None:
            d["ends"] = choice(ends, ENDS, "wire ends")
        if sides is not None:
            d["sides"] = choice(sides, SIDES, "wire sides")
        if side_falloff != "keep":
            d.pop("side_falloff", None)
            if side_falloff is not None:
                d["side_falloff"] = float(side_falloff)
        if vacated is not None:
            d["vacated"] = choice(vacated, VACATED, "wire vacated")
        if kind is not None:
            kind = choice(kind, WIRE_KINDS, "wire kind")
            if kind != w.kind:
                d["base"] = _resampled(w.base.control_points, kind)
                d["modified"] = _resampled(w.modified.control_points, kind)
                d["kind"] = kind
        if radius is not None:
            d["radius"] = radius
        if beta != "keep":
            d["beta"] = None if beta is None else [float(beta[0]), float(beta[1])]
        self._wires[wire] = wire_from(d)
        self._edited()

    def set_wire_settings(self, **settings: Any) -> None:
        """Change how the wire field is built: ``field_scale`` (1, 2, 4, 8 or 16),
        ``layout`` (``"float"``/``"packed"``/``"paper"``), ``masks`` (bool); the field is
        then stale."""
        allowed = set(WIRE_SETTINGS)
        unknown = set(settings) - allowed
        if unknown:
            raise EditorError(
                f"unknown wire settings {sorted(unknown)}; allowed: {sorted(allowed)}"
            )
        if "field_scale" in settings and settings["field_scale"] not in (1, 2, 4, 8, 16):
            raise EditorError(
                f"field_scale must be 1, 2, 4, 8 or 16; got {settings['field_scale']!r}"
            )
        if "layout" in settings and settings["layout"] not in ("float", "packed", "paper"):
            raise EditorError(
                f"layout must be 'float', 'packed' or 'paper'; got {settings['layout']!r}"
            )
        if "masks" in settings and not isinstance(settings["masks"], bool):
            raise EditorError(f"masks must be true or false; got {settings['masks']!r}")
        self.session.options.wire_settings.update(settings)
        self._edited()

    def set_wire_key(
        self, handle: int | None, *, twist: float | None = None, scale: float | None = None
    ) -> None:
        """Set the twist (radians) or scale at the control point of ``handle``: a key
        at that point's fraction of the wire's length (replacing a key there)."""
        if handle is None:
            raise EditorError("select a control point of a wire first (click it)")
        w, k = self.point(int(handle))
        wire = self._wires[w]
        t = _length_fraction(wire.modified, k)
        d = wire.to_dict()
        for name, value in (("twist", twist), ("scale", scale)):
            if value is None:
                continue
            keys = [tuple(x) for x in (d.get(name) or []) if abs(float(x[0]) - t) > 1e-6]
            keys.append((t, float(value)))
            d[name] = sorted(keys)
        self._wires[w] = wire_from(d)
        self._edited()

    def add_wire_point(self, camera: Camera, size: tuple[int, int], pixel: Sequence[float]) -> None:
        """Lay a control point of a new wire where the cursor meets the plane parallel
        to the image through the volume's centre (the slice plane of the view)."""
        lo, hi = self.session.box
        p = camera.point_on_view_plane(pixel, size, 0.5 * (lo + hi))
        m = np.linalg.inv(self.session.placement_matrix)
        self.pending_wire.append(p @ m[:3, :3].T + m[:3, 3])

    # ---------------------------------------------------------------- placing (new wires)
    def start_placing(self) -> None:
        """The next clicks lay control points of a new wire (:meth:`add_wire_point`)."""
        self.placing = True

    def place_point(self, camera: Camera, size: tuple[int, int], pixel: Sequence[float]) -> None:
        """:meth:`add_wire_point`."""
        self.add_wire_point(camera, size, pixel)

    def finish_placing(self, **options: Any) -> int:
        """Stop laying and make the laid points a wire (:meth:`finish_wire`; ``options``:
        its ``kind`` and ``radius``)."""
        self.placing = False
        return self.finish_wire(**options)

    def cancel_placing(self) -> None:
        """Stop laying and drop the laid points."""
        self.placing = False
        self.pending_wire = []

    def finish_wire(self, kind: str = "catmull-rom", radius: float | None = None) -> int:
        """Make the laid points a wire (base = modified; then bend it by dragging).
        Returns its index. Needs 2+ points (Bézier: 3k + 1, extra points are dropped)."""
        kind = choice(kind, WIRE_KINDS, "wire kind")
        pts = np.asarray(self.pending_wire, dtype=np.float64).reshape(-1, 3)
        if kind == "bezier":
            pts = pts[: 3 * ((len(pts) - 1) // 3) + 1]
        if len(pts) < (4 if kind == "bezier" else 2):
            raise EditorError(
                f"a {kind} wire needs at least {4 if kind == 'bezier' else 2} control points;"
                f" {len(self.pending_wire)} laid: click more points first"
            )
        if radius is None:
            extent = float(np.max(np.ptp(self.session.box, 0)))
            radius = self._wires[-1].radius if self._wires else 0.1 * extent
        wire = wire_from(
            {
                "base": pts.tolist(),
                "modified": pts.tolist(),
                "kind": kind,
                "radius": radius,
                "ends": self._wires[-1].ends if self._wires else DEFAULT_ENDS,
                "sides": self._wires[-1].sides if self._wires else DEFAULT_SIDES,
                "name": f"wire {len(self._wires) + 1}",
            }
        )
        self._wires.append(wire)
        self.pending_wire = []
        self._edited()
        return len(self._wires) - 1

    def remove_wire(self, wire: int) -> None:
        """Delete a wire (the last one cannot go: switch the deformation off instead)."""
        self.wire(wire)
        if len(self._wires) == 1:
            raise EditorError("a wire field needs a wire: choose deformation 'none' instead")
        del self._wires[wire]
        self.changed()
        self.session.select([], "replace")
        self.session.edited()

    # ---------------------------------------------------------------- drawing
    def overlay(
        self, handles: np.ndarray, display: DisplayOptions, to_world: ToWorld
    ) -> list[OverlayLayer]:
        layers = []
        t = np.linspace(0.0, 1.0, 96)
        for wire in self._wires:
            if display.wires_base:
                seg = polyline_segments(to_world(wire.base.evaluate(t)))
                layers.append(OverlayLayer("lines", seg, COLORS["wire_base"], name="base"))
            if display.wires_modified:
                seg = polyline_segments(to_world(wire.modified.evaluate(t)))
                layers.append(OverlayLayer("lines", seg, COLORS["wire_modified"], name="wire"))
        if display.wires_modified and len(handles):
            layers.append(OverlayLayer("points", handles, COLORS["wire_modified"], 8.0, "points"))
        if self.pending_wire:
            p = to_world(np.asarray(self.pending_wire))
            layers.append(OverlayLayer("points", p, COLORS["pending"], 8.0, "new wire"))
            if len(p) > 1:
                layers.append(OverlayLayer("lines", polyline_segments(p), COLORS["pending"]))
        return layers

    # ---------------------------------------------------------------- undo and animation
    def snapshot(self) -> dict[str, Any]:
        return {"wires": [w.to_dict() for w in self._wires]}

    def adopt(self, previous: Family, snap: Snapshot) -> None:
        """Keep the field drawn by ``previous`` (a wire family): as it is when ``snap``
        has the same wires and settings and the field is up to date, else drawn until
        the rebuilt one replaces it; keep laying a new wire if ``previous`` was."""
        if not isinstance(previous, WiresFamily):
            return
        self.placing = previous.placing  # undo keeps laying a new wire (not its points)
        same = (
            snap.state.get("wires") == [w.to_dict() for w in previous.wires]
            and snap.options.wire_settings == self.session.options.wire_settings
        )
        if same and not previous.field_stale:
            self._kept = previous.field
        else:
            self._drawn = previous.field
        previous.field = None  # not released by previous.close()

    def restore(self, state: dict[str, Any]) -> None:
        self._wires = [Wire.from_dict(w) for w in state.get("wires", [])]
        self.changed()
        if self._kept is not None:
            self.field, self.built = self._kept, self.generation
        else:
            self.field = self._drawn  # drawn until the rebuilt field replaces it
            self.refresh_field()
        self._kept = self._drawn = None

    def set_keys(self, animation: Animation, frame: int, interpolation: str) -> None:
        for i, wire in enumerate(self._wires):
            value = json_values(wire.modified.control_points)
            put_key(track(animation, f"wires[{i}].modified", interpolation), frame, value)


# ---------------------------------------------------------------------------- helpers
def with_modified(wire: Wire, points: np.ndarray) -> Wire:
    """``wire`` with its modified curve through ``points``."""
    d = wire.to_dict()
    d["modified"] = np.asarray(points, dtype=np.float64).tolist()
    return Wire.from_dict(d)


def wire_from(d: dict[str, Any]) -> Wire:
    """A wire from its dict; an :class:`EditorError` naming what is wrong."""
    try:
        return Wire.from_dict(d)
    except (WarpError, TypeError, ValueError) as exc:
        raise EditorError(str(exc)) from exc


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
