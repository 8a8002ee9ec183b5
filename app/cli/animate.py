"""``voxwarp animate``: its parser and command (the work is in :mod:`voxwarp.animation.movie`)."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from voxwarp.animation import FRAME_FORMATS
from voxwarp.cli.options import add_allow_dir_arg
from voxwarp.core.checks import image_size, positive_int


def _fps(text: str) -> float:
    try:
        v = float(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"fps must be a number; got {text!r}") from exc
    if not 0 < v <= 1000:
        raise argparse.ArgumentTypeError(f"fps must be in (0, 1000]; got {text!r}")
    return v


def _frames(text: str) -> int:
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.animation.tracks import MAX_FRAMES

    n = positive_int(text)
    if n > MAX_FRAMES:
        raise argparse.ArgumentTypeError(f"frames must be 1..{MAX_FRAMES}; got {text!r}")
    return n


def add_frame_args(p: argparse.ArgumentParser) -> None:
    """The frame options of every command that renders an animation's frames (``animate``
    and the lab's ``python -m benchmarks movie``): how many, their size and file format."""
    p.add_argument("--frames", type=_frames, help="frames to render (default: the animation's)")
    p.add_argument("--size", type=image_size, default=(512, 512), help="WxH pixels")
    p.add_argument(
        "--format",
        dest="image_format",
        choices=tuple(FRAME_FORMATS),
        default="png",
        help="frame files: 8-bit PNG or float EXR (default png)",
    )


def add_parser(sub: Any) -> None:
    """Add ``animate`` to the ``voxwarp`` sub-commands (``sub``: their sub-parsers object)."""
    p = sub.add_parser(
        "animate",
        help="render an animated scene JSON into frames and a movie",
        description="Render the frames of a scene JSON with an 'animation' entry (see"
        " app/animation/tracks.py and sample_volumes/*anim*.json) and encode them with"
        " ffmpeg. An interrupted run resumes: finished frames are kept and skipped.",
    )
    p.add_argument(
        "scene",
        help="scene JSON with an 'animation' entry, or sample:NAME of a bundled one"
        " (voxwarp samples lists them)",
    )
    p.add_argument(
        "-o",
        "--output",
        default="movie.mp4",
        help="movie file (.mp4, .mov, .mkv); frames go to <stem>_frames/",
    )
    add_frame_args(p)
    add_allow_dir_arg(p)
    p.add_argument("--fps", type=_fps, help="frames per second (default: the animation's)")
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=positive_int,
        metavar="N",
        help="render on a local Dask cluster of N worker processes (one GL context each)",
    )
    where.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="render on an existing Dask cluster, e.g. tcp://host:8786 (docs/distributed.md)",
    )
    p.add_argument("--no-movie", action="store_true", help="write the frames only")
    p.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="progress bar on stderr (default on)",
    )
    p.add_argument(
        "--bench",
        action="store_true",
        help="moved: 'python -m benchmarks movie SCENE' from a checkout of voxwarp",
    )
    p.set_defaults(func=cmd_animate)


def cmd_animate(args: argparse.Namespace) -> int:
    """``voxwarp animate SCENE -o movie.mp4``."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.animation.movie import animate

    if args.bench:  # the lab's, not installed: one line naming it
        print(
            "voxwarp: error: 'voxwarp animate --bench' moved out of the installed package:"
            " run 'python -m benchmarks movie SCENE' from a checkout of voxwarp",
            file=sys.stderr,
        )
        return 2
    from voxwarp.io.samples import resolve_sample_path

    result = animate(
        str(resolve_sample_path(args.scene)),  # sample:NAME: a bundled animation
        args.output,
        frames=args.frames,
        fps=args.fps,
        size=args.size,
        image_format=args.image_format,
        workers=args.workers,
        scheduler=args.scheduler,
        movie=not args.no_movie,
        progress=args.progress,
    )
    n = len(result.frames)
    note = f"{len(result.rendered)} of {n} frames rendered"
    if result.skipped:
        note += f", {len(result.skipped)} kept from an earlier run"
    if result.removed:
        note += f", {result.removed} stale frame files removed"
    print(f"{note} ({result.frames_dir})", file=sys.stderr)
    print(result.movie if result.movie is not None else result.frames_dir)
    return 0
