"""Fuzz ``voxwarp info FOLDER`` on DICOM folders with hostile headers (issue 33).

Each case writes a small series (4x4 pixels, 1-5 slices, :mod:`tests.io.dicom_folders`)
and changes what a damaged or unusual folder holds: slice positions (missing, copied,
uneven, tilted, NaN), orientation, Rows/Columns up to 65535 over a short pixel data,
bit depth, samples, photometric interpretation, spacing, series and instance UIDs,
compressed transfer syntaxes over garbage, frames, extra files (DICOMDIR, text,
truncated copies, a second series) and ``--series``. The property is the command
line's, stricter than :func:`tests.fuzz._support.cli_outcome`: exit 0, or exit 2 with
exactly one stderr line (no warning before it), never a traceback, within the per-case
time limit.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, reject
from hypothesis import strategies as st

from tests.fuzz._support import CASES, ERROR_LINE, _record, fuzz_settings, time_limit
from tests.io import dicom_folders as df

COMPRESSED = [
    "1.2.840.10008.1.2.4.90",
    "1.2.840.10008.1.2.4.57",
    "1.2.840.10008.1.2.4.70",
    "1.2.840.10008.1.2.5",
    "1.2.840.10008.1.2.4.80",
]
#: header fields and hostile values, applied to one slice or to all
FIELDS: dict[str, list[Any]] = {
    "Rows": [0, 1, 3, 65535],
    "Columns": [0, 5, 65535],
    "BitsAllocated": [1, 8, 12, 32, 64],
    "SamplesPerPixel": [0, 3],
    "PhotometricInterpretation": ["MONOCHROME1", "RGB", "PALETTE COLOR", "YBR_FULL", ""],
    "PixelSpacing": [[0, 0], [-0.5, 0.5], ["nan", 1], [1], [1e-300, 1e300]],
    "SliceThickness": [0, -1, "nan"],
    "ImageOrientationPatient": [
        [1, 0, 0, 0, 0, -1],
        [0.9, 0.1, 0, 0, 1, 0],
        [1, 0, 0, 1, 0, 0],
        [0, 0, 0, 0, 0, 0],
        ["nan", 0, 0, 0, 1, 0],
        [1, 0, 0],
    ],
    "ImagePositionPatient": [["nan", 0, 0], [0, 0], [0, 0, 1e300], [5, 0, 2.5]],
    "SeriesInstanceUID": ["", df.UID + ".2"],
    "SOPInstanceUID": [df.UID + ".1", ""],
    "InstanceNumber": ["", -1],
    "NumberOfFrames": [0, 2, 1000],
    "RescaleSlope": [0, "nan", 1e300],
}
GEOMETRY = ["none", "drop", "copy", "other-at-same", "shift", "tilt", "reverse"]
EXTRAS = [None, "dicomdir", "text", "truncated", "empty"]


def _encapsulate_garbage(ds: Any, uid: str) -> None:
    from pydicom.encaps import encapsulate

    ds.file_meta.TransferSyntaxUID = uid
    ds.PixelData = encapsulate([b"\xff\x4f\xff\x51garbage" * 2])
    ds["PixelData"].VR = "OB"


def _geometry(datasets: list[Any], kind: str, k: int, amount: float) -> list[Any]:
    import copy

    k %= len(datasets)
    if kind == "drop" and len(datasets) > 2:
        return datasets[:k] + datasets[k + 1 :]
    if kind in ("copy", "other-at-same"):
        extra = copy.deepcopy(datasets[k])
        if kind == "other-at-same":
            extra.SOPInstanceUID = extra.file_meta.MediaStorageSOPInstanceUID = "1.2.3.99"
        return [*datasets, extra]
    if kind == "shift":
        ipp = [float(v) for v in datasets[k].ImagePositionPatient]
        datasets[k].ImagePositionPatient = [ipp[0], ipp[1], ipp[2] + amount]
    if kind == "tilt":
        for n, ds in enumerate(datasets):
            ipp = [float(v) for v in ds.ImagePositionPatient]
            ds.ImagePositionPatient = [ipp[0], ipp[1] + n * amount, ipp[2]]
    if kind == "reverse":
        return datasets[::-1]
    return datasets


def _run(argv: list[str]) -> str:
    """``voxwarp ARGV`` in this process: exit 0, or exit 2 with exactly one stderr line."""
    CASES["dicom folders"] += 1
    with time_limit():
        code, lines, text = df.cli_in_process(argv)
    assert "Traceback" not in text, text
    if code == 0:
        assert not any(ERROR_LINE.match(line) for line in lines), text
        result = "ok"
    else:
        assert code == 2, f"exit code {code}: {text}"
        assert len(lines) == 1, f"expected exactly one stderr line: {text}"
        assert ERROR_LINE.match(lines[0]), text
        result = "error"
    _record("dicom folders", result)
    return result


@pytest.mark.timeout(60)
@fuzz_settings(150)
@given(
    n=st.integers(1, 5),
    edits=st.lists(
        st.tuples(
            st.sampled_from(sorted(FIELDS)), st.integers(0, 5), st.booleans(), st.integers(0, 9)
        ),
        max_size=2,
    ),
    geometry=st.tuples(st.sampled_from(GEOMETRY), st.integers(0, 5), st.sampled_from([0.5, 3.0])),
    syntax=st.one_of(st.none(), st.sampled_from(COMPRESSED)),
    extra=st.sampled_from(EXTRAS),
    second=st.booleans(),
    series=st.sampled_from([None, None, "1", "2", "9", df.UID]),
)
def test_dicom_folder(n, edits, geometry, syntax, extra, second, series) -> None:
    """A small series with up to two hostile header fields, one geometry change, a
    compressed syntax over garbage, an extra file and maybe a second (intact, smaller)
    series, through ``voxwarp info``."""
    datasets = df.series(n, rows=4, cols=4)
    datasets = _geometry(datasets, *geometry)
    for name, which, everywhere, pick in edits:
        values = FIELDS[name]
        for ds in datasets if everywhere else [datasets[which % len(datasets)]]:
            setattr(ds, name, values[pick % len(values)])
    if syntax is not None:
        for ds in datasets:
            _encapsulate_garbage(ds, syntax)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "series"
        try:
            df.save(folder, datasets)
        except Exception:  # pydicom refuses to write this combination: not a case
            reject()
        _extra(folder, extra)
        if second:
            df.save(folder, df.series(1, rows=3, cols=3, uid=df.UID + ".7"), prefix="OTHER")
        argv = ["info", str(folder)] + ([] if series is None else ["--series", series])
        _run(argv)


def _extra(folder: Path, extra: str | None) -> None:
    first = sorted(folder.iterdir())[0]
    if extra == "dicomdir":
        (folder / "DICOMDIR").write_bytes(_dicomdir_bytes())
    elif extra == "text":
        (folder / "notes.txt").write_text("not DICOM\n")
    elif extra == "truncated":
        (folder / "IM9999.dcm").write_bytes(first.read_bytes()[: first.stat().st_size // 2])
    elif extra == "empty":
        (folder / "IM0000.dcm").write_bytes(b"")


_DICOMDIR: list[bytes] = []


def _dicomdir_bytes() -> bytes:
    """A real DICOMDIR indexing three slices in subfolders (made once)."""
    if not _DICOMDIR:
        from pydicom.fileset import FileSet

        with tempfile.TemporaryDirectory() as tmp:
            fs = FileSet()
            for p in sorted(df.save(Path(tmp) / "src", df.series(3)).iterdir()):
                fs.add(str(p))
            fs.write(str(Path(tmp) / "disc"))
            _DICOMDIR.append((Path(tmp) / "disc" / "DICOMDIR").read_bytes())
    return _DICOMDIR[0]


def test_fuzz_generator_changes_what_it_says() -> None:
    """The generator's edits reach the files: a dropped slice is gone, a tilt moves the
    positions sideways, a garbage syntax is in the meta (so the fuzz tests what it says)."""
    s = _geometry(df.series(6, rows=4, cols=4), "drop", 2, 0.5)
    assert len(s) == 5
    t = _geometry(df.series(6, rows=4, cols=4), "tilt", 0, 0.5)
    assert np.allclose([float(ds.ImagePositionPatient[1]) for ds in t], -3 + 0.5 * np.arange(6))
    ds = df.dataset(0, rows=4, cols=4)
    _encapsulate_garbage(ds, COMPRESSED[0])
    assert df.encoded(ds).count(COMPRESSED[0].encode()) == 1
