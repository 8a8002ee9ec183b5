"""Tests of ``voxwarp render --chainmail`` (voxwarp.cli.main): headless 3D ChainMail deformation.

Error paths run in-process through ``voxwarp.cli.main.main`` and must fail before any GL work
(``no_rendering``). Rendering runs in a subprocess, as in ``test_cli.py``. Oracles: a
drag along +x moves the intensity centroid of an orthographic MIP seen from +z (+x to
the right) to the right; a saved scene renders the identical image again; relaxation
changes the image; a cut through the grid keeps the elements beyond it at rest (read
from the saved field).

Volume: a 16³ bright ball (radius 5 voxels) in air, as in ``test_cli_massspring.py``;
the 7³ element grid puts element (3, 3, 3) at the ball's centre (spacing 16/6 mm).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.cli.test_cli import (  # noqa: F401  (fixtures used by name)
    _keep_warning_state,
    assert_render_refused,
    no_rendering,
    render,
)
from tests.cli.test_cli_massspring import VIEW, ball_file, centroid_x, grey  # noqa: F401
from voxwarp.cli.main import main
from voxwarp.io.images import read_image

DRAG = ["--chainmail", "7", "--anchor", "corners", "--drag", "3,3,3:3,0,0"]


# ---------------------------------------------------------------------- errors
@pytest.mark.usefixtures("no_rendering")
@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--chainmail", "x"], "expected N or NX,NY,NZ"),
        (["--chainmail", "200"], "out of range"),
        (["--chainmail", "8", "--relax", "-1"], "relaxation steps >= 0"),
        (["--chainmail", "8", "--relax", "two"], "relaxation steps >= 0"),
        (["--chainmail", "8", "--variant", "schill"], "invalid choice"),
        (["--chainmail", "8", "--anchor", "box"], "invalid choice: 'box'"),
        (["--chainmail", "8", "--fix-outside", "-2"], "expected a radius in mm >= 0"),
        (["--chainmail", "8", "--cut", "1,2,3"], "expected PX,PY,PZ:NX,NY,NZ[:RADIUS]"),
        (["--chainmail", "8", "--cut", "1,2:1,0,0"], "expected PX,PY,PZ:NX,NY,NZ"),
        (["--chainmail", "8", "--cut", "1,2,3:0,0,0"], "the normal must not be 0,0,0"),
        (["--chainmail", "8", "--cut", "1,2,3:1,0,0:0"], "the radius must be > 0 mm"),
        (["--chainmail", "8", "--cut", "1,2,3:1,0,0:nan"], "numbers must be finite"),
        (["--chainmail", "8", "--cut", "-1,2,3:1,0,0:1:2"], "expected PX,PY,PZ"),
        (["--chainmail", "8", "--join", "1,2,3"], "expected PX,PY,PZ:NX,NY,NZ[:RADIUS]"),
    ],
)
def test_bad_syntax_is_an_argparse_error(
    ball_file: Path,  # noqa: F811
    capsys: pytest.CaptureFixture,
    args: list[str],
    message: str,
) -> None:
    with pytest.raises(SystemExit) as info:
        main(["render", str(ball_file), *args])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert message in err
    assert "Traceback" not in err


@pytest.mark.usefixtures("no_rendering")
@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--relax", "2"], "--relax needs --chainmail: add --chainmail N"),
        (["--cut", "8,8,8:1,0,0"], "--cut needs --chainmail"),
        (["--join", "8,8,8:1,0,0"], "--join needs --chainmail"),
        (["--variant", "gibson"], "--variant needs --chainmail"),
        (["--drag", "1,1,1:0,0,5"], "--drag needs --massspring: add --massspring N"),
        (["--drag", "1,1,1:0,0,5"], "or --chainmail N"),
        (
            ["--massspring", "8", "--chainmail", "8"],
            "--massspring and --chainmail cannot be combined",
        ),
        (["--chainmail", "8", "--settle"], "--settle is a mass-spring option (--massspring)"),
        (["--chainmail", "8", "--steps", "10"], "--steps is a mass-spring option"),
        (["--chainmail", "8", "--integrator", "explicit"], "--integrator is a mass-spring"),
        (["--chainmail", "8", "--no-shear"], "--shear/--no-shear is a mass-spring option"),
        (["--chainmail", "8", "--bend"], "--bend is a mass-spring option"),
        (["--massspring", "8", "--relax", "1"], "--relax is a ChainMail option (--chainmail)"),
        (["--massspring", "8", "--variant", "gibson"], "--variant is a ChainMail option"),
        (["--massspring", "8", "--cut", "8,8,8:1,0,0"], "--cut is a ChainMail option"),
        (["--massspring", "8", "--join", "8,8,8:1,0,0"], "--join is a ChainMail option"),
        (
            ["--chainmail", "8", "--drag", "8,3,3:1,0,0"],
            "--drag 8,3,3:1,0,0: element (8, 3, 3) is outside the 8x8x8 grid; indices run 0..7",
        ),
        (
            ["--chainmail", "8", "--anchor", "corners", "--drag", "7,7,0:1,0,0"],
            "(7, 7, 0) is on the 8x8x8 grid's corners (--anchor corners fixes it)",
        ),
        (
            ["--chainmail", "8", "--anchor", "shell", "--drag", "7,3,3:1,0,0"],
            "(7, 3, 3) is on the 8x8x8 grid's shell",
        ),
        (["--chainmail", "8", "--fix", "0..8,0,0"], "--fix 0..8,0,0: reaches outside"),
        (
            ["--chainmail", "8", "--fix", "2,2,2", "--drag", "2,2,2:1,0,0"],
            "(2, 2, 2) is fixed by --fix",
        ),
        (
            ["--chainmail", "8", "--cut", "50,8,8:1,0,0"],
            "--cut 50,8,8:1,0,0: the plane crosses no link of the 8x8x8 grid, whose"
            " elements span x -0.5..15.5, y -0.5..15.5, z -0.5..15.5 mm",
        ),
        (
            ["--chainmail", "8", "--cut", "7.5,7.5,7.5:1,0,0:0.1"],
            "the disk of radius 0.1 mm crosses no link",
        ),
        (
            ["--chainmail", "8", "--join", "7.5,7.5,7.5:1,0,0"],
            "--join 7.5,7.5,7.5:1,0,0: the plane crosses no link that a --cut removed",
        ),
        (  # the cut removes links along x, the join's plane crosses links along y
            ["--chainmail", "8", "--cut", "7.5,7.5,7.5:1,0,0", "--join", "7.5,7.5,7.5:0,1,0"],
            "--join 7.5,7.5,7.5:0,1,0: the plane crosses no link that a --cut removed",
        ),
    ],
)
def test_bad_options_are_one_line_errors(
    ball_file: Path,  # noqa: F811
    tmp_path: Path,
    capsys: pytest.CaptureFixture,
    args: list[str],
    message: str,
) -> None:
    assert_render_refused(ball_file, tmp_path, capsys, args, message)


def test_help_documents_chainmail(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit):
        main(["render", "--help"])
    out = capsys.readouterr().out
    for opt in ("--chainmail", "--relax", "--variant", "--cut", "--join", "3D ChainMail options"):
        assert opt in out


# ---------------------------------------------------------------------- rendering
@pytest.fixture(scope="module")
def drags(gl_ctx: Any, ball_file: Path, tmp_path_factory: pytest.TempPathFactory) -> dict:  # noqa: F811
    """Renders shared by the tests below: the ball at rest, dragged 3 mm along +x
    (relax 0, its scene saved) and dragged with 4 relaxation steps."""
    folder = tmp_path_factory.mktemp("cli_chainmail")
    out: dict[str, Any] = {"folder": folder}
    render(str(ball_file), "-o", str(folder / "rest.png"), *VIEW)
    out["relax0"] = render(
        str(ball_file),
        "-o",
        str(folder / "relax0.png"),
        "--save-scene",
        str(folder / "relax0.json"),
        *VIEW,
        *DRAG,
    )
    out["relax4"] = render(
        str(ball_file), "-o", str(folder / "relax4.png"), *VIEW, *DRAG, "--relax", "4"
    )
    return out


@pytest.mark.gl
@pytest.mark.slow
def test_drag_along_x_moves_the_centroid_right(gl_ctx: Any, drags: dict) -> None:
    err = drags["relax0"].stderr
    assert "chainmail: 7x7x7 cpu enhanced, 1 dragged," in err
    assert " elements touched in " in err
    a, b = grey(drags["folder"] / "rest.png"), grey(drags["folder"] / "relax0.png")
    assert abs(centroid_x(a) - 63.5) < 0.5
    # 3 mm of 16 mm across 128 px is 24 px; the links' slack (2/3 mm per link) lets
    # the field fall off around the dragged element, so the ball's centroid moves less
    shift = centroid_x(b) - centroid_x(a)
    assert 5.0 < shift < 24.0, shift  # measured: 9.0 px
    rows = np.arange(128.0)
    assert abs((b.sum(axis=1) * rows).sum() / b.sum() - 63.5) < 0.5  # nothing moves along y


@pytest.mark.gl
def test_saved_scene_renders_the_identical_image(gl_ctx: Any, drags: dict, tmp_path: Path) -> None:
    scene = drags["folder"] / "relax0.json"
    (w,) = json.loads(scene.read_text())["warps"]
    assert w["type"] == "offset_field"
    assert w["inverse"] == "baked"
    u = np.asarray(w["displacements"])
    assert u.shape == (7, 7, 7, 3)
    np.testing.assert_allclose(u[3, 3, 3], [3.0, 0.0, 0.0])
    model = w["model"]
    assert model["type"] == "chainmail"
    assert model["variant"] == "enhanced"
    assert model["relax_steps"] == 0
    assert model["held"] == [{"index": [3, 3, 3], "offset": [3.0, 0.0, 0.0]}]
    assert model["grid"]["shape"] == [7, 7, 7]
    assert model["cuts"] == []
    again = tmp_path / "again.png"
    render(str(scene), "-o", str(again), "--size", "128x128")
    a, b = read_image(drags["folder"] / "relax0.png"), read_image(again)
    assert a[..., :3].max() > 0
    np.testing.assert_array_equal(a, b)


@pytest.mark.gl
def test_relax_changes_the_image(gl_ctx: Any, drags: dict) -> None:
    assert "relax 4 steps in " in drags["relax4"].stderr
    a, b = grey(drags["folder"] / "relax0.png"), grey(drags["folder"] / "relax4.png")
    diff = np.abs(a - b)
    assert diff.max() >= 10, diff.max()  # measured: 26 (of 255)
    assert diff.mean() > 0.3, diff.mean()  # measured: 1.15
    # relaxation spreads the drag to more elements: the ball moves a little further
    rest = grey(drags["folder"] / "rest.png")
    assert centroid_x(b) > centroid_x(a)  # measured: 9.5 px from rest, against 9.0
    assert centroid_x(b) > centroid_x(rest) + 5.0


@pytest.mark.gl
@pytest.mark.slow
def test_cut_keeps_the_far_side_at_rest(
    gl_ctx: Any,
    ball_file: Path,  # noqa: F811
    drags: dict,
    tmp_path: Path,
) -> None:
    # drag element (2, 3, 3) along y: without a cut its links' shear pulls the elements
    # beyond x = 8.5 mm along; the plane x = 8.5 mm between element layers 3 (7.5 mm)
    # and 4 (10.2 mm) removes the links across, and those elements stay at rest
    fields, images = {}, {}
    for name, extra in (("whole", []), ("cut", ["--cut", "8.5,0,0:1,0,0"])):
        scene = tmp_path / f"{name}.json"
        images[name] = grey_path = tmp_path / f"{name}.png"
        proc = render(
            str(ball_file),
            "-o",
            str(grey_path),
            "--save-scene",
            str(scene),
            *VIEW,
            "--chainmail",
            "7",
            "--anchor",
            "corners",
            "--drag",
            "2,3,3:0,4,0",
            "--grid-margin",  # the layers at 7.5 and 10.2 mm are those of the volume's box
            "0",
            *extra,
        )
        (w,) = json.loads(scene.read_text())["warps"]
        fields[name] = np.asarray(w["displacements"])
        if name == "cut":
            assert ", 49 links cut;" in proc.stderr  # the 7 x 7 links along x
            assert {(c[0], c[3]) for c in w["model"]["cuts"]} == {(3, 0)}
    assert np.abs(fields["whole"][4:]).max() > 0.5  # without the cut the far side moves
    np.testing.assert_array_equal(fields["cut"][4:], 0.0)
    np.testing.assert_allclose(fields["cut"][2, 3, 3], [0.0, 4.0, 0.0])
    # rendered: right of layer 4 (x > 10.2 mm, column (x + 0.5) * 8 > 85) the cut
    # image is the undeformed one, the uncut one is not
    right = slice(88, 128)
    rest = grey(drags["folder"] / "rest.png")[:, right]
    whole, cut = grey(images["whole"])[:, right], grey(images["cut"])[:, right]
    assert np.abs(whole - rest).max() > 20
    np.testing.assert_array_equal(cut, rest)


@pytest.mark.gl
@pytest.mark.slow
def test_gpu_and_cpu_backends_give_nearly_the_same_image(
    gl_ctx: Any,
    ball_file: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    images = {}
    for backend in ("cpu", "gpu"):
        out = tmp_path / f"{backend}.png"
        proc = render(str(ball_file), "-o", str(out), *VIEW, *DRAG, "--backend", backend)
        assert f"chainmail: 7x7x7 {backend}" in proc.stderr
        # nothing holds this drag back (the CPU moves the element all the way)
        assert "went only" not in proc.stderr, f"{backend}: {proc.stderr}"
        images[backend] = read_image(out).astype(np.int64)
    diff = np.abs(images["cpu"] - images["gpu"])
    # float32 GPU solver vs float64 CPU solver, the same half-float field texture
    assert diff.max() <= 4, diff.max()
    assert diff.mean() < 0.05, diff.mean()
    assert images["gpu"][..., :3].max() > 100
