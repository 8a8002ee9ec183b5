"""``--allow-dir``: the one rule for files that other files name (scenes, detached NRRD
and MetaImage data), for volumes and fields alike (voxwarp.core.allowed_folders).

Oracles: a refusal is exactly one stderr line naming the file and ``--allow-dir FOLDER``;
the same command with that option succeeds and reads the named file's voxels."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.run_cli import run_cli
from voxwarp.core.allowed_folders import allowed_folders
from voxwarp.core.volume import Volume
from voxwarp.errors import FieldError, VolumeError
from voxwarp.io.volumes import load_volume, save_volume

DATA = np.arange(5 * 6 * 7, dtype=np.float32).reshape(5, 6, 7)


def _one_line_refusal(proc: object, *needles: str) -> None:
    assert proc.returncode != 0  # type: ignore[attr-defined]
    lines = proc.stderr.strip().splitlines()  # type: ignore[attr-defined]
    assert len(lines) == 1, proc.stderr  # type: ignore[attr-defined]
    assert "Traceback" not in lines[0]
    for needle in needles:
        assert needle in lines[0], lines[0]


def test_a_scene_naming_a_volume_elsewhere_needs_allow_dir(tmp_path: Path) -> None:
    target = save_volume(Volume(DATA), tmp_path / "shared/v.nrrd").resolve()
    scene = tmp_path / "scn/s.json"
    scene.parent.mkdir()
    scene.write_text(
        json.dumps({"format": "voxwarp-scene", "volume": {"path": "../shared/v.nrrd"}})
    )
    _one_line_refusal(run_cli("info", str(scene)), str(target), f"--allow-dir {target.parent}")
    proc = run_cli("info", str(scene), "--allow-dir", str(target.parent))
    assert proc.returncode == 0, proc.stderr
    assert "(5, 6, 7)" in proc.stdout


def _mhd(header: Path, data_name: str, components: int) -> Path:
    header.parent.mkdir(parents=True, exist_ok=True)
    header.write_text(
        "ObjectType = Image\nNDims = 3\nDimSize = 2 3 4\n"
        f"ElementNumberOfChannels = {components}\nElementType = MET_FLOAT\n"
        "ElementSpacing = 1 1 1\nOffset = 0 0 0\nTransformMatrix = 1 0 0 0 1 0 0 0 1\n"
        f"ElementDataFile = {data_name}\n"
    )
    return header


@pytest.mark.parametrize("kind", ["volume", "field"])
def test_metaimage_data_files_follow_one_rule_for_volumes_and_fields(
    tmp_path: Path, kind: str
) -> None:
    """A ``.mhd``'s data in a subfolder loads; ``../`` is refused with the --allow-dir
    hint; allowed, it loads: the same for the volume and the field reader."""
    pytest.importorskip("SimpleITK")
    from voxwarp.io.fields import load_transform

    components = 1 if kind == "volume" else 3
    values = np.arange(2 * 3 * 4 * components, dtype="<f4")
    read = load_volume if kind == "volume" else load_transform
    error = VolumeError if kind == "volume" else FieldError
    (tmp_path / "hdr/data").mkdir(parents=True)
    (tmp_path / "hdr/data/x.raw").write_bytes(values.tobytes())
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere/x.raw").write_bytes(values.tobytes())
    read(_mhd(tmp_path / "hdr/in.mhd", "data/x.raw", components))  # a subfolder: fine
    out = _mhd(tmp_path / "hdr/out.mhd", "../elsewhere/x.raw", components)
    with pytest.raises(error) as info:
        read(out)
    msg = str(info.value)
    assert "\n" not in msg
    assert "outside the header's folder" in msg
    assert f"--allow-dir {(tmp_path / 'elsewhere').resolve()}" in msg
    with allowed_folders([tmp_path / "elsewhere"]):
        read(out)
