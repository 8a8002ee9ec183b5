"""``voxwarp.core.heap.return_freed_memory``: freed heap pages the allocator kept
resident go back to the system (oracle: the process's resident set, /proc)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from voxwarp.core.heap import return_freed_memory

_SCRIPT = r"""
import json
import numpy as np
from voxwarp.core.heap import return_freed_memory

def rss():
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS"):
            return int(line.split()[1]) * 1024

big = np.ones(16 << 20, np.uint8)
del big  # a freed mmap chunk raises glibc's mmap threshold: 1 MiB arrays come from the heap
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
