"""``--window NAME|LEVEL,WIDTH`` and ``sample:NAME`` files on the command line (issue 32,
item 7).

Oracles: a CT slice with no ``--window`` is the same image as ``--window mediastinum``
and ``--window 40,400`` (and not the percentile window's); ``render --window bone``
saves the window 400/1800 in the scene; a HU preset on an MR is one line; bundled wire
and lattice files and scenes open by ``sample:NAME``, giving the same image as their
path."""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from voxwarp.cli.main import main
from voxwarp.io.images import read_image
from voxwarp.io.samples import sample_file


@pytest.fixture(autouse=True)
def _keep_warning_state(monkeypatch: pytest.MonkeyPatch) -> None:
    """main() replaces warnings.formatwarning for good; undo it after each test."""
    monkeypatch.setattr(warnings, "formatwarning", warnings.formatwarning)


def _slice(tmp_path: Path, name: str, *args: str) -> np.ndarray:
    out = tmp_path / f"{name}.png"
    assert main(["slice", "sample:fish", "-o", str(out), "--pixel", "1", *args]) == 0
    return read_image(out)


@pytest.mark.slow
def test_ct_slice_opens_at_mediastinum(gl_ctx: Any, tmp_path: Path) -> None:
    default = _slice(tmp_path, "default")
    assert np.array_equal(default, _slice(tmp_path, "named", "--window", "mediastinum"))
    assert np.array_equal(default, _slice(tmp_path, "numbers", "--window", "40,400"))
    assert not np.array_equal(default, _slice(tmp_path, "pct", "--window", "percentile"))
    assert not np.array_equal(default, _slice(tmp_path, "lung", "--window", "lung"))


def test_render_window_preset_is_saved(gl_ctx: Any, tmp_path: Path) -> None:
    scene = tmp_path / "scene.json"
    args = ["render", "sample:fish", "--mode", "mip", "--size", "32x32", "--window", "bone"]
    assert main([*args, "-o", str(tmp_path / "mip.png"), "--save-scene", str(scene)]) == 0
    assert json.loads(scene.read_text(encoding="utf-8"))["window"] == [400.0, 1800.0]


def test_hu_preset_on_an_mr_is_one_line(
    gl_ctx: Any, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    code = main(["slice", "sample:colin27", "--window", "brain", "-o", str(tmp_path / "x.png")])
    err = capsys.readouterr().err
    assert code != 0
    assert err.count("\n") == 1
    assert "'brain' is in HU" in err


@pytest.mark.slow
def test_sample_files_by_name_render_as_their_paths(gl_ctx: Any, tmp_path: Path) -> None:
    common = ["--size", "48x32", "--view", "+z", "--no-jitter"]
    for option, name in (("--wires", "fish_spine_wires"), ("--lattice", "fish_lattice_bend")):
        images = []
        for ref in (f"sample:{name}", str(sample_file(name))):
            out = tmp_path / f"{name}_{len(images)}.png"
            assert main(["render", "sample:fish", option, ref, *common, "-o", str(out)]) == 0
            images.append(read_image(out))
        assert np.array_equal(*images), option
    out = tmp_path / "tubes.png"
    assert main(["render", "sample:lattice_torus_tubes", *common, "-o", str(out)]) == 0
    assert read_image(out).max() > 0
