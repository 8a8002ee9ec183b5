"""Smoke tests of ``python -m benchmarks chainmail`` (benchmarks.chainmail) on tiny grids.

Oracles: both CPU variants end a single drag in the same state, so they touch the same
elements; a local drag (1 spacing) touches 63 elements on any grid of 8³ and more (the
slack of a quarter spacing per link stops it 3 links away); the large drag moves every
element of a small grid (no fixed elements, so nothing limits it); the target line
states the ratio to 100 ms.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from benchmarks.__main__ import main
from benchmarks.chainmail import (
    DRAGS,
    ChainBenchReport,
    ChainBenchRow,
    bench_chainmail,
    drag_offset,
)
from tests.cli.test_cli import _keep_warning_state  # noqa: F401  (autouse fixture)


def test_cpu_rows_on_tiny_grids() -> None:
    report = bench_chainmail((4, 8), repeats=2, use_gpu=False, log=lambda s: None)
    for n in (4, 8):
        for drag, _, _ in DRAGS:
            rows = [report.find(n, v, drag) for v in ("gibson", "enhanced")]
            assert all(r is not None for r in rows)
            g, e = rows
            assert g.repeats == e.repeats == 2  # type: ignore[union-attr]
            assert g.touched == e.touched  # type: ignore[union-attr]
            for r in rows:
                assert 0 < r.min_ms <= r.median_ms <= r.max_ms  # type: ignore[union-attr]
                assert r.fraction == 1.0  # type: ignore[union-attr]
            assert report.find(n, "gpu", drag) is None
            assert report.skipped(n, "gpu") == "skipped (not asked for)"
    assert report.find(8, "enhanced", "local").touched == 63  # type: ignore[union-attr]
    assert report.find(4, "enhanced", "large").touched == 4**3  # type: ignore[union-attr]
    text = report.markdown("python -m benchmarks chainmail --sizes 4,8")
    assert "Command: `python -m benchmarks chainmail --sizes 4,8`" in text
    assert "| 8³ | local |" in text
    assert "| 4³ | large |" in text
    assert "* GPU (4³, 8³): skipped (not asked for)" in text
    assert "not measured (128 is not among the sizes)" in text


def test_drag_offsets_are_in_spacings() -> None:
    np.testing.assert_allclose(drag_offset(11, "local"), [10.0, 0.0, 0.0])  # spacing 10 mm
    large = drag_offset(11, "large")
    np.testing.assert_allclose(np.linalg.norm(large), 200.0)
    np.testing.assert_allclose(large / large[1], [2.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="unknown drag"):
        drag_offset(11, "huge")


def test_target_line_states_the_ratio() -> None:
    report = ChainBenchReport(sizes=(128,), repeats=3)
    report.rows = [
        ChainBenchRow(128, "gibson", "local", 3, 0.5, 0.4, 0.6, 63),
        ChainBenchRow(128, "enhanced", "local", 3, 125.0, 120.0, 130.0, 63),
    ]
    line = report.target_line()
    assert line.startswith("Target: a local drag on 128³ settles in < 100 ms on the CPU")
    assert "gibson 0.5 ms = 0.0050 x the target (met, 200x faster than needed)" in line
    assert "enhanced 125 ms = 1.2500 x the target (MISSED)" in line


def test_cli_writes_the_markdown(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "bench.md"
    args = ["chainmail", "--sizes", "4", "--repeats", "1", "--no-gpu"]
    assert main([*args, "--markdown", str(out)]) == 0
    printed = capsys.readouterr().out
    text = out.read_text()
    assert "| 4³ | local |" in text
    assert text in printed


@pytest.mark.gl
def test_gpu_rows_are_timed_or_skipped_with_a_reason(gl_ctx: Any) -> None:
    report = bench_chainmail((4,), repeats=1, ctx=gl_ctx, log=lambda s: None)
    assert report.gl_renderer != "not used"
    for drag, _, _ in DRAGS:
        row = report.find(4, "gpu", drag)
        if row is None:
            assert report.skipped(4, "gpu").startswith("skipped: ")
        else:
            assert row.repeats == 1
            assert row.median_ms > 0


# ---------------------------------------------------------------------- --relax
def test_relax_rows_cover_less_and_agree(gl_ctx: Any) -> None:
    """Oracles: the full relaxation (box of displaced elements) equals the whole-grid
    one; the GPU agrees with the CPU to float32 round-off; local covers fewer elements
    than full, full no more than the whole grid; local differs from full here because
    the earlier drag was relaxed only a few steps."""
    from benchmarks.chainmail_relax import bench_relax, relax_markdown

    report = bench_relax((12,), steps=2, repeats=1, ctx=gl_ctx)
    rows = {(r["backend"], r["mode"]): r for r in report["rows"]}
    assert len(rows) == 6
    for backend in ("cpu", "gpu"):
        grid, full, local = (rows[backend, m] for m in ("grid", "full", "local"))
        assert grid["covered"] == 2 * 2 * 12**3
        assert local["covered"] < full["covered"] <= grid["covered"]
        assert all(r["median_ms"] > 0 for r in (grid, full, local))
    r = rows["cpu", "full"]
    assert r["grid_vs_full_mm"] <= 1e-9
    assert r["gpu_vs_cpu_mm"] <= 1e-4
    assert r["local_vs_full_mm"] > 1e-3
    text = relax_markdown(report, "python -m benchmarks chainmail --relax 2")
    assert "| 12³ | GPU | local |" in text
    assert "Command: `python -m benchmarks chainmail --relax 2`" in text


def test_cli_relax_writes_the_markdown(tmp_path: Path) -> None:
    out = tmp_path / "relax.md"
    args = ["chainmail", "--relax", "1", "--sizes", "6", "--repeats", "1", "--no-gpu"]
    assert main([*args, "--markdown", str(out)]) == 0
    text = out.read_text()
    assert "| 6³ | CPU | whole grid |" in text
    assert "| 6³ | GPU" not in text
