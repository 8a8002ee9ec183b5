"""``voxwarp bench slices``: the report's structure and its command line (timings are
not asserted)."""

from __future__ import annotations

import pytest

from benchmarks import all as bench_all
from voxwarp.bench.slices import bench_slices
from voxwarp.cli.main import main


def test_bench_slices_times_every_case_against_the_3d_frame() -> None:
    report = bench_slices(volumes=("colin27",), sizes=(32,), rounds=1)
    assert [r.deformation for r in report.rows] == ["undeformed", "mass-spring", "wires"]
    for r in report.rows:
        assert r.size == 32
        assert min(r.frame_ms, r.slice_ms, r.slab_ms, r.values_ms) > 0
        assert r.slice_ratio == pytest.approx(r.slice_ms / r.frame_ms)
    assert report.ratio("colin27", "wires", 32) == report.rows[2].slice_ratio
    assert report.ratio("stent", "wires", 32) is None
    (drag,) = report.drags
    assert min(drag.frame_ms, drag.drag_slices_ms, drag.drag_frame_ms, drag.step_ms) > 0
    text = report.markdown("voxwarp bench slices --sizes 32")
    assert "`voxwarp bench slices --sizes 32`" in text
    assert "| colin27 | mass-spring | 32² |" in text
    assert text.count("\n| colin27 |") == 4  # three deformations and the drag


def test_bench_slices_is_registered() -> None:
    assert "slices" in bench_all.BENCHMARKS
    assert "slices" in bench_all.RUNNERS
    with pytest.raises(SystemExit) as info:
        main(["bench", "slices", "--volumes", "brain"])
    assert info.value.code == 2
