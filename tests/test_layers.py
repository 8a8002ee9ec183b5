"""Layer rules: app, deform, shaders never import Qt; lower layers never import upper ones.

Checked from the source with ``ast`` (every import statement, including those inside
functions), independent of import-linter which `make lint` also runs.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
QT = ("PySide6", "PyQt5", "PyQt6", "PySide2", "shiboken6")
FORBIDDEN = {
    "shaders": (*QT, "app", "deform", "ui"),
    "deform": (*QT, "app", "ui"),
    "app": (*QT, "ui"),
    "sample_volumes": (*QT, "app", "deform", "ui", "shaders"),
}


def _imports(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.append((node.lineno, node.module))
    return out


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_package_respects_layers(package: str) -> None:
    files = sorted((ROOT / package).rglob("*.py"))
    assert files or package == "shaders", f"no python files found in {package}/"
    bad = []
    for f in files:
        for line, mod in _imports(f):
            if mod.split(".")[0] in FORBIDDEN[package]:
                bad.append(f"{f.relative_to(ROOT)}:{line} imports {mod}")
    assert not bad, "layer violations:\n" + "\n".join(bad)


def test_checker_sees_violations(tmp_path: Path) -> None:
    f = tmp_path / "m.py"
    f.write_text("def f():\n    from PySide6 import QtCore\n")
    assert _imports(f) == [(2, "PySide6")]
