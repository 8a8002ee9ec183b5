"""``voxwarp bench NAME`` for a benchmark that moved to the lab (``benchmarks/``, not
installed): one line naming ``python -m benchmarks NAME``, exit 2, no traceback; the
installed ones (render, slices, interactive) stay."""

from __future__ import annotations

import warnings

import pytest

from voxwarp.cli.bench import MOVED_BENCHMARKS
from voxwarp.cli.main import build_parser, main


@pytest.fixture(autouse=True)
def _keep_warning_state(monkeypatch: pytest.MonkeyPatch) -> None:
    """main() replaces warnings.formatwarning for good; undo it after each test."""
    monkeypatch.setattr(warnings, "formatwarning", warnings.formatwarning)


@pytest.mark.parametrize("name", MOVED_BENCHMARKS)
def test_a_moved_benchmark_names_the_lab(name: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", name, "--quick", "--sizes", "4", "-x", "--json", "a.json"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    (line,) = captured.err.splitlines()
    assert line.startswith("voxwarp: error: ")
    assert f"'python -m benchmarks {name}'" in line
    assert "Traceback" not in captured.err


def test_the_installed_benchmarks_stay() -> None:
    args = build_parser().parse_args(["bench", "render", "--deformed", "--frames", "1"])
    assert args.deformed
    assert args.frames == 1
    for name in ("slices", "interactive"):
        assert build_parser().parse_args(["bench", name]).bench == name
    assert set(MOVED_BENCHMARKS).isdisjoint({"render", "slices", "interactive"})


def test_animate_bench_names_the_lab(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["animate", "scene.json", "--bench"]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert "'python -m benchmarks movie SCENE'" in line


def test_installed_bench_render_times_voxwarp_alone() -> None:
    """``voxwarp bench render --input FILE --deformed``: voxwarp's rows, then dvr through a
    settled mass-spring offset field on the same volume; no VTK (the lab's ``python -m
    benchmarks render`` adds it). In a subprocess: it makes its own GL context."""
    from tests.run_cli import run_cli

    argv = ["bench", "render", "--input", "sample:colin27", "--tf", "mri", "--size", "48x48"]
    proc = run_cli(*argv, "--frames", "1", "--warmup", "1", "--deformed", timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "Volume: colin27 91x109x91" in proc.stdout
    assert "| voxwarp | dvr |" in proc.stdout
    assert "| voxwarp, no skipping | dvr |" in proc.stdout
    assert "VTK" not in proc.stdout + proc.stderr
    assert "| offset warp, baked |" in proc.stdout
    assert "deformed dvr (offset warp, baked inverse) costs" in proc.stdout
