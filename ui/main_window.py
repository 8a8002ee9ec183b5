"""The main window: viewport, docks, menus, undo/redo, files, screenshots, status bar.

Every edit goes through :meth:`MainWindow.edit`: a snapshot of the session before and
after (:meth:`voxwarp.editing.session.EditSession.snapshot`) makes one :class:`SnapshotCommand` on
the
``QUndoStack``, so undo restores the previous state exactly. Work that can take longer
than ~100 ms (opening a volume, rebuilding a wire field) runs off the GUI thread
(:mod:`voxwarp.ui.tasks`). Errors from the core are shown as dialogs with their message.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from PySide6.QtCore import QPoint, QSettings, Qt, QTimer, Signal
from PySide6.QtGui import (
    QAction,
    QDragEnterEvent,
    QDropEvent,
    QKeySequence,
    QUndoCommand,
    QUndoStack,
)
from PySide6.QtWidgets import (
    QApplication,
    QDialog,
    QDockWidget,
    QFileDialog,
    QLabel,
    QMainWindow,
    QMenu,
    QMessageBox,
    QProgressBar,
    QSpinBox,
    QTextBrowser,
    QVBoxLayout,
)

from voxwarp.core.camera import VIEWS, Camera
from voxwarp.core.orientation import ANATOMICAL_VIEWS
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import WarpError
from voxwarp.editing.keyframes import DEFAULT_FRAMES, delete_keys, key_frames, set_key
from voxwarp.editing.session import EditorError, EditSession, Snapshot, warm_up_kernels
from voxwarp.editing.state import BuildJob
from voxwarp.errors import VoxwarpError
from voxwarp.inputs import load_input
from voxwarp.io.fields import load_transform
from voxwarp.io.frames import FrameChoiceError
from voxwarp.io.images import write_image
from voxwarp.io.samples import suggested_transfer_function
from voxwarp.scene import Scene
from voxwarp.teaching.tour import read_tour
from voxwarp.ui.correction_export import install_correction_export
from voxwarp.ui.detj_overlay import install_detj_controls
from voxwarp.ui.export_dialog import open_export_dialog
from voxwarp.ui.field_view import SEP
from voxwarp.ui.fixed_image import install_fixed_image
from voxwarp.ui.folder_access import ask_allow_folder, outside_folder
from voxwarp.ui.frame_dialog import ask_frame
from voxwarp.ui.mpr import SliceLayout, install_slice_controls
from voxwarp.ui.panels import DeformationPanel, DisplayPanel, ScenePanel, VolumePanel
from voxwarp.ui.tasks import Task, run_with_progress
from voxwarp.ui.tf_editor import TransferFunctionEditor
from voxwarp.ui.tour_panel import TourPanel
from voxwarp.ui.viewport import Viewport, qimage_to_array
from voxwarp.ui.warp_overlays import install_warp_overlays

#: frames per second of the simulation timer
SIM_FPS = 30
#: seconds a closing window waits for each running task (a build, a load) to end
CLOSE_WAIT_S = 30.0
MAX_RECENT = 8
SCENE_FILTER = "voxwarp scene (*.json)"
OPEN_FILTER = (
    "Volumes and scenes (*.json *.nrrd *.nhdr *.nii *.nii.gz *.mha *.mhd *.tif *.tiff *.npy"
    " *.npz *.dcm *.raw);;All files (*)"
)
FIELD_FILTER = (
    "Displacement fields and transforms (*.nii *.nii.gz *.nrrd *.nhdr *.mha *.mhd *.h5"
    " *.hdf5 *.tfm *.txt *.mat *.npz);;All files (*)"
)

#: shortcuts of the anatomical views (Shift: R, P and S are taken by reset, projection
#: and step)
ANATOMICAL_VIEW_KEYS: dict[str, str] = {
    "anterior": "Shift+A",
    "posterior": "Shift+P",
    "left": "Shift+L",
    "right": "Shift+R",
    "superior": "Shift+S",
    "inferior": "Shift+I",
}

SHORTCUTS: list[tuple[str, str]] = [
    (
        "Left drag on a handle",
        "drag the selection in the view plane (reference follows the cursor)",
    ),
    ("Left drag elsewhere", "orbit"),
    ("Shift + left click", "add a handle to the selection"),
    ("Ctrl + left click", "toggle a handle in the selection"),
    ("Shift + left drag elsewhere", "rubber-band selection (Ctrl: remove)"),
    ("Middle drag / right drag", "pan"),
    ("Wheel, + / -", "zoom"),
    ("Arrow keys / Shift + arrow keys", "orbit / pan"),
    ("Right click", "context menu (fix, free, reference)"),
    ("F / U", "fix / free the selected elements"),
    ("Space", "run / pause the simulation"),
    ("S", "one simulation step"),
    ("Ctrl+A / Esc", "select all / clear the selection"),
    ("1 … 6", "views from +x, -x, +y, -y, +z, -z"),
    (
        "Shift + A / P / L / R / S / I",
        "anterior, posterior, left, right, superior (neurological: the patient's right"
        " on the right), inferior (radiological) views of a volume with a patient"
        " orientation",
    ),
    ("M", "show / hide the orientation marker"),
    ("Ctrl+1 / Ctrl+2 / Ctrl+3", "3D and three slices / slices in a column / 3D only"),
    ("Slice view: left click / drag", "set the crosshair in all views; on a handle: drag it"),
    ("Slice view: wheel / Ctrl + wheel", "next or previous slice / zoom"),
    (
        "Slice view: Shift + wheel / Alt + wheel",
        "tilt the plane (oblique) about its vertical / horizontal axis",
    ),
    ("Slice view: right drag / middle drag", "window (horizontal) and level (vertical) / pan"),
    ("R", "reset the camera"),
    ("P", "perspective / orthographic"),
    ("Ctrl+Z / Ctrl+Shift+Z", "undo / redo"),
    ("Ctrl+O / Ctrl+S / Ctrl+Shift+S", "open / save scene / save scene as"),
    ("Ctrl+E", "export a screenshot (PNG or EXR)"),
    ("K", "set a key: store the deformation and the view at the toolbar's frame"),
    ("Ctrl+M", "render the keyed animation into a movie"),
    ("F1", "this help"),
]


class SnapshotCommand(QUndoCommand):
    """One undoable edit: the session's state before and after it."""

    def __init__(
        self,
        window: MainWindow,
        text: str,
        before: Snapshot,
        after: Snapshot,
        merge: str | None = None,
    ) -> None:
        super().__init__(text)
        self.window = window
        self.before = before
        self.after = after
        self.merge = merge
        self._first = True

    def id(self) -> int:
        """Commands with the same merge key merge (slider drags)."""
        return -1 if self.merge is None else (hash(self.merge) & 0x3FFFFFFF)

    def mergeWith(self, other: QUndoCommand) -> bool:
        """Keep this command's *before* and the other's *after*."""
        if (
            not isinstance(other, SnapshotCommand)
            or other.merge != self.merge
            or self.merge is None
        ):
            return False
        self.after = other.after
        return True

    def redo(self) -> None:
        """Apply *after* (the first time the state is already there)."""
        if self._first:
            self._first = False
            return
        self.window.restore(self.after)

    def undo(self) -> None:
        """Back to *before*."""
        self.window.restore(self.before)


class MainWindow(QMainWindow):
    """voxwarp's desktop window (see the module docstring)."""

    sessionChanged = Signal()

    def __init__(self, session: EditSession, path: str | Path | None = None) -> None:
        super().__init__()
        session.sync_builds = False  # wire fields build off the GUI thread here
        session.set_model_thread(model_thread())
        self.session = session
        self.path: Path | None = (
            Path(path) if path is not None and str(path).endswith(".json") else None
        )
        self.source: str | None = str(path) if path is not None else None
        self.undo_stack = QUndoStack(self)
        self.viewport = Viewport(session, self)
        #: the central area: the viewport and the linked slice views
        self.mpr = SliceLayout(self)
        self.setCentralWidget(self.mpr)
        self.setAcceptDrops(True)
        self.resize(1280, 820)
        self._pending_before: Snapshot | None = None
        self._build_task: Task | None = None
        self._closed = False  # closeEvent ran: no new background work
        self._build_job: BuildJob | None = None
        self._open_task: Task | None = None
        self._fps_times: list[float] = []
        self._panels: list[Any] = []
        self.errors: list[str] = []  # every message shown to the user (tests read it)
        self._make_docks()
        self._make_actions()
        self._make_status_bar()
        self.viewport.editStarted.connect(self._begin_mouse_edit)
        self.viewport.editFinished.connect(self._end_mouse_edit)
        self.viewport.dragged.connect(self._dragged)
        self.viewport.frameDrawn.connect(self._frame_drawn)
        self.viewport.failed.connect(self.show_error)
        self.viewport.contextMenuAt.connect(self._context_menu)
        self.viewport.pointPlaced.connect(self.refresh_panels)
        for view in self.mpr.views:
            view.editStarted.connect(self._begin_mouse_edit)
            view.editFinished.connect(self._end_mouse_edit)
            view.dragged.connect(self._dragged)
            view.failed.connect(self.show_error)
        self.undo_stack.cleanChanged.connect(self._clean_changed)
        self.sim_timer = QTimer(self)
        self.sim_timer.setInterval(int(1000 / SIM_FPS))
        self.sim_timer.timeout.connect(self._tick)
        self.sim_timer.start()
        threading.Thread(
            target=_quiet(warm_up_kernels), name="voxwarp-warm-up", daemon=True
        ).start()
        self._update_title()
        self.refresh_panels()

    # ------------------------------------------------------------------ docks
    def _make_docks(self) -> None:
        self.volume_panel = VolumePanel(self)
        self.tf_editor = TransferFunctionEditor(
            self.session.scene.transfer_function, self.session.volume
        )
        self.tf_editor.transferFunctionChanged.connect(self._tf_edited)
        self.deformation_panel = DeformationPanel(self)
        self.display_panel = DisplayPanel(self)
        self.scene_panel = ScenePanel(self)
        self._panels = [
            self.volume_panel,
            self.deformation_panel,
            self.display_panel,
            self.scene_panel,
        ]
        self.docks: dict[str, QDockWidget] = {}
        left = Qt.DockWidgetArea.LeftDockWidgetArea
        right = Qt.DockWidgetArea.RightDockWidgetArea
        for name, widget, area in (
            ("Volume", self.volume_panel, left),
            ("Transfer function", self.tf_editor, left),
            ("Deformation", self.deformation_panel, right),
            ("Display", self.display_panel, right),
            ("Scene", self.scene_panel, right),
        ):
            dock = QDockWidget(name, self)
            dock.setObjectName(name)
            dock.setWidget(widget)
            self.addDockWidget(area, dock)
            self.docks[name] = dock
        self.tabifyDockWidget(self.docks["Display"], self.docks["Scene"])
        self.docks["Display"].raise_()
        # the viewport gets the room: docks at their compact widths
        QTimer.singleShot(
            0,
            lambda: (
                self.resizeDocks(
                    [self.docks["Volume"], self.docks["Deformation"]],
                    [300, 290],
                    Qt.Orientation.Horizontal,
                ),
                self.resizeDocks(
                    [self.docks["Deformation"], self.docks["Display"]],
                    [3 * self.height() // 4, self.height() // 4],
                    Qt.Orientation.Vertical,
                ),
                self._fit_volume_dock(),
            ),
        )

    def _fit_volume_dock(self) -> None:
        """The Volume dock as tall as its content (its clipping group in view, no
        scrolling), the transfer function editor the rest, when the window has room."""
        volume, tf = self.docks["Volume"], self.docks["Transfer function"]
        if volume.isFloating() or tf.isFloating():
            return
        title = volume.height() - self.volume_panel.height()
        want = self.volume_panel.sizeHint().height() + max(0, title)
        both = volume.height() + tf.height()
        if both - want < 220:  # too little room: the editor keeps a usable height
            want = max(both - 220, both // 2)
        self.resizeDocks([volume, tf], [want, both - want], Qt.Orientation.Vertical)

    def refresh_panels(self) -> None:
        """Update every panel from the session (after undo, open, edits)."""
        for p in self._panels:
            p.refresh()
        if hasattr(self, "anatomical_view_actions"):
            self._refresh_view_actions()
        self.tf_editor.set_transfer_function(self.session.scene.transfer_function)
        if hasattr(self, "keys_label"):
            self._refresh_animation()

    # ------------------------------------------------------------------ actions
    def _action(
        self,
        menu: QMenu,
        text: str,
        slot: Callable[[], Any],
        shortcut: Any = None,
        checkable: bool = False,
    ) -> QAction:
        a = QAction(text, self)
        if shortcut is not None:
            a.setShortcut(QKeySequence(shortcut))
            a.setShortcutContext(Qt.ShortcutContext.WindowShortcut)
        a.setCheckable(checkable)
        a.triggered.connect(lambda *_: slot())
        menu.addAction(a)
        self.addAction(a)
        return a

    def _make_actions(self) -> None:
        mb = self.menuBar()
        f = mb.addMenu("&File")
        self._action(f, "&Open…", self.open_file_dialog, QKeySequence.StandardKey.Open)
        self.recent_menu = f.addMenu("Open &Recent")
        self.recent_menu.aboutToShow.connect(self._fill_recent)
        self._action(f, "&Save Scene", self.save, QKeySequence.StandardKey.Save)
        self._action(f, "Save Scene &As…", self.save_as, "Ctrl+Shift+S")
        self._action(f, "&Export Screenshot…", self.export_dialog, "Ctrl+E")
        self._action(f, "Export Volume, Field or det &J…", lambda: open_export_dialog(self))
        f.addSeparator()
        self._action(f, "Add &Displacement Field…", self.add_field_dialog)
        self.remove_fields_action = self._action(
            f, "Remove Displacement Fields", self.remove_fields
        )
        install_fixed_image(self, f)
        f.addSeparator()
        self._action(f, "&Quit", self.close, QKeySequence.StandardKey.Quit)

        e = mb.addMenu("&Edit")
        undo = self.undo_stack.createUndoAction(self, "&Undo")
        undo.setShortcut(QKeySequence.StandardKey.Undo)
        redo = self.undo_stack.createRedoAction(self, "&Redo")
        redo.setShortcuts([QKeySequence.StandardKey.Redo, QKeySequence("Ctrl+Shift+Z")])
        e.addAction(undo)
        e.addAction(redo)
        self.undo_action, self.redo_action = undo, redo
        e.addSeparator()
        self._action(e, "Select &All", self.select_all, QKeySequence.StandardKey.SelectAll)
        self._action(e, "&Clear Selection", self.clear_selection, "Esc")
        self._action(e, "&Fix Selected", lambda: self.fix_selected(True), "F")
        self._action(e, "Fr&ee Selected", lambda: self.fix_selected(False), "U")

        v = mb.addMenu("&View")
        self._action(v, "&Reset Camera", self.viewport.reset_camera, "R")
        #: axis views by name (their text names the anatomical side for oriented volumes)
        self.axis_view_actions: dict[str, QAction] = {}
        for i, name in enumerate(VIEWS):
            self.axis_view_actions[name] = self._action(
                v, f"View from {name}", lambda n=name: self.viewport.set_view(n), str(i + 1)
            )
        v.addSeparator()
        #: anatomical views (enabled for volumes with a patient orientation)
        self.anatomical_view_actions: dict[str, QAction] = {}
        for name, key in ANATOMICAL_VIEW_KEYS.items():
            self.anatomical_view_actions[name] = self._action(
                v, f"{name.capitalize()} View", lambda n=name: self.set_anatomical_view(n), key
            )
        v.addSeparator()
        self._action(v, "&Perspective / Orthographic", self.toggle_projection, "P")
        self.marker_action = self._action(
            v, "Orientation &Marker", self.toggle_marker, "M", checkable=True
        )
        self.marker_action.setChecked(self.viewport.show_marker)
        v.addSeparator()
        install_slice_controls(self, v)
        install_detj_controls(self, v)
        v.addSeparator()
        install_warp_overlays(self, v)
        v.addSeparator()
        for dock in self.docks.values():
            v.addAction(dock.toggleViewAction())

        d = mb.addMenu("&Deformation")
        self.run_action = self._action(
            d, "&Run", lambda: self.set_running(not self.session.running), "Space", checkable=True
        )
        self._action(d, "&Single Step", self.single_step, "S")
        self._action(d, "Reset &Model", lambda: self.edit("Reset model", self.session.reset_model))
        install_correction_export(self, d)
        family_actions = self.deformation_panel.window_actions()
        if family_actions:
            d.addSeparator()
        for fa in family_actions:  # e.g. the wire family's Lay a New Wire (W)
            self._action(d, fa.text, fa.slot, fa.shortcut)

        a = mb.addMenu("&Animation")
        self._action(a, "Set &Key at This Frame", self.set_key, "K")
        self._action(a, "&Delete Keys at This Frame", self.delete_key)
        self._action(a, "&Render Movie…", self.render_movie_dialog, "Ctrl+M")
        self._make_animation_bar()

        h = mb.addMenu("&Help")
        self._action(
            h, "&Keyboard and Mouse…", self.show_help, QKeySequence.StandardKey.HelpContents
        )
        self._action(h, "&About voxwarp", self._about)

    def _make_animation_bar(self) -> None:
        """A toolbar: frame, length, Set Key, the key frames, Render Movie."""
        bar = self.addToolBar("Animation")
        bar.setObjectName("Animation")
        self.frame_spin = QSpinBox()
        self.frame_spin.setRange(0, DEFAULT_FRAMES - 1)
        self.frame_spin.setToolTip("the frame Set Key stores the current state at")
        self.frames_spin = QSpinBox()
        self.frames_spin.setRange(2, 100_000)
        self.frames_spin.setValue(DEFAULT_FRAMES)
        self.frames_spin.setToolTip("frames of the animation")
        self.frames_spin.valueChanged.connect(lambda n: self.frame_spin.setMaximum(n - 1))
        bar.addWidget(QLabel(" Frame "))
        bar.addWidget(self.frame_spin)
        bar.addWidget(QLabel(" of "))
        bar.addWidget(self.frames_spin)
        key = bar.addAction("Set Key")
        key.setToolTip("store the deformation and the view at this frame (K)")
        key.triggered.connect(self.set_key)
        self.keys_label = QLabel(" no keys ")
        bar.addWidget(self.keys_label)
        movie = bar.addAction("Render Movie…")
        movie.triggered.connect(self.render_movie_dialog)

    def _make_status_bar(self) -> None:
        sb = self.statusBar()
        self.fps_label = QLabel("")
        self.mem_label = QLabel("")
        self.progress = QProgressBar()
        self.progress.setMaximumWidth(160)
        self.progress.setRange(0, 1000)
        self.progress.hide()
        sb.addPermanentWidget(self.progress)
        self.fps_label.setToolTip("frames drawn in the last second · time of the last frame")
        sb.addPermanentWidget(self.fps_label)
        sb.addPermanentWidget(self.mem_label)

    # ------------------------------------------------------------------ edits and undo
    def edit(self, text: str, fn: Callable[[], Any], merge: str | None = None) -> Any:
        """Run ``fn`` as one undoable edit (see the module docstring); errors become a
        dialog and the state goes back to where it was."""
        before = self.viewport.with_context(self.session.snapshot)
        try:
            result = self.viewport.with_context(fn)
        except VoxwarpError as exc:
            self.viewport.with_context(lambda: self.session.restore(before))
            self.show_error(str(exc))
            self.refresh_panels()
            return None
        after = self.viewport.with_context(self.session.snapshot)
        self.undo_stack.push(SnapshotCommand(self, text, before, after, merge))
        self._changed()
        return result

    def _changed(self) -> None:
        """After an edit, undo or redo: a stale wire field is rebuilt, panels and the
        view follow."""
        if self.session.family.field_stale:
            self.request_field_build()
        self.refresh_panels()
        self.viewport.update()

    def restore(self, snap: Snapshot) -> None:
        """Put the session in a snapshot's state (undo/redo)."""
        self._cancel_field_build()
        try:
            self.viewport.with_context(lambda: self.session.restore(snap))
        except VoxwarpError as exc:
            self.show_error(str(exc))
        self._changed()

    def scene_changed(self) -> None:
        """The scene's look changed outside :meth:`edit`: redraw."""
        self.viewport.update()
        self._update_title()

    def _begin_mouse_edit(self, _text: str) -> None:
        self._pending_before = self.viewport.with_context(self.session.snapshot)

    def _end_mouse_edit(self, text: str) -> None:
        before, self._pending_before = self._pending_before, None
        if before is None:
            return
        after = self.viewport.with_context(self.session.snapshot)
        if after.same_as(before):
            return
        if text == "Drag" and self.session.family.handle_name:
            text = f"Drag {self.session.family.handle_name}"
        self.undo_stack.push(SnapshotCommand(self, text, before, after))
        self._changed()

    def _dragged(self) -> None:
        self.request_field_build()  # only when the drag left a wire field stale

    def _tf_edited(self, tf: Any) -> None:
        self.edit(
            "Transfer function",
            lambda: setattr(self.session.scene, "transfer_function", tf),
            merge="transfer function",
        )

    # ------------------------------------------------------------------ field builds
    def request_field_build(self) -> None:
        """Rebuild the active family's stale field (the wire field) off the GUI thread (one
        at a time; a newer edit starts the next build when this one is done)."""
        if self._build_task and self._build_task.running:
            return
        if self._closed:  # a build queued before the window closed: Qt deletes its task
            return
        if not self.session.family.field_stale:  # (never for the other families)
            return
        job = self.session.family.build_job()
        if job is None:
            return
        task = Task(lambda progress, cancelled: job.run(progress), self)
        self._build_task, self._build_job = task, job
        self.progress.setValue(0)
        self.progress.setFormat(f"{job.label} %p%")
        self.progress.show()
        task.progressed.connect(lambda f, _t: self.progress.setValue(int(1000 * f)))
        task.succeeded.connect(lambda _w: self._field_built(job))
        task.failed.connect(self.show_error)
        task.finished.connect(lambda: self._build_task_done(task))
        task.start()

    def _field_built(self, job: BuildJob) -> None:
        if job is not self._build_job:
            return
        self.viewport.with_context(lambda: self.session.family.install(job))
        self.refresh_panels()
        self.viewport.update()

    def _build_task_done(self, task: Task) -> None:
        # A task counts as done (``running`` false) before its queued ``finished``
        # arrives, so the next build may have started meanwhile: an older task's end
        # must not clear it (that restarted the build each time, over and over).
        if task is not self._build_task:
            return
        self.progress.hide()
        self._build_task = None
        if self.session.family.field_stale and not self.session.dragging:
            QTimer.singleShot(0, self.request_field_build)
        elif self.session.family.field_stale:
            QTimer.singleShot(30, self.request_field_build)

    def _cancel_field_build(self) -> None:
        if self._build_job is not None:
            self._build_job.cancel()
        self._build_job = None

    def wait_for_field_build(self, timeout: float = 60.0) -> bool:
        """Process events until no field build is running or due (tests, scripts)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            QApplication.processEvents()
            if (
                not (self._build_task and self._build_task.running)
                and not self.session.family.field_stale
            ):
                return True
            time.sleep(0.01)
        return False

    # ------------------------------------------------------------------ simulation
    def set_running(self, running: bool) -> None:
        """Run or pause the simulation."""
        self.session.set_option("running", running)
        self.run_action.setChecked(running)
        self.refresh_panels()

    def single_step(self) -> None:
        """One step of the model (undoable)."""
        self.edit("Single step", self.session.single_step)

    def _tick(self) -> None:
        if self.viewport.ctx is None or self.session.model is None:
            return
        # shows what the model worker finished, then posts the next steps when running
        try:
            changed = self.viewport.with_context(self.session.advance)
        except VoxwarpError as exc:  # a step failed (on the worker or here)
            self.set_running(False)
            self.show_error(str(exc))
            return
        if changed:
            self.viewport.update()

    # ------------------------------------------------------------------ selection
    def select_all(self) -> None:
        """Select every handle."""
        self.session.select(range(len(self.session.handles())))
        self.viewport.update()

    def clear_selection(self) -> None:
        """Clear the selection (and cancel placing a new object, such as a wire)."""
        self.session.family.cancel_placing()
        self.session.select([], "replace")
        self.refresh_panels()  # (the wire panel's New wire button and label)
        self.viewport.update()

    def fix_selected(self, fixed: bool) -> None:
        """Fix or free the selected elements."""
        sel = list(self.session.selection)
        if not sel:
            self.statusBar().showMessage("Select elements first (click or Shift+drag)", 4000)
            return
        self.edit(
            "Fix elements" if fixed else "Free elements", lambda: self.session.set_fixed(sel, fixed)
        )

    def _context_menu(self, pos: QPoint, hit: Any) -> None:
        menu = QMenu(self)
        if hit is not None and hit not in self.session.selection:
            self.session.select([hit], "replace")
        has_sel = bool(self.session.selection)
        fixable = self.session.family.can_fix
        a = menu.addAction("Fix", lambda: self.fix_selected(True))
        a.setEnabled(has_sel and fixable)
        a = menu.addAction("Free", lambda: self.fix_selected(False))
        a.setEnabled(has_sel and fixable)
        if hit is not None:
            menu.addAction(
                "Make Reference", lambda: (self.session.set_reference(hit), self.viewport.update())
            )
        menu.addSeparator()
        menu.addAction("Select All", self.select_all)
        menu.addAction("Clear Selection", self.clear_selection)
        menu.addAction("Reset Camera", self.viewport.reset_camera)
        self.viewport.update()
        menu.popup(pos)

    def set_anatomical_view(self, name: str) -> None:
        """Look from an anatomical side (``"anterior"`` ... ``"inferior"``, see
        :data:`voxwarp.core.orientation.ANATOMICAL_VIEWS`); a volume without a patient
        orientation has no sides: the status bar says so."""
        if not self.viewport.oriented():
            self.statusBar().showMessage(
                f"{name} view: this volume has no patient orientation; use the axis views (1 … 6)",
                5000,
            )
            return
        self.viewport.set_view(ANATOMICAL_VIEWS[name])

    def toggle_marker(self) -> None:
        """Show or hide the orientation marker."""
        self.viewport.show_marker = self.marker_action.isChecked()
        self.viewport.update()

    def _refresh_view_actions(self) -> None:
        """Anatomical views only for oriented volumes; axis views named by the side."""
        oriented = self.viewport.oriented()
        side = {axis: name for name, axis in ANATOMICAL_VIEWS.items()}
        for name, action in self.axis_view_actions.items():
            action.setText(f"View from {name} ({side[name]})" if oriented else f"View from {name}")
        for name, action in self.anatomical_view_actions.items():
            action.setEnabled(oriented)
            action.setToolTip(
                f"look from the patient's {name} side"
                if oriented
                else "needs a volume with a patient orientation"
            )

    def toggle_projection(self) -> None:
        """Perspective <-> orthographic."""
        p = "orthographic" if self.viewport.camera.projection == "perspective" else "perspective"
        self.viewport.set_projection(p)
        self.refresh_panels()

    # ------------------------------------------------------------------ files
    def open_file_dialog(self) -> None:
        """Choose a volume or scene file to open."""
        path, _ = QFileDialog.getOpenFileName(
            self, "Open volume or scene", self._last_dir(), OPEN_FILTER
        )
        if path:
            self.open_path(path)

    def add_field_dialog(self) -> None:
        """Choose a displacement field or ITK transform file to add to the warp chain."""
        path, _ = QFileDialog.getOpenFileName(
            self, "Add displacement field", self._last_dir(), FIELD_FILTER
        )
        if path:
            self.add_field(path)

    def add_field(self, path: str | Path) -> bool:
        """Read a field or transform file (:func:`voxwarp.io.fields.load_transform`) and put
        its warps in the scene's chain after the model's, which corrects it in the displayed
        space (undoable); errors become the one-line dialog."""
        try:
            warps = load_transform(path)
        except (VoxwarpError, WarpError, OSError) as exc:
            self.show_error(f"could not add {Path(path).name}: {exc}")
            return False
        name = Path(path).name
        if self.edit(f"Add {name}", lambda: self.session.add_warps_front(warps)) is None:
            return False
        self.statusBar().showMessage(f"Added {name}: {_describe(warps)}", 10000)
        self.display_panel.field_view.select(f"field |u|{SEP}{name}")
        return True

    def remove_fields(self) -> None:
        """Take the imported displacement fields out of the warp chain (undoable)."""
        if not self.session.imported_warps:
            self.statusBar().showMessage("No displacement fields to remove", 4000)
            return
        n = self.edit("Remove displacement fields", self.session.remove_imported_warps)
        self.statusBar().showMessage(f"Removed {n} imported warp(s)", 4000)

    def open_path(
        self, path: str | Path, wait: bool = False, refit: bool = False, **pick: int
    ) -> Task:
        """Open a volume or a scene JSON off the GUI thread (progress, cancel); with
        ``refit`` the camera is fitted to this viewport instead of the file's camera
        (tour scenes were framed for their figure's image shape). ``pick``
        (``frame_index=``, ``channel=``) chooses in a 4-D file; without, the window asks
        (:mod:`voxwarp.ui.frame_dialog`)."""
        spec = str(path)

        def job(progress: Callable[[float, str], None], cancelled: Callable[[], bool]) -> Any:
            progress(0.1, "reading")
            try:
                return load_session_input(spec, **pick)
            except FrameChoiceError as exc:
                return exc  # asked on the GUI thread, in done
            except VoxwarpError as exc:
                if outside_folder(exc) is None:
                    raise
                return exc  # may the scene read there? asked on the GUI thread, in done

        def done(result: Any) -> None:
            if isinstance(result, FrameChoiceError):
                choice = ask_frame(self, Path(spec).name, result)
                if choice is not None:  # after this task has finished emitting
                    QTimer.singleShot(0, lambda: self.open_path(spec, refit=refit, **choice))
                return
            if isinstance(result, VoxwarpError):
                if ask_allow_folder(self, result):
                    QTimer.singleShot(0, lambda: self.open_path(spec, refit=refit, **pick))
                return
            self.viewport.with_context(self.session.close)
            if refit:
                result.scene.camera = None
            self.set_session(result, spec)

        if self._open_task is not None and self._open_task.running:
            self._open_task.cancel()  # the newest request wins (tour steps clicked fast)
        task = run_with_progress(self, f"Opening {Path(spec).name}", job, done, self.show_error)
        self._open_task = task
        if wait:
            end = time.monotonic() + 120
            while task.running and time.monotonic() < end:
                QApplication.processEvents()
                time.sleep(0.01)
            for _ in range(5):  # deliver the queued result
                QApplication.processEvents()
        return task

    def set_session(self, session: EditSession, source: str | None = None) -> None:
        """Show another session (a file was opened); clears the undo history."""
        self._cancel_field_build()
        session.running = self.session.running  # run/pause is the window's, not the file's
        session.sync_builds = False
        self.session.set_model_thread(False)
        session.set_model_thread(model_thread())
        self.session = session
        self.viewport.set_session(session, keep_camera=session.scene.camera is not None)
        self.mpr.set_session(session)
        self.fixed_image.apply()  # the comparison carries over to the new scene
        if session.scene.camera is not None:
            self.viewport.camera = session.scene.camera
        self.undo_stack.clear()
        self.source = source
        self.path = Path(source) if source and source.endswith(".json") else None
        if source and not source.startswith("sample:"):
            _add_recent(source)
        self.tf_editor.set_volume(session.volume)
        self.refresh_panels()
        self.detj.schedule()  # the status line's det J of the new scene
        self.sessionChanged.emit()
        self._update_title()
        if source is not None:  # what the volume was taken for and how it is shown
            self.statusBar().showMessage(session.scene.display_note(), 10000)

    def save(self) -> bool:
        """Save the scene to its file (asks for one the first time)."""
        if self.path is None:
            return self.save_as()
        return self.save_to(self.path)

    def save_as(self) -> bool:
        """Save the scene under a new name."""
        path, _ = QFileDialog.getSaveFileName(self, "Save scene", self._last_dir(), SCENE_FILTER)
        if not path:
            return False
        if not path.endswith(".json"):
            path += ".json"
        return self.save_to(path)

    def save_to(self, path: str | Path) -> bool:
        """Write the session (camera included) atomically; errors become a dialog."""
        scene = self.session.scene
        old_camera = scene.camera
        # the saved camera is the document's from now on: a resize no longer refits it
        self.viewport.camera_moved = True
        scene.camera = Camera.from_dict(self.viewport.camera.to_dict())
        try:
            self.viewport.with_context(lambda: self.session.save(path))
        except (VoxwarpError, OSError) as exc:
            scene.camera = old_camera
            self.show_error(f"could not save {path}: {exc}")
            return False
        self.path = Path(path)
        _add_recent(str(path))
        self.undo_stack.setClean()
        self.statusBar().showMessage(f"Saved {path}", 4000)
        self._update_title()
        return True

    def export_dialog(self) -> None:
        """Export the viewport as PNG or EXR."""
        path, _ = QFileDialog.getSaveFileName(
            self, "Export screenshot", self._last_dir(), "PNG (*.png);;OpenEXR (*.exr)"
        )
        if path:
            self.export_screenshot(path)

    def export_screenshot(self, path: str | Path, whole_window: bool = False) -> Path | None:
        """Write the viewport's frame (or the whole window) to PNG/EXR, atomically: a
        still (full quality and volume resolution), even while the user interacts."""
        path = Path(path)
        if path.suffix.lower() not in (".png", ".exr"):
            self.show_error(f"screenshots are PNG or EXR; {path.name} has neither ending")
            return None
        try:
            with self.viewport.drawing_still():  # full quality and volume while dragging
                if whole_window:
                    img = qimage_to_array(self.grab().toImage())
                else:
                    img = self.viewport.screenshot()
            if path.suffix.lower() == ".exr":
                img = img.astype("float32") / 255.0
            return write_image(path, img)
        except (VoxwarpError, OSError) as exc:
            self.show_error(f"could not write {path}: {exc}")
            return None

    def _last_dir(self) -> str:
        recent = recent_files()
        return str(Path(recent[0]).parent) if recent else os.getcwd()

    def _fill_recent(self) -> None:
        self.recent_menu.clear()
        files = recent_files()
        if not files:
            self.recent_menu.addAction("(none)").setEnabled(False)
        for p in files:
            self.recent_menu.addAction(p, lambda p=p: self.open_path(p))

    def dragEnterEvent(self, event: QDragEnterEvent) -> None:
        """Accept dropped files."""
        if event.mimeData().hasUrls():
            event.acceptProposedAction()

    def dropEvent(self, event: QDropEvent) -> None:
        """Open the first dropped file."""
        urls = event.mimeData().urls()
        if urls:
            self.open_path(urls[0].toLocalFile())

    # ------------------------------------------------------------------ animation
    def set_key(self) -> None:
        """Key the deformation and the view at the toolbar's frame (undoable)."""
        frame, frames = self.frame_spin.value(), self.frames_spin.value()
        camera = Camera.from_dict(self.viewport.camera.to_dict())

        def key() -> None:
            s = self.session
            s.animation = set_key(s.animation, s, frame, camera, frames=frames)

        self.edit(f"Set key at frame {frame}", key)

    def delete_key(self) -> None:
        """Remove the keys at the toolbar's frame (undoable)."""
        frame = self.frame_spin.value()
        if self.session.animation is None:
            return
        self.edit(
            f"Delete keys at frame {frame}",
            lambda: setattr(self.session, "animation", delete_keys(self.session.animation, frame)),
        )

    def _refresh_animation(self) -> None:
        anim = self.session.animation
        keys = key_frames(anim)
        self.keys_label.setText(f" keys: {', '.join(map(str, keys))} " if keys else " no keys ")
        if anim is not None and self.frames_spin.value() != anim.frames:
            self.frames_spin.setValue(anim.frames)

    def render_movie_dialog(self) -> None:
        """Choose a movie file and render the keyed animation into it."""
        path, _ = QFileDialog.getSaveFileName(self, "Render movie", self._last_dir(), "MP4 (*.mp4)")
        if path:
            self.render_movie(path if path.endswith(".mp4") else path + ".mp4")

    def render_movie(
        self, path: str | Path, size: tuple[int, int] | None = None, wait: bool = False
    ) -> Task | None:
        """Render the keyed animation to ``path`` (mp4) off the GUI thread: the scene
        is saved as ``<movie>_scene.json`` beside it (``voxwarp animate`` renders it
        again, and resumes it) and ``voxwarp animate`` runs in its own process, with a
        cancellable progress dialog; the frames stay in ``<movie>_frames/``."""
        if self.session.animation is None or not self.session.animation.tracks:
            self.show_error("nothing to render: set keys first (Animation -> Set Key)")
            return None
        movie = Path(path)
        scene_path = movie.with_name(movie.stem + "_scene.json")
        if not self.save_copy(scene_path):
            return None
        w, h = size or self.viewport.size_px()
        w, h = max(2, w - w % 2), max(2, h - h % 2)
        frames_dir = movie.with_name(movie.stem + "_frames")
        total = self.session.animation.frames
        cmd = [sys.executable, "-m", "voxwarp", "animate", str(scene_path), "-o", str(movie)]
        cmd += ["--size", f"{w}x{h}", "--no-progress"]

        def job(progress: Callable[[float, str], None], cancelled: Callable[[], bool]) -> Any:
            proc = subprocess.Popen(
                cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
            )
            while proc.poll() is None:
                if cancelled():
                    proc.terminate()
                    proc.wait()
                    return None
                done = len(list(frames_dir.glob("frame_*"))) if frames_dir.is_dir() else 0
                progress(0.95 * done / total, f"frame {done} of {total}")
                time.sleep(0.2)
            err = proc.stderr.read() if proc.stderr else ""
            if proc.returncode != 0:
                line = err.strip().splitlines()[-1] if err.strip() else f"exit {proc.returncode}"
                raise EditorError(f"rendering the movie failed: {line}")
            return movie

        def done(result: Any) -> None:
            if result is not None:
                self.statusBar().showMessage(f"Movie written: {result}", 8000)
                self.last_movie = Path(result)

        task = run_with_progress(self, f"Rendering {movie.name}", job, done, self.show_error)
        if wait:
            end = time.monotonic() + 600
            while task.running and time.monotonic() < end:
                QApplication.processEvents()
                time.sleep(0.02)
            for _ in range(5):
                QApplication.processEvents()
        return task

    def save_copy(self, path: str | Path) -> bool:
        """Write the session (camera included) to ``path`` without making it the
        document's file; errors become a dialog."""
        scene = self.session.scene
        old = scene.camera
        scene.camera = Camera.from_dict(self.viewport.camera.to_dict())
        try:
            self.viewport.with_context(lambda: self.session.save(path))
        except (VoxwarpError, OSError) as exc:
            self.show_error(f"could not save {path}: {exc}")
            return False
        finally:
            scene.camera = old
        return True

    def start_tour(self, path: str | Path) -> None:
        """Step through a teaching demo's tour (``voxwarp demo NAME --gui``) in a dock."""
        try:
            tour = read_tour(path)
        except VoxwarpError as exc:
            self.show_error(str(exc))
            return
        old = self.docks.pop("Tour", None)
        if old is not None:
            self.removeDockWidget(old)
            old.deleteLater()
        self.tour_panel = TourPanel(self, tour)
        dock = QDockWidget("Tour", self)
        dock.setObjectName("Tour")
        dock.setWidget(self.tour_panel)
        self.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, dock)
        self.tabifyDockWidget(self.docks["Deformation"], dock)
        dock.show()
        dock.raise_()
        self.docks["Tour"] = dock

    # ------------------------------------------------------------------ status and dialogs
    def _frame_drawn(self, ms: float) -> None:
        now = time.perf_counter()
        self._fps_times = [t for t in self._fps_times if now - t < 1.0] + [now]
        fps = len(self._fps_times)
        self.fps_label.setText(f"{fps} fps · frame {ms:.0f} ms")
        self.mem_label.setText(f"{_rss_mb():.0f} MB")
        self.deformation_panel.refresh_timings()

    def show_error(self, message: str) -> None:
        """Show a core error in a dialog (never a traceback)."""
        self.errors.append(str(message))
        self.statusBar().showMessage(str(message), 8000)
        if os.environ.get("VOXWARP_GUI_NO_DIALOGS"):
            return
        QMessageBox.warning(self, "voxwarp", str(message))

    def show_help(self) -> None:
        """The keyboard and mouse help dialog."""
        dlg = QDialog(self)
        dlg.setWindowTitle("voxwarp — keyboard and mouse")
        lay = QVBoxLayout(dlg)
        text = QTextBrowser()
        family_rows = [a.help for a in self.deformation_panel.window_actions() if a.help]
        rows = "".join(
            f"<tr><td><b>{k}</b></td><td>{v}</td></tr>" for k, v in [*SHORTCUTS, *family_rows]
        )
        text.setHtml(f"<table cellspacing=6>{rows}</table>")
        lay.addWidget(text)
        dlg.resize(620, 520)
        self.help_dialog = dlg
        dlg.show()

    def _about(self) -> None:
        QMessageBox.about(
            self,
            "voxwarp",
            "voxwarp: deform volumes and meshes at render time, without resampling the volume.",
        )

    def _clean_changed(self, _clean: bool) -> None:
        self._update_title()

    def _update_title(self) -> None:
        name = self.path.name if self.path else (self.source or self.session.volume.name)
        star = "" if self.undo_stack.isClean() else " *"
        self.setWindowTitle(f"{name}{star} — voxwarp")

    def closeEvent(self, event: Any) -> None:
        """Stop the timer, let running tasks end (Qt deletes them with the window: a
        signal from a worker thread would then leave a deleted object) and release GL
        resources."""
        self._closed = True
        self.sim_timer.stop()
        self._cancel_field_build()
        for task in self.findChildren(Task):
            task.cancel()
            task.wait(CLOSE_WAIT_S)
        self.session.set_model_thread(False)
        self.viewport.release_gl()
        super().closeEvent(event)


# ---------------------------------------------------------------------------- helpers
def model_thread() -> bool:
    """Whether the window steps CPU element models on a worker thread: yes, unless the
    environment sets ``VOXWARP_MODEL_THREAD=0`` (the old synchronous path, to compare)."""
    return os.environ.get("VOXWARP_MODEL_THREAD", "1").strip() != "0"


def load_session_input(spec: str, series: int | str | None = None, **pick: int) -> EditSession:
    """A session for INPUT: a scene JSON (resuming its deformation), a volume file or
    ``sample:NAME`` (shown with the sample's suggested transfer function); ``series``
    picks one series of a DICOM folder (``voxwarp gui --series``), ``pick``
    (``frame_index=``, ``channel=``) one volume of a 4-D file."""
    path = Path(spec)
    if path.suffix.lower() == ".json" and path.is_file():
        if series is not None:
            raise EditorError(f"--series applies to DICOM folders; {spec} is a scene JSON")
        return EditSession.load(path)
    given = {"series": series, **pick}
    obj = load_input(spec, **{k: v for k, v in given.items() if v is not None})
    if isinstance(obj, Scene):
        return EditSession(obj)
    if not isinstance(obj, Volume):
        raise EditorError(f"{spec} is neither a volume nor a scene")
    # a file gets the defaults of its modality (voxwarp.core.modality)
    tf = suggested_transfer_function(obj.name) if spec.startswith("sample:") else None
    return EditSession(Scene(obj, transfer_function=tf, zoom=1.2))


def recent_files() -> list[str]:
    """Recently opened or saved files that still exist (newest first)."""
    value = QSettings("voxwarp", "voxwarp").value("recent", [])
    files = [value] if isinstance(value, str) else list(value or [])
    return [f for f in files if Path(f).exists()][:MAX_RECENT]


def _add_recent(path: str) -> None:
    p = str(Path(path).resolve())
    files = [p] + [f for f in recent_files() if f != p]
    QSettings("voxwarp", "voxwarp").setValue("recent", files[:MAX_RECENT])


def _describe(warps: list[Any]) -> str:
    """Grid and max ``|u|`` of each displacement field, the kind of other warps."""
    parts = []
    for w in warps:
        if callable(getattr(w, "max_displacement", None)):
            grid = " x ".join(str(n) for n in w.shape)
            parts.append(f"{w.kind} grid {grid}, max |u| {w.max_displacement():.3g} mm")
        else:
            parts.append(str(w.kind))
    return "; ".join(parts)


def _rss_mb() -> float:
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        import resource

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _quiet(fn: Callable[[], Any]) -> Callable[[], None]:
    def run() -> None:
        try:
            fn()
        except Exception:  # a warm-up only saves time later; never fail for it
            pass

    return run


__all__ = ["MainWindow", "SnapshotCommand", "load_session_input", "recent_files"]
