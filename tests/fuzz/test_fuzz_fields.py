"""Fuzz the displacement field readers with broken files: NIfTI (headers too), NRRD,
MetaImage, ITK transform files (.h5, .tfm) and .npz.

Each case starts from a valid field written by voxwarp or SimpleITK and breaks it;
:func:`voxwarp.io.fields.load_transform` must return warps or raise a one-line
VoxwarpError, within the per-case time limit (``tests/fuzz/_support.py``).
"""

from __future__ import annotations

import tempfile
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.fuzz._mutate import mutated_bytes
from tests.fuzz._support import fuzz_settings, outcome
from tests.fuzz.test_fuzz_volumes import nifti_field
from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.io.fields import load_transform, save_displacement_field

pytest.importorskip("SimpleITK")

SUFFIXES = [".nii", ".nii.gz", ".nrrd", ".mha", ".h5", ".tfm", ".npz"]


@cache
def valid_bytes(suffix: str) -> bytes:
    """A small valid field file of the format (4x3x3 nodes, oblique grid)."""
    rng = np.random.default_rng(0)
    a = np.eye(4)
    a[:3, :3] = np.array([[0.0, -2.0, 0.0], [1.5, 0.0, 0.0], [0.0, 0.0, 3.0]])
    a[:3, 3] = (10.0, -5.0, 2.0)
    field = DisplacementFieldWarp(rng.normal(0, 1, (4, 3, 3, 3)), a)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"f{suffix}"
        if suffix == ".tfm":
            import SimpleITK as sitk

            from voxwarp.io.fields import field_image

            sitk.WriteTransform(sitk.DisplacementFieldTransform(field_image(field)), str(path))
        else:
            save_displacement_field(field, path)
        return path.read_bytes()


def run(test: str, suffix: str, blob: bytes) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"field{suffix}"
        path.write_bytes(blob)
        outcome(test, lambda: load_transform(path))


@fuzz_settings(140)
@given(suffix=st.sampled_from(SUFFIXES), data=st.data())
def test_field_files(suffix: str, data: st.DataObject) -> None:
    """Truncated, flipped, overwritten and padded field files of every format."""
    run("fields", suffix, data.draw(mutated_bytes(valid_bytes(suffix), keep=0.05)))


@fuzz_settings(60)
@given(fields=st.lists(nifti_field(), min_size=1, max_size=3), data=st.data())
def test_nifti_field_headers(fields: list, data: st.DataObject) -> None:
    """NIfTI field headers with broken dims, datatypes, s/qforms, intents and magic."""
    raw = bytearray(valid_bytes(".nii"))
    for offset, value in fields:
        raw[offset : offset + len(value)] = value
    intent = data.draw(st.sampled_from([None, 0, 1006, 1007, 1011, -5, 32767]))
    if intent is not None:
        raw[68:70] = int(intent).to_bytes(2, "little", signed=True)
    run("field NIfTI headers", ".nii", bytes(raw))
