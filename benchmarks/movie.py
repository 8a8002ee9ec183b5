"""``python -m benchmarks movie SCENE``: a serial run against local Dask workers, frames
compared (the former ``voxwarp animate --bench``).

The numbers of docs/distributed.md come from here.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.animation.frames import release_process_renderer
from voxwarp.animation.movie import animate


def bench_workers(
    scene: str,
    *,
    frames: int | None = None,
    size: tuple[int, int] = (512, 512),
    workers: int = 2,
    image_format: str = "png",
    progress: bool = False,
) -> dict[str, Any]:
    """Time a serial run against ``workers`` local Dask workers; compare their frames.

    Both runs render every frame into their own temporary folder (no movie). The serial
    run starts with a fresh renderer in this process (its GL context and shader
    compilation count, as they do on each worker).

    Parameters
    ----------
    scene
        Animated scene JSON.
    frames, size, image_format
        As for :func:`voxwarp.animation.movie.animate`.
    workers
        Local worker processes.
    progress
        Progress bars on stderr.

    Returns
    -------
    dict
        ``frames``, ``size``, ``workers``, ``evaluate_s`` (the serial evaluation, once per
        run), ``serial_s``, ``cluster_start_s``, ``distributed_s`` (rendering only),
        ``speedup`` (serial / distributed rendering), ``speedup_with_start`` and
        ``identical`` (every frame bit-exact).
    """
    from voxwarp.animation.distributed import CONNECT_TIMEOUT_S, dask_client
    from voxwarp.io.images import read_image

    tmp = Path(tempfile.mkdtemp(prefix="voxwarp-bench-"))
    try:
        release_process_renderer()
        serial = animate(
            scene,
            tmp / "serial.mp4",
            frames=frames,
            size=size,
            image_format=image_format,
            movie=False,
            progress=progress,
        )
        t0 = time.perf_counter()
        with dask_client(workers=workers) as client:
            client.wait_for_workers(workers, timeout=CONNECT_TIMEOUT_S * 3)
            start = time.perf_counter() - t0
            dist = animate(
                scene,
                tmp / "dask.mp4",
                frames=frames,
                size=size,
                image_format=image_format,
                client=client,
                movie=False,
                progress=progress,
            )
        identical = all(
            np.array_equal(read_image(a), read_image(b))
            for a, b in zip(serial.frames, dist.frames, strict=True)
        )
        s, d = serial.seconds["render"], dist.seconds["render"]
        return {
            "frames": len(serial.frames),
            "size": f"{size[0]}x{size[1]}",
            "workers": workers,
            "evaluate_s": serial.seconds["evaluate"],
            "serial_s": s,
            "cluster_start_s": start,
            "distributed_s": d,
            "speedup": s / d if d > 0 else float("nan"),
            "speedup_with_start": s / (d + start) if d + start > 0 else float("nan"),
            "identical": identical,
        }
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def format_bench(row: Mapping[str, Any]) -> str:
    """A markdown table of :func:`bench_workers`' result."""
    head = (
        "| frames | size | evaluate (s) | serial (s) | workers | cluster start (s) |"
        " distributed (s) | speed-up | incl. start | identical |"
    )
    sep = "|" + "---|" * 10
    body = (
        f"| {row['frames']} | {row['size']} | {row['evaluate_s']:.2f} | {row['serial_s']:.2f} |"
        f" {row['workers']} | {row['cluster_start_s']:.2f} | {row['distributed_s']:.2f} |"
        f" {row['speedup']:.2f}x | {row['speedup_with_start']:.2f}x |"
        f" {'yes' if row['identical'] else 'NO'} |"
    )
    return "\n".join([head, sep, body])


def add_bench_movie_parser(bsub: Any) -> None:
    """The ``movie`` sub-command (the options ``voxwarp animate --bench`` took)."""
    from voxwarp.cli.animate import add_frame_args
    from voxwarp.core.checks import positive_int

    p = bsub.add_parser(
        "movie",
        help="time a serial run against N local Dask workers, check that their frames are"
        " identical, print a table (no movie)",
    )
    p.add_argument("scene", help="scene JSON with an 'animation' entry")
    add_frame_args(p)
    p.add_argument(
        "--workers", type=positive_int, default=2, metavar="N", help="local workers (default 2)"
    )
    p.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="progress bar on stderr (default on)",
    )
    p.set_defaults(func=cmd_bench_movie)


def cmd_bench_movie(args: argparse.Namespace) -> int:
    """``python -m benchmarks movie SCENE``: exit 1 when the frames differ."""
    row = bench_workers(
        args.scene,
        frames=args.frames,
        size=args.size,
        workers=args.workers,
        image_format=args.image_format,
        progress=args.progress,
    )
    print(format_bench(row))
    return 0 if row["identical"] else 1
