"""Straight-ray cell maps built off the drawing thread (``cell_skip_maps="background"``,
what the GUI uses): block skipping until a worker's cell visibility is installed, then
the same image as maps built at once, and no visibility work on the drawing thread."""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
import pytest

from voxwarp.core.transfer_function import TransferFunction
from voxwarp.core.volume import Volume
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.render.skipping import cache as skip_cache
from voxwarp.scene import Scene


def shells() -> Volume:
    x, y, z = np.meshgrid(*[np.arange(40.0)] * 3, indexing="ij")
    r = np.sqrt((x - 20) ** 2 + (y - 19) ** 2 + (z - 21) ** 2)
    return Volume(np.where(np.abs(r - 12) < 2, 180, 0).astype(np.uint8))


TF = TransferFunction([(0, 0, 0, 0, 0), (90, 1, 0.8, 0.6, 0.0), (180, 1, 1, 1, 0.7)])


def test_worker_builds_the_cells_and_the_image_is_unchanged(
    gl_ctx: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(skip_cache, "EAGER_CELLS", 1000)  # 41³ cells count as big
    threads: list[int] = []
    build = skip_cache.cell_visibility

    def recorded(*args: Any) -> Any:
        threads.append(threading.get_ident())
        return build(*args)

    monkeypatch.setattr(skip_cache, "cell_visibility", recorded)
    scene = Scene(shells(), transfer_function=TF, view=(-40, 30), jitter=False)
    with OffscreenRenderer(64, 64, ctx=gl_ctx) as ref:
        ref.renderer.cell_skip_maps = "always"
        expected = ref.render(scene)
        assert ref.renderer.last_skip_kind == "cells"
    threads.clear()
    with OffscreenRenderer(64, 64, ctx=gl_ctx) as r:
        r.renderer.cell_skip_maps = "background"
        first = r.render(scene)
        assert r.renderer.last_skip_kind == "blocks"
        assert r.renderer.needs_skip_maps(scene)
        r.render(scene)  # still blocks: nothing built on this thread
        assert r.renderer.last_skip_kind == "blocks"
        key, job = r.renderer.skip_map_job()
        out: list[Any] = []
        worker = threading.Thread(target=lambda: out.append(job()))
        worker.start()
        worker.join()
        r.renderer.install_skip_map(key, out[0])
        assert not r.renderer.needs_skip_maps(scene)
        second = r.render(scene)
        assert r.renderer.last_skip_kind == "cells"
        assert r.renderer.skip_map_job() is None  # nothing more wanted
    assert threads == [worker.ident]
    np.testing.assert_array_equal(first, expected)  # blocks and cells: the same image
    np.testing.assert_array_equal(second, expected)


def test_a_changed_transfer_function_offers_a_new_job(
    gl_ctx: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(skip_cache, "EAGER_CELLS", 1000)
    scene = Scene(shells(), transfer_function=TF, jitter=False)
    with OffscreenRenderer(32, 32, ctx=gl_ctx) as r:
        r.renderer.cell_skip_maps = "background"
        r.render(scene)
        key, job = r.renderer.skip_map_job()
        r.renderer.install_skip_map(key, job())
        r.render(scene)
        assert r.renderer.last_skip_kind == "cells"
        other = scene.copy(transfer_function=TransferFunction([(0, 0, 0, 0, 0), (250, 1, 1, 1, 1)]))
        r.render(other)
        assert r.renderer.last_skip_kind == "blocks"
        assert r.renderer.skip_map_job() is not None


def test_bad_setting_names_the_choices(gl_ctx: Any) -> None:
    from voxwarp.errors import RenderError

    with OffscreenRenderer(8, 8, ctx=gl_ctx) as r, pytest.raises(RenderError, match="'background'"):
        r.renderer.cell_skip_maps = "later"
