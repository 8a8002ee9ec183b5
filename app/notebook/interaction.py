"""What the mouse and keys do in the notebook viewer, without a widget or a browser.

:class:`Interaction` holds an :class:`~voxwarp.editing.session.EditSession` (the same
Qt-free session the desktop GUI drives), the camera and an undo stack of session
snapshots, and turns presses, moves, releases, wheel turns and keys into the GUI's
actions (``voxwarp.ui.viewport``):

* left button on a handle: pick it (Shift adds it to the selection, Ctrl/Cmd toggles)
  and drag the selection in the plane parallel to the image; on nothing: orbit; a click
  on nothing clears the selection;
* right or middle button, or Shift + left on nothing: pan;
* wheel: zoom;
* keys: arrows orbit (Shift + arrows pan), ``+``/``-`` zoom, ``r`` refits the camera,
  space runs or pauses the simulation, Ctrl+Z / Ctrl+Shift+Z (or Ctrl+Y) undo and redo.

Coordinates are CSS pixels of the view, origin top-left, y down; ``size`` is the view's
size in those pixels. A drag of a wire's control point rebuilds the wire field when the
button is released (the desktop GUI does it on a worker thread while dragging).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from voxwarp.core.camera import Camera
from voxwarp.core.limits import MAX_ZOOM, MIN_ZOOM
from voxwarp.editing.session import EditorError, EditSession, Snapshot

#: pixels the pointer may move before a press becomes a drag (orbit, pan)
CLICK_SLOP_PX = 3
#: degrees of orbit per pixel of pointer motion, and per arrow key
ORBIT_DEG_PER_PX = 0.4
KEY_ORBIT_DEG = 5.0
#: fraction of the view height panned per Shift+arrow
KEY_PAN = 0.05
#: zoom factor per wheel notch (100 CSS pixels of wheel delta) and per +/- key
ZOOM_PER_STEP = 1.15
WHEEL_PX_PER_STEP = 100.0
#: seconds after the last input during which frames count as interactive
SETTLE_S = 0.25


#: largest view side in CSS pixels
MAX_VIEW_SIDE = 16384


def view_size(size: Any) -> tuple[int, int]:
    """``size`` as ``(width, height)`` whole CSS pixels, each 1 to :data:`MAX_VIEW_SIDE`;
    anything else (a string, three numbers, NaN) is a one-line :class:`EditorError`."""
    try:
        if isinstance(size, str | bytes):
            raise TypeError("a string")
        w, h = (float(v) for v in size)
        if not all(math.isfinite(v) and v >= 1 for v in (w, h)):
            raise ValueError("not positive and finite")
    except (TypeError, ValueError) as exc:
        raise EditorError(
            f"size must be (width, height) in CSS pixels, e.g. (480, 360); got {size!r:.60}"
        ) from exc
    return min(round(w), MAX_VIEW_SIDE), min(round(h), MAX_VIEW_SIDE)


class Interaction:
    """Camera, picking, dragging and undo of one view of an edit session.

    Parameters
    ----------
    session
        The edit session (its scene is drawn; its handles are picked and dragged).
    size
        The view's (width, height) in CSS pixels.
    """

    def __init__(self, session: EditSession, size: tuple[int, int]) -> None:
        self.session = session
        self.size = view_size(size)
        #: magnification since the camera was fitted (kept in MIN_ZOOM..MAX_ZOOM)
        self.magnification = 1.0
        self.camera: Camera = self.fitted_camera()
        self.camera_moved = False
        self._press: dict[str, Any] | None = None
        self._undo: list[tuple[str, Snapshot, Snapshot]] = []
        self._redo: list[tuple[str, Snapshot, Snapshot]] = []
        self._last_input = 0.0

    # ------------------------------------------------------------------ camera
    def fitted_camera(self) -> Camera:
        """The scene's camera fitted to this view (also when it is taller than wide)."""
        cam = self.session.scene.resolved_camera()
        # our own copy: orbiting must not move the scene's explicit camera
        cam = dataclasses.replace(cam, center=cam.center.copy(), rotation=cam.rotation.copy())
        w, h = self.size
        if w < h:
            cam.zoom(w / h)
        return cam

    def resize(self, size: tuple[int, int]) -> None:
        """The view's size changed; the camera is refitted until the user moves it."""
        self.size = view_size(size)
        if not self.camera_moved:
            self.camera = self.fitted_camera()
            self.magnification = 1.0

    def reset_camera(self) -> None:
        """Refit the camera to the scene."""
        self.camera = self.fitted_camera()
        self.magnification = 1.0
        self.camera_moved = False
        self.note_input()

    def orbit(self, d_azimuth: float, d_elevation: float) -> None:
        """Turn the camera about its centre (degrees)."""
        self.camera.orbit(float(d_azimuth), float(d_elevation))
        self._moved_camera()

    def pan(self, dx: float, dy: float) -> None:
        """Move the camera's centre by fractions of the view height (right, up)."""
        self.camera.pan(float(dx), float(dy))
        self._moved_camera()

    def zoom(self, factor: float) -> None:
        """Magnify by ``factor`` (> 1 zooms in), within :data:`MIN_ZOOM`..:data:`MAX_ZOOM`
        of the fitted view (so a burst of wheel events cannot shrink the camera's
        distance to zero)."""
        target = min(MAX_ZOOM, max(MIN_ZOOM, self.magnification * float(factor)))
        if not math.isfinite(target) or target == self.magnification:
            return
        self.camera.zoom(target / self.magnification)
        self.magnification = target
        self._moved_camera()

    def _moved_camera(self) -> None:
        self.camera_moved = True
        self.note_input()

    def note_input(self) -> None:
        """Something changed the view just now (frames are interactive for a moment)."""
        self._last_input = time.perf_counter()

    def interacting(self) -> bool:
        """A drag or orbit in progress, input a moment ago, or a model still moving."""
        if self._press is not None and self._press["moved"]:
            return True
        if time.perf_counter() - self._last_input < SETTLE_S:
            return True
        return self.simulating()

    def simulating(self) -> bool:
        """Whether the model runs and has not come to rest (or a drag holds it)."""
        s = self.session
        return bool(s.running and s.model is not None and (not s.settled or s.dragging))

    @property
    def pressed(self) -> bool:
        """Whether a button is down (a press not yet released)."""
        return self._press is not None

    # ------------------------------------------------------------------ handles
    def handle_pixels(self) -> np.ndarray:
        """(N, 2) CSS pixel positions of the session's handles in this view."""
        pts = self.session.handles()
        if len(pts) == 0:
            return np.zeros((0, 2))
        return self.camera.project(pts, self.size)

    def pick(self, x: float, y: float, mode: str = "replace") -> int | None:
        """Select the handle under ``(x, y)`` (``mode``: replace, add or toggle the
        selection); returns its index, or None (the selection is then unchanged)."""
        hit = self.session.pick(self.camera, self.size, (float(x), float(y)))
        if hit is not None:
            self._select(hit, mode)
        return hit

    def _select(self, hit: int, mode: str) -> None:
        if mode == "replace" and hit in self.session.selection:
            self.session.set_reference(hit)  # keep the selection: drag all of it
        else:
            self.session.select([hit], mode)  # type: ignore[arg-type]

    # ------------------------------------------------------------------ pointer
    def press(self, x: float, y: float, button: int = 1, modifiers: Sequence[str] = ()) -> None:
        """A button went down at ``(x, y)`` (1 left, 2 right, 3 middle)."""
        mods = {str(m) for m in modifiers}
        p: dict[str, Any] = {"start": (x, y), "last": (x, y), "mode": "pan", "moved": False}
        self._press = p
        if button != 1:
            return
        shift, ctrl = "Shift" in mods, bool({"Control", "Meta"} & mods)
        mode = "toggle" if ctrl else "add" if shift else "replace"
        hit = self.session.pick(self.camera, self.size, (float(x), float(y)))
        if hit is None:
            p["mode"] = "pan" if shift else "orbit"
            return
        p["before"] = self.session.snapshot()  # only edits pay for a snapshot
        self._select(hit, mode)
        begun = self.session.begin_drag(self.camera, self.size, (x, y))
        p["mode"] = "drag" if begun else "select"

    def move(self, x: float, y: float) -> None:
        """The pointer moved to ``(x, y)`` with a button down (ignored otherwise)."""
        p = self._press
        if p is None:
            return
        if not p["moved"]:
            sx, sy = p["start"]
            if abs(x - sx) + abs(y - sy) < CLICK_SLOP_PX:
                return
            p["moved"] = True
        dx, dy = x - p["last"][0], y - p["last"][1]
        p["last"] = (x, y)
        if p["mode"] == "drag":
            self.session.drag_to((x, y))
            self.note_input()
        elif p["mode"] == "orbit":
            self.orbit(-dx * ORBIT_DEG_PER_PX, -dy * ORBIT_DEG_PER_PX)
        elif p["mode"] == "pan":
            self.pan(-dx / self.size[1], dy / self.size[1])

    def release(self, x: float | None = None, y: float | None = None) -> None:
        """The button went up (at ``(x, y)``, if known): ends a drag (one undo step)."""
        if self._press is not None and x is not None and y is not None:
            self.move(x, y)
        p, self._press = self._press, None
        if p is None:
            return
        if p["mode"] in ("drag", "select"):
            self.session.end_drag()
            self.session.family.rebuild_if_stale()
            self._push("Drag" if p["moved"] else "Select", p["before"])
        elif p["mode"] == "orbit" and not p["moved"]:
            self.session.select([], "replace")  # a click on nothing clears the selection

    def drag(self, start: Sequence[float], end: Sequence[float], steps: int = 8) -> int | None:
        """Press on the handle at ``start``, move to ``end`` in ``steps`` moves (the model
        advancing one frame after each), release; returns the dragged handle or None
        (nothing under ``start``: no drag)."""
        x0, y0 = float(start[0]), float(start[1])
        x1, y1 = float(end[0]), float(end[1])
        self.press(x0, y0)
        assert self._press is not None
        if self._press["mode"] != "drag":
            self.release()
            return None
        hit = self.session.reference
        for t in np.linspace(0.0, 1.0, max(1, int(steps)) + 1)[1:]:
            self.move(x0 + (x1 - x0) * t, y0 + (y1 - y0) * t)
            self.session.advance()
        self.release()
        return hit

    def wheel(self, dy: float) -> None:
        """A wheel turn of ``dy`` CSS pixels (negative: away from the user, zooms in)."""
        steps = -float(dy) / WHEEL_PX_PER_STEP
        if steps and math.isfinite(steps):
            self.zoom(ZOOM_PER_STEP ** max(-10.0, min(10.0, steps)))

    def key(self, key: str, modifiers: Sequence[str] = ()) -> bool:
        """A key went down; returns whether it did something."""
        mods = {str(m) for m in modifiers}
        ctrl, shift = bool({"Control", "Meta"} & mods), "Shift" in mods
        arrows = {
            "ArrowLeft": (-1, 0),
            "ArrowRight": (1, 0),
            "ArrowUp": (0, 1),
            "ArrowDown": (0, -1),
        }
        k = key.lower() if len(key) == 1 else key
        if key in arrows:
            dx, dy = arrows[key]
            if shift:
                self.pan(-dx * KEY_PAN, -dy * KEY_PAN)
            else:
                self.orbit(dx * KEY_ORBIT_DEG, dy * KEY_ORBIT_DEG)
        elif ctrl and (k == "y" or (k == "z" and shift)):
            return self.redo()
        elif ctrl and k == "z":
            return self.undo()
        elif key in ("+", "="):
            self.zoom(ZOOM_PER_STEP)
        elif key == "-":
            self.zoom(1 / ZOOM_PER_STEP)
        elif k == "r":
            self.reset_camera()
        elif key == " ":
            self.session.set_option("running", not self.session.running)
            self.note_input()
        else:
            return False
        return True

    # ------------------------------------------------------------------ undo
    def edit(self, text: str, fn: Callable[[], Any]) -> Any:
        """Run ``fn`` (a change of the session) as one undoable edit."""
        before = self.session.snapshot()
        try:
            result = fn()
        except EditorError:
            self.session.restore(before)
            raise
        self._push(text, before)
        return result

    def _push(self, text: str, before: Snapshot) -> None:
        after = self.session.snapshot()
        if not after.same_as(before):
            self._undo.append((text, before, after))
            self._redo.clear()

    def undo(self) -> bool:
        """Go back one edit; returns False when there is none."""
        if not self._undo:
            return False
        text, before, after = self._undo.pop()
        self.session.restore(before)
        self._redo.append((text, before, after))
        self.note_input()
        return True

    def redo(self) -> bool:
        """Redo the last undone edit; returns False when there is none."""
        if not self._redo:
            return False
        text, before, after = self._redo.pop()
        self.session.restore(after)
        self._undo.append((text, before, after))
        self.note_input()
        return True

    @property
    def undo_texts(self) -> list[str]:
        """What each undo step undoes, oldest first."""
        return [t for t, _, _ in self._undo]
