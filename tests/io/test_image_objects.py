"""SimpleITK and nibabel images load like their files; the affine/axis_order contract.

Oracles: the same image written to a file and read by :func:`load_volume`, and
SimpleITK's own ``TransformIndexToPhysicalPoint`` (LPS, so x and y change sign in RAS).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from voxwarp.errors import VolumeError
from voxwarp.io.volumes import load_volume

sitk = pytest.importorskip("SimpleITK")
nib = pytest.importorskip("nibabel")

SHAPE_ZYX = (7, 6, 5)


def _rotation(degrees: tuple[float, float, float]) -> np.ndarray:
    """A rotation about x, then y, then z (degrees)."""
    ax, ay, az = np.radians(degrees)
    rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
    ry = np.array([[np.cos(ay), 0, np.sin(ay)], [0, 1, 0], [-np.sin(ay), 0, np.cos(ay)]])
    rz = np.array([[np.cos(az), -np.sin(az), 0], [np.sin(az), np.cos(az), 0], [0, 0, 1]])
    return rz @ ry @ rx


def _sitk_oblique() -> object:
    """An int16 image with distinct voxels, anisotropic spacing, oblique LPS direction
    with a flipped axis."""
    arr = np.arange(np.prod(SHAPE_ZYX), dtype=np.int16).reshape(SHAPE_ZYX)
    img = sitk.GetImageFromArray(arr)
    img.SetSpacing((0.9, 1.3, 2.5))
    img.SetOrigin((12.0, -40.0, 7.5))
    direction = _rotation((10.0, -20.0, 25.0)) @ np.diag([1.0, -1.0, 1.0])
    img.SetDirection(direction.ravel().tolist())
    return img


def _assert_same(a: object, b: object) -> None:
    np.testing.assert_array_equal(a.data, b.data)
    np.testing.assert_allclose(a.affine, b.affine, atol=1e-5)
    assert a.space == b.space == "RAS"


def test_a_simpleitk_image_loads_as_its_file(tmp_path: Path) -> None:
    img = _sitk_oblique()
    sitk.WriteImage(img, str(tmp_path / "oblique.nrrd"))
    vol = load_volume(img)
    assert vol.name == vol.source == "SimpleITK image"
    assert vol.is_oblique
    _assert_same(vol, load_volume(tmp_path / "oblique.nrrd"))


def test_voxel_positions_agree_with_simpleitk() -> None:
    img = _sitk_oblique()
    arr = sitk.GetArrayFromImage(img)  # (z, y, x)
    vol = load_volume(img)
    inverse = np.linalg.inv(vol.affine)
    for index in [(0, 0, 0), (4, 5, 6), (1, 2, 3), (4, 0, 6), (2, 5, 0)]:
        x, y, z = img.TransformIndexToPhysicalPoint(index)
        ras = np.array([-x, -y, z, 1.0])
        ijk = inverse @ ras
        stored = tuple(int(v) for v in np.rint(ijk[:3]))
        np.testing.assert_allclose(ijk[:3], stored, atol=1e-6)
        assert vol.data[stored] == arr[index[2], index[1], index[0]]


@pytest.mark.parametrize(
    ("flips", "degrees"),
    [((1, 1, 1), (0, 0, 0)), ((-1, 1, 1), (5, 0, -12)), ((-1, -1, 1), (-8, 15, 30))],
    ids=["RAS", "LAS-oblique", "LPS-oblique"],
)
def test_a_nibabel_image_loads_as_its_file(
    tmp_path: Path, flips: tuple[int, int, int], degrees: tuple[float, float, float]
) -> None:
    data = np.arange(5 * 6 * 7, dtype=np.float32).reshape(5, 6, 7) - 20.0
    affine = np.eye(4)
    affine[:3, :3] = _rotation(degrees) @ np.diag(flips) @ np.diag([1.1, 0.8, 2.0])
    affine[:3, 3] = (-30.0, 12.5, 4.0)
    img = nib.Nifti1Image(data, affine)
    nib.save(img, str(tmp_path / "v.nii.gz"))
    from_file = load_volume(tmp_path / "v.nii.gz")
    vol = load_volume(img)
    assert vol.source == "nibabel image"
    _assert_same(vol, from_file)
    reread = load_volume(nib.load(str(tmp_path / "v.nii.gz")))
    assert reread.name == "v"  # the stem of the file it came from
    _assert_same(reread, from_file)
    world = vol.affine @ np.linalg.inv(from_file.affine)
    np.testing.assert_allclose(world, np.eye(4), atol=1e-5)


def test_scaled_and_mgh_nibabel_images(tmp_path: Path) -> None:
    data = np.arange(60, dtype=np.int16).reshape(3, 4, 5)
    affine = np.diag([-1.0, 1.0, 1.5, 1.0])
    img = nib.Nifti1Image(data, affine)
    img.header.set_slope_inter(0.5, -3.0)
    nib.save(img, str(tmp_path / "s.nii"))
    _assert_same(load_volume(nib.load(str(tmp_path / "s.nii"))), load_volume(tmp_path / "s.nii"))
    mgh = nib.MGHImage(data.astype(np.float32), affine)
    nib.save(mgh, str(tmp_path / "m.mgz"))
    vol = load_volume(nib.load(str(tmp_path / "m.mgz")))
    np.testing.assert_allclose(vol.affine, load_volume(nib.Nifti1Image(data, affine)).affine)
    assert vol.file_axes == "LAS"


def test_an_array_with_an_affine_follows_the_contract() -> None:
    """The affine maps the index of the array AS PASSED: a SimpleITK array (z, y, x)
    with its affine's columns reversed loads as the image itself."""
    img = _sitk_oblique()
    lps = _itk_index_affine(img)
    zyx = load_volume(
        sitk.GetArrayFromImage(img), affine=lps[:, [2, 1, 0, 3]], space="LPS", axis_order="zyx"
    )
    _assert_same(zyx, load_volume(img))


def _itk_index_affine(img: object) -> np.ndarray:
    """ITK's index (x, y, z) -> LPS world matrix of ``img``."""
    a = np.eye(4)
    a[:3, :3] = np.asarray(img.GetDirection()).reshape(3, 3) * np.asarray(img.GetSpacing())
    a[:3, 3] = img.GetOrigin()
    return a


def test_a_transposed_affine_and_axis_order_is_one_line() -> None:
    img = _sitk_oblique()
    lps = _itk_index_affine(img)
    with pytest.raises(VolumeError, match="disagree") as info:
        load_volume(
            sitk.GetArrayFromImage(img),
            affine=lps,  # indexes (x, y, z) while the array is (z, y, x)
            space="LPS",
            axis_order="zyx",
            spacing=img.GetSpacing(),
        )
    assert "\n" not in str(info.value)
    assert "affine[:, [2, 1, 0, 3]]" in str(info.value)
    with pytest.raises(VolumeError, match="not both"):  # consistent: the old refusal
        load_volume(sitk.GetArrayFromImage(img).T, affine=lps, spacing=img.GetSpacing())


def test_four_d_and_vector_images_without_a_choice_are_one_line_errors() -> None:
    """A 4-D or vector image needs frame_index=/channel= (voxwarp.io.frames); a float
    3-vector image is taken for a displacement field."""
    four = sitk.Image([4, 4, 4, 3], sitk.sitkFloat32)
    vector = sitk.Image([4, 4, 4], sitk.sitkVectorFloat32, 3)
    nib4 = nib.Nifti1Image(np.zeros((4, 4, 4, 3), np.float32), np.eye(4))
    cases = (
        (four, r"3 time points; pick one with --frame-index 0\.\.2"),
        (vector, "displacement field"),
        (nib4, r"3 time points; pick one with --frame-index 0\.\.2"),
    )
    for image, match in cases:
        with pytest.raises(VolumeError, match=match) as info:
            load_volume(image)
        assert "\n" not in str(info.value)


def test_image_objects_refuse_array_options() -> None:
    img = _sitk_oblique()
    with pytest.raises(VolumeError, match="axis_order"):
        load_volume(img, axis_order="zyx")
    with pytest.raises(VolumeError, match="affine="):
        load_volume(img, affine=np.eye(4))
