"""Fuzz every volume loader with broken files: .npy/.npz, raw + JSON sidecar, NRRD/NHDR,
NIfTI, DICOM (folders and single files), TIFF (files and folders), odd paths.

Each case starts from a valid file written by the format's own library and breaks it
(header fields, byte mutations, wrong sizes); :func:`voxwarp.io.volumes.load_volume`
must return a volume or raise a one-line VolumeError, within the per-case time limit
(``tests/fuzz/_support.py``). Sizes stay tiny: no case allocates more than a few MB.
"""

from __future__ import annotations

import io
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, reject
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.fuzz._mutate import bad_numbers, bad_value, json_text, json_value, mutated_bytes
from tests.fuzz._support import assert_one_line, fuzz_settings, outcome, time_limit
from voxwarp.errors import VolumeError
from voxwarp.io.volumes import load_volume

DTYPES = ["u1", "i1", "<u2", ">i2", "<i4", "<u4", "<f4", ">f8", "<i8", "<u8", "?", "<f2", "<c8"]
small_shape = st.lists(st.integers(0, 5), min_size=0, max_size=4).map(tuple)
mostly_3d = st.one_of(st.lists(st.integers(1, 5), min_size=3, max_size=3).map(tuple), small_shape)


@st.composite
def arrays(draw: st.DrawFn, shape: Any = mostly_3d) -> np.ndarray:
    dtype = np.dtype(draw(st.sampled_from(DTYPES)))
    shp = draw(shape)
    elements = None
    if dtype.kind == "f":
        elements = st.floats(allow_nan=True, allow_infinity=True, width=8 * min(dtype.itemsize, 8))
    return draw(hnp.arrays(dtype, shp, elements=elements))


def load_kwargs() -> st.SearchStrategy[dict[str, Any]]:
    return st.fixed_dictionaries(
        {},
        optional={
            "axis_order": st.sampled_from(["xyz", "zyx"]),
            "nan_policy": st.sampled_from(["raise", "mask"]),
            "downsample": st.sampled_from([1, 2, 3]),
        },
    )


def run_load(test: str, path: Path, kwargs: dict[str, Any] | None = None) -> str:
    return outcome(test, lambda: load_volume(path, **(kwargs or {})))


# ---------------------------------------------------------------------------- npy / npz
@fuzz_settings(120)
@given(
    array=arrays(),
    container=st.sampled_from(["npy", "npz", "npz-compressed"]),
    key=st.sampled_from(["data", "volume", "arr_0", "image", "x"]),
    extras=st.dictionaries(
        st.sampled_from(["spacing", "origin", "affine", "space", "units", "junk"]),
        st.one_of(
            hnp.arrays(np.float64, st.sampled_from([(3,), (4, 4), (2,), (), (3, 3)])),
            st.sampled_from([np.array("LPS"), np.array(["a", "b"]), np.array([1, 2, 3], "i8")]),
        ),
        max_size=3,
    ),
    mutate=st.booleans(),
    kwargs=load_kwargs(),
    data=st.data(),
)
def test_npy_npz(array, container, key, extras, mutate, kwargs, data) -> None:
    """Arrays of every dtype and rank, npz keys and geometry arrays, then byte damage."""
    buf = io.BytesIO()
    if container == "npy":
        np.save(buf, array)
    else:
        save = np.savez_compressed if container == "npz-compressed" else np.savez
        save(buf, **{key: array}, **extras)
    raw = buf.getvalue()
    if mutate:
        raw = data.draw(mutated_bytes(raw))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"v.{container[:3]}"
        path.write_bytes(raw)
        run_load("npy/npz", path, kwargs)


# ---------------------------------------------------------------------------- raw + sidecar
RAW_DTYPES = ["uint8", "int8", "uint16", "int16", "int32", "uint32", "float32", "float64"]


@fuzz_settings(120)
@given(
    dims=st.one_of(
        st.lists(st.integers(1, 4), min_size=3, max_size=3),
        st.lists(st.sampled_from([0, -1, 2**31, 2**40, 10**6, 3]), min_size=3, max_size=3),
        bad_value,
    ),
    dtype=st.one_of(st.sampled_from(RAW_DTYPES), json_value),
    optional=st.dictionaries(
        st.sampled_from(
            ["byte_order", "header_bytes", "spacing", "origin", "affine", "space", "units", "zz"]
        ),
        st.one_of(
            st.sampled_from(["little", "big", "LPS", "RAS", "mm"]),
            st.lists(st.floats(0.1, 5), min_size=3, max_size=3),
            bad_value,
        ),
        max_size=4,
    ),
    payload=st.integers(0, 600),
    sidecar_style=st.sampled_from(["name.raw.json", "name.json", "broken-json", "not-object"]),
    open_as=st.sampled_from(["raw", "json"]),
)
def test_raw_sidecar(dims, dtype, optional, payload, sidecar_style, open_as) -> None:
    """Sidecars with wrong, missing, huge or mistyped entries; raw files of any length
    (huge dims over a tiny file must be refused before anything is allocated)."""
    meta = {"dims": dims, "dtype": dtype, **optional}
    text = json_text(meta)
    if sidecar_style == "broken-json":
        text = text[: max(1, len(text) // 2)]
    elif sidecar_style == "not-object":
        text = json_text([meta])
    with tempfile.TemporaryDirectory() as tmp:
        raw = Path(tmp) / "v.raw"
        raw.write_bytes(bytes(range(256)) * (payload // 256) + bytes(payload % 256))
        side = Path(tmp) / ("v.raw.json" if sidecar_style == "name.raw.json" else "v.json")
        side.write_text(text)
        run_load("raw+sidecar", raw if open_as == "raw" else side)


# ---------------------------------------------------------------------------- NRRD
NRRD_FIELDS: dict[str, st.SearchStrategy[str]] = {
    "type": st.sampled_from(
        ["uint8", "short", "ushort", "int", "float", "double", "int64", "block", "bogus", ""]
    ),
    "dimension": st.sampled_from(["3", "2", "4", "1", "0", "-3", "x", "1000"]),
    "sizes": st.one_of(
        st.sampled_from(["2 3 4", "2 3", "2 3 4 1", "1 2 3 4", "0 3 4", "-2 3 4", "a b c"]),
        st.lists(st.integers(0, 6), min_size=1, max_size=4).map(lambda v: " ".join(map(str, v))),
    ),
    "encoding": st.sampled_from(["raw", "gzip", "ascii", "text", "bzip2", "hex", "zzz"]),
    "endian": st.sampled_from(["little", "big", "middle"]),
    "space": st.sampled_from(
        ["left-posterior-superior", "RAS", "scanner-xyz", "3D-right-handed", "nowhere", ""]
    ),
    "space directions": st.sampled_from(
        [
            "(1,0,0) (0,1,0) (0,0,1)",
            "(1,0,0) (0,1,0) (0,0,0)",
            "(nan,0,0) (0,1,0) (0,0,1)",
            "(1,0,0) (0,1,0)",
            "none (1,0,0) (0,1,0) (0,0,1)",
            "(1,0) (0,1) (1,1)",
            "(1e308,0,0) (0,1e308,0) (0,0,1e308)",
            "garbage",
        ]
    ),
    "spacings": st.sampled_from(["1 1 1", "nan nan nan", "0 1 1", "-1 2 3", "inf 1 1", "1 2"]),
    "space origin": st.sampled_from(["(0,0,0)", "(nan,0,0)", "(1,2)", "(inf,0,0)", "zero"]),
    "space units": st.sampled_from(['"mm" "mm" "mm"', '"km" "km" "km"', '"mm" "cm" "m"', '""']),
    "byte skip": st.sampled_from(["0", "-1", "4", "100000", "x"]),
    "line skip": st.sampled_from(["0", "1", "100", "-1"]),
    "kinds": st.sampled_from(["domain domain domain", "RGB-color domain domain", "space"]),
}


@fuzz_settings(120)
@given(
    fields=st.dictionaries(
        st.sampled_from(sorted(NRRD_FIELDS)), st.just(""), min_size=2, max_size=10
    ).flatmap(
        lambda keys: (
            st.fixed_dictionaries({k: NRRD_FIELDS[k] for k in keys})
            | st.fixed_dictionaries({k: NRRD_FIELDS[k] for k in keys}).map(
                lambda d: {
                    "type": "uint8",
                    "dimension": "3",
                    "sizes": "2 3 4",
                    "encoding": "raw",
                    **d,
                }
            )
        )
    ),
    body=st.binary(max_size=120),
    magic=st.sampled_from(["NRRD0004", "NRRD0005", "NRRD9999", "NRRD", "nrrd0004"]),
    detached=st.sampled_from(
        [None, "v.raw", "missing.raw", ".", "LIST", "v.raw.gz", "sub", "v%03d.raw 0 2 1 2"]
    ),
    extension=st.sampled_from([".nrrd", ".nhdr"]),
    data=st.data(),
)
def test_nrrd(fields, body, magic, detached, extension, data) -> None:
    """NRRD headers with wrong, missing or contradictory fields, attached or detached
    data (missing, a folder, a symlinked folder, a list), then byte damage."""
    lines = [magic] + [f"{k}: {v}" for k, v in fields.items()]
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        (d / "v.raw").write_bytes(body)
        (d / "v000.raw").write_bytes(body[:24])
        (d / "sub").mkdir()
        os.symlink(d / "sub", d / "linkdir")
        if detached is not None:
            lines.append(f"data file: {detached}")
            if detached == "LIST":
                lines += ["v.raw", "linkdir", "missing.raw"]
        text = "\n".join(lines) + "\n"
        content = text.encode() if detached is not None else text.encode() + b"\n" + body
        content = data.draw(mutated_bytes(content, keep=0.5))
        path = d / f"v{extension}"
        path.write_bytes(content)
        run_load("nrrd", path)


# ---------------------------------------------------------------------------- NIfTI
def _nifti_bytes(array: np.ndarray, compressed: bool) -> bytes:
    import nibabel as nib

    img = nib.Nifti1Image(array, np.diag([1.0, 2.0, 3.0, 1.0]), dtype=array.dtype)
    raw = img.to_bytes()
    if compressed:
        import gzip

        return gzip.compress(raw)
    return raw


#: offsets in the NIfTI-1 header of fields worth breaking: (offset, struct format)
NIFTI_FIELDS = {
    "dim": (40, "<8h"),
    "datatype": (70, "<h"),
    "bitpix": (72, "<h"),
    "pixdim": (76, "<8f"),
    "vox_offset": (108, "<f"),
    "scl_slope": (112, "<f"),
    "scl_inter": (116, "<f"),
    "qform_code": (252, "<h"),
    "sform_code": (254, "<h"),
    "quatern": (256, "<6f"),
    "srow": (280, "<12f"),
    "magic": (344, "4s"),
    "sizeof_hdr": (0, "<i"),
}


@st.composite
def nifti_field(draw: st.DrawFn) -> tuple[int, bytes]:
    import struct

    name = draw(st.sampled_from(sorted(NIFTI_FIELDS)))
    offset, fmt = NIFTI_FIELDS[name]
    if fmt == "4s":
        return offset, draw(st.sampled_from([b"n+1\0", b"ni1\0", b"n+2\0", b"\0\0\0\0", b"xxxx"]))
    count = struct.calcsize(fmt) // (2 if "h" in fmt else 4)
    if "h" in fmt:
        if name == "dim":
            values = [draw(st.integers(-2, 8))] + [
                draw(st.sampled_from([0, 1, 2, 3, 4, -1, 200, 32767])) for _ in range(count - 1)
            ]
        else:
            values = [draw(st.integers(-32768, 32767)) for _ in range(count)]
        return offset, struct.pack(fmt, *values)
    if "i" in fmt:
        return offset, struct.pack(fmt, draw(st.integers(-(2**31), 2**31 - 1)))
    floats = st.one_of(
        bad_numbers.filter(lambda v: abs(v) < 3e38 or not np.isfinite(v)),
        st.floats(-4, 4, width=32),
    )
    values = [float(np.float32(draw(floats))) for _ in range(count)]
    return offset, struct.pack(fmt, *values)


@fuzz_settings(80)
@given(
    array=arrays(st.lists(st.integers(1, 4), min_size=3, max_size=4).map(tuple)),
    fields=st.lists(nifti_field(), min_size=0, max_size=3),
    compressed=st.booleans(),
    data=st.data(),
)
def test_nifti(array, fields, compressed, data) -> None:
    """NIfTI-1 headers with broken dims, datatypes, voxel sizes, offsets, scaling,
    s/qforms and magic; truncated or damaged files, plain and gzipped."""
    if array.dtype.kind in "bc" or (array.dtype.itemsize == 2 and array.dtype.kind == "f"):
        array = np.real(array).astype(np.float32)
    raw = bytearray(_nifti_bytes(array.astype(array.dtype.newbyteorder("<")), False))
    for offset, value in fields:
        raw[offset : offset + len(value)] = value
    blob = data.draw(mutated_bytes(bytes(raw), keep=0.6))
    if compressed:
        import gzip

        blob = data.draw(mutated_bytes(gzip.compress(blob), keep=0.8))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / ("v.nii.gz" if compressed else "v.nii")
        path.write_bytes(blob)
        run_load("nifti", path)


# ---------------------------------------------------------------------------- DICOM
def _dicom_dataset(index: int, rows: int, cols: int, pixels: np.ndarray) -> Any:
    from pydicom.dataset import FileDataset, FileMetaDataset
    from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid

    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = CTImageStorage
    meta.MediaStorageSOPInstanceUID = generate_uid(entropy_srcs=[str(index)])
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = FileDataset("x", {}, file_meta=meta, preamble=b"\0" * 128)
    ds.SOPClassUID = CTImageStorage
    ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
    ds.SeriesInstanceUID = "1.2.3.4"
    ds.StudyInstanceUID = "1.2.3"
    ds.Modality = "CT"
    ds.Rows, ds.Columns = rows, cols
    ds.SamplesPerPixel = 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 16, 12, 11, 1
    ds.PixelSpacing = [0.5, 0.5]
    ds.SliceThickness = 1.0
    ds.ImageOrientationPatient = [1, 0, 0, 0, 1, 0]
    ds.ImagePositionPatient = [0, 0, float(index)]
    ds.InstanceNumber = index + 1
    ds.RescaleSlope, ds.RescaleIntercept = 1, -1024
    ds.PixelData = pixels.astype("<i2").tobytes()
    return ds


DICOM_FIELDS: dict[str, st.SearchStrategy[Any]] = {
    "Rows": st.sampled_from([0, 1, 3, 4, 65535]),
    "Columns": st.sampled_from([0, 1, 3, 4, 65535]),
    "BitsAllocated": st.sampled_from([0, 1, 8, 12, 16, 32, 64]),
    "BitsStored": st.sampled_from([0, 1, 8, 16, 40]),
    "PixelRepresentation": st.sampled_from([0, 1, 2]),
    "SamplesPerPixel": st.sampled_from([0, 1, 3, 4]),
    "PhotometricInterpretation": st.sampled_from(["MONOCHROME1", "RGB", "PALETTE COLOR", "X"]),
    "PixelSpacing": st.sampled_from([[0, 0], [-1, 1], ["nan", "1"], [1], [1, 2, 3], ["inf", 1]]),
    "ImageOrientationPatient": st.sampled_from(
        [[0, 0, 0, 0, 0, 0], [1, 0, 0, 1, 0, 0], [1, 0, 0], ["nan"] * 6, [1e300] * 6]
    ),
    "ImagePositionPatient": st.sampled_from([[0, 0], ["nan", 0, 0], [0, 0, 0], [1e308] * 3]),
    "SliceThickness": st.sampled_from([0, -1, "nan", 1e308]),
    "RescaleSlope": st.sampled_from([0, "nan", "inf", 1e308, -1]),
    "RescaleIntercept": st.sampled_from(["nan", 1e308, -1e308]),
    "NumberOfFrames": st.sampled_from([0, 1, 2, 3, 1000, -1]),
    "PixelData": st.sampled_from([b"", b"\0\0", b"\x01" * 7, b"\0" * 64]),
    "SeriesInstanceUID": st.sampled_from(["", "1.2.3.5", "x" * 70]),
    "PixelPaddingValue": st.sampled_from([-2000, 0, 70000]),
    "TransferSyntaxUID": st.sampled_from(
        ["1.2.840.10008.1.2.4.50", "1.2.840.10008.1.2.5", "1.2.840.10008.1.2.2", "9.9"]
    ),
}


@fuzz_settings(60)
@given(
    slices=st.integers(1, 3),
    edits=st.lists(
        st.tuples(st.integers(0, 2), st.sampled_from(sorted(DICOM_FIELDS)), st.data()),
        max_size=3,
    ),
    damage=st.one_of(st.none(), st.integers(0, 2)),
    single_file=st.booleans(),
    extra_file=st.sampled_from([None, "empty", "text", "subdir", "symlink-dir"]),
    data=st.data(),
)
def test_dicom(slices, edits, damage, single_file, extra_file, data) -> None:
    """DICOM slices with broken size, bit depth, geometry, rescale, frame counts, pixel
    data and transfer syntax; folders with odd extra entries; single .dcm files."""
    rows, cols = 3, 4
    pixels = np.arange(rows * cols, dtype=np.int16).reshape(rows, cols)
    datasets = [_dicom_dataset(i, rows, cols, pixels + i) for i in range(slices)]
    for which, name, field_data in edits:
        value = field_data.draw(DICOM_FIELDS[name])
        ds = datasets[which % slices]
        if name == "TransferSyntaxUID":
            ds.file_meta.TransferSyntaxUID = value
        else:
            setattr(ds, name, value)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "series"
        folder.mkdir()
        for i, ds in enumerate(datasets):
            buf = io.BytesIO()
            try:
                ds.save_as(buf, enforce_file_format=True)
            except Exception:  # pydicom refuses to write this edit: not a case
                reject()
            blob = buf.getvalue()
            if damage == i:
                blob = data.draw(mutated_bytes(blob, keep=0.0))
            (folder / f"slice{i}.dcm").write_bytes(blob)
        if extra_file == "empty":
            (folder / "DICOMDIR").write_bytes(b"")
        elif extra_file == "text":
            (folder / "notes.txt").write_text("not dicom\n")
        elif extra_file == "subdir":
            (folder / "sub").mkdir()
        elif extra_file == "symlink-dir":
            os.symlink(folder, folder / "loop")
        run_load("dicom", folder / "slice0.dcm" if single_file else folder)


# ---------------------------------------------------------------------------- TIFF
@st.composite
def tiff_bytes(draw: st.DrawFn) -> bytes:
    import tifffile

    buf = io.BytesIO()
    imagej = draw(st.booleans())
    dtype = draw(st.sampled_from(["u1", "<u2", "<f4", "<i2"] + ([] if imagej else ["?", "<f8"])))
    shapes = draw(
        st.lists(
            st.tuples(st.integers(1, 4), st.integers(1, 4)).map(tuple),
            min_size=1,
            max_size=3,
        )
    )
    rgb = draw(st.booleans()) and not imagej
    meta = draw(
        st.dictionaries(
            st.sampled_from(["spacing", "unit", "xorigin", "zorigin", "vunit", "axes"]),
            st.one_of(st.sampled_from(["nan", "micron", "km", "ZYX", ""]), bad_numbers),
            max_size=3,
        )
    )
    try:
        with tifffile.TiffWriter(buf, imagej=imagej) as tw:
            for i, shape in enumerate(shapes):
                page = np.arange(int(np.prod(shape)) * (3 if rgb else 1), dtype=dtype)
                page = page.reshape((*shape, 3) if rgb else shape)
                kw: dict[str, Any] = {"contiguous": draw(st.booleans()) and not imagej}
                if imagej and i == 0:
                    kw["metadata"] = {
                        k: (v if isinstance(v, str) else float(v)) for k, v in meta.items()
                    }
                if draw(st.booleans()):
                    kw["resolution"] = draw(
                        st.sampled_from([(1.0, 1.0), (0.0, 1.0), (1e-30, 1e30), (2.0, 3.0)])
                    )
                tw.write(page, photometric="rgb" if rgb else "minisblack", **kw)
    except (ValueError, TypeError, OverflowError):  # tifffile refuses it: not a case
        reject()
    return draw(mutated_bytes(buf.getvalue(), keep=0.4))


@fuzz_settings(60)
@given(
    files=st.lists(tiff_bytes(), min_size=1, max_size=3),
    as_folder=st.booleans(),
    extension=st.sampled_from([".tif", ".tiff", ".TIF"]),
)
def test_tiff(files, as_folder, extension) -> None:
    """Single- and multi-page TIFF (ImageJ or plain, grey or RGB, pages of different
    sizes, bad resolution and ImageJ metadata), damaged; files and folders of slices."""
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        for i, blob in enumerate(files):
            (d / f"s{i:02d}{extension}").write_bytes(blob)
        run_load("tiff", d if as_folder else d / f"s00{extension}")


# ---------------------------------------------------------------------------- paths
@fuzz_settings(40)
@given(
    kind=st.sampled_from(
        [
            "missing",
            "empty-file",
            "dir-named-npy",
            "symlink-to-dir",
            "dangling-symlink",
            "empty-dir",
            "nul-in-name",
            "no-extension",
            "unknown-extension",
            "symlink-loop",
        ]
    ),
    suffix=st.sampled_from([".npy", ".npz", ".nrrd", ".nii", ".tif", ".raw", ".json", ".dcm"]),
)
def test_odd_paths(kind, suffix) -> None:
    """Paths that are not regular volume files: missing, empty, a folder with a volume's
    extension, symlinks to folders, dangling or looping symlinks, a FIFO."""
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        target: Any = d / f"v{suffix}"
        if kind == "empty-file":
            target.write_bytes(b"")
        elif kind == "dir-named-npy":
            target.mkdir()
            (target / f"inner{suffix}").write_bytes(b"\0" * 8)
        elif kind == "symlink-to-dir":
            (d / "sub").mkdir()
            os.symlink(d / "sub", target)
        elif kind == "dangling-symlink":
            os.symlink(d / "nowhere", target)
        elif kind == "empty-dir":
            target = d
        elif kind == "nul-in-name":
            target = f"{d}/v\0{suffix}"
        elif kind == "no-extension":
            target = d / "volume"
            target.write_bytes(b"\x93NUMPY")
        elif kind == "unknown-extension":
            target = d / "volume.xyz"
            target.write_bytes(b"data")
        elif kind == "symlink-loop":
            os.symlink(d / f"w{suffix}", target)
            os.symlink(target, d / f"w{suffix}")
        run_load("paths", target)


def test_fifo_does_not_hang(tmp_path: Path) -> None:
    """A named pipe with a volume's extension is refused, not read (reading blocks)."""
    fifo = tmp_path / "v.npy"
    os.mkfifo(fifo)
    with time_limit(2.0):
        try:
            load_volume(fifo)
        except VolumeError as exc:
            assert_one_line(str(exc), "VolumeError")
        else:
            pytest.fail("a FIFO loaded as a volume")


def test_nrrd_nul_in_data_file(tmp_path: Path) -> None:
    """The minimal input the NRRD fuzz found: ``data file:\\x00v.raw``."""
    (tmp_path / "v.raw").write_bytes(bytes(24))
    header = b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 3 4\nencoding: raw\n"
    (tmp_path / "v.nhdr").write_bytes(header + b"data file:\x00v.raw\n")
    with pytest.raises(VolumeError) as info:
        load_volume(tmp_path / "v.nhdr")
    assert_one_line(str(info.value), "VolumeError")
