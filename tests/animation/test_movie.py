"""Tests of voxwarp.animation.movie and voxwarp.animation.distributed: ``voxwarp animate`` frames,
resume, movie, Dask.

Oracles: a direct ``OffscreenRenderer.render`` of a frame's scene, the movie decoded by
imageio-ffmpeg, render calls counted by wrapping :func:`voxwarp.animation.frames.render_frame`, file
modification times, and the serial run's frames for the Dask run (bit-exact).
Error cases run ``main()`` in-process and must fail before any GL work.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import imageio_ffmpeg
import numpy as np
import pytest

import voxwarp.animation.distributed
import voxwarp.animation.frames
import voxwarp.animation.movie
from tests.cli.test_cli import _keep_warning_state, no_rendering  # noqa: F401
from voxwarp.animation.movie import animate, encode_movie, frames_dir_for
from voxwarp.animation.tracks import Animation, Track, load_animated_scene, save_animated_scene
from voxwarp.cli.main import main
from voxwarp.editing.families.lattice import LatticeFamily
from voxwarp.editing.session import EditSession
from voxwarp.errors import OutputError
from voxwarp.io.images import read_image, write_image
from voxwarp.io.samples import load_sample
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.scene import Scene

SIZE = (64, 48)


@pytest.fixture(scope="module", autouse=True)
def _release_the_process_renderer() -> Iterator[None]:
    yield
    voxwarp.animation.frames.release_process_renderer()


def _animated(path: Path, opaque_end: bool = False) -> Path:
    """A small fish bent by a lattice while the camera turns: 3 frames."""
    volume = load_sample("fish", shape=(48, 24, 20))
    session = EditSession(Scene(volume, view="-y"))
    session.set_deformation("lattice", resolution=3)
    bent = session.adapter(LatticeFamily).lattice_nodes.copy()
    bent[-1, :, :, 2] += 9.0
    tracks = [
        Track("lattice.nodes", [(0, "rest"), (2, bent.tolist())], "smooth"),
        Track("camera", [(0, {"view": "-y"}), (2, {"view": [-70.0, 25.0]})]),
    ]
    if opaque_end:  # the transfer function turns opaque towards the last frame
        start = [list(p) for p in session.scene.transfer_function.points]
        end = [[v, r, g, b, 1.0 if a > 0 else 0.0] for v, r, g, b, a in start]
        tracks.append(Track("transfer_function", [(0, start), (1, start), (2, end)]))
    return save_animated_scene(path, session, Animation(3, 12.0, tracks))


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _animated(tmp_path_factory.mktemp("anim") / "bend_anim.json")


def _decode(movie: Path) -> tuple[tuple[int, int], list[np.ndarray]]:
    reader = imageio_ffmpeg.read_frames(str(movie))
    meta = next(reader)
    w, h = meta["size"]
    frames = [np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in reader]
    return (w, h), frames


def _count_renders(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    calls: list[int] = []
    real = voxwarp.animation.frames.render_frame

    def counting(header: Any, scene: Any) -> np.ndarray:
        calls.append(1)
        return real(header, scene)

    monkeypatch.setattr(voxwarp.animation.frames, "render_frame", counting)
    return calls


# ---------------------------------------------------------------------- frames and movie
def test_three_frames_write_three_images_and_a_decodable_movie(
    scene_file: Path, tmp_path: Path, gl_ctx: Any
) -> None:
    out = tmp_path / "bend.mp4"
    result = animate(scene_file, out, size=SIZE, progress=False)
    folder = tmp_path / "bend_frames"
    assert result.frames_dir == folder
    assert result.movie == out
    names = sorted(p.name for p in folder.iterdir())
    assert names == ["frame_00000.png", "frame_00001.png", "frame_00002.png", "manifest.json"]
    assert result.rendered == [0, 1, 2]
    assert result.skipped == []
    images = [read_image(p) for p in result.frames]
    assert all(img.shape == (48, 64, 4) for img in images)
    assert not np.array_equal(images[0], images[1])
    assert not np.array_equal(images[1], images[2])
    # frame 0 is exactly a direct render of frame 0's scene
    states = load_animated_scene(scene_file)
    with OffscreenRenderer(*SIZE, ctx=gl_ctx) as r:
        direct = r.render(states.scene(0))
    np.testing.assert_array_equal(images[0], direct)
    size, decoded = _decode(out)
    assert size == SIZE
    assert len(decoded) == 3
    for img, frame in zip(images, decoded, strict=True):  # H.264 is lossy, but close
        assert np.abs(frame.astype(int) - img[..., :3].astype(int)).mean() < 4.0


def test_odd_frame_sizes_are_padded_to_even_for_the_movie(
    scene_file: Path, tmp_path: Path, gl_ctx: Any
) -> None:
    result = animate(scene_file, tmp_path / "odd.mp4", size=(63, 47), progress=False)
    assert read_image(result.frames[0]).shape == (47, 63, 4)
    size, decoded = _decode(tmp_path / "odd.mp4")
    assert size == (64, 48)
    assert len(decoded) == 3


def test_a_failing_ffmpeg_is_one_line_with_its_reason_and_leaves_no_movie(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture
) -> None:
    frames = [write_image(tmp_path / f"f{i}.png", np.zeros((8, 8, 4), np.uint8)) for i in (0, 1)]
    monkeypatch.setattr(voxwarp.animation.movie, "MOVIE_CRF", "nope")  # ffmpeg rejects it
    out = tmp_path / "m.mp4"
    with pytest.raises(OutputError) as exc:
        encode_movie(frames, out, 12.0)
    message = str(exc.value)
    assert message.startswith(f"cannot write {out}: "), message
    assert "Invalid argument" in message  # ffmpeg's last line (its option error)
    assert "\n" not in message
    assert capfd.readouterr().err == ""  # ffmpeg's messages went into the error, not stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f0.png", "f1.png"]


def test_without_the_ffmpeg_process_the_log_still_tells_a_failure(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Should a later imageio-ffmpeg keep its process elsewhere, the movie is still
    checked: ffmpeg at ``-v error`` logs nothing when it succeeds."""
    real = voxwarp.animation.movie._start_encoder
    monkeypatch.setattr(voxwarp.animation.movie, "_start_encoder", lambda *a: (real(*a)[0], None))
    frames = [
        write_image(tmp_path / f"f{i}.png", np.full((8, 8, 4), 9 * i, np.uint8)) for i in (0, 1)
    ]
    good = encode_movie(frames, tmp_path / "ok.mp4", 12.0)
    assert len(_decode(good)[1]) == 2
    monkeypatch.setattr(voxwarp.animation.movie, "MOVIE_CRF", "nope")
    with pytest.raises(OutputError, match="Invalid argument"):
        encode_movie(frames, tmp_path / "bad.mp4", 12.0)
    assert not (tmp_path / "bad.mp4").exists()


def test_an_interrupted_run_resumes_without_rendering_finished_frames_again(
    scene_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, gl_ctx: Any
) -> None:
    calls = _count_renders(monkeypatch)
    out = tmp_path / "resume.mp4"

    def interrupt_after_frame_1(index: int, path: Path) -> None:
        if index == 1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        animate(scene_file, out, size=SIZE, progress=False, on_frame=interrupt_after_frame_1)
    folder = frames_dir_for(out)
    done = [folder / "frame_00000.png", folder / "frame_00001.png"]
    assert len(calls) == 2
    assert all(p.is_file() for p in done)
    assert not (folder / "frame_00002.png").exists()
    assert not out.exists()
    stamps = [p.stat().st_mtime_ns for p in done]
    calls.clear()
    result = animate(scene_file, out, size=SIZE, progress=False)
    assert len(calls) == 1
    assert result.skipped == [0, 1]
    assert result.rendered == [2]
    assert [p.stat().st_mtime_ns for p in done] == stamps
    assert len(_decode(out)[1]) == 3
    calls.clear()
    assert animate(scene_file, out, size=SIZE, progress=False).rendered == []
    assert calls == []


def test_frames_of_another_scene_size_or_format_are_never_reused(
    scene_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, gl_ctx: Any
) -> None:
    out = tmp_path / "movie.mp4"
    first = animate(scene_file, out, size=SIZE, progress=False, movie=False)
    assert first.rendered == [0, 1, 2]
    calls = _count_renders(monkeypatch)
    # another scene: only the last frame's transfer function differs
    other = _animated(tmp_path / "other_anim.json", opaque_end=True)
    result = animate(other, out, size=SIZE, progress=False, movie=False)
    assert result.skipped == [0, 1]
    assert result.rendered == [2]
    assert result.removed == 1
    assert len(calls) == 1
    states = load_animated_scene(other)
    with OffscreenRenderer(*SIZE) as r:
        np.testing.assert_array_equal(read_image(result.frames[2]), r.render(states.scene(2)))
    # another size
    calls.clear()
    result = animate(other, out, size=(32, 24), progress=False, movie=False)
    assert result.rendered == [0, 1, 2]
    assert read_image(result.frames[0]).shape == (24, 32, 4)
    # no manifest: frame files of unknown origin are rendered again
    (frames_dir_for(out) / "manifest.json").unlink()
    assert animate(other, out, size=(32, 24), progress=False, movie=False).rendered == [0, 1, 2]
    # another format: float EXR frames replace the PNG ones
    result = animate(other, out, size=(32, 24), image_format="exr", progress=False)
    names = sorted(p.name for p in frames_dir_for(out).iterdir())
    assert names == ["frame_00000.exr", "frame_00001.exr", "frame_00002.exr", "manifest.json"]
    exr = read_image(result.frames[1])
    assert exr.dtype == np.float32
    assert exr.shape == (24, 32, 4)
    assert len(_decode(out)[1]) == 3


# ---------------------------------------------------------------------- Dask
@pytest.mark.slow
def test_two_local_dask_workers_equal_the_serial_run_bit_exactly(
    scene_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, gl_ctx: Any
) -> None:
    serial = animate(scene_file, tmp_path / "serial.mp4", size=SIZE, progress=False)

    def not_here(*args: Any) -> None:
        raise AssertionError("a --workers run must render on the workers, not in the client")

    monkeypatch.setattr(voxwarp.animation.frames, "render_frame", not_here)
    dask = animate(scene_file, tmp_path / "dask.mp4", size=SIZE, progress=False, workers=2)
    assert dask.rendered
    assert sorted(dask.rendered) == [0, 1, 2]
    for a, b in zip(serial.frames, dask.frames, strict=True):
        np.testing.assert_array_equal(read_image(a), read_image(b))
    assert len(_decode(tmp_path / "dask.mp4")[1]) == 3


# ---------------------------------------------------------------------- command line
@pytest.mark.usefixtures("_keep_warning_state")
def test_cli_animate_renders_and_reports(
    scene_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture, gl_ctx: Any
) -> None:
    out = tmp_path / "cli.mp4"
    code = main(["animate", str(scene_file), "-o", str(out), "--size", "64x48", "--no-progress"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert captured.out.strip() == str(out)
    assert "3 of 3 frames rendered" in captured.err
    assert len(_decode(out)[1]) == 3


@pytest.mark.usefixtures("no_rendering", "_keep_warning_state")
@pytest.mark.parametrize(
    ("case", "message"),
    [
        ("static", "the scene has no 'animation' entry"),
        ("target", "unknown animation target 'wobble'; targets: camera"),
        ("keys", "key frames must increase strictly"),
        ("missing", "no such scene file"),
        ("avi", "the movie must end in .mp4, .mov, .mkv"),
        ("scheduler", "cannot reach the Dask scheduler at tcp://127.0.0.1:9"),
    ],
)
def test_cli_errors_are_one_line(
    case: str,
    message: str,
    scene_file: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    d = json.loads(scene_file.read_text())
    scene, extra, out = tmp_path / "s.json", [], tmp_path / "m.mp4"
    if case == "static":
        del d["animation"]
    elif case == "target":
        d["animation"]["tracks"][0]["target"] = "wobble"
    elif case == "keys":
        d["animation"]["tracks"][0]["keys"] = [[1, "rest"], [0, "rest"]]
    elif case == "missing":
        scene = tmp_path / "nothing.json"
    elif case == "avi":
        out = tmp_path / "m.avi"
    elif case == "scheduler":
        monkeypatch.setattr(voxwarp.animation.distributed, "CONNECT_TIMEOUT_S", 1)
        extra = ["--scheduler", "tcp://127.0.0.1:9"]
    if case != "missing":
        scene.write_text(json.dumps(d))
    code = main(["animate", str(scene), "-o", str(out), "--no-progress", *extra])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert err[-1].startswith("voxwarp: error: "), err
    assert message in err[-1], err
    assert not any("Traceback" in line for line in err)


@pytest.mark.usefixtures("no_rendering")
@pytest.mark.parametrize(
    "args",
    [
        ["--frames", "0"],
        ["--fps", "-3"],
        ["--fps", "x"],
        ["--size", "0x4"],
        ["--workers", "2", "--scheduler", "tcp://h:8786"],
        ["--workers", "0"],
        ["--format", "tif"],
    ],
)
def test_bad_animate_options_exit_2(
    args: list[str], scene_file: Path, capsys: pytest.CaptureFixture
) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["animate", str(scene_file), *args])
    assert exc.value.code == 2
    assert "error: argument" in capsys.readouterr().err
