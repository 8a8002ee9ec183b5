"""Tests of ``python -m benchmarks costs`` (the cost table, before vs after) and of
``python -m benchmarks readme`` (the README paragraph written from its JSON).

The harness itself runs once, in its quick mode, against HEAD exported as the "before"
tree; the rest checks its parts on fakes: the tree shim, the interleaving, the table and
the paragraph."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from benchmarks import ROOT, costs_readme, costs_table, costs_tree, costs_worker
from benchmarks import costs as bench_costs
from benchmarks.__main__ import build_parser

#: keys that may be 0 in the quick mode: a 32³ array's peak memory rounds to no pages
MAY_BE_ZERO = {"memory"}


def _fields(template: str) -> set[str]:
    import string

    return {name for _, name, _, _ in string.Formatter().parse(template) if name}


# ---------------------------------------------------------------------- the harness
@pytest.mark.slow
def test_quick_run_measures_every_line_before_and_after(tmp_path: Path) -> None:
    out, md = tmp_path / "run.json", tmp_path / "table.md"
    cmd = [sys.executable, "-m", "benchmarks", "costs", "--quick", "--before", "HEAD"]
    cmd += ["--volume", "sample:colin27", "--json", str(out), "--markdown-out", str(md)]
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=900, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    run = json.loads(out.read_text())
    before, after = run["revisions"]
    assert (before["label"], after["label"]) == ("before", "after")
    # the before worker imported the exported tree, not the checkout
    assert Path(after["voxwarp"]) == ROOT / "app"
    assert Path(before["voxwarp"]).name == "app"
    assert ROOT not in Path(before["voxwarp"]).parents
    vtk_missing = _vtk_missing()
    lines = {(r["line"], r["volume"]) for r in run["rows"]}
    for line in costs_table.LINES:
        assert (line.key, "sample:colin27" if line.per_volume else None) in lines
    for row in run["rows"]:
        line = next(ln for ln in costs_table.LINES if ln.key == row["line"])
        for label in ("before", "after"):
            result = row["results"][label]
            if line.key == "vtk_per_pixel" and vtk_missing:
                assert "VTK is not installed" in result["error"]
                continue
            assert not result["error"], (line.key, label, result["error"])
            median = result["median"]
            assert _fields(line.template + line.extra) <= median.keys(), line.key
            for key, value in median.items():
                assert math.isfinite(value), (line.key, key)
                assert value > 0 or (key in MAY_BE_ZERO and value == 0), (line.key, key, value)
    table = md.read_text()
    assert table.strip() == proc.stdout.strip()
    assert f"before (`{before['commit'][:10]}`)" in table
    assert table.count("\n| ") == 1 + len(run["rows"])  # the header and one line a row


def _vtk_missing() -> bool:
    import importlib.util

    return importlib.util.find_spec("vtk") is None


def test_parser_defaults() -> None:
    args = build_parser().parse_args(["costs"])
    assert args.func is bench_costs.cmd_bench_costs
    assert args.volume is None
    assert args.before == ""  # the merge base with main
    assert args.repeats is None
    args = build_parser().parse_args(["costs", "--volume", "a.nii", "--volume", "b.nii"])
    assert args.volume == ["a.nii", "b.nii"]


def test_bad_revision_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    from benchmarks.__main__ import main

    assert main(["costs", "--before", "no-such-rev-xyz", "--volume", "sample:fish"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("benchmarks: error: --before no-such-rev-xyz: no such git revision")
    assert "\n" not in err


def test_bad_volume_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    from benchmarks.__main__ import main

    assert main(["costs", "--before", "none", "--volume", "sample:nope"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("benchmarks: error:")
    assert "nope" in err
    assert "\n" not in err


def test_bad_transfer_function_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    from benchmarks.__main__ import main

    assert main(["costs", "--before", "none", "--volume", "sample:fish", "--tf", "ct-sofft"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("benchmarks: error:")
    assert "ct-sofft" in err
    assert "\n" not in err


def test_the_labs_transfer_function_replaces_every_default() -> None:
    from benchmarks.costs_measure import Lab

    assert Lab(True, transfer_function="ct-soft").volume("sample:stent")[1] == "ct-soft"
    own = Lab(True).volume("sample:stent")[1]
    assert own is not None  # the sample's suggested one
    assert own != "ct-soft"
    note = costs_table.markdown({**_fake_run(), "transfer_function": "ct-soft"})
    assert "512x512 dvr with transfer function ct-soft;" in note
    assert "transfer function" not in costs_table.markdown(_fake_run()).split("\n")[2]


# ---------------------------------------------------------------------- the tree shim
def _fake_tree(root: Path, package_dir: str) -> Path:
    (root / "src").mkdir(parents=True)
    (root / "src" / "__init__.py").write_text("WHERE = 'fake tree'\n")
    (root / "extra").mkdir()
    (root / "extra" / "__init__.py").write_text("")
    (root / "extra" / "leaf.py").write_text("VALUE = 42\n")
    (root / "pyproject.toml").write_text(f"[tool.setuptools.package-dir]\n{package_dir}\n")
    return root


def test_use_tree_imports_voxwarp_from_the_tree(tmp_path: Path) -> None:
    tree = _fake_tree(tmp_path / "t", '"voxwarp" = "src"\n"voxwarp.deform" = "extra"')
    code = (
        "import sys; from pathlib import Path; from benchmarks.costs_tree import use_tree;"
        f" use_tree(Path({str(tree)!r})); import voxwarp; from voxwarp.deform import leaf;"
        " print(voxwarp.WHERE, leaf.VALUE, Path(leaf.__file__).parent.name)"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=False
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["fake", "tree", "42", "extra"]


def test_use_tree_refuses_another_voxwarp_once_imported(tmp_path: Path) -> None:
    import voxwarp

    tree = _fake_tree(tmp_path / "t", '"voxwarp" = "src"')
    with pytest.raises(costs_tree.TreeError, match="already imported"):
        costs_tree.use_tree(tree)
    costs_tree.use_tree(Path(voxwarp.__file__).resolve().parent.parent)  # the same: fine


def test_package_dirs_errors(tmp_path: Path) -> None:
    with pytest.raises(costs_tree.TreeError, match=r"no readable pyproject\.toml"):
        costs_tree.package_dirs(tmp_path)
    tree = _fake_tree(tmp_path / "t", '"other" = "src"')
    with pytest.raises(costs_tree.TreeError, match="maps no 'voxwarp' package"):
        costs_tree.package_dirs(tree)


def test_package_dirs_of_this_checkout() -> None:
    dirs = costs_tree.package_dirs(ROOT)
    assert dirs["voxwarp"] == ROOT / "app"
    assert dirs["voxwarp.deform"] == ROOT / "deform"


def test_export_revision_writes_a_tree(tmp_path: Path) -> None:
    commit = costs_tree.resolve_revision(ROOT, "HEAD")
    assert len(commit) == 40
    tree = costs_tree.export_revision(ROOT, commit, tmp_path / "x")
    assert (tree / "app" / "__init__.py").is_file()
    assert (tree / "deform" / "__init__.py").is_file()
    assert not (tree / "tree.tar").exists()
    with pytest.raises(costs_tree.TreeError, match="no such git revision"):
        costs_tree.resolve_revision(ROOT, "no-such-rev-xyz")


# ---------------------------------------------------------------------- worker and runs
class _Lab:
    def measure(self, row: str, spec: str) -> dict[str, float]:
        if row == "boom":
            raise RuntimeError("no context\nsecond line")
        return {"ratio": float("nan")} if row == "nan" else {"ratio": 2.0}


def test_worker_answers() -> None:
    assert costs_worker.answer(_Lab(), {"row": "x", "volume": "v"}) == {"values": {"ratio": 2.0}}
    assert costs_worker.answer(_Lab(), {"row": "boom", "volume": "v"}) == {
        "error": "RuntimeError: no context"
    }
    assert "not finite" in costs_worker.answer(_Lab(), {"row": "nan", "volume": "v"})["error"]


class _FakeWorker:
    def __init__(self, label: str, calls: list[str], fail: bool = False) -> None:
        self.label, self.calls, self.fail = label, calls, fail

    def ask(self, measure: str, volume: str) -> dict[str, Any]:
        self.calls.append(self.label)
        if self.fail:
            return {"error": "no such API"}
        return {"values": {"ratio": float(len(self.calls))}}


def test_repeats_alternate_and_a_failed_first_try_is_not_repeated(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(bench_costs, "_tasks", lambda volumes, measures: [("m", "v")])
    calls: list[str] = []
    workers = [_FakeWorker("before", calls), _FakeWorker("after", calls)]
    got = bench_costs.measure_all(workers, ["v"], 4, log=lambda s: None)
    assert calls == ["before", "after", "after", "before"] * 2
    res = got[("m", "v")]["results"]
    assert [r["ratio"] for r in res["before"]["repeats"]] == [1.0, 4.0, 5.0, 8.0]
    assert res["before"]["median"] == {"ratio": 4.5}
    assert len(got[("m", "v")]["load"]) == 4
    calls.clear()
    workers = [_FakeWorker("before", calls, fail=True), _FakeWorker("after", calls)]
    got = bench_costs.measure_all(workers, ["v"], 3, log=lambda s: None)
    assert calls == ["before", "after", "after", "after"]
    assert got[("m", "v")]["results"]["before"] == {
        "repeats": [],
        "error": "no such API",
        "median": {},
    }


def test_tasks_run_global_measurements_once() -> None:
    tasks = bench_costs._tasks(["a", "b"])
    for m in costs_table.MEASUREMENTS:
        volumes = [v for mm, v in tasks if mm == m]
        assert volumes == ([None] if m in costs_table.GLOBAL else ["a", "b"])


def test_only_some_measurements() -> None:
    tasks = bench_costs._tasks(["a", "b"], ["massspring_settled", "wire_build"])
    assert tasks == [("massspring_settled", "a"), ("massspring_settled", "b"), ("wire_build", None)]
    args = build_parser().parse_args(["costs", "--only", "chainmail_local,gui_drag"])
    assert args.only == "chainmail_local,gui_drag"


def test_unknown_measurement_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    from benchmarks.__main__ import main

    assert main(["costs", "--before", "none", "--only", "chainmail_local,warp_speed"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("benchmarks: error: unknown measurement warp_speed; pick from")
    assert "chainmail_local" in err.split("pick from", 1)[1]
    assert "\n" not in err


# ---------------------------------------------------------------------- the table
def _fake_run(quick: bool = False) -> dict[str, Any]:
    values = {
        "ratio": 2.5,
        "per_pixel": 2.4,
        "raw": 1.6,
        "covered": 0.25,
        "s_1_8": 0.2,
        "s_1_1": 1.5,
        "cpu_1_8": 0.1,
        "cpu_1_1": 0.7,
        "first_steady": 20.0,
        "memory": 4.8,
        "chainmail_fps": 3.0,
        "massspring_fps": 2.0,
    }
    rows = []
    for line in costs_table.LINES:
        for volume in ("sample:stent", "x/chest.nii.gz") if line.per_volume else (None,):
            after = {"repeats": [values], "error": "", "median": values}
            failed = {"repeats": [], "error": "AttributeError: old API", "median": {}}
            results = {"before": failed if line.key == "gui_drag" else after, "after": after}
            rows.append({"line": line.key, "volume": volume, "results": results, "load": [2, 3]})
    return {
        "command": "python -m benchmarks costs",
        "machine": "fake CPU, GL: fake",
        "quick": quick,
        "repeats": 5,
        "size": [512, 512],
        "revisions": [
            {"label": "before", "commit": "a" * 40},
            {"label": "after", "commit": "b" * 40},
        ],
        "load": [2.0, 3.0],
        "wall_s": 100.0,
        "rows": rows,
    }


def test_markdown_table() -> None:
    text = costs_table.markdown(_fake_run())
    head = "| what | volume | before (`aaaaaaaaaa`) | after (`bbbbbbbbbb`) | target | load avg |"
    assert head in text
    rows = [ln for ln in text.splitlines() if ln.startswith("| ")]
    assert len(rows) == 1 + len(_fake_run()["rows"])
    assert all(ln.count(" | ") == 5 for ln in rows)
    assert "| 2.40x (1.60x raw) | 2.40x (1.60x raw) | ≥ 2.0x | 2.0–3.0 |" in text
    assert "| failed: AttributeError: old API | 3.0 / 2.0 fps |" in text
    assert "+4.8x its bytes" in text
    assert "| 0.20 / 1.50 s (CPU 0.10 / 0.70 s) | 0.20 / 1.50 s (CPU 0.10 / 0.70 s) |" in text
    assert "″" in text  # the second volume's line does not repeat the what
    assert costs_table.QUICK_NOTE not in text
    assert costs_table.QUICK_NOTE in costs_table.markdown(_fake_run(quick=True))


def test_cell_leaves_out_extra_numbers_the_run_lacks() -> None:
    line = next(ln for ln in costs_table.LINES if ln.extra)
    fields = _fields(line.template)
    result = {"median": dict.fromkeys(fields, 1.0), "error": ""}
    assert costs_table.cell(line, result) == line.template.format(**result["median"])


def test_cell_without_numbers() -> None:
    line = costs_table.LINES[0]
    assert costs_table.cell(line, None) == "—"
    assert costs_table.cell(line, {"median": {}, "error": ""}) == "failed: no numbers"
    nan = {"median": {"ratio": float("nan")}, "error": "x"}
    assert costs_table.cell(line, nan) == "failed: x"


def test_medians() -> None:
    got = costs_table.medians([{"a": 1.0}, {"a": 3.0}, {"a": 2.0, "b": 5.0}])
    assert got == {"a": 2.0, "b": 5.0}


# ---------------------------------------------------------------------- the README
def test_paragraph_quotes_every_volume() -> None:
    run = _fake_run()
    vtk = next(r for r in run["rows"] if r["line"] == "vtk_per_pixel")
    repeats = [dict(vtk["results"]["after"]["median"], per_pixel=v) for v in (1.9, 2.4, 2.6)]
    vtk["results"]["after"] = dict(vtk["results"]["after"], repeats=repeats)
    text = costs_readme.paragraph(run)
    stent = "is 2.4x on the bundled `stent` CT (25 % of the image covered; 1.6x per frame;"
    assert f"{stent} runs 1.9–2.6x)" in text
    chest = "2.4x on `chest.nii.gz` (25 % of the image covered; 1.6x per frame; every run 2.4x)"
    assert f" and {chest} as fast" in text
    assert "load average 2–3; medians of 5 runs" in text
    assert "issue" not in text.lower()
    assert "\n" not in text


def test_paragraph_needs_vtk_numbers() -> None:
    run = _fake_run()
    run["rows"] = [r for r in run["rows"] if r["line"] != "vtk_per_pixel"]
    with pytest.raises(costs_readme.ReadmeError, match="no VTK numbers"):
        costs_readme.paragraph(run)


def test_replace_block() -> None:
    readme = f"intro\n{costs_readme.BEGIN}\nold text\n{costs_readme.END}\nrest\n"
    new = costs_readme.replace_block(readme, "new text")
    assert new == f"intro\n{costs_readme.BEGIN}\nnew text\n{costs_readme.END}\nrest\n"
    assert costs_readme.current_block(new) == "new text"
    with pytest.raises(costs_readme.ReadmeError, match="add the two markers"):
        costs_readme.replace_block("no markers", "x")


def test_the_readme_paragraph_is_the_generators_of_the_recorded_run() -> None:
    run = costs_readme.load_run(costs_readme.RUN_JSON)
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert costs_readme.current_block(readme) == costs_readme.paragraph(run)
    assert not run["quick"]


def test_readme_command_rewrites_and_checks(tmp_path: Path) -> None:
    from benchmarks.__main__ import main

    readme = tmp_path / "README.md"
    readme.write_text(f"a\n{costs_readme.BEGIN}\nstale\n{costs_readme.END}\nb\n")
    run = tmp_path / "run.json"
    run.write_text(json.dumps(_fake_run()))
    assert main(["readme", str(run), "--readme", str(readme), "--check"]) == 1
    assert main(["readme", str(run), "--readme", str(readme)]) == 0
    assert costs_readme.current_block(readme.read_text()) == costs_readme.paragraph(_fake_run())
    assert main(["readme", str(run), "--readme", str(readme), "--check"]) == 0
    run.write_text("{}")
    assert main(["readme", str(run), "--readme", str(readme)]) == 2
