"""``bench_warp_render``: the deformed-vs-undeformed DVR benchmark runs and reports sanely.

No timing assertions (benchmarks measure, tests check): the rows exist, times are
positive and finite, ratios are relative to the undeformed row, and the markdown names
the command.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from voxwarp.core.transfer_function import TransferFunction
from voxwarp.core.volume import Volume

pytestmark = pytest.mark.gl


def _volume() -> Volume:
    g = np.indices((24, 24, 24)).transpose(1, 2, 3, 0) - 11.5
    data = 200.0 * np.exp(-np.sum(g**2, axis=-1) / 40.0)
    return Volume(data.astype(np.uint8), spacing=(1.0, 1.0, 1.5), name="blob")


def test_bench_warp_render_reports_every_row() -> None:
    from voxwarp.bench.render import bench_warp_render

    tf = TransferFunction([(0, 0, 0, 0, 0), (40, 1, 0.5, 0.2, 0.0), (255, 1, 1, 1, 0.8)])
    lines: list[str] = []
    report = bench_warp_render(
        _volume(),
        size=(48, 48),
        frames=1,
        warmup=1,
        grid=5,
        transfer_function=tf,
        log=lines.append,
    )
    names = [r.renderer for r in report.rows]
    assert names[0] == "undeformed"
    assert {"offset warp, approx", "offset warp, baked", "offset warp, exact"} <= set(names)
    assert all(math.isfinite(r.median_ms) and r.median_ms > 0 for r in report.rows)
    assert report.ratio("undeformed") == pytest.approx(1.0)
    baked = report.ratio("offset warp, baked")
    assert baked is not None
    assert baked > 0
    assert report.max_displacement_mm > 0.5 * report.drag_mm  # the drag really moved it
    text = report.markdown("voxwarp bench massspring --sizes 3")
    assert text.startswith("Command: `voxwarp bench massspring --sizes 3`")
    assert text.count("\n| ") == len(report.rows) + 1
    assert len(lines) == len(report.rows)


def test_bench_warp_render_margin_row() -> None:
    """``margin``: one more row, the baked warp on the padded grid, timed in the same run."""
    from voxwarp.bench.render import bench_warp_render

    tf = TransferFunction([(0, 0, 0, 0, 0), (40, 1, 0.5, 0.2, 0.0), (255, 1, 1, 1, 0.8)])
    only = ("undeformed", "offset warp, baked", "offset warp, baked, margin 6 mm")
    report = bench_warp_render(
        _volume(), size=(48, 48), frames=1, warmup=1, grid=5, transfer_function=tf,
        only=only, margin=6.0, log=str,
    )  # fmt: skip
    assert [r.renderer for r in report.rows] == list(only)
    ratio = report.ratio("offset warp, baked, margin 6 mm")
    assert ratio is not None
    assert ratio > 0


def test_bench_grid_margin_needs_deformed(capsys: pytest.CaptureFixture) -> None:
    from voxwarp.cli.main import main

    assert main(["bench", "render", "--grid-margin", "10", "--frames", "1"]) == 2
    err = capsys.readouterr().err
    assert "--grid-margin times the deformed render: add --deformed" in err
    assert err.count("\n") == 1
