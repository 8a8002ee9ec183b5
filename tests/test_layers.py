"""Layer rules: nothing below ui imports Qt; lower layers never import upper ones.

Checked from the source with ``ast`` (every import statement, including those inside
functions), independent of import-linter which `make lint` also runs. The folders are
the design card's; their import names are those of the installed package (pyproject's
``package-dir``: app/ is ``voxwarp``, deform/ is ``voxwarp.deform``, ...).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
QT = ("PySide6", "PyQt5", "PyQt6", "PySide2", "shiboken6")
#: app/'s role subpackages, top to bottom (``voxwarp.<name>``)
APP = ("cli", "teaching", "bench", "editing", "animation", "render", "inputs", "scene", "io")
APP_ALL = (*APP, "core")
#: the lab (benchmarks/ in the checkout): never installed, so nothing installed imports it
LAB = "benchmarks"
FORBIDDEN = {
    "shaders": (*QT, "voxwarp.ui", "voxwarp.deform", *(f"voxwarp.{m}" for m in APP_ALL), LAB),
    "deform": (*QT, "voxwarp.ui", *(f"voxwarp.{m}" for m in APP_ALL), LAB),
    "app": (*QT, "voxwarp.ui", LAB),
    "ui": (LAB,),
    "sample_volumes": (
        *QT,
        *(f"voxwarp.{m}" for m in (*APP_ALL, "ui", "deform", "shaders", "errors")),
        LAB,
    ),
    # teaching is installed without the benchmarks: it imports neither
    "app/teaching": ("voxwarp.bench", LAB),
}
#: entry points that stand outside the layers: ``python -m voxwarp`` runs the console
#: script (``voxwarp.cli.main:main``), whose ``gui`` command (app/cli/gui.py) is the one
#: door from the command line up to the window (it imports ``voxwarp.ui.app`` when run)
ENTRY_POINTS = ("app/__main__.py", "app/cli/gui.py")
#: generic top-level names the wheel must not provide any more
OLD_NAMES = ("app", "deform", "ui", "shaders", "sample_volumes")


def _imports(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out += [(node.lineno, f"{node.module}.{a.name}") for a in node.names]
    return out


def _hits(mod: str, prefixes: tuple[str, ...]) -> bool:
    return any(mod == p or mod.startswith(p + ".") for p in prefixes)


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
@pytest.mark.slow
def test_package_respects_layers(package: str) -> None:
    files = sorted((ROOT / package).rglob("*.py"))
    assert files, f"no python files found in {package}/"
    bad = []
    for f in files:
        if str(f.relative_to(ROOT)) in ENTRY_POINTS:
            continue
        for line, mod in _imports(f):
            if _hits(mod, FORBIDDEN[package]):
                bad.append(f"{f.relative_to(ROOT)}:{line} imports {mod}")
    assert not bad, "layer violations:\n" + "\n".join(bad)


@pytest.mark.parametrize(
    "folder", ["app", "deform", "ui", "shaders", "sample_volumes", "benchmarks", "tests"]
)
@pytest.mark.slow
def test_no_generic_top_level_imports(folder: str) -> None:
    """Every import of the project's own code goes through ``voxwarp``."""
    bad = []
    for f in sorted((ROOT / folder).rglob("*.py")):
        for line, mod in _imports(f):
            if mod.split(".")[0] in OLD_NAMES:
                bad.append(f"{f.relative_to(ROOT)}:{line} imports {mod}")
    assert not bad, "imports of the old top-level names:\n" + "\n".join(bad)


def test_checker_sees_violations(tmp_path: Path) -> None:
    f = tmp_path / "m.py"
    f.write_text("def f():\n    from PySide6 import QtCore\n")
    assert _imports(f) == [(2, "PySide6.QtCore")]
    assert _hits("voxwarp.render.raycaster", ("voxwarp.render",))
    assert not _hits("voxwarp.renderer", ("voxwarp.render",))
