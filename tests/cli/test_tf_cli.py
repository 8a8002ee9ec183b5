"""``--tf FILE[:NAME]`` on the command line: Slicer presets.xml and ParaView colour maps.

Renders run in a child process (see tests/cli/test_cli.py's docstring). Oracle: the image
rendered with the imported file equals the image rendered with a voxwarp JSON whose
points are built here by hand from the file's numbers and the stated rules (Slicer
opacity per 1 mm -> per reference sample; ParaView 0..1 stretched onto the window), so
the CLI reads the file against the right volume. Files as in tests/core/test_tf_formats.py.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from tests.core.test_tf_formats import PARAVIEW_PRESETS, PRESETS_XML, paraview_json
from tests.run_cli import run_cli
from voxwarp.cli.main import main
from voxwarp.io.images import read_image
from voxwarp.io.samples import load_sample

SIZE = "96x64"
COMMON = ["--size", SIZE, "--no-jitter", "--view", "-y"]


@pytest.fixture(autouse=True)
def _keep_warning_state(monkeypatch: pytest.MonkeyPatch) -> None:
    """main() replaces warnings.formatwarning for good; undo it after each test."""
    monkeypatch.setattr(warnings, "formatwarning", warnings.formatwarning)


def render(tmp_path: Path, name: str, *args: str) -> np.ndarray:
    out = tmp_path / f"{name}.png"
    proc = run_cli("render", *args, *COMMON, "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    return read_image(out).astype(int)


def ct_bone_points(spacing_mm: float) -> list[list[float]]:
    """Slicer's CT-Bone by hand: colour and opacity share x; opacity per 1 mm converted."""
    rows = [
        (-3024, 0, 0, 0, 0),
        (-16.4458, 0.729412, 0.254902, 0.301961, 0),
        (641.385, 0.905882, 0.815686, 0.552941, 0.715686),
        (3071, 1, 1, 1, 0.705882),
    ]
    return [[x, r, g, b, 1 - (1 - a) ** spacing_mm] for x, r, g, b, a in rows]


@pytest.mark.usefixtures("gl_ctx")
@pytest.mark.slow
def test_render_with_a_slicer_preset_by_name(tmp_path: Path) -> None:
    presets = tmp_path / "presets.xml"
    presets.write_text(PRESETS_XML)
    fish = load_sample("fish")
    own = tmp_path / "own.json"
    own.write_text(json.dumps({"points": ct_bone_points(min(fish.spacing))}))
    got = render(tmp_path, "slicer", "sample:fish", "--tf", f"{presets}:CT-Bone")
    want = render(tmp_path, "own", "sample:fish", "--tf", str(own))
    assert (got[..., :3].max(axis=-1) > 40).mean() > 0.05  # the fish is there
    assert np.abs(got - want).max() <= 1
    other = render(tmp_path, "aaa", "sample:fish", "--tf", f"{presets}:CT-AAA")
    assert np.abs(got - other).mean() > 1  # the name picks the map


@pytest.mark.usefixtures("gl_ctx")
def test_render_with_a_normalised_paraview_map(tmp_path: Path) -> None:
    maps = tmp_path / "ColorMaps.json"
    maps.write_text(paraview_json(PARAVIEW_PRESETS))
    stent = load_sample("stent")
    level, width = stent.default_window()
    lo, hi = level - width / 2, level + width / 2
    rgb = np.reshape(PARAVIEW_PRESETS[1]["RGBPoints"], (-1, 4))
    pts = [[lo + t * (hi - lo), r, g, b, 0.5 * t] for t, r, g, b in rgb]  # ramp 0..0.5
    own = tmp_path / "own.json"
    own.write_text(json.dumps({"points": pts}))
    got = render(tmp_path, "pv", "sample:stent", "--tf", f"{maps}:Black-Body Radiation")
    want = render(tmp_path, "own", "sample:stent", "--tf", str(own))
    assert (got[..., :3].max(axis=-1) > 40).mean() > 0.05
    assert np.abs(got - want).max() <= 1


@pytest.mark.usefixtures("gl_ctx")
def test_slice_and_colormap_names_go_through_the_same_resolver(tmp_path: Path) -> None:
    presets = tmp_path / "presets.xml"
    presets.write_text(PRESETS_XML)
    out = tmp_path / "slice.png"
    args = ["sample:fish", "--look", "tf", "--size", SIZE, "-o", str(out)]
    proc = run_cli("slice", *args, "--tf", f"{presets}:CT-Bone")
    assert proc.returncode == 0, proc.stderr
    a = read_image(out).astype(int)
    proc = run_cli("slice", *args, "--tf", "viridis")
    assert proc.returncode == 0, proc.stderr
    b = read_image(out).astype(int)
    assert np.abs(a - b).mean() > 1


@pytest.mark.usefixtures("no_rendering")
@pytest.mark.parametrize(
    ("spec", "needles"),
    [
        ("{presets}:CT-Bones", ("no map 'CT-Bones'", "CT-AAA, CT-Bone, MR-Default")),
        ("nosuchmap", ("unknown transfer function preset 'nosuchmap'", "ct-bone", "matplotlib")),
        ("{tmp}/missing.xml:CT-Bone", ("no such transfer function file",)),
        ("{tmp}", ("folder",)),
    ],
)
def test_bad_tf_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture, spec: str, needles: tuple[str, ...]
) -> None:
    presets = tmp_path / "presets.xml"
    presets.write_text(PRESETS_XML)
    spec = spec.format(presets=presets, tmp=tmp_path)
    for cmd in (["render"], ["slice", "--look", "tf"]):
        rc = main([*cmd, "sample:fish", "--tf", spec, "-o", str(tmp_path / "x.png")])
        assert rc == 2
        err = capsys.readouterr().err
        assert err.startswith("voxwarp: error:")
        assert err.count("\n") == 1, err
        for needle in needles:
            assert needle in err


@pytest.fixture
def no_rendering(monkeypatch: pytest.MonkeyPatch) -> None:
    """In-process main() must fail before creating a GL context."""

    class _NoRendering:
        def __init__(self, *args: object, **kwargs: object) -> None:
            raise AssertionError("this test must fail before rendering")

    monkeypatch.setattr("voxwarp.render.offscreen.OffscreenRenderer", _NoRendering)
