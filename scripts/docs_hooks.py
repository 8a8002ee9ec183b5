"""mkdocs hook: lay the package out as it installs, for the API pages.

pyproject maps the design card's top-level folders into one package (``voxwarp`` is
app/, ``voxwarp.deform`` is deform/, ...). mkdocstrings reads a package from one folder
tree, so this copies the Python files under their installed names into build/docs-src
(git-ignored; ``lay_out`` of scripts/lint_imports.py, as ``make lint`` does), which
mkdocs.yml gives the python handler as its ``paths``. A fresh copy on every build and
every reload of ``mkdocs serve``. Named in mkdocs.yml under ``hooks``.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEST = ROOT / "build" / "docs-src"


def lay_out() -> None:
    """Replace build/docs-src with the package laid out as it installs."""
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        from lint_imports import lay_out as copy_package
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    shutil.rmtree(DEST, ignore_errors=True)
    copy_package(DEST)


# at import: mkdocs imports its hooks while it validates mkdocs.yml, before any plugin's
# on_config (mkdocstrings keeps only the ``paths`` that exist when its on_config runs)
lay_out()
