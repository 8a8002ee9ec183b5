"""Issue 33: one rule for files other files name (detached NRRD/MetaImage data, scene
paths): regular files only, inside the naming file's folder; a FIFO named there hung
the reader forever before."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from voxwarp.errors import FieldError, SceneError, VolumeError
from voxwarp.io.volumes import load_volume

NHDR = "NRRD0004\ntype: float\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: {}\n\n"
MHD = (
    "ObjectType = Image\nNDims = 3\nDimSize = 2 2 2\nElementType = MET_FLOAT\n"
    "ElementDataFile = {}\n"
)


@pytest.mark.timeout(20)
@pytest.mark.parametrize("suffix", [".nhdr", ".mhd"])
def test_fifo_as_detached_data_is_refused(suffix: str, tmp_path: Path) -> None:
    if suffix == ".mhd":
        pytest.importorskip("SimpleITK")
    os.mkfifo(tmp_path / "data.raw")
    header = tmp_path / f"v{suffix}"
    header.write_text((NHDR if suffix == ".nhdr" else MHD).format("data.raw"))
    with pytest.raises(VolumeError, match=r"data file .* is a pipe \(FIFO\)"):
        load_volume(header)


@pytest.mark.timeout(20)
def test_fifo_as_field_mhd_data_is_refused(tmp_path: Path) -> None:
    pytest.importorskip("SimpleITK")
    from voxwarp.io.fields import load_transform

    os.mkfifo(tmp_path / "u.raw")
    header = tmp_path / "u.mhd"
    header.write_text(
        MHD.format("u.raw").replace("MET_FLOAT", "MET_FLOAT\nElementNumberOfChannels = 3")
    )
    with pytest.raises(FieldError, match=r"pipe \(FIFO\)"):
        load_transform(header)


def test_mhd_data_file_linked_outside_is_refused(tmp_path: Path) -> None:
    pytest.importorskip("SimpleITK")
    outside = tmp_path / "outside"
    inside = tmp_path / "in"
    outside.mkdir()
    inside.mkdir()
    np.zeros(8, np.float32).tofile(outside / "data.raw")
    (inside / "data.raw").symlink_to(outside / "data.raw")
    (inside / "v.mhd").write_text(MHD.format("data.raw"))
    with pytest.raises(VolumeError, match="outside the header's folder"):
        load_volume(inside / "v.mhd")
    (inside / "data.raw").unlink()
    np.zeros(8, np.float32).tofile(inside / "data.raw")
    assert load_volume(inside / "v.mhd").shape == (2, 2, 2)


@pytest.mark.timeout(20)
def test_scene_volume_path_fifo_is_refused(tmp_path: Path) -> None:
    from voxwarp.scene import Scene

    os.mkfifo(tmp_path / "v.nii")
    scene = tmp_path / "s.json"
    scene.write_text(json.dumps({"format": "voxwarp-scene", "volume": {"path": "v.nii"}}))
    with pytest.raises(SceneError, match=r"scene volume path .* pipe \(FIFO\)"):
        Scene.load(scene)


@pytest.mark.timeout(20)
@pytest.mark.parametrize("target", ["/proc/self/environ", "/dev/zero"])
def test_kernel_and_device_files_are_refused_even_through_a_link(
    target: str, tmp_path: Path
) -> None:
    """/proc files are 'regular' to stat but may block (/proc/kmsg) or leak the
    environment; /dev/zero never ends. A link named like a volume does not help."""
    link = tmp_path / "v.nii"
    link.symlink_to(target)
    with pytest.raises(VolumeError, match=r"not a regular file \(a (file of the kernel|char)"):
        load_volume(link)
