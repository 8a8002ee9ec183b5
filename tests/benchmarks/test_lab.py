"""The lab (``benchmarks/``) lives in the checkout only: importable there as ``benchmarks``
(tests/ is a package, so pytest puts the repository's root on ``sys.path``), never
installed, never importable as ``voxwarp.*``, and never imported by the installed package
(also an import-linter contract of pyproject.toml, which ``make lint`` checks)."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
LAB = ROOT / "benchmarks"
MODULES = sorted(p.stem for p in LAB.glob("*.py") if p.stem not in ("__init__", "__main__"))
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))


def test_the_lab_imports_from_the_checkout() -> None:
    import benchmarks

    assert Path(benchmarks.__file__).resolve() == LAB / "__init__.py"
    assert benchmarks.ROOT == ROOT
    assert "all" in MODULES
    assert "wires" in MODULES


@pytest.mark.parametrize("name", MODULES)
def test_no_lab_module_is_importable_as_voxwarp(name: str) -> None:
    for qualified in (f"voxwarp.{name}", f"voxwarp.bench.{name}", f"voxwarp.teaching.{name}"):
        try:
            spec = importlib.util.find_spec(qualified)
        except ModuleNotFoundError:
            continue
        assert spec is None or LAB not in Path(spec.origin or "").parents, qualified


def test_the_lab_is_not_installed() -> None:
    tool = PYPROJECT["tool"]["setuptools"]
    assert not [p for p in tool["packages"] if "benchmarks" in p.split(".")]
    assert "benchmarks" not in tool["package-dir"].values()
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        from lint_imports import installed_files  # the wheel's layout
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    files = installed_files(Path("/x"))
    assert files
    assert not [src for src in files if LAB in src.parents]


def test_an_import_linter_contract_keeps_the_lab_out() -> None:
    """The installed package never imports ``benchmarks`` (checked by ``make lint``)."""
    contracts = PYPROJECT["tool"]["importlinter"]["contracts"]
    lab = [
        c
        for c in contracts
        if c["type"] == "forbidden"
        and c.get("source_modules") == ["voxwarp"]
        and c["forbidden_modules"] == ["benchmarks"]
    ]
    assert len(lab) == 1
    teaching = [c for c in contracts if c.get("source_modules") == ["voxwarp.teaching"]]
    assert teaching
    assert set(teaching[0]["forbidden_modules"]) == {"voxwarp.bench", "benchmarks"}


def test_python_m_benchmarks_lists_every_benchmark() -> None:
    from benchmarks.__main__ import COMMANDS

    proc = subprocess.run(
        [sys.executable, "-m", "benchmarks", "--help"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("usage: python -m benchmarks")
    for name in COMMANDS:
        assert name in proc.stdout
