"""4-D and multi-channel inputs load one time point or channel (voxwarp.io.frames).

Oracles: the array a file was written from (nibabel, pynrrd, tifffile, NumPy), the same
frame written by nibabel as a 3-D file and read by voxwarp (voxels and affine), and
SimpleITK's own component selection (``VectorIndexSelectionCast``) of a vector image.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.run_cli import run_cli
from voxwarp.errors import VolumeError
from voxwarp.io.frames import FRAME, FrameChoiceError
from voxwarp.io.volumes import load_volume

nib = pytest.importorskip("nibabel")

#: An LIA-like affine (x from -i, y from k, z from -j) with anisotropic voxels: the frame
#: is reoriented to RAS as a 3-D file would be.
LIA = np.array([[-1.5, 0, 0, 40.0], [0, 0, 2.0, -30.0], [0, -2.5, 0, 25.0], [0, 0, 0, 1]])


def _bold(tmp_path: Path, frames: int = 5, dtype: type = np.int16) -> tuple[Path, np.ndarray]:
    """A 4-D NIfTI time series with distinct voxels per frame, TR 2 s, and its array."""
    data = np.arange(4 * 5 * 6 * frames, dtype=dtype).reshape(4, 5, 6, frames)
    img = nib.Nifti1Image(data, LIA)
    img.header.set_xyzt_units("mm", "sec")
    img.header["pixdim"][4] = 2.0
    path = tmp_path / "bold.nii.gz"
    nib.save(img, str(path))
    return path, data


def test_nifti_frame_equals_the_same_frame_written_as_3d(tmp_path: Path) -> None:
    path, data = _bold(tmp_path)
    for k in (0, 3, 4):
        three = tmp_path / f"frame{k}.nii.gz"
        nib.save(nib.Nifti1Image(data[..., k], LIA), str(three))
        got, want = load_volume(path, frame_index=k), load_volume(three)
        np.testing.assert_array_equal(got.data, want.data)
        np.testing.assert_allclose(got.affine, want.affine, atol=1e-9)
        assert got.frame_choice == {"frame_index": k}
    # and the voxels are the array's frame, reoriented as the affine says (LIA -> RAS)
    ras = load_volume(path, frame_index=2).data
    np.testing.assert_array_equal(ras, data[..., 2][::-1].transpose(0, 2, 1)[:, :, ::-1])


def test_nifti_without_a_frame_names_the_count_the_option_and_the_step(tmp_path: Path) -> None:
    path, _ = _bold(tmp_path, frames=180, dtype=np.uint8)
    with pytest.raises(FrameChoiceError) as info:
        load_volume(path)
    assert str(info.value) == (
        "bold.nii.gz holds 180 time points; pick one with --frame-index 0..179"
        " (or load_volume(..., frame_index=))"
    )
    (axis,) = info.value.axes
    assert (axis.kind, axis.size, axis.step, axis.unit) == (FRAME, 180, 2.0, "s")
    with pytest.raises(VolumeError, match=r"^--frame-index 180 is out of range: .* \(0\.\.179\)"):
        load_volume(path, frame_index=180)
    with pytest.raises(VolumeError, match="has no channels; leave --channel out"):
        load_volume(path, frame_index=0, channel=0)


def test_nifti_5d_frames_and_channels(tmp_path: Path) -> None:
    data = np.random.default_rng(1).integers(0, 999, (3, 4, 5, 2, 4)).astype(np.int16)
    nib.save(nib.Nifti1Image(data, np.eye(4)), str(tmp_path / "tc.nii"))
    with pytest.raises(FrameChoiceError, match=r"2 time points of 4 channels; .*--channel 0\.\.3"):
        load_volume(tmp_path / "tc.nii")
    vol = load_volume(tmp_path / "tc.nii", frame_index=1, channel=2)
    np.testing.assert_array_equal(vol.data, data[:, :, :, 1, 2])


def test_vector_intent_nifti_is_a_displacement_field(tmp_path: Path) -> None:
    from voxwarp.io.fields import load_displacement_field

    u = np.random.default_rng(2).normal(size=(4, 5, 6, 1, 3)).astype(np.float32)
    img = nib.Nifti1Image(u, np.diag([2.0, 2.0, 2.0, 1.0]))
    img.header.set_intent("vector")
    nib.save(img, str(tmp_path / "warp.nii.gz"))
    with pytest.raises(VolumeError) as info:
        load_volume(tmp_path / "warp.nii.gz")
    text = str(info.value)
    assert "is a displacement field (NIfTI intent vector)" in text
    assert "--displacement warp.nii.gz" in text
    assert "\n" not in text
    np.testing.assert_array_equal(
        load_volume(tmp_path / "warp.nii.gz", channel=2).data, u[:, :, :, 0, 2]
    )
    field = load_displacement_field(tmp_path / "warp.nii.gz")  # where it belongs: ITK LPS
    np.testing.assert_allclose(field.displacements, u[:, :, :, 0] * [-1.0, -1.0, 1.0])


def test_transform_file_points_to_displacement(tmp_path: Path) -> None:
    (tmp_path / "Composite.h5").write_bytes(b"\x89HDF\r\n\x1a\n")
    with pytest.raises(VolumeError, match=r"ITK transform file.*--displacement Composite.h5"):
        load_volume(tmp_path / "Composite.h5")


def test_nrrd_with_a_vector_or_list_axis(tmp_path: Path) -> None:
    nrrd = pytest.importorskip("nrrd")
    data = np.random.default_rng(3).normal(size=(2, 5, 6, 7)).astype(np.float32)
    nan = [np.nan] * 3
    header = {
        "kinds": ["vector", "domain", "domain", "domain"],
        "space": "right-anterior-superior",
        "space directions": np.array([nan, [1.0, 0, 0], [0, 2.0, 0], [0, 0, 3.0]]),
        "space origin": [1.0, 2.0, 3.0],
    }
    nrrd.write(str(tmp_path / "two.nrrd"), data, header, index_order="F")
    with pytest.raises(FrameChoiceError, match=r"two.nrrd holds 2 channels; .*--channel 0\.\.1"):
        load_volume(tmp_path / "two.nrrd")
    for c in (0, 1):
        vol = load_volume(tmp_path / "two.nrrd", channel=c)
        np.testing.assert_array_equal(vol.data, data[c])
        assert vol.spacing == (1.0, 2.0, 3.0)
        assert vol.origin == (1.0, 2.0, 3.0)
    # the same channels on the last axis, kinds 'list'
    last = np.moveaxis(data, 0, -1)
    header["kinds"] = ["domain", "domain", "domain", "list"]
    header["space directions"] = np.array([[1.0, 0, 0], [0, 2.0, 0], [0, 0, 3.0], nan])
    nrrd.write(str(tmp_path / "last.nrrd"), last, header, index_order="F")
    np.testing.assert_array_equal(load_volume(tmp_path / "last.nrrd", channel=1).data, data[1])


def test_nrrd_3_float_vector_axis_points_to_displacement(tmp_path: Path) -> None:
    nrrd = pytest.importorskip("nrrd")
    u = np.zeros((3, 4, 4, 4), np.float32)
    nan = [np.nan] * 3
    header = {
        "kinds": ["vector", "domain", "domain", "domain"],
        "space": "left-posterior-superior",
        "space directions": np.array([nan, [1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]]),
    }
    nrrd.write(str(tmp_path / "u.nrrd"), u, header, index_order="F")
    with pytest.raises(VolumeError, match=r"displacement field .*--displacement u.nrrd"):
        load_volume(tmp_path / "u.nrrd")


def test_simpleitk_vector_image_channel_is_the_component(tmp_path: Path) -> None:
    sitk = pytest.importorskip("SimpleITK")
    arr = np.random.default_rng(4).integers(0, 255, (7, 6, 5, 3)).astype(np.uint8)
    img = sitk.GetImageFromArray(arr, isVector=True)  # RGB-like: not a field
    img.SetSpacing((0.5, 1.5, 2.0))
    img.SetOrigin((10.0, -4.0, 3.0))
    img.SetDirection((0.0, 1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0))
    with pytest.raises(FrameChoiceError, match=r"holds 3 channels; pick one with --channel"):
        load_volume(img)
    sitk.WriteImage(img, str(tmp_path / "rgb.mha"))
    for c in range(3):
        want = load_volume(sitk.VectorIndexSelectionCast(img, c))
        for source in (img, tmp_path / "rgb.mha"):
            got = load_volume(source, channel=c)
            np.testing.assert_array_equal(got.data, want.data)
            np.testing.assert_allclose(got.affine, want.affine, atol=1e-9)


def test_simpleitk_4d_image_frame(tmp_path: Path) -> None:
    sitk = pytest.importorskip("SimpleITK")
    frames = [np.random.default_rng(k).normal(size=(4, 5, 6)).astype(np.float32) for k in range(3)]
    img = sitk.JoinSeries([sitk.GetImageFromArray(f) for f in frames])
    img.SetOrigin((1.0, 2.0, 3.0, 0.0))
    with pytest.raises(FrameChoiceError, match="3 time points"):
        load_volume(img)
    vol = load_volume(img, frame_index=1)
    np.testing.assert_array_equal(vol.data, frames[1].transpose(2, 1, 0)[::-1, ::-1])
    assert vol.origin == (-1.0 - 5.0, -2.0 - 4.0, 3.0)  # LPS -> RAS, x and y flipped


@pytest.mark.parametrize("order", ["xyz", "zyx"])
def test_numpy_4d_takes_either_option(tmp_path: Path, order: str) -> None:
    data = np.random.default_rng(5).normal(size=(3, 4, 5, 2)).astype(np.float32)  # x,y,z,t
    stored = data if order == "xyz" else data.transpose(3, 2, 1, 0)  # t,z,y,x
    np.save(tmp_path / "a.npy", stored)
    with pytest.raises(FrameChoiceError, match=r"2 volumes; .*--frame-index 0\.\.1 or --channel"):
        load_volume(tmp_path / "a.npy", axis_order=order)
    for kw in ({"frame_index": 1}, {"channel": 1}):
        vol = load_volume(tmp_path / "a.npy", axis_order=order, **kw)
        np.testing.assert_array_equal(vol.data, data[..., 1])


def test_tiff_hyperstack_time_and_channels(tmp_path: Path) -> None:
    tifffile = pytest.importorskip("tifffile")
    data = np.random.default_rng(6).integers(0, 999, (2, 4, 3, 6, 5)).astype(np.uint16)
    tifffile.imwrite(tmp_path / "h.tif", data, imagej=True, metadata={"axes": "TZCYX"})
    with pytest.raises(FrameChoiceError, match="2 time points of 3 channels"):
        load_volume(tmp_path / "h.tif")
    vol = load_volume(tmp_path / "h.tif", frame_index=1, channel=2)
    np.testing.assert_array_equal(vol.data, data[1, :, 2].transpose(2, 1, 0))


def test_hostile_shapes_are_one_line_errors(tmp_path: Path) -> None:
    empty = nib.Nifti1Image(np.zeros((4, 4, 4, 0), np.int16), np.eye(4))  # no frames
    nib.save(empty, str(tmp_path / "empty.nii"))
    six = nib.Nifti1Image(np.zeros((3, 3, 3, 2, 2, 2), np.int16), np.eye(4))
    nib.save(six, str(tmp_path / "six.nii"))
    for name, match in (("empty.nii", "length 0"), ("six.nii", "6-D image")):
        with pytest.raises(VolumeError, match=match) as info:
            load_volume(tmp_path / name, frame_index=0)
        assert "\n" not in str(info.value)
    with pytest.raises(VolumeError, match="length 0"):
        load_volume(np.zeros((3, 3, 3, 0)))
    with pytest.raises(VolumeError, match="frame_index must be an integer"):
        load_volume(np.zeros((3, 3, 3, 2)), frame_index=1.5)  # type: ignore[arg-type]


def test_a_3d_file_refuses_the_options(tmp_path: Path) -> None:
    nib.save(nib.Nifti1Image(np.zeros((3, 3, 3), np.int16), np.eye(4)), str(tmp_path / "v.nii"))
    with pytest.raises(VolumeError, match="has no time axis; leave --frame-index out"):
        load_volume(tmp_path / "v.nii", frame_index=0)
    with pytest.raises(VolumeError, match="has no channels"):
        load_volume("sample:fish", channel=0)


def test_scene_keeps_the_frame(tmp_path: Path) -> None:
    from voxwarp.scene import Scene

    path, _data = _bold(tmp_path)
    Scene(load_volume(path, frame_index=3)).save(tmp_path / "s.json")
    again = Scene.load(tmp_path / "s.json").volume
    np.testing.assert_array_equal(again.data, load_volume(path, frame_index=3).data)
    assert again.frame_choice == {"frame_index": 3}


def test_itk_python_image_loads_like_simpleitk() -> None:
    itk = pytest.importorskip("itk")
    sitk = pytest.importorskip("SimpleITK")
    rng = np.random.default_rng(7)
    arr = rng.normal(size=(4, 5, 6, 2)).astype(np.float32)  # z, y, x, component
    direction = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    image = itk.image_from_array(np.ascontiguousarray(arr), is_vector=True)
    ref = sitk.GetImageFromArray(arr, isVector=True)
    for img in (image, ref):
        img.SetSpacing((0.5, 1.0, 2.0))
        img.SetOrigin((3.0, -2.0, 1.0))
    image.SetDirection(itk.matrix_from_array(direction))
    ref.SetDirection(direction.ravel().tolist())
    with pytest.raises(FrameChoiceError, match="the ITK image holds 2 channels"):
        load_volume(image)
    for c in (0, 1):
        got, want = load_volume(image, channel=c), load_volume(ref, channel=c)
        np.testing.assert_array_equal(got.data, want.data)
        np.testing.assert_allclose(got.affine, want.affine)


def test_cli_error_lines_without_traceback(tmp_path: Path) -> None:
    path, _ = _bold(tmp_path)
    cases = (
        ((), "bold.nii.gz holds 5 time points; pick one with --frame-index 0..4"),
        (("--frame-index", "7"), "--frame-index 7 is out of range: bold.nii.gz holds 5"),
        (("--channel", "1"), "has no channels; leave --channel out"),
    )
    for extra, line in cases:
        proc = run_cli("info", str(path), *extra)
        assert proc.returncode != 0
        assert line in proc.stderr
        assert "Traceback" not in proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1
    proc = run_cli("info", str(path), "--frame-index", "4")
    assert proc.returncode == 0, proc.stderr


def test_info_of_three_time_points_names_both_readings(tmp_path: Path) -> None:
    """A 4-D NIfTI of 3 frames (no vector intent) may be a displacement field or a time
    series: ``info`` without options says how to ask for either; with --frame-index it
    describes that frame's volume (it used to ask for a field convention even then)."""
    path, data = _bold(tmp_path, frames=3)
    proc = run_cli("info", str(path))
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1
    assert "--field-convention" in proc.stderr
    assert "--frame-index" in proc.stderr
    proc = run_cli("info", str(path), "--frame-index", "2")
    assert proc.returncode == 0, proc.stderr
    low, high = int(data[..., 2].min()), int(data[..., 2].max())
    assert f"range:       [{low}, {high}]" in proc.stdout  # that frame's values
    assert low != int(data[..., 0].min())
