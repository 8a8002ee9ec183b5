"""Execute every teaching notebook in notebooks/ headless (nbclient, a kernel on this
Python) and check what its outputs hold: no errors, the pictures, the viewer widget."""

from __future__ import annotations

import base64
import json
import sys
from pathlib import Path

import numpy as np
import pytest

NOTEBOOKS = Path(__file__).resolve().parents[2] / "notebooks"
CELL_TIMEOUT_S = 180
WIDGET = "application/vnd.jupyter.widget-view+json"
#: notebook -> least number of pictures (image/png outputs) it must show
MIN_PICTURES = {"mass_spring": 4, "chainmail": 4, "wires": 4, "lattice": 4, "registration": 2}

pytestmark = pytest.mark.slow


def test_every_notebook_is_checked() -> None:
    names = sorted(p.stem for p in NOTEBOOKS.glob("*.ipynb"))
    assert names == sorted(MIN_PICTURES)


def _kernel_manager(tmp_path: Path):
    """A kernel on this interpreter (not whatever 'python3' kernelspec the user has)."""
    from jupyter_client.kernelspec import KernelSpecManager
    from jupyter_client.manager import KernelManager

    spec = tmp_path / "kernels" / "voxwarp-test"
    spec.mkdir(parents=True)
    argv = [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"]
    spec.joinpath("kernel.json").write_text(
        json.dumps({"argv": argv, "display_name": "voxwarp test", "language": "python"})
    )
    ksm = KernelSpecManager(kernel_dirs=[str(spec.parent)])
    return KernelManager(kernel_name="voxwarp-test", kernel_spec_manager=ksm)


def _png_size(data: str) -> tuple[int, int]:
    raw = base64.b64decode(data)
    assert raw[:8] == b"\x89PNG\r\n\x1a\n"
    w, h = np.frombuffer(raw[16:24], dtype=">u4")
    return int(w), int(h)


@pytest.mark.parametrize("name", sorted(MIN_PICTURES))
def test_notebook_runs_and_shows_its_pictures(name: str, tmp_path: Path, gl_ctx: object) -> None:
    """(``gl_ctx``: skipped without headless OpenGL, failed with VOXWARP_REQUIRE_GL=1.)"""
    import nbformat
    from nbclient import NotebookClient

    path = NOTEBOOKS / f"{name}.ipynb"
    nb = nbformat.read(path, as_version=4)
    for cell in nb.cells:  # committed without outputs (reviewable as code)
        assert cell.cell_type != "code" or not cell.outputs, f"{path} has outputs"
    client = NotebookClient(
        nb,
        km=_kernel_manager(tmp_path),
        timeout=CELL_TIMEOUT_S,
        resources={"metadata": {"path": str(NOTEBOOKS)}},
    )
    client.execute()  # raises CellExecutionError naming the cell on any error

    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    stderr = "".join(o.text for o in outputs if o.output_type == "stream" and o.name == "stderr")
    assert "Traceback" not in stderr
    assert "no picture of the scene" not in stderr
    pictures = [o.data["image/png"] for o in outputs if "image/png" in o.get("data", {})]
    assert len(pictures) >= MIN_PICTURES[name]
    for png in pictures:
        w, h = _png_size(png)
        assert 64 <= min(w, h)
        assert max(w, h) <= 1024
    widgets = [o for o in outputs if WIDGET in o.get("data", {}) and "image/png" in o.data]
    assert len(widgets) == 1, "the Viewer cell shows the widget, with a PNG for static views"


LIVE_CELLS = [
    """\
import asyncio, json
import numpy as np
from voxwarp import Scene, load_sample
from voxwarp.notebook import Viewer

scene = Scene(load_sample("fish", shape=(64, 32, 28)), view="+z")
v = Viewer(scene, "massspring", resolution=5, size=(200, 150), anchor="corners")
v._has_visible_views = True  # what the browser reports once the view is on screen


def msg(**event):
    v._rfb_handle_msg(v, event, [])  # the path of a browser event (jupyter_rfb's comm handler)


async def confirm(seconds):
    for _ in range(int(seconds / 0.05)):  # the browser confirms each frame it shows
        v._frame_feedback = {"index": v._rfb_frame_index, "timestamp": 0, "localtime": 0}
        await asyncio.sleep(0.05)


msg(type="resize", width=200, height=150, pwidth=400, pheight=300, ratio=2.0, timestamp=0)
await confirm(0.5)
print(json.dumps({"resize_frames": v.get_stats()["sent_frames"]}))""",
    """\
g = v.session.model.grid
h = int(np.ravel_multi_index((3, 2, g.shape[2] - 1), g.shape))
x, y = (float(c) for c in v.handle_pixels()[h])
rest = v.session.handles()[h].copy()
press = dict(button=1, buttons=[1], modifiers=[])
msg(type="pointer_down", x=x, y=y, timestamp=1, **press)
for i in range(1, 5):
    msg(type="pointer_move", x=x, y=y - 5 * i, timestamp=1 + i, **press)
    await confirm(0.1)
msg(type="pointer_up", x=x, y=y - 20, button=1, buttons=[], modifiers=[], timestamp=9)
n0 = v.frames_drawn
await confirm(1.0)  # no more events: the running model asks for its own frames
print(json.dumps({
    "moved_mm": float(np.linalg.norm(v.session.handles()[h] - rest)),
    "frames_while_running": v.frames_drawn - n0,
    "undo": v.interaction.undo_texts,
}))
v.running = False  # pause: the view rests, the full-resolution frame follows
await confirm(0.8)
print(json.dumps({"rest_shape": list(v._rfb_last_frame.shape), "rest_scale": v.last_quality.scale}))
v.display()""",
]


def test_viewer_live_in_a_kernel(tmp_path: Path, gl_ctx: object) -> None:
    """The widget in a real kernel: browser events through jupyter_rfb's message handler,
    frames sent through its comm, the simulation drawing frames on its own."""
    from nbclient import NotebookClient
    from nbformat.v4 import new_code_cell, new_notebook

    nb = new_notebook(cells=[new_code_cell(c) for c in LIVE_CELLS])
    NotebookClient(nb, km=_kernel_manager(tmp_path), timeout=CELL_TIMEOUT_S).execute()
    outputs = [o for c in nb.cells for o in c.outputs]
    printed = [json.loads(o.text) for o in outputs if o.output_type == "stream"]
    assert printed[0]["resize_frames"] >= 1
    live = printed[1]
    assert live["moved_mm"] > 3.0
    assert live["undo"] == ["Drag"]
    assert live["frames_while_running"] >= 3
    assert printed[2] == {"rest_shape": [300, 400, 4], "rest_scale": 1.0}  # 2 device px per px
    shown = outputs[-1]
    assert WIDGET in shown.data
    assert "image/png" in shown.data
