"""Tests of voxwarp.deform.parallel: numba's parallel kernels launched from several
threads under the workqueue threading layer, which terminates the process on concurrent
launches unless voxwarp's launches take turns."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np

from voxwarp.deform.lattice import kernel as lattice_kernel
from voxwarp.deform.parallel import layer_is_threadsafe, threadsafe
from voxwarp.render.skipping import kernels as skip_kernels

# two threads, each launching a different voxwarp parallel kernel over and over
_SCRIPT = textwrap.dedent(
    """
    import threading
    import numpy as np
    import numba
    from voxwarp.deform.lattice import kernel as lk
    from voxwarp.render.skipping import kernels as sk

    rng = np.random.default_rng(0)
    nodes = rng.normal(size=(5, 5, 5, 3))
    t = rng.uniform(0, 1, (400_000, 3))
    vol = rng.integers(0, 255, (64, 64, 64)).astype(np.float32)
    lo = np.empty((16, 16, 16), np.float32)
    hi = np.empty_like(lo)

    def grid():
        out = np.empty_like(t)
        for _ in range(40):
            lk.eval_grid_kernel(nodes, t, out)

    def blocks():
        for _ in range(400):
            sk.block_range(vol, 4, lo, hi)

    grid(); blocks()  # compile (or load the cache) before the race
    assert numba.threading_layer() == "workqueue", numba.threading_layer()
    threads = [threading.Thread(target=f) for f in (grid, blocks)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    print("both threads done")
    """
)


def test_kernels_from_two_threads_survive_the_workqueue_layer() -> None:
    """Without the lock this process aborts ("Concurrent access has been detected")."""
    env = dict(os.environ, NUMBA_THREADING_LAYER="workqueue")
    res = subprocess.run(
        [sys.executable, "-c", _SCRIPT], env=env, capture_output=True, text=True, timeout=300
    )
    assert res.returncode == 0, res.stderr[-2000:]
    assert "both threads done" in res.stdout


def test_the_launcher_is_the_kernel_with_its_name() -> None:
    k = skip_kernels.block_range
    assert k.__name__ == "block_range"
    assert "Per-block (min, max)" in (k.__doc__ or "")
    assert k.kernel.py_func.__name__ == "block_range"
    rng = np.random.default_rng(1)
    nodes, t = rng.normal(size=(3, 3, 3, 3)), rng.uniform(0, 1, (50, 3))
    a, b = np.empty_like(t), np.empty_like(t)
    lattice_kernel.eval_grid_kernel(nodes, t, a)
    lattice_kernel.eval_grid_kernel.kernel(nodes, t, b)
    assert np.array_equal(a, b)


def test_this_process_knows_its_layer_after_a_launch() -> None:
    lattice_kernel.eval_grid_kernel(np.zeros((2, 2, 2, 3)), np.zeros((1, 3)), np.empty((1, 3)))
    assert layer_is_threadsafe() is not None
    assert callable(threadsafe)
