"""Inline pictures: the PNG encoder, RenderedImage as a plain array, Scene previews."""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from voxwarp.errors import RenderError
from voxwarp.render.inline_image import RenderedImage, is_image, png_bytes, rendered


def _decode(data: bytes, tmp_path: Path) -> np.ndarray:
    """Decode PNG bytes with OpenImageIO (an independent decoder), straight alpha."""
    import OpenImageIO as oiio

    path = tmp_path / "x.png"
    path.write_bytes(data)
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(str(path), config)
    assert inp is not None, oiio.geterror()
    spec = inp.spec()
    a = np.asarray(inp.read_image("uint8")).reshape(spec.height, spec.width, -1)
    inp.close()
    return a


@pytest.mark.parametrize("channels", [1, 3, 4])
def test_png_bytes_round_trip(tmp_path: Path, channels: int) -> None:
    rng = np.random.default_rng(1)
    img = rng.integers(0, 256, (7, 13, channels), dtype=np.uint8)
    if channels == 4:
        img[..., 3] = 255  # opaque: premultiplied == straight
    assert np.array_equal(_decode(png_bytes(img), tmp_path), img)


def test_png_bytes_grey_float_and_premultiplied(tmp_path: Path) -> None:
    grey = np.linspace(0.0, 1.0, 12, dtype=np.float32).reshape(3, 4)
    out = _decode(png_bytes(grey), tmp_path)[..., 0]
    assert np.array_equal(out, np.rint(grey * 255).astype(np.uint8))
    # premultiplied (the renderer's) half-transparent red is stored straight: full red
    rgba = np.zeros((2, 2, 4), np.uint8)
    rgba[...] = (100, 0, 0, 100)
    assert np.array_equal(_decode(png_bytes(rgba), tmp_path)[0, 0], [255, 0, 0, 100])


def test_png_bytes_refuses_non_images() -> None:
    for bad in (np.zeros((4, 4, 2), np.uint8), np.zeros(5), np.zeros((0, 3, 3))):
        with pytest.raises(RenderError):
            png_bytes(bad)


def test_rendered_image_behaves_as_its_array() -> None:
    base = np.arange(2 * 3 * 4, dtype=np.uint8).reshape(2, 3, 4)
    img = rendered(base)
    assert isinstance(img, RenderedImage)
    assert np.shares_memory(img, base)
    assert type(img / 255) is np.ndarray
    assert type(img + 1) is np.ndarray
    assert isinstance(img.mean(), float)
    assert img.mean() == base.mean()
    assert np.array_equal(img, base)
    assert (img == base).all()
    assert type(np.asarray(img)) is np.ndarray
    assert img._repr_png_().startswith(b"\x89PNG")
    assert img[..., :3]._repr_png_() is not None  # still an image
    assert img[0, 0]._repr_png_() is None  # a pixel is not: text form
    assert not is_image(np.zeros((3, 3, 3), np.int64))


def test_render_and_slice_show_inline(offscreen, tmp_path: Path) -> None:
    from voxwarp import Scene, load_sample, write_image
    from voxwarp.io.images import read_image

    r = offscreen(64, 48)
    scene = Scene(load_sample("fish", shape=(48, 24, 20)), view="+z")
    img = r.render(scene)
    assert isinstance(img, RenderedImage)
    assert img.shape == (48, 64, 4)
    assert img.dtype == np.uint8
    assert img[..., :3].max() > 0
    assert np.array_equal(_decode(img._repr_png_(), tmp_path), np.asarray(img))
    write_image(tmp_path / "a.png", img)  # the writer takes it as any array
    assert np.array_equal(read_image(tmp_path / "a.png"), np.asarray(img))
    sl = r.render_slice(scene, "z")
    assert isinstance(sl.rgba, RenderedImage)
    assert sl.rgba._repr_png_() is not None


class _Shell:
    """What :func:`voxwarp.notebook.display.register` needs of an IPython shell."""

    def __init__(self) -> None:
        from IPython.core.formatters import DisplayFormatter

        self.display_formatter = DisplayFormatter()


@pytest.fixture
def preview_renderer(offscreen, monkeypatch: pytest.MonkeyPatch):
    from voxwarp.notebook import display
    from voxwarp.notebook.gl_thread import SameThread

    r = offscreen(display.PREVIEW_PX, display.PREVIEW_PX)
    monkeypatch.setitem(display._shared, "renderer", r)
    monkeypatch.setitem(display._shared, "gl", SameThread())  # the session context is here
    return r


def test_scene_shows_inline_once_registered(preview_renderer, tmp_path: Path) -> None:
    from voxwarp import Scene, load_sample
    from voxwarp.notebook.display import PREVIEW_PX, register

    scene = Scene(load_sample("fish", shape=(48, 24, 20)), view="+z")
    shell = _Shell()
    assert register(shell)
    data, _ = shell.display_formatter.format(scene)
    assert data["text/plain"].startswith("Scene(volume=")
    png = _decode(data["image/png"], tmp_path)
    assert png.shape[:2] == (PREVIEW_PX, PREVIEW_PX)
    assert np.array_equal(png, np.asarray(preview_renderer.render(scene)))


def test_scene_preview_failure_falls_back_to_text(monkeypatch: pytest.MonkeyPatch) -> None:
    from voxwarp import Scene, load_sample
    from voxwarp.notebook import display

    def broken(_scene: object, size: int = 0) -> None:
        raise RenderError("could not create a headless OpenGL 4.3 context through EGL")

    monkeypatch.setattr(display, "preview", broken)
    shell = _Shell()
    display.register(shell)
    scene = Scene(load_sample("fish", shape=(16, 8, 8)))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        data, _ = shell.display_formatter.format(scene)
    assert "image/png" not in data
    assert data["text/plain"].startswith("Scene(")
    assert any("no picture of the scene" in str(w.message) for w in caught)


def test_side_by_side() -> None:
    from voxwarp.notebook import side_by_side

    a = np.full((4, 3, 4), 200, np.uint8)
    a[..., 3] = 255
    b = np.full((2, 5, 3), 0.5, np.float32)
    out = side_by_side([a, b], gap=2)
    assert out.shape == (4, 3 + 2 + 5, 4)
    assert isinstance(out, RenderedImage)
    assert (out[:, :3, :3] == 200).all()
    assert (out[:2, 5:, :3] == 128).all()
    assert (out[2:, 5:, :3] == 0).all()
    assert (out[..., 3] == 255).all()


def test_load_ext_registers_the_scene_formatter() -> None:
    from voxwarp import Scene
    from voxwarp.notebook import load_ipython_extension

    shell = _Shell()
    png = shell.display_formatter.formatters["image/png"]
    assert Scene not in png.type_printers
    load_ipython_extension(shell)
    assert Scene in png.type_printers


def test_import_voxwarp_in_ipython_shows_scenes_inline(gl_ctx) -> None:
    """In a fresh IPython shell, ``import voxwarp`` alone (no voxwarp.notebook) makes a
    Scene format as a 256 x 256 PNG preview."""
    code = (
        "import sys\n"
        "from IPython.core.interactiveshell import InteractiveShell\n"
        "shell = InteractiveShell.instance()\n"
        "from voxwarp import Scene, load_sample\n"
        "assert 'voxwarp.notebook' not in sys.modules\n"
        "scene = Scene(load_sample('fish', shape=(32, 16, 16)))\n"
        "data, _ = shell.display_formatter.format(scene)\n"
        "png = data['image/png']\n"
        "assert png[:8] == b'\\x89PNG\\r\\n\\x1a\\n', png[:8]\n"
        "import struct; print(struct.unpack('>II', png[16:24]))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip() == "(256, 256)"
