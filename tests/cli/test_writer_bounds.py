"""Writers and their sizes (issue 33): every export and slice size is checked before any
work, native writers never run into a limit they cannot survive, and a killed writer's
temporary file is gone after the next run.

Oracles: the CLI run in a child process (rc, exactly one stderr line naming the problem
and the fix, no traceback, no file and no temporary left); the written files' sizes
against the estimates; ``os.listdir`` of the output folder after a ``kill -9``.
"""

from __future__ import annotations

import contextlib
import os
import resource
import signal
import subprocess
import sys
import time
import warnings
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from tests.run_cli import REPO, run_cli
from voxwarp.cli.slice import pixel_note, useful_slab
from voxwarp.core.files import is_temp_name
from voxwarp.core.slice_plane import parse_plane
from voxwarp.core.volume import Volume
from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.scene import Scene


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 24x20x16 volume of 1 mm voxels (the issue's size), as a scene JSON."""
    rng = np.random.default_rng(3)
    vol = Volume(rng.integers(0, 200, (24, 20, 16), dtype=np.int16), spacing=(1, 1, 1))
    return Scene(vol).save(tmp_path_factory.mktemp("scene") / "scene.json")


def _one_line_error(proc: subprocess.CompletedProcess, *words: str) -> str:
    """The one stderr line of a refused run, checked to name every word."""
    err = proc.stderr
    assert proc.returncode not in (0, None), err
    assert "Traceback" not in err, err
    assert err.count("\n") == 1, err
    for word in words:
        assert word in err, (word, err)
    return err


def _leftovers(folder: Path) -> list[str]:
    return sorted(n for n in os.listdir(folder) if is_temp_name(n))


# ---------------------------------------------------------------------------- sizes
@pytest.mark.timeout(20)
def test_export_volume_huge_grid_is_refused_before_any_work(
    scene_file: Path, tmp_path: Path
) -> None:
    """--spacing 0.01 of a 24x20x16 mm box: 2400x2000x1600 int16 voxels (14 GiB) are
    over a 1 GiB budget; refused with the estimate, at once, nothing written."""
    out = tmp_path / "e.nrrd"
    t0 = time.perf_counter()
    proc = run_cli(
        "export-volume", str(scene_file), "-o", str(out), "--spacing", "0.01",
        "--memory-budget", "1G", timeout=20,
    )  # fmt: skip
    err = _one_line_error(proc, "2400x2000x1600", "over the memory budget", "--spacing")
    assert "GiB" in err
    assert time.perf_counter() - t0 < 15
    assert os.listdir(tmp_path) == []


@pytest.mark.timeout(20)
def test_export_volume_nifti_side_limit(scene_file: Path, tmp_path: Path) -> None:
    """1e-6 mm along z: 16,000,000 slices, over NIfTI's int16 dim (was nibabel's
    HeaderDataError traceback); 1e-7 is below the smallest voxel size."""
    out = tmp_path / "e.nii.gz"
    proc = run_cli("export-volume", str(scene_file), "-o", str(out), "--spacing", "1,1,1e-6")
    _one_line_error(proc, "32767", ".nrrd", "--spacing")
    proc = run_cli("export-volume", str(scene_file), "-o", str(out), "--spacing", "1,1,1e-7")
    _one_line_error(proc, "1e-06", "--spacing")
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("value", ["1e-300", "0", "inf", "1e9"])
def test_volume_spacing_outside_sane_range_is_refused(value: str, tmp_path: Path) -> None:
    proc = run_cli("info", "sample:head", "--spacing", value, "1", "1")
    _one_line_error(proc, "--spacing", "1e-06", "1e+06")


def test_pixel_note_says_which_pixel_is_used() -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        pixel_note(None, 0.5)
        pixel_note(0.5, 0.5 * (1 + 1e-9))
        assert caught == []
        pixel_note(1e-6, 0.02461)
    assert len(caught) == 1
    text = str(caught[0].message)
    assert "--pixel 1e-06" in text
    assert "0.02461" in text
    assert "\n" not in text


def test_slab_is_clamped_to_the_deformed_box() -> None:
    """A plane through the middle of a 10x20x40 mm box along z: the farthest corner is
    20 mm away, so slabs up to 40 mm are kept and thicker ones become 40 mm."""
    vol = Volume(np.zeros((10, 20, 40), dtype=np.uint8), spacing=(1, 1, 1))
    scene = Scene(vol)
    lo, hi = (np.asarray(b, dtype=np.float64) for b in scene.deformed_bounds())
    plane = parse_plane("z", (lo, hi))
    assert useful_slab(scene, plane, 12.0) == 12.0
    assert useful_slab(scene, plane, 40.0) == 40.0
    with pytest.warns(UserWarning, match="--slab 1e\\+06 mm"):
        assert useful_slab(scene, plane, 1e6) == pytest.approx(40.0)


# ---------------------------------------------------------------------------- native writers
def _limited(limit: int) -> None:
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))


@pytest.mark.timeout(30)
@pytest.mark.parametrize("suffix", [".h5", ".mha"])
def test_export_field_under_a_file_size_limit(
    suffix: str, scene_file: Path, tmp_path: Path
) -> None:
    """24x20x16 nodes x 3 float64 (SimpleITK writes doubles) = 180 KiB: under a 64 KiB
    ``ulimit -f`` HDF5 used to die of SIGSEGV; now one line before any write."""
    out = tmp_path / f"f{suffix}"
    cmd = [sys.executable, "-m", "voxwarp.cli.main", "export-field", str(scene_file)]
    proc = subprocess.run(
        [*cmd, "-o", str(out), "--spacing", "1"],
        capture_output=True, text=True, cwd=REPO, timeout=30, check=False,
        env={**os.environ, "PYTHONPATH": str(REPO)}, preexec_fn=lambda: _limited(64 << 10),
    )  # fmt: skip
    _one_line_error(proc, "file-size limit", "ulimit -f", "--spacing")
    assert proc.returncode > 0  # an error, not a signal
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("name", ["x.h5", "x.mha"])
def test_native_field_writer_prints_nothing_itself(
    name: str, tmp_path: Path, capfd: pytest.CaptureFixture
) -> None:
    """HDF5 prints its error stack (MetaImage its own line) on fd 2 when it cannot create
    the file: held back; the one OSError names the reason."""
    from voxwarp.io.fields import _write_sitk

    field = DisplacementFieldWarp(np.zeros((4, 4, 4, 3), np.float32), np.eye(4))
    capfd.readouterr()
    with pytest.raises(OSError, match="No such file or directory") as info:
        _write_sitk(field, tmp_path / "missing" / name, {})
    out, err = capfd.readouterr()
    assert err == ""
    assert out == ""
    assert "\n" not in str(info.value)
    assert "No such file or directory" in str(info.value)


# ---------------------------------------------------------------------------- kill -9
def _start_export(scene: Path, out: Path) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "voxwarp.cli.main", "export-volume", str(scene)]
    return subprocess.Popen(
        [*cmd, "-o", str(out), "--spacing", "0.05", "--no-progress"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )  # fmt: skip


@pytest.mark.timeout(40)
def test_killed_export_leaves_no_temp_after_the_rerun(scene_file: Path, tmp_path: Path) -> None:
    """kill -9 while the temporary file grows; a rerun (here one refused by its size)
    removes it first, whatever becomes of the rerun itself."""
    out = tmp_path / "e.nii"
    proc = _start_export(scene_file, out)
    try:
        deadline = time.monotonic() + 30
        while not _leftovers(tmp_path) and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.02)
        assert _leftovers(tmp_path), "the export never started writing"
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    finally:
        with contextlib.suppress(ProcessLookupError):
            proc.kill()
    assert _leftovers(tmp_path)
    assert not out.exists()
    rerun = run_cli(
        "export-volume", str(scene_file), "-o", str(out), "--spacing", "0.01",
        "--memory-budget", "1G",
    )  # fmt: skip
    _one_line_error(rerun, "over the memory budget")
    assert os.listdir(tmp_path) == []


@pytest.mark.timeout(20)
def test_export_volume_over_the_file_size_limit_is_refused_first(
    scene_file: Path, tmp_path: Path
) -> None:
    """24x20x16 int16 at 0.5 mm: 48x40x32 voxels, 120 KiB + the header allowance, over
    a 64 KiB ``ulimit -f``: refused before any slice is drawn."""
    out = tmp_path / "e.nii.gz"
    cmd = [sys.executable, "-m", "voxwarp.cli.main", "export-volume", str(scene_file)]
    proc = subprocess.run(
        [*cmd, "-o", str(out), "--spacing", "0.5"],
        capture_output=True, text=True, cwd=REPO, timeout=20, check=False,
        env={**os.environ, "PYTHONPATH": str(REPO)}, preexec_fn=lambda: _limited(64 << 10),
    )  # fmt: skip
    _one_line_error(proc, "file-size limit", "--spacing")
    assert os.listdir(tmp_path) == []


# ---------------------------------------------------------------------------- disk faults
@pytest.fixture
def small_fs(tmp_path: Path) -> Iterator[Path]:
    """A 4 MiB tmpfs (skipped where mounting is not permitted; RLIMIT_FSIZE covers it)."""
    folder = tmp_path / "fs"
    folder.mkdir()
    mount = ["mount", "-t", "tmpfs", "-o", "size=4m", "tmpfs", str(folder)]
    if subprocess.run(mount, capture_output=True, check=False).returncode != 0:
        pytest.skip("mounting a tmpfs is not permitted here")
    try:
        yield folder
    finally:
        subprocess.run(["umount", "-l", str(folder)], capture_output=True, check=False)


@pytest.mark.timeout(40)
@pytest.mark.parametrize("suffix", [".h5", ".mha"])
def test_export_field_on_full_and_read_only_disks(
    suffix: str, scene_file: Path, small_fs: Path
) -> None:
    """HDF5 printed 23-54 lines on these, MetaImage its own line, before voxwarp's."""
    out = small_fs / f"f{suffix}"
    remount = ["mount", "-o", "remount,ro", str(small_fs)]
    if subprocess.run(remount, capture_output=True, check=False).returncode != 0:
        pytest.skip("remounting read-only is not permitted here")
    proc = run_cli("export-field", str(scene_file), "-o", str(out), "--spacing", "1")
    # the plan and the "no warps" warning come first (the write fails after them): every
    # line is voxwarp's own, one error, nothing of HDF5's or MetaImage's
    lines = proc.stderr.splitlines()
    assert proc.returncode == 2
    assert lines[-1].startswith("voxwarp: error: cannot write")
    assert "read-only file system" in lines[-1]
    assert [line for line in lines if "error" in line.lower()] == lines[-1:]
    assert all(line.startswith(("voxwarp: ", "spacing ")) for line in lines), lines
    subprocess.run(["mount", "-o", "remount,rw", str(small_fs)], check=True)
    with open(small_fs / "filler", "wb") as fh:
        with contextlib.suppress(OSError):
            while True:
                fh.write(b"\0" * 65536)
    proc = run_cli("export-field", str(scene_file), "-o", str(out), "--spacing", "1")
    _one_line_error(proc, "free on its disk", "--spacing")
    assert sorted(os.listdir(small_fs)) == ["filler"]
