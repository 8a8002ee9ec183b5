"""The default pixel grid of a named plane sits on the voxel grid (issue 32, item 7).

Oracle: nibabel. Each input is a NIfTI file whose affine permutes and flips the axes
(RAS, LPS, LIA) with even and odd axis lengths. The default ``voxwarp slice`` of a named
plane (linear interpolation, native pixel size, no warp) must put every pixel centre
that falls inside the volume on a voxel centre of the *file* (``inv(affine)`` of the
pixel's world point, from ``--json``, is an integer index) and show that voxel's value
(uint8 data through ``--window 127.5,255``: grey = value), covering the whole array slice
once. For RAS input it is also compared with the radiologically flipped array slice.
Before the change the grid sat half a voxel off, a linear slice averaged 2x2 voxels and
every one of these comparisons failed.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from voxwarp.cli.main import main
from voxwarp.io.images import read_image

#: file axis directions of each orientation code (RAS world unit vectors)
_DIRS = {"R": (1, 0, 0), "L": (-1, 0, 0), "A": (0, 1, 0), "P": (0, -1, 0), "S": (0, 0, 1)}
_DIRS["I"] = (0, 0, -1)
PLANES = {"axial": 2, "coronal": 1, "sagittal": 0}


@pytest.fixture(autouse=True)
def _keep_warning_state(monkeypatch: pytest.MonkeyPatch) -> None:
    """main() replaces warnings.formatwarning for good; undo it after each test."""
    monkeypatch.setattr(warnings, "formatwarning", warnings.formatwarning)


def _nifti(path: Path, code: str, shape: tuple[int, int, int], spacing: float) -> Any:
    import nibabel as nib

    rng = np.random.default_rng(sum(map(ord, code)) + sum(shape))
    data = rng.integers(16, 240, shape).astype(np.uint8)
    affine = np.eye(4)
    for i, letter in enumerate(code):
        affine[:3, i] = np.asarray(_DIRS[letter], float) * spacing
    affine[:3, 3] = (-7.0, 11.0, 3.0)
    img = nib.Nifti1Image(data, affine)
    img.set_sform(affine, code=1)
    img.set_qform(affine, code=1)
    nib.save(img, str(path))
    return img


def _slice(src: Path, out: Path, plane: str, capsys: pytest.CaptureFixture) -> tuple:
    args = ["slice", str(src), "-o", str(out), "--json", "--plane", plane]
    assert main([*args, "--window", "127.5,255"]) == 0
    doc = json.loads(capsys.readouterr().out)
    return read_image(out)[..., 0].astype(np.int64), doc


def _file_indices(doc: dict, affine: np.ndarray) -> np.ndarray:
    """(H, W, 3) file indices of each pixel centre (continuous)."""
    w, h = doc["size"]
    cols, rows = np.meshgrid(np.arange(w), np.arange(h))
    pix = np.stack([cols, rows, np.zeros_like(cols), np.ones_like(cols)], -1).astype(float)
    world = pix @ np.asarray(doc["pixel_to_world"]).T
    return (world @ np.linalg.inv(affine).T)[..., :3]


def _radiological(data: np.ndarray, plane: str, k: int) -> np.ndarray:
    """The array slice of a RAS file as the radiological image shows it."""
    if plane == "axial":
        return data[::-1, ::-1, k].T
    if plane == "coronal":
        return data[::-1, k, ::-1].T
    return data[k, ::-1, ::-1].T


@pytest.mark.parametrize("code", ["RAS", "LPS", "LIA"])
@pytest.mark.parametrize("shape", [(9, 7, 5), (10, 8, 6)], ids=["odd", "even"])
def test_default_named_slice_is_the_array_slice(
    gl_ctx: Any, tmp_path: Path, capsys: pytest.CaptureFixture, code: str, shape: tuple
) -> None:
    src = tmp_path / f"{code}.nii.gz"
    img = _nifti(src, code, shape, 2.0)
    data = np.asarray(img.dataobj)
    for plane in PLANES:
        grey, doc = _slice(src, tmp_path / f"{plane}.png", plane, capsys)
        idx = _file_indices(doc, img.affine)
        inside = np.all((idx > -0.5) & (idx < np.array(shape) - 0.5), axis=-1)
        on_voxels = np.abs(idx[inside] - np.round(idx[inside]))
        assert on_voxels.max() < 1e-6, f"{code} {plane}: pixels between voxels"
        near = np.round(idx[inside]).astype(int)
        np.testing.assert_array_equal(grey[inside], data[tuple(near.T)], err_msg=plane)
        # the whole array slice, each voxel once: one file axis constant, two spanned
        fixed = [a for a in range(3) if np.ptp(near[:, a]) == 0]
        assert len(fixed) == 1, f"{code} {plane}: not one voxel plane"
        spanned = [shape[a] for a in range(3) if a != fixed[0]]
        assert len({tuple(v) for v in near}) == inside.sum() == spanned[0] * spanned[1]
        assert np.all(grey[~inside] == 0)  # the margin around it is empty
        if code == "RAS":  # radiological: data[::-1, ::-1, k].T and so on
            rows, cols = np.nonzero(inside)
            box = grey[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1]
            want = _radiological(data, plane, int(near[0, PLANES[plane]]))
            np.testing.assert_array_equal(box, want)


def test_default_position_is_a_voxel_centre(
    gl_ctx: Any, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """Even lengths put the box centre between two voxels: ``--at`` defaults to one of
    them, not to the midpoint (which would average the two planes)."""
    src = tmp_path / "even.nii.gz"
    img = _nifti(src, "LPS", (6, 8, 10), 2.0)
    for plane in PLANES:
        _, doc = _slice(src, tmp_path / f"{plane}.png", plane, capsys)
        centre = np.r_[doc["center"], 1.0] @ np.linalg.inv(img.affine).T
        depth = np.abs(centre[:3] - np.round(centre[:3]))
        axis = int(np.argmax(np.abs(np.linalg.inv(img.affine)[:3, PLANES[plane]])))
        assert depth[axis] < 1e-6, f"{plane}: between voxel planes ({centre[:3]})"
