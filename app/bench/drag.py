"""The scripted drag of ``voxwarp bench interactive --drag``: frames per second while an
element is dragged, as the desktop window draws them, and the time from the release to
the full-quality frame; the model stepped on the GUI thread (``sync``, the old path,
``VOXWARP_MODEL_THREAD=0`` in the GUI) and on the model worker (``thread``, the GUI's
default) in the same run.

The loop is the GUI thread's at the default window (1280x820, the four-up layout: a
3D view of :data:`DRAG_SIZE` and three slice views of the same size). Each frame the
cursor moves along a straight line (the grid's middle element dragged by a quarter of
the view's height over :data:`DRAG_FRAMES` frames), the session drags
(``drag_to``; ``sync`` moves the model here, ``thread`` posts the move), the simulation
timer's ``advance`` runs (``sync``: the steps; ``thread``: shows the worker's newest
state and posts the next steps), the handles' overlay is computed, the 3D view is drawn
at the level :class:`~voxwarp.render.adaptive_quality.AdaptiveQuality` chose from the
frame before (deformed-space skip maps off, as while the warp changes) and the three
slice views at :data:`LIVE_SCALE` of their resolution, as the GUI's slices follow a
drag; the controller is fed the time of the 3D view and the slices, as the GUI's is.
Then the button is released: ``end_drag``, the undo snapshot (which waits for the
worker's last steps), the deformed-space skip maps of the final state (the GUI builds
them on a worker thread before its full-quality frame), the full-quality 3D frame and
the three slices in full: *release to full quality* is that time (the GUI adds its
:data:`voxwarp.ui.viewport.REFINE_AFTER_MS` pause after the last mouse event).

Rounds alternate the two paths (each on a fresh session), so the shared machine's
load falls on both alike; the report gives medians over the rounds.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from voxwarp.core.slice_plane import SlicePlane
from voxwarp.editing.session import EditSession
from voxwarp.editing.slice_views import SliceViews
from voxwarp.render.adaptive_quality import FULL, AdaptiveQuality, scene_at
from voxwarp.render.slice_grid import slice_window
from voxwarp.scene import Scene

#: the 3D view of the default window (1280x820, four-up layout) and each slice view
DRAG_SIZE = (324, 355)
#: frames of the scripted drag
DRAG_FRAMES = 20
#: the slices' resolution while the deformation changes (as ui/mpr.py's LIVE_SCALE)
LIVE_SCALE = 0.5
#: the two paths: the model stepped on the drawing thread, or on the model worker
MODES = ("sync", "thread")
#: the families dragged
DRAG_FAMILIES = ("massspring", "chainmail")


@dataclass
class DragResult:
    """One scripted drag: frames per second while dragging, the seconds from the
    release to the full-quality frame (of which ``maps_s`` built the skip maps), and
    the frames that showed a new model state."""

    fps: float
    release_s: float
    fresh_frames: int
    maps_s: float = 0.0


@dataclass
class DragRow:
    """Medians over the rounds of one family, per mode."""

    family: str
    resolution: int
    results: dict[str, list[DragResult]] = field(default_factory=dict)

    def median(self, mode: str, name: str) -> float:
        """The median of ``name`` (a :class:`DragResult` field) over ``mode``'s rounds."""
        return statistics.median(getattr(r, name) for r in self.results[mode])


def drag_markdown(rows: list[DragRow], size: tuple[int, int], reference_ms: float) -> str:
    """The scripted drag's table (the reference: the undeformed full-quality frame of
    the 3D view at ``size``)."""
    w, h = size
    n = min((len(v) for r in rows for v in r.results.values()), default=0)
    lines = [
        f"Scripted drag at the default window (3D view and three slices of {w}x{h}, the"
        f" slices at {LIVE_SCALE:g} while dragging), {DRAG_FRAMES} frames, medians of"
        f" {n} rounds per path; undeformed full-quality 3D frame: {reference_ms:.0f} ms",
        "",
        "| deformation | grid | dragging fps: sync / thread | frames with a new state:"
        " sync / thread | release to full quality: sync / thread | of which skip maps |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        fps = [r.median(m, "fps") for m in MODES]
        fresh = [r.median(m, "fresh_frames") for m in MODES]
        rel = [r.median(m, "release_s") for m in MODES]
        maps = [r.median(m, "maps_s") for m in MODES]
        lines.append(
            f"| {r.family} | {r.resolution}³ | {fps[0]:.1f} / {fps[1]:.1f}"
            f" ({fps[1] / fps[0]:.2f}x) | {fresh[0]:.0f} / {fresh[1]:.0f} |"
            f" {rel[0]:.2f} s / {rel[1]:.2f} s | {maps[0]:.2f} s / {maps[1]:.2f} s |"
        )
    return "\n".join(lines) + "\n"


class DragLoop:
    """The GUI thread's work per frame (see the module docstring), headless.

    ``draw(scene, scale, camera)`` draws the 3D view; ``renderer`` is the
    :class:`~voxwarp.render.raycaster.Renderer` (slices, skip maps)."""

    def __init__(self, renderer: Any, draw: Callable[..., None], size: tuple[int, int]):
        self.renderer = renderer
        self.draw = draw
        self.size = size

    def slices(self, scene: Scene, views: SliceViews, scale: float) -> None:
        """The three slice views' data at ``scale`` of :attr:`size`."""
        w, h = self.size
        size = (max(1, round(w * scale)), max(1, round(h * scale)))
        for name in views.names:
            plane: SlicePlane = views.plane(name, w / h, size)
            self.renderer.slice_values(scene, plane.pixel_to_world(size), size)

    def run(self, base: Scene, family: str, resolution: int, mode: str) -> DragResult:
        """One scripted drag of ``family`` on a fresh session over ``base``."""
        session = EditSession(base.copy(warps=[]))
        try:
            session.set_model_thread(mode == "thread")
            session.set_deformation(family, resolution=resolution)
            return self._drag(session)
        finally:
            session.close()

    def _drag(self, session: EditSession) -> DragResult:
        rr, scene = self.renderer, session.scene
        camera = scene.resolved_camera()
        views = SliceViews(scene.volume, slice_window(scene))
        model = session.model
        shape = model.grid.shape
        index = int(np.ravel_multi_index(tuple(s // 2 for s in shape), shape))
        session.select([index])
        start = camera.project(session.handles()[index : index + 1], self.size)[0]
        session.begin_drag(camera, self.size, start)
        aq, fresh, shown = AdaptiveQuality(), 0, None
        rr.warped_skip_maps = "never"
        rr.support_maps = "never"  # as the window while the user interacts
        t0 = time.perf_counter()
        for k in range(1, DRAG_FRAMES + 1):
            session.drag_to(start + np.array([0.0, -0.25 * self.size[1] * k / DRAG_FRAMES]))
            session.advance()
            t = time.perf_counter()  # the GUI's frame time: the 3D view and the slices
            session.overlay_layers()
            q = aq.quality
            self.draw(scene_at(scene, q), q.scale, camera)
            self.slices(scene, views, LIVE_SCALE)
            aq.frame_drawn(time.perf_counter() - t)
            state = scene.warps[0].revision if scene.warps else None
            fresh += state != shown
            shown = state
        fps = DRAG_FRAMES / (time.perf_counter() - t0)
        t0 = time.perf_counter()
        session.end_drag()
        session.snapshot()  # the window's undo entry: waits for the worker's last steps
        rr.warped_skip_maps = "background"
        rr.support_maps = "auto"
        maps = 0.0
        if rr.needs_skip_maps(scene):
            self.draw(scene_at(scene, aq.quality), aq.quality.scale, camera)
            wanted = rr.skip_map_job()
            if wanted is not None:
                t = time.perf_counter()
                rr.install_skip_map(wanted[0], wanted[1]())
                maps = time.perf_counter() - t
        self.draw(scene, FULL.scale, camera)
        self.slices(scene, views, 1.0)
        return DragResult(fps, time.perf_counter() - t0, fresh, maps)


def bench_drag(
    loop: DragLoop,
    base: Scene,
    rounds: int,
    resolution: int,
    families: tuple[str, ...] = DRAG_FAMILIES,
    log: Any = None,
) -> list[DragRow]:
    """:data:`MODES` alternating over ``rounds`` rounds per family (one warm-up round
    each first, left out: it compiles kernels and shaders)."""
    rows = []
    for family in families:
        row = DragRow(family, resolution, {m: [] for m in MODES})
        for m in MODES:
            loop.run(base, family, resolution, m)
        for _ in range(rounds):
            for m in MODES:
                row.results[m].append(loop.run(base, family, resolution, m))
        if log:
            med = row.median
            parts = [
                f"{m} {med(m, 'fps'):.1f} fps, release {med(m, 'release_s'):.2f} s" for m in MODES
            ]
            log(f"drag {family}: " + ", ".join(parts))
        rows.append(row)
    return rows
