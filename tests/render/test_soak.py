"""Soak test (issue 33): 1000 operations in one process, each on a renderer of its own
as the CLI, napari and notebooks make them, must not accumulate memory, descriptors or
GL objects.

The operations cycle through 3D renders in every mode (plain, deformed by a warp that
lives through the run, deformed by a new warp dropped unreleased, with the det J
overlay and handles drawn over), slices (windowed, through the transfer function, with
the grid, glyph and det J overlays) and, every ``EXPORT_EVERY``-th, a whole
``voxwarp export-volume`` run (in-process). Every ``SAMPLE_EVERY`` operations the test
records the resident set size, the open descriptors and the GL objects alive in the
pooled context (counted by the driver: tests/gl_resources.py). After ``WARMUP``
operations (every program variant compiled once) it asserts:

* the RSS trend (least squares over the samples) is under ``RSS_SLOPE_KB`` per
  operation; a context per renderer measured 106 KB per create/render/close cycle;
* the descriptors and the GL objects are the same at every sample.

``VOXWARP_SOAK_OPS`` changes the number of operations (default 1000; at least 400).
"""

from __future__ import annotations

import gc
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.gl_resources import fds, gl_objects, rss_kb
from voxwarp.cli.main import main
from voxwarp.core.modes import MODES
from voxwarp.core.volume import Volume
from voxwarp.deform.elements.offset_field import OffsetFieldWarp
from voxwarp.io.volumes import load_volume, save_volume
from voxwarp.render.jacobian_overlay import DETJ_MODES, JacobianOverlay
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.render.overlay import OverlayLayer, OverlayRenderer, box_edges
from voxwarp.scene import Scene

OPS = max(400, int(os.environ.get("VOXWARP_SOAK_OPS", "1000")))
WARMUP = 200
SAMPLE_EVERY = 100
EXPORT_EVERY = 100
RSS_SLOPE_KB = 20.0
SIZE = 24


def _warp(volume: Volume, seed: int) -> OffsetFieldWarp:
    lo, hi = volume.bounds
    u = np.random.default_rng(seed).normal(0.0, 0.8, (3, 3, 3, 3))
    return OffsetFieldWarp(lo, hi, u, inverse="baked")


def _render(r: OffscreenRenderer, scene: Scene, i: int) -> np.ndarray:
    """A 3D frame; every third one with det J (where it draws) and handles over it."""
    mode = MODES[i % len(MODES)]
    scene = scene.copy(mode=mode)
    if i % 3 == 0 and mode in DETJ_MODES and scene.warps:
        r.renderer.jacobian_overlay = JacobianOverlay()
    image = r.render(scene)
    if i % 3 == 0:
        with r.current():
            overlay = OverlayRenderer(r.ctx)
            lines = OverlayLayer("lines", box_edges(*scene.volume.bounds), (1.0, 1.0, 0.0, 1.0))
            overlay.draw([lines], r.framebuffer, scene.resolved_camera())
            overlay.release()
        image = r.read()
    return np.asarray(image)


def _slice(r: OffscreenRenderer, scene: Scene, i: int) -> np.ndarray:
    overlays = [(), ("grid",), ("glyphs",), ("jacobian",), ("grid", "jacobian")][i % 5]
    plane = ("axial", "coronal", "sagittal")[i % 3]
    look = "tf" if i % 2 else "window"
    image = r.render_slice(scene, plane, overlay=overlays if scene.warps else (), look=look)
    return np.asarray(image.rgba)


def _operation(i: int, scenes: list[Scene], volume: Volume, scene_json: Path, out: Path) -> Any:
    if i % EXPORT_EVERY == EXPORT_EVERY - 1:
        rc = main(["export-volume", str(scene_json), "-o", str(out), "--spacing", "2"])
        assert rc == 0
        return None
    scene = scenes[i % len(scenes)]
    if i % 7 == 0:  # a new warp, never released: only the context's cleaning frees it
        scene = scene.copy(warps=[_warp(volume, i)])
    with OffscreenRenderer(SIZE, SIZE) as r:
        image = _render(r, scene, i) if i % 2 else _slice(r, scene, i)
        return r.ctx, image


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_a_thousand_operations_hold_no_memory_descriptors_or_gl_objects(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rng = np.random.default_rng(11)
    data = (rng.random((16, 14, 12)) * 1000).astype(np.float32)
    volume = load_volume(save_volume(Volume(data, spacing=(1.5, 1.5, 2.0)), tmp_path / "v.nii.gz"))
    kept = _warp(volume, 1)
    scenes = [
        Scene(volume, transfer_function="grayscale"),
        Scene(volume, warps=[kept], transfer_function="grayscale"),
    ]
    scene_json = scenes[1].save(tmp_path / "scene.json")
    out = tmp_path / "deformed.nii.gz"
    samples: list[tuple[int, float, int, dict[str, int]]] = []
    ctx = None
    for i in range(OPS):
        done = _operation(i, scenes, volume, scene_json, out)
        ctx = done[0] if done is not None else ctx
        if (i + 1) % SAMPLE_EVERY == 0 and i + 1 >= WARMUP:
            gc.collect()
            samples.append((i + 1, rss_kb(), fds(), gl_objects(ctx)))
    capsys.readouterr()  # the exports' summaries
    ops = np.array([s[0] for s in samples], float)
    rss = np.array([s[1] for s in samples])
    slope = float(np.polyfit(ops, rss, 1)[0])
    print(f"soak: {OPS} ops, RSS {rss[0]:.0f} -> {rss[-1]:.0f} KB, slope {slope:.2f} KB/op")
    assert slope < RSS_SLOPE_KB, f"RSS grows {slope:.1f} KB per operation"
    # held means growing: no sample above the first. (In a shared test worker the count
    # can also drop, when an earlier test's file or pipe is closed by the collector.)
    assert max(s[2] for s in samples) <= samples[0][2], f"descriptors {[s[2] for s in samples]}"
    assert all(s[3] == samples[0][3] for s in samples), f"GL objects {[s[3] for s in samples]}"
    assert out.stat().st_size > 0
