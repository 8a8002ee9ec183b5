"""Render animation frames on Dask workers (``voxwarp animate --workers N / --scheduler``).

The animation is evaluated serially in the client (:func:`voxwarp.animation.tracks.evaluate`:
physics depends on history); each frame is then an independent task
``render_task(header, scene, path)`` of plain JSON values: the shared header (volume
entry by sample name, file path or embedded array; the base folder of relative paths;
image size and dtype) is scattered to every worker once, the frame's scene dict travels
with its task. No GL object ever leaves a process.

Workers
    Each worker process makes its own EGL context and
    :class:`~voxwarp.render.raycaster.OffscreenRenderer` on its first frame and keeps it, with the
    volume and the warps, for the next frames (:func:`voxwarp.animation.movie.render_frame`);
    frames of
    one process are drawn one at a time. Workers write the frame files themselves
    (atomically) into the frame folder, which must be on a filesystem the client sees at
    the same path, as must volume files; the client then encodes the movie.
Identical output
    A frame's pixels depend only on its scene dict and the header (deformed-space skip
    maps are off, see :mod:`voxwarp.animation.movie`), so any split of the frames over any number of
    processes gives the serial run's frames bit for bit (tested with 2 local workers).
``--workers N``
    ``LocalCluster(n_workers=N, threads_per_worker=1, processes=True)`` on this machine.
``--scheduler ADDRESS``
    ``Client(ADDRESS)`` of a running cluster; see ``docs/distributed.md`` for a
    multi-node GPU deployment (one worker per GPU, ``GLCONTEXT_DEVICE_INDEX``).
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any

from voxwarp.animation.tracks import AnimationError
from voxwarp.errors import VoxwarpError

#: seconds to wait for a scheduler to answer / for a first worker to join
CONNECT_TIMEOUT_S = 20


@contextlib.contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None) -> Iterator[Any]:
    """A ``distributed.Client`` on a new local cluster or an existing scheduler.

    Parameters
    ----------
    workers
        Start ``LocalCluster(n_workers=workers, threads_per_worker=1, processes=True)``
        (closed on exit).
    scheduler
        Connect to this scheduler address instead (the cluster stays up on exit).

    Yields
    ------
    distributed.Client

    Raises
    ------
    AnimationError
        When the scheduler cannot be reached or the local cluster cannot start.
    """
    from distributed import Client, LocalCluster

    if (workers is None) == (scheduler is None):
        raise AnimationError("give exactly one of --workers N and --scheduler ADDRESS")
    if scheduler is not None:
        try:
            client = Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S}s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise AnimationError(
                f"cannot reach the Dask scheduler at {scheduler} ({type(exc).__name__}: {exc});"
                " start one with `dask scheduler` and workers with `dask worker ADDRESS"
                " --nthreads 1` (docs/distributed.md)"
            ) from exc
        try:
            yield client
        finally:
            client.close()
        return
    try:
        cluster = LocalCluster(
            n_workers=int(workers),  # type: ignore[arg-type]
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            silence_logs=logging.ERROR,
        )
    except (OSError, TimeoutError, RuntimeError) as exc:
        raise AnimationError(
            f"cannot start a local Dask cluster of {workers} workers: {exc}"
        ) from exc
    try:
        with Client(cluster) as client:
            yield client
    finally:
        cluster.close()


def render_task(header: Mapping[str, Any], scene: Mapping[str, Any], path: str) -> str:
    """The task a worker runs: render one frame and write it (see :mod:`voxwarp.animation.movie`).

    Parameters
    ----------
    header
        :func:`voxwarp.animation.movie.render_header`.
    scene
        The frame's scene dict (without the volume entry).
    path
        Absolute frame file path on the shared filesystem.

    Returns
    -------
    str
        ``path``.
    """
    from voxwarp.animation.frames import render_frame_to_file

    return render_frame_to_file(header, scene, path)


def render_on_dask(
    client: Any,
    header: Mapping[str, Any],
    jobs: Sequence[Any],
    on_done: Callable[[Any], None],
) -> None:
    """Render :class:`voxwarp.animation.movie.FrameJob` objects on ``client``'s workers.

    Parameters
    ----------
    client
        A ``distributed.Client``.
    header
        :func:`voxwarp.animation.movie.render_header` (scattered to every worker once).
    jobs
        Frames to render; submitted in order (earlier frames first).
    on_done
        Called in this process with each job once its file is written (in completion
        order).

    Raises
    ------
    VoxwarpError
        A frame's own error (bad scene, no GL context on a worker) as the worker raised
        it, or :class:`AnimationError` for a worker that died or another failure. The
        frames not finished are cancelled; finished ones stay on disk.
    """
    from distributed import as_completed

    if not jobs:
        return
    try:
        client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError) as exc:
        raise AnimationError(
            f"no Dask worker joined the scheduler within {CONNECT_TIMEOUT_S} s; start"
            " workers with `dask worker ADDRESS --nthreads 1`"
        ) from exc
    [shared] = client.scatter([dict(header)], broadcast=True, hash=False)
    futures = {
        client.submit(
            render_task,
            shared,
            job.scene,
            job.path,
            pure=False,
            priority=len(jobs) - n,
            key=f"voxwarp-frame-{job.index:05d}-{job.digest[:12]}",
        ): job
        for n, job in enumerate(jobs)
    }
    try:
        for fut in as_completed(list(futures)):
            job = futures[fut]
            try:
                fut.result()
            except VoxwarpError:
                raise
            except Exception as exc:
                raise AnimationError(
                    f"frame {job.index} failed on a Dask worker: {type(exc).__name__}: {exc}"
                ) from exc
            on_done(job)
    finally:
        pending = [f for f in futures if not f.done()]
        if pending:
            client.cancel(pending)


# ---------------------------------------------------------------------------- measurement
