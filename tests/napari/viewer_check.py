"""Drive a real napari viewer with the voxwarp dock widget (run by test_viewer.py in a
child process on a private Xvfb display).

Usage: ``python tests/napari/viewer_check.py OUT_DIR [SIZE]`` (SIZE: rendered pixels).
Opens the voxwarp ``fish`` sample through the plugin's sample data, docks the widget
through the plugin, renders the layer with no deformation and with the mass-spring
push, starts "Open in voxwarp", and writes ``result.json`` (layers, shapes, image
statistics) and ``window.png``.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np


def wait_for(widget, worker, timeout: float = 120.0) -> None:
    from qtpy.QtWidgets import QApplication

    # the widget re-enables its button on the worker's `finished` (connected before start)
    start = time.monotonic()
    while not widget.render_button.isEnabled() and time.monotonic() - start < timeout:
        QApplication.processEvents()
        time.sleep(0.01)
    QApplication.processEvents()
    if not widget.render_button.isEnabled():
        raise SystemExit(f"render did not finish in {timeout} s: {widget.status.text()}")


def render(viewer, widget, deformation: str) -> dict:
    widget.deformation_box.setCurrentText(deformation)
    start = time.perf_counter()
    worker = widget.render_deformed()
    if worker is None:
        raise SystemExit(f"render refused: {widget.status.text()}")
    wait_for(widget, worker)
    layer = viewer.layers[-1]
    image = np.asarray(layer.data)
    return {
        "name": layer.name,
        "rgb": bool(layer.rgb),
        "shape": list(image.shape),
        "std": float(image.std()),
        "seconds": time.perf_counter() - start,
        "status": widget.status.text(),
        "image": image,
    }


def open_files(viewer, out: Path) -> dict:
    """Open a scene JSON as napari's File > Open does (``plugin=None``: the only reader
    for it) and an oblique NIfTI with ``plugin="voxwarp"``; show them in 3D."""
    import nibabel as nib

    from voxwarp import Scene, load_sample
    from voxwarp.napari_plugin.deformed_view import push_warps

    head = load_sample("head", shape=(24, 24, 24))
    scene_path = Scene(head, warps=push_warps(head)).save(out / "scene.json")
    affine = np.diag([-0.8, 1.1, 2.5, 1.0])
    c, s = np.cos(np.radians(25)), np.sin(np.radians(25))
    affine[:3, :3] = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ affine[:3, :3]
    data = np.zeros((20, 24, 16), np.int16)
    data[4:16, 6:18, 3:13] = 1000
    nib.save(nib.Nifti1Image(data, affine), out / "tilted.nii.gz")
    viewer.layers.clear()
    viewer.canvas.grid.enabled = False
    scene_layers = viewer.open(scene_path, plugin=None)
    nifti_layers = viewer.open(out / "tilted.nii.gz", plugin="voxwarp")
    viewer.dims.ndisplay = 3
    viewer.layers[scene_layers[1].name].visible = False
    viewer.reset_view()
    canvas = viewer.screenshot(canvas_only=True, flash=False)
    from voxwarp.io.images import write_image

    write_image(out / "canvas_3d.png", np.ascontiguousarray(canvas))
    return {
        "scene_layers": [(layer.name, list(layer.data.shape)) for layer in scene_layers],
        "nifti_layers": [(layer.name, list(layer.data.shape)) for layer in nifti_layers],
        "nifti_affine": np.asarray(nifti_layers[0].affine.affine_matrix).tolist(),
        "canvas_3d_std": float(np.asarray(canvas)[..., :3].std()),
    }


def main(out: Path, size: int = 160) -> None:
    import napari

    out.mkdir(parents=True, exist_ok=True)
    viewer = napari.Viewer(show=False)
    viewer.window.resize(1280, 760)
    viewer.open_sample("voxwarp", "fish")
    viewer.add_image(np.zeros((16, 16)), name="flat")  # 2D: the widget must not list it
    viewer.layers.selection.active = viewer.layers["fish"]
    _, widget = viewer.window.add_plugin_dock_widget("voxwarp", "voxwarp deformed view")
    widget.size_box.setValue(size)
    widget.view_box.setCurrentText("+z")
    listed = [widget.layer_box.itemText(i) for i in range(widget.layer_box.count())]
    viewer.layers.selection.active = viewer.layers["flat"]  # not taken: the status says why
    flat_status, flat_choice = widget.status.text(), widget.layer_box.currentText()
    viewer.layers.selection.active = viewer.layers["fish"]
    plain = render(viewer, widget, "none")
    pushed = render(viewer, widget, "mass-spring push")
    changed = float(np.abs(plain.pop("image").astype(int) - pushed.pop("image")).mean())
    widget.deformation_box.setCurrentText("scene file")  # no file picked: an error line
    refused = widget.render_deformed() is None
    error = widget.status.text()
    widget.scene_edit.setText(str(out / "missing.json"))  # a worker error: one line too
    wait_for(widget, widget.render_deformed())
    worker_error = widget.status.text()
    widget.scene_edit.setText("")
    widget.deformation_box.setCurrentText("mass-spring push")
    widget.view_box.setCurrentText("anterior")  # the fish has no patient orientation
    wait_for(widget, widget.render_deformed())
    view_error = widget.status.text()
    count_after_errors = len(viewer.layers)
    widget.view_box.setCurrentText("+z")
    widget.layer_box.setCurrentText("fish")
    process = widget.open_in_voxwarp()
    started = process is not None and process.poll() is None
    if process is not None:
        process.terminate()
        process.wait(30)
    for name in ("flat", "fish"):  # the two renders side by side: before and after the push
        viewer.layers[name].visible = False
    viewer.canvas.grid.enabled = True
    viewer.reset_view()
    shot = viewer.screenshot(canvas_only=False, flash=False)
    from voxwarp.io.images import write_image

    write_image(out / "window.png", np.ascontiguousarray(shot))
    layer_names = [layer.name for layer in viewer.layers]
    opened = open_files(viewer, out)
    result = {
        "listed": listed,
        "flat_status": flat_status,
        "flat_choice": flat_choice,
        "layers": layer_names,
        "none": plain,
        "push": pushed,
        "push_vs_none_mean_abs": changed,
        "voxwarp_started": started,
        "refused": refused,
        "error_status": error,
        "worker_error_status": worker_error,
        "view_error_status": view_error,
        "layer_count_after_error": count_after_errors,
        "scene": widget.status.text(),
        "screenshot_shape": list(shot.shape),
        **opened,
    }
    (out / "result.json").write_text(json.dumps(result, indent=2))
    viewer.close()


if __name__ == "__main__":
    main(Path(sys.argv[1]), *(int(a) for a in sys.argv[2:3]))
