"""``voxwarp reproduce`` (voxwarp.teaching.reproduce): the report beside the papers' numbers.

The quick run takes the demos' quick sizes; it requests ``gl_ctx`` only so that it skips,
like every GL test, where EGL is missing.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path
from typing import Any

import pytest

from voxwarp.cli.main import main
from voxwarp.teaching.demos import DEMO_TITLES, DEMOS
from voxwarp.teaching.reproduce import QUICK_SKIP, THESIS_HAS_NONE, cpu_model, reproduce


@pytest.fixture(autouse=True)
def _keep_warning_state(monkeypatch: pytest.MonkeyPatch) -> None:
    """main() replaces warnings.formatwarning for good; undo it after each test."""
    monkeypatch.setattr(warnings, "formatwarning", warnings.formatwarning)


@pytest.mark.gl
@pytest.mark.slow
def test_quick_reproduction_writes_the_report_and_its_figures(gl_ctx: Any, tmp_path: Path) -> None:
    out = tmp_path / "docs" / "reproduction.md"
    assert reproduce(out, quick=True) == out
    text = out.read_text(encoding="utf-8")
    # the hardware section names the CPU, the GL renderer and the OpenCL device
    hw = text.split("## Hardware", 1)[1].split("\n## ", 1)[0]
    assert f"| CPU | {cpu_model()}," in hw
    assert re.search(r"\| GL renderer [^|]*\| \S", hw)
    assert re.search(r"\| OpenCL device [^|]*\| \S", hw)
    assert "| memory |" in hw
    assert "Quick run" in text
    assert "`voxwarp reproduce --quick --out " in text
    # one section per demo, each with its figure beside the report and a table
    for name in DEMOS:
        assert f". {DEMO_TITLES[name]}\n" in text
        link = f"(reproduction/{name}.png)"
        assert link in text
        assert (tmp_path / "docs" / "reproduction" / f"{name}.png").is_file()
    sections = text.split("\n## ")[2:]
    assert len(sections) == len(DEMOS)
    for sec in sections:
        assert "| --- |" in sec, sec[:80]
    # the papers' numbers, quoted from their tables, and the honest gaps
    lattice = next(s for s in sections if s.startswith(f"{DEMOS.index('lattice') + 1}."))
    for number in ("76.4%", "80.6%", "77.8%"):
        assert number in lattice, number
    assert "75%-80%" not in lattice
    wires = next(s for s in sections if s.startswith(f"{DEMOS.index('wires') + 1}."))
    assert "1.86-5.31x" in wires
    assert "2.2-5.3x" not in wires
    for number in ("11.74", "4.45", "2.61", "2.17", "2.12", "59.7", "86.3", "2.20x", "5.31x"):
        assert number in wires, number
    assert "| paper | 2 (flag 1 bit, wire 4, segment 4, t 7) | 2 |" in wires  # section 7.2
    assert "| float | at least 5 (float t, 7-bit wire, flag) | 5 |" in wires
    # Figure 12's artefacts measured against the 1:1 field, and its close-up sheet
    assert "Figure 12's artefacts, measured" in wires
    assert "| 1:4096 |" in wires.split("Figure 12's artefacts, measured", 1)[1]
    assert "(reproduction/wires_fig12.png)" in wires
    assert "Figure 5: images, no numbers" in lattice
    # GRAPP's own scenes, each row beside the paper's (timings skipped in a quick run)
    for scene, counts, paper in (
        ("spheres", "| 185 | 1,500,000 (paper 1.5M) |", "| 19.5 / 14.9 | 76.4% |"),
        ("helix_4617", "| 4,617 | 164,000 (paper 164k) |", "| 16.5 / 13.3 | 80.6% |"),
        ("helix_2566", "| 2,566 | 656,000 (paper 656k) |", "| 10.8 / 8.4 | 77.8% |"),
    ):
        line = next(x for x in lattice.splitlines() if x.startswith(f"| {scene} ("))
        assert counts + paper.removeprefix("|") in line, line
        assert QUICK_SKIP in line
    assert "(reproduction/lattice_grapp.png)" in lattice
    assert (tmp_path / "docs" / "reproduction" / "lattice_grapp.png").is_file()
    assert "lattice_accessories_anim.json" in lattice  # Figure 8
    assert "not in the repo" not in text
    massspring = next(s for s in sections if s.startswith(f"{DEMOS.index('massspring') + 1}."))
    assert THESIS_HAS_NONE in massspring
    # a quick run prints no timing ratio it cannot measure meaningfully
    assert QUICK_SKIP in wires
    # the lattice's and Tables 1-3's measurements are the lab's: the report names them
    assert "`python -m benchmarks lattice`" in lattice
    assert "`python -m benchmarks wire-tables`" in wires
    assert not re.search(r"\| \d+% \|", lattice)
    # nothing half-written left behind, and only the figure sheets beside the report (the
    # registration demo's transform files stay out of docs/)
    assert not [p for p in out.parent.rglob(".*")]
    assert {p.suffix for p in (tmp_path / "docs" / "reproduction").iterdir()} == {".png"}


def test_cli_reproduce_passes_its_options(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    calls: list[tuple[Any, ...]] = []

    def fake(out_md: Any, quick: bool = False, **kw: Any) -> Path:
        calls.append((out_md, quick, kw.get("command")))
        return Path(out_md)

    monkeypatch.setattr("voxwarp.teaching.reproduce.reproduce", fake)
    out = tmp_path / "r.md"
    assert main(["reproduce", "--quick", "--out", str(out)]) == 0
    assert calls == [(str(out), True, f"voxwarp reproduce --quick --out {out}")]
    assert capsys.readouterr().out.strip() == str(out)
    calls.clear()
    assert main(["reproduce"]) == 0
    assert calls == [("docs/reproduction.md", False, "voxwarp reproduce")]
