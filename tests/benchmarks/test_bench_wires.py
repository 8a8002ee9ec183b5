"""Smoke tests of ``python -m benchmarks wires`` (benchmarks.wires) on a small configuration.

Oracles: every ratio in the report is the quotient of the two times it names; voxel and
sample counts split exactly into identity / vacated / swept and the % ignored is their
share; the report has a row per requested scale, camera and layout, and every target
line appears in the markdown; the reference warp (zero offset field) renders the
undeformed image while the wires change it; rays leave through their pixel centres
(camera.project) and march ceil(L / step - 1/2) samples through a box of depth L.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from benchmarks import wires as bw
from benchmarks.wires import (
    CAMERAS,
    LAYOUTS,
    REFERENCE_LAYOUT,
    WireBenchReport,
    add_bench_wires_parser,
    bench_wires,
    camera_rays,
    check_scales,
    padded_fish,
    ray_sample_stats,
)
from voxwarp.core.camera import Camera


@pytest.fixture(scope="module")
def small_fish() -> Any:
    """The fish at 64x32x27 padded with air to 64³ (the bench volume, 4x coarser)."""
    return padded_fish((64, 32, 27), 64)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m benchmarks")
    bsub = p.add_subparsers(dest="bench", required=True)
    add_bench_wires_parser(bsub)
    return p


def _small_phantom(tmp_path: Path) -> Path:
    spec = json.loads(bw.FISH_WIRES.read_text())
    path = tmp_path / "small_fish_wires.json"
    path.write_text(json.dumps({**spec, "sample": "fish"}))
    return path


def _check_report_invariants(report: WireBenchReport) -> None:
    for b in report.builds:
        assert 0 < b.min_s <= b.median_s
        assert set(b.stages) == set(bw.STAGES)
        assert all(v >= 0 for v in b.stages.values())
        assert b.voxels == math.prod(b.field_shape)
        assert b.swept + b.vacated + b.ignored == b.voxels
        assert 0 <= b.percent_ignored <= 100
        assert b.percent_ignored == pytest.approx(100 * b.ignored / b.voxels)
        assert b.swept > 0
    for p in report.propagation:
        assert p.scipy_s > 0
        assert p.seeds > 0
        if p.opencl_s is not None:
            assert p.opencl_s > 0
            assert p.speedup == pytest.approx(p.scipy_s / p.opencl_s)
            assert p.agree is True
        else:
            assert p.speedup is None
            assert "OpenCL" in p.note
    for s in report.stats:
        assert s.samples == s.identity + s.vacated + s.swept > 0
        assert 0 <= s.percent_ignored <= 100
        assert s.percent_ignored == pytest.approx(100 * s.ignored / s.samples)
        assert s.ignored == s.identity
        assert s.rays == math.ceil(s.size[0] / s.subsample) * math.ceil(s.size[1] / s.subsample)
        assert 0 < s.rays_hitting <= s.rays


@pytest.mark.slow
def test_small_run_with_render(small_fish: Any, gl_ctx: Any, tmp_path: Path) -> None:
    missing = tmp_path / "no_such_wires.json"
    phantom = _small_phantom(tmp_path)
    report = bench_wires(
        small_fish,
        scales=(4, 2),
        repeats=1,
        frames=1,
        sizes=((64, 32),),
        tfs=("ct-bone",),
        full_grid=32,
        phantoms=(("missing", missing, {}), ("small fish", phantom, {"shape": (48, 24, 20)})),
        ctx=gl_ctx,
        log=lambda s: None,
    )
    _check_report_invariants(report)
    assert report.gl_renderer not in ("", "not used")
    # one float row per requested scale (ascending) + the packed row at the render scale
    assert [(b.scale, b.layout) for b in report.builds] == [
        (2, "float"),
        (4, "float"),
        (2, "packed"),
    ]
    # scale 1 not run: the propagation used the finest grid run, and says so
    assert report.propagation[0].grid.startswith("1:8 ")
    assert report.propagation[1].shape == (32, 32, 32)
    assert any("Scale 1 was not run" in n for n in report.notes)
    # a row per camera and layout, plus the reference warp per camera
    rows = [(r.camera, r.layout) for r in report.renders]
    assert rows == [(c, la) for c in CAMERAS for la in (*LAYOUTS, REFERENCE_LAYOUT)]
    for r in report.renders:
        assert r.frames == 1
        assert 0 < r.min_ms <= r.median_ms
        assert 0 < r.undeformed_min_ms <= r.undeformed_median_ms
        assert r.ratio == pytest.approx(r.median_ms / r.undeformed_median_ms)
        assert r.skip_kind == "cells"
        if r.reference:
            assert r.first_ms is None
            assert r.changed_pixels < 1.0  # the undeformed image, through the warped path
        else:
            assert r.first_ms > 0
            assert r.second_ms > 0
            assert r.changed_pixels > 0.5  # the wire bends the fish
    assert [s.camera for s in report.stats] == list(CAMERAS)
    assert all(s.swept > 0 for s in report.stats)
    # Tables 2-3: the bench volume per layout (from sections 1 and 3), then the phantoms
    fish = report.phantoms[:2]
    assert [p.layout for p in fish] == list(LAYOUTS)
    for p, layout in zip(fish, LAYOUTS, strict=True):
        r = report.render_row((64, 32), "ct-bone", layout, "framed")
        b = report.build(2, layout)
        assert r is not None
        assert b is not None
        assert (p.build_s, p.first_ms, p.frame_ms) == (b.median_s, r.first_ms, r.median_ms)
        assert p.total_s == pytest.approx(b.median_s + r.first_ms / 1000)
    skipped, small = report.phantoms[2:]
    assert skipped.build_s is None
    assert skipped.total_s is None
    assert "does not exist" in skipped.note
    assert small.volume_shape == (48, 24, 20)
    assert small.build_s > 0
    assert small.first_ms > 0
    assert small.frame_ms > 0
    assert small.total_s == pytest.approx(small.build_s + small.first_ms / 1000)

    text = report.markdown("python -m benchmarks wires --scales 2,4")
    assert text.startswith("Command: `python -m benchmarks wires --scales 2,4`")
    lines = report.target_lines()
    # builds at 1:8 and 1:1, the two propagation grids, one per camera x layout
    assert len(lines) == 2 + 2 + len(CAMERAS) * len(LAYOUTS)
    for line in lines:
        assert f"* {line}" in text
        assert line.endswith(("PASS", "FAIL")) or "NOT MEASURED" in line
    assert "field build at 1:1 (scale 1, float layout) <= 2 s: not measured" in text
    verdict = "PASS" if report.build(2).median_s <= 0.25 else "FAIL"  # type: ignore[union-attr]
    assert any(ln.startswith("Target: field build at 1:8") and verdict in ln for ln in lines)
    for heading in ("## 1.", "## 2.", "## 3.", "## 4.", "## 5."):
        assert heading in text
    assert "| 64x32 | framed | ct-bone | packed |" in text
    assert "| small fish |" in text


def test_no_render_still_reports_everything_else(small_fish: Any) -> None:
    report = bench_wires(
        small_fish,
        scales=(8,),
        repeats=2,
        frames=1,
        sizes=((32, 16),),
        tfs=("ct-soft",),
        cameras=("framed",),
        render=False,
        full_grid=0,
        phantoms=(),
        log=lambda s: None,
    )
    _check_report_invariants(report)
    assert report.renders == []
    assert report.render_skipped == "--no-render"
    assert report.builds[0].repeats == 2
    assert len(report.propagation) == 1
    text = report.markdown("python -m benchmarks wires --scales 8 --no-render")
    assert "Target: deformed dvr <= 1.5x the undeformed dvr: not measured -> NOT MEASURED" in text
    assert "Not run: --no-render." in text
    assert [(p.layout, p.first_ms) for p in report.phantoms] == [(la, None) for la in LAYOUTS]


def test_bad_options_are_rejected(capsys: pytest.CaptureFixture) -> None:
    parser = _parser()
    for bad in (["--scales", "3"], ["--scales", "2,x"], ["--size", "512"], ["--repeats", "0"]):
        with pytest.raises(SystemExit) as exc:
            parser.parse_args(["wires", *bad])
        assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "field scales must be among 1, 2, 4, 8, 16; got 3" in err
    assert "size must look like 512x512" in err
    assert "expected a positive integer; got '0'" in err
    with pytest.raises(ValueError, match="among 1, 2, 4, 8, 16"):
        check_scales([2, 3])
    with pytest.raises(ValueError, match="among 1, 2, 4, 8, 16"):
        bench_wires(None, scales=(32,), log=lambda s: None)
    with pytest.raises(ValueError, match="cameras must be among"):
        bench_wires(None, cameras=("top",), log=lambda s: None)
    args = parser.parse_args(["wires"])
    assert args.scales == (1, 2, 4, 8, 16)
    assert (args.repeats, args.frames, args.size, args.no_render) == (3, 5, None, False)
    assert args.func is bw.cmd_bench_wires
    args = parser.parse_args(["wires", "--scales", "4,2,4", "--size", "64x32"])
    assert args.scales == (4, 2)
    assert args.size == [(64, 32)]


def test_cli_writes_the_markdown(
    small_fish: Any, tmp_path: Path, capsys: pytest.CaptureFixture, monkeypatch: Any
) -> None:
    real = bw.bench_wires

    def small(**kw: Any) -> WireBenchReport:
        return real(small_fish, **kw, full_grid=0, phantoms=())

    monkeypatch.setattr(bw, "bench_wires", small)
    monkeypatch.setattr(sys, "argv", ["pytest"])
    out = tmp_path / "bench.md"
    argv = ["wires", "--scales", "4", "--repeats", "1", "--camera", "framed"]
    argv.append("--no-render")
    args = _parser().parse_args([*argv, "--markdown", str(out)])
    assert args.func(args) == 0
    printed = capsys.readouterr()
    text = out.read_text()
    assert text in printed.out
    assert text.startswith(f"Command: `python -m benchmarks {' '.join(argv)} --markdown {out}`")
    assert "| 4 | 1:64 |" in text
    assert "build 1:64" in printed.err  # progress goes to stderr
    assert "| 32x16 | framed |" not in text  # default size 512x256
    assert "| 512x256 | framed | 8192 |" in text  # ray statistics, framed camera only
    assert "| 512x256 | bench |" not in text


def test_cli_main_knows_bench_wires() -> None:
    from benchmarks.__main__ import build_parser

    args = build_parser().parse_args(["wires", "--scales", "2"])
    assert args.func is bw.cmd_bench_wires


def test_rays_pass_through_their_pixel_centres() -> None:
    cam = Camera.fit((0, 0, 0), (40, 20, 10), view=(-90.0, 45.0), fov=30.0, zoom=1.3)
    size = (40, 20)
    ro, rd, t_far = camera_rays(cam, size, subsample=4)
    assert ro.shape == rd.shape == (50, 3)
    np.testing.assert_allclose(np.linalg.norm(rd, axis=1), 1.0)
    px, py = np.meshgrid(np.arange(0, 40, 4) + 0.5, np.arange(0, 20, 4) + 0.5, indexing="xy")
    # gl_FragCoord counts rows from the bottom, camera.project from the top
    expected = np.stack([px.ravel(), size[1] - py.ravel()], axis=1)
    for t in (1.0, 50.0):
        np.testing.assert_allclose(cam.project(ro + t * rd, size), expected, atol=1e-6)
    near, far = cam.near_far()
    assert np.all((t_far > far - near - 1e-6) & (t_far < 2 * far))


class _Field:
    lo = np.array([-100.0, -100.0, -100.0])
    spacing = np.array([1.0, 1.0, 1.0])
    shape = (200, 200, 200)


class _HalfSwept:
    """Samples with x > 5 swept, 2 < x <= 5 vacated, the rest identity."""

    field = _Field()

    def _lookup(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        state = np.where(p[:, 0] > 5, 2, np.where(p[:, 0] > 2, 1, 0)).astype(np.uint8)
        return state, np.zeros(len(p), dtype=np.int64), np.zeros(len(p))


class _Box:
    sample_distance_mm = 0.7

    def ray_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return np.array([0.0, 0.0, 0.0]), np.array([10.0, 10.0, 6.0])


def test_ray_samples_are_counted_on_the_lattice() -> None:
    # orthographic from +z: every ray through the box crosses its whole depth of 6 mm
    cam = Camera.fit((0, 0, 0), (10, 10, 6), view="+z", projection="orthographic")
    stats = ray_sample_stats(_Box(), cam, (64, 64), _HalfSwept(), subsample=2, chunk=500)
    per_ray = math.ceil(6.0 / 0.7 - 0.5)
    assert stats.rays == 32 * 32
    assert stats.samples == stats.rays_hitting * per_ray
    ro, _, _ = camera_rays(cam, (64, 64), 2)
    hit = np.all((ro[:, :2] >= 0) & (ro[:, :2] <= 10), axis=1)
    assert stats.rays_hitting == int(hit.sum())
    x = ro[hit, 0]
    assert stats.swept == int((x > 5).sum()) * per_ray
    assert stats.vacated == int(((x > 2) & (x <= 5)).sum()) * per_ray
    assert stats.identity == stats.samples - stats.swept - stats.vacated
    assert stats.outside_field == 0
    assert stats.percent_not_swept == pytest.approx(
        100 * (stats.samples - stats.swept) / stats.samples
    )


def test_bench_curve_speed_times_evaluation_and_closest_points() -> None:
    """The curve measurement that replaced the wall-clock assert of test_curves.py."""
    out = bw.bench_curve_speed(parameters=5000, points=500, repeats=2)
    assert out["parameters"] == 5000
    assert out["points"] == 500
    for key in ("evaluate_derivative_s", "closest_point_s"):
        assert 0.0 < out[key] < 60.0
