"""``voxwarp.core.heap.return_freed_memory``: freed heap pages the allocator kept
resident go back to the system (oracle: the process's resident set, /proc)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from voxwarp.core.heap import return_freed_memory

_SCRIPT = r"""
import ctypes
import ctypes.util
import json
import numpy as np
from voxwarp.core.heap import return_freed_memory

def rss():
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS"):
            return int(line.split()[1]) * 1024

# fixed thresholds (not glibc's dynamic ones, which depend on what ran before): 1 MiB
# arrays come from the heap, and free() never trims the heap's top by itself
libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
assert libc.mallopt(M_MMAP_THRESHOLD, 32 << 20) == 1
assert libc.mallopt(M_TRIM_THRESHOLD, 1 << 30) == 1
parts, pins = [], []
for _ in range(64):  # each followed by a live allocation, so none merges into the heap's top
    parts.append(np.ones(1 << 20, np.uint8))
    pins.append(bytearray(4096))
before = rss()
del parts
freed = rss()
called = return_freed_memory()
print(json.dumps({"called": called, "by_free": before - freed, "by_trim": freed - rss()}))
"""


def test_freed_heap_pages_leave_the_resident_set() -> None:
    if not sys.platform.startswith("linux") or not return_freed_memory():
        pytest.skip("needs glibc on Linux")
    run = subprocess.run([sys.executable, "-c", _SCRIPT], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr[-2000:]
    got = json.loads(run.stdout.strip().splitlines()[-1])
    assert got["called"]
    assert got["by_free"] < 16 << 20, got  # freeing alone kept (most of) the 64 MiB
    assert got["by_trim"] > 48 << 20, got
