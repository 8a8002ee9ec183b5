"""Every writer through the same disk faults, and kill -9 then rerun (issue 33, item 7).

Writers: ``export-volume`` (.nii, .nii.gz, .nrrd), ``export-field`` (.nii.gz, .nrrd,
.mha, .h5), ``slice -o``, ``render -o`` and ``--save-scene`` (the CLI, in a child
process: :func:`tests.cli.cli_batch.run_cli_batch`), and in this process ``Scene.save``,
the notebook ``Viewer``'s saves (its session's scene JSON, its snapshot as PNG), the
napari hand-off and the GUI's export (:func:`voxwarp.ui.export_dialog.run_export`).

Faults: a file-size limit (``RLIMIT_FSIZE``) smaller than the output; a full disk (a
1 MiB tmpfs filled to the last byte, slow-marked and skipped where mounting is not
permitted; always: ``fsync`` failing with ``ENOSPC``, as file systems with delayed
allocation report it); a read-only folder (the tmpfs remounted read-only, skipped where
not permitted; always: the rename failing with ``EROFS`` or ``EACCES``, as root ignores
``chmod``).

Oracles, for every writer and fault: the exit status 2 (the API: a
:class:`~voxwarp.errors.VoxwarpError`), exactly one error line that names the file, the
cause and a fix, no traceback and nothing of the native libraries' own output (HDF5,
MetaImage, OpenImageIO), the destination absent or with its old bytes, and no temporary
file left. A writer killed with SIGKILL while its temporary file grows leaves that file;
the rerun of the same command succeeds, leaves only its output, and the output equals
the source voxels (export-volume on the volume's own grid) or the chain's field
computed in this process (export-field).
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.cli.cli_batch import run_cli_batch
from tests.core.test_writers_faults import OLD, _check_folder, _file_size_limit, _fill, _tmpfs
from tests.run_cli import REPO, run_cli
from voxwarp.core.files import is_temp_name
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import AffineWarp
from voxwarp.errors import VoxwarpError
from voxwarp.io.volumes import load_volume, save_volume
from voxwarp.scene import Scene

#: a file-size limit under every output here (the smallest, a 48x48 PNG, is ~2 KiB)
LIMIT = 1024

_VOLUME = ("export-volume", "{scene}", "-o", "{dest}", "--spacing", "1", "--no-progress")
_FIELD = ("export-field", "{scene}", "-o", "{dest}", "--spacing", "1")
#: writer -> (destination file name, the command's arguments: {scene} {dest} {aside})
CLI: dict[str, tuple[str, tuple[str, ...]]] = {
    "export-volume .nii": ("e.nii", _VOLUME),
    "export-volume .nii.gz": ("e.nii.gz", _VOLUME),
    "export-volume .nrrd": ("e.nrrd", _VOLUME),
    "export-field .nii.gz": ("f.nii.gz", _FIELD),
    "export-field .nrrd": ("f.nrrd", _FIELD),
    "export-field .mha": ("f.mha", _FIELD),
    "export-field .h5": ("f.h5", _FIELD),
    "slice -o .png": ("s.png", ("slice", "{scene}", "-o", "{dest}", "--size", "64x64")),
    "render -o .png": ("r.png", ("render", "{scene}", "-o", "{dest}", "--size", "48x48")),
    "render --save-scene": (
        "s.json",
        ("render", "{scene}", "-o", "{aside}", "--size", "16x16", "--save-scene", "{dest}"),
    ),
}

#: fault -> what its one line must say (the cause; export sizes are refused up front)
CAUSES = {
    "fsize": r"file-size limit of 1 KiB",
    "ENOSPC": r"disk full \(No space left on device|free on its disk",
    "EROFS": r"read-only file system",
    "EACCES": r"permission denied",
}
#: every one-line error ends with its fix
FIX = re.compile(r"; (free|write|raise|use|create) ")
#: what the native libraries print themselves (held back or never reached)
NATIVE = re.compile(
    r"HDF5-DIAG|#\d{3}:|H5[A-Z]\w*\.c|MetaImage|itk::|WARNING: In |libpng|TIFF|Traceback"
    r"|Segmentation fault|core dumped"
)
#: the lines voxwarp prints before an error (the plan, notes, warnings)
OWN = ("voxwarp: ", "spacing ", "other (")


# ---------------------------------------------------------------------------- inputs
def _warped(folder: Path, shape: tuple[int, int, int]) -> Path:
    """A random int16 volume of 1 mm voxels in an .npz, turned 0.2 rad about z by an
    affine warp (a non-zero field), as a scene JSON."""
    data = np.random.default_rng(5).integers(0, 3000, shape, dtype=np.int16)
    vol = load_volume(save_volume(Volume(data, spacing=(1, 1, 1), name="v"), folder / "v.npz"))
    turn = np.eye(4)
    turn[:2, :2] = [[np.cos(0.2), -np.sin(0.2)], [np.sin(0.2), np.cos(0.2)]]
    return Scene(vol, warps=[AffineWarp(turn)]).save(folder / "warped.json")


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """24x20x16 voxels: every output of the matrix is over :data:`LIMIT` and under 1 MiB."""
    return _warped(tmp_path_factory.mktemp("in"), (24, 20, 16))


#: a pid above Linux's largest (2**22): the process that left such a temporary file is gone
DEAD_PID = 4999999


def _commands(
    root: Path, scene: Path, fault: str | None, fresh: bool, stale: bool = True
) -> list[Any]:
    """Every CLI writer into its own folder under ``root`` (its destination holding
    :data:`OLD` unless ``fresh``; beside a temporary file a killed writer left when
    ``stale``: not on the tmpfs, where removing it frees the space the test took, nor
    where the folder turns read-only) under ``fault``: ``[(argv, fault)]``."""
    commands = []
    aside = root.parent / f"{root.name}-aside"
    aside.mkdir(exist_ok=True)
    for i, (file, args) in enumerate(CLI.values()):
        dest = root / str(i) / file
        dest.parent.mkdir(parents=True)
        if not fresh:
            dest.write_bytes(OLD)
        if stale:
            (dest.parent / f".{file}.{DEAD_PID}-0123abcd.vwtmp").write_bytes(b"stale")
        values = {"{scene}": str(scene), "{dest}": str(dest), "{aside}": str(aside / "r.png")}
        commands.append(([values.get(a, a) for a in args], fault))
    return commands


def _dest(argv: list[str]) -> Path:
    return Path(argv[argv.index("--save-scene" if "--save-scene" in argv else "-o") + 1])


def _check_refused(result: dict[str, Any], dest: Path, cause: str) -> None:
    """One refused command: rc 2, one error line (the last) naming ``dest``, ``cause``
    and a fix, every other line voxwarp's own; ``dest`` as before, no temporary file."""
    err = result["stderr"]
    assert result["rc"] == 2, err
    assert not NATIVE.search(err), err
    lines = err.splitlines()
    assert [ln for ln in lines if "error" in ln.lower()] == lines[-1:], err
    assert all(ln.startswith(OWN) for ln in lines), err
    assert lines[-1].startswith("voxwarp: error: "), err
    assert str(dest) in lines[-1], err
    assert re.search(cause, lines[-1]), err
    assert FIX.search(lines[-1]), err
    if dest.exists():
        assert dest.read_bytes() == OLD
    _check_folder(dest.parent, {dest.name} if dest.exists() else set())


def _check_batch(commands: list[Any], results: list[dict[str, Any]], kinds: list[str]) -> None:
    """Every writer refused as :func:`_check_refused` says, its cause that of ``kinds``."""
    assert len(results) == len(CLI)
    for name, (argv, _), result, kind in zip(CLI, commands, results, kinds, strict=True):
        try:
            _check_refused(result, _dest(argv), CAUSES[kind])
        except AssertionError as exc:
            raise AssertionError(f"{name} ({kind}): {exc}") from None


# ---------------------------------------------------------------------------- CLI, always
@pytest.mark.timeout(60)
def test_cli_writers_under_a_file_size_limit(scene_file: Path, tmp_path: Path) -> None:
    """ulimit -f 1 KiB: exports are refused by their estimate; the images (OpenImageIO
    wrote a 1024-byte PNG and exited 0) and the scene JSON stop at the limit."""
    commands = _commands(tmp_path / "w", scene_file, f"fsize:{LIMIT}", fresh=False)
    _check_batch(commands, run_cli_batch(commands), ["fsize"] * len(CLI))


@pytest.mark.timeout(60)
def test_cli_writers_when_the_sync_finds_the_disk_full(scene_file: Path, tmp_path: Path) -> None:
    """fsync fails with ENOSPC (delayed allocation, NFS): no destination is created."""
    commands = _commands(tmp_path / "w", scene_file, "fsync:ENOSPC", fresh=True)
    _check_batch(commands, run_cli_batch(commands), ["ENOSPC"] * len(CLI))


@pytest.mark.timeout(60)
def test_cli_writers_when_the_rename_is_refused(scene_file: Path, tmp_path: Path) -> None:
    """The folder turns read-only (EROFS) or forbidden (EACCES) before the rename: the
    old file stays; the writers alternate between the two."""
    kinds = [("EROFS", "EACCES")[i % 2] for i in range(len(CLI))]
    commands = [
        (argv, f"replace:{kind}")
        for (argv, _), kind in zip(
            _commands(tmp_path / "w", scene_file, None, False), kinds, strict=True
        )
    ]
    _check_batch(commands, run_cli_batch(commands), kinds)


def test_formats_the_writers_lack_are_refused_first(scene_file: Path, tmp_path: Path) -> None:
    """export-volume has no .mha, export-field no .tfm: one line before any work."""
    cases = [
        ("export-volume", tmp_path / "e.mha", ("-o", ".nii.gz", ".nrrd")),
        ("export-field", tmp_path / "f.tfm", ("-o", ".tfm", ".h5")),
    ]
    argvs = [((cmd, str(scene_file), "-o", str(out)), None) for cmd, out, _ in cases]
    for (_, _, words), result in zip(cases, run_cli_batch(argvs), strict=True):
        assert result["rc"] == 2
        assert result["stderr"].count("\n") == 1, result["stderr"]
        assert all(w in result["stderr"] for w in words), result["stderr"]
    assert os.listdir(tmp_path) == []


# ---------------------------------------------------------------------------- CLI, tmpfs
@pytest.mark.slow
@pytest.mark.timeout(90)
def test_cli_writers_on_a_full_disk(scene_file: Path, tmp_path: Path) -> None:
    """A 1 MiB tmpfs filled to the last byte, every destination holding old bytes."""
    with _tmpfs(tmp_path / "full", "1m") as fs:
        commands = _commands(fs / "w", scene_file, None, fresh=False, stale=False)
        _fill(fs)
        _check_batch(commands, run_cli_batch(commands), ["ENOSPC"] * len(CLI))


@pytest.mark.slow
@pytest.mark.timeout(90)
def test_cli_writers_in_a_read_only_folder(scene_file: Path, tmp_path: Path) -> None:
    """The tmpfs remounted read-only (root ignores chmod), every destination holding old
    bytes: HDF5 printed 23-54 lines here, MetaImage its own line."""
    with _tmpfs(tmp_path / "ro", "1m") as fs:
        commands = _commands(fs / "w", scene_file, None, fresh=False, stale=False)
        remount = ["mount", "-o", "remount,ro", str(fs)]
        if subprocess.run(remount, capture_output=True, check=False).returncode != 0:
            pytest.skip("remounting read-only is not permitted here")
        _check_batch(commands, run_cli_batch(commands), ["EROFS"] * len(CLI))


# ---------------------------------------------------------------------------- API, in process
@contextlib.contextmanager
def _fault(kind: str, monkeypatch: pytest.MonkeyPatch, folder: Path) -> Iterator[None]:
    """``kind`` in this process: ``fsize`` (the limit set and restored, SIGXFSZ ignored),
    ``ENOSPC`` (every fsync fails), ``EROFS``/``EACCES`` (a rename into ``folder`` or a
    folder inside it fails)."""
    if kind == "fsize":
        with _file_size_limit(LIMIT):
            yield
        return
    code = getattr(errno, kind)
    real = os.replace

    def replace(src: Any, dst: Any, *a: Any, **k: Any) -> None:
        if Path(dst).is_relative_to(folder):
            raise OSError(code, os.strerror(code))
        real(src, dst, *a, **k)

    def fsync(_fd: int) -> None:
        raise OSError(code, os.strerror(code))

    with monkeypatch.context() as m:
        m.setattr(os, *(("fsync", fsync) if kind == "ENOSPC" else ("replace", replace)))
        yield


@pytest.fixture(scope="module")
def viewer(gl_ctx: Any, scene_file: Path) -> Iterator[Any]:
    """The notebook Viewer on the matrix's volume (no warps: the editor takes none of
    the affine kind)."""
    from voxwarp.notebook import Viewer

    v = Viewer(Scene(load_volume(scene_file.parent / "v.npz")), size=(64, 48), ctx=gl_ctx)
    yield v
    v.release()


def _snapshot(dest: Path, v: Any) -> Any:
    from voxwarp.io.images import write_image

    return write_image(dest, v.snapshot())


#: in-process writer -> (destination file name, write(dest, viewer))
API: dict[str, tuple[str, Callable[[Path, Any], Any]]] = {
    "Scene.save": ("s.json", lambda dest, v: v.session.scene.save(dest)),
    "Viewer session save": ("v.json", lambda dest, v: v.session.save(dest)),
    "Viewer snapshot PNG": ("v.png", _snapshot),
}


@pytest.mark.parametrize("kind", list(CAUSES))
@pytest.mark.parametrize("name", list(API))
def test_api_writers_under_every_fault(
    name: str, kind: str, viewer: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    file, write = API[name]
    dest = tmp_path / file
    dest.write_bytes(OLD)
    with _fault(kind, monkeypatch, tmp_path), pytest.raises(VoxwarpError) as info:
        write(dest, viewer)
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(f"cannot write {dest}: ")
    assert re.search(CAUSES[kind], msg), msg
    assert FIX.search(msg), msg
    assert dest.read_bytes() == OLD
    _check_folder(tmp_path, {file})


@pytest.mark.parametrize("kind", ["fsize", "ENOSPC", "EROFS"])
def test_napari_handoff_leaves_nothing(
    kind: str, scene_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The hand-off into a given folder (an old scene.json there) and into a new
    temporary folder: a failed write leaves neither the volume nor the folder."""
    from voxwarp.napari_plugin.handoff import FOLDER_PREFIX, write_handoff

    vol = load_volume(scene_file.parent / "v.npz")
    given = tmp_path / "given"
    given.mkdir()
    (given / "scene.json").write_bytes(OLD)
    temp_root = tmp_path / "tmp"
    temp_root.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp_root))
    for folder in (given, None):
        where = given if folder is not None else temp_root
        with _fault(kind, monkeypatch, where), pytest.raises(VoxwarpError) as info:
            write_handoff(vol, {}, folder)
        assert "\n" not in str(info.value)
        assert re.search(CAUSES[kind], str(info.value)), info.value
    assert (given / "scene.json").read_bytes() == OLD
    _check_folder(given, {"scene.json"})
    assert not [p for p in temp_root.iterdir() if p.name.startswith(FOLDER_PREFIX)]


def test_napari_handoff_whose_scene_fails_removes_its_volume(
    scene_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The volume is written, then the scene's rename fails: the new volume goes too."""
    from voxwarp.napari_plugin.handoff import write_handoff

    real = os.replace

    def replace(src: Any, dst: Any) -> None:
        if Path(dst).name == "scene.json":
            raise OSError(errno.EROFS, os.strerror(errno.EROFS))
        real(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(VoxwarpError, match="read-only file system"):
        write_handoff(load_volume(scene_file.parent / "v.npz"), {}, tmp_path)
    assert os.listdir(tmp_path) == []


def test_gui_export_whose_rename_fails(scene_file: Path, tmp_path: Path, monkeypatch: Any) -> None:
    """File › Export's job (the CLI in a child, then the rename over the file): a refused
    rename is one OutputError line, the old file stays, no temporary file is left."""
    pytest.importorskip("PySide6")
    from voxwarp.ui.export_dialog import run_export

    dest = tmp_path / "e.nii.gz"
    dest.write_bytes(OLD)
    with _fault("EROFS", monkeypatch, tmp_path), pytest.raises(VoxwarpError) as info:
        run_export(Scene.load(scene_file), "volume", dest, "volume", [2.0])
    assert str(info.value).startswith(f"cannot write {dest}: read-only file system")
    assert dest.read_bytes() == OLD
    _check_folder(tmp_path, {dest.name})


# ---------------------------------------------------------------------------- kill -9
@pytest.fixture(scope="module")
def kill_scenes(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """64x48x40 voxels: the scene without warps, and the turned one. The writer is
    killed while its temporary file has bytes: export-volume draws slices for about half
    a second; export-field at 1 mm writes 0.9 MB of .nrrd for about a quarter of a second
    (at 2 mm its 8 KB took a few milliseconds, and the command often finished three times
    before the poll saw them: 3 of 6 runs of the test failed on an idle machine)."""
    warped = _warped(tmp_path_factory.mktemp("kill"), (64, 48, 40))
    plain = Scene(load_volume(warped.parent / "v.npz")).save(warped.parent / "plain.json")
    return plain, warped


def _growing(folder: Path) -> bool:
    """Whether a temporary file with bytes in it is in ``folder``."""
    with contextlib.suppress(OSError):
        return any(is_temp_name(e.name) and e.stat().st_size > 0 for e in os.scandir(folder))
    return False


def _kill_while_writing(argv: list[str], folder: Path) -> bool:
    """Start ``voxwarp ARGV``; SIGKILL it as soon as its temporary file in ``folder``
    has bytes (mid-write). ``False`` when the command finished first (a busy machine did
    not look in time)."""
    cmd = [sys.executable, "-m", "voxwarp.cli.main", *argv]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 40
        while not _growing(folder):
            if proc.poll() is not None:
                assert proc.returncode == 0, "the command failed before it wrote"
                return False
            assert time.monotonic() < deadline, "no temporary file in 40 s"
            time.sleep(0.002)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        with contextlib.suppress(ProcessLookupError):
            proc.kill()
        proc.wait(10)
    assert proc.returncode == -signal.SIGKILL
    return True


def _kill_then_rerun(argv: list[str], out: Path) -> None:
    """The killed run leaves its temporary file and no output; the rerun of the same
    command succeeds and leaves only its output."""
    for _ in range(3):
        if _kill_while_writing(argv, out.parent):
            break
        out.unlink()
    else:
        pytest.fail("the command finished three times before it could be killed")
    left = os.listdir(out.parent)
    assert len(left) == 1, left
    assert is_temp_name(left[0])
    rerun = run_cli(*argv, timeout=60)
    assert rerun.returncode == 0, rerun.stderr
    assert os.listdir(out.parent) == [out.name]


@pytest.mark.slow
@pytest.mark.timeout(120)
def test_killed_export_volume_then_rerun(kill_scenes: tuple[Path, Path], tmp_path: Path) -> None:
    """Oracle: the volume's own grid at its voxel size gives back its voxels exactly."""
    import nibabel as nib

    plain, _ = kill_scenes
    out = tmp_path / "run" / "e.nii.gz"
    out.parent.mkdir()
    _kill_then_rerun(["export-volume", str(plain), "-o", str(out), "--no-progress"], out)
    source = load_volume(plain.parent / "v.npz").data
    np.testing.assert_array_equal(np.asarray(nib.load(out).dataobj), source)


@pytest.mark.slow
@pytest.mark.timeout(120)
def test_killed_export_field_then_rerun(kill_scenes: tuple[Path, Path], tmp_path: Path) -> None:
    """Oracle: the chain's field on the same nodes, computed in this process."""
    from voxwarp.io.fields import load_displacement_field

    _, warped = kill_scenes
    out = tmp_path / "run" / "f.nrrd"
    out.parent.mkdir()
    _kill_then_rerun(["export-field", str(warped), "-o", str(out), "--spacing", "1"], out)
    expected = Scene.load(warped).export_field(spacing=1.0).field
    got = load_displacement_field(out)
    np.testing.assert_allclose(got.affine, expected.affine, atol=1e-9)
    np.testing.assert_allclose(got.displacements, expected.displacements, atol=1e-5)
    assert np.abs(expected.displacements).max() > 1.0  # a real field, not zeros


# ---------------------------------------------------------------------------- HDF5 from the API
H5_CHILD = r"""
import resource, sys
import numpy as np
from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.errors import OutputError
from voxwarp.io.fields import save_displacement_field

field = DisplacementFieldWarp(np.zeros((24, 20, 16, 3), np.float32), np.eye(4))
resource.setrlimit(resource.RLIMIT_FSIZE, (int(sys.argv[2]), resource.RLIM_INFINITY))
try:
    save_displacement_field(field, sys.argv[1])
except OutputError as exc:
    print(exc)
"""


@pytest.mark.timeout(60)
def test_h5_field_from_the_api_under_a_file_size_limit_exits_cleanly(tmp_path: Path) -> None:
    """``save_displacement_field(.h5)`` under a 146 KiB limit (244 KiB to write): HDF5
    returned an error, then the process died of SIGSEGV at exit (rc 139); now the limit
    is checked before HDF5 runs."""
    out = tmp_path / "f.h5"
    proc = subprocess.run(
        [sys.executable, "-c", H5_CHILD, str(out), "150000"],
        capture_output=True, text=True, cwd=REPO, timeout=60, check=False,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stderr == ""
    assert proc.stdout.startswith(f"cannot write {out}: file too large for this process's")
    assert "needs about 244 KiB" in proc.stdout
    assert os.listdir(tmp_path) == []


def test_h5_field_from_the_api_refuses_a_full_disk_first(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """4 KiB free for 244 KiB: refused before HDF5 runs (it would crash at exit)."""
    import shutil

    from voxwarp.deform.fields.displacement import DisplacementFieldWarp
    from voxwarp.io.fields import save_displacement_field

    field = DisplacementFieldWarp(np.zeros((24, 20, 16, 3), np.float32), np.eye(4))
    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(shutil, "disk_usage", lambda _p: usage._replace(free=4096))
    with pytest.raises(VoxwarpError, match=r"disk full \(the file needs about 244 KiB, 4 KiB"):
        save_displacement_field(field, tmp_path / "f.h5")
    assert os.listdir(tmp_path) == []
