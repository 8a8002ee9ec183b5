"""Run import-linter over voxwarp as it installs.

pyproject maps the design card's top-level folders into one package (``voxwarp`` is
app/, ``voxwarp.deform`` is deform/, ...). import-linter reads a package from one folder
tree, so this lays the Python files out as the wheel does (from ``package-dir``) in a
temporary folder and runs ``lint-imports`` with the contracts of pyproject.toml there.
Usage: ``python scripts/lint_imports.py`` (``make lint`` runs it).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def installed_files(dest: Path) -> dict[Path, Path]:
    """Every package ``*.py`` file -> its path under ``dest`` by its installed name (from
    pyproject's ``package-dir``); scripts/docs_hooks.py lays out the API pages' tree too."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    package_dir = config["tool"]["setuptools"]["package-dir"]
    files = {}
    for name, folder in package_dir.items():
        target = dest.joinpath(*name.split("."))
        for src in (ROOT / folder).rglob("*.py"):
            rel = src.relative_to(ROOT / folder)
            if rel.parts[0] in package_dir.values() or "__pycache__" in rel.parts:
                continue
            files[src] = target / rel
    return files


def lay_out(dest: Path) -> None:
    """Copy every package's ``*.py`` files to ``dest`` under their installed names."""
    for src, out in installed_files(dest).items():
        out.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, out)


def main() -> int:
    with tempfile.TemporaryDirectory(prefix="voxwarp-lint-") as tmp:
        lay_out(Path(tmp))
        env = {**os.environ, "PYTHONPATH": tmp}
        exe = Path(sys.executable).with_name("lint-imports")
        cmd = [str(exe), str(ROOT / "pyproject.toml"), "--no-cache"]
        return subprocess.run(cmd, env=env, cwd=tmp).returncode


if __name__ == "__main__":
    sys.exit(main())
