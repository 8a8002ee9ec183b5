"""The voxwarp dock widget (Plugins > voxwarp): the selected Image layer in voxwarp.

Two actions on the chosen 3D Image layer, read through
:mod:`voxwarp.napari_plugin.convert` (zyx data, scale, translate/affine, contrast
limits, colormap, rendering):

* **Render deformed view** renders the layer through a voxwarp deformation
  (:data:`~voxwarp.napari_plugin.deformed_view.DEFORMATIONS`) on a worker thread, which
  owns its EGL context, and adds the picture as an RGB layer.
* **Open in voxwarp** writes the volume and a scene JSON to a temporary folder and
  starts the voxwarp window on it in its own process.

Written with qtpy, so it runs on whatever Qt binding napari uses. Problems show as one
line in the widget's status (and as a napari notification).
"""

from __future__ import annotations

import traceback
from typing import TYPE_CHECKING, Any

from qtpy.QtWidgets import (
    QComboBox,
    QFileDialog,
    QFormLayout,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from voxwarp.core.orientation import ANATOMICAL_VIEWS
from voxwarp.errors import VoxwarpError
from voxwarp.napari_plugin import convert, deformed_view, handoff

if TYPE_CHECKING:
    import napari

#: The camera views offered: "default" lets voxwarp choose, then the axis views and the
#: anatomical views (for layers with a patient orientation, e.g. from voxwarp's reader).
VIEWS: tuple[str, ...] = ("default", "-y", "+y", "-x", "+x", "+z", "-z", *ANATOMICAL_VIEWS)


class VoxwarpWidget(QWidget):
    """Dock widget: pick an Image layer, a deformation, a view and a size; render the
    deformed view back into napari or open the layer in the voxwarp window."""

    def __init__(self, napari_viewer: napari.viewer.Viewer) -> None:
        super().__init__()
        self.viewer = napari_viewer
        self.worker: Any = None
        self.process: Any = None
        self.layer_box = QComboBox()
        self.deformation_box = QComboBox()
        self.deformation_box.addItems(deformed_view.DEFORMATIONS)
        self.scene_edit = QLineEdit()
        self.scene_edit.setPlaceholderText("scene JSON with a deformation")
        self.view_box = QComboBox()
        self.view_box.addItems(VIEWS)
        self.size_box = QSpinBox()
        self.size_box.setRange(32, 2048)
        self.size_box.setValue(deformed_view.DEFAULT_SIZE)
        self.render_button = QPushButton("Render deformed view")
        self.open_button = QPushButton("Open in voxwarp")
        self.status = QLabel("")
        self.status.setWordWrap(True)
        self._lay_out()
        self._connect()
        self.refresh_layers()

    def _lay_out(self) -> None:
        browse = QPushButton("...")
        browse.clicked.connect(self._pick_scene)
        scene_row = QHBoxLayout()
        scene_row.addWidget(self.scene_edit)
        scene_row.addWidget(browse)
        form = QFormLayout()
        form.addRow("Layer", self.layer_box)
        form.addRow("Deformation", self.deformation_box)
        form.addRow("Scene file", scene_row)
        form.addRow("View", self.view_box)
        form.addRow("Size (px)", self.size_box)
        column = QVBoxLayout(self)
        column.addLayout(form)
        column.addWidget(self.render_button)
        column.addWidget(self.open_button)
        column.addWidget(self.status)
        column.addStretch(1)

    def _connect(self) -> None:
        events = self.viewer.layers.events
        events.inserted.connect(self.refresh_layers)
        events.removed.connect(self.refresh_layers)
        self.viewer.layers.selection.events.active.connect(self.refresh_layers)
        self.render_button.clicked.connect(self.render_deformed)
        self.open_button.clicked.connect(self.open_in_voxwarp)

    # ------------------------------------------------------------------ layers
    def refresh_layers(self, *_: Any) -> None:
        """List the 3D single-channel Image layers; the active one is chosen. An active
        layer voxwarp does not take says why in the status line (what to do instead)."""
        names = [layer.name for layer in self.viewer.layers if _usable(layer)]
        active = self.viewer.layers.selection.active
        current = active.name if active is not None and active.name in names else None
        current = current or self.layer_box.currentText()
        self.layer_box.blockSignals(True)
        self.layer_box.clear()
        self.layer_box.addItems(names)
        if current in names:
            self.layer_box.setCurrentText(current)
        self.layer_box.blockSignals(False)
        if active is not None and active.name not in names:
            self._set_status(f"voxwarp: {_refusal(active)}")

    def selected_layer(self) -> Any:
        """The chosen layer; :class:`VoxwarpError` when there is none."""
        name = self.layer_box.currentText()
        if not name or name not in self.viewer.layers:
            raise VoxwarpError("no 3D image layer: open a volume or a voxwarp sample first")
        return self.viewer.layers[name]

    # ------------------------------------------------------------------ actions
    def render_deformed(self) -> Any:
        """Start rendering the chosen layer deformed; the RGB layer is added when the
        worker returns. Returns the napari worker (``None`` after an error)."""
        try:
            layer = self.selected_layer()
            volume = convert.layer_to_volume(layer)
            options = convert.layer_scene_options(layer)
            kind = self.deformation_box.currentText()
            deformed_view.check_deformation(kind, self.scene_edit.text())  # before a worker
        except (VoxwarpError, ValueError) as exc:
            self._report(exc)
            return None
        view = self.view_box.currentText()
        if view != "default":
            options["view"] = view
        job = _RenderJob(volume, options, kind, self.scene_edit.text(), self.size_box.value())
        return self._start(job, f"{layer.name} (voxwarp, {kind})")

    def _start(self, job: _RenderJob, name: str) -> Any:
        from napari.qt.threading import create_worker

        self.render_button.setEnabled(False)
        self._set_status(f"rendering {name} ...")
        # the job returns its error wrapped instead of raising: napari 0.9.2's task status
        # handler of `errored` itself fails (TypeError), and errors are one line here
        self.worker = create_worker(job.run)
        self.worker.returned.connect(lambda result: self._finish(result, name))
        self.worker.finished.connect(lambda: self.render_button.setEnabled(True))
        self.worker.start()
        return self.worker

    def _finish(self, result: Any, name: str) -> None:
        if isinstance(result, _Failed):
            self._worker_error(result.error)
            return
        image = result
        self.viewer.add_image(image, rgb=True, name=name, metadata={"voxwarp": {"render": name}})
        self._set_status(f"added {name}: {image.shape[1]}x{image.shape[0]} px")

    def open_in_voxwarp(self) -> Any:
        """Write the chosen layer and its scene to a temporary folder and start the voxwarp
        window on it; returns the process (``None`` after an error)."""
        try:
            layer = self.selected_layer()
            volume = convert.layer_to_volume(layer)
            scene_path = handoff.write_handoff(volume, convert.layer_scene_options(layer))
            self.process = handoff.launch_voxwarp(scene_path)
        except (VoxwarpError, ValueError, OSError) as exc:
            self._report(exc)
            return None
        self._set_status(f"voxwarp opens {scene_path}")
        return self.process

    def _pick_scene(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Scene JSON", "", "Scene JSON (*.json)")
        if path:
            self.scene_edit.setText(path)
            self.deformation_box.setCurrentText("scene file")

    # ------------------------------------------------------------------ status
    def _set_status(self, text: str) -> None:
        self.status.setText(text)

    def _worker_error(self, exc: BaseException) -> None:
        """A voxwarp error is one status line; anything else also prints its traceback."""
        if not isinstance(exc, VoxwarpError):
            traceback.print_exception(exc)
        self._report(exc)

    def _report(self, exc: BaseException) -> None:
        from napari.utils.notifications import show_warning

        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        self._set_status(f"voxwarp: {text}")
        show_warning(f"voxwarp: {text}")


class _RenderJob:
    """The worker thread's part: the deformation's warps and the headless render."""

    def __init__(
        self, volume: Any, options: dict[str, Any], kind: str, scene: str, size: int
    ) -> None:
        self.volume, self.options, self.kind = volume, options, kind
        self.scene, self.size = scene, size

    def run(self) -> Any:
        """The RGB image, or the error that stopped it (wrapped: a worker that returns an
        exception raises it)."""
        try:
            scene_path = self.scene or None
            scene = deformed_view.deformed_scene(self.volume, self.options, self.kind, scene_path)
            return deformed_view.render_rgb(scene, self.size)
        except Exception as exc:  # handed to the GUI thread, reported there
            return _Failed(exc)


class _Failed:
    """What a render job returns when it fails: the exception, for the GUI thread."""

    def __init__(self, error: Exception) -> None:
        self.error = error


def _refusal(layer: Any) -> str:
    """Why voxwarp does not take ``layer`` (empty when it does)."""
    try:
        convert.check_layer(layer)
    except VoxwarpError as exc:
        return str(exc)
    return ""


def _usable(layer: Any) -> bool:
    """Whether ``layer`` is an Image layer voxwarp can take (3D, single channel)."""
    try:
        convert.check_layer(layer)
    except VoxwarpError:
        return False
    return True
