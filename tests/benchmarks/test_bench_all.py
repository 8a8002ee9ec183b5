"""Tests of ``python -m benchmarks all`` (benchmarks.all) on fake benchmark runners, of the
hardware probe and of the dense ``bench render`` case; no real benchmark runs here."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from benchmarks import all as bench_all
from benchmarks import hardware
from benchmarks.__main__ import build_parser, main

FAKE_HW = {"gl": {"renderer": "fake GL", "version": "4.5"}, "opencl": "pyopencl not installed"}


def test_parser() -> None:
    args = build_parser().parse_args(["all", "--quick", "--json", "a.json", "--markdown", "b.md"])
    assert args.quick
    assert args.json == "a.json"
    assert args.markdown == "b.md"
    assert args.func is bench_all.cmd_bench_all
    assert args.only is None
    assert not args.in_process
    args = build_parser().parse_args(["all", "--only", "render,scale"])
    assert args.only == ("render", "scale")
    assert not args.quick


def test_parser_rejects_unknown_benchmark(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["all", "--only", "render,nope"])
    assert exc.value.code == 2
    assert "unknown benchmark nope" in capsys.readouterr().err


def _fake(runs: list[tuple[str, bool]]) -> Any:
    def ok(quick: bool) -> dict[str, Any]:
        runs.append(("startup", quick))
        return {
            "ratios": {"voxwarp --help / python": 4.2},
            "issue": {"startup": "0.90 s (median of 2)"},
            "markdown": "| fake | table |",
        }

    def boom(quick: bool) -> dict[str, Any]:
        runs.append(("render", quick))
        raise RuntimeError("no volume here\nsecond line never shown")

    return ok, boom


def test_fake_run_writes_json_and_markdown(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """One benchmark ok, one failing: both outputs say so, the exit status is 0."""
    runs: list[tuple[str, bool]] = []
    ok, boom = _fake(runs)
    monkeypatch.setattr(bench_all, "RUNNERS", {"startup": ok, "render": boom})
    monkeypatch.setattr(hardware, "probe_hardware", lambda: dict(FAKE_HW))
    js, md = tmp_path / "out.json", tmp_path / "out.md"
    argv = ["all", "--quick", "--in-process", "--only", "startup,render"]
    rc = main([*argv, "--json", str(js), "--markdown", str(md)])
    assert rc == 0
    assert runs == [("startup", True), ("render", True)]
    data = json.loads(js.read_text())
    assert data["quick"] is True
    assert data["hardware"]["gl"]["renderer"] == "fake GL"
    recs = {r["name"]: r for r in data["benchmarks"]}
    assert recs["startup"]["status"] == "ok"
    assert recs["startup"]["ratios"] == {"voxwarp --help / python": 4.2}
    assert recs["render"]["status"] == "failed"
    assert recs["render"]["error"] == "RuntimeError: no volume here"
    text = md.read_text()
    assert capsys.readouterr().out.strip() == text.strip()  # printed and written alike
    assert "GL: fake GL (OpenGL 4.5)" in text
    assert "1 of 2 benchmarks ran" in text
    assert "| `voxwarp render sample:stent -o x.png` end to end | 0.90 s (median of 2) |" in text
    assert "| startup |" in text  # the benchmark that measured the row
    assert "**failed**: RuntimeError: no volume here" in text
    assert "second line" not in text
    # every row of the issue's table is there, measured or not
    assert text.count("not measured by bench all") == len(bench_all.ISSUE_ROWS) - 1


def test_all_failing_exits_nonzero(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _, boom = _fake([])
    monkeypatch.setattr(bench_all, "RUNNERS", {"render": boom})
    monkeypatch.setattr(hardware, "probe_hardware", lambda: dict(FAKE_HW))
    js = tmp_path / "out.json"
    rc = main(["all", "--in-process", "--only", "render", "--json", str(js)])
    assert rc == 1
    assert json.loads(js.read_text())["benchmarks"][0]["status"] == "failed"


def test_subprocess_timeout_is_a_failed_record() -> None:
    rec = bench_all.run_subprocess("startup", True, timeout_s=0.05)
    assert rec.status == "failed"
    assert rec.error.startswith("timed out")


def test_hardware_probe_names_the_gl_renderer(gl_ctx: Any) -> None:
    """The probe's own standalone context reports the renderer the tests' context has."""
    info = hardware.gl_info()
    assert info["renderer"] == str(gl_ctx.info["GL_RENDERER"])
    assert info["version"]
    lines = hardware.hardware_lines(hardware.probe_hardware())
    assert lines[0].startswith(f"GL: {info['renderer']}")
    assert any(line.startswith("CPU: ") and "cores" in line for line in lines)


def test_body_phantom_tissues() -> None:
    """The dense case: air outside, fat, soft tissue, spine at their HU values."""
    from voxwarp.bench.render import body_phantom

    vol = body_phantom((64, 64, 24), noise=0.0)
    d = vol.data
    assert d.dtype == np.int16
    assert d.shape == (64, 64, 24)
    assert d[0, 0, 5] == -1000  # outside the body
    assert d[32, 40, 5] == 40  # soft tissue, anterior of the centre
    assert d[32, 21, 5] == 700  # spine, posterior
    assert (d == -100).any()  # the fat layer
    # noise keeps the tissues near their values
    noisy = body_phantom((64, 64, 24), noise=10.0).data
    assert abs(float(noisy[28:36, 36:44, :].mean()) - 40.0) < 3.0


def test_bench_render_input_file() -> None:
    """``python -m benchmarks render --input FILE --tf --view``: one case, its covered
    share, and the VTK rows skipped with a note (not a failure) where VTK is not installed.
    In a subprocess from the checkout's root: the command makes and releases its own GL
    context."""
    from benchmarks import vtk as bench_vtk
    from tests.run_cli import REPO

    argv = ["render", "--input", "sample:colin27", "--tf", "mri", "--view=-y"]
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "benchmarks",
            *argv,
            "--size",
            "64x64",
            "--frames",
            "1",
            "--warmup",
            "1",
        ],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        timeout=300,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert "Volume: colin27 91x109x91" in out
    covered = float(out.split("dvr covers ")[1].split(" %")[0])
    assert 10.0 < covered < 100.0  # the head is in the picture, not all of it
    assert "| voxwarp | dvr |" in out
    assert "| voxwarp, gradients on the fly | dvr |" in out  # the mri preset shades
    if not bench_vtk.vtk_available():
        assert "VTK not installed" in proc.stderr


def test_missing_vtk_is_a_note_not_a_failure(monkeypatch: pytest.MonkeyPatch) -> None:
    from benchmarks import render
    from benchmarks import vtk as bench_vtk

    monkeypatch.setattr(bench_vtk, "vtk_available", lambda: False)
    report = render.BenchReport("v", (8, 8, 8), (8, 8), 1.0, 1, "gl")
    logs: list[str] = []
    render.vtk_rows(report, None, {}, None, (8, 8), 1, 0, logs.append)  # type: ignore[arg-type]
    assert [r.renderer for r in report.rows] == ["VTK fixed-point (CPU)", "VTK GPU raycaster"]
    assert all(r.note.startswith("skipped: VTK not installed") for r in report.rows)
    assert logs[0].startswith("VTK not installed")
    assert report.ratio("VTK fixed-point (CPU)", "dvr") is None
