"""``voxwarp bench detj``: the report's structure and its command line (timings are
not asserted, only that every case ran and the ratio is with / without)."""

from __future__ import annotations

import pytest

from benchmarks import all as bench_all
from voxwarp.bench.detj import bench_detj
from voxwarp.cli.main import main


@pytest.mark.slow
def test_bench_detj_times_each_view_with_and_without() -> None:
    report = bench_detj(volumes=("colin27",), sizes=(32,), rounds=1, deformations=("wires",))
    assert [r.view for r in report.rows] == ["3D dvr", "3D mip", "slice (axial)"]
    for r in report.rows:
        assert min(r.plain_ms, r.overlay_ms) > 0
        assert r.ratio == pytest.approx(r.overlay_ms / r.plain_ms)
    text = report.markdown("voxwarp bench detj --sizes 32")
    assert "`voxwarp bench detj --sizes 32`" in text
    assert text.count("\n| colin27 | wires | 32² |") == 3


def test_bench_detj_is_registered() -> None:
    assert "detj" in bench_all.BENCHMARKS
    assert "detj" in bench_all.RUNNERS
    with pytest.raises(SystemExit) as info:
        main(["bench", "detj", "--volumes", "brain"])
    assert info.value.code == 2
