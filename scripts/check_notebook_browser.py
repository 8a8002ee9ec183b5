"""Check the notebook Viewer in a real JupyterLab in a real browser (not part of CI).

Starts JupyterLab with a kernel on voxwarp's Python, opens a small notebook in headless
Chromium (Playwright), and with the mouse and keyboard: shows a Viewer, orbits it, zooms
it with the wheel, drags a mass-spring element, undoes the drag with Ctrl+Z. After each
step a cell prints what the kernel saw; the script checks it and saves screenshots.

Run it from an environment that has JupyterLab and Playwright (they are not voxwarp
dependencies), e.g.::

    python -m venv /tmp/jl && /tmp/jl/bin/pip install jupyterlab anywidget playwright
    /tmp/jl/bin/python scripts/check_notebook_browser.py --kernel-python .venv/bin/python \\
        --chromium /usr/bin/chromium --out /tmp/browser_check

Exit code 0 when every check holds. What it found last is in docs/notebooks.md.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CELLS = [
    """\
import json, numpy as np
from voxwarp import Scene, load_sample
from voxwarp.notebook import Viewer

scene = Scene(load_sample("fish", shape=(96, 48, 40)), view="+z", transfer_function="ct-soft")
viewer = Viewer(scene, "massspring", resolution=6, size=(480, 320))
viewer""",
    """\
state = lambda **more: print(json.dumps({"rotation": viewer.camera.rotation.round(4).tolist(),
    "distance": viewer.camera.distance, "undo": viewer.interaction.undo_texts,
    "sent": viewer.get_stats()["sent_frames"], **more}))
state()""",
    """\
viewer.reset_camera()
g = viewer.session.model.grid
h = int(np.ravel_multi_index((3, 2, g.shape[2] - 1), g.shape))
rest = viewer.session.handles()[h].copy()
state(handle=[float(c) for c in viewer.handle_pixels()[h]], size=list(viewer.size))""",
    """state(moved=float(np.linalg.norm(viewer.session.handles()[h] - rest)))""",
]


def _notebook(folder: Path) -> Path:
    nb = {
        "cells": [
            {"cell_type": "code", "metadata": {}, "source": c, "outputs": [], "id": f"c{i}"}
            | {"execution_count": None}
            for i, c in enumerate(CELLS)
        ],
        "metadata": {"kernelspec": {"name": "voxwarp", "display_name": "voxwarp"}},
        "nbformat": 4,
        "nbformat_minor": 5,
    }
    path = folder / "viewer_check.ipynb"
    path.write_text(json.dumps(nb))
    return path


def _kernel(folder: Path, python: str) -> None:
    spec = folder / "share" / "jupyter" / "kernels" / "voxwarp"
    spec.mkdir(parents=True)
    argv = [python, "-m", "ipykernel_launcher", "-f", "{connection_file}"]
    (spec / "kernel.json").write_text(json.dumps({"argv": argv, "display_name": "voxwarp"}))


def _run_cell(page, index: int) -> dict:
    cell = page.locator(".jp-Cell").nth(index)
    cell.click()
    page.keyboard.press("Shift+Enter")
    time.sleep(3)
    text = cell.locator(".jp-OutputArea-output").all_inner_texts()
    return json.loads(text[-1].strip().splitlines()[-1])


def _drag(page, start: tuple[float, float], steps: list[tuple[float, float]]) -> None:
    page.mouse.move(*start)
    page.mouse.down()
    for p in steps:
        page.mouse.move(*p)
        time.sleep(0.06)
    page.mouse.up()
    time.sleep(3)


def _box(view) -> dict:
    """The view's box on the page now (running a cell may have scrolled the notebook)."""
    view.scroll_into_view_if_needed()
    time.sleep(0.5)
    return view.bounding_box()


def check(page, out: Path) -> list[str]:
    """Drive the notebook; returns the failed checks."""
    failed: list[str] = []
    page.locator(".jp-Cell").first.click()
    page.keyboard.press("Shift+Enter")
    view = page.locator(".jp-Cell").first.locator(".jp-OutputArea-output img").last
    view.wait_for(timeout=120_000)
    time.sleep(4)
    box = view.bounding_box()
    page.screenshot(path=str(out / "1_shown.png"), clip=box)
    first = _run_cell(page, 1)
    if first["sent"] < 1:
        failed.append("no frame reached the browser")
    x0, y0 = box["x"] + 12, box["y"] + 12  # a corner: no handle, the drag orbits
    _drag(page, (x0, y0), [(x0 + 8 * i, y0 + 2 * i) for i in range(1, 11)])
    page.screenshot(path=str(out / "2_orbited.png"), clip=box)
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    page.mouse.wheel(0, -300)
    time.sleep(3)
    page.screenshot(path=str(out / "3_zoomed.png"), clip=box)
    second = _run_cell(page, 1)
    box = _box(view)
    if second["rotation"] == first["rotation"]:
        failed.append("the mouse drag did not orbit the camera")
    if not second["distance"] < first["distance"]:
        failed.append("the wheel did not zoom in")
    setup = _run_cell(page, 2)
    box = _box(view)
    (hx, hy), (w, h) = setup["handle"], setup["size"]
    sx, sy = box["x"] + hx * box["width"] / w, box["y"] + hy * box["height"] / h
    _drag(page, (sx, sy), [(sx, sy - 4 * i) for i in range(1, 11)])
    page.screenshot(path=str(out / "4_dragged.png"), clip=box)
    dragged = _run_cell(page, 3)
    if dragged["undo"] != ["Drag"] or dragged["moved"] < 3.0:
        failed.append(f"the handle drag did not move the element: {dragged}")
    box = _box(view)
    page.mouse.click(box["x"] + 5, box["y"] + 5)  # focus the view
    page.keyboard.press("Control+z")
    time.sleep(3)
    undone = _run_cell(page, 3)
    if undone["undo"] != [] or undone["moved"] > 1e-6:
        failed.append(f"Ctrl+Z did not undo the drag: {undone}")
    page.screenshot(path=str(out / "5_undone.png"), clip=box)
    print(json.dumps({"first": first, "after": second, "dragged": dragged, "undone": undone}))
    return failed


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kernel-python", required=True, help="voxwarp's Python (its venv)")
    ap.add_argument("--chromium", default="/usr/bin/chromium")
    ap.add_argument("--out", type=Path, default=Path("browser_check"))
    ap.add_argument("--port", type=int, default=8899)
    args = ap.parse_args()
    from playwright.sync_api import sync_playwright

    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        _kernel(work, str(Path(args.kernel_python).absolute()))
        _notebook(work)
        env = {**os.environ, "JUPYTER_PATH": str(work / "share" / "jupyter")}
        server = subprocess.Popen(
            [sys.executable, "-m", "jupyterlab", "--no-browser", f"--port={args.port}",
             "--ServerApp.token=check", f"--ServerApp.root_dir={work}", "--allow-root"],
            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        try:
            time.sleep(8)
            with sync_playwright() as p:
                browser = p.chromium.launch(executable_path=args.chromium, args=["--no-sandbox"])
                page = browser.new_page(viewport={"width": 1100, "height": 900})
                url = f"http://localhost:{args.port}/lab/tree/viewer_check.ipynb?token=check"
                page.goto(url)
                page.wait_for_selector(".jp-Notebook", timeout=60_000)
                time.sleep(5)
                failed = check(page, args.out)
                browser.close()
        finally:
            server.terminate()
            server.wait(30)
    for f in failed:
        print(f"FAILED: {f}", file=sys.stderr)
    print(f"screenshots in {args.out}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
