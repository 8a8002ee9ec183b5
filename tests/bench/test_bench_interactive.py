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
