"""Run many ``voxwarp`` command lines in ONE child process, each under an injected fault (tests).

Starting a child per command costs its imports each time; the writer-fault matrix runs
a dozen commands per fault, so :func:`run_cli_batch` starts one child (this file run as
a script) that calls :func:`voxwarp.cli.main.main` for each command in turn, with the
command's own fds 1 and 2 (native libraries' output included, HDF5's and MetaImage's)
captured through pipes, and reports ``{"rc", "stdout", "stderr"}`` per command as JSON.

Faults, set in the child around their command only:

* ``"fsize:N"``: ``RLIMIT_FSIZE`` of N bytes (``ulimit -f``; Python ignores ``SIGXFSZ``,
  so a write past it fails with ``EFBIG`` as in any ``voxwarp`` process under the limit);
* ``"fsync:ENOSPC"``: every ``os.fsync`` fails with "No space left on device" (what a
  file system with delayed allocation, NFS, reports only at the sync or the close);
* ``"replace:EROFS"`` / ``"replace:EACCES"``: ``os.replace`` fails (a folder that became
  read-only or forbidden between the write and the rename);
* ``None``: no fault.
"""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
import threading
from collections.abc import Callable, Sequence
from typing import Any

try:  # as a module of the test suite
    from tests.run_cli import REPO
except ImportError:  # as the child's script
    REPO = None  # type: ignore[assignment]


def run_cli_batch(
    commands: Sequence[tuple[Sequence[str], str | None]], timeout: float = 120
) -> list[dict[str, Any]]:
    """Run ``voxwarp ARGS`` under ``FAULT`` (see the module docstring) for every
    ``(ARGS, FAULT)`` of ``commands``, in turn, in one child; returns one
    ``{"rc", "stdout", "stderr"}`` per command."""
    spec = json.dumps([[list(argv), fault] for argv, fault in commands])
    proc = subprocess.run(
        [sys.executable, __file__],
        input=spec, capture_output=True, text=True, cwd=REPO, timeout=timeout, check=False,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


class _Pipe:
    """Redirect fd ``fd`` into a pipe drained by a thread; :meth:`close` gives the text."""

    def __init__(self, fd: int) -> None:
        self.fd, self.saved = fd, os.dup(fd)
        read, write = os.pipe()
        os.dup2(write, fd)
        os.close(write)
        self.chunks: list[bytes] = []
        self.thread = threading.Thread(target=self._drain, args=(read,), daemon=True)
        self.thread.start()

    def _drain(self, read: int) -> None:
        while chunk := os.read(read, 65536):
            self.chunks.append(chunk)
        os.close(read)

    def close(self) -> str:
        os.dup2(self.saved, self.fd)  # the pipe's last writer closes: the thread ends
        os.close(self.saved)
        self.thread.join(10)
        return b"".join(self.chunks).decode("utf-8", "replace")


def _fail(code: int) -> Callable[..., Any]:
    def fail(*_a: Any, **_k: Any) -> Any:
        raise OSError(code, os.strerror(code))

    return fail


def _run_one(argv: list[str], fault: str | None) -> dict[str, Any]:
    import resource

    from voxwarp.cli.main import main

    kind, _, arg = (fault or "").partition(":")
    saved = {"fsync": os.fsync, "replace": os.replace}
    limits = resource.getrlimit(resource.RLIMIT_FSIZE)
    sys.stdout.flush()
    sys.stderr.flush()
    out, err = _Pipe(1), _Pipe(2)
    try:
        if kind == "fsize":
            resource.setrlimit(resource.RLIMIT_FSIZE, (int(arg), limits[1]))
        elif kind in saved:
            setattr(os, kind, _fail(getattr(errno, arg)))
        try:
            rc: Any = main(argv)
        except SystemExit as exc:  # argparse
            rc = exc.code
        except BaseException as exc:  # what escaped main is the finding
            import traceback

            traceback.print_exception(exc)
            rc = f"escaped: {type(exc).__name__}"
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, limits)
        os.fsync, os.replace = saved["fsync"], saved["replace"]
        sys.stdout.flush()
        sys.stderr.flush()
        stdout, stderr = out.close(), err.close()
    return {"rc": rc, "stdout": stdout, "stderr": stderr}


def _child() -> None:
    results = [_run_one(argv, fault) for argv, fault in json.loads(sys.stdin.read())]
    sys.stdout.write(json.dumps(results))


if __name__ == "__main__":
    _child()
