"""``voxwarp animate``: render an animated scene's frames and encode them into a movie.

::

    voxwarp animate scene.json --frames 48 --fps 24 -o movie.mp4 [--size 640x480]
        [--format png|exr] [--workers N | --scheduler tcp://host:8786] [--no-movie]

The scene JSON's ``"animation"`` entry (:mod:`voxwarp.animation.tracks`) is first evaluated
serially into one complete scene dict per frame (physics included); the frames are then
rendered from those dicts — in this process, or on Dask workers
(:mod:`voxwarp.animation.distributed`),
with identical results — and encoded.

Frames
    ``<output stem>_frames/frame_00000.png`` (``--format exr``: float EXR), written
    through OpenImageIO (:func:`voxwarp.io.images.write_image`, atomic: a frame file that
    exists is complete). Images are RGBA with the scene's background composited in.
Resume
    The frame folder holds ``manifest.json``: per frame, a SHA-256 of everything the
    frame's pixels depend on (its scene dict, the volume entry and, for a volume file,
    its absolute path, size and modification time, the image size and format). A run
    keeps the frame files whose manifest digest equals the new one and skips them;
    every other frame file of the folder (``frame_NNNNN.png|exr``: another scene, size
    or format, or no manifest) is deleted and rendered again, so frames of another
    scene are never reused. The new manifest is written before the first frame is rendered. An
    interrupted run (Ctrl+C, a failed worker) therefore resumes where it stopped.
    Two runs must not write to the same folder at once.
Movie
    Encoded with imageio-ffmpeg's bundled ffmpeg: H.264 (libx264, CRF 18), yuv420p, at
    ``--fps``; the RGB of each frame (alpha dropped: the background is already in), padded
    to an even size by repeating the last row/column. Written to a temporary name in the
    output's folder and renamed when complete. ``.mp4``, ``.mov`` or ``.mkv``.
Rendering
    One :class:`~voxwarp.render.raycaster.OffscreenRenderer` per process (made on first use, kept
    for
    the next frames: see :func:`render_frame`), with the volume loaded once and warps
    rebuilt only when their entry changes. Deformed-space skip maps are off
    (``warped_skip_maps = "never"``): a frame's image then never depends on which
    frames the process drew before, so serial and distributed runs are bit-identical.
Progress
    A tqdm bar on stderr (``--no-progress`` turns it off).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.animation import FRAME_FORMATS
from voxwarp.animation.frames import canonical_json, render_frame_to_file
from voxwarp.animation.tracks import MAX_FRAMES, FrameStates, load_animated_scene
from voxwarp.core.extras import require
from voxwarp.errors import VoxwarpError

#: ``--format`` -> frame file extension
#: movie containers accepted for ``-o``
MOVIE_SUFFIXES: tuple[str, ...] = (".mp4", ".mov", ".mkv")
#: name of the frame folder's manifest
MANIFEST_NAME = "manifest.json"
MANIFEST_FORMAT = "voxwarp-animation-frames"
#: changes whenever what a frame digest covers changes (old frames are then re-rendered)
DIGEST_VERSION = 1
#: H.264 constant rate factor of the movie (18: visually lossless)
MOVIE_CRF = 18

_FRAME_FILE = re.compile(r"^frame_\d{5}\.(png|exr)$")
_FRAME_TEMP = re.compile(r"^\.frame_\d{5}\.(png|exr)\..+\.tmp\.(png|exr)$")
#: a 1-voxel stand-in: scenes are parsed with it, then given the cached volume


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


def render_header(states: FrameStates, size: tuple[int, int], dtype: str = "u1") -> dict[str, Any]:
    """What every frame of ``states`` shares: volume entry, base folder, image size, dtype.

    Parameters
    ----------
    states
        The evaluated animation.
    size
        ``(width, height)`` in pixels.
    dtype
        ``"u1"`` (8-bit frames) or ``"f4"`` (float frames for EXR).

    Returns
    -------
    dict
        JSON values only (shipped to Dask workers as is).
    """
    volume = states.scenes[0]["volume"] if states.scenes else {}
    return {
        "volume": volume,
        "base_dir": None if states.base_dir is None else str(states.base_dir),
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
    states: FrameStates, frames_dir: str | os.PathLike, header: Mapping[str, Any], ext: str
) -> list[FrameJob]:
    """One :class:`FrameJob` per frame of ``states`` (absolute paths in ``frames_dir``)."""
    folder = Path(frames_dir).resolve()
    jobs = []
    for i, d in enumerate(states.scenes):
        scene = {k: v for k, v in d.items() if k != "volume"}
        jobs.append(
            FrameJob(i, scene, str(folder / frame_name(i, ext)), frame_digest(header, scene, ext))
        )
    return jobs


def _read_manifest(folder: Path) -> list[str] | None:
    try:
        d = json.loads((folder / MANIFEST_NAME).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(d, dict) or d.get("format") != MANIFEST_FORMAT:
        return None
    frames = d.get("frames")
    if not isinstance(frames, list) or not all(isinstance(x, str) for x in frames):
        return None
    return frames


def prepare_frames_dir(
    frames_dir: str | os.PathLike, jobs: Sequence[FrameJob]
) -> tuple[list[FrameJob], list[FrameJob], int]:
    """Sort ``jobs`` into finished frames (kept) and frames to render (see Resume above).

    Deletes frame files the manifest does not vouch for, and leftover temporary files of
    a killed run, then writes the new manifest.

    Parameters
    ----------
    frames_dir
        The frame folder (made if missing).
    jobs
        The frames of this run.

    Returns
    -------
    (kept, todo, removed)
        Finished frames, frames to render, and the number of stale frame files deleted.
    """
    from voxwarp.core.files import atomic_write_text

    folder = Path(frames_dir)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise VoxwarpError(f"cannot make the frame folder {folder}: {exc}") from exc
    old = _read_manifest(folder)
    kept: list[FrameJob] = []
    todo: list[FrameJob] = []
    for job in jobs:
        p = Path(job.path)
        ok = old is not None and job.index < len(old) and old[job.index] == job.digest
        (kept if ok and p.is_file() else todo).append(job)
    keep = {Path(j.path).name for j in kept}
    removed = 0
    for p in folder.iterdir():
        if (_FRAME_FILE.match(p.name) and p.name not in keep) or _FRAME_TEMP.match(p.name):
            p.unlink(missing_ok=True)
            removed += int(bool(_FRAME_FILE.match(p.name)))
    manifest = {
        "format": MANIFEST_FORMAT,
        "version": DIGEST_VERSION,
        "frames": [j.digest for j in jobs],
    }
    atomic_write_text(folder / MANIFEST_NAME, json.dumps(manifest, indent=1))
    return kept, todo, removed


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


def encode_movie(
    frame_paths: Sequence[str | os.PathLike], output: str | os.PathLike, fps: float
) -> Path:
    """Encode frame files into an H.264 movie (see the module doc), atomically.

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
    """
    import imageio_ffmpeg

    from voxwarp.core.files import atomic_write
    from voxwarp.io.images import read_image

    out = Path(output)
    if out.suffix.lower() not in MOVIE_SUFFIXES:
        raise VoxwarpError(f"movie output {out} must end in {', '.join(MOVIE_SUFFIXES)}")
    if not frame_paths:
        raise VoxwarpError("no frames to encode")
    first = _rgb8(read_image(frame_paths[0]))
    height, width = first.shape[:2]

    def write(tmp: Path) -> None:
        writer = imageio_ffmpeg.write_frames(
            str(tmp),
            (width, height),
            fps=float(fps),
            codec="libx264",
            pix_fmt_in="rgb24",
            pix_fmt_out="yuv420p",
            quality=None,
            macro_block_size=1,
            ffmpeg_log_level="error",
            output_params=["-crf", str(MOVIE_CRF)],
        )
        writer.send(None)  # start ffmpeg
        try:
            for n, p in enumerate(frame_paths):
                rgb = first if n == 0 else _rgb8(read_image(p))
                if rgb.shape != first.shape:
                    raise VoxwarpError(
                        f"frame {p} is {rgb.shape[1]}x{rgb.shape[0]}; the first frame is"
                        f" {width}x{height}"
                    )
                writer.send(rgb)
        finally:
            writer.close()

    out.parent.mkdir(parents=True, exist_ok=True)
    try:
        atomic_write(out, out.suffix, write)
    except VoxwarpError:
        raise
    except (OSError, RuntimeError) as exc:
        raise VoxwarpError(f"could not encode the movie {out}: {exc}") from exc
    return out


# ---------------------------------------------------------------------------- animate
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
    fps
        Frames per second of the movie.
    seconds
        Wall times: ``evaluate``, ``render`` (including worker start for ``workers``),
        ``encode``.
    """

    movie: Path | None
    frames_dir: Path
    frames: list[Path]
    rendered: list[int] = field(default_factory=list)
    skipped: list[int] = field(default_factory=list)
    removed: int = 0
    fps: float = 24.0
    seconds: dict[str, float] = field(default_factory=dict)


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
    client
        An existing ``distributed.Client`` to render on (instead of the two above).
    movie
        Encode the movie (False: frames only).
    progress
        Show a progress bar on stderr.
    on_frame
        ``on_frame(index, path)`` after each frame is written (in this process).

    Returns
    -------
    AnimateResult

    Raises
    ------
    VoxwarpError
        On bad input (scene, animation, options); frames finished before an error or
        an interruption stay and are skipped by the next run.
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
    ext = FRAME_FORMATS[image_format]
    t0 = time.perf_counter()
    states = load_animated_scene(scene, frames=frames)
    rate = float(fps) if fps is not None else states.animation.fps
    header = render_header(states, size, "f4" if image_format == "exr" else "u1")
    folder = frames_dir_for(out)
    jobs = plan_jobs(states, folder, header, ext)
    kept, todo, removed = prepare_frames_dir(folder, jobs)
    result = AnimateResult(
        movie=None,
        frames_dir=folder,
        frames=[Path(j.path) for j in jobs],
        skipped=[j.index for j in kept],
        removed=removed,
        fps=rate,
    )
    result.seconds["evaluate"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    if todo:
        _render_jobs(
            header, todo, result, workers, scheduler, client, progress, on_frame, len(jobs)
        )
    result.seconds["render"] = time.perf_counter() - t0
    if movie:
        t0 = time.perf_counter()
        result.movie = encode_movie(result.frames, out, rate)
        result.seconds["encode"] = time.perf_counter() - t0
    return result


def _render_jobs(
    header: Mapping[str, Any],
    todo: list[FrameJob],
    result: AnimateResult,
    workers: int | None,
    scheduler: str | None,
    client: Any,
    progress: bool,
    on_frame: Callable[[int, Path], None] | None,
    total: int,
) -> None:
    from tqdm import tqdm

    bar = tqdm(
        total=total,
        initial=total - len(todo),
        unit="frame",
        desc="frames",
        file=sys.stderr,
        disable=not progress,
        dynamic_ncols=True,
    )

    def done(job: FrameJob) -> None:
        result.rendered.append(job.index)
        bar.update(1)
        if on_frame is not None:
            on_frame(job.index, Path(job.path))

    try:
        if workers is None and scheduler is None and client is None:
            for job in todo:
                render_frame_to_file(header, job.scene, job.path)
                done(job)
            return
        from voxwarp.animation.distributed import dask_client, render_on_dask

        if client is not None:
            render_on_dask(client, header, todo, done)
            return
        with dask_client(workers=workers, scheduler=scheduler) as c:
            render_on_dask(c, header, todo, done)
    finally:
        bar.close()
