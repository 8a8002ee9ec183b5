"""mkdocs hook: lay the package out as it installs, for the API pages.

pyproject maps the design card's top-level folders into one package (``voxwarp`` is
app/, ``voxwarp.deform`` is deform/, ...). mkdocstrings reads a package from one folder
tree, so this mirrors the Python files under their installed names into build/docs-src
(git-ignored), which mkdocs.yml gives the python handler as its ``paths``. Files are
replaced one by one, atomically and only when they changed, so a second build running
at the same time (``make docs`` twice, ``mkdocs serve``) never reads a half-made tree.
Named in mkdocs.yml under ``hooks``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from lint_imports import ROOT, installed_files  # a sibling script

DEST = ROOT / "build" / "docs-src"


def sync() -> None:
    """Bring DEST up to date: changed files replaced atomically, vanished ones removed."""
    files = installed_files(DEST)
    for src, dest in files.items():
        data = src.read_bytes()
        if dest.is_file() and dest.read_bytes() == data:
            continue
        dest.parent.mkdir(parents=True, exist_ok=True)
        tmp = dest.with_name(f".{dest.name}.{os.getpid()}.tmp")
        tmp.write_bytes(data)
        tmp.replace(dest)
    wanted = set(files.values())
    for old in DEST.rglob("*.py"):
        if old not in wanted:
            old.unlink(missing_ok=True)


# at import: mkdocs imports its hooks while it validates mkdocs.yml, before any plugin's
# on_config (mkdocstrings keeps only the ``paths`` that exist when its on_config runs)
sync()
