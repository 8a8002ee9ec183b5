"""Tests of voxwarp.io.volumes: round trips, axis order, DICOM/TIFF folders, errors, info text."""

from __future__ import annotations

import io
import json
import os
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import nibabel as nib
import nrrd
import numpy as np
import pydicom
import pytest
import tifffile
from pydicom.dataset import FileDataset, FileMetaDataset
from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid

from voxwarp.core.volume import Volume
from voxwarp.errors import OutputError, VolumeError
from voxwarp.io.volumes import load_volume, save_volume, volume_info, volume_summary

DTYPES = ["uint8", "uint16", "int16", "float32"]
FORMATS = [".npz", ".raw", ".nrrd", ".nii", ".nii.gz", ".tif"]
SPACING = (0.5, 0.75, 1.25)
ORIGIN = (-10.5, 3.25, 7.0)


def asym(dtype: str = "int16") -> np.ndarray:
    """A (5, 6, 7) array of distinct values: 100*i + 10*j + k (uint8: 0..209 in C order)."""
    if dtype == "uint8":
        return np.arange(210, dtype=np.uint8).reshape(5, 6, 7)
    i, j, k = np.indices((5, 6, 7))
    return (100 * i + 10 * j + k).astype(dtype)  # 0 .. 456


def assert_geometry(vol: Volume, spacing=SPACING, origin=ORIGIN) -> None:
    np.testing.assert_allclose(vol.spacing, spacing, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(vol.origin, origin, rtol=1e-9, atol=1e-9)


def assert_same_voxels(vol: Volume, data: np.ndarray, ras_affine: np.ndarray) -> None:
    """Every file voxel ``data[i, j, k]`` sits at world ``ras_affine @ (i, j, k)`` in ``vol``
    (the oracle for voxwarp's lossless reorientation: values at the same RAS points)."""
    ijk = np.indices(data.shape).reshape(3, -1).T.astype(float)
    world = ijk @ ras_affine[:3, :3].T + ras_affine[:3, 3]
    stored = np.rint(vol.world_to_index(world)).astype(int)
    np.testing.assert_allclose(vol.world_to_index(world), stored, atol=1e-6)
    np.testing.assert_array_equal(
        vol.data[tuple(stored.T)],
        data.reshape(-1)[np.ravel_multi_index(ijk.T.astype(int), data.shape)],
    )


def lps_to_ras(affine: np.ndarray) -> np.ndarray:
    return np.diag([-1.0, -1.0, 1.0, 1.0]) @ affine


def diag_affine(spacing=SPACING, origin=ORIGIN) -> np.ndarray:
    a = np.diag([*spacing, 1.0])
    a[:3, 3] = origin
    return a


@contextmanager
def no_warnings() -> Iterator[None]:
    """Turn every warning into an error inside the block."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield


# ---------------------------------------------------------------------------- round trips
@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("ext", FORMATS)
def test_round_trip_every_format_and_dtype(tmp_path: Path, ext: str, dtype: str) -> None:
    data = asym(dtype)
    vol = Volume(data, SPACING, ORIGIN, name="x", units="HU")
    written = save_volume(vol, tmp_path / f"vol{ext}")
    assert written == tmp_path / f"vol{ext}"
    back = load_volume(written)
    assert back.dtype == np.dtype(dtype)
    assert back.shape == (5, 6, 7)
    np.testing.assert_array_equal(back.data, data)
    assert_geometry(back)
    assert back.name == "vol"
    assert back.source == str(written)
    if ext in (".npz", ".raw", ".nrrd", ".tif"):
        assert back.units == "HU"
    # atomic writes leave no temporary files behind
    leftovers = sorted(p.name for p in tmp_path.iterdir())
    expected = ["vol.raw", "vol.raw.json"] if ext == ".raw" else [f"vol{ext}"]
    assert leftovers == expected


def test_asym_values_are_distinct() -> None:
    for dtype in DTYPES:
        assert np.unique(asym(dtype)).size == 210


def test_save_overwrites_and_format_argument(tmp_path: Path) -> None:
    a = Volume(asym(), SPACING, ORIGIN)
    b = Volume(asym()[::-1].copy(), (1.0, 2.0, 3.0))
    target = save_volume(a, tmp_path / "out", format="nrrd")
    assert target.name == "out.nrrd"
    save_volume(b, target)
    back = load_volume(target)
    np.testing.assert_array_equal(back.data, b.data)
    assert back.spacing == (1.0, 2.0, 3.0)
    with pytest.raises(VolumeError, match="does not match"):
        save_volume(a, tmp_path / "x.npz", format="nrrd")
    with pytest.raises(VolumeError, match=r"\.nrrd"):
        save_volume(a, tmp_path / "x.xyz")
    with pytest.raises(VolumeError, match="unknown format"):
        save_volume(a, tmp_path / "x", format="png")


def test_failed_save_keeps_previous_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    old = Volume(asym(), SPACING, ORIGIN)
    target = save_volume(old, tmp_path / "v.nrrd")

    def broken_write(filename: str, *args, **kwargs) -> None:
        Path(filename).write_bytes(b"NRRD0005\npartial")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(nrrd, "write", broken_write)
    with pytest.raises(OutputError, match=r"cannot write .*: disk full"):
        save_volume(Volume(np.zeros((2, 2, 2), np.uint8)), target)
    monkeypatch.undo()
    assert [p.name for p in tmp_path.iterdir()] == ["v.nrrd"]  # temp file removed
    np.testing.assert_array_equal(load_volume(target).data, old.data)


def test_raw_sidecar_content_and_json_path(tmp_path: Path) -> None:
    vol = Volume(asym("uint16"), SPACING, ORIGIN, units="HU")
    raw = save_volume(vol, tmp_path / "scan.raw")
    meta = json.loads((tmp_path / "scan.raw.json").read_text())
    assert meta["dims"] == [5, 6, 7]
    assert meta["dtype"] == "uint16"
    assert meta["byte_order"] == "little"
    assert raw.stat().st_size == 210 * 2
    via_json = load_volume(tmp_path / "scan.raw.json")
    np.testing.assert_array_equal(via_json.data, vol.data)
    assert via_json.name == "scan"


# ---------------------------------------------------------------------------- axis order
def test_raw_written_by_hand_is_x_fastest(tmp_path: Path) -> None:
    data = asym("uint16")
    # big-endian with a 16-byte header, sidecar named vol.json
    (tmp_path / "vol.bin").write_bytes(b"H" * 16 + data.astype(">u2").tobytes(order="F"))
    sidecar = {
        "dims": [5, 6, 7],
        "dtype": "uint16",
        "spacing": list(SPACING),
        "origin": list(ORIGIN),
        "byte_order": "big",
        "header_bytes": 16,
        "units": "a.u.",
    }
    (tmp_path / "vol.json").write_text(json.dumps(sidecar))
    vol = load_volume(tmp_path / "vol.bin")
    np.testing.assert_array_equal(vol.data, data)
    assert vol.data[1, 2, 3] == 123  # x=1, y=2, z=3
    assert vol.units == "a.u."
    assert_geometry(vol)
    # the first nx values on disk are the row y=0, z=0
    first = np.frombuffer((tmp_path / "vol.bin").read_bytes()[16:26], ">u2")
    np.testing.assert_array_equal(first, [0, 100, 200, 300, 400])


def test_nrrd_written_by_pynrrd_keeps_xyz(tmp_path: Path) -> None:
    data = asym("int16")
    header = {
        "space": "left-posterior-superior",
        "space directions": np.diag(SPACING),
        "space origin": np.array(ORIGIN),
    }
    nrrd.write(str(tmp_path / "a.nrrd"), data, header, index_order="F")
    _, read_header = nrrd.read(str(tmp_path / "a.nrrd"), index_order="F")
    assert list(read_header["sizes"]) == [5, 6, 7]
    with no_warnings():
        vol = load_volume(tmp_path / "a.nrrd")
    # LPS file axes: stored flipped in x and y so that they run along RAS
    assert (vol.file_axes, vol.orientation, vol.space) == ("LPS", "RAS", "RAS")
    np.testing.assert_array_equal(vol.data, data[::-1, ::-1, :])
    assert_same_voxels(vol, data, lps_to_ras(diag_affine()))
    np.testing.assert_allclose(vol.spacing, SPACING)


def test_nrrd_permuted_directions_are_reoriented_without_warning(tmp_path: Path) -> None:
    dirs = np.array([[0.0, 2.0, 0.0], [1.0, 0.0, 0.0], [0, 0, 3.0]])  # rows: i -> +y, j -> +x
    header = {"space directions": dirs, "space": "right-anterior-superior"}
    nrrd.write(str(tmp_path / "r.nrrd"), asym(), header, index_order="F")
    with no_warnings():
        vol = load_volume(tmp_path / "r.nrrd")
    assert vol.file_axes == "ARS"
    assert vol.spacing == (1.0, 2.0, 3.0)
    assert not vol.is_oblique
    affine = np.eye(4)
    affine[:3, :3] = dirs.T
    assert_same_voxels(vol, asym(), affine)


def test_nrrd_spacings_field_and_vector_axis(tmp_path: Path) -> None:
    nrrd.write(str(tmp_path / "s.nrrd"), asym(), {"spacings": [0.5, 0.75, 1.25]}, index_order="F")
    assert load_volume(tmp_path / "s.nrrd").spacing == SPACING
    header = {
        "space": "left-posterior-superior",
        "space directions": np.array([[np.nan] * 3, *np.diag(SPACING)]),
        "kinds": ["vector", "domain", "domain", "domain"],
    }
    nrrd.write(str(tmp_path / "v.nrrd"), asym()[None], header, index_order="F")
    vol = load_volume(tmp_path / "v.nrrd")
    assert_same_voxels(vol, asym(), lps_to_ras(diag_affine(origin=(0, 0, 0))))
    assert vol.spacing == SPACING


def test_nifti_written_by_nibabel_keeps_xyz(tmp_path: Path) -> None:
    data = asym("int16")
    affine = np.diag([*SPACING, 1.0])
    affine[:3, 3] = ORIGIN
    nib.save(nib.Nifti1Image(data, affine), str(tmp_path / "a.nii.gz"))
    with no_warnings():
        vol = load_volume(tmp_path / "a.nii.gz")
    assert vol.name == "a"
    np.testing.assert_array_equal(vol.data, data)
    assert_geometry(vol)


def test_nifti_scaling_keeps_integers_and_trailing_singleton(tmp_path: Path) -> None:
    data = asym("int16")[..., None]  # (5, 6, 7, 1)
    img = nib.Nifti1Image(data, np.eye(4))
    img.header.set_slope_inter(2.0, -1024.0)
    nib.save(img, str(tmp_path / "s.nii"))
    vol = load_volume(tmp_path / "s.nii")
    assert vol.shape == (5, 6, 7)
    assert vol.dtype.kind == "i"
    np.testing.assert_array_equal(vol.data, 2 * asym("int16").astype(int) - 1024)
    img = nib.Nifti1Image(asym("int16"), np.eye(4))
    img.header.set_slope_inter(0.5, 0.25)
    nib.save(img, str(tmp_path / "f.nii"))
    vol = load_volume(tmp_path / "f.nii")
    assert vol.dtype == np.float32
    np.testing.assert_allclose(vol.data, 0.5 * asym("int16") + 0.25)


def test_nifti_rotated_affine_is_kept_as_an_oblique_direction(tmp_path: Path) -> None:
    theta = 0.3
    affine = np.eye(4)
    affine[:2, :2] = [[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]]
    affine[:3, :3] *= 1.5
    nib.save(nib.Nifti1Image(asym(), affine), str(tmp_path / "r.nii"))
    with no_warnings():
        vol = load_volume(tmp_path / "r.nii")
    assert vol.is_oblique
    assert vol.obliquity == pytest.approx(np.degrees(theta))
    np.testing.assert_allclose(vol.affine, affine, atol=1e-9)  # RAS already: data as is
    np.testing.assert_array_equal(vol.data, asym())


def test_nifti_sheared_affine_warns(tmp_path: Path) -> None:
    affine = np.eye(4)
    affine[0, 2] = 0.2  # k tilts towards x: a gantry tilt
    nib.save(nib.Nifti1Image(asym(), affine), str(tmp_path / "s.nii"))
    with pytest.warns(UserWarning, match="not orthogonal"):
        load_volume(tmp_path / "s.nii")


def test_tiff_multipage_written_by_tifffile_keeps_xyz(tmp_path: Path) -> None:
    data = asym("uint16")
    tifffile.imwrite(tmp_path / "stack.tif", data.transpose(2, 1, 0))  # pages = z
    np.testing.assert_array_equal(tifffile.imread(tmp_path / "stack.tif", key=0), data[:, :, 0].T)
    with no_warnings():
        vol = load_volume(tmp_path / "stack.tif")
    np.testing.assert_array_equal(vol.data, data)
    assert vol.spacing == (1.0, 1.0, 1.0)
    assert vol.origin == (0.0, 0.0, 0.0)


def test_tiff_imagej_calibration_in_microns(tmp_path: Path) -> None:
    tifffile.imwrite(
        tmp_path / "ij.tif",
        asym("uint8").transpose(2, 1, 0),
        imagej=True,
        resolution=(1 / 0.2, 1 / 0.4),
        metadata={"spacing": 2.0, "unit": "micron", "axes": "ZYX"},
    )
    vol = load_volume(tmp_path / "ij.tif")
    np.testing.assert_allclose(vol.spacing, (0.2e-3, 0.4e-3, 2.0e-3), rtol=1e-9)
    np.testing.assert_array_equal(vol.data, asym("uint8"))


def test_tiff_folder_natural_order(tmp_path: Path) -> None:
    i, j, k = np.indices((5, 6, 12))
    data = (100 * i + 10 * j + k).astype(np.uint16)
    folder = tmp_path / "slices"
    folder.mkdir()
    for z in range(12):  # slice_1 .. slice_12: lexicographic order would put 10 after 1
        tifffile.imwrite(folder / f"slice_{z + 1}.tif", data[:, :, z].T)
    with no_warnings():
        vol = load_volume(folder)
    assert vol.name == "slices"
    np.testing.assert_array_equal(vol.data, data)


def test_tiff_folder_rejects_mismatched_slices(tmp_path: Path) -> None:
    tifffile.imwrite(tmp_path / "a1.tif", np.zeros((6, 5), np.uint8))
    tifffile.imwrite(tmp_path / "a2.tif", np.zeros((7, 5), np.uint8))
    with pytest.raises(VolumeError, match="same size"):
        load_volume(tmp_path)


def test_tiff_rgb_needs_a_channel(tmp_path: Path) -> None:
    rgb = np.arange(4 * 6 * 5 * 3, dtype=np.uint8).reshape(4, 6, 5, 3)  # z, y, x, sample
    tifffile.imwrite(tmp_path / "rgb.tif", rgb, photometric="rgb")
    with pytest.raises(VolumeError, match=r"3 channels; pick one with --channel 0\.\.2"):
        load_volume(tmp_path / "rgb.tif")
    green = load_volume(tmp_path / "rgb.tif", channel=1)
    np.testing.assert_array_equal(green.data, rgb[..., 1].transpose(2, 1, 0))


def test_numpy_arrays_xyz_and_zyx(tmp_path: Path) -> None:
    data = asym("float32")
    assert load_volume(data).source is None
    np.testing.assert_array_equal(load_volume(data).data, data)
    zyx = data.transpose(2, 1, 0).copy()
    vol = load_volume(zyx, spacing=SPACING, origin=ORIGIN, axis_order="zyx")
    np.testing.assert_array_equal(vol.data, data)
    assert_geometry(vol)
    np.save(tmp_path / "z.npy", zyx)
    np.testing.assert_array_equal(load_volume(tmp_path / "z.npy", axis_order="zyx").data, data)
    np.save(tmp_path / "x.npy", data)
    np.testing.assert_array_equal(load_volume(tmp_path / "x.npy").data, data)


def test_npz_only_array_and_metadata_keys(tmp_path: Path) -> None:
    np.savez(tmp_path / "one.npz", asym())
    np.testing.assert_array_equal(load_volume(tmp_path / "one.npz").data, asym())
    np.savez(tmp_path / "m.npz", volume=asym(), spacing=np.array(2.0), units=np.array("HU"))
    vol = load_volume(tmp_path / "m.npz")
    assert vol.spacing == (2.0, 2.0, 2.0)
    assert vol.units == "HU"
    np.savez(tmp_path / "two.npz", a=asym(), b=asym())
    with pytest.raises(VolumeError, match="'data'"):
        load_volume(tmp_path / "two.npz")


def test_sample_names_go_to_app_samples(monkeypatch: pytest.MonkeyPatch) -> None:
    import voxwarp.io.samples

    def fake_sample(name: str) -> Volume:
        assert name == "tiny"
        return Volume(asym(), SPACING, name="tiny", source="sample:tiny", units="HU")

    monkeypatch.setattr(voxwarp.io.samples, "load_sample", fake_sample)
    vol = load_volume("sample:tiny", origin=ORIGIN)
    np.testing.assert_array_equal(vol.data, asym())
    assert_geometry(vol)
    assert (vol.name, vol.source, vol.units) == ("tiny", "sample:tiny", "HU")
    monkeypatch.undo()
    with pytest.raises(VolumeError, match="unknown sample"):
        load_volume("sample:no-such-sample")


def test_explicit_spacing_and_origin_override_file(tmp_path: Path) -> None:
    path = save_volume(Volume(asym(), SPACING, ORIGIN), tmp_path / "v.nrrd")
    vol = load_volume(path, spacing=2.0, origin=(1, 2, 3))
    assert vol.spacing == (2.0, 2.0, 2.0)
    assert vol.origin == (1.0, 2.0, 3.0)


# ---------------------------------------------------------------------------- DICOM
def write_dicom_slice(
    path: Path,
    pixels: np.ndarray,
    *,
    z: float | None,
    instance: int | None,
    series_uid: str,
    modality: str = "CT",
    frames: int = 1,
    description: str = "axial",
) -> None:
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = CTImageStorage
    meta.MediaStorageSOPInstanceUID = generate_uid()
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = FileDataset(str(path), {}, file_meta=meta, preamble=b"\0" * 128)
    ds.SOPClassUID = CTImageStorage
    ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
    ds.StudyInstanceUID = "1.2.3"
    ds.SeriesInstanceUID = series_uid
    ds.SeriesDescription = description
    ds.Modality = modality
    if instance is not None:
        ds.InstanceNumber = instance
    if z is not None:
        ds.ImagePositionPatient = [-20.0, 10.0, z]
        ds.ImageOrientationPatient = [1, 0, 0, 0, 1, 0]
    ds.PixelSpacing = [0.7, 0.5]  # (row spacing = sy, column spacing = sx)
    ds.SliceThickness = 1.5
    ds.Rows, ds.Columns = (int(n) for n in pixels.shape[-2:])
    if frames > 1:
        ds.NumberOfFrames = frames
        ds.SpacingBetweenSlices = 2.5
    ds.SamplesPerPixel = 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.BitsAllocated = 16
    ds.BitsStored = 16
    ds.HighBit = 15
    ds.PixelRepresentation = 0
    ds.RescaleSlope = 2
    ds.RescaleIntercept = -1024
    ds.PixelData = pixels.astype("<u2").tobytes()
    ds.save_as(path, enforce_file_format=True)


def dicom_expected() -> np.ndarray:
    """Stored values x + 10*y + 100*z for 10 columns (x), 8 rows (y), 6 slices (z)."""
    x, y, z = np.indices((10, 8, 6))
    return x + 10 * y + 100 * z


def write_series(folder: Path, *, positions: bool = True, uid: str = "1.2.3.4") -> None:
    stored = dicom_expected()
    rng = np.random.default_rng(0)
    names = rng.permutation(6)
    for k in range(6):
        write_dicom_slice(
            folder / f"IM{names[k]:03d}",  # shuffled names, no extension
            stored[:, :, k].T,  # (rows, cols) = (y, x)
            z=30.0 + 1.5 * k if positions else None,
            # instance numbers disagree with the positions: the positions must win
            instance=(6 - k) if positions else k + 1,
            series_uid=uid,
        )


def test_dicom_series_order_values_spacing_units(tmp_path: Path) -> None:
    folder = tmp_path / "ct"
    folder.mkdir()
    write_series(folder)
    (folder / "README.txt").write_text("not a DICOM file\n")
    with no_warnings():
        vol = load_volume(folder)
    assert vol.shape == (10, 8, 6)
    assert vol.dtype == np.int16
    # LPS patient axes (IOP 1,0,0,0,1,0): stored flipped in x and y, at the same points
    assert (vol.file_axes, vol.modality) == ("LPS", "CT")
    np.testing.assert_array_equal(vol.data, (2 * dicom_expected() - 1024)[::-1, ::-1, :])
    assert_same_voxels(
        vol, 2 * dicom_expected() - 1024, lps_to_ras(diag_affine((0.5, 0.7, 1.5), (-20, 10, 30)))
    )
    np.testing.assert_allclose(vol.spacing, (0.5, 0.7, 1.5))
    assert vol.units == "HU"
    assert vol.name == "ct"
    assert vol.source == str(folder)


def test_dicom_falls_back_to_instance_number(tmp_path: Path) -> None:
    write_series(tmp_path, positions=False)
    with no_warnings():  # no positions: InstanceNumber order, SliceThickness spacing
        vol = load_volume(tmp_path)
    np.testing.assert_array_equal(vol.data, 2 * dicom_expected() - 1024)
    assert vol.spacing[2] == pytest.approx(1.5)


def test_dicom_missing_slice_is_a_filled_slot_not_a_stretch(tmp_path: Path) -> None:
    """A missing slice leaves an empty slot (the series' lowest value), so the others
    keep their positions (before: 5 slices stacked at the median gap, shape (10, 8, 5))."""
    write_series(tmp_path)
    ds = {p: pydicom.dcmread(p, stop_before_pixels=True) for p in tmp_path.iterdir()}
    middle = next(p for p, d in ds.items() if float(d.ImagePositionPatient[2]) == 33.0)
    middle.unlink()  # z = 30, 31.5, _, 34.5, 36, 37.5
    with pytest.warns(UserWarning, match=r"1 slice\(s\) missing \(positions 3 of 1..6"):
        vol = load_volume(tmp_path)
    expected = 2 * dicom_expected() - 1024
    expected[:, :, 2] = expected[:, :, [0, 1, 3, 4, 5]].min()
    assert_same_voxels(vol, expected, lps_to_ras(diag_affine((0.5, 0.7, 1.5), (-20, 10, 30))))


def test_dicom_several_series_pick_largest(tmp_path: Path) -> None:
    write_series(tmp_path)
    write_dicom_slice(
        tmp_path / "other.dcm",
        np.zeros((4, 4)),
        z=0.0,
        instance=1,
        series_uid="9.9",
        description="scout",
    )
    with pytest.warns(UserWarning, match="scout"):
        vol = load_volume(tmp_path)
    assert vol.shape == (10, 8, 6)
    # choose the other one by index (as voxwarp info lists them) or by UID
    with no_warnings():
        assert load_volume(tmp_path, series=2).shape == (4, 4, 1)
        assert load_volume(tmp_path, series="9.9").shape == (4, 4, 1)
        assert load_volume(tmp_path, series="1.2.3.4").shape == (10, 8, 6)
    with pytest.raises(VolumeError, match=r"no DICOM series '3'.*1: 6 files.*2: 1 files"):
        load_volume(tmp_path, series=3)
    with pytest.raises(VolumeError, match="is a file"):
        load_volume(tmp_path / "other.dcm", series=1)


def test_info_lists_the_series_of_a_folder(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from voxwarp.cli.main import main

    write_series(tmp_path)
    write_dicom_slice(tmp_path / "other.dcm", np.zeros((4, 4)), z=0.0, instance=1, series_uid="9.9")
    assert main(["info", str(tmp_path), "--series", "2"]) == 0
    out = capsys.readouterr().out
    assert "dims:        (4, 4, 1)" in out
    assert "* 2: 1 files, 4x4, CT" in out
    assert "  1: 6 files, 10x8, CT" in out
    assert "orientation: LPS in the file" in out


def test_dicom_multiframe_file_and_single_slice(tmp_path: Path) -> None:
    stored = dicom_expected()[:, :, :4]
    write_dicom_slice(
        tmp_path / "mf.dcm",
        stored.transpose(2, 1, 0),
        z=None,
        instance=1,
        series_uid="5.5",
        modality="MR",
        frames=4,
    )
    vol = load_volume(tmp_path / "mf.dcm")
    np.testing.assert_array_equal(vol.data, 2 * stored - 1024)
    np.testing.assert_allclose(vol.spacing, (0.5, 0.7, 2.5))
    assert vol.units == ""
    write_dicom_slice(tmp_path / "one.dcm", stored[:, :, 0].T, z=0.0, instance=1, series_uid="6")
    with pytest.raises(VolumeError, match="single DICOM slice"):
        load_volume(tmp_path / "one.dcm")


def test_dicom_written_files_are_real_dicom(tmp_path: Path) -> None:
    write_series(tmp_path)
    files = sorted(tmp_path.iterdir())
    ds = pydicom.dcmread(files[0])
    assert ds.Modality == "CT"
    assert ds.pixel_array.shape == (8, 10)


# ---------------------------------------------------------------------------- bad input
def write_raw(tmp_path: Path, n_bytes: int, **meta) -> Path:
    (tmp_path / "v.raw").write_bytes(bytes(n_bytes))
    (tmp_path / "v.raw.json").write_text(json.dumps(meta))
    return tmp_path / "v.raw"


def test_truncated_raw(tmp_path: Path) -> None:
    path = write_raw(tmp_path, 100, dims=[5, 6, 7], dtype="uint16", spacing=[1, 1, 1])
    with pytest.raises(VolumeError, match=r"expected 420 bytes .* file has 100 bytes"):
        load_volume(path)


def test_raw_longer_than_dims_warns(tmp_path: Path) -> None:
    path = write_raw(tmp_path, 430, dims=[5, 6, 7], dtype="uint16")
    with pytest.warns(UserWarning, match="extra 10 bytes"):
        assert load_volume(path).shape == (5, 6, 7)


@pytest.mark.parametrize(
    "dims", [[5, 6], [5, 6, 0], [5, -6, 7], [5, 6, 7.5], "5x6x7", [5, True, 7]]
)
def test_raw_wrong_dims(tmp_path: Path, dims) -> None:
    path = write_raw(tmp_path, 420, dims=dims, dtype="uint16")
    with pytest.raises(VolumeError, match="'dims'"):
        load_volume(path)


@pytest.mark.parametrize("dtype", ["complex64", "float16", "O", 16, None])
def test_raw_unsupported_dtype(tmp_path: Path, dtype) -> None:
    path = write_raw(tmp_path, 420, dims=[5, 6, 7], dtype=dtype)
    with pytest.raises(VolumeError, match="unsupported dtype"):
        load_volume(path)


@pytest.mark.parametrize(
    ("key", "value"),
    [("spacing", "1mm"), ("spacing", [1, -1, 1]), ("byte_order", "middle"), ("header_bytes", -1)],
)
def test_raw_bad_sidecar_values(tmp_path: Path, key: str, value) -> None:
    path = write_raw(tmp_path, 420, dims=[5, 6, 7], dtype="uint16", **{key: value})
    with pytest.raises(VolumeError, match=key):
        load_volume(path)


def test_raw_bad_json_and_missing_sidecar(tmp_path: Path) -> None:
    (tmp_path / "v.raw").write_bytes(bytes(420))
    with pytest.raises(VolumeError, match="no JSON sidecar"):
        load_volume(tmp_path / "v.raw")
    (tmp_path / "v.raw.json").write_text("{dims: [5, 6, 7]")
    with pytest.raises(VolumeError, match="not valid JSON"):
        load_volume(tmp_path / "v.raw")
    (tmp_path / "v.raw.json").write_text("[5, 6, 7]")
    with pytest.raises(VolumeError, match="JSON object"):
        load_volume(tmp_path / "v.raw")


def test_nan_raise_and_mask() -> None:
    data = asym("float32")
    data[1, 2, 3] = np.nan
    data[0, 0, 1] = np.inf
    with pytest.raises(VolumeError, match="NaN"):
        load_volume(data)
    with pytest.warns(UserWarning, match="NaN"):
        vol = load_volume(data, nan_policy="mask")
    assert np.isfinite(vol.data).all()
    assert vol.data[1, 2, 3] == vol.data[0, 0, 1] == 0.0  # minimum finite value
    assert vol.data[4, 5, 6] == 456.0


def test_float64_overflow_is_caught_as_inf() -> None:
    data = np.ones((2, 2, 2))
    data[0, 0, 0] = 1e300  # becomes Inf in float32
    with pytest.raises(VolumeError, match="NaN/Inf"):
        load_volume(data)


def test_missing_file_and_unknown_extension(tmp_path: Path) -> None:
    with pytest.raises(VolumeError, match="no such file or directory"):
        load_volume(tmp_path / "nope.nrrd")
    (tmp_path / "a.png").write_bytes(b"\x89PNG")
    with pytest.raises(VolumeError, match=r"unsupported file type \.png.*\.nrrd"):
        load_volume(tmp_path / "a.png")


def test_empty_directory_and_text_files(tmp_path: Path) -> None:
    with pytest.raises(VolumeError, match="no DICOM files in"):
        load_volume(tmp_path)
    for n in range(3):
        (tmp_path / f"notes{n}.txt").write_text("hello " * n)
    with pytest.raises(VolumeError, match="no DICOM files in"):
        load_volume(tmp_path)


def test_nifti_4d_needs_a_frame(tmp_path: Path) -> None:
    nib.save(nib.Nifti1Image(np.zeros((4, 4, 4, 3), np.int16), np.eye(4)), str(tmp_path / "t.nii"))
    with pytest.raises(VolumeError, match=r"t.nii holds 3 time points; pick one with --frame"):
        load_volume(tmp_path / "t.nii")


@pytest.mark.parametrize("name", ["c.npz", "c.npy", "c.nrrd", "c.nii", "c.nii.gz", "c.tif"])
def test_corrupt_files(tmp_path: Path, name: str) -> None:
    (tmp_path / name).write_bytes(b"garbage, not a volume file" * 3)
    with pytest.raises(VolumeError, match="cannot read"):
        load_volume(tmp_path / name)


def test_truncated_nifti_and_pickled_npy(tmp_path: Path) -> None:
    save_volume(Volume(asym()), tmp_path / "v.nii")
    blob = (tmp_path / "v.nii").read_bytes()
    (tmp_path / "v.nii").write_bytes(blob[:400])
    with pytest.raises(VolumeError, match="NIfTI"):
        load_volume(tmp_path / "v.nii")
    np.save(tmp_path / "o.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(VolumeError, match="pickled"):
        load_volume(tmp_path / "o.npy")


def test_bad_arguments(tmp_path: Path) -> None:
    data = asym()
    with pytest.raises(VolumeError, match="axis_order"):
        load_volume(data, axis_order="yxz")  # type: ignore[arg-type]
    with pytest.raises(VolumeError, match="nan_policy"):
        load_volume(data, nan_policy="drop")  # type: ignore[arg-type]
    with pytest.raises(VolumeError, match="downsample"):
        load_volume(data, downsample=0)
    with pytest.raises(VolumeError, match="spacing"):
        load_volume(data, spacing=(1, 2))
    with pytest.raises(VolumeError, match="spacing"):
        load_volume(data, spacing="big")  # type: ignore[arg-type]
    with pytest.raises(VolumeError, match="3D"):
        load_volume(np.zeros((4, 4)))
    with pytest.raises(VolumeError, match="unsupported volume dtype"):
        load_volume(np.zeros((2, 2, 2), np.complex64))
    with pytest.raises(VolumeError, match="path or a NumPy array"):
        load_volume(42)  # type: ignore[arg-type]
    path = save_volume(Volume(data), tmp_path / "v.nrrd")
    with pytest.raises(VolumeError, match="own axis order"):
        load_volume(path, axis_order="zyx")


# ---------------------------------------------------------------------------- downsample, info
def test_downsample_halves_shape_doubles_spacing(tmp_path: Path) -> None:
    data = np.arange(8 * 6 * 4, dtype=np.float32).reshape(8, 6, 4)
    path = save_volume(Volume(data, (1.0, 2.0, 3.0)), tmp_path / "d.npz")
    with pytest.warns(UserWarning, match="downsampled by 2") as record:
        vol = load_volume(path, downsample=2)
    assert record[0].filename == __file__  # attributed to the caller, not to app/io/volumes.py
    assert vol.shape == (4, 3, 2)
    assert vol.spacing == (2.0, 4.0, 6.0)
    assert vol.data[0, 0, 0] == pytest.approx(data[:2, :2, :2].mean())
    with no_warnings():
        assert load_volume(path, downsample=1).shape == (8, 6, 4)


def test_volume_summary_and_info() -> None:
    vol = Volume(asym("int16"), SPACING, ORIGIN, name="head", units="HU")
    text = volume_summary(vol)
    assert "(5, 6, 7)" in text
    assert "int16" in text
    assert "head" in text
    assert "HU" in text
    hist_lines = [line for line in text.splitlines() if line.startswith("  [")]
    assert len(hist_lines) == 16
    info = volume_info(vol)
    counts = [int(line.split()[-1]) for line in hist_lines]
    assert counts == info["histogram"]["counts"]
    assert 0 in counts  # the values 100*i + 10*j + k leave gaps
    assert all(("#" in line) == (c > 0) for line, c in zip(hist_lines, counts, strict=True))
    decoded = json.loads(json.dumps(info))
    assert decoded["dims"] == [5, 6, 7]
    assert decoded["dtype"] == "int16"
    assert decoded["min"] == 0
    assert decoded["max"] == 456
    assert sum(decoded["histogram"]["counts"]) == 210
    assert len(decoded["histogram"]["edges"]) == 17
    assert decoded["percentiles"]["50"] == pytest.approx(np.percentile(asym(), 50))
    np.testing.assert_allclose(decoded["size_mm"], [2.5, 4.5, 8.75])
    # log-scaled bars: a bin with 1 voxel is much shorter than one with 200
    skewed = np.zeros((10, 10, 2), np.uint8)
    skewed[0, 0, 0] = 255
    lines = [line for line in volume_summary(Volume(skewed)).splitlines() if "#" in line]
    assert len(lines) == 2
    big, small = lines[0].count("#"), lines[1].count("#")
    assert big > 4 * small
    assert small >= 3  # log1p(1) / log1p(199) of the width; a linear bar would be 1/199


def test_volume_info_ignores_nonfinite() -> None:
    data = np.ones((2, 2, 2), np.float32)
    data[0, 0, 0] = np.nan
    info = volume_info(Volume(data))
    assert info["nonfinite"] == 1
    json.loads(json.dumps(info, allow_nan=False))


def test_loading_does_not_create_files(tmp_path: Path) -> None:
    path = save_volume(Volume(asym()), tmp_path / "v.tif")
    before = sorted(os.listdir(tmp_path))
    load_volume(path)
    assert sorted(os.listdir(tmp_path)) == before


@pytest.mark.parametrize(("degrees", "oblique"), [(2e-5, False), (0.05, True)])
def test_header_rounding_is_not_an_oblique_scan(degrees: float, oblique: bool) -> None:
    """A direction off the axes by header rounding (DICOM writes ImageOrientationPatient
    to ~6 digits) snaps to the axes; a real tilt, however small, stays oblique."""
    t = np.radians(degrees)
    affine = np.eye(4)
    affine[:2, :2] = [[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]]
    vol = load_volume(asym(), affine=affine)
    assert vol.is_oblique is oblique
    assert vol.obliquity == pytest.approx(degrees if oblique else 0.0, abs=1e-9)


def test_nifti_broken_sform_falls_back_with_a_warning(tmp_path: Path) -> None:
    """A coded sform that is singular or not finite is ignored with a warning (the
    qform, if coded, is used; here none): the volume loads without an orientation."""
    import struct

    img = nib.Nifti1Image(asym(), np.eye(4))
    img.set_sform(np.eye(4), code=1)
    img.set_qform(None, code=0)
    nib.save(img, str(tmp_path / "base.nii"))
    raw = bytearray((tmp_path / "base.nii").read_bytes())
    raw[280:296] = struct.pack("<4f", 0.0, 0.0, 0.0, 0.0)  # srow_x: a zero voxel axis
    (tmp_path / "bad.nii").write_bytes(bytes(raw))
    with pytest.warns(UserWarning, match="sform .code 1. is not a finite, invertible"):
        vol = load_volume(tmp_path / "bad.nii")
    assert (vol.space, vol.orientation) == ("", "")


@pytest.mark.parametrize(
    ("make", "message"),
    [
        ("nrrd_zero_axis", "not an invertible index -> world map"),
        ("npz_3x3", r"'affine' in .* must be a finite 4x4 matrix"),
        ("npz_space", r"'space' in .* must be 'RAS' or 'LPS'"),
        ("npz_both", "states both an 'affine' and 'spacing'"),
        ("sidecar_text", r"'affine' in vol.raw.json must be a 4x4 matrix of numbers"),
    ],
)
def test_bad_stated_geometry_is_one_clear_error(tmp_path: Path, make: str, message: str) -> None:
    d = asym()
    if make == "nrrd_zero_axis":
        dirs = np.array([[1.0, 0, 0], [0, 0, 0], [0, 0, 1.0]])
        header = {"space": "left-posterior-superior", "space directions": dirs}
        nrrd.write(str(tmp_path / "v.nrrd"), d, header, index_order="F")
        path = tmp_path / "v.nrrd"
    elif make.startswith("npz"):
        extra = {
            "npz_3x3": {"affine": np.eye(3)},
            "npz_space": {"affine": np.eye(4), "space": np.array("XYZ")},
            "npz_both": {"affine": np.eye(4), "spacing": np.ones(3)},
        }[make]
        np.savez(tmp_path / "v.npz", data=d, **extra)
        path = tmp_path / "v.npz"
    else:
        d.T.tofile(tmp_path / "vol.raw")
        side = {"dims": [5, 6, 7], "dtype": "int16", "affine": "eye"}
        (tmp_path / "vol.raw.json").write_text(json.dumps(side))
        path = tmp_path / "vol.raw"
    with pytest.raises(VolumeError, match=message):
        load_volume(path)


@pytest.mark.parametrize("writer", ["save_volume", "stream"])
def test_unoriented_nrrd_and_nifti_coincide_in_simpleitk(tmp_path: Path, writer: str) -> None:
    """A volume without patient orientation (npy, raw, TIFF, the samples) written as NRRD
    and as NIfTI: SimpleITK places every voxel of both at the same physical point (a NRRD
    without ``space`` is read as LPS, 180 degrees from the NIfTI), and voxwarp reads the
    NRRD back without a patient orientation and with the same geometry."""
    sitk = pytest.importorskip("SimpleITK")
    from voxwarp.io.volume_stream import write_volume_slices

    vol = Volume(asym(), spacing=(1.5, 2.0, 2.5), origin=(10.0, -20.0, 30.0))
    assert not vol.space
    for suffix in (".nrrd", ".nii.gz"):
        path = tmp_path / f"v{suffix}"
        if writer == "save_volume":
            save_volume(vol, path)
        else:
            slices = [np.asarray(vol.data)[:, :, k].T for k in range(vol.shape[2])]
            write_volume_slices(path, vol.affine, vol.shape, vol.dtype, slices, oriented=False)
    images = [sitk.ReadImage(str(tmp_path / f"v{s}")) for s in (".nrrd", ".nii.gz")]
    corners = [(0, 0, 0), (vol.shape[0] - 1, 1, 2), (1, vol.shape[1] - 1, vol.shape[2] - 1)]
    for index in corners:
        a, b = (np.asarray(im.TransformIndexToPhysicalPoint(index)) for im in images)
        np.testing.assert_allclose(a, b, atol=1e-9)
        # ITK is LPS: x and y of voxwarp's world (RAS) change sign
        world = vol.affine @ np.array([*index, 1.0])
        np.testing.assert_allclose(a, world[:3] * [-1, -1, 1], atol=1e-9)
    np.testing.assert_array_equal(
        sitk.GetArrayFromImage(images[0]), sitk.GetArrayFromImage(images[1])
    )
    back = load_volume(tmp_path / "v.nrrd")
    assert not back.space
    np.testing.assert_allclose(back.affine, vol.affine, atol=1e-12)
    np.testing.assert_array_equal(back.data, vol.data)


def test_a_qform_quaternion_that_is_no_rotation_is_ignored_with_a_warning(
    tmp_path: Path,
) -> None:
    """nibabel raises ValueError for a qform whose quaternion has b^2 + c^2 + d^2 > 1; when
    the coded sform is unusable too, the reader falls back to that qform: the volume
    loads without an orientation and says why in warnings, and a field with no other
    transform is refused in one line (found by tests/fuzz/test_fuzz_fields.py)."""
    from voxwarp.io.fields import FieldError, load_displacement_field

    def broken(data: np.ndarray, path: Path) -> Path:
        img = nib.Nifti1Image(data, np.eye(4))
        img.set_qform(np.eye(4), code=1)
        # a coded sform that is no transform, so the reader falls back to the qform
        img.set_sform(np.diag([1.0, 1.0, 0.0, 1.0]), code=1)
        nib.save(img, str(path))
        raw = bytearray(path.read_bytes())
        raw[256:264] = np.array([0.9, 0.9], "<f4").tobytes()  # quatern_b, quatern_c
        path.write_bytes(bytes(raw))
        with pytest.raises(ValueError, match="w2 should be positive"):
            nib.Nifti1Header.from_fileobj(io.BytesIO(bytes(raw))).get_qform(coded=True)
        return path

    path = broken(asym(), tmp_path / "v.nii")
    with pytest.warns(UserWarning, match="the qform cannot be read"):
        vol = load_volume(path)
    assert not vol.space
    field = broken(np.zeros((4, 4, 4, 3), np.float32), tmp_path / "u.nii")
    with pytest.warns(UserWarning, match="the qform cannot be read"):
        with pytest.raises(FieldError, match="has no sform or qform") as err:
            load_displacement_field(field, convention="itk")
    assert "\n" not in str(err.value)
