"""Every writer against a full disk, a read-only folder and injected faults.

Each writer (images, volumes in every format, scene JSON, meshes, text, teaching
figures, the CLI's ``-o``, ``--save-scene`` and ``--save-camera``) must, when the write
fails: raise :class:`~voxwarp.errors.OutputError` with one line naming the path and the
cause, keep the destination as it was (old content, or absent), and leave no temporary
file. Three ways to make a write fail:

* a tiny tmpfs filled to the last byte (``mount -t tmpfs``; skipped where the test may
  not mount), and the same tmpfs remounted read-only;
* always: a file-size limit (``RLIMIT_FSIZE``, so every library, OpenImageIO included,
  meets a real short write), and an ``os.replace`` that fails with ``EROFS``.
"""

from __future__ import annotations

import errno
import os
import re
import resource
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from tests.run_cli import run_cli
from voxwarp.core.files import (
    atomic_open,
    atomic_write,
    atomic_write_text,
    is_temp_name,
    output_error,
    remove_stale_temps,
    temp_name,
)
from voxwarp.core.mesh import Mesh
from voxwarp.core.volume import Volume
from voxwarp.errors import OutputError
from voxwarp.io.images import write_image
from voxwarp.io.volumes import load_volume, save_volume
from voxwarp.scene import Scene

OLD = b"old content\n"


# ---------------------------------------------------------------------------- writers
def _volume() -> Volume:
    rng = np.random.default_rng(1)
    return Volume(rng.integers(0, 255, (16, 16, 16), dtype=np.uint8), spacing=(1, 1, 2))


@pytest.fixture(scope="module")
def scene_volume(tmp_path_factory: pytest.TempPathFactory) -> Volume:
    """A volume from a file outside the failing folder (a scene JSON refers to it)."""
    return load_volume(save_volume(_volume(), tmp_path_factory.mktemp("src") / "v.npz"))


@pytest.fixture(scope="module")
def tiny_volume(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An 8^3 ramp: the CLI's render is quick, the test is about its outputs."""
    data = np.broadcast_to(np.arange(8, dtype=np.uint8) * 30, (8, 8, 8)).copy()
    return save_volume(Volume(data), tmp_path_factory.mktemp("tiny") / "tiny.npz")


def _mesh() -> Mesh:
    rng = np.random.default_rng(2)
    faces = np.stack([np.arange(200), np.arange(200) + 1, np.arange(200) + 2], axis=1)
    return Mesh(rng.random((300, 3)), faces, name="m")  # no degenerate faces


def _figure(path: Path) -> None:
    from matplotlib.figure import Figure

    from voxwarp.teaching.sheets import save_figure

    fig = Figure(figsize=(2, 2), dpi=50)
    fig.add_subplot().imshow(np.random.default_rng(3).random((20, 20)))
    save_figure(fig, path)


IMAGE = np.random.default_rng(0).integers(0, 255, (64, 64, 3), dtype=np.uint8)

#: name -> (destination file name, writer(path)); every payload is over 1 KiB
WRITERS: dict[str, tuple[str, Callable[..., object]]] = {
    "image-png": ("out.png", lambda p, _v: write_image(p, IMAGE)),
    "image-exr": ("out.exr", lambda p, _v: write_image(p, IMAGE.astype(np.float32) / 255)),
    "image-tif": ("out.tif", lambda p, _v: write_image(p, IMAGE)),
    "volume-npz": ("v.npz", lambda p, _v: save_volume(_volume(), p)),
    "volume-raw": ("v.raw", lambda p, _v: save_volume(_volume(), p)),
    "volume-nrrd": ("v.nrrd", lambda p, _v: save_volume(_volume(), p)),
    "volume-nii.gz": ("v.nii.gz", lambda p, _v: save_volume(_volume(), p)),
    "volume-tif": ("v.tif", lambda p, _v: save_volume(_volume(), p)),
    "scene-json": ("s.json", lambda p, v: Scene(v).save(p)),
    "mesh-ply": ("m.ply", lambda p, _v: _mesh().save(p)),
    "mesh-obj": ("m.obj", lambda p, _v: _mesh().save(p)),
    "text": ("t.md", lambda p, _v: atomic_write_text(p, "| a | b |\n" * 400)),
    "teaching-figure": ("f.png", lambda p, _v: _figure(p)),
}
IDS = list(WRITERS)


def _check_failure(exc: OutputError, dest: Path, cause: str | None) -> None:
    msg = str(exc)
    assert "\n" not in msg, msg
    # a raw volume's sidecar (DEST.json) may be the file that failed
    assert re.match(rf"cannot write {re.escape(str(dest))}(\.json)?: ", msg), msg
    if cause is not None:
        assert cause in msg, msg
    assert ".vwtmp" not in msg  # the user's path, not the temporary one


def _check_folder(folder: Path, expected: set[str]) -> None:
    names = {p.name for p in folder.iterdir()}
    assert not [n for n in names if is_temp_name(n)], names
    assert names == expected


# ---------------------------------------------------------------------------- tmpfs
def _run(*cmd: str) -> bool:
    return subprocess.run(cmd, capture_output=True, check=False).returncode == 0


@contextmanager
def _tmpfs(folder: Path, size: str = "64k") -> Iterator[Path]:
    folder.mkdir()
    if not _run("mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)):
        pytest.skip("mounting a tmpfs is not permitted here (fault injection covers it)")
    try:
        yield folder
    finally:
        _run("umount", "-l", str(folder))


def _fill(folder: Path) -> None:
    """Fill the file system of ``folder`` to the last byte."""
    with open(folder / "filler", "wb", buffering=0) as fh:
        code = None
        while code is None:
            try:
                fh.write(b"\0" * 1024)
            except OSError as exc:
                code = exc.errno
    assert code == errno.ENOSPC
    assert os.statvfs(folder).f_bavail == 0


@pytest.fixture
def full_fs(tmp_path: Path) -> Iterator[Path]:
    with _tmpfs(tmp_path / "full") as folder:
        yield folder


@pytest.fixture
def readonly_fs(tmp_path: Path) -> Iterator[Path]:
    with _tmpfs(tmp_path / "ro") as folder:
        yield folder


@pytest.mark.parametrize("name", IDS)
def test_full_disk_keeps_old_file(name: str, full_fs: Path, scene_volume: Volume) -> None:
    file, write = WRITERS[name]
    dest = full_fs / file
    dest.write_bytes(OLD)
    _fill(full_fs)
    with pytest.raises(OutputError) as info:
        write(dest, scene_volume)
    _check_failure(info.value, dest, "disk full (No space left on device")
    assert dest.read_bytes() == OLD
    _check_folder(full_fs, {file, "filler"})


@pytest.mark.parametrize("name", ["image-png", "volume-raw", "scene-json"])
def test_full_disk_leaves_nothing(name: str, full_fs: Path, scene_volume: Volume) -> None:
    file, write = WRITERS[name]
    _fill(full_fs)
    with pytest.raises(OutputError, match="disk full"):
        write(full_fs / "sub" / file, scene_volume)  # a new folder fits (no data blocks)
    assert not (full_fs / "sub" / file).exists()
    assert not [p for p in (full_fs / "sub").iterdir()]


@pytest.mark.parametrize("name", IDS)
def test_read_only_folder(name: str, readonly_fs: Path, scene_volume: Volume) -> None:
    file, write = WRITERS[name]
    dest = readonly_fs / file
    dest.write_bytes(OLD)
    if not _run("mount", "-o", "remount,ro", str(readonly_fs)):
        pytest.skip("remounting read-only is not permitted here")
    with pytest.raises(OutputError) as info:
        write(dest, scene_volume)
    _check_failure(info.value, dest, "read-only file system")
    assert info.value.errno == errno.EROFS
    assert dest.read_bytes() == OLD
    _check_folder(readonly_fs, {file})


# ---------------------------------------------------------------------------- injected
@contextmanager
def _file_size_limit(limit: int) -> Iterator[None]:
    """Writes past ``limit`` bytes of any file fail with EFBIG (a quota, for every library)."""
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    old_handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, old_handler)


@pytest.mark.parametrize("name", IDS)
def test_short_write_keeps_old_file(name: str, tmp_path: Path, scene_volume: Volume) -> None:
    file, write = WRITERS[name]
    folder = tmp_path / "out"
    folder.mkdir()
    dest = folder / file
    dest.write_bytes(OLD)
    with _file_size_limit(1024), pytest.raises(OutputError) as info:
        write(dest, scene_volume)
    # OpenImageIO and tifffile (numpy's tofile) report a short write without its errno:
    # their own text is the cause (the tmpfs tests check that a full disk is named)
    cause = None if name.startswith("image") or name == "volume-tif" else "file too large"
    _check_failure(info.value, dest, cause)
    assert dest.read_bytes() == OLD
    _check_folder(folder, {file})


@pytest.mark.parametrize("name", IDS)
def test_failed_rename_keeps_old_file(
    name: str, tmp_path: Path, scene_volume: Volume, monkeypatch: pytest.MonkeyPatch
) -> None:
    file, write = WRITERS[name]
    folder = tmp_path / "out"
    folder.mkdir()
    dest = folder / file
    dest.write_bytes(OLD)

    def replace(src: object, dst: object) -> None:
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(OutputError) as info:
        write(dest, scene_volume)
    _check_failure(info.value, dest, "read-only file system (Read-only file system)")
    assert dest.read_bytes() == OLD
    _check_folder(folder, {file})


# ---------------------------------------------------------------------------- helper
def test_failing_cleanup_does_not_hide_the_cause(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    real_unlink = os.unlink

    def unlink(path: object, *a: object, **k: object) -> None:
        raise OSError(errno.EROFS, "Read-only file system")

    def write_then_fail(tmp: Path) -> None:
        tmp.write_bytes(b"partial")
        monkeypatch.setattr(os, "unlink", unlink)
        raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(OutputError, match=r"disk full \(No space left on device\)"):
        atomic_write(tmp_path / "x.png", ".png", write_then_fail)
    monkeypatch.setattr(os, "unlink", real_unlink)


def test_other_errors_pass_through_and_clean_up(tmp_path: Path) -> None:
    def bug() -> None:
        with atomic_open(tmp_path / "a.json") as fh:
            fh.write("{")
            raise KeyError("bug")

    with pytest.raises(KeyError):
        bug()
    assert list(tmp_path.iterdir()) == []


def test_writer_that_writes_nothing(tmp_path: Path) -> None:
    with pytest.raises(OutputError, match="produced no file"):
        atomic_write(tmp_path / "a.bin", ".bin", lambda tmp: None)
    assert list(tmp_path.iterdir()) == []


def test_success_replaces_and_leaves_no_temp(tmp_path: Path) -> None:
    dest = tmp_path / "a.txt"
    dest.write_text("old")
    atomic_write_text(dest, "new")
    with atomic_open(tmp_path / "b.bin", "wb") as fh:
        fh.write(b"\1\2")
    assert dest.read_text() == "new"
    assert (tmp_path / "b.bin").read_bytes() == b"\1\2"
    _check_folder(tmp_path, {"a.txt", "b.bin"})


def test_temp_names_do_not_stack_and_are_recognised(tmp_path: Path) -> None:
    t = temp_name(tmp_path / "scene.json")
    assert t.name.startswith(".scene.json.")
    assert t.name.endswith(".vwtmp")
    assert ".tmp.tmp" not in t.name
    assert temp_name(tmp_path / "a.json", ".tmp").name.endswith(".vwtmp")
    nested = temp_name(t, ".png")  # the temporary of a temporary is of the real name
    assert nested.name.startswith(".scene.json.")
    assert nested.name.count(".vwtmp") == 1
    assert is_temp_name(t)
    assert is_temp_name(temp_name(tmp_path / "v.nii.gz", ".nii.gz"))
    assert is_temp_name(".scene.json.123-0123abcd.tmp.tmp")  # left by earlier versions
    assert not is_temp_name("scene.json")
    assert not is_temp_name(".hidden.json")


def test_remove_stale_temps(tmp_path: Path) -> None:
    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        capture_output=True,
        text=True,
        check=True,
    )
    dead_pid = int(dead.stdout)
    stale = tmp_path / f".out.png.{dead_pid}-0123abcd.vwtmp.png"
    legacy = tmp_path / f".s.json.{dead_pid}-89abcdef.tmp.tmp"
    live = temp_name(tmp_path / "out.png", ".png")  # this process: still writing
    other = tmp_path / f".x.json.{dead_pid}-01234567.vwtmp"
    keep = tmp_path / "out.png"
    for p in (stale, legacy, live, other, keep):
        p.write_bytes(b"x")
    assert set(remove_stale_temps(tmp_path, for_name="out.png")) == {stale}
    assert set(remove_stale_temps(tmp_path, min_age_s=3600)) == set()  # all are new
    assert set(remove_stale_temps(tmp_path)) == {legacy, other}
    assert {p.name for p in tmp_path.iterdir()} == {live.name, keep.name}


def test_output_error_is_one_line_for_library_text() -> None:
    err = output_error("/d/o.png", "Write error at position 1\nWrite error at position 2")
    assert "\n" not in str(err)
    assert str(err).startswith("cannot write /d/o.png: ")
    perm = output_error("/d/o.png", PermissionError(errno.EACCES, "Permission denied"))
    assert str(perm).startswith("cannot write /d/o.png: permission denied (Permission denied)")
    assert isinstance(perm, OSError)
    assert perm.errno == errno.EACCES


# ---------------------------------------------------------------------------- CLI


def _one_error_line(proc: subprocess.CompletedProcess, dest: Path, cause: str) -> None:
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    errors = [ln for ln in proc.stderr.splitlines() if ln.startswith("voxwarp: error:")]
    assert len(errors) == 1, proc.stderr
    assert errors[0].startswith(f"voxwarp: error: cannot write {dest}: {cause}"), errors


@pytest.mark.parametrize("option", ["-o", "--save-scene"])
def test_cli_render_on_full_disk(
    option: str, gl_ctx: object, tiny_volume: Path, full_fs: Path, tmp_path: Path
) -> None:
    names = {"-o": "out.png", "--save-scene": "scene.json", "--save-camera": "cam.json"}
    dest = full_fs / names[option]
    dest.write_bytes(OLD)
    _fill(full_fs)
    outputs = {opt: str(tmp_path / name) for opt, name in names.items()}
    outputs[option] = str(dest)
    args = [x for opt in ("-o", "--save-scene", "--save-camera") for x in (opt, outputs[opt])]
    proc = run_cli("render", str(tiny_volume), "--size", "32x32", *args)
    _one_error_line(proc, dest, "disk full (No space left on device")
    assert dest.read_bytes() == OLD
    _check_folder(full_fs, {dest.name, "filler"})


def test_save_camera_on_full_disk(full_fs: Path) -> None:
    from types import SimpleNamespace

    from voxwarp.cli.render_options import save_camera
    from voxwarp.core.camera import Camera

    dest = full_fs / "cam.json"
    dest.write_bytes(OLD)
    _fill(full_fs)
    scene = SimpleNamespace(resolved_camera=lambda: Camera())
    with pytest.raises(OutputError) as info:
        save_camera(scene, SimpleNamespace(save_camera=str(dest)))
    _check_failure(info.value, dest, "disk full (No space left on device")
    assert dest.read_bytes() == OLD
    _check_folder(full_fs, {dest.name, "filler"})


def test_cli_save_scene_and_output_same_file(
    tmp_path: Path, capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    import warnings

    from voxwarp.cli.main import main

    monkeypatch.setattr(warnings, "formatwarning", warnings.formatwarning)  # main() sets it

    dest = tmp_path / "x.png"
    dest.write_bytes(OLD)
    alias = tmp_path / "sub" / ".." / "x.png"
    (tmp_path / "sub").mkdir()
    assert main(["render", "missing.nrrd", "-o", str(dest), "--save-scene", str(alias)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("voxwarp: error: -o and --save-scene both name ")
    assert err.count("\n") == 1  # one line, before even loading the (missing) input
    assert dest.read_bytes() == OLD
