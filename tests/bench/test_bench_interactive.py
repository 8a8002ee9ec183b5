"""``voxwarp bench interactive``: the report's structure (timings are not asserted)."""

from __future__ import annotations

import pytest

from voxwarp.bench.interactive import bench_interactive
from voxwarp.render.adaptive_quality import LEVELS


@pytest.mark.slow
def test_bench_interactive_times_each_family_three_ways() -> None:
    report = bench_interactive(size=(64, 48), frames=1, families=("none", "lattice"))
    assert report.size == (64, 48)
    assert report.reference_ms > 0
    assert [r.family for r in report.rows] == ["none", "lattice"]
    none, lattice = report.rows
    assert none.maps_s == 0.0  # nothing warped: no deformed-space maps to build
    assert lattice.maps_s > 0.0  # the bent lattice needed them, and they were built
    for row in report.rows:
        assert min(row.interactive_ms, row.rest_blocks_ms, row.rest_cells_ms) > 0
        assert row.coarse_ms > 0
        assert row.adaptive_fps > 0
        assert row.adaptive_level in LEVELS
    text = report.markdown("voxwarp bench interactive --size 64x48")
    assert "`voxwarp bench interactive --size 64x48`" in text
    assert "| lattice | node (1, 1, 2) of 3³ cells moved" in text
    assert text.count("\n| ") == 3  # the header and the 2 rows


@pytest.mark.slow
def test_the_scripted_drag_runs_both_paths_and_reports_them() -> None:
    from voxwarp.bench.drag import DRAG_FRAMES, MODES, DragLoop, bench_drag, drag_markdown
    from voxwarp.io.samples import load_sample
    from voxwarp.render.offscreen import OffscreenRenderer
    from voxwarp.scene import Scene

    base = Scene(load_sample("fish", shape=(32, 32, 32)), jitter=False)
    size = (64, 48)
    with OffscreenRenderer(*size) as r:
        rr = r.renderer

        def draw(scene: Scene, scale: float, camera: object = None) -> None:
            rr.draw_scaled(scene, r.framebuffer, None, camera, scale)

        with r.current():
            rows = bench_drag(DragLoop(rr, draw, size), base, 1, 4, ("chainmail",))
    (row,) = rows
    assert set(row.results) == set(MODES)
    sync, thread = row.results["sync"][0], row.results["thread"][0]
    assert sync.fresh_frames == DRAG_FRAMES  # on the drawing thread every frame moves it
    assert 1 <= thread.fresh_frames <= DRAG_FRAMES
    for result in (sync, thread):
        assert result.fps > 0
        assert result.release_s >= result.maps_s >= 0
    text = drag_markdown(rows, size, 10.0)
    assert "| chainmail | 4³ |" in text
    assert text.count("\n| ") == 2  # the header and the row
