"""``VOXWARP_REQUIRE_GL=1`` turns "no GL context" from a skip into a failure.

Without an EGL context every GL test would skip and the suite would pass with most of
its checks unrun; ``make test`` (and so CI) sets the variable. Each test here runs
pytest in a subprocess on a tiny GL test, with the shared fixtures of ``tests/conftest.py``
and ``moderngl.create_standalone_context`` replaced by one that raises (EGL broken).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

BROKEN_EGL_CONFTEST = textwrap.dedent(
    """
    import moderngl

    def _no_egl(*args, **kwargs):
        raise RuntimeError("simulated: EGL cannot create a context")

    moderngl.create_standalone_context = _no_egl
    pytest_plugins = ["tests.conftest"]
    """
)

TINY_GL_TEST = textwrap.dedent(
    """
    def test_draws(gl_ctx):
        assert gl_ctx is not None

    def test_plain():
        assert 1 + 1 == 2
    """
)


def run_tiny_suite(tmp_path: Path, require: str | None) -> subprocess.CompletedProcess[str]:
    (tmp_path / "pytest.ini").write_text("[pytest]\nmarkers =\n    gl: needs GL\n")
    (tmp_path / "conftest.py").write_text(BROKEN_EGL_CONFTEST)
    (tmp_path / "test_tiny_gl.py").write_text(TINY_GL_TEST)
    env = {k: v for k, v in os.environ.items() if k != "VOXWARP_REQUIRE_GL"}
    # only the tiny suite's own conftest: installed plugins (napari's, npe2's) add warnings
    env["PYTEST_DISABLE_PLUGIN_AUTOLOAD"] = "1"
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    if require is not None:
        env["VOXWARP_REQUIRE_GL"] = require
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-rA", "-p", "no:cacheprovider", str(tmp_path)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_gl_tests_skip_without_egl_by_default(tmp_path: Path) -> None:
    proc = run_tiny_suite(tmp_path, None)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    assert re.search(r"\b1 passed, 1 skipped\b", out), out
    assert "no headless OpenGL 4.3 context through EGL" in out
    assert "simulated: EGL cannot create a context" in out


def test_gl_tests_fail_without_egl_when_gl_is_required(tmp_path: Path) -> None:
    proc = run_tiny_suite(tmp_path, "1")
    out = proc.stdout + proc.stderr
    assert proc.returncode == 1, out
    assert re.search(r"\b1 passed, 1 error\b", out), out
    assert "skipped" not in out
    assert "VOXWARP_REQUIRE_GL is set but no headless OpenGL 4.3 context" in out
    assert "simulated: EGL cannot create a context" in out  # the cause is shown


def test_make_test_requires_gl() -> None:
    """The ``test`` target of the Makefile (what CI runs) sets VOXWARP_REQUIRE_GL=1."""
    text = (REPO / "Makefile").read_text()
    recipe = re.search(r"^test:.*\n((?:\t.*\n)+)", text, re.MULTILINE)
    assert recipe is not None, "no test target in the Makefile"
    assert re.search(r"VOXWARP_REQUIRE_GL=1 \S+ -m pytest", recipe.group(1))
    assert "make test" in (REPO / ".ci" / "run").read_text()
