"""Fuzz the readers issue 33 attacked, with structured hostile values (not only flipped
bytes): ITK text transforms (grid sizes and Parameters counts), NRRD field headers,
``.npz`` npy headers, ParaView/Slicer transfer-function files and scene JSON text (BOM,
NaN, duplicate keys, nesting). Each case must return or raise a one-line VoxwarpError
within the per-case limit; no native abort, traceback or hang."""

from __future__ import annotations

import io
import json
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.fuzz._mutate import deep_nesting, json_value
from tests.fuzz._support import fuzz_settings, outcome
from voxwarp.core import limits
from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.io.fields import load_transform, save_displacement_field

#: grid sizes and numbers a hostile FixedParameters line states
_SIZES = st.one_of(
    st.integers(1, 6),
    st.sampled_from([0, -4, 100000, 2**31, 2**63, 10**30]),
    st.sampled_from(["nan", "inf", "-inf", "4.5", "1e308", "x", "0x10"]),
)
_NAMES = st.sampled_from(
    [
        "BSplineTransform_double_3_3",
        "BSplineTransform_float_3_3",
        "BSplineTransform_double_2_2",
        "DisplacementFieldTransform_double_3_3",
        "AffineTransform_double_3_3",
        "MatrixOffsetTransformBase_double_3_3",
        "Euler3DTransform_double_3_3",
        "TranslationTransform_double_3_3",
        "ScaleTransform_double_3_3",
        "CompositeTransform_double_3_3",
    ]
)
_NUMBER = st.one_of(
    st.floats(-10, 10, allow_nan=False),
    st.sampled_from([0.0, 1.0, 1e300, -1e300, float("nan"), float("inf")]),
)


@st.composite
def itk_text_transform(draw: st.DrawFn) -> str:
    """One to three transforms with hostile grid sizes and Parameters counts."""
    parts = ["#Insight Transform File V1.0"]
    for k in range(draw(st.integers(1, 3))):
        sizes = [str(draw(_SIZES)) for _ in range(3)]
        rest = "0 0 0 1 1 1 1 0 0 0 1 0 0 0 1".split()
        rest = rest[: draw(st.integers(0, len(rest)))] if draw(st.booleans()) else rest
        grid = 1
        for s in sizes:
            grid *= int(s) if s.lstrip("-").isdigit() and 0 < int(s) < 8 else 1
        count = draw(st.sampled_from([3 * grid, 3 * grid + 1, 0, 3, 12]))
        params = " ".join(repr(draw(_NUMBER)) for _ in range(min(count, 200)))
        parts += [
            f"#Transform {k}",
            f"Transform: {draw(_NAMES)}",
            f"Parameters: {params}",
            f"FixedParameters: {' '.join(sizes + rest)}",
        ]
    return "\n".join(parts) + "\n"


def _load(tmp: str, name: str, data: bytes) -> None:
    path = Path(tmp) / name
    path.write_bytes(data)
    outcome(f"readers: {Path(name).suffix or name}", lambda: load_transform(path))


@fuzz_settings(300)
@given(text=itk_text_transform(), suffix=st.sampled_from([".tfm", ".txt"]))
def test_itk_text_transforms(text: str, suffix: str) -> None:
    pytest.importorskip("SimpleITK")
    with tempfile.TemporaryDirectory() as tmp, limits.memory_budget("256M"):
        _load(tmp, f"t{suffix}", text.encode())


def _bspline_h5() -> bytes:
    import SimpleITK as sitk

    t = sitk.BSplineTransformInitializer(sitk.Image([8, 8, 8], sitk.sitkFloat32), [3, 3, 3])
    with tempfile.TemporaryDirectory() as tmp:
        sitk.WriteTransform(t, str(Path(tmp) / "b.h5"))
        return (Path(tmp) / "b.h5").read_bytes()


@fuzz_settings(60)
@given(
    sizes=st.lists(
        st.one_of(st.sampled_from([0.0, -6.0, 1e5, 1e12, 2.0**63, 6.5]), st.floats()),
        min_size=3,
        max_size=3,
    )
)
def test_itk_h5_bspline_grid_sizes(sizes: list[float]) -> None:
    """The grid-size doubles of an ITK .h5 B-spline replaced by hostile ones."""
    pytest.importorskip("SimpleITK")
    import struct

    raw = _bspline_h5()
    six = struct.pack("<d", 6.0) * 3
    blob = raw.replace(six, struct.pack("<3d", *sizes))
    with tempfile.TemporaryDirectory() as tmp, limits.memory_budget("256M"):
        _load(tmp, "t.h5", blob)


# ---------------------------------------------------------------------------- NRRD fields
def _nrrd_field() -> bytes:
    u = np.random.default_rng(0).normal(0, 1, (3, 3, 2, 3)).astype(np.float32)
    with tempfile.TemporaryDirectory() as tmp:
        path = save_displacement_field(DisplacementFieldWarp(u, np.eye(4)), Path(tmp) / "f.nrrd")
        return path.read_bytes()


NRRD_FIELD = _nrrd_field()
_NRRD_VALUES = {
    "space directions": [
        "none (1,0,0) (0,1,0)",
        "none (1,0) (0,1) (0,0)",
        "(1,0,0) (0,1,0) (0,0,1) (1,1,1)",
        "none (nan,0,0) (0,1,0) (0,0,1)",
        "none none none none",
        "none (1,0,0) (0,1,0) (0,0,1) (0,0,1)",
        "garbage",
    ],
    "sizes": ["3 3 3 2", "3 100000 100000 100000", "3 0 3 2", "3 -3 3 2", "3 3 3", "x"],
    "kinds": ["domain domain domain domain", "vector vector domain domain", "list", ""],
    "space": ["right-anterior-superior", "scanner-xyz", "3D-right-handed", ""],
    "space origin": ["(0,0)", "(nan,0,0)", "none", "(1e308,1e308,1e308)"],
    "type": ["double", "uint8", "block", "float16"],
    "encoding": ["raw", "gzip", "bzip2", "hex"],
    "measurement frame": ["(1,0,0) (0,1,0)", "(nan,0,0) (0,1,0) (0,0,1)"],
}


@st.composite
def nrrd_header_edit(draw: st.DrawFn) -> bytes:
    head, sep, body = NRRD_FIELD.partition(b"\n\n")
    lines = head.decode().split("\n")
    for _ in range(draw(st.integers(1, 3))):
        key = draw(st.sampled_from(sorted(_NRRD_VALUES)))
        value = draw(st.sampled_from(_NRRD_VALUES[key]))
        lines = [x for x in lines if not x.startswith(f"{key}:")] + [f"{key}: {value}"]
    return "\n".join(lines).encode() + sep + body


@fuzz_settings(200)
@given(blob=nrrd_header_edit())
def test_nrrd_field_headers(blob: bytes) -> None:
    with tempfile.TemporaryDirectory() as tmp, limits.memory_budget("256M"):
        _load(tmp, "f.nrrd", blob)


# ---------------------------------------------------------------------------- npz fields
@st.composite
def npz_member(draw: st.DrawFn) -> bytes:
    """An .npz whose displacement member's npy header states a hostile shape/dtype."""
    dim = st.one_of(st.integers(0, 5), st.sampled_from([-1, 4000, 2**31, 2**40]))
    shape = tuple(draw(dim) for _ in range(draw(st.integers(0, 5))))
    descr = draw(st.sampled_from(["<f4", "<f8", "|u1", "<c16", "|O", "<U4", "|V8"]))
    payload = bytes(draw(st.integers(0, 600)))
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        with zf.open("displacement.npy", "w") as fh:
            head = {"descr": descr, "fortran_order": draw(st.booleans()), "shape": shape}
            try:
                np.lib.format.write_array_header_1_0(fh, head)
            except ValueError:
                fh.write(b"\x93NUMPY\x01\x00" + b"\x10\x00{'descr': 5}    \n")
            fh.write(payload)
        aff = io.BytesIO()
        np.save(aff, np.eye(4))
        zf.writestr("affine.npy", aff.getvalue())
    return buf.getvalue()


@fuzz_settings(150)
@given(blob=npz_member())
def test_npz_field_members(blob: bytes) -> None:
    with tempfile.TemporaryDirectory() as tmp, limits.memory_budget("256M"):
        _load(tmp, "f.npz", blob)


# ---------------------------------------------------------------------------- TF files
_COUNT = st.one_of(
    st.integers(0, 12), st.sampled_from(["999999999", "9" * 40, "-4", "4.5", "x", "131074"])
)


@st.composite
def tf_file(draw: st.DrawFn) -> tuple[str, str]:
    """A ParaView JSON, Slicer presets.xml or .vp with hostile counts and values."""
    kind = draw(st.sampled_from(["paraview", "xml", "vp"]))
    values = draw(st.lists(_NUMBER, max_size=16))
    nums = " ".join(repr(v) for v in values)
    if kind == "paraview":
        doc = [{"Name": "m", "RGBPoints": values, "Points": draw(json_value)}]
        text = json.dumps(doc) if draw(st.booleans()) else json.dumps(deep_nesting(200))
        return "tf.json", text
    attr = f"{draw(_COUNT)} {nums}"
    if kind == "vp":
        return "tf.vp", "\n".join(["1", "0", "0.2", "0.9", "0.3", "10", attr, "2 0 1", attr])
    pre = draw(st.sampled_from(["", "<!-- " + "x" * 5000 + " -->", "<!DOCTYPE MRML>"]))
    return "presets.xml", (
        f'{pre}<MRML><VolumeProperty name="x" scalarOpacity="{attr}"'
        f' colorTransfer="{draw(_COUNT)} {nums}"/></MRML>'
    )


@fuzz_settings(200)
@given(case=tf_file())
def test_transfer_function_files(case: tuple[str, str]) -> None:
    from voxwarp.core.tf_formats import read_file

    name, text = case
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / name
        path.write_text(text)
        outcome("readers: TF files", lambda: read_file(str(path)))


# ---------------------------------------------------------------------------- scene text
SCENE = '{"format": "voxwarp-scene", "volume": {"sample": "tubes", "shape": [8, 8, 8]}'


@st.composite
def scene_text(draw: st.DrawFn) -> bytes:
    extra = draw(
        st.lists(
            st.sampled_from(
                [
                    '"iso_value": NaN',
                    '"step": Infinity',
                    '"mode": "mip", "mode": "dvr"',
                    '"volume": {"sample": "tubes", "sample": "fish"}',
                    '"warps": ' + "[" * 70 + "]" * 70,
                    '"description": "\\ud800"',
                    '"iso_value": 0.5',
                    '"window": [1e400, 1]',
                ]
            ),
            max_size=3,
        )
    )
    text = SCENE + "".join(f", {e}" for e in extra) + "}"
    raw = text.encode("utf-8")
    if draw(st.booleans()):
        raw = b"\xef\xbb\xbf" + raw
    if draw(st.booleans()):
        raw = raw[: draw(st.integers(0, len(raw)))]
    return raw


@fuzz_settings(150)
@given(raw=scene_text(), via=st.sampled_from(["scene", "napari"]))
def test_scene_json_text(raw: bytes, via: str) -> None:
    """Scene JSON text through Scene.load and through the napari reader."""
    from voxwarp.napari_plugin.reader import read_scene
    from voxwarp.scene import Scene

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "s.json"
        path.write_bytes(raw)
        load = Scene.load if via == "scene" else read_scene
        outcome(f"readers: scene text ({via})", lambda: load(path))
