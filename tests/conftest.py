"""Shared pytest fixtures: one headless GL context, offscreen renderers, golden images.

* ``gl_ctx``: one EGL standalone OpenGL 4.3 context for the whole session. Tests that
  use it (directly or through ``offscreen``) are marked ``gl`` automatically, and the
  context's error flag must read ``GL_NO_ERROR`` before and after each of them (the
  pattern of moderngl's own test suite). Without EGL they are skipped, with the reason;
  with ``VOXWARP_REQUIRE_GL=1`` in the environment (``make test`` and CI set it) they
  fail instead, so a machine that cannot create the context cannot pass the suite with
  most checks skipped.
* ``offscreen``: factory of :class:`voxwarp.render.offscreen.OffscreenRenderer` objects sharing
  ``gl_ctx``; all are released at the end of the session.
* ``golden``: compares an image with ``tests/golden/NAME.png``; ``pytest
  --regenerate-golden`` rewrites the files instead. On a mismatch the actual, expected
  and difference images go to ``tests/_failures/`` (git-ignored).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

GOLDEN_DIR = Path(__file__).parent / "golden"


def pytest_configure(config: pytest.Config) -> None:
    """Scene seals (voxwarp.core.scene_seal) use a key in a per-run folder, inherited by
    the CLI subprocesses, never the user's ~/.config."""
    import atexit
    import shutil
    import tempfile

    if "VOXWARP_CONFIG_DIR" not in os.environ:
        folder = tempfile.mkdtemp(prefix="voxwarp-test-config-")
        os.environ["VOXWARP_CONFIG_DIR"] = folder
        atexit.register(shutil.rmtree, folder, ignore_errors=True)


#: environment variable that turns "no GL context" from a skip into a failure
REQUIRE_GL = "VOXWARP_REQUIRE_GL"
FAILURE_DIR = Path(__file__).parent / "_failures"


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--regenerate-golden",
        action="store_true",
        default=False,
        help="rewrite tests/golden/*.png from the current renderer instead of comparing",
    )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    # every test that needs the GL context (also through `offscreen`) is a `gl` test
    for item in items:
        if "gl_ctx" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.gl)


@pytest.fixture(autouse=True)
def _seed_numpy() -> None:
    """Seed numpy's legacy global RNG (tests should still use default_rng(seed))."""
    np.random.seed(0)


# ---------------------------------------------------------------------- GL context
@pytest.fixture(scope="session")
def gl_ctx() -> Iterator[Any]:
    """One headless OpenGL 4.3+ context (EGL) for the session; skips GL tests without one
    (fails them when ``VOXWARP_REQUIRE_GL=1``)."""
    from voxwarp.errors import RenderError
    from voxwarp.render.context import create_context

    try:
        ctx = create_context()
    except RenderError as exc:
        if os.environ.get(REQUIRE_GL, "") not in ("", "0"):
            pytest.fail(
                f"{REQUIRE_GL} is set but no headless OpenGL 4.3 context could be created"
                f" through EGL: {exc}",
                pytrace=False,
            )
        pytest.skip(f"no headless OpenGL 4.3 context through EGL: {exc}")
    ctx.mglo.__enter__()  # current now, even if a pooled renderer's context was
    _SESSION_GL.append(ctx)
    yield ctx
    _SESSION_GL.clear()
    ctx.release()


#: the session context once made (module fixtures must find it current, see below)
_SESSION_GL: list[Any] = []


@pytest.fixture(autouse=True, scope="module")
def _gl_current_for_module_fixtures() -> None:
    """Make the session context current before a module's own fixtures run: they run
    before the per-test check below, after another module's renderers may have left
    their pooled context current or none (voxwarp.render.context_pool)."""
    if _SESSION_GL:
        _SESSION_GL[0].mglo.__enter__()


@pytest.fixture(autouse=True)
def _gl_error_check(request: pytest.FixtureRequest) -> Iterator[None]:
    """For tests using ``gl_ctx``: the session context is the current one (a test that
    made and dropped a context of its own may have left another current, and a
    renderer given a context does not switch to it), no GL error pending before the
    test, none left after it."""
    if "gl_ctx" not in request.fixturenames:
        yield
        return
    ctx = request.getfixturevalue("gl_ctx")
    ctx.mglo.__enter__()  # eglMakeCurrent(the session context), as OffscreenRenderer does
    before = ctx.error  # reading the flag also clears it
    assert before == "GL_NO_ERROR", f"GL error pending before the test: {before}"
    yield
    after = ctx.error
    assert after == "GL_NO_ERROR", f"the test left a GL error behind: {after}"


@pytest.fixture(scope="session")
def offscreen(gl_ctx: Any) -> Iterator[Callable[..., Any]]:
    """Factory ``offscreen(width, height, dtype="u1")`` of renderers sharing ``gl_ctx``.

    Renderers are cached per (width, height, dtype), so programs and textures are reused
    across tests; all are released at the end of the session.
    """
    from voxwarp.render.offscreen import OffscreenRenderer

    made: dict[tuple[int, int, str], Any] = {}

    def make(width: int, height: int, dtype: str = "u1") -> Any:
        key = (int(width), int(height), dtype)
        if key not in made:
            made[key] = OffscreenRenderer(width, height, ctx=gl_ctx, dtype=dtype)
        return made[key]

    yield make
    for r in made.values():
        r.release()


# ---------------------------------------------------------------------- golden images
def _to_u8(image: np.ndarray) -> np.ndarray:
    a = np.asarray(image)
    if a.dtype == np.uint8:
        return a
    return np.clip(np.rint(np.asarray(a, np.float64) * 255.0), 0, 255).astype(np.uint8)


def _write_png(path: Path, image: np.ndarray) -> None:
    import OpenImageIO as oiio

    a = np.ascontiguousarray(_to_u8(image))
    if a.ndim == 2:
        a = a[:, :, None]
    h, w, c = a.shape
    path.parent.mkdir(parents=True, exist_ok=True)
    spec = oiio.ImageSpec(w, h, c, "uint8")
    spec.attribute("oiio:UnassociatedAlpha", 1)  # store RGBA as given, no (un)premultiply
    out = oiio.ImageOutput.create(str(path))
    if out is None or not out.open(str(path), spec):
        raise OSError(f"cannot write {path}: {oiio.geterror()}")
    ok = out.write_image(a)
    out.close()
    if not ok:
        raise OSError(f"cannot write {path}: {oiio.geterror()}")


def _read_png(path: Path) -> np.ndarray:
    import OpenImageIO as oiio

    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(str(path), config)
    if inp is None:
        raise OSError(f"cannot read {path}: {oiio.geterror()}")
    a = inp.read_image("uint8")
    inp.close()
    return np.asarray(a, dtype=np.uint8).reshape(inp.spec().height, inp.spec().width, -1)


@pytest.fixture
def golden(request: pytest.FixtureRequest) -> Callable[..., None]:
    """``golden(name, image, tol, *, fraction=1.0, max_abs=None)``.

    ``image`` is (H, W, C) uint8 or float in [0, 1]; it is compared in 8-bit units with
    ``tests/golden/NAME.png``: at least ``fraction`` of the pixels must have every channel
    within ``tol`` (in [0, 1] units) and no channel may differ by more than ``max_abs``
    (default ``tol``). With ``--regenerate-golden`` the file is (re)written and the test
    skips with a note.
    """
    regenerate = request.config.getoption("--regenerate-golden")

    def check(
        name: str,
        image: np.ndarray,
        tol: float,
        *,
        fraction: float = 1.0,
        max_abs: float | None = None,
    ) -> None:
        path = GOLDEN_DIR / f"{name}.png"
        actual = _to_u8(image)
        if regenerate:
            _write_png(path, actual)
            pytest.skip(f"golden image regenerated: {path} (inspect it before committing)")
        if not path.exists():
            pytest.fail(
                f"no golden image {path}; create it with `pytest --regenerate-golden`"
                " and inspect it before committing"
            )
        expected = _read_png(path)
        if expected.shape != actual.shape:
            pytest.fail(f"{name}: image shape {actual.shape} != golden {expected.shape}")
        diff = np.abs(actual.astype(np.int16) - expected.astype(np.int16))
        limit = tol if max_abs is None else max_abs
        per_pixel = diff.max(axis=-1)
        ok_fraction = float(np.mean(per_pixel <= round(tol * 255)))
        worst = int(diff.max())
        if ok_fraction >= fraction and worst <= round(limit * 255):
            return
        FAILURE_DIR.mkdir(parents=True, exist_ok=True)
        _write_png(FAILURE_DIR / f"{name}_actual.png", actual)
        _write_png(FAILURE_DIR / f"{name}_expected.png", expected)
        vis = np.clip(diff[..., :3] * 8, 0, 255).astype(np.uint8)  # amplified 8x
        _write_png(FAILURE_DIR / f"{name}_diff.png", vis)
        pytest.fail(
            f"{name}: {ok_fraction:.2%} of pixels within {round(tol * 255)}/255 per channel"
            f" (need >= {fraction:.2%}); max abs diff {worst}/255"
            f" (tolerance {round(limit * 255)}/255). Images written to {FAILURE_DIR}/{name}_*.png"
        )

    return check
