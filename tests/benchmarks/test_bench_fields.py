"""``python -m benchmarks fields --quick``: the report's rows and sane values (timings are not
compared against targets: the machine is shared)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.__main__ import main
from benchmarks.fields import bench_fields, quick_volume, smooth_field


def test_smooth_field_covers_the_volume_with_the_asked_amplitude() -> None:
    vol = quick_volume()
    w = smooth_field(vol, 8, amplitude_mm=2.5, angle_deg=5.0)
    assert w.shape == (8, 8, 8)
    assert w.max_displacement() == pytest.approx(2.5, rel=1e-3)
    lo, hi = vol.bounds
    corners = np.array([[i, j, k] for i in (0, 7) for j in (0, 7) for k in (0, 7)], float)
    world = corners @ w.affine[:3, :3].T + w.affine[:3, 3]
    assert np.all(world.min(0) < lo)
    assert np.all(world.max(0) > hi)
    # the grid is rotated about z: its i axis is not the world x axis
    axis = w.affine[:3, 0] / np.linalg.norm(w.affine[:3, 0])
    assert math.degrees(math.acos(axis[0])) == pytest.approx(5.0, abs=1e-6)


def test_bench_fields_quick_report_has_every_row() -> None:
    report = bench_fields(quick_volume(), nodes=(4, 8), size=(48, 48), frames=1, log=None)
    names = [(r.name, r.mode) for r in report.frame_rows]
    assert names == [(n, m) for m in ("dvr", "mip") for n in ("undeformed", "field 4³", "field 8³")]
    for row in report.frame_rows:
        assert row.median_ms > 0
        assert math.isfinite(row.median_ms)
        if row.name != "undeformed":
            ratio = report.ratio(row.name, row.mode)
            assert ratio is not None
            assert ratio > 0
            assert math.isfinite(ratio)
            assert row.first_ms > 0
    assert [r.field for r in report.resample_rows] == ["field 4³", "field 8³"]
    for r in report.resample_rows:
        assert r.resample_s > 0
        assert r.first_frame_ms > 0
        ratio = report.resample_ratio(r)
        assert ratio is not None
        assert ratio > 0
        assert math.isfinite(ratio)
        # 8³ or 4³ float64 vectors + the 32³ float32 resampled volume
        nodes = int(r.field.split()[1][:-1])
        assert r.extra_mib == pytest.approx((nodes**3 * 24 + 32**3 * 4) / 2**20)
        assert r.texture_mib == pytest.approx(nodes**3 * 8 / 2**20)
    steps = [e.step for e in report.export_rows]
    assert steps == ["sample the chain on the 32x32x32 grid", "write .nii.gz", "write .nrrd"]
    assert all(e.seconds > 0 for e in report.export_rows)
    assert all(e.mib > 0 for e in report.export_rows[1:])
    text = report.markdown("python -m benchmarks fields --quick")
    assert "`python -m benchmarks fields --quick`" in text
    assert "| field 8³ | mip |" in text
    assert "| write .nrrd |" in text


def test_cli_bench_fields_quick_writes_markdown(tmp_path, capsys) -> None:
    out = tmp_path / "fields.md"
    assert main(["fields", "--quick", "--no-resample", "--markdown", str(out)]) == 0
    text = out.read_text()
    assert "| undeformed | dvr |" in text
    assert "| write .nii.gz |" in text
    assert "resample instead" in text
    assert "| field 4³ | 0.00 |" not in text
    assert "field 8³ dvr:" in capsys.readouterr().out
