"""``python -m benchmarks support`` on a tiny image: its rows are consistent with themselves."""

from __future__ import annotations

import pytest

from benchmarks.support import CASES, bench_support
from voxwarp.render.skipping.support import MAP_MAX_FRACTION


@pytest.mark.slow
def test_bench_support_reports_both_paths_per_deformation() -> None:
    report = bench_support(size=(40, 40), frames=1, volumes=("stent",))
    assert [r.case for r in report.rows] == list(CASES)
    rows = {r.case: r for r in report.rows}
    assert all(r.old > 0 and r.box > 0 and r.new > 0 for r in report.rows)
    assert rows["chainmail identity"].plan == "none"
    assert rows["chainmail identity"].bricks == 0.0
    drag = rows["chainmail drag"]
    assert 0.0 < drag.bricks < 1.0
    assert drag.plan == ("map" if drag.bricks <= MAP_MAX_FRACTION else "all")
    assert all(r.max_diff <= 1 for r in report.rows)
    text = report.markdown("python -m benchmarks support")
    assert "| stent | chainmail drag |" in text
    assert len(report.load) == 2
