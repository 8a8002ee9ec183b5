"""python -m benchmarks startup: the report and its oracle (no heavy module at start-up, no
unused reader or mesh module in ``voxwarp render sample:stent``)."""

from __future__ import annotations

from benchmarks.__main__ import build_parser
from benchmarks.startup import (
    CASES,
    HEAVY,
    RENDER_CASE,
    RENDER_UNUSED,
    StartupRow,
    bench_startup,
    markdown,
)


def test_one_run_loads_no_heavy_module() -> None:
    cases = {k: v for k, v in CASES.items() if k != RENDER_CASE}
    rows = bench_startup(repeats=1, cases=cases)
    assert [r.label for r in rows] == list(cases)
    assert all(r.seconds > 0 and r.cpu_seconds is not None for r in rows)
    assert {r.label: r.heavy for r in rows} == {label: [] for label in cases}


def test_stent_render_loads_none_of_the_modules_it_does_not_use() -> None:
    """The whole ``voxwarp render sample:stent -o x.png`` in a fresh interpreter (it must
    succeed) loads no mesh library, volume reader, OpenCL, Qt, dask or matplotlib."""
    ref = next(iter(CASES))
    rows = bench_startup(repeats=1, cases={ref: CASES[ref], RENDER_CASE: CASES[RENDER_CASE]})
    loaded = set(rows[1].heavy)
    assert loaded <= set(HEAVY) | set(RENDER_UNUSED)  # what the probe reports
    assert not loaded & set(RENDER_UNUSED), sorted(loaded & set(RENDER_UNUSED))
    assert rows[1].seconds > rows[0].seconds


def test_report_gives_ratios_to_the_reference() -> None:
    rows = [StartupRow("ref", 0.05, [], 0.04), StartupRow("help", 0.15, ["scipy"])]
    text = markdown(rows, "python -m benchmarks startup")
    assert "| ref | 50 | 1.00x | none | 40 |" in text
    assert "| help | 150 | 3.00x | scipy | — |" in text


def test_command_is_registered_without_heavy_benchmarks() -> None:
    args = build_parser().parse_args(["startup", "--repeats", "2"])
    assert (args.repeats, args.func.__name__) == (2, "cmd_bench_startup")
