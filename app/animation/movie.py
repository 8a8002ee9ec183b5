"""``voxwarp animate``: render an animated scene's frames and encode them into a movie.

::

    voxwarp animate scene.json --frames 48 --fps 24 -o movie.mp4 [--size 640x480]
        [--format png|exr] [--workers N | --scheduler tcp://host:8786] [--no-movie]

The scene JSON's ``"animation"`` entry (:mod:`voxwarp.animation.tracks`) is evaluated
serially into one complete scene dict per frame (physics included), *streamed*: frame
``i``'s dict is evaluated when the renderer is ready for it and dropped once its file is
written (:func:`voxwarp.animation.tracks.stream_animated_scene`), so memory stays bounded
and the first frame appears after the first physics step, whatever ``--frames``. The
frames are rendered from those dicts — in this process, or on Dask workers
(:mod:`voxwarp.animation.distributed`, at most a window of frames in flight) — with
identical results, and encoded.

Frames
    ``<output stem>_frames/frame_00000.png`` (``--format exr``: float EXR), written
    through OpenImageIO (:func:`voxwarp.io.images.write_image`, atomic and checked: a frame
    file that exists is complete), then read back and compared with the rendered pixels
    (a short write the library did not report fails the run). Images are RGBA with the
    scene's background composited in. A failed write (disk full, read-only folder) ends
    the run with one line naming the file and the cause (:class:`~voxwarp.errors.OutputError`).
Resume
    The frame folder holds ``manifest.json``: per finished frame, a SHA-256 of everything
    the frame's pixels depend on (its scene dict, the volume entry and, for a volume file,
    its absolute path, size and modification time, the image size and format) *and* the
    size and SHA-256 of the frame file as written. A run first checks every frame the
    manifest lists against the file on disk: a missing, truncated or modified file is
    re-rendered (one warning line says how many). It then keeps the frame files whose
    recorded digest equals the new one and renders the others; every other frame file
    of the folder (another scene, size or format, no manifest, a manifest of an older
    voxwarp without file hashes) is deleted and rendered again, so frames of another
    scene are never reused and a damaged frame never reaches the movie. The manifest is
    rewritten atomically as frames finish (after each frame while that is cheap, at
    most a few per cent of the run's time for very long animations) and when the run
    stops for any reason; a frame written after the last manifest update of a killed run
    is rendered again. An interrupted run (Ctrl+C, kill, a failed worker) therefore
    resumes where it stopped. Temporary files of a killed run (frames, manifest, the
    movie beside ``-o``) are removed when the next run starts. Two runs must not write
    to the same folder at once.
Movie
    Encoded with imageio-ffmpeg's bundled ffmpeg: H.264 (libx264, CRF 18), yuv420p, at
    ``--fps``; the RGB of each frame (alpha dropped: the background is already in), padded
    to an even size by repeating the last row/column. Written to a temporary name in the
    output's folder and renamed when complete; ffmpeg (started by
    ``imageio_ffmpeg.write_frames``) has its exit status checked and is killed when
    voxwarp fails or is interrupted; when voxwarp itself is killed, ffmpeg reads the end
    of its input and stops, leaving a temporary movie the next run removes. ``.mp4``,
    ``.mov`` or ``.mkv``.
Rendering
    One :class:`~voxwarp.render.offscreen.OffscreenRenderer` per process (made on first use, kept
    for
    the next frames: see :func:`render_frame`), with the volume loaded once and warps
    rebuilt only when their entry changes. Deformed-space skip maps are off
    (``warped_skip_maps = "never"``): a frame's image then never depends on which
    frames the process drew before, so serial and distributed runs are bit-identical.
Progress
    A tqdm bar on stderr, or on a non-terminal stderr one line every few seconds
    (``--no-progress`` turns it off). Frames kept from an earlier run count as done.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import re
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Callable, Generator, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.animation import FRAME_FORMATS
from voxwarp.animation.distributed import dask_client, probe_scheduler, render_on_dask
from voxwarp.animation.frames import canonical_json, file_record, render_frame_to_file
from voxwarp.animation.tracks import MAX_FRAMES, FrameStream, stream_animated_scene
from voxwarp.core.extras import require
from voxwarp.core.files import (
    atomic_output,
    atomic_write_text,
    is_temp_name,
    output_error,
    remove_stale_temps,
)
from voxwarp.core.json_input import read_json
from voxwarp.core.progress import ProgressBar
from voxwarp.errors import VoxwarpError
from voxwarp.io import images  # images.read_image: tests stand in for it

#: movie containers accepted for ``-o``
MOVIE_SUFFIXES: tuple[str, ...] = (".mp4", ".mov", ".mkv")
#: name of the frame folder's manifest
MANIFEST_NAME = "manifest.json"
MANIFEST_FORMAT = "voxwarp-animation-frames"
#: changes whenever what a frame digest covers changes (old frames are then re-rendered)
DIGEST_VERSION = 1
#: layout of the manifest: 2 records each frame file's size and SHA-256 (1 did not)
MANIFEST_VERSION = 2
#: the manifest is rewritten after a frame only when the last write took at most this
#: fraction of the time since (bounds its cost for very long animations)
MANIFEST_COST_FRACTION = 0.05
#: H.264 constant rate factor of the movie (18: visually lossless)
MOVIE_CRF = 18

_FRAME_FILE = re.compile(r"^frame_(\d{5})\.(png|exr)$")


# ---------------------------------------------------------------------------- frame jobs
@dataclass
class FrameJob:
    """One frame to render: its scene (without the volume entry) and where it goes."""

    index: int
    scene: dict[str, Any]
    path: str
    digest: str


def frame_name(index: int, ext: str) -> str:
    """``frame_00012.png`` for ``(12, ".png")``."""
    return f"frame_{index:05d}{ext}"


def frames_dir_for(output: str | os.PathLike) -> Path:
    """The frame folder of a movie: ``movie.mp4`` -> ``movie_frames``."""
    out = Path(output)
    return out.with_name(f"{out.stem}_frames")


def render_header(
    volume: Mapping[str, Any],
    base_dir: str | os.PathLike | None,
    size: tuple[int, int],
    dtype: str = "u1",
) -> dict[str, Any]:
    """What every frame shares: volume entry, base folder, image size, dtype.

    Parameters
    ----------
    volume
        The scene's volume entry (the same in every frame).
    base_dir
        Folder that relative paths of the scene refer to.
    size
        ``(width, height)`` in pixels.
    dtype
        ``"u1"`` (8-bit frames) or ``"f4"`` (float frames for EXR).

    Returns
    -------
    dict
        JSON values only (shipped to Dask workers as is).
    """
    return {
        "volume": dict(volume),
        "base_dir": None if base_dir is None else str(base_dir),
        "size": [int(size[0]), int(size[1])],
        "dtype": dtype,
    }


def _volume_identity(header: Mapping[str, Any]) -> Any:
    """The volume entry with a file path made absolute, plus the file's size and mtime
    (so a changed file invalidates its frames, and moving the scene file does not)."""
    vol = header.get("volume") or {}
    if not isinstance(vol, Mapping) or "path" not in vol:
        return vol
    p = Path(str(vol["path"]))
    if not p.is_absolute() and header.get("base_dir"):
        p = Path(str(header["base_dir"])) / p
    try:
        st = p.stat()
        stamp = [st.st_size, st.st_mtime_ns]
    except OSError:
        stamp = None
    return {**vol, "path": str(p.resolve()), "stamp": stamp}


def frame_digest(header: Mapping[str, Any], scene: Mapping[str, Any], ext: str) -> str:
    """SHA-256 (hex) of what a frame's pixels depend on (see the module doc).

    The base folder counts only for scenes with meshes (their files are named relative
    to it); a volume file counts by its absolute path, size and modification time.
    """
    doc = {
        "version": DIGEST_VERSION,
        "volume": _volume_identity(header),
        "base_dir": header.get("base_dir") if scene.get("meshes") else None,
        "size": list(header["size"]),
        "dtype": header.get("dtype", "u1"),
        "ext": ext,
        "scene": scene,
    }
    return hashlib.sha256(canonical_json(doc).encode("utf-8")).hexdigest()


def plan_jobs(
    scenes: Iterable[Mapping[str, Any]],
    frames_dir: str | os.PathLike,
    header: Mapping[str, Any],
    ext: str,
) -> Iterator[FrameJob]:
    """One :class:`FrameJob` per scene dict of ``scenes`` (absolute paths in
    ``frames_dir``), made as ``scenes`` yields them."""
    folder = Path(frames_dir).resolve()
    for i, d in enumerate(scenes):
        scene = {k: v for k, v in d.items() if k != "volume"}
        yield FrameJob(i, scene, str(folder / frame_name(i, ext)), frame_digest(header, scene, ext))


# ---------------------------------------------------------------------------- frame folder
#: a manifest entry: (input digest, file size, file SHA-256)
Entry = tuple[str, int, str]


def _read_manifest(folder: Path) -> tuple[str | None, dict[int, Entry], bool]:
    """``(ext, entries, older)`` of the folder's manifest; ``older``: a readable
    manifest of an older layout (no file hashes). A missing or unreadable manifest
    gives no entries."""
    try:
        d = read_json(folder / MANIFEST_NAME)
    except (OSError, ValueError, UnicodeDecodeError):
        return None, {}, False
    if not isinstance(d, dict) or d.get("format") != MANIFEST_FORMAT:
        return None, {}, False
    if d.get("version") != MANIFEST_VERSION or d.get("digest_version") != DIGEST_VERSION:
        return None, {}, isinstance(d.get("frames"), list) and bool(d.get("frames"))
    ext, frames = d.get("ext"), d.get("frames")
    if ext not in FRAME_FORMATS.values() or not isinstance(frames, list):
        return None, {}, False
    entries: dict[int, Entry] = {}
    for i, e in enumerate(frames):
        if (
            isinstance(e, list)
            and len(e) == 3
            and isinstance(e[0], str)
            and isinstance(e[1], int)
            and not isinstance(e[1], bool)
            and isinstance(e[2], str)
        ):
            entries[i] = (e[0], e[1], e[2])
    return ext, entries, False


class FrameFolder:
    """The frame folder of one run: which frames are finished, and its manifest.

    Made at the start of a run (see Resume in the module doc): removes temporary files of
    killed runs, checks every frame the old manifest lists against its file, deletes
    the frame files nothing vouches for and writes the manifest of what is left.

    Parameters
    ----------
    folder
        The frame folder (made if missing).
    count
        Frames of this run.
    ext
        Frame file extension (``".png"``, ``".exr"``).
    """

    def __init__(self, folder: str | os.PathLike, count: int, ext: str) -> None:
        self.folder = Path(folder)
        self.count = int(count)
        self.ext = ext
        #: stale frame files deleted (not vouched for, changed on disk, or another scene)
        self.removed = 0
        #: frames the manifest listed whose file was missing or not as written
        self.changed = 0
        #: frames listed by a manifest of an older layout (re-rendered)
        self.older = 0
        self._last_write = 0.0
        self._write_cost = 0.0
        self._dirty = False
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise output_error(self.folder, exc) from exc
        self._remove_temps()
        old_ext, old, older = _read_manifest(self.folder)
        self.entries: dict[int, Entry] = {}
        for i, entry in old.items():
            if i >= self.count or old_ext != ext:
                continue
            if file_record(self.folder / frame_name(i, ext)) == entry[1:]:
                self.entries[i] = entry
            else:
                self.changed += 1
        frame_files = [p for p in self.folder.iterdir() if _FRAME_FILE.match(p.name)]
        if older:
            self.older = len(frame_files)
        for p in frame_files:
            m = _FRAME_FILE.match(p.name)
            assert m is not None
            if p.suffix != ext or int(m.group(1)) not in self.entries:
                self._delete(p)
        self.write_manifest()

    def _remove_temps(self) -> None:
        """Remove temporary frame and manifest files of killed runs (this folder is
        written by one run at a time)."""
        for p in self.folder.iterdir():
            n = p.name
            ours = n.startswith(".frame_") or n.startswith(f".{MANIFEST_NAME}.")
            if ours and is_temp_name(n):
                _unlink(p)

    def _delete(self, p: Path) -> None:
        if _unlink(p):
            self.removed += 1

    def keep(self, job: FrameJob) -> bool:
        """Whether ``job``'s frame is finished; a frame file of other inputs is deleted."""
        entry = self.entries.get(job.index)
        if entry is None:
            return False
        if entry[0] == job.digest:
            return True
        del self.entries[job.index]
        self._dirty = True
        self._delete(Path(job.path))
        return False

    def record(self, job: FrameJob, size: int, sha256: str) -> None:
        """Note a frame file as written; the manifest follows when that is cheap."""
        self.entries[job.index] = (job.digest, int(size), str(sha256))
        self._dirty = True
        now = time.perf_counter()
        if self._write_cost <= MANIFEST_COST_FRACTION * (now - self._last_write):
            self.write_manifest()

    def write_manifest(self) -> None:
        """Write the manifest (atomically; :class:`~voxwarp.errors.OutputError` on failure)."""
        frames: list[Any] = [None] * self.count
        for i, e in self.entries.items():
            frames[i] = list(e)
        doc = {
            "format": MANIFEST_FORMAT,
            "version": MANIFEST_VERSION,
            "digest_version": DIGEST_VERSION,
            "ext": self.ext,
            "frames": frames,
        }
        t0 = time.perf_counter()
        atomic_write_text(self.folder / MANIFEST_NAME, json.dumps(doc, separators=(",", ":")))
        self._last_write = time.perf_counter()
        self._write_cost = self._last_write - t0
        self._dirty = False

    def flush(self) -> None:
        """Write the manifest if frames finished since the last write."""
        if self._dirty:
            self.write_manifest()


def prepare_frames_dir(
    frames_dir: str | os.PathLike, jobs: Sequence[FrameJob]
) -> tuple[list[FrameJob], list[FrameJob], int]:
    """Sort ``jobs`` into finished frames (kept) and frames to render (see Resume above).

    :class:`FrameFolder` for a list of jobs known in advance.

    Returns
    -------
    (kept, todo, removed)
        Finished frames, frames to render, and the number of stale frame files deleted.
    """
    ext = Path(jobs[0].path).suffix if jobs else ".png"
    ff = FrameFolder(frames_dir, len(jobs), ext)
    kept = [j for j in jobs if ff.keep(j)]
    todo = [j for j in jobs if j.index not in ff.entries]
    ff.flush()
    return kept, todo, ff.removed


# ---------------------------------------------------------------------------- movie
def _rgb8(image: np.ndarray) -> np.ndarray:
    a = np.asarray(image)
    if a.dtype != np.uint8:
        a = np.clip(np.rint(np.asarray(a, np.float64) * 255.0), 0, 255).astype(np.uint8)
    if a.shape[2] >= 3:
        a = a[:, :, :3]
    else:
        a = np.repeat(a[:, :, :1], 3, axis=2)
    h, w = a.shape[:2]
    if h % 2 or w % 2:  # yuv420p needs an even size
        a = np.pad(a, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")
    return np.ascontiguousarray(a)


@contextmanager
def _stderr_into(fh: Any) -> Iterator[None]:
    """Point this process's file descriptor 2 at ``fh`` while a child starts: the child
    inherits it, so its messages land in ``fh`` (restored at once for this process)."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        os.dup2(fh.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _start_encoder(
    tmp: Path, width: int, height: int, fps: float, log: Any
) -> tuple[Generator[None, Any, None], subprocess.Popen | None]:
    """imageio-ffmpeg's frame writer of :func:`encode_movie`, started, and its ffmpeg.

    ``imageio_ffmpeg.write_frames`` runs ffmpeg with stderr inherited and does not
    return the process; ffmpeg's messages are sent to ``log`` by starting it with this
    process's stderr pointed there, and the process (the generator's local ``p``) is
    taken so its exit status can be checked and it can be killed and reaped (None if a
    later imageio-ffmpeg keeps it elsewhere: then ``log`` alone says whether it failed).
    """
    from fractions import Fraction

    import imageio_ffmpeg

    writer = imageio_ffmpeg.write_frames(
        str(tmp),
        (width, height),
        pix_fmt_in="rgb24",
        pix_fmt_out="yuv420p",
        fps=Fraction(float(fps)).limit_denominator(),
        quality=None,  # the CRF below instead
        codec="libx264",
        macro_block_size=1,  # frames are padded to an even size, never rescaled
        ffmpeg_log_level="error",
        output_params=["-crf", str(MOVIE_CRF)],
    )
    with _stderr_into(log):
        writer.send(None)  # starts ffmpeg
    frame = writer.gi_frame
    proc = frame.f_locals.get("p") if frame is not None else None
    return writer, proc if all(hasattr(proc, n) for n in ("kill", "wait", "stdin")) else None


def _last_line(fh: Any) -> str:
    try:
        fh.seek(0)
        text = fh.read().decode("utf-8", "replace")
    except OSError:
        return ""
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return lines[-1] if lines else ""


def encode_movie(
    frame_paths: Sequence[str | os.PathLike], output: str | os.PathLike, fps: float
) -> Path:
    """Encode frame files into an H.264 movie (see the module doc), atomically.

    ffmpeg runs through ``imageio_ffmpeg.write_frames`` as a child that is killed
    whenever this function does not finish normally (an error, Ctrl+C); its exit status
    is checked, so a movie cut short (disk full) never replaces ``output``.

    Parameters
    ----------
    frame_paths
        Frame images in order (PNG, EXR, ...), all of one size.
    output
        ``.mp4``, ``.mov`` or ``.mkv`` file.
    fps
        Frames per second.

    Returns
    -------
    Path

    Raises
    ------
    OutputError
        When the movie cannot be written (one line naming the file and the cause).
    VoxwarpError
        When a frame cannot be read or has another size than the first.
    """
    out = Path(output)
    if out.suffix.lower() not in MOVIE_SUFFIXES:
        raise VoxwarpError(f"movie output {out} must end in {', '.join(MOVIE_SUFFIXES)}")
    if not frame_paths:
        raise VoxwarpError("no frames to encode")
    first = _rgb8(images.read_image(frame_paths[0]))
    height, width = first.shape[:2]
    with atomic_output(out, out.suffix) as tmp, tempfile.TemporaryFile() as log:
        try:
            writer, proc = _start_encoder(tmp, width, height, fps, log)
        except OSError as exc:
            raise VoxwarpError(f"cannot start ffmpeg to encode {out}: {exc}") from exc
        finished = False
        try:
            try:
                for n, p in enumerate(frame_paths):
                    rgb = first if n == 0 else _rgb8(images.read_image(p))
                    if rgb.shape != first.shape:
                        raise VoxwarpError(
                            f"frame {p} is {rgb.shape[1]}x{rgb.shape[0]}; the first frame is"
                            f" {width}x{height}"
                        )
                    writer.send(rgb)
            except OSError:
                pass  # ffmpeg stopped: its exit status and log say why
            writer.close()  # closes ffmpeg's input and waits for it
            finished = True
        finally:
            if proc is not None:
                if not finished:
                    proc.kill()
                proc.wait()
                try:
                    proc.stdin.close()  # what the killed ffmpeg did not read is dropped
                except OSError:
                    pass
            writer.close()
        reason = _last_line(log)
        if proc is None:
            failed = bool(reason)  # ffmpeg -v error writes nothing when it succeeds
        else:
            failed = proc.returncode != 0
        if failed:
            raise output_error(out, reason or f"ffmpeg exited with status {proc.returncode}")
    return out


# ---------------------------------------------------------------------------- animate
class FramesChangedWarning(UserWarning):
    """Frames of an earlier run were missing or changed on disk and are rendered again."""


@dataclass
class AnimateResult:
    """What :func:`animate` did.

    Attributes
    ----------
    movie
        The movie file (None with ``movie=False``).
    frames_dir
        The frame folder.
    frames
        Every frame file, in order.
    rendered, skipped
        Indices of the frames rendered in this run (in the order they finished) and of
        those kept from an earlier one.
    removed
        Stale frame files deleted.
    changed
        Frames an earlier run had finished whose file was missing or not as written
        (rendered again).
    fps
        Frames per second of the movie.
    seconds
        Wall times: ``evaluate`` (binding the animation and the physics of every frame,
        interleaved with rendering), ``render`` (the rest of the frame loop, including
        worker start for ``workers``), ``encode``.
    """

    movie: Path | None
    frames_dir: Path
    frames: list[Path]
    rendered: list[int] = field(default_factory=list)
    skipped: list[int] = field(default_factory=list)
    removed: int = 0
    changed: int = 0
    fps: float = 24.0
    seconds: dict[str, float] = field(default_factory=dict)


class _Timed:
    """Iterates ``it``, adding the time spent in it to ``self.seconds``."""

    def __init__(self, it: Iterator[Any]) -> None:
        self.it, self.seconds = it, 0.0

    def __iter__(self) -> _Timed:
        return self

    def __next__(self) -> Any:
        t0 = time.perf_counter()
        try:
            return next(self.it)
        finally:
            self.seconds += time.perf_counter() - t0


def remove_stale_movie_temps(output: str | os.PathLike) -> list[Path]:
    """Remove temporary movies of ``output`` that killed runs left beside it (only
    temporaries of that name whose writing process is gone)."""
    out = Path(output)
    return remove_stale_temps(out.parent, for_name=out.name)


def animate(
    scene: str | os.PathLike,
    output: str | os.PathLike,
    *,
    frames: int | None = None,
    fps: float | None = None,
    size: tuple[int, int] = (512, 512),
    image_format: str = "png",
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
    movie: bool = True,
    progress: bool = True,
    on_frame: Callable[[int, Path], None] | None = None,
) -> AnimateResult:
    """Render an animated scene into frames and a movie (see the module doc).

    Parameters
    ----------
    scene
        Scene JSON with an ``"animation"`` entry.
    output
        The movie (``.mp4``, ``.mov``, ``.mkv``); frames go to ``<stem>_frames/``.
    frames
        Frames to render (default: the animation's; the keys scale to it).
    fps
        Frames per second (default: the animation's).
    size
        ``(width, height)`` of the frames.
    image_format
        ``"png"`` (8-bit) or ``"exr"`` (float).
    workers
        Render on a local Dask cluster of this many worker processes.
    scheduler
        Render on the Dask cluster of this scheduler address (``tcp://host:8786``).
        It must be a cluster you trust: Dask deserialises what it receives with pickle.
    client
        An existing ``distributed.Client`` to render on (instead of the two above).
    movie
        Encode the movie (False: frames only).
    progress
        Show progress on stderr.
    on_frame
        ``on_frame(index, path)`` after each frame is written (in this process).

    Returns
    -------
    AnimateResult

    Raises
    ------
    VoxwarpError
        On bad input (scene, animation, options) or a failed write
        (:class:`~voxwarp.errors.OutputError`); frames finished before an error or an
        interruption stay and are skipped by the next run.

    Warns
    -----
    FramesChangedWarning
        When frames of an earlier run are rendered again because their files changed.
    """
    out = Path(output)
    if image_format not in FRAME_FORMATS:
        raise VoxwarpError(
            f"frame format must be one of {', '.join(FRAME_FORMATS)}; got {image_format!r}"
        )
    if movie and out.suffix.lower() not in MOVIE_SUFFIXES:
        raise VoxwarpError(
            f"-o {out}: the movie must end in {', '.join(MOVIE_SUFFIXES)} (or pass --no-movie)"
        )
    if sum(x is not None for x in (workers, scheduler, client)) > 1:
        raise VoxwarpError("give at most one of --workers and --scheduler")
    if workers is not None and not 1 <= int(workers) <= 1024:
        raise VoxwarpError(f"--workers must be 1..1024; got {workers}")
    if fps is not None and not (0 < float(fps) <= 1000):
        raise VoxwarpError(f"--fps must be in (0, 1000]; got {fps}")
    if frames is not None and not 1 <= int(frames) <= MAX_FRAMES:
        raise VoxwarpError(f"--frames must be 1..{MAX_FRAMES}; got {frames}")
    require("movie", "voxwarp animate")
    if workers is not None or scheduler is not None:
        require("distributed", "voxwarp animate --workers/--scheduler")
    if scheduler is not None:  # a wrong address fails before any file is touched
        probe_scheduler(scheduler)
    ext = FRAME_FORMATS[image_format]
    folder = frames_dir_for(out)
    t_start = time.perf_counter()
    stream = stream_animated_scene(scene, frames=frames)
    try:
        result = _animate_frames(
            stream, out, folder, ext, size, image_format,
            (workers, scheduler, client), progress, on_frame, t_start,
        )  # fmt: skip
    finally:
        stream.close()
    result.fps = float(fps) if fps is not None else stream.animation.fps
    if movie:
        t0 = time.perf_counter()
        result.movie = encode_movie(result.frames, out, result.fps)
        result.seconds["encode"] = time.perf_counter() - t0
    return result


def _animate_frames(
    stream: FrameStream,
    out: Path,
    folder: Path,
    ext: str,
    size: tuple[int, int],
    image_format: str,
    cluster: tuple[int | None, str | None, Any],
    progress: bool,
    on_frame: Callable[[int, Path], None] | None,
    t_start: float,
) -> AnimateResult:
    """The frame loop of :func:`animate`: resume, render, keep the manifest up to date."""
    scenes = _Timed(stream.frames)
    first = next(scenes)  # frame 0: checks the physics set-up before any file is touched
    header = render_header(
        first["volume"], stream.base_dir, size, "f4" if image_format == "exr" else "u1"
    )
    remove_stale_movie_temps(out)
    ff = FrameFolder(folder, stream.count, ext)
    result = AnimateResult(
        movie=None,
        frames_dir=folder,
        frames=[folder / frame_name(i, ext) for i in range(stream.count)],
        removed=ff.removed,
        changed=ff.changed,
    )
    if ff.changed:
        warnings.warn(
            f"re-rendering {ff.changed} frame{'s' * (ff.changed != 1)} that changed on disk"
            f" (missing, truncated or modified since written) in {folder}",
            FramesChangedWarning,
            stacklevel=3,
        )
    if ff.older:
        warnings.warn(
            f"the frame manifest in {folder} is from an older voxwarp (no frame hashes):"
            f" re-rendering its {ff.older} frame{'s' * (ff.older != 1)}",
            FramesChangedWarning,
            stacklevel=3,
        )
    bar = ProgressBar(stream.count, progress)

    def todo() -> Iterator[FrameJob]:
        for job in plan_jobs(itertools.chain([first], scenes), folder, header, ext):
            if ff.keep(job):
                result.skipped.append(job.index)
                bar.update(1)
            else:
                yield job

    def done(job: FrameJob, record: Mapping[str, Any]) -> None:
        ff.record(job, record["size"], record["sha256"])
        result.rendered.append(job.index)
        bar.update(1)
        if on_frame is not None:
            on_frame(job.index, Path(job.path))

    t0 = time.perf_counter()
    evaluate0 = scenes.seconds
    try:
        _render_jobs(header, todo(), done, *cluster)
        ff.flush()
    except BaseException:
        try:
            ff.flush()  # keep what finished; the first error is the one to report
        except (OSError, VoxwarpError):
            pass
        raise
    finally:
        bar.close()
    result.removed = ff.removed
    loop = time.perf_counter() - t0
    result.seconds["evaluate"] = (t0 - t_start) + scenes.seconds - evaluate0
    result.seconds["render"] = max(loop - (scenes.seconds - evaluate0), 0.0)
    return result


def _render_jobs(
    header: Mapping[str, Any],
    jobs: Iterator[FrameJob],
    done: Callable[[FrameJob, Mapping[str, Any]], None],
    workers: int | None,
    scheduler: str | None,
    client: Any,
) -> None:
    head = next(jobs, None)
    if head is None:  # every frame kept: no cluster to start
        return
    jobs = itertools.chain([head], jobs)
    if workers is None and scheduler is None and client is None:
        for job in jobs:
            done(job, render_frame_to_file(header, job.scene, job.path))
        return
    if client is not None:
        render_on_dask(client, header, jobs, done)
        return
    with dask_client(workers=workers, scheduler=scheduler) as c:
        render_on_dask(c, header, jobs, done)


def _unlink(p: Path) -> bool:
    """Delete ``p``; False if it was already gone, OutputError if it cannot be deleted."""
    try:
        p.unlink()
    except FileNotFoundError:
        return False
    except OSError as exc:
        raise output_error(p, exc) from exc
    return True
