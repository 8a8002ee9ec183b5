"""Walk through the desktop GUI as a new user would, with real mouse events, and save a
screenshot of the whole window after every step (to look at them).

    xvfb-run -a -s "-screen 0 1600x1000x24" .venv/bin/python scripts/gui_walkthrough.py OUT_DIR

Steps: open the bundled CT, poke it with mass-spring, then ChainMail, bend it with a
wire, bend it with a lattice, undo, save, reopen, export a picture. Prints what each
step did (frame times, displacements) and exits non-zero if a step had no effect.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np
from PySide6.QtCore import QPoint, Qt
from PySide6.QtTest import QTest
from PySide6.QtWidgets import QApplication

from voxwarp.editing.families.lattice import LatticeFamily
from voxwarp.ui.app import application
from voxwarp.ui.main_window import MainWindow, load_session_input


def main(out: Path) -> int:
    """Run the walk-through, writing ``out/NN_step.png``."""
    os.environ.setdefault("VOXWARP_GUI_NO_DIALOGS", "1")
    out.mkdir(parents=True, exist_ok=True)
    app = application()
    w = MainWindow(load_session_input("sample:stent"), "sample:stent")
    w.resize(1400, 900)
    w.show()
    problems: list[str] = []
    n = [0]

    def pump(seconds: float = 0.3) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            app.processEvents()
            time.sleep(0.01)

    def shot(name: str) -> None:
        end = time.monotonic() + 20
        while not w.viewport.at_rest() and time.monotonic() < end:
            w.viewport.update()
            pump(0.05)
        pump(0.2)
        n[0] += 1
        path = out / f"{n[0]:02d}_{name}.png"
        w.export_screenshot(path, whole_window=True)
        print(f"{path}  (frame {w.viewport.last_frame_ms:.0f} ms)")

    def pixel_of(index: int) -> QPoint:
        xy = w.viewport.camera.project(w.session.handles()[index : index + 1], w.viewport.size_px())
        return QPoint(round(xy[0, 0]), round(xy[0, 1]))

    def mouse_drag(start: QPoint, delta: QPoint) -> None:
        QTest.mousePress(
            w.viewport, Qt.MouseButton.LeftButton, Qt.KeyboardModifier.NoModifier, start
        )
        for k in range(1, 9):
            QTest.mouseMove(w.viewport, start + delta * (k / 8))
            pump(0.05)
        QTest.mouseRelease(
            w.viewport, Qt.MouseButton.LeftButton, Qt.KeyboardModifier.NoModifier, start + delta
        )

    def choose_model(kind: str, resolution: int) -> None:
        panel = w.deformation_panel
        panel.resolution_spin.setValue(resolution)
        panel.model_combo.setCurrentIndex(panel.model_combo.findData(kind))
        if w.session.kind != kind:
            panel.apply_button.click()
        w.wait_for_field_build(60)

    def front_middle(shape: tuple[int, ...]) -> int:
        pts = w.session.handles()
        depth = (pts - w.viewport.camera.eye) @ -w.viewport.camera.rotation[:, 2]
        mid = [s // 2 for s in shape]
        column = [np.ravel_multi_index((mid[0], j, mid[2]), shape) for j in range(shape[1])]
        return int(min(column, key=lambda i: depth[i]))

    pump(1.0)
    shot("opened")
    w.viewport.set_view((-60, 20))

    # mass-spring: drag the front middle element up and to the right, let it run
    choose_model("massspring", 6)
    i = front_middle(w.session.model.grid.shape)
    d0 = w.session.model.displacements().reshape(-1, 3)[i].copy()
    mouse_drag(pixel_of(i), QPoint(90, -60))
    pump(1.5)
    moved = float(np.linalg.norm(w.session.model.displacements().reshape(-1, 3)[i] - d0))
    print(f"mass-spring: element {i} moved {moved:.1f} mm")
    if moved < 5:
        problems.append("mass-spring drag had no effect")
    shot("massspring_drag")

    # ChainMail
    choose_model("chainmail", 6)
    i = front_middle(w.session.model.grid.shape)
    mouse_drag(pixel_of(i), QPoint(-80, -40))
    pump(0.5)
    disp = np.abs(w.session.model.displacements()).max()
    print(f"chainmail: largest displacement {disp:.1f} mm")
    if disp < 5:
        problems.append("ChainMail drag had no effect")
    shot("chainmail_drag")

    # wire: bend the default wire by its third control point
    choose_model("wires", 6)
    mouse_drag(pixel_of(2), QPoint(110, 0))
    ok = w.wait_for_field_build(60)
    print(f"wire: field rebuilt {ok}, {w.session.timings.get('field', float('nan')):.0f} ms")
    if not ok or w.session.family.field_stale:
        problems.append("wire field not rebuilt")
    shot("wire_bend")

    # lattice: drag a top-middle node sideways
    choose_model("lattice", 4)
    nodes = w.session.adapter(LatticeFamily).lattice_nodes
    j = int(np.ravel_multi_index((1, 1, nodes.shape[2] - 1), nodes.shape[:3]))
    rest = nodes.reshape(-1, 3)[j].copy()
    mouse_drag(pixel_of(j), QPoint(120, 20))
    pump(0.5)
    moved = float(
        np.linalg.norm(w.session.adapter(LatticeFamily).lattice_nodes.reshape(-1, 3)[j] - rest)
    )
    print(f"lattice: node {j} moved {moved:.1f} mm")
    if moved < 5:
        problems.append("lattice drag had no effect")
    shot("lattice_bend")

    # undo the lattice drag
    w.undo_action.trigger()
    pump(0.5)
    back = float(
        np.linalg.norm(w.session.adapter(LatticeFamily).lattice_nodes.reshape(-1, 3)[j] - rest)
    )
    print(f"undo: node {j} is {back:.3g} mm from rest")
    if back != 0:
        problems.append("undo did not restore the lattice")
    shot("undo")
    w.redo_action.trigger()

    # save, reopen, export
    scene = out / "walkthrough_scene.json"
    if not w.save_to(scene):
        problems.append("save failed")
    w.open_path(scene, wait=True)
    pump(1.0)
    print(f"reopened {scene.name}: {w.session.kind}")
    if w.session.kind != "lattice":
        problems.append("reopen lost the lattice")
    shot("reopened")
    png = w.export_screenshot(out / "exported_view.png")
    print(f"exported {png}")
    w.close()
    QApplication.processEvents()
    for p in problems:
        print(f"PROBLEM: {p}", file=sys.stderr)
    print("errors shown:", w.errors or "none")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/walkthrough")))
