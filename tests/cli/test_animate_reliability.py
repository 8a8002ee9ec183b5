"""Reliability of ``voxwarp animate``: kills, damaged frames, full disks, leftovers, schedulers.

Oracles: an undisturbed run's frame and movie bytes (rendering and encoding are
deterministic), the physics of the bundled mass-spring animation as evaluated all at
once before frames were streamed (a SHA-256 of its scene dicts, computed on the code
before streaming), the process table (ffmpeg gone), and the files left in the folders.
Subprocess runs use a small mass-spring animation (6 frames of 32x24 pixels).
"""

from __future__ import annotations

import hashlib
import json
import os
import random
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import voxwarp.animation.distributed
import voxwarp.animation.frames
import voxwarp.io.images
from tests.cli.test_cli import _keep_warning_state  # noqa: F401
from voxwarp.animation.frames import canonical_json
from voxwarp.animation.movie import (
    MANIFEST_NAME,
    FramesChangedWarning,
    animate,
    encode_movie,
    frames_dir_for,
)
from voxwarp.animation.tracks import (
    Animation,
    Track,
    evaluate,
    load_animated_scene,
    stream_animated_scene,
)
from voxwarp.cli.main import main
from voxwarp.core.files import is_temp_name
from voxwarp.editing.session import EditSession
from voxwarp.io.samples import load_sample
from voxwarp.scene import Scene, read_scene_dict

ROOT = Path(__file__).resolve().parents[2]
FRAMES = 6
SIZE = "32x24"
OPTS = ("--size", SIZE, "--no-progress")
#: SHA-256 of canonical_json(evaluate(fish_massspring_jiggle_anim.json, frames=30).scenes),
#: computed with the all-at-once evaluation before frames were streamed
MASSSPRING_30_GOLDEN = "cb7bf6062d6b976f12b2bfe207c7e921ad1d10ce9646a2cf500f483783e2598f"


@pytest.fixture(scope="module", autouse=True)
def _release_the_process_renderer() -> Iterator[None]:
    yield
    voxwarp.animation.frames.release_process_renderer()


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small fish, a 4x4x4 mass-spring grid: an element dragged 8 mm and let go while
    the camera turns; 6 frames, 3 steps per frame."""
    out = tmp_path_factory.mktemp("anim") / "ms_anim.json"
    session = EditSession(Scene(load_sample("fish", shape=(48, 24, 20)), view="-y"))
    session.set_deformation("massspring", resolution=4)
    session.set_option("steps_per_frame", 3)
    session.save(out)
    raw = json.loads(out.read_text())
    keys = [(0, [0.0, 0.0, 0.0]), (3, [0.0, 0.0, 8.0]), (4, None)]
    tracks = [
        Track("elements.drag", keys, "smooth", elements=[[3, 2, 2]]),
        Track("camera", [(0, {"view": "-y"}), (5, {"view": [-60.0, 20.0]})]),
    ]
    raw["animation"] = Animation(FRAMES, 12.0, tracks).to_dict()
    out.write_text(json.dumps(raw))
    return out


def _cli(scene: Path, out: Path) -> list[str]:
    return [sys.executable, "-m", "voxwarp", "animate", str(scene), "-o", str(out), *OPTS]


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT)}


@pytest.fixture(scope="module")
def reference(scene_file: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """An undisturbed subprocess run: its frame bytes, movie bytes and duration."""
    out = tmp_path_factory.mktemp("ref") / "ms.mp4"
    t0 = time.monotonic()
    proc = subprocess.run(_cli(scene_file, out), capture_output=True, text=True, env=_env())
    assert proc.returncode == 0, proc.stderr
    frames = sorted(frames_dir_for(out).glob("frame_*.png"))
    assert len(frames) == FRAMES
    return {
        "frames": {p.name: p.read_bytes() for p in frames},
        "movie": out.read_bytes(),
        "seconds": time.monotonic() - t0,
        "out": out,
    }


def _children(pid: int) -> list[int]:
    kids: list[int] = []
    try:
        for tid in os.listdir(f"/proc/{pid}/task"):
            text = Path(f"/proc/{pid}/task/{tid}/children").read_text()
            kids += [int(x) for x in text.split()]
    except OSError:
        pass
    return kids


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state not in ("Z", "X")


def _assert_nothing_partial(out: Path, ref: dict[str, Any]) -> None:
    """Every frame file in place is complete (the undisturbed run's bytes); the movie is
    absent or complete."""
    for p in frames_dir_for(out).glob("frame_*"):
        assert p.read_bytes() == ref["frames"][p.name], f"partial or wrong frame {p.name}"
    if out.exists():
        assert out.read_bytes() == ref["movie"]


# ---------------------------------------------------------------------- streaming physics
def test_streamed_physics_equals_the_all_at_once_evaluation() -> None:
    path = ROOT / "sample_volumes" / "fish_massspring_jiggle_anim.json"
    stream = stream_animated_scene(path, frames=30)
    # each dict serialised as soon as it is yielded: later frames must not change it
    parts = [canonical_json(d) for d in stream.frames]
    streamed = hashlib.sha256(("[" + ",".join(parts) + "]").encode()).hexdigest()
    assert streamed == MASSSPRING_30_GOLDEN
    assert stream.count == 30


def test_a_stream_closed_early_frees_its_models(scene_file: Path) -> None:
    stream = stream_animated_scene(scene_file)
    first = next(stream.frames)
    stream.close()
    stream.close()  # idempotent
    assert first == load_animated_scene(scene_file).scenes[0]
    with pytest.raises(StopIteration):
        next(stream.frames)
    d = read_scene_dict(scene_file)
    assert len(evaluate(d, base_dir=scene_file.parent).scenes) == FRAMES


# ---------------------------------------------------------------------- kill -9 and resume
@pytest.mark.slow
def test_kill_9_at_random_points_then_resume_is_byte_identical(
    scene_file: Path, reference: dict[str, Any], tmp_path: Path
) -> None:
    out = tmp_path / "ms.mp4"
    folder = frames_dir_for(out)
    rng = random.Random(17)
    ffmpeg_seen: list[int] = []

    def wait_for(cond: Any, proc: subprocess.Popen, limit: float) -> bool:
        end = time.monotonic() + limit
        while time.monotonic() < end and proc.poll() is None:
            if cond():
                return True
            time.sleep(0.003)
        return False

    def temp_movies() -> list[Path]:
        return [p for p in out.parent.iterdir() if p.name.startswith(".ms.mp4.")]

    plans = ["time", "frame", "movie"]
    for plan in plans:
        proc = subprocess.Popen(
            _cli(scene_file, out), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=_env()
        )
        limit = 4 * reference["seconds"] + 30
        if plan == "time":
            wait_for(lambda: False, proc, rng.uniform(0.2, 0.8) * reference["seconds"])
        elif plan == "frame":
            k = rng.randrange(1, FRAMES - 1)
            wait_for(lambda k=k: len(list(folder.glob("frame_*.png"))) >= k, proc, limit)
            time.sleep(rng.uniform(0.0, 0.03))
        else:  # while ffmpeg writes the temporary movie
            pid = proc.pid
            wait_for(lambda pid=pid: temp_movies() and _children(pid), proc, limit)
        kids = _children(proc.pid)
        proc.kill()
        proc.wait()
        if plan != "time":  # the kill landed while the run was at work
            assert proc.returncode == -signal.SIGKILL, plan
        proc.stderr.close()  # type: ignore[union-attr]
        _assert_nothing_partial(out, reference)
        if plan == "movie":
            ffmpeg_seen += kids
            end = time.monotonic() + 5
            while any(_alive(k) for k in kids) and time.monotonic() < end:
                time.sleep(0.02)
            assert not any(_alive(k) for k in kids), "ffmpeg outlived voxwarp"
    assert ffmpeg_seen, "the last kill was meant to land while ffmpeg encodes"
    proc2 = subprocess.run(_cli(scene_file, out), capture_output=True, text=True, env=_env())
    assert proc2.returncode == 0, proc2.stderr
    assert "kept from an earlier run" in proc2.stderr
    assert {p.name: p.read_bytes() for p in folder.glob("frame_*.png")} == reference["frames"]
    assert out.read_bytes() == reference["movie"]
    leftovers = [p.name for d in (out.parent, folder) for p in d.iterdir() if is_temp_name(p)]
    assert leftovers == []  # the stale temporary movie of the last kill is gone


def test_ffmpeg_is_killed_when_the_encoder_is_interrupted(
    reference: dict[str, Any], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    frames = sorted(frames_dir_for(reference["out"]).glob("frame_*.png"))
    started: list[subprocess.Popen] = []
    real_popen = subprocess.Popen

    def spy(*args: Any, **kwargs: Any) -> subprocess.Popen:
        p = real_popen(*args, **kwargs)
        started.append(p)
        return p

    real_read = voxwarp.io.images.read_image
    calls: list[int] = []

    def read_then_interrupt(path: Any) -> np.ndarray:
        calls.append(1)
        if len(calls) == 4:
            raise KeyboardInterrupt
        return real_read(path)

    monkeypatch.setattr(subprocess, "Popen", spy)
    monkeypatch.setattr(voxwarp.io.images, "read_image", read_then_interrupt)
    out = tmp_path / "cut.mp4"
    with pytest.raises(KeyboardInterrupt):
        encode_movie(frames, out, 12.0)
    encoders = [p for p in started if "-crf" in p.args]  # not ffmpeg -version
    assert len(encoders) == 1
    assert encoders[0].returncode == -signal.SIGKILL  # stopped and reaped, not left running
    assert list(tmp_path.iterdir()) == []  # neither the movie nor its temporary file


# ---------------------------------------------------------------------- damaged frames
@pytest.mark.usefixtures("gl_ctx")
def test_truncated_and_swapped_frames_are_detected_and_rendered_again(
    scene_file: Path, tmp_path: Path
) -> None:
    out = tmp_path / "d.mp4"
    first = animate(scene_file, out, size=(32, 24), progress=False, movie=False)
    good = [p.read_bytes() for p in first.frames]
    f = first.frames
    f[1].write_bytes(good[1][: len(good[1]) // 2])  # truncated
    f[2].write_bytes(good[3])  # two valid frames swapped
    f[3].write_bytes(good[2])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        again = animate(scene_file, out, size=(32, 24), progress=False)
    notes = [str(w.message) for w in caught if issubclass(w.category, FramesChangedWarning)]
    assert len(notes) == 1
    assert notes[0].startswith("re-rendering 3 frames that changed on disk")
    assert again.changed == 3
    assert sorted(again.rendered) == [1, 2, 3]
    assert again.skipped == [0, 4, 5]
    assert [p.read_bytes() for p in again.frames] == good
    # a missing frame is rendered again too; an untouched folder renders nothing
    f[5].unlink()
    with pytest.warns(FramesChangedWarning, match="re-rendering 1 frame that changed"):
        missing = animate(scene_file, out, size=(32, 24), progress=False, movie=False)
    assert missing.rendered == [5]
    assert animate(scene_file, out, size=(32, 24), progress=False, movie=False).rendered == []


@pytest.mark.usefixtures("gl_ctx")
def test_a_manifest_of_the_older_format_is_rendered_again_not_crashed_on(
    scene_file: Path, tmp_path: Path
) -> None:
    out = tmp_path / "old.mp4"
    first = animate(scene_file, out, size=(32, 24), progress=False, movie=False)
    good = [p.read_bytes() for p in first.frames]
    manifest = frames_dir_for(out) / MANIFEST_NAME
    doc = json.loads(manifest.read_text())
    older = {
        "format": doc["format"],
        "version": 1,
        "frames": [e[0] for e in doc["frames"]],
    }  # voxwarp before frame hashes: input digests only
    manifest.write_text(json.dumps(older))
    first.frames[2].write_bytes(good[2][:40])  # the old layout could not have caught this
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        again = animate(scene_file, out, size=(32, 24), progress=False, movie=False)
    assert any("older voxwarp" in str(w.message) for w in caught)
    assert again.rendered == list(range(FRAMES))
    assert [p.read_bytes() for p in again.frames] == good
    for garbage in ("{", '{"format": "voxwarp-animation-frames", "version": 2, "frames": 3}'):
        manifest.write_text(garbage)
        assert len(animate(scene_file, out, size=(32, 24), progress=False, movie=False).rendered)


# ---------------------------------------------------------------------- full disk
@pytest.mark.usefixtures("gl_ctx", "_keep_warning_state")
def test_a_frame_cut_short_without_an_error_fails_the_run_and_is_not_kept(
    scene_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: Any
) -> None:
    """The original bug: the image library cut frame 2 at the free space and reported
    success. The read-back check fails the run with one line; nothing cut stays."""
    real = voxwarp.io.images.write_image

    def short_write(path: Any, image: np.ndarray) -> Path:
        p = real(path, image)
        if Path(path).name == "frame_00002.png":
            data = p.read_bytes()
            p.write_bytes(data[: len(data) // 3])
        return p

    monkeypatch.setattr(voxwarp.io.images, "write_image", short_write)
    out = tmp_path / "full.mp4"
    code = main(["animate", str(scene_file), "-o", str(out), "--size", SIZE, "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1, err
    assert err[0].startswith("voxwarp: error: cannot write ")
    assert "frame_00002.png" in err[0]
    assert "disk full" in err[0]
    folder = frames_dir_for(out)
    assert sorted(p.name for p in folder.glob("frame_*")) == ["frame_00000.png", "frame_00001.png"]
    monkeypatch.setattr(voxwarp.io.images, "write_image", real)
    again = animate(scene_file, out, size=(32, 24), progress=False)
    assert again.skipped == [0, 1]
    assert again.rendered == [2, 3, 4, 5]


@pytest.mark.usefixtures("gl_ctx", "_keep_warning_state")
def test_a_frame_write_failing_with_enospc_is_one_line_and_exit_2(
    scene_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: Any
) -> None:
    import errno

    from voxwarp.core.files import output_error

    real = voxwarp.io.images.write_image

    def enospc(path: Any, image: np.ndarray) -> Path:
        if Path(path).name == "frame_00001.png":
            raise output_error(path, OSError(errno.ENOSPC, "No space left on device"))
        return real(path, image)

    monkeypatch.setattr(voxwarp.io.images, "write_image", enospc)
    out = tmp_path / "nospace.mp4"
    code = main(["animate", str(scene_file), "-o", str(out), "--size", SIZE, "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert err == [
        f"voxwarp: error: cannot write {frames_dir_for(out).resolve() / 'frame_00001.png'}:"
        " disk full (No space left on device); free some space or write to another disk"
    ]
    doc = json.loads((frames_dir_for(out) / MANIFEST_NAME).read_text())
    assert doc["frames"][0] is not None  # the finished frame is recorded for the rerun
    assert doc["frames"][1] is None


def _can_mount_tmpfs(where: Path) -> bool:
    if not sys.platform.startswith("linux") or shutil.which("unshare") is None:
        return False
    probe = subprocess.run(
        ["unshare", "-rm", "sh", "-c", f"mount -t tmpfs -o size=8k tmpfs {where}"],
        capture_output=True,
    )
    return probe.returncode == 0


@pytest.mark.slow
def test_a_real_full_disk_fails_with_one_line_and_the_rerun_keeps_only_whole_frames(
    scene_file: Path, reference: dict[str, Any], tmp_path: Path
) -> None:
    """A 20 KiB tmpfs (in a user and mount namespace) fills up during the run."""
    small = tmp_path / "small"
    small.mkdir()
    if not _can_mount_tmpfs(small):
        pytest.skip("cannot mount a tmpfs here (no unshare or user namespaces)")
    rescued = tmp_path / "rescued"
    cmd = " ".join(_cli(scene_file, small / "ms.mp4"))
    script = (
        f"mount -t tmpfs -o size=20k tmpfs {small} && {cmd} 2> {tmp_path}/err;"
        f" echo $? > {tmp_path}/rc; cp -a {small} {rescued}"
    )
    subprocess.run(["unshare", "-rm", "sh", "-c", script], env=_env(), check=True)
    err = (tmp_path / "err").read_text().strip().splitlines()
    assert (tmp_path / "rc").read_text().strip() == "2"
    assert len(err) == 1, err
    assert err[0].startswith(f"voxwarp: error: cannot write {small}/ms_frames/")
    assert "disk full (No space left on device" in err[0]
    out = rescued / "ms.mp4"
    assert not out.exists()
    _assert_nothing_partial(out, reference)
    assert not [p for p in frames_dir_for(out).iterdir() if is_temp_name(p)]
    proc = subprocess.run(_cli(scene_file, out), capture_output=True, text=True, env=_env())
    assert proc.returncode == 0, proc.stderr
    assert {p.name: p.read_bytes() for p in frames_dir_for(out).glob("frame_*")} == (
        reference["frames"]
    )
    assert out.read_bytes() == reference["movie"]


# ---------------------------------------------------------------------- leftovers
@pytest.mark.usefixtures("gl_ctx")
def test_stale_temporary_movies_and_frames_are_removed_on_start(
    scene_file: Path, tmp_path: Path
) -> None:
    out = tmp_path / "m.mp4"
    dead = 2**22 + 17  # above the default pid_max: no such process
    stale_movie = tmp_path / f".m.mp4.{dead}-0123abcd.vwtmp.mp4"
    older_movie = tmp_path / f".m.mp4.{dead}-89abcdef.tmp.mp4"  # earlier voxwarp
    other = tmp_path / f".other.mp4.{dead}-0123abcd.vwtmp.mp4"  # another output's
    folder = frames_dir_for(out)
    folder.mkdir()
    stale_frame = folder / f".frame_00001.png.{dead}-0123abcd.vwtmp.png"
    stale_manifest = folder / f".manifest.json.{dead}-0123abcd.vwtmp"
    for p in (stale_movie, older_movie, other, stale_frame, stale_manifest):
        p.write_bytes(b"\0" * 100)
    animate(scene_file, out, size=(32, 24), progress=False)
    assert not stale_movie.exists()
    assert not older_movie.exists()
    assert not stale_frame.exists()
    assert not stale_manifest.exists()
    assert other.exists()  # not this output's: left alone
    assert out.is_file()


# ---------------------------------------------------------------------- Dask scheduler
def _serve(kind: str) -> tuple[int, Any]:
    """A localhost server that is not a Dask scheduler: ``http`` answers HTTP only after
    a request line, ``bytes`` sends 8 bytes of text at once (as a web server's banner)."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen()
    conns: list[socket.socket] = []

    def loop() -> None:
        while True:
            try:
                c, _ = srv.accept()
            except OSError:
                return
            conns.append(c)
            if kind == "bytes":
                c.sendall(b"HTTP/1.1 400 Bad Request\r\n\r\n")

    threading.Thread(target=loop, daemon=True).start()

    def close() -> None:
        srv.close()
        for c in conns:
            c.close()

    return srv.getsockname()[1], close


@pytest.mark.usefixtures("_keep_warning_state")
@pytest.mark.parametrize("kind", ["http", "bytes"])
def test_a_scheduler_address_that_is_not_dask_is_one_line(
    kind: str, scene_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: Any
) -> None:
    monkeypatch.setattr(voxwarp.animation.distributed, "CONNECT_TIMEOUT_S", 1)
    port, close = _serve(kind)
    try:
        url = f"tcp://127.0.0.1:{port}"
        t0 = time.monotonic()
        code = main(
            ["animate", str(scene_file), "-o", str(tmp_path / "m.mp4"), *OPTS, "--scheduler", url]
        )
        seconds = time.monotonic() - t0
    finally:
        close()
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1, err
    assert err[0].startswith(
        f"voxwarp: error: tcp://127.0.0.1:{port} does not answer like a Dask scheduler ("
    )
    assert "a Dask scheduler you trust" in err[0]
    assert seconds < 30
    assert not (tmp_path / "m_frames").exists()  # refused before any frame


def test_a_real_scheduler_passes_the_probe() -> None:
    import logging

    from distributed import LocalCluster

    from voxwarp.animation.distributed import probe_scheduler

    with LocalCluster(
        n_workers=0,
        processes=False,
        protocol="tcp://",
        dashboard_address=None,
        silence_logs=logging.ERROR,
    ) as cluster:
        probe_scheduler(cluster.scheduler_address, 10)


def test_docs_say_the_scheduler_must_be_trusted() -> None:
    for doc in (ROOT / "README.md", ROOT / "docs" / "distributed.md"):
        text = " ".join(doc.read_text().split())
        assert "trusted" in text, doc
        assert "pickle" in text, doc
