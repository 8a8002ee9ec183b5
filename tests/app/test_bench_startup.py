"""voxwarp bench startup: the report and its oracle (no heavy module at start-up)."""

from __future__ import annotations

from voxwarp.bench.startup import CASES, StartupRow, bench_startup, markdown
from voxwarp.cli.main import build_parser


def test_one_run_loads_no_heavy_module() -> None:
    rows = bench_startup(repeats=1)
    assert [r.label for r in rows] == list(CASES)
    assert all(r.seconds > 0 for r in rows)
    assert {r.label: r.heavy for r in rows} == {label: [] for label in CASES}


def test_report_gives_ratios_to_the_reference() -> None:
    rows = [StartupRow("ref", 0.05, []), StartupRow("help", 0.15, ["scipy"])]
    text = markdown(rows, "voxwarp bench startup")
    assert "| ref | 50 | 1.00x | none |" in text
    assert "| help | 150 | 3.00x | scipy |" in text


def test_command_is_registered_without_heavy_benchmarks() -> None:
    args = build_parser(bench=False).parse_args(["bench", "startup", "--repeats", "2"])
    assert (args.repeats, args.func.__name__) == (2, "cmd_bench_startup")
