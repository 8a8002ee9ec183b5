"""``--fixed FILE`` of ``voxwarp slice`` and ``voxwarp render`` (a subprocess each).

Oracles: the moving image is a RAS NIfTI; the fixed image holds the same voxels written
in LPS voxel order (flipped x and y, affine to match), so it lies at the same world
points: ``slice --show difference`` then has no red and no blue anywhere (R == B),
while a fixed image with other values does. ``slice --show rest`` with ``--fixed`` is the
fixed image (nearest, grey = value), which equals the moving slice here. ``render
--save-scene`` stores the fixed file relative to the scene and the comparison settings,
and ``--show`` without a fixed image is a one-line error.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.run_cli import run_cli
from voxwarp.io.images import read_image

SHAPE = (12, 10, 8)


def _nifti(path: Path, data: np.ndarray, affine: np.ndarray) -> Path:
    import nibabel as nib

    img = nib.Nifti1Image(data, affine)
    img.set_sform(affine, code=1)
    img.set_qform(affine, code=1)
    nib.save(img, str(path))
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("compare_cli")
    rng = np.random.default_rng(5)
    data = rng.integers(16, 240, SHAPE).astype(np.uint8)
    ras = np.diag([2.0, 2.0, 3.0, 1.0])
    ras[:3, 3] = (-11.0, -9.0, -10.5)
    # LPS voxel order: i runs towards -x, j towards -y; the same world points
    lps = ras.copy()
    lps[0, 0], lps[1, 1] = -2.0, -2.0
    lps[0, 3] = ras[0, 3] + 2.0 * (SHAPE[0] - 1)
    lps[1, 3] = ras[1, 3] + 2.0 * (SHAPE[1] - 1)
    return {
        "moving": _nifti(d / "moving.nii.gz", data, ras),
        "fixed": _nifti(d / "fixed_lps.nii.gz", np.ascontiguousarray(data[::-1, ::-1]), lps),
        "other": _nifti(d / "other.nii.gz", rng.integers(16, 240, SHAPE).astype(np.uint8), ras),
        "dir": d,
    }


def _slice(files: dict[str, Path], fixed: str, show: str) -> np.ndarray:
    out = files["dir"] / f"{fixed}_{show}.png"
    res = run_cli(
        "slice", str(files["moving"]), "--fixed", str(files[fixed]), "--show", show,
        "--interpolation", "nearest", "--window", "127.5,255", "-o", str(out),
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    return read_image(out)[..., :3].astype(int)


@pytest.mark.slow
def test_slice_difference_of_the_same_data_on_another_grid_is_empty(files: dict) -> None:
    same = _slice(files, "fixed", "difference")
    assert np.array_equal(same[..., 0], same[..., 2])
    other = _slice(files, "other", "difference")
    assert (other[..., 0] > other[..., 2] + 20).any()
    rest = _slice(files, "fixed", "rest")
    run = run_cli(
        "slice", str(files["moving"]), "--interpolation", "nearest", "--window", "127.5,255",
        "-o", str(files["dir"] / "moving.png"),
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    moving = read_image(files["dir"] / "moving.png")[..., :3].astype(int)
    assert np.array_equal(rest, moving)


@pytest.mark.slow
def test_render_saves_the_comparison_and_refuses_show_alone(files: dict) -> None:
    scene = files["dir"] / "scene.json"
    res = run_cli(
        "render", str(files["moving"]), "--fixed", str(files["fixed"]), "--show", "blend",
        "--blend", "0.25", "--size", "32x32", "-o", str(files["dir"] / "r.png"),
        "--save-scene", str(scene),
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    d = json.loads(scene.read_text())
    assert d["fixed"]["path"] == "fixed_lps.nii.gz"
    assert d["compare"] == {"show": "blend", "blend": 0.25, "checker_mm": None}
    bad = run_cli("render", str(files["moving"]), "--show", "difference", "-o", "x.png")
    assert bad.returncode != 0
    assert "give --fixed FILE" in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1
    worse = run_cli("slice", str(files["moving"]), "--fixed", "x.png", "--blend", "2")
    assert worse.returncode != 0
    assert "--blend must be a number in 0..1" in worse.stderr
