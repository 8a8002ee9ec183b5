"""The command line's shared conventions, checked across its commands.

``--window`` takes ``LEVEL,WIDTH`` (and ``LEVEL WIDTH``) wherever it exists; every command
that writes a file or folder names it with ``-o``/``--output``; ``--save-scene`` writes a
scene that reopens from any working directory; ``--help`` says what voxwarp is and has a
line per command; a closed stdout pipe ends the command quietly. Renders run in a child
process (see tests/cli/test_cli.py's docstring).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.run_cli import REPO
from voxwarp.cli.main import CLOSED_PIPE_EXIT, build_parser
from voxwarp.cli.options import join_negative_views
from voxwarp.core.volume import Volume
from voxwarp.io.images import read_image
from voxwarp.io.volumes import save_volume


def voxwarp(
    *args: str, cwd: Path, stdout: Any = subprocess.PIPE, timeout: float = 120
) -> subprocess.CompletedProcess:
    """``voxwarp ARGS...`` in a child process started in ``cwd``."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run(
        [sys.executable, "-m", "voxwarp", *args],
        cwd=cwd,
        env=env,
        stdout=stdout,
        stderr=subprocess.PIPE,
        text=True,
        timeout=timeout,
        check=False,
    )


def ball(path: Path) -> Path:
    """A small CT-like ball (HU -1000 outside, up to 1500 inside) saved as ``path``."""
    shape = (24, 20, 16)
    idx = np.indices(shape, dtype=np.float64)
    centre = (np.asarray(shape) - 1)[:, None, None, None] / 2
    r = np.sqrt((((idx - centre) / 7.0) ** 2).sum(axis=0))
    data = (-1000 + 2500 * np.clip(1.2 - r, 0, 1)).astype(np.int16)
    path.parent.mkdir(parents=True, exist_ok=True)
    return save_volume(Volume(data, spacing=(1.0, 1.0, 1.5), name="ball"), path)


def parse(*argv: str) -> argparse.Namespace:
    """``argv`` parsed as :func:`voxwarp.cli.main.main` parses it."""
    return build_parser(bench=False).parse_args(join_negative_views(list(argv)))


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


# ------------------------------------------------------------------------------ --window
@pytest.mark.parametrize("command", ["render", "slice"])
@pytest.mark.parametrize(
    ("forms", "want"),
    [
        ((["--window", "40,400"], ["--window", "40", "400"], ["--window=40,400"]), (40, 400)),
        (
            (["--window", "-500,1500"], ["--window", "-500", "1500"], ["--window=-500,1500"]),
            (-500, 1500),
        ),
    ],
)
def test_window_takes_level_comma_width_and_two_values(
    command: str, forms: tuple[list[str], ...], want: tuple[float, float]
) -> None:
    """Every command with a window takes ``LEVEL,WIDTH`` and ``LEVEL WIDTH``, negative
    levels too, before or after INPUT, and reads them alike."""
    for form in forms:
        after = parse(command, "v.nii", *form)
        before = parse(command, *form, "v.nii")
        assert tuple(after.window) == want, form
        assert before.window == after.window, form
        assert before.input == "v.nii", form
    assert len({repr(parse(command, "v.nii", *f).window) for f in forms}) == 1


def test_every_window_option_takes_both_forms() -> None:
    """No command has a ``--window`` that the test above leaves out."""
    with_window = {
        name
        for name, p in subcommands(build_parser(bench=False)).items()
        if "--window" in p._option_string_actions
    }
    assert with_window == {"render", "slice"}


@pytest.mark.gl
def test_render_window_forms_give_the_same_image(gl_ctx: Any, tmp_path: Path) -> None:
    vol = ball(tmp_path / "ball.npz")
    common = ["--mode", "mip", "--size", "32x32", "--no-jitter"]
    images = []
    for i, form in enumerate((["--window", "-500,1500"], ["--window", "-500", "1500"])):
        out = tmp_path / f"w{i}.png"
        proc = voxwarp("render", str(vol), *form, *common, "-o", str(out), cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr
        images.append(read_image(out))
    np.testing.assert_array_equal(images[0], images[1])
    assert images[0][..., :3].max() > 0


# ------------------------------------------------------------------------- -o / --output
def test_every_written_output_is_named_by_o_and_output() -> None:
    """A command that writes a file or folder names it with ``-o`` and ``--output``."""
    missing = []
    for name, p in subcommands(build_parser(bench=False)).items():
        for action in p._actions:
            if action.dest in ("output", "out") and not {"-o", "--output"} <= set(
                action.option_strings
            ):
                missing.append(f"{name} {'/'.join(action.option_strings)}")
    assert not missing


@pytest.mark.parametrize(("command", "value"), [("demo", "figures"), ("reproduce", "report.md")])
def test_demo_and_reproduce_take_o_and_keep_out(command: str, value: str) -> None:
    forms = (["-o", value], ["--output", value], ["--out", value], [f"--out={value}"])
    assert {parse(command, *form).out for form in forms} == {value}


# ----------------------------------------------------------------------------- --save-scene
@pytest.mark.gl
def test_saved_scene_reopens_from_another_folder_without_a_warning(
    gl_ctx: Any, tmp_path: Path
) -> None:
    """Saved from one working directory into another folder (the volume under it), the
    scene renders from a third working directory: no warning, the same image."""
    ball(tmp_path / "project" / "volumes" / "ball.npz")
    first, second = tmp_path / "one", tmp_path / "two"
    first.mkdir()
    second.mkdir()
    common = ["--size", "32x32", "--mode", "mip", "--no-jitter"]
    proc = voxwarp(
        "render",
        "../project/volumes/ball.npz",
        *common,
        "-o",
        "a.png",
        "--save-scene",
        "../project/scene.json",
        cwd=first,
    )
    assert proc.returncode == 0, proc.stderr
    entry = json.loads((tmp_path / "project" / "scene.json").read_text())["volume"]["path"]
    assert entry == os.path.join("volumes", "ball.npz")  # relative to the scene's folder
    proc = voxwarp("render", "../project/scene.json", "--size", "32x32", "-o", "b.png", cwd=second)
    assert proc.returncode == 0, proc.stderr
    assert "warning" not in proc.stderr, proc.stderr
    np.testing.assert_array_equal(read_image(first / "a.png"), read_image(second / "b.png"))


@pytest.mark.gl
def test_saved_scene_naming_a_volume_outside_its_folder_opens_without_a_warning(
    gl_ctx: Any, tmp_path: Path
) -> None:
    """A volume outside the scene's folder is stored by its absolute path: the scene
    reopens from any working directory without a warning (a relative ``..`` written by
    hand still warns: tests/core/test_trusted_paths.py)."""
    vol = ball(tmp_path / "volumes" / "ball.npz")
    work, other = tmp_path / "work", tmp_path / "other"
    work.mkdir()
    other.mkdir()
    common = ["--size", "32x32", "--mode", "mip", "--no-jitter"]
    scene = "../scenes/scene.json"
    proc = voxwarp(
        "render", "../volumes/ball.npz", *common, "-o", "a.png", "--save-scene", scene, cwd=work
    )
    assert proc.returncode == 0, proc.stderr
    proc = voxwarp("render", "../scenes/scene.json", "--size", "32x32", "-o", "b.png", cwd=other)
    assert proc.returncode == 0, proc.stderr
    assert "warning" not in proc.stderr, proc.stderr
    saved = json.loads((tmp_path / "scenes" / "scene.json").read_text())
    assert saved["volume"]["path"] == str(vol.resolve())
    np.testing.assert_array_equal(read_image(work / "a.png"), read_image(other / "b.png"))


# ---------------------------------------------------------------------------------- --help
def test_top_level_help_says_what_voxwarp_is_and_lists_every_command(tmp_path: Path) -> None:
    proc = voxwarp("--help", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    text = " ".join(proc.stdout.split())
    assert "deformed at render time" in text
    assert "without resampling" in text
    for name in subcommands(build_parser(bench=False)):
        assert f" {name} " in text, name


def test_every_command_has_a_help_line() -> None:
    parser = build_parser(bench=False)
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    helps = {a.dest: a.help for a in sub._choices_actions}
    assert set(helps) == set(sub.choices)
    assert all(h and h.strip() for h in helps.values()), helps
    bench = subcommands(subcommands(parser)["bench"])
    bench_sub = next(
        a
        for a in subcommands(parser)["bench"]._actions
        if isinstance(a, argparse._SubParsersAction)
    )
    assert {a.dest for a in bench_sub._choices_actions} == set(bench)
    assert all(a.help for a in bench_sub._choices_actions)


# ------------------------------------------------------------------------------ closed pipe
@pytest.mark.parametrize(
    "argv",
    [["samples"], ["info", "VOLUME", "--json"], ["--help"], ["render", "--help"]],
    ids=["samples", "info-json", "help", "render-help"],
)
def test_closed_stdout_pipe_is_a_quiet_exit(tmp_path: Path, argv: list[str]) -> None:
    """``voxwarp info VOL --json | head -c 10``, with the reader gone before anything is
    written: no "Broken pipe" error, no traceback, exit status 141 (128 + SIGPIPE)."""
    vol = ball(tmp_path / "ball.npz")
    argv = [str(vol) if a == "VOLUME" else a for a in argv]
    read_end, write_end = os.pipe()
    os.close(read_end)  # the reader has gone
    try:
        proc = voxwarp(*argv, cwd=tmp_path, stdout=write_end)
    finally:
        os.close(write_end)
    assert proc.returncode == CLOSED_PIPE_EXIT == 141, proc.stderr
    assert "Broken pipe" not in proc.stderr
    assert "Traceback" not in proc.stderr
    assert "Exception ignored" not in proc.stderr
    assert "error" not in proc.stderr, proc.stderr


def test_open_pipe_still_gets_everything(tmp_path: Path) -> None:
    proc = voxwarp("samples", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "sample:stent" in [line.split()[0] for line in proc.stdout.splitlines()]
    from voxwarp.io.samples import sample_files, sample_names

    assert len(proc.stdout.splitlines()) == len(sample_names()) + len(sample_files())
