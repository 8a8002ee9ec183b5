"""The code a ``python -m benchmarks costs`` worker measures: a source tree imported as
``voxwarp`` without installing it.

The package installs from several top-level folders (``pyproject.toml``'s
``[tool.setuptools.package-dir]``: ``app/`` is ``voxwarp``, ``deform/`` is
``voxwarp.deform``, ...). :func:`use_tree` reads that table from a tree (a checkout, or
a revision exported by :func:`export_revision`) and puts a finder first on
``sys.meta_path`` that maps each package to its folder, so ``import voxwarp`` in this
process runs that tree's code, whatever the virtual environment has installed. Its
third-party dependencies are this environment's.
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import importlib.util
import subprocess
import sys
import tarfile
import tomllib
from pathlib import Path
from types import ModuleType


class TreeError(ValueError):
    """A source tree or revision that cannot be measured (not a ``VoxwarpError``: this
    module imports no ``voxwarp`` before :func:`use_tree` chose which one)."""


def package_dirs(root: Path) -> dict[str, Path]:
    """Package name -> folder of the tree at ``root`` (from its ``pyproject.toml``)."""
    try:
        meta = tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError) as exc:
        why = f"{root}: no readable pyproject.toml ({exc}); give a voxwarp checkout"
        raise TreeError(why) from None
    table = meta.get("tool", {}).get("setuptools", {}).get("package-dir", {})
    dirs = {name: root / folder for name, folder in table.items() if name.startswith("voxwarp")}
    if "voxwarp" not in dirs:
        raise TreeError(f"{root}: pyproject.toml maps no 'voxwarp' package; give a voxwarp tree")
    return dirs


class _TreeFinder(importlib.abc.MetaPathFinder):
    """Finds the mapped packages of one tree (their sub-modules load through the
    packages' ``__path__`` as usual)."""

    def __init__(self, dirs: dict[str, Path]) -> None:
        self.dirs = dirs

    def find_spec(
        self, fullname: str, path: object = None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        folder = self.dirs.get(fullname)
        if folder is None or not (folder / "__init__.py").is_file():
            return None
        return importlib.util.spec_from_file_location(
            fullname, folder / "__init__.py", submodule_search_locations=[str(folder)]
        )


def use_tree(root: Path) -> None:
    """Import ``voxwarp`` from the tree at ``root`` in this process from now on; call it
    before anything imports ``voxwarp`` (a ``voxwarp`` already imported from elsewhere is
    refused)."""
    dirs = package_dirs(root)
    loaded = sys.modules.get("voxwarp")
    if loaded is not None:
        where = Path(loaded.__file__ or "").resolve().parent
        if where != dirs["voxwarp"].resolve():
            raise TreeError(f"voxwarp is already imported from {where}; start a new process")
        return
    sys.meta_path.insert(0, _TreeFinder(dirs))


def resolve_revision(checkout: Path, rev: str) -> str:
    """The commit id of ``rev`` in the git repository of ``checkout``."""
    res = subprocess.run(
        ["git", "-C", str(checkout), "rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}"],
        capture_output=True,
        text=True,
        check=False,
    )
    if res.returncode != 0:
        raise TreeError(f"--before {rev}: no such git revision here; give a branch, tag or commit")
    return res.stdout.strip()


def default_before(checkout: Path, branch: str = "main") -> str:
    """The revision ``--before`` defaults to: where HEAD left ``branch`` (their merge
    base; HEAD itself on ``branch``)."""
    res = subprocess.run(
        ["git", "-C", str(checkout), "merge-base", "HEAD", branch],
        capture_output=True,
        text=True,
        check=False,
    )
    if res.returncode != 0:
        raise TreeError(
            f"no merge base of HEAD and {branch!r} here; give --before REV (or --before none)"
        )
    return res.stdout.strip()


def export_revision(checkout: Path, commit: str, dest: Path) -> Path:
    """Write the files of ``commit`` into ``dest`` (``git archive``: no worktree to
    register or clean up) and return ``dest``."""
    dest.mkdir(parents=True, exist_ok=True)
    archive = dest / "tree.tar"
    with archive.open("wb") as out:
        res = subprocess.run(
            ["git", "-C", str(checkout), "archive", "--format=tar", commit],
            stdout=out,
            stderr=subprocess.PIPE,
            check=False,
        )
    if res.returncode != 0:
        raise TreeError(f"git archive {commit} failed: {res.stderr.decode().strip()[:200]}")
    with tarfile.open(archive) as tar:
        tar.extractall(dest, filter="data")
    archive.unlink()
    package_dirs(dest)  # a voxwarp tree?
    return dest
