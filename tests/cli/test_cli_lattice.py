"""``voxwarp render --lattice FILE`` (voxwarp.cli.main): a lattice of trilinear cells deforms a
volume. Errors run in-process and fail before any GL work; the bundled fish bend renders
in a subprocess, differs from the plain fish and renders again identically from its
saved scene."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.cli.test_cli import (  # noqa: F401  (fixtures used by name)
    _keep_warning_state,
    assert_render_refused,
    no_rendering,
    render,
)
from tests.cli.test_cli_massspring import ball_file  # noqa: F401
from voxwarp.io.images import read_image

ROOT = Path(__file__).resolve().parents[2]
FISH_BEND = ROOT / "sample_volumes" / "fish_lattice_bend.json"


@pytest.mark.usefixtures("no_rendering")
@pytest.mark.parametrize(
    ("content", "args", "message"),
    [
        (None, ["--lattice", "missing.json"], "--lattice missing.json: no such file"),
        ("{grid", [], "not valid JSON"),
        ('{"nodes": []}', [], "a lattice file is a JSON object with a 'grid'"),
        ('{"grid": {"nodes": [[1, 2]]}}', [], "--lattice"),
        ('{"grid": {"nodes": []}, "colour": 1}', [], "unknown keys ['colour']"),
        ("ok", ["--wires", "w.json"], "--lattice cannot be combined"),
        ("ok", ["--massspring", "4"], "--lattice cannot be combined"),
    ],
)
def test_bad_lattice_options_are_one_line_errors(
    ball_file: Path,  # noqa: F811
    tmp_path: Path,
    capsys: pytest.CaptureFixture,
    content: str | None,
    args: list[str],
    message: str,
) -> None:
    if content is not None:
        path = tmp_path / "lattice.json"
        path.write_text(FISH_BEND.read_text() if content == "ok" else content)
        args = ["--lattice", str(path), *args]
    assert_render_refused(ball_file, tmp_path, capsys, args, message)


@pytest.mark.slow
def test_bundled_fish_bend_renders_and_round_trips(tmp_path: Path) -> None:
    plain, bent, again = (tmp_path / f"{n}.png" for n in ("plain", "bent", "again"))
    scene = tmp_path / "scene.json"
    view = ["--view", "+z", "--size", "96x64", "--tf", "ct-soft", "--no-jitter"]
    render("sample:fish", "-o", str(plain), *view)
    render(
        "sample:fish",
        "-o",
        str(bent),
        *view,
        "--lattice",
        str(FISH_BEND),
        "--save-scene",
        str(scene),
    )
    a = read_image(plain)[..., :3].astype(float)
    b = read_image(bent)[..., :3].astype(float)
    changed = np.abs(a - b).max(axis=-1) > 24
    # the default camera frames the undeformed fish: the tail (right) moved, the head not
    assert 0.005 < changed.mean() < 0.6
    assert not changed[:, : a.shape[1] * 2 // 5].any()
    assert json.loads(scene.read_text())["warps"][0]["type"] == "lattice"
    render(str(scene), "-o", str(again), "--size", "96x64")
    np.testing.assert_array_equal(read_image(again), read_image(bent))
