"""Read a binary ITK transform file in a forked child first, so that ITK cannot abort voxwarp.

ITK ``.h5`` (HDF5) and ``.mat`` transform files are binary: voxwarp cannot check the
grid a B-spline's ``FixedParameters`` state before ITK allocates it, as it does for
text files (:mod:`voxwarp.io.transform_sizes`). A patched 2 KB ``.h5`` claiming a
100000³ grid made ITK abort the whole process (SIGABRT). :func:`probe_binary_transform`
lets a forked child read the file first, its data segment limited to the memory budget;
if the child dies by a signal, the file is refused with one line and voxwarp lives on.
Only files naming a grid transform are probed (a linear ``.mat`` costs nothing more).
"""

from __future__ import annotations

import mmap
import os
import resource
import signal
import time
from pathlib import Path
from typing import Any

from voxwarp.core import limits as _limits
from voxwarp.errors import FieldError

#: Longest a probe may read before it counts as a hang (seconds).
PROBE_SECONDS = 300.0
_GRID_NAMES = (b"BSplineTransform", b"DisplacementFieldTransform")


def names_a_grid(path: Path) -> bool:
    """Whether the file's bytes name a B-spline or displacement-field transform."""
    with open(path, "rb") as fh:
        if os.fstat(fh.fileno()).st_size == 0:
            return False
        with mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as m:
            return any(m.find(name) >= 0 for name in _GRID_NAMES)


def _data_segment() -> int:
    """This process's data segment (VmData, bytes); 0 where /proc is missing."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmData:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0


#: the probe child's exit status when ITK threw std::bad_alloc
OUT_OF_MEMORY = 3


def _child(sitk: Any, path: Path, limit: int) -> None:
    """In the fork: limit the data segment, silence stderr, read, exit (never returns)."""
    code = 1
    try:
        resource.setrlimit(resource.RLIMIT_DATA, (limit, resource.RLIM_INFINITY))
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 2)
        sitk.ReadTransform(str(path))
        code = 0
    except RuntimeError as exc:  # ITK's std::bad_alloc: out of the limited memory
        code = OUT_OF_MEMORY if "bad_alloc" in str(exc) else 1
    finally:
        os._exit(code)


def probe_binary_transform(sitk: Any, path: Path) -> None:
    """Refuse ``path`` with one line when reading it kills a forked child (ITK's abort
    on a grid over the memory budget, or any crash); a read error in the child is left
    to the real read, which words it. No-op where fork is missing."""
    if not hasattr(os, "fork") or not names_a_grid(path):
        return
    budget = int(_limits.current_memory_budget())
    limit = _data_segment() + budget + (256 << 20)
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child exits in _child
        _child(sitk, path, limit)
    deadline = time.monotonic() + PROBE_SECONDS
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            raise FieldError(f"{path.name}: ITK read it for over {PROBE_SECONDS:.0f} s; damaged?")
        time.sleep(0.005)
    if os.WIFSIGNALED(status) or os.WEXITSTATUS(status) == OUT_OF_MEMORY:
        what = (
            f"crashed reading it ({signal.Signals(os.WTERMSIG(status)).name})"
            if os.WIFSIGNALED(status)
            else "ran out of memory reading it (std::bad_alloc)"
        )
        raise FieldError(
            f"{path.name}: ITK {what}: the file is damaged or its grid needs more than the"
            f" memory budget of {_limits.format_bytes(budget)} (raise --memory-budget SIZE"
            " only if it is genuine)"
        )
