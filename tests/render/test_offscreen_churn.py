"""Creating, drawing with and closing an OffscreenRenderer many times holds no memory,
file descriptors or threads of voxwarp's own (issue 33).

Measured (llvmpipe, 2 cores): 150 renderers on one shared context, each drawing a
16³ volume, grow RSS by about 1 KB each. The test pins it: the per-renderer growth
stays under 16 KB (a renderer that kept its textures, programs or framebuffer alive
measures far above it), the descriptors and threads are flat. Renderers made without
``ctx=`` lease the pooled context instead of making one each (a standalone EGL context
costs 100-270 KB that moderngl never gives back): tests/render/test_context_pool.py.
"""

from __future__ import annotations

import gc
import os
import threading
from typing import Any

import numpy as np
import pytest

from voxwarp.core.volume import Volume
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.scene import Scene

N = 150
BOUND_KB = 16.0


def _rss_kb() -> float:
    with open("/proc/self/statm", encoding="ascii") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1024


def _fds() -> int:
    return len(os.listdir("/proc/self/fd"))


def _cycle(ctx: Any, scene: Scene, n: int) -> None:
    for _ in range(n):
        with OffscreenRenderer(16, 16, ctx=ctx) as r:
            r.render(scene)


@pytest.mark.timeout(60)
def test_renderer_churn_on_a_shared_context_is_flat(gl_ctx: Any) -> None:
    vol = Volume(np.random.default_rng(0).integers(0, 255, (16, 16, 16), dtype=np.uint8))
    scene = Scene(vol, transfer_function="grayscale")
    _cycle(gl_ctx, scene, 30)  # caches (programs per context) filled
    gc.collect()
    rss, fds, threads = _rss_kb(), _fds(), threading.active_count()
    _cycle(gl_ctx, scene, N)
    gc.collect()
    grown = (_rss_kb() - rss) / N
    assert grown < BOUND_KB, f"{grown:.1f} KB per renderer"
    # no growth: a leak adds descriptors or threads per renderer; the count may drop
    # meanwhile, when something an earlier test of this worker left (a pipe, a
    # finishing thread) is closed during the cycle (seen once: 28 -> 26 descriptors)
    assert _fds() <= fds
    assert threading.active_count() <= threads
