"""``python -m benchmarks segments`` on a tiny image: its rows are consistent with themselves."""

from __future__ import annotations

from benchmarks.segments import SETTINGS, bench_segments


def test_bench_segments_reports_ratios_and_differences() -> None:
    report = bench_segments(size=(48, 48), frames=1, cases=("field",))
    (row,) = report.rows
    assert row.case == "field"
    assert set(row.ratios) == {str(s) for s in SETTINGS}
    assert all(v > 0 for v in row.ratios.values())
    assert row.max_diff["1"] == 0  # the per-sample frame against itself
    assert row.mean_diff["8"] >= row.mean_diff["1"]
    assert 0.0 <= row.long_cells <= 1.0
    text = report.markdown("python -m benchmarks segments")
    assert "| field |" in text
    assert "K = auto" in text
