"""Boundary conditions on the command line (``--anchor``, ``--fix-outside``): a default
drag on a head stays local, ``--anchor corners`` is the thesis's set-up that moves the
whole head, and the conditions in use are named in one stderr line.

Oracle (``tests/cli/locality.py``): a 15 mm posterior push at the face front; the mean
|deformed - rest| grey of sagittal slices over the head's posterior (far) third against
its anterior (near) third. On the bundled MRI (``sample:colin27``) and a phantom
(``sample:head``).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cli.locality import thirds_change
from tests.cli.test_cli import run_cli

MODELS = {"massspring": ["--massspring", "16", "--settle"], "chainmail": ["--chainmail", "16"]}
#: each model's default boundary line: mass-spring fixes the shell and anchors a region;
#: ChainMail keeps the thesis's corners (its link slack keeps a drag local)
BOUNDARY = {
    "massspring": ("grid shell fixed", "anchored"),
    "chainmail": ("8 grid corners fixed", "ChainMail's link slack keeps a drag local"),
}


@pytest.mark.slow
@pytest.mark.parametrize("sample", ["sample:colin27", "sample:head"])
@pytest.mark.parametrize("model", sorted(MODELS))
def test_default_drag_stays_local(sample: str, model: str, tmp_path: Path) -> None:
    near, far, err = thirds_change(sample, tmp_path, *MODELS[model])
    assert near > 0.0, "the push changed nothing near it"
    assert far < near / 5, f"far third {far:.3f} vs near third {near:.3f}"
    lines = [line for line in err.splitlines() if "boundary:" in line]
    assert len(lines) == 1
    for phrase in BOUNDARY[model]:
        assert phrase in lines[0]
    assert "(--anchor, --fix-outside)" in lines[0]
    # the default drag goes all the way (a fixed shell would hold a ChainMail push back)
    assert "went only" not in err


@pytest.mark.slow
def test_chainmail_shell_holds_a_push_back_and_says_why(tmp_path: Path) -> None:
    _, _, err = thirds_change("sample:head", tmp_path, *MODELS["chainmail"], "--anchor", "shell")
    limited = [line for line in err.splitlines() if "went only" in line]
    assert len(limited) == 1
    assert "the grid's shell is fixed: --anchor shell" in limited[0]


@pytest.mark.slow
@pytest.mark.parametrize("sample", ["sample:colin27", "sample:head"])
def test_corners_move_the_whole_head_as_before(sample: str, tmp_path: Path) -> None:
    near, far, err = thirds_change(sample, tmp_path, *MODELS["massspring"], "--anchor", "corners")
    assert far >= near / 5, f"far third {far:.3f} vs near third {near:.3f}"
    assert "boundary: 8 grid corners fixed; no region of influence" in err


@pytest.mark.slow
def test_fix_outside_sets_the_radius_and_off_removes_it(tmp_path: Path) -> None:
    base = ["--massspring", "16", "--steps", "10"]
    _, _, err = thirds_change("sample:head", tmp_path, *base, "--fix-outside", "40")
    assert "elements beyond 40 mm of a drag anchored;" in err
    _, _, err = thirds_change("sample:head", tmp_path, *base, "--fix-outside", "off")
    assert "grid shell fixed; no region of influence" in err


@pytest.mark.slow
@pytest.mark.parametrize("preset", ["ct", "mr"])
def test_stiffness_preset_is_named_in_one_line(preset: str, tmp_path: Path) -> None:
    out = tmp_path / "s.png"
    args = ["--massspring", "6", "--drag", "3,3,3:0,5,0", "--steps", "1"]
    proc = run_cli("slice", "sample:head", "-o", str(out), *args, "--stiffness-from-volume", preset)
    assert proc.returncode == 0, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if "materials:" in line]
    assert len(lines) == 1
    assert f"the {preset} preset" in lines[0]
