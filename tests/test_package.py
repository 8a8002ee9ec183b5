"""The installed package: one ``voxwarp`` namespace, light imports, extras, entry points.

Each check runs in a fresh interpreter started outside the repository (``cwd`` is a
temporary folder), so only what the installed package provides can be imported.
"""

from __future__ import annotations

import importlib.metadata
import json
import os
import shutil
import subprocess
import sys
import tomllib
import venv
from pathlib import Path

import pytest

from voxwarp.core import extras
from voxwarp.errors import MissingExtraError, VoxwarpError

ROOT = Path(__file__).resolve().parent.parent
#: modules that must not load on ``import voxwarp`` or ``voxwarp --help``
HEAVY = ("numba", "scipy", "pyopencl", "PySide6", "dask", "distributed", "matplotlib")
OLD_NAMES = ("app", "deform", "ui", "shaders", "sample_volumes")
#: what a source distribution leaves out (copied trees of the core-only install)
NOT_PACKAGED = (".git", ".venv", "build", "*.egg-info", "__pycache__", "tests", "out", ".*cache")


def _python(code: str, cwd: Path, exe: str = sys.executable) -> str:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    res = subprocess.run(
        [exe, "-c", code], cwd=cwd, capture_output=True, text=True, timeout=300, env=env
    )
    assert res.returncode == 0, res.stderr[-3000:]
    return res.stdout


def _loaded(code: str, cwd: Path) -> list[str]:
    out = _python(f"{code}\nimport json, sys\nprint(json.dumps(sorted(sys.modules)))", cwd)
    mods = json.loads(out.strip().splitlines()[-1])
    return sorted({m.split(".")[0] for m in mods} & set(HEAVY))


def test_import_voxwarp_loads_no_heavy_module(tmp_path: Path) -> None:
    assert _loaded("import voxwarp, voxwarp.deform", tmp_path) == []


def test_command_line_parser_loads_no_heavy_module(tmp_path: Path) -> None:
    code = "from voxwarp.cli.main import build_parser\nbuild_parser(bench=False)"
    assert _loaded(code, tmp_path) == []


def test_public_names_resolve(tmp_path: Path) -> None:
    out = _python(
        "import voxwarp\n"
        "for n in voxwarp.__all__: getattr(voxwarp, n)\n"
        "print(voxwarp.Scene.__module__, voxwarp.load_volume.__module__)",
        tmp_path,
    )
    assert out.split() == ["voxwarp.scene", "voxwarp.io.volumes"]
    import voxwarp

    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        voxwarp.nope  # noqa: B018


def test_version_everywhere(tmp_path: Path) -> None:
    version = importlib.metadata.version("voxwarp")
    assert _python("import voxwarp; print(voxwarp.__version__)", tmp_path).strip() == version
    exe = Path(sys.executable)
    for cmd in (
        [str(exe), "-m", "voxwarp", "--version"],
        [str(exe.with_name("voxwarp")), "--version"],
    ):
        res = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=60)
        assert res.returncode == 0, res.stderr
        assert res.stdout.strip() == f"voxwarp {version}"


def test_no_generic_top_level_package_is_installed(tmp_path: Path) -> None:
    code = f"import importlib.util\nprint([importlib.util.find_spec(n) for n in {OLD_NAMES!r}])"
    assert _python(code, tmp_path).strip() == str([None] * len(OLD_NAMES))


@pytest.mark.gl
@pytest.mark.slow
def test_renders_beside_a_users_own_app_package(tmp_path: Path) -> None:
    """The usual Flask/FastAPI layout has its own ``app/``: both must import."""
    (tmp_path / "app").mkdir()
    (tmp_path / "app" / "__init__.py").write_text("load_volume = 'the user app'\n")
    out = _python(
        "import app\n"
        "from voxwarp import OffscreenRenderer, Scene, load_volume\n"
        "vol = load_volume('sample:fish')\n"
        "with OffscreenRenderer(48, 32) as r:\n"
        "    img = r.render(Scene(vol, view='+z'))\n"
        "print(app.load_volume, '|', img.shape, int(img[..., :3].max()))",
        tmp_path,
    )
    user, image = out.strip().split(" | ")
    assert user == "the user app"
    shape, brightest = image.rsplit(" ", 1)
    assert shape == "(32, 48, 4)"
    assert int(brightest) > 0


def test_every_package_folder_is_installed() -> None:
    """pyproject lists the packages one by one (package-dir maps the folders): a folder
    with an ``__init__.py`` missing from the list would be left out of the wheel."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    package_dir = config["tool"]["setuptools"]["package-dir"]
    found = set()
    for name, folder in package_dir.items():
        for init in (ROOT / folder).rglob("__init__.py"):
            rel = init.parent.relative_to(ROOT / folder)
            found.add(".".join((name, *rel.parts)))
    assert found == set(config["tool"]["setuptools"]["packages"])


def test_extras_match_pyproject() -> None:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    declared = set(config["project"]["optional-dependencies"]) - {"all", "dev", "bench"}
    assert declared == set(extras.EXTRAS)
    assert "PySide6" not in " ".join(config["project"]["dependencies"])


def test_missing_extra_is_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(extras.EXTRAS, "gui", ("no_such_module_voxwarp",))
    with pytest.raises(MissingExtraError) as info:
        extras.require("gui", "voxwarp gui")
    msg = str(info.value)
    assert msg == (
        "voxwarp gui needs the gui extra (missing: no_such_module_voxwarp):"
        " pip install 'voxwarp[gui]'"
    )
    assert isinstance(info.value, VoxwarpError)
    extras.require("movie", "voxwarp animate")  # installed here: no error


@pytest.mark.slow
@pytest.mark.gl
def test_core_only_install_renders_headless(tmp_path: Path) -> None:
    """A fresh venv with the core dependencies only (no extra) installs the wheel, renders
    one image, and ``voxwarp gui`` names the extra it needs."""
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=True)
    py = env_dir / "bin" / "python"
    source = tmp_path / "source"  # a copy: pip builds in the tree and would leave build/
    shutil.copytree(ROOT, source, ignore=shutil.ignore_patterns(*NOT_PACKAGED))
    res = subprocess.run(
        [str(py), "-m", "pip", "install", "-q", "--disable-pip-version-check", str(source)],
        capture_output=True,
        text=True,
        timeout=1200,
    )
    assert res.returncode == 0, res.stderr[-3000:]
    out = _python(
        "import importlib.util, sys\n"
        "from voxwarp import OffscreenRenderer, Scene, load_volume, write_image\n"
        "vol = load_volume('sample:stent')\n"
        "with OffscreenRenderer(64, 64) as r:\n"
        "    img = r.render(Scene(vol))\n"
        "write_image('x.png', img)\n"
        "print([m for m in ('PySide6', 'matplotlib', 'dask') if importlib.util.find_spec(m)])",
        tmp_path,
        exe=str(py),
    )
    assert out.strip().splitlines()[-1] == "[]"
    assert (tmp_path / "x.png").stat().st_size > 100
    res = subprocess.run(
        [str(env_dir / "bin" / "voxwarp"), "gui"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "DISPLAY": ":99"},
    )
    assert res.returncode == 2
    assert res.stderr.strip() == (
        "voxwarp: error: voxwarp gui needs the gui extra (missing: PySide6):"
        " pip install 'voxwarp[gui]'"
    )


def test_loading_an_array_imports_neither_simpleitk_nor_nibabel(tmp_path: Path) -> None:
    """load_volume tells SimpleITK/nibabel images apart by their class's module name."""
    out = _python(
        "import sys, numpy as np\n"
        "from voxwarp import load_volume\n"
        "load_volume(np.zeros((2, 3, 4), np.float32))\n"
        "print(sorted(m for m in ('SimpleITK', 'nibabel') if m in sys.modules))",
        tmp_path,
    )
    assert out.strip().splitlines()[-1] == "[]"
