"""Render animation frames on Dask workers (``voxwarp animate --workers N / --scheduler``).

The animation is evaluated serially in the client (:func:`voxwarp.animation.tracks.evaluate`:
physics depends on history); each frame is then an independent task
``render_task(header, scene, path)`` of plain JSON values: the shared header (volume
entry by sample name, file path or embedded array; the base folder of relative paths;
image size and dtype) is scattered to every worker once, the frame's scene dict travels
with its task. No GL object ever leaves a process.

Workers
    Each worker process makes its own EGL context and
    :class:`~voxwarp.render.offscreen.OffscreenRenderer` on its first frame and keeps it, with the
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
import socket
import struct
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from typing import Any

from voxwarp.animation.frames import render_frame_to_file
from voxwarp.animation.tracks import AnimationError
from voxwarp.errors import VoxwarpError

#: seconds to wait for a scheduler to answer / for a first worker to join
CONNECT_TIMEOUT_S = 20


#: the most bytes a Dask scheduler's opening handshake may take
_HANDSHAKE_MAX_BYTES = 1 << 20


def _recv_exactly(sock: socket.socket, n: int, deadline: float) -> bytes:
    data = bytearray()
    while len(data) < n:
        left = deadline - time.monotonic()
        if left <= 0:
            raise TimeoutError("no answer")
        sock.settimeout(left)
        chunk = sock.recv(min(n - len(data), 65536))
        if not chunk:
            raise ConnectionError("the connection was closed")
        data += chunk
    return bytes(data)


def probe_scheduler(address: str, timeout: float | None = None) -> None:
    """Check that ``address`` answers like a Dask scheduler before Dask talks to it.

    A Dask scheduler sends a short handshake message as soon as a client connects
    (a frame count and frame lengths, then the frames). Anything else (a web server, a
    silent port, random bytes) would make Dask's client wait forever or try to allocate
    the size it reads from the first bytes; here it is one line within ``timeout``
    seconds. Only ``tcp://`` addresses (and bare ``host:port``) are probed; ``tls://``
    and other transports are left to Dask.

    Raises
    ------
    AnimationError
        When nothing listens there, or what answers is not a Dask scheduler.
    """
    from distributed.comm.addressing import parse_address, parse_host_port

    limit = CONNECT_TIMEOUT_S if timeout is None else float(timeout)
    try:
        scheme, loc = parse_address(address)
        if scheme != "tcp":
            return
        host, port = parse_host_port(loc, 8786)
    except (ValueError, TypeError) as exc:
        raise AnimationError(
            f"--scheduler {address!r} is not a Dask address (tcp://HOST:PORT): {exc}"
        ) from exc
    deadline = time.monotonic() + limit
    try:
        sock = socket.create_connection((host, int(port)), timeout=limit)
    except OSError as exc:
        raise AnimationError(
            f"cannot reach the Dask scheduler at {address} ({type(exc).__name__}: {exc});"
            " start one with `dask scheduler` and workers with `dask worker ADDRESS"
            " --nthreads 1` (docs/distributed.md)"
        ) from exc
    why = ""
    try:
        with sock:
            (size,) = struct.unpack("Q", _recv_exactly(sock, 8, deadline))
            if not 16 <= size <= _HANDSHAKE_MAX_BYTES:
                why = "its first bytes are not a Dask message"
            else:
                body = _recv_exactly(sock, size, deadline)
                (count,) = struct.unpack_from("Q", body)
                if not 1 <= count <= 64 or 8 * (1 + count) > size:
                    why = "its first message is not a Dask message"
    except TimeoutError:
        why = f"no Dask handshake within {limit:g} s"
    except OSError as exc:
        why = f"{type(exc).__name__}: {exc}"
    if why:
        raise AnimationError(
            f"{address} does not answer like a Dask scheduler ({why}); --scheduler must be"
            " the address of a Dask scheduler you trust (docs/distributed.md)"
        )


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
        probe_scheduler(scheduler)
        try:
            client = Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S}s")
        except (OSError, TimeoutError, ValueError, MemoryError, OverflowError) as exc:
            raise AnimationError(
                f"cannot connect to the Dask scheduler at {scheduler} ({type(exc).__name__}:"
                f" {exc}); is it a Dask scheduler? (docs/distributed.md)"
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


def render_task(header: Mapping[str, Any], scene: Mapping[str, Any], path: str) -> dict[str, Any]:
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
    dict
        ``{"path", "size", "sha256"}`` of the file written
        (:func:`voxwarp.animation.frames.render_frame_to_file`).
    """
    return render_frame_to_file(header, scene, path)


def render_on_dask(
    client: Any,
    header: Mapping[str, Any],
    jobs: Iterable[Any],
    on_done: Callable[[Any, Mapping[str, Any]], None],
    window: int | None = None,
) -> None:
    """Render :class:`voxwarp.animation.movie.FrameJob` objects on ``client``'s workers.

    Parameters
    ----------
    client
        A ``distributed.Client``.
    header
        :func:`voxwarp.animation.movie.render_header` (scattered to every worker once).
    jobs
        Frames to render, in order; taken lazily (the animation's physics is evaluated
        as the iterator advances), with at most ``window`` frames in flight.
    on_done
        ``on_done(job, record)`` in this process once a job's file is written, in
        completion order; ``record`` is the task's ``{"path", "size", "sha256"}``.
    window
        Frames submitted ahead (default: 4 per worker, at least 16): bounds the frames
        held in memory here and on the scheduler.

    Raises
    ------
    VoxwarpError
        A frame's own error (bad scene, no GL context on a worker, a failed write) as
        the worker raised it, or :class:`AnimationError` for a worker that died or
        another failure. The frames not finished are cancelled; finished ones stay on
        disk.
    """
    from distributed import as_completed

    it = iter(jobs)
    try:
        client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError) as exc:
        raise AnimationError(
            f"no Dask worker joined the scheduler within {CONNECT_TIMEOUT_S} s; start"
            " workers with `dask worker ADDRESS --nthreads 1`"
        ) from exc
    if window is None:
        try:
            n_workers = len(client.scheduler_info().get("workers", {}))
        except (OSError, TimeoutError, AttributeError):
            n_workers = 1
        window = max(16, 4 * n_workers)
    [shared] = client.scatter([dict(header)], broadcast=True, hash=False)
    futures: dict[Any, Any] = {}

    def submit() -> Any:
        job = next(it, None)
        if job is None:
            return None
        fut = client.submit(
            render_task,
            shared,
            job.scene,
            job.path,
            pure=False,
            priority=-job.index,  # earlier frames first
            key=f"voxwarp-frame-{job.index:05d}-{job.digest[:12]}",
        )
        futures[fut] = job
        return fut

    try:
        pending = as_completed()
        for _ in range(max(1, int(window))):
            fut = submit()
            if fut is None:
                break
            pending.add(fut)
        for fut in pending:
            job = futures.pop(fut)
            try:
                record = fut.result()
            except VoxwarpError:
                raise
            except Exception as exc:
                raise AnimationError(
                    f"frame {job.index} failed on a Dask worker: {type(exc).__name__}: {exc}"
                ) from exc
            on_done(job, record)
            nxt = submit()
            if nxt is not None:
                pending.add(nxt)
    finally:
        left = [f for f in futures if not f.done()]
        if left:
            client.cancel(left)


# ---------------------------------------------------------------------------- measurement
