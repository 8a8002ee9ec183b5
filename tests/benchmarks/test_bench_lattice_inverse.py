"""Smoke test of section 3 of ``python -m benchmarks lattice`` (benchmarks.lattice_inverse).

Oracles: one accuracy row per variant of the study in order, each distribution ordered
(median <= 99th percentile <= max) and the default's maximum below its tolerance (the
bound the convergence tests prove out); one render row per variant, the ratio columns
the quotients of the medians they name; the command line's options reach the report.
"""

from __future__ import annotations

import argparse
from typing import Any

import pytest

from benchmarks import lattice_inverse as li
from benchmarks.lattice import add_bench_lattice_parser, command_line
from benchmarks.lattice_inverse import STUDY_VARIANTS
from voxwarp.deform.lattice.warp import DEFAULT_TOLERANCE


@pytest.mark.slow
def test_tiny_section(gl_ctx: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(li, "VOLUME_SIZE", 24)
    monkeypatch.setattr(li, "IMAGE", (32, 24))
    logged: list[str] = []
    report = li.bench_inverse(gl_ctx, trials=4, points=300, frames=1, log=logged.append)
    assert [r["label"] for r in report.accuracy] == [v[0] for v in STUDY_VARIANTS]
    for r in report.accuracy:
        assert r["median"] <= r["p99"] <= r["max"]
    default = next(r for r in report.accuracy if "(default)" in r["label"])
    assert default["max"] < DEFAULT_TOLERANCE
    assert default["unconverged"] == 0
    assert [r.label for r in report.render] == [v[0] for v in li.RENDER_VARIANTS]
    text = "\n".join(report.markdown_lines())
    seed = report.render[0].median_ms
    fixed = report.render[1].median_ms
    last = report.render[-1]
    assert f"| {last.label} | {last.median_ms:.1f} ({last.min_ms:.1f}) |" in text
    assert f"{last.median_ms / seed:.2f}x | {last.median_ms / fixed:.2f}x |" in text
    assert any("(default)" in line for line in logged)


def test_accuracy_only_section() -> None:
    report = li.bench_inverse(None, trials=1, points=100, frames=0, log=lambda s: None)
    assert report.render == []
    assert "Render cost" not in "\n".join(report.markdown_lines())
    text = report.standalone_markdown(
        "python -m benchmarks lattice --inverse-only", "gl", (0.5, 1), 2
    )
    assert text.startswith("Command: `python -m benchmarks lattice --inverse-only`")
    assert "## 3. Lattice over a volume" in text
    assert "## 1." not in text


def test_command_line_options() -> None:
    p = argparse.ArgumentParser(prog="python -m benchmarks")
    bsub = p.add_subparsers(dest="bench")
    add_bench_lattice_parser(bsub)
    args = p.parse_args(["lattice", "--inverse-only", "--inverse-frames", "3"])
    assert args.inverse_only
    assert args.inverse_frames == 3
    assert "--inverse-only" in command_line(args)
    assert "--inverse-frames 3" in command_line(args)
    with pytest.raises(SystemExit):
        p.parse_args(["lattice", "--inverse-frames", "-1"])
