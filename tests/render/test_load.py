"""Load test: a long run of frames, each with a new volume and new warps, must not drift.

Every frame draws a volume of a changing shape through a new baked-inverse
``OffsetFieldWarp``; every ``LATTICE_EVERY``-th frame chains a new ``LatticeWarp`` to it
(fewer: a lattice bakes its inverse on the CPU) and every ``WIRE_EVERY``-th frame also
draws a new wire warp. Each warp is released after its frame, as the warp contract asks.
After a warm-up (every program variant of the run compiled once) the test checks:

* no GPU program is compiled any more: programs are shared per context
  (``voxwarp.deform.gl_programs``), not compiled per warp instance;
* the number of live GL objects on the context is the same as after the warm-up (moderngl
  wrappers still alive, plus wrappers collected without ``release()``, which the
  context's ``context_gc`` mode queues in ``ctx.objects``);
* the resident set size grows by less than ``RSS_BOUND_MIB``. Native memory of the GL
  driver does not show in Python's heap, so RSS is the measure, read after the heap has
  returned its freed pages (live memory, not the allocator's retention). The bound is several
  times the growth measured over this run, and far below what one leaked program per
  frame costs (the figures are in docs/reliability.md).

``VOXWARP_LOAD_FRAMES`` changes the number of frames (default 1000; at least 31).
"""

from __future__ import annotations

import gc
import os
from typing import Any

import moderngl
import numpy as np
import pytest

from benchmarks.lattice_inverse import bent_grid
from voxwarp.core.heap import return_freed_memory
from voxwarp.core.volume import Volume
from voxwarp.deform.elements.offset_field import OffsetFieldWarp
from voxwarp.deform.lattice.warp import LatticeWarp
from voxwarp.deform.wires.field import Wire, WireDeformer
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.scene import Scene

FRAMES = int(os.environ.get("VOXWARP_LOAD_FRAMES", "1000"))
WARMUP = 30
LATTICE_EVERY = 20
WIRE_EVERY = 50
RSS_BOUND_MIB = 16.0
SIZE = 16

_GL_TYPES = tuple(
    getattr(moderngl, name)
    for name in (
        "Buffer",
        "ComputeShader",
        "Framebuffer",
        "Program",
        "Query",
        "Renderbuffer",
        "Sampler",
        "Scope",
        "Texture",
        "Texture3D",
        "TextureArray",
        "TextureCube",
        "VertexArray",
    )
    if hasattr(moderngl, name)
)


def _invalid(mglo: Any) -> bool:
    return type(mglo).__name__ == "InvalidObject"


def live_gl_objects(ctx: Any) -> int:
    """GL objects alive on ``ctx``: unreleased moderngl wrappers still referenced, plus
    unreleased ones collected by Python (queued in ``ctx.objects`` in ``context_gc``)."""
    gc.collect()
    alive = sum(
        1
        for o in gc.get_objects()
        if isinstance(o, _GL_TYPES) and getattr(o, "ctx", None) is ctx and not _invalid(o.mglo)
    )
    return alive + sum(1 for m in ctx.objects if not _invalid(m))


def rss_mib() -> float:
    """Resident memory (MiB) once the allocator has handed back the pages it keeps
    after frees: what is live, not what glibc's per-thread heaps last held (in a test
    worker that ran hundreds of other tests, those moved this reading by tens of MiB
    either way)."""
    return_freed_memory()
    with open("/proc/self/status", encoding="ascii") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    pytest.skip("no VmRSS in /proc/self/status on this system")


def _wire_warp(volume: Volume, bend: float) -> Any:
    base = np.array([[4, 4, 1], [4, 4, 3], [4, 4, 5], [4, 4, 7]], dtype=float)
    moved = base.copy()
    moved[1:, 1] += bend
    wire = Wire(base, moved, radius=3.0, beta=(50.0, 200.0), name="load")
    deformer = WireDeformer(volume, [wire], field_scale=1)
    deformer.build()
    return deformer.warp()


def _frame_scenes(i: int, rng: np.random.Generator) -> tuple[list[Scene], list[Any]]:
    """Frame ``i``: a new volume (shape cycling over three), new warps; the scenes to
    draw and the warps to release afterwards."""
    data = rng.random((8 + i % 3, 8, 8)).astype(np.float32) * 100.0
    volume = Volume(data, spacing=(1.0, 1.0, 1.0))
    lo, hi = volume.bounds
    offset = OffsetFieldWarp(lo, hi, rng.normal(0.0, 0.3, (3, 3, 3, 3)), inverse="baked")
    warps: list[Any] = [offset]
    if i % LATTICE_EVERY == 0:
        warps.append(LatticeWarp(bent_grid(2, lo, hi, bend=0.1 + 0.05 * (i % 7)), (lo, hi)))
    scenes = [Scene(volume, warps=list(warps))]
    if i % WIRE_EVERY == 0:
        wire = _wire_warp(volume, 0.5 + 0.1 * (i % 7))
        scenes.append(Scene(volume, warps=[wire]))
        warps.append(wire)
    return scenes, warps


@pytest.mark.load
@pytest.mark.slow
def test_frames_with_new_warps_keep_memory_and_gl_objects_flat(
    gl_ctx: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    compiles = [0]

    def counting(name: str) -> Any:
        original = getattr(type(gl_ctx), name)

        def wrapper(self: Any, *args: Any, **kwargs: Any) -> Any:
            compiles[0] += 1
            return original(self, *args, **kwargs)

        return wrapper

    monkeypatch.setattr(type(gl_ctx), "program", counting("program"))
    monkeypatch.setattr(type(gl_ctx), "compute_shader", counting("compute_shader"))
    saved_mode = gl_ctx.gc_mode
    gl_ctx.gc_mode = "context_gc"
    renderer = OffscreenRenderer(SIZE, SIZE, ctx=gl_ctx)
    rng = np.random.default_rng(17)
    try:
        images = []
        for i in range(FRAMES):
            scenes, warps = _frame_scenes(i, rng)
            for k, scene in enumerate(scenes):
                image = renderer.render(scene)
                if i < 2 and k == 0:
                    images.append(image)
            for w in warps:
                w.release()
            if i == WARMUP - 1:
                compiles_warm = compiles[0]
                objects_warm = live_gl_objects(gl_ctx)
                rss_warm = rss_mib()
        objects_end = live_gl_objects(gl_ctx)
        rss_end = rss_mib()
    finally:
        renderer.release()
        gl_ctx.gc_mode = saved_mode
        for mglo in gl_ctx.objects:  # free what was collected unreleased (none if passed)
            if not _invalid(mglo):
                mglo.release()
        gl_ctx.objects.clear()

    assert compiles_warm > 0  # the counter sees the compiles
    assert not np.array_equal(images[0], images[1])  # the frames do change
    assert compiles[0] == compiles_warm, "programs were compiled after the warm-up"
    assert objects_end == objects_warm, f"GL objects {objects_warm} -> {objects_end}"
    growth = rss_end - rss_warm
    print(
        f"load: {FRAMES} frames, RSS {rss_warm:.1f} -> {rss_end:.1f} MiB, GL objects {objects_warm}"
    )
    assert growth < RSS_BOUND_MIB, f"RSS grew {growth:.1f} MiB over {FRAMES - WARMUP} frames"
