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
