"""Damaged, absurd or contradictory headers are refused or reported in one line, not
read as something else: a voxel size no scanner makes (a unit or header error), a
``space directions`` vector with a NaN in it (pynrrd's ``none`` is a whole row of NaN:
a non-spatial axis; a NaN inside a vector used to drop the orientation without a word),
a MetaImage whose data does not decompress (MetaIO returned the raw bytes as voxels),
and a NIfTI whose sform and qform place the volume in different places."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.run_cli import run_cli
from voxwarp.core import limits
from voxwarp.core.volume import Volume
from voxwarp.errors import VolumeError
from voxwarp.io.volumes import load_volume


def _nifti(path: Path, pixdim: tuple[float, float, float]) -> Path:
    import nibabel as nib

    img = nib.Nifti1Image(np.arange(4 * 5 * 6, dtype=np.uint8).reshape(4, 5, 6), None)
    img.header.set_zooms(pixdim)
    img.header.set_sform(None, code=0)
    img.header.set_qform(None, code=0)
    nib.save(img, str(path))
    return path


@pytest.mark.parametrize("spacing", [(1e30, 1.0, 1.0), (1.0, 1e-9, 1.0)])
def test_a_voxel_size_out_of_range_is_refused(tmp_path: Path, spacing: tuple) -> None:
    with pytest.raises(VolumeError, match="outside 1e-06 to 1e"):
        Volume(np.zeros((3, 3, 3), np.uint8), spacing=spacing)
    path = _nifti(tmp_path / "v.nii", spacing)
    proc = run_cli("render", str(path), "-o", str(tmp_path / "v.png"), "--size", "32x32")
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1, proc.stderr
    assert "--spacing" in proc.stderr
    assert not (tmp_path / "v.png").exists()
    given = ["--spacing", "1", "1", "1"]
    proc = run_cli("render", str(path), "-o", str(tmp_path / "v.png"), "--size", "32x32", *given)
    assert proc.returncode == 0, proc.stderr  # the fix the message names works
    edge = (limits.MIN_SPACING_MM, limits.MAX_SPACING_MM, 1.0)
    assert Volume(np.zeros((3, 3, 3), np.uint8), spacing=edge).spacing == edge


def _nrrd(folder: Path, directions: str) -> Path:
    (folder / "data.raw").write_bytes(bytes(range(8)) * 64)
    header = (
        "NRRD0004\ntype: uint8\ndimension: 3\nspace: left-posterior-superior\n"
        f"sizes: 8 8 8\nspace directions: {directions}\nspace origin: (0,0,0)\n"
        "encoding: raw\ndata file: data.raw\n\n"
    )
    path = folder / "v.nhdr"
    path.write_text(header)
    return path


@pytest.mark.parametrize("bad", ["(0,nan,0)", "(0,inf,0)"])
def test_a_space_direction_with_a_nan_is_refused(tmp_path: Path, bad: str) -> None:
    path = _nrrd(tmp_path, f"(1,0,0) {bad} (0,0,1)")
    with pytest.raises(VolumeError, match=r"'space directions' vector 2 is .*fix the header"):
        load_volume(path)
    good = load_volume(_nrrd(tmp_path, "(1,0,0) (0,2,0) (0,0,1)"))
    assert good.space == "RAS"
    np.testing.assert_allclose(good.spacing, (1.0, 2.0, 1.0))


def test_a_metaimage_that_does_not_decompress_is_refused(tmp_path: Path) -> None:
    """MetaIO prints "Uncompress failed" and hands back the undecoded bytes as voxels;
    voxwarp refuses the file in one line instead of showing them. A file that is
    compressed as its header says reads as written."""
    sitk = pytest.importorskip("SimpleITK")
    data = (np.arange(8 * 8 * 8) % 2 * 200).astype(np.uint8)
    (tmp_path / "data.raw").write_bytes(data.tobytes())
    header = (
        "ObjectType = Image\nNDims = 3\nDimSize = 8 8 8\nElementType = MET_UCHAR\n"
        "CompressedData = True\nElementDataFile = data.raw\n"
    )
    (tmp_path / "bad.mhd").write_text(header)
    with pytest.raises(VolumeError, match=r"Uncompress failed.*fix the header") as info:
        load_volume(tmp_path / "bad.mhd")
    assert "\n" not in str(info.value)
    good = tmp_path / "good.mha"
    sitk.WriteImage(sitk.GetImageFromArray(data.reshape(8, 8, 8)), str(good), True)
    np.testing.assert_array_equal(np.sort(np.unique(load_volume(good).data)), [0, 200])


def test_a_nifti_whose_qform_disagrees_with_its_sform_warns(tmp_path: Path) -> None:
    """voxwarp (as nibabel) takes the sform; a coded qform that places the volume
    elsewhere gets a one-line warning naming both (ITK-based tools may take the qform).
    A file whose two forms agree (as nibabel and voxwarp write them) reads silently."""
    import warnings

    import nibabel as nib

    data = np.zeros((6, 5, 4), np.int16)
    sform = np.diag([0.8, 0.8, 2.0, 1.0])
    qform = np.diag([-0.8, -0.8, 2.0, 1.0])  # x and y flipped: another patient orientation
    img = nib.Nifti1Image(data, None)
    img.header.set_sform(sform, code=2)
    img.header.set_qform(qform, code=1)
    nib.save(img, str(tmp_path / "two.nii"))
    apart = r"sform and the qform .* mm apart; voxwarp uses the sform"
    with pytest.warns(UserWarning, match=apart):
        vol = load_volume(tmp_path / "two.nii")
    np.testing.assert_allclose(vol.affine, sform)
    nib.save(nib.Nifti1Image(data, sform), str(tmp_path / "one.nii"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_volume(tmp_path / "one.nii")
