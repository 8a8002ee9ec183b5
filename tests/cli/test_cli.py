"""Smoke tests of the ``voxwarp`` command line (voxwarp.cli.main).

``info``, ``samples`` and the error paths run in-process through ``voxwarp.cli.main.main``.
Commands that render run in a subprocess (``python -m voxwarp.cli.main``): ``render`` creates and
releases its own EGL context, and doing that in the test process would leave the
session's shared context (``gl_ctx``) no longer current, corrupting later GL tests (see
``test_in_process_render_leaves_other_contexts_usable``). Rendering tests request
``gl_ctx`` only so that they skip, like every GL test, where EGL is missing.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.run_cli import run_cli
from voxwarp.cli.main import main
from voxwarp.core.volume import Volume
from voxwarp.io.images import read_image
from voxwarp.io.volumes import save_volume

REPO = Path(__file__).resolve().parents[2]
SHAPE = (24, 20, 16)


@pytest.fixture(autouse=True)
def _keep_warning_state(monkeypatch: pytest.MonkeyPatch) -> None:
    """main() replaces warnings.formatwarning for good; undo it after each test."""
    monkeypatch.setattr(warnings, "formatwarning", warnings.formatwarning)


class _NoRendering:
    def __init__(self, *args: Any, **kwargs: Any) -> None:
        raise AssertionError("this test must fail before rendering")


@pytest.fixture
def no_rendering(monkeypatch: pytest.MonkeyPatch) -> None:
    """In-process main() must not create a GL context (see the module docstring)."""
    monkeypatch.setattr("voxwarp.render.offscreen.OffscreenRenderer", _NoRendering)


def ball() -> np.ndarray:
    """A smooth bright ball in HU (-1000 outside, 1500 at the centre), shape (24, 20, 16)."""
    idx = np.indices(SHAPE, dtype=np.float64)
    centre = (np.asarray(SHAPE) - 1)[:, None, None, None] / 2
    r = np.sqrt(((idx - centre) ** 2).sum(axis=0))
    return np.clip(1500 - 250 * r, -1000, 1500).astype(np.int16)


@pytest.fixture(scope="module")
def volume_files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("cli_volumes")
    vol = Volume(ball(), spacing=(1.0, 1.0, 1.5), name="ball")
    return {
        "npz": save_volume(vol, folder / "ball.npz"),
        "nrrd": save_volume(vol, folder / "ball.nrrd"),
    }


def render(*args: str) -> subprocess.CompletedProcess:
    proc = run_cli("render", *args)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    return proc


def assert_render_refused(
    volume: Path, tmp_path: Path, capsys: pytest.CaptureFixture, args: list[str], message: str
) -> None:
    """``voxwarp render VOLUME ... ARGS`` exits 2 with one line naming ``message`` and
    writes no image."""
    out = tmp_path / "x.png"
    assert main(["render", str(volume), "-o", str(out), "--tf", "grayscale", *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("voxwarp: error:")
    assert err.count("\n") == 1
    assert message in err
    assert not out.exists()


def assert_not_blank(img: np.ndarray) -> None:
    rgb = img[..., :3].astype(np.float64)
    assert rgb.max() > 0, "the image is black"
    assert rgb.std() > 0, "the image is one flat colour"


# ---------------------------------------------------------------------- info
@pytest.mark.parametrize("fmt", ["npz", "nrrd"])
def test_info_prints_dims_and_dtype(
    volume_files: dict[str, Path], capsys: pytest.CaptureFixture, fmt: str
) -> None:
    assert main(["info", str(volume_files[fmt])]) == 0
    out = capsys.readouterr().out
    assert "(24, 20, 16)" in out
    assert "int16" in out
    assert "ball" in out


def test_info_json(volume_files: dict[str, Path], capsys: pytest.CaptureFixture) -> None:
    assert main(["info", str(volume_files["npz"]), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    data = ball()
    assert info["dims"] == list(SHAPE)
    assert info["dtype"] == "int16"
    assert info["voxels"] == data.size
    assert info["min"] == data.min()
    assert info["max"] == data.max()
    assert info["spacing_mm"] == [1.0, 1.0, 1.5]


def test_info_with_downsample_and_spacing(
    volume_files: dict[str, Path], capsys: pytest.CaptureFixture
) -> None:
    args = ["info", str(volume_files["npz"]), "--json", "--downsample", "2"]
    with pytest.warns(UserWarning, match="downsampled by 2"):
        assert main([*args, "--spacing", "2", "3", "4"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["dims"] == [12, 10, 8]
    assert info["spacing_mm"] == [4.0, 6.0, 8.0]  # overridden, then doubled


def test_info_of_a_scene_json_describes_its_volume(
    volume_files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    from voxwarp.io.volumes import load_volume
    from voxwarp.scene import Scene

    Scene(load_volume(volume_files["npz"])).save(tmp_path / "scene.json")
    assert main(["info", str(tmp_path / "scene.json"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["dims"] == list(SHAPE)


# ---------------------------------------------------------------------- errors
@pytest.mark.usefixtures("no_rendering")
@pytest.mark.parametrize("command", ["info", "render"])
def test_missing_input_file(tmp_path: Path, capsys: pytest.CaptureFixture, command: str) -> None:
    missing = tmp_path / "no_such_volume.npz"
    assert (
        main([command, str(missing), *(["-o", str(tmp_path / "x.png")] * (command == "render"))])
        == 2
    )
    err = capsys.readouterr().err
    assert err.startswith("voxwarp: error:")
    assert "no_such_volume.npz" in err
    assert "Traceback" not in err
    assert not (tmp_path / "x.png").exists()


def test_missing_input_file_in_a_subprocess(tmp_path: Path) -> None:
    proc = run_cli("info", str(tmp_path / "gone.nrrd"))
    assert proc.returncode == 2
    assert proc.stderr.startswith("voxwarp: error:")
    assert "gone.nrrd" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stdout == ""


@pytest.mark.parametrize(
    ("size", "message"),
    [("big", "512x512"), ("64", "512x512"), ("0x10", "1..16384"), ("64x99999", "1..16384")],
)
def test_bad_size_is_an_argparse_error(
    volume_files: dict[str, Path], capsys: pytest.CaptureFixture, size: str, message: str
) -> None:
    with pytest.raises(SystemExit) as info:
        main(["render", str(volume_files["npz"]), "--size", size])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "--size" in err
    assert message in err


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--view", "top"], "AZIMUTH,ELEVATION"),
        (["--mode", "radiograph"], "invalid choice"),
        (["--projection", "fisheye"], "invalid choice"),
    ],
)
def test_bad_render_options_are_argparse_errors(
    volume_files: dict[str, Path], capsys: pytest.CaptureFixture, args: list[str], message: str
) -> None:
    with pytest.raises(SystemExit) as info:
        main(["render", str(volume_files["npz"]), *args])
    assert info.value.code == 2
    assert message in capsys.readouterr().err


@pytest.mark.usefixtures("no_rendering")
@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--tf", "rainbowz"], ("rainbowz", "ct-bone")),
        (["--step", "-1"], ("step",)),
        (["--step", "1000"], ("step", "100")),
        pytest.param(["--step", "0"], ("step",)),
        (["--zoom", "-1"], ("zoom",)),
        pytest.param(["--zoom", "0"], ("zoom",)),
        (["--window", "0", "-5"], ("window width",)),
        (["--tf", "missing_tf.json"], ("missing_tf.json",)),
    ],
)
def test_bad_scene_options_are_clean_errors(
    volume_files: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture,
    args: list[str],
    needles: tuple[str, ...],
) -> None:
    out = tmp_path / "x.png"
    assert main(["render", str(volume_files["npz"]), "-o", str(out), *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("voxwarp: error:")
    for needle in needles:
        assert needle in err
    assert not out.exists()


@pytest.mark.usefixtures("no_rendering")
def test_bad_transfer_function_file(
    volume_files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    tf = tmp_path / "tf.json"
    tf.write_text('{"points": [[0, 2, 0, 0, 0]]}')
    assert main(["render", str(volume_files["npz"]), "--tf", str(tf)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("voxwarp: error:")
    assert "[0, 1]" in err


def test_no_command_is_an_argparse_error(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as info:
        main([])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1  # one line, no usage block
    assert err.startswith("voxwarp: error: the following arguments are required: command")
    assert "(see 'voxwarp --help')" in err


@pytest.mark.usefixtures("no_rendering")
@pytest.mark.parametrize("view", ["-y", "-30,20"])
def test_negative_views_can_follow_the_view_option(
    volume_files: dict[str, Path], tmp_path: Path, view: str
) -> None:
    # --tf rainbowz (neither preset nor colour map) fails cleanly before any rendering
    rc = main(["render", str(volume_files["npz"]), "--view", view, "--tf", "rainbowz"])
    assert rc == 2


# ---------------------------------------------------------------------- samples
def test_samples_lists_names(capsys: pytest.CaptureFixture) -> None:
    from voxwarp.io.samples import sample_names

    names = sample_names()
    assert main(["samples"]) == 0
    lines = capsys.readouterr().out.splitlines()
    first = [line.split()[0] for line in lines]  # sample:NAME, then its kind
    assert first[: len(names)] == [f"sample:{n}" for n in names]  # the volumes first
    assert all(line.split()[1] == "volumes" for line in lines[: len(names)])
    assert names, "no samples listed"


# ---------------------------------------------------------------------- render (subprocess)
@pytest.mark.gl
def test_render_png_of_the_requested_size(
    gl_ctx: Any, volume_files: dict[str, Path], tmp_path: Path
) -> None:
    out = tmp_path / "dvr.png"
    proc = render(str(volume_files["npz"]), "-o", str(out), "--size", "64x48")
    assert str(out) in proc.stdout
    img = read_image(out)
    assert img.shape == (48, 64, 4)
    assert img.dtype == np.uint8
    assert_not_blank(img)
    assert list(tmp_path.iterdir()) == [out]  # no temp files left


@pytest.mark.gl
def test_render_mip_orthographic_from_plus_z(
    gl_ctx: Any, volume_files: dict[str, Path], tmp_path: Path
) -> None:
    out = tmp_path / "mip.png"
    args = ["--mode", "mip", "--projection", "orthographic", "--view", "+z", "--size", "40x40"]
    render(str(volume_files["nrrd"]), "-o", str(out), *args)
    img = read_image(out)
    assert img.shape == (40, 40, 4)
    assert_not_blank(img)
    grey = img[..., :3].astype(float).mean(axis=-1)
    # the ball is brightest through its centre, which projects to the image centre
    assert grey[18:22, 18:22].mean() > grey[0:3, 0:3].mean() + 100
    assert grey[18:22, 18:22].mean() > 200
    # symmetric ball, orthographic: left-right and top-bottom mirror images (8-bit, ~1 level)
    assert np.abs(grey - grey[:, ::-1]).max() <= 3
    assert np.abs(grey - grey[::-1, :]).max() <= 3


@pytest.mark.gl
def test_render_with_azimuth_elevation_view(
    gl_ctx: Any, volume_files: dict[str, Path], tmp_path: Path
) -> None:
    out = tmp_path / "view.png"
    render(str(volume_files["npz"]), "-o", str(out), "--view", "30,20", "--size", "48x32")
    img = read_image(out)
    assert img.shape == (32, 48, 4)
    assert_not_blank(img)


@pytest.mark.gl
def test_scene_json_reproduces_the_image_exactly(
    gl_ctx: Any, volume_files: dict[str, Path], tmp_path: Path
) -> None:
    first, second, scene = tmp_path / "a.png", tmp_path / "b.png", tmp_path / "s" / "scene.json"
    args = ["--size", "40x32", "--view=-x", "--mode", "dvr", "--step", "0.7", "--seed", "5"]
    proc = render(str(volume_files["npz"]), "-o", str(first), "--save-scene", str(scene), *args)
    assert str(scene) in proc.stdout
    d = json.loads(scene.read_text())
    assert d["format"] == "voxwarp-scene"
    assert d["view"] == "-x"
    assert d["step"] == 0.7
    assert d["seed"] == 5
    render(str(scene), "-o", str(second), "--size", "40x32")
    a, b = read_image(first), read_image(second)
    assert_not_blank(a)
    np.testing.assert_array_equal(a, b)


@pytest.mark.gl
def test_render_exr_writes_float_data(
    gl_ctx: Any, volume_files: dict[str, Path], tmp_path: Path
) -> None:
    out = tmp_path / "x.exr"
    render(str(volume_files["npz"]), "-o", str(out), "--size", "32x24", "--view", "+y")
    img = read_image(out)
    assert img.dtype == np.float32
    assert img.shape == (24, 32, 4)
    assert np.all(np.isfinite(img))
    assert img.min() >= 0.0
    assert img.max() <= 1.0 + 1e-6
    assert_not_blank(img)
    # float precision: not everything sits on the 8-bit grid
    off_grid = np.abs(img * 255 - np.rint(img * 255)) > 1e-3
    assert off_grid.any()


@pytest.mark.gl
def test_in_process_render_leaves_other_contexts_usable(
    gl_ctx: Any, volume_files: dict[str, Path], tmp_path: Path
) -> None:
    script = textwrap.dedent(
        f"""
        import numpy as np
        from voxwarp.cli.main import main
        from voxwarp.render.context import create_context
        from voxwarp.render.offscreen import OffscreenRenderer
        from voxwarp.scene import Scene
        from voxwarp.core.volume import Volume

        ctx = create_context()
        r = OffscreenRenderer(16, 16, ctx=ctx)
        vol = Volume(np.linspace(0, 1, 512, dtype=np.float32).reshape(8, 8, 8))
        scene = Scene(vol, transfer_function="grayscale", jitter=False)
        before = r.render(scene)
        assert main(["render", {str(volume_files["npz"])!r}, "-o", {str(tmp_path / "y.png")!r},
                     "--size", "16x16"]) == 0
        after = r.render(scene)
        error = ctx.error
        assert error == "GL_NO_ERROR", error
        assert np.array_equal(before, after), "the first context renders differently"
        """
    )
    proc = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        cwd=REPO,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]


@pytest.mark.gl
@pytest.mark.slow
def test_demo_writes_every_mode_and_a_mass_spring_bend(tmp_path: Path) -> None:
    """`voxwarp demo` (what `make run` does): every mode of the bundled CT, plus the same
    dvr view bent by a settled mass-spring drag and by a wire, and scenes that reproduce
    them."""
    out = tmp_path / "out"
    assert main(["demo", "--out", str(out), "--size", "96x96"]) == 0
    images = {p.stem: read_image(p) for p in out.glob("*.png")}
    modes = ("dvr", "mip", "minip", "average", "xray", "flm", "iso")
    bends = {"stent_dvr_massspring", "stent_dvr_wires"}
    assert set(images) == {f"stent_{m}" for m in modes} | bends
    for name, img in images.items():
        assert img.shape == (96, 96, 4), name
    for m in ("dvr", "mip", "average", "iso"):  # minip/flm may be dark by design
        assert images[f"stent_{m}"][..., :3].max() > 50, m
    plain = images["stent_dvr"].astype(float)
    bent = images["stent_dvr_massspring"].astype(float)
    # the bend moves the picture, but it is the same object: most of it stays put
    # (measured: 13% of the pixels change by more than 24/255)
    changed = np.abs(bent - plain).max(axis=-1) > 24
    assert 0.01 < changed.mean() < 0.5
    # the saved scene holds the field and the model and renders the same image
    scene = json.loads((out / "stent_massspring_scene.json").read_text(encoding="utf-8"))
    assert scene["warps"][0]["model"]["type"] == "massspring"
    again = tmp_path / "again.png"
    scene_path = out / "stent_massspring_scene.json"
    assert main(["render", str(scene_path), "--size", "96x96", "-o", str(again)]) == 0
    np.testing.assert_array_equal(read_image(again), images["stent_dvr_massspring"])
    # the wire bend too: a different picture of the same object, saved as wires only
    wired = images["stent_dvr_wires"].astype(float)
    changed = np.abs(wired - plain).max(axis=-1) > 24
    assert 0.01 < changed.mean() < 0.5
    scene_path = out / "stent_wires_scene.json"
    scene = json.loads(scene_path.read_text(encoding="utf-8"))
    assert scene["warps"][0]["type"] == "wires"
    assert main(["render", str(scene_path), "--size", "96x96", "-o", str(again)]) == 0
    np.testing.assert_array_equal(read_image(again), images["stent_dvr_wires"])
