"""Frame rates of GRAPP 2010's own scenes (section 6 table), linear against trilinear.

Each scene of :mod:`voxwarp.teaching.grapp_scenes` is drawn as an animated scene graph
is: every frame composes its graph (``compose_scene``: one transform per object),
wraps the results in mesh instances (a new lattice is a new node texture) and draws them
(:class:`voxwarp.render.mesh_pass.MeshRenderer`, one draw call per object, bound by
``ctx.finish()``). The linear and the trilinear graph alternate frame by frame (the order
flips every frame) after one untimed warm-up frame of each (programs, mesh buffers), so
load changes hit both alike; the rates are 1000 / the median frame ms.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from voxwarp.core.camera import Camera
from voxwarp.core.mesh_warp import mesh_instances_bounds
from voxwarp.render.mesh_pass import MeshRenderer
from voxwarp.teaching.grapp_scenes import VARIANTS, GrappScene

#: image size and timed frames per variant: the reproduction's and ``--quick``'s
FULL_SIZE, FULL_FRAMES = (320, 240), 5
QUICK_SIZE, QUICK_FRAMES = (64, 48), 1


class _Target:
    """An RGBA8 colour + depth framebuffer of ``size`` on ``ctx`` (released by close)."""

    def __init__(self, ctx: Any, size: tuple[int, int]) -> None:
        self.ctx = ctx
        self.color = ctx.texture(size, 4, dtype="f1")
        self.depth = ctx.depth_texture(size)
        self.fbo = ctx.framebuffer(color_attachments=[self.color], depth_attachment=self.depth)

    def rgb(self) -> np.ndarray:
        """The image (H, W, 3) uint8, top row first."""
        w, h = self.color.size
        a = np.frombuffer(self.color.read(), dtype=np.uint8).reshape(h, w, 4)
        return a[::-1, :, :3].copy()

    def close(self) -> None:
        try:  # never release the bound framebuffer (moderngl re-binds the dead name)
            self.ctx.detect_framebuffer(0).use()
        except Exception:
            pass
        for obj in (self.fbo, self.color, self.depth):
            obj.release()


def _camera(scene: GrappScene) -> Camera:
    """A camera that frames both variants (composed once, untimed)."""
    boxes = [mesh_instances_bounds(scene.instances(v)) for v in VARIANTS]
    lo = np.min([b[0] for b in boxes if b is not None], axis=0)
    hi = np.max([b[1] for b in boxes if b is not None], axis=0)
    return Camera.fit(lo, hi, scene.view, "perspective")


def measure_scene(
    scene: GrappScene, ctx: Any, size: tuple[int, int], frames: int
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Time ``frames`` frames of each variant of ``scene`` at ``size``, alternated.

    Returns
    -------
    (dict, dict)
        The row (``scene, objects, triangles``, per variant ``{v}_ms`` median frame,
        ``{v}_fps``, ``{v}_compose_ms`` compose + wrap, ``{v}_draw_ms``; ``ratio`` =
        trilinear FPS / linear FPS; ``frames``, ``size``) and the warm-up frame's image
        per variant.
    """
    cam = _camera(scene)
    target = _Target(ctx, size)
    renderers = {v: MeshRenderer(ctx) for v in VARIANTS}
    times: dict[str, list[tuple[float, float]]] = {v: [] for v in VARIANTS}
    images: dict[str, np.ndarray] = {}

    def frame(v: str) -> tuple[float, float]:
        t0 = time.perf_counter()
        insts = scene.instances(v)
        t1 = time.perf_counter()
        renderers[v].draw(insts, target.fbo, cam)
        ctx.finish()
        return (t1 - t0) * 1000.0, (time.perf_counter() - t1) * 1000.0

    try:
        for v in VARIANTS:
            frame(v)
            images[v] = target.rgb()
        for i in range(max(1, int(frames))):
            for v in VARIANTS if i % 2 == 0 else VARIANTS[::-1]:
                times[v].append(frame(v))
    finally:
        for r in renderers.values():
            r.release()
        target.close()
    row: dict[str, Any] = {
        "scene": scene.name,
        "objects": scene.objects,
        "triangles": scene.triangles,
        "frames": max(1, int(frames)),
        "size": list(size),
    }
    for v in VARIANTS:
        total = statistics.median(c + d for c, d in times[v])
        row[f"{v}_ms"] = total
        row[f"{v}_fps"] = 1000.0 / total
        row[f"{v}_compose_ms"] = statistics.median(c for c, _ in times[v])
        row[f"{v}_draw_ms"] = statistics.median(d for _, d in times[v])
    row["ratio"] = row["linear_ms"] / row["trilinear_ms"]
    return row, images


def measure_scenes(
    builders: Iterable[Callable[[], GrappScene]],
    ctx: Any,
    size: tuple[int, int],
    frames: int,
    log: Callable[[str], None] = lambda _s: None,
) -> tuple[list[dict[str, Any]], list[tuple[str, dict[str, np.ndarray]]]]:
    """:func:`measure_scene` for each built scene: the rows and (name, images) per scene,
    each with the paper's row beside it (``paper_linear_fps``, ``paper_trilinear_fps``,
    ``paper_ratio``, ``paper_triangles`` as printed) and our scene's ``layout``."""
    rows, shots = [], []
    for build in builders:
        scene = build()
        row, images = measure_scene(scene, ctx, size, frames)
        p = scene.row
        row.update(
            paper_linear_fps=p.linear_fps,
            paper_trilinear_fps=p.trilinear_fps,
            paper_ratio=p.ratio,
            paper_triangles=p.triangles,
            measures=p.measures,
            layout=scene.layout,
        )
        rows.append(row)
        shots.append((scene.name, images))
        log(
            f"GRAPP {scene.name}: {row['objects']} objects, {row['triangles']} triangles:"
            f" linear {row['linear_fps']:.2f} FPS, trilinear {row['trilinear_fps']:.2f} FPS"
        )
    return rows, shots
