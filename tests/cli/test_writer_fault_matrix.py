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
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.cli.cli_batch import run_cli_batch
from tests.core.test_writers_faults import OLD, _check_folder, _file_size_limit, _fill, _tmpfs
from tests.run_cli import run_cli
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


def _commands(root: Path, scene: Path, fault: str | None, fresh: bool) -> list[Any]:
    """Every CLI writer into its own folder under ``root`` (its destination holding
    :data:`OLD` unless ``fresh``) under ``fault``: ``[(argv, fault)]``."""
    commands = []
    aside = root.parent / f"{root.name}-aside"
    aside.mkdir(exist_ok=True)
    for i, (file, args) in enumerate(CLI.values()):
        dest = root / str(i) / file
        dest.parent.mkdir(parents=True)
        if not fresh:
            dest.write_bytes(OLD)
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


def test_formats_the_writers_do_not_have_are_refused_first(
    scene_file: Path, tmp_path: Path
) -> None:
    """export-volume has no .mha, export-field no .tfm: one line before any work."""
    for cmd, out, words in (
        ("export-volume", tmp_path / "e.mha", ("-o", ".nii.gz", ".nrrd")),
        ("export-field", tmp_path / "f.tfm", ("-o", ".tfm", ".h5")),
    ):
        proc = run_cli(cmd, str(scene_file), "-o", str(out))
        assert proc.returncode == 2
        assert "Traceback" not in proc.stderr
        assert proc.stderr.count("\n") == 1, proc.stderr
        assert all(w in proc.stderr for w in words), proc.stderr
    assert os.listdir(tmp_path) == []


# ---------------------------------------------------------------------------- CLI, tmpfs
@pytest.mark.slow
@pytest.mark.timeout(90)
def test_cli_writers_on_a_full_disk(scene_file: Path, tmp_path: Path) -> None:
    """A 1 MiB tmpfs filled to the last byte, every destination holding old bytes."""
    with _tmpfs(tmp_path / "full", "1m") as fs:
        commands = _commands(fs / "w", scene_file, None, fresh=False)
        _fill(fs)
        _check_batch(commands, run_cli_batch(commands), ["ENOSPC"] * len(CLI))


@pytest.mark.slow
@pytest.mark.timeout(90)
def test_cli_writers_in_a_read_only_folder(scene_file: Path, tmp_path: Path) -> None:
    """The tmpfs remounted read-only (root ignores chmod), every destination holding old
    bytes: HDF5 printed 23-54 lines here, MetaImage its own line."""
    with _tmpfs(tmp_path / "ro", "1m") as fs:
        commands = _commands(fs / "w", scene_file, None, fresh=False)
        remount = ["mount", "-o", "remount,ro", str(fs)]
        if subprocess.run(remount, capture_output=True, check=False).returncode != 0:
            pytest.skip("remounting read-only is not permitted here")
        _check_batch(commands, run_cli_batch(commands), ["EROFS"] * len(CLI))


# ---------------------------------------------------------------------------- API, in process
@contextlib.contextmanager
def _fault(kind: str, monkeypatch: pytest.MonkeyPatch, folder: Path) -> Iterator[None]:
    """``kind`` in this process: ``fsize`` (the limit set and restored, SIGXFSZ ignored),
    ``ENOSPC`` (every fsync fails), ``EROFS``/``EACCES`` (a rename into ``folder`` fails)."""
    if kind == "fsize":
        with _file_size_limit(LIMIT):
            yield
        return
    code = getattr(errno, kind)
    real = os.replace

    def replace(src: Any, dst: Any, *a: Any, **k: Any) -> None:
        if Path(dst).parent == folder:
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
