"""Hostile DICOM folders (issue 33): mixed series, missing, duplicate and uneven slices,
gantry tilt, enormous Rows/Columns in tiny files, compressed syntaxes without a working
decoder, DICOMDIR-only and non-image folders, colour images and damaged geometry.

Oracles: a loaded slice's first voxel lies on the ImagePositionPatient its file states
(LPS -> RAS); the voxel values are the pixels written; refusals are one line naming the
file or number and the fix. Series come from :mod:`tests.io.dicom_folders` (8x8 x 6).
"""

from __future__ import annotations

import copy
import math
import struct
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from tests.io import dicom_folders as df
from tests.run_cli import run_cli
from voxwarp.errors import VolumeError
from voxwarp.io.dicom import read_dicom_dir
from voxwarp.io.dicom_geometry import GRID_TOLERANCE
from voxwarp.io.volumes import dicom_series, load_volume

OBLIQUE = (math.cos(0.4), math.sin(0.4), 0.0, 0.0, 0.0, -1.0)  # a tilted coronal plane


def _read(folder: Path, series: str | None = None):  # type: ignore[no-untyped-def]
    return read_dicom_dir(folder, sorted(folder.iterdir()), series)


def _one_line_error(proc) -> str:  # type: ignore[no-untyped-def]
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode != 0, proc.stderr
    assert "Traceback" not in proc.stderr, proc.stderr
    assert len(lines) == 1, proc.stderr
    return lines[0]


def _assert_slices_on_their_ipp(loaded, datasets, slots) -> None:  # type: ignore[no-untyped-def]
    """Slice m of ``datasets`` fills slot ``slots[m]``: its first voxel at its IPP, its
    values the pixels written."""
    for ds, slot in zip(datasets, slots, strict=True):
        world = loaded.affine @ np.array([0.0, 0.0, slot, 1.0])
        np.testing.assert_allclose(world[:3], df.lps_to_ras(ds.ImagePositionPatient), atol=1e-5)
        k = int(ds.InstanceNumber) - 1
        np.testing.assert_array_equal(loaded.data[:, :, slot], df.pixels(k, 8, 8).T)


# ---------------------------------------------------------------------------- geometry
@pytest.mark.parametrize("iop", [(1, 0, 0, 0, 1, 0), OBLIQUE])
def test_missing_slices_leave_filled_slots_at_the_true_positions(tmp_path: Path, iop) -> None:
    """Before: 4 slices stacked at the median gap (the stack shrank by two spacings)."""
    s = df.series(6, iop=iop, dz=1.5)
    kept = [s[0], s[1], s[3], s[5]]
    df.save(tmp_path, kept[::-1])
    with pytest.warns(UserWarning, match=r"2 slice\(s\) missing \(positions 3, 5 of 1..6"):
        loaded = _read(tmp_path)
    assert loaded.data.shape == (8, 8, 6)
    _assert_slices_on_their_ipp(loaded, kept, [0, 1, 3, 5])
    low = min(int(df.pixels(k, 8, 8).min()) for k in (0, 1, 3, 5))
    assert np.all(loaded.data[:, :, [2, 4]] == low)
    # the volume voxwarp renders puts them at the same world points
    vol = load_volume(tmp_path)
    for ds, slot in zip(kept, [0, 1, 3, 5], strict=True):
        ijk = vol.world_to_index(df.lps_to_ras(ds.ImagePositionPatient)[None])[0]
        assert vol.data[tuple(np.rint(ijk).astype(int))] == loaded.data[0, 0, slot]


def test_more_missing_than_present_is_one_line(tmp_path: Path) -> None:
    s = df.series(12)
    df.save(tmp_path, [s[0], s[1], s[11]])
    with pytest.raises(VolumeError, match="3 slices spread over 12 positions"):
        _read(tmp_path)


def test_uneven_spacing_names_the_gap(tmp_path: Path) -> None:
    """Before: loaded at the median spacing with a warning (rc 0)."""
    s = df.series(6)
    s[3].ImagePositionPatient = [-2.0, -3.0, 4.0 + 3.4]
    df.save(tmp_path, s)
    with pytest.raises(VolumeError, match=r"IM0003.dcm and IM0004.dcm .* 1.4 mm apart.* 1 mm"):
        _read(tmp_path)


@pytest.mark.parametrize(("offset", "loads"), [(0.9, True), (1.1, False)])
def test_grid_tolerance_is_exact(tmp_path: Path, offset: float, loads: bool) -> None:
    """A slice 0.09 of a spacing off its grid position loads; 0.11 is refused."""
    s = df.series(6, dz=2.0)
    s[2].ImagePositionPatient = [-2.0, -3.0, 4.0 + 4.0 + offset * GRID_TOLERANCE * 2.0]
    df.save(tmp_path, s)
    if loads:
        assert _read(tmp_path).data.shape == (8, 8, 6)
    else:
        with pytest.raises(VolumeError, match="uneven slice spacing"):
            _read(tmp_path)


def test_copies_of_one_instance_are_read_once(tmp_path: Path) -> None:
    """Before: '2 slices share a position' (refused)."""
    s = df.series(6)
    df.save(tmp_path, [*s, copy.deepcopy(s[2])])
    with pytest.warns(UserWarning, match=r"1 file\(s\) repeat a slice"):
        loaded = _read(tmp_path)
    _assert_slices_on_their_ipp(loaded, s, range(6))


def test_two_instances_at_one_position_are_one_line(tmp_path: Path) -> None:
    s = df.series(6)
    other = copy.deepcopy(s[2])
    other.SOPInstanceUID = other.file_meta.MediaStorageSOPInstanceUID = "1.2.3.99"
    df.save(tmp_path, [*s, other])
    with pytest.raises(VolumeError, match=r"IM0003\.dcm and IM0007\.dcm are different images"):
        _read(tmp_path)


def test_oblique_stack_lands_on_every_ipp(tmp_path: Path) -> None:
    s = df.series(6, iop=OBLIQUE, dz=1.25)
    df.save(tmp_path, s)
    _assert_slices_on_their_ipp(_read(tmp_path), s, range(6))


def _world_ramp(datasets, iop, rows: int = 16, cols: int = 16) -> None:  # type: ignore[no-untyped-def]
    """Give every slice the pixels of one fixed world function, f = 1000 + 40 * (LPS
    point . column direction): a linear ramp, which linear interpolation keeps exactly."""
    row, col = np.asarray(iop[:3], float), np.asarray(iop[3:], float)
    r, c = np.mgrid[0:rows, 0:cols]
    for ds in datasets:
        ipp = np.asarray(ds.ImagePositionPatient, float)
        world = ipp + (c[..., None] * 0.5) * row + (r[..., None] * 0.5) * col
        ds.PixelData = np.rint(1000 + 40 * (world @ col)).astype("<i2").tobytes()


@pytest.mark.parametrize("iop", [(1, 0, 0, 0, 1, 0), OBLIQUE])
def test_gantry_tilt_is_put_back_on_an_orthogonal_grid(tmp_path: Path, iop) -> None:
    """Before: rc 0, every slice after the first misplaced (1.34 mm at the sixth); then
    refused. Now each slice is shifted in its plane by its drift, with a warning naming
    the tilt. Oracle: a world-fixed linear ramp reads back at every interior voxel's
    world position (affine), within the int16 rounding."""
    s = df.series(6, rows=16, cols=16, iop=iop, tilt_deg=15.0)
    _world_ramp(s, iop)
    df.save(tmp_path, s)
    with pytest.warns(UserWarning, match=r"tilted 15\.0 deg .* gantry tilt"):
        loaded = _read(tmp_path)
    col = np.asarray(iop[3:], float)
    i, j, k = np.mgrid[0:16, 3:13, 0:6]  # rows 3..12 stay covered after the 2.7-pixel drift
    idx = np.stack([i, j, k, np.ones_like(i)], -1).reshape(-1, 4).astype(float)
    lps = (loaded.affine @ idx.T).T[:, :3] * np.array([-1.0, -1.0, 1.0])
    expected = 1000 + 40 * (lps @ col)
    got = loaded.data[i, j, k].reshape(-1).astype(float)
    assert np.abs(got - expected).max() <= 1.0


def test_sideways_offsets_out_of_step_are_one_line(tmp_path: Path) -> None:
    """One slice knocked sideways (not a shear of the whole stack): refused, naming it."""
    s = df.series(6)
    ipp = np.asarray(s[3].ImagePositionPatient, float) + np.array([0.0, 0.4, 0.0])
    s[3].ImagePositionPatient = [float(v) for v in ipp]
    df.save(tmp_path, s)
    df.save(tmp_path, df.series(2, rows=4, cols=4, uid=df.UID + ".2"), prefix="B")
    proc = run_cli("info", str(tmp_path), timeout=60)
    line = _one_line_error(proc)
    assert "IM0004.dcm" in line
    assert "out of step" in line
    assert "dcm2niix" in line
    assert "the largest of 2 DICOM series" in line


def test_tilt_within_the_tolerance_loads_within_it(tmp_path: Path) -> None:
    """Sideways drift under 0.1 pixel over the stack loads; each IPP within 0.1 pixel."""
    tilt = math.degrees(math.atan(0.09 * 0.5 / 5.0))  # 0.09 pixel at the last slice
    s = df.series(6, tilt_deg=tilt, iop=OBLIQUE)
    df.save(tmp_path, s)
    loaded = _read(tmp_path)
    for k, ds in enumerate(s):
        world = loaded.affine @ np.array([0.0, 0.0, k, 1.0])
        gap = np.linalg.norm(world[:3] - df.lps_to_ras(ds.ImagePositionPatient))
        assert gap <= GRID_TOLERANCE * 0.5 + 1e-6


@pytest.mark.parametrize(
    ("iop", "match"),
    [
        ((0.9, 0.1, 0, 0, 1, 0), "IM0003.dcm is oriented"),
        ((1, 0, 0, 0.5, 0.5, 0), "not two perpendicular unit vectors"),
        (("nan", 0, 0, 0, 1, 0), "ImageOrientationPatient .* not 6 finite numbers"),
    ],
)
def test_bad_orientation_is_one_line(tmp_path: Path, iop, match: str) -> None:
    s = df.series(6)
    target = s[2] if "IM0003" in match else s[0]
    target.ImageOrientationPatient = list(iop)
    df.save(tmp_path, s)
    with pytest.raises(VolumeError, match=match):
        _read(tmp_path)


# ---------------------------------------------------------------------------- series
def _mixed(tmp_path: Path, same_uid: bool) -> tuple[Path, str]:
    uid2 = df.UID if same_uid else df.UID + ".2"
    b = df.series(3, rows=16, cols=12, uid=uid2, iop=(1, 0, 0, 0, 0, -1))
    for ds in b:
        ds.SOPInstanceUID = ds.file_meta.MediaStorageSOPInstanceUID = ds.SOPInstanceUID + ".9"
    df.save(tmp_path, df.series(6))
    df.save(tmp_path, b, prefix="B")
    return tmp_path, uid2


@pytest.mark.parametrize("same_uid", [False, True])
def test_mixed_series_largest_by_default_others_by_index(tmp_path: Path, same_uid: bool) -> None:
    """Before (same UID, two sizes): 'slices share a position' (refused)."""
    folder, uid2 = _mixed(tmp_path, same_uid)
    listed = dicom_series(folder)
    assert [(s.index, s.files, s.rows, s.columns) for s in listed] == [(1, 6, 8, 8), (2, 3, 16, 12)]
    with pytest.warns(UserWarning, match="holds 2 DICOM series; loading the largest.*--series"):
        assert _read(folder).data.shape == (8, 8, 6)
    assert _read(folder, "2").data.shape == (12, 16, 3)
    if same_uid:
        with pytest.raises(VolumeError, match="holds 2 image sizes \\(series 1, 2\\)"):
            _read(folder, uid2)
    else:
        assert _read(folder, uid2).data.shape == (12, 16, 3)


def test_cli_series_choice_and_unknown_series(tmp_path: Path) -> None:
    """``--series 2`` picks the other size of one UID (a subprocess, as a user runs it);
    an unknown ``--series`` is one line listing the series."""
    folder, _ = _mixed(tmp_path, same_uid=True)
    proc = run_cli("info", str(folder), "--series", "2", timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert "= 576 voxels" in proc.stdout  # 12 x 16 x 3
    assert not proc.stderr.strip()
    code, lines, text = df.cli_in_process(["info", str(folder), "--series", "7"])
    assert code == 2, text
    assert len(lines) == 1, text
    assert "no DICOM series '7'" in lines[0]
    assert "pass an index 1..2" in lines[0]


# ---------------------------------------------------------------------------- sizes
@pytest.mark.parametrize("budget", [None, "unlimited"])
@pytest.mark.parametrize("pixel_data", [b"", None])
def test_enormous_rows_columns_in_tiny_files(tmp_path: Path, budget, pixel_data) -> None:
    """65535 x 65535 x 3 slices (24 GiB) in 3 files of under 1 KB: one line, under 8 MiB
    of Python allocations, whether the budget or the pixel-data length refuses it."""
    s = df.series(3)
    for ds in s:
        ds.Rows = ds.Columns = 65535
        if pixel_data is None:
            del ds.PixelData
        else:
            ds.PixelData = pixel_data
    df.save(tmp_path, s)
    tracemalloc.start()
    try:
        with pytest.raises(VolumeError) as err:
            load_volume(tmp_path, memory_budget=budget)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 8 << 20
    text = str(err.value)
    if budget is None:
        assert "65535x65535x3 voxels need 24 GiB" in text
    else:
        assert "8 x 65535" not in text
        assert "need 8,589,672,450" in text or "pixel" in text


# ---------------------------------------------------------------------------- syntaxes
SYNTAXES = {
    "1.2.840.10008.1.2.4.90": "JPEG 2000 Image Compression",
    "1.2.840.10008.1.2.4.57": "JPEG Lossless, Non-Hierarchical (Process 14)",
    "1.2.840.10008.1.2.4.70": "JPEG Lossless, Non-Hierarchical, First-Order",
    "1.2.840.10008.1.2.5": "RLE Lossless",
    "1.2.840.10008.1.2.4.80": "JPEG-LS Lossless",
}


def _garbage_compressed(folder: Path, uid: str) -> None:
    """Two slices whose meta says ``uid``, with garbage encapsulated in their pixel data."""
    from pydicom.encaps import encapsulate

    s = df.series(2, syntax=uid)
    for ds in s:
        ds.PixelData = encapsulate([b"\xff\x4f\xff\x51garbage" * 3])
        ds["PixelData"].VR = "OB"
    df.save(folder, s)


@pytest.mark.parametrize("uid", sorted(SYNTAXES))
def test_compressed_garbage_names_the_syntax(tmp_path: Path, uid: str) -> None:
    """Decoders installed, data garbage: one line naming the syntax (before: its UID and
    'needs a decoder', which was installed)."""
    _garbage_compressed(tmp_path, uid)
    with pytest.raises(VolumeError) as err:
        _read(tmp_path)
    text = str(err.value)
    assert SYNTAXES[uid] in text
    assert uid in text
    assert "gdcmconv --raw" in text or "pip install" in text


def test_missing_decoder_names_the_extra(tmp_path: Path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """pydicom's own 'missing dependencies' error (no plugin installed) gets the install
    hint, not 'damaged'."""
    import pydicom

    def no_plugin(self):  # type: ignore[no-untyped-def]
        raise RuntimeError("Unable to decompress: all plugins are missing dependencies")

    _garbage_compressed(tmp_path, "1.2.840.10008.1.2.5")
    monkeypatch.setattr(pydicom.dataset.Dataset, "pixel_array", property(no_plugin))
    with pytest.raises(VolumeError, match=r"no decoder for RLE Lossless .*pip install"):
        _read(tmp_path)


def test_deflated_garbage_names_the_syntax(tmp_path: Path) -> None:
    df.save(tmp_path, df.series(3, syntax="1.2.840.10008.1.2.1.99"))
    for p in tmp_path.iterdir():
        blob = p.read_bytes()
        end = 144 + struct.unpack("<I", blob[140:144])[0]  # after the file meta group
        p.write_bytes(blob[:end] + b"\x13\x37garbage" * 20)
    with pytest.raises(VolumeError, match=r"3 damaged file.*Deflated Explicit VR Little Endian"):
        _read(tmp_path)


# ---------------------------------------------------------------------------- odd folders
def test_dicomdir_only_names_the_series_folder(tmp_path: Path) -> None:
    from pydicom.fileset import FileSet

    fs = FileSet()
    for p in sorted(df.save(tmp_path / "src", df.series(3)).iterdir()):
        fs.add(str(p))
    fs.write(str(tmp_path / "disc"))
    only = tmp_path / "only"
    only.mkdir()
    (only / "DICOMDIR").write_bytes((tmp_path / "disc" / "DICOMDIR").read_bytes())
    for folder in (only, tmp_path / "disc"):
        with pytest.raises(VolumeError, match=r"holds a DICOMDIR .* \(3 images listed there\)"):
            load_volume(folder)


def test_non_image_dicom_and_other_files(tmp_path: Path) -> None:
    sr = df.series(2)
    for ds in sr:
        del ds.PixelData, ds.Rows, ds.Columns
        ds.Modality = "SR"
    df.save(tmp_path / "sr", sr)
    with pytest.raises(VolumeError, match=r"DICOM files but no image \(2 SR"):
        load_volume(tmp_path / "sr")
    folder = df.save(tmp_path / "mixed", df.series(6))
    (folder / "notes.txt").write_text("not DICOM\n")
    (folder / "blob.bin").write_bytes(bytes(300))
    df.save(folder, sr, prefix="SR")
    _assert_slices_on_their_ipp(_read(folder), df.series(6), range(6))


def test_truncated_slice_is_one_line(tmp_path: Path) -> None:
    df.save(tmp_path, df.series(6))
    p = tmp_path / "IM0003.dcm"
    p.write_bytes(p.read_bytes()[:-30])
    with pytest.raises(VolumeError, match=r"IM0003\.dcm: its pixel data holds 98 bytes"):
        _read(tmp_path)


def test_one_bit_and_float_pixels_load(tmp_path: Path) -> None:
    bits = df.series(6)
    for ds in bits:
        ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 1, 1, 0, 0
        ds.PixelData = np.packbits(np.arange(64) % 3 == 0, bitorder="little").tobytes()
    df.save(tmp_path / "bits", bits)
    loaded = _read(tmp_path / "bits")
    np.testing.assert_array_equal(loaded.data[:, :, 4], (np.arange(64) % 3 == 0).reshape(8, 8).T)
    floats = df.series(6)
    for k, ds in enumerate(floats):
        del ds.PixelData, ds.BitsStored, ds.HighBit, ds.PixelRepresentation
        ds.BitsAllocated = 32
        ds.FloatPixelData = (np.arange(64, dtype="<f4") / 4 + k).tobytes()
    df.save(tmp_path / "float", floats)
    loaded = _read(tmp_path / "float")
    np.testing.assert_array_equal(loaded.data[:, :, 5], (np.arange(64) / 4 + 5).reshape(8, 8).T)


def _colour(ds, kind: str) -> None:  # type: ignore[no-untyped-def]
    ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 8, 8, 7, 0
    if kind == "RGB":
        ds.PhotometricInterpretation, ds.SamplesPerPixel, ds.PlanarConfiguration = "RGB", 3, 0
        ds.PixelData = bytes(64 * 3)
    elif kind == "PALETTE COLOR":
        ds.PhotometricInterpretation, ds.PixelData = kind, bytes(64)
    else:  # three samples, but a grayscale photometric interpretation
        ds.SamplesPerPixel, ds.PixelData = 3, bytes(64 * 3)


@pytest.mark.parametrize("kind", ["RGB", "PALETTE COLOR", "samples=3"])
def test_colour_images_are_one_line(tmp_path: Path, kind: str) -> None:
    """Before: PALETTE COLOR loaded its palette indices as values (rc 0)."""
    s = df.series(6)
    for ds in s:
        _colour(ds, kind)
    df.save(tmp_path, s)
    with pytest.raises(VolumeError, match=r"IM0001\.dcm is a colour image.*reads grayscale"):
        _read(tmp_path)


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("PixelSpacing", [-0.5, 0.5], "PixelSpacing .* not two positive numbers"),
        ("PixelSpacing", [0, 0], "PixelSpacing .* not two positive numbers"),
        ("ImagePositionPatient", ["nan", 0, 2], "IM0001.dcm: its ImagePositionPatient"),
        ("RescaleSlope", 1e300, "RescaleSlope 1e.300 .* past the float32 range"),
    ],
)
def test_damaged_geometry_is_one_line(tmp_path: Path, field: str, value, match: str) -> None:
    """Before: a 1 mm spacing was assumed ('no PixelSpacing'), a NaN position dropped
    every position (rc 0) and a slope of 1e300 gave infinite voxels (the fuzz found a
    missing-slice warning before that error: two lines)."""
    s = df.series(6)
    setattr(s[0], field, value)
    df.save(tmp_path, s)
    with pytest.raises(VolumeError, match=match):
        _read(tmp_path)


def test_zero_slice_thickness_is_unused_when_positions_exist(tmp_path: Path) -> None:
    s = df.series(6, dz=2.5)
    for ds in s:
        ds.SliceThickness = -1
    df.save(tmp_path, s)
    assert _read(tmp_path).affine[2, 2] == pytest.approx(2.5)


# ---------------------------------------------------------------------------- CLI
def _hostile(kind: str, folder: Path) -> None:
    """Write the hostile folder ``kind`` (one per refusal above)."""
    s = df.series(6)
    if kind == "uneven":
        s[3].ImagePositionPatient = [-2.0, -3.0, 7.4]
    elif kind == "two-at-one-position":
        s.append(copy.deepcopy(s[2]))
        s[-1].SOPInstanceUID = s[-1].file_meta.MediaStorageSOPInstanceUID = "1.2.3.99"
    elif kind == "orientations":
        s[2].ImageOrientationPatient = [0.9, 0.1, 0, 0, 1, 0]
    elif kind == "huge":
        for ds in s:
            ds.Rows = ds.Columns = 65535
    elif kind == "sparse":
        s = [*df.series(12)[:2], df.series(12)[11]]
    elif kind in ("RGB", "PALETTE COLOR"):
        for ds in s:
            _colour(ds, kind)
    elif kind == "spacing":
        s[0].PixelSpacing = [0, 0]
    elif kind == "nan-position":
        s[4].ImagePositionPatient = ["nan", 0, 0]
    if kind == "jpeg2000":
        _garbage_compressed(folder, "1.2.840.10008.1.2.4.90")
    elif kind == "sr":
        for ds in s:
            del ds.PixelData, ds.Rows, ds.Columns
        df.save(folder, s)
    else:
        df.save(folder, s)


@pytest.mark.parametrize(
    ("kind", "problem", "fix"),
    [
        ("uneven", "uneven slice spacing", "Resample"),
        ("two-at-one-position", "different images at one position", "one acquisition per"),
        ("orientations", "must share their ImageOrientationPatient", "--series"),
        ("huge", "65535x65535x6 voxels need", "--memory-budget"),
        ("sparse", "more slices are missing than present", "Resample"),
        ("RGB", "colour image", "convert the images to grayscale"),
        ("PALETTE COLOR", "colour image", "convert the images to grayscale"),
        ("spacing", "not two positive numbers", "Fix it"),
        ("nan-position", "not 3 finite numbers", "remove the file"),
        ("jpeg2000", "JPEG 2000 Image Compression", "gdcmconv --raw"),
        ("sr", "holds DICOM files but no image", "pass the folder of the image series"),
    ],
)
def test_every_refusal_is_one_cli_line(tmp_path: Path, kind: str, problem: str, fix: str) -> None:
    """``voxwarp info`` on each hostile folder: exit 2 and exactly one stderr line (no
    warning before it) naming the problem and the fix (in process; the subprocess form
    is checked by the tilt and --series tests)."""
    _hostile(kind, tmp_path)
    code, lines, text = df.cli_in_process(["info", str(tmp_path)])
    assert code == 2, text
    assert len(lines) == 1, text
    assert lines[0].startswith("voxwarp: error: "), text
    assert problem in lines[0]
    assert fix in lines[0]
