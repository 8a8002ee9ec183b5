"""``voxwarp slice/render --overlay grid,glyphs``, end to end in a child process.

Oracles: on an undeformed slice the grid lines sit on the pixels whose world point
(from ``--json``'s pixel -> world matrix) lies within half a pixel of a multiple of
``--grid-spacing`` in x or y, yellow there, and only near such points; the
render with the grid differs from the one without it, and a bad name is one line.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.run_cli import run_cli
from voxwarp.io.images import read_image

N = 6.0


@pytest.fixture(scope="module")
def volume_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    import nibabel as nib

    data = np.full((20, 18, 10), 60, np.uint8)
    affine = np.diag([1.5, 1.5, 2.0, 1.0])
    affine[:3, 3] = (-13.0, -11.0, -8.0)
    path = tmp_path_factory.mktemp("overlays") / "vol.nii.gz"
    nib.save(nib.Nifti1Image(data, affine), str(path))
    return path


def test_slice_grid_lines_at_multiples(gl_ctx: Any, volume_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "grid.png"
    proc = run_cli(
        "slice", str(volume_file), "-o", str(out), "--json", "--overlay", "grid",
        "--grid-spacing", str(N), "--window", "127.5,255", "--pixel", "0.5",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert f"lines every {N:g} mm" in proc.stderr
    doc = json.loads(proc.stdout)
    img = read_image(out)[..., :3].astype(int)
    h, w = img.shape[:2]
    cols, rows = np.meshgrid(np.arange(w), np.arange(h))
    pix = np.stack([cols, rows, 0 * cols, 0 * cols + 1], -1).astype(float)
    world = (pix @ np.asarray(doc["pixel_to_world"]).T)[..., :3]
    d_px = np.abs(world[..., :2] / N - np.round(world[..., :2] / N)) * N / doc["pixel_mm"]
    on = (d_px.min(axis=-1) <= 0.5 + 1e-6) & (img[..., 0] > 0)  # inside the volume
    grey = img[..., 2]
    assert on.sum() > 100
    assert np.all(img[on, 0] - img[on, 2] > 100)  # yellow on the lines
    far = d_px.min(axis=-1) > 1.3
    assert np.all(img[far, 0] == grey[far])  # grey (untouched) away from them


@pytest.mark.slow  # two renders in child processes (~7 s)
def test_render_grid_and_glyphs(gl_ctx: Any, volume_file: Path, tmp_path: Path) -> None:
    plain, grid = tmp_path / "plain.png", tmp_path / "grid.png"
    common = ["--size", "64x64", "--seed", "1"]
    assert run_cli("render", str(volume_file), "-o", str(plain), *common).returncode == 0
    proc = run_cli(
        "render", str(volume_file), "-o", str(grid), *common, "--overlay", "grid",
        "--overlay", "glyphs", "--grid-plane", "axial",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "grid, glyphs every" in proc.stderr
    diff = np.abs(read_image(grid).astype(int) - read_image(plain).astype(int)).max(axis=-1)
    assert (diff > 30).sum() > 20


def test_bad_overlay_is_one_line(tmp_path: Path, volume_file: Path) -> None:
    proc = run_cli("slice", str(volume_file), "-o", str(tmp_path / "x.png"), "--overlay", "gird")
    assert proc.returncode != 0
    assert "grid, glyphs" in proc.stderr
    assert "Traceback" not in proc.stderr
