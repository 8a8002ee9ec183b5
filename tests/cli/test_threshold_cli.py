"""``voxwarp render``'s threshold levels and minIP hint on the command line: the iso value
and FLM threshold printed are the ones used (the Python API's choice; ``--flm-threshold``
lands in the scene), and a thick minIP's line names a slab command that works.

Renders run in a subprocess (see tests/cli/test_cli.py's docstring)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from tests.run_cli import run_cli
from voxwarp.inputs import load_input
from voxwarp.io.images import read_image
from voxwarp.scene import Scene

SMALL = ["--size", "48x48"]


@pytest.mark.slow
@pytest.mark.parametrize(("mode", "word"), [("iso", "iso"), ("flm", "threshold")])
def test_printed_level_is_the_apis_choice(tmp_path: Path, mode: str, word: str) -> None:
    res = run_cli("render", "sample:colin27", "--mode", mode, "-o", str(tmp_path / "a.png"), *SMALL)
    assert res.returncode == 0, res.stderr
    match = re.search(rf", {word} (\S+) \(the histogram's object/background split", res.stderr)
    assert match, res.stderr
    scene = Scene(load_input("sample:colin27"), mode=mode)
    assert float(match.group(1)) == float(f"{scene.resolved_level().value:.4g}")


@pytest.mark.slow
def test_flm_threshold_option_is_used_and_printed(tmp_path: Path) -> None:
    scene_path = tmp_path / "scene.json"
    res = run_cli(
        "render", "sample:colin27", "--mode", "flm", "--flm-threshold", "60",
        "-o", str(tmp_path / "a.png"), "--save-scene", str(scene_path), *SMALL,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "shaded FLM, threshold 60 (given)" in res.stderr
    assert json.loads(scene_path.read_text())["flm_threshold"] == 60.0


@pytest.mark.slow
def test_thick_minip_names_a_slab_that_shows_something(tmp_path: Path) -> None:
    thick, slab = tmp_path / "thick.png", tmp_path / "slab.png"
    res = run_cli("render", "sample:colin27", "--mode", "minip", "-o", str(thick), *SMALL)
    assert res.returncode == 0, res.stderr
    assert "a slab shows the airways" in res.stderr
    match = re.search(r"--slab (\S+:\S+:\S+)", res.stderr)
    assert match, res.stderr
    res = run_cli(
        "render", "sample:colin27", "--mode", "minip", "--slab", match.group(1), "-o", str(slab),
        *SMALL,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "slab shows" not in res.stderr  # a thin slab: no hint
    dark = np.asarray(read_image(thick), np.float64)[..., :3].mean()
    lit = np.asarray(read_image(slab), np.float64)[..., :3].mean()
    assert lit > 5 * max(dark, 1e-3), (dark, lit)


@pytest.mark.slow
def test_demo_of_an_mri_shows_something_in_every_mode(tmp_path: Path) -> None:
    """`voxwarp demo sample:colin27`: no image is blank, the threshold modes leave the air
    around the head as background (not a flat box), the minIP is lit (through a slab)."""
    res = run_cli("demo", "sample:colin27", "-o", str(tmp_path), "--size", "64x64")
    assert res.returncode == 0, res.stderr
    assert "minip through a 20 mm slab" in res.stderr
    for path in tmp_path.glob("*.png"):
        rgb = np.asarray(read_image(path), np.float64)[..., :3]
        assert rgb.max() > 50, path.name
    for mode in ("flm", "iso"):
        rgb = np.asarray(read_image(tmp_path / f"colin27_{mode}.png"), np.float64)[..., :3]
        black = np.all(rgb == 0, axis=-1)  # the demo's background
        assert 0.3 < black.mean() < 0.9, (mode, black.mean())
    minip = np.asarray(read_image(tmp_path / "colin27_minip.png"), np.float64)[..., :3]
    assert np.mean(minip.max(axis=-1) > 30) > 0.1  # measured 0.31; through the whole head 0.004
