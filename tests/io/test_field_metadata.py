"""``save_displacement_field(..., metadata)``: what an export measured, read back by each
format's own library (nibabel, pynrrd, SimpleITK, numpy), and the vectors unchanged."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.io.fields import load_displacement_field, save_displacement_field

NOTES = {"max_error_mm": "0.123", "tolerance_mm": "0.5", "outside_nodes": "42", "torn_nodes": "7"}


@pytest.fixture
def field() -> DisplacementFieldWarp:
    u = np.random.default_rng(3).normal(size=(5, 4, 3, 3)).astype(np.float32)
    return DisplacementFieldWarp(u, np.diag([2.0, 2.0, 3.0, 1.0]))


def _read_notes(path: Path) -> dict[str, str]:
    name = path.name
    if name.endswith(".nii.gz"):
        import nibabel as nib

        text = nib.load(str(path)).header["descrip"].item().decode()
        assert text.startswith("voxwarp ")
        return dict(pair.split("=") for pair in text.split()[1:])
    if name.endswith(".nrrd"):
        import nrrd

        header = nrrd.read_header(str(path))
        return {k[8:]: v for k, v in header.items() if k.startswith("voxwarp_")}
    if name.endswith(".npz"):
        with np.load(path) as npz:
            return {k[8:]: str(npz[k]) for k in npz.files if k.startswith("voxwarp_")}
    sitk = pytest.importorskip("SimpleITK")
    image = sitk.ReadImage(str(path))
    return {
        k[8:]: image.GetMetaData(k) for k in image.GetMetaDataKeys() if k.startswith("voxwarp_")
    }


@pytest.mark.parametrize("suffix", [".nii.gz", ".nrrd", ".npz", ".mha"])
def test_metadata_is_recorded_and_the_vectors_are_unchanged(
    field: DisplacementFieldWarp, tmp_path: Path, suffix: str
) -> None:
    if suffix == ".mha":
        pytest.importorskip("SimpleITK")
    path = save_displacement_field(field, tmp_path / f"f{suffix}", NOTES)
    assert _read_notes(path) == NOTES
    back = load_displacement_field(path)
    np.testing.assert_allclose(back.displacements, field.displacements, atol=1e-6)
    np.testing.assert_allclose(back.affine, field.affine, atol=1e-6)


def test_without_metadata_nothing_is_added(field: DisplacementFieldWarp, tmp_path: Path) -> None:
    path = save_displacement_field(field, tmp_path / "f.npz")
    with np.load(path) as npz:
        assert sorted(npz.files) == ["affine", "displacement", "space", "units"]
