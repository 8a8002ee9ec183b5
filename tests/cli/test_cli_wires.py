"""Tests of ``voxwarp render --wires`` (voxwarp.cli.main): the wire deformer, headless.

Error paths run in-process through ``voxwarp.cli.main.main`` and fail before any GL work
(``no_rendering``); rendering runs in a subprocess, as in ``test_cli.py``. Oracles: a
wire file that moves a rod's wire by +4 mm along x moves the orthographic MIP's
intensity centroid to the right by 4 mm; a saved scene renders the
identical image again; the bundled wire files load on their samples.
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
from tests.cli.test_cli_massspring import VIEW, centroid_x, grey
from voxwarp.cli.main import main
from voxwarp.core.volume import Volume
from voxwarp.inputs import load_wire_file
from voxwarp.io.volumes import save_volume
from voxwarp.scene import Scene

ROOT = Path(__file__).resolve().parents[2]
N = 24


@pytest.fixture(scope="module")
def rod_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A bright rod along y (radius 3 mm) in a 24³ 1 mm volume."""
    folder = tmp_path_factory.mktemp("cli_wires")
    i, _, k = np.indices((N, N, N), dtype=np.float64)
    r = np.hypot(i - 11.5, k - 11.5)
    data = np.clip(1000.0 * (3.5 - r), 0.0, 1000.0).astype(np.float32)
    data[:, :3] = 0.0
    data[:, -3:] = 0.0
    return save_volume(Volume(data, spacing=(1.0, 1.0, 1.0), name="rod"), folder / "rod.npz")


def wire_file(tmp_path: Path, dx: float = 4.0, **extra: Any) -> Path:
    # the wire's region of influence stays inside the volume's box
    base = [[11.5, y, 11.5] for y in (5.0, 10.0, 14.0, 19.0)]
    mod = [[11.5 + dx, y, 11.5] for y in (5.0, 10.0, 14.0, 19.0)]
    d = {"wires": [{"base": base, "modified": mod, "radius": 4.5, "beta": [100, 2000]}]}
    d.update(extra)
    path = tmp_path / "wires.json"
    path.write_text(json.dumps(d))
    return path


# ---------------------------------------------------------------------- errors
@pytest.mark.usefixtures("no_rendering")
@pytest.mark.parametrize(
    ("make", "args", "message"),
    [
        (None, ["--field-scale", "2"], "--field-scale needs --wires FILE"),
        (None, ["--layout", "packed"], "--layout needs --wires FILE"),
        (None, ["--no-masks"], "--masks/--no-masks needs --wires FILE"),
        (None, ["--sides", "rigid"], "--sides needs --wires FILE"),
        (None, ["--side-falloff", "10"], "--side-falloff needs --wires FILE"),
        (None, ["--vacated", "rest"], "--vacated needs --wires FILE"),
        (None, ["--wires", "missing.json"], "--wires missing.json: no such file"),
        ("bad_json", [], "not valid JSON"),
        ("no_wires", [], "a wire file is a JSON object with a 'wires' list"),
        ("unknown_key", [], "unknown keys ['colour']"),
        ("outside", [], "lies entirely outside the volume box"),
        ("one_point", [], "at least 2 control points"),
        ("ok", ["--massspring", "4"], "--wires cannot be combined with --massspring"),
    ],
)
def test_bad_wire_options_are_one_line_errors(
    rod_file: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture,
    make: str | None,
    args: list[str],
    message: str,
) -> None:
    if make is not None:
        path = tmp_path / "w.json"
        good = json.loads(wire_file(tmp_path).read_text())
        content = {
            "bad_json": "{wires: ",
            "no_wires": json.dumps({"wire": []}),
            "unknown_key": json.dumps({**good, "colour": "red"}),
            "outside": json.dumps({"wires": [{"base": [[500, 0, 0], [600, 0, 0]], "radius": 2}]}),
            "one_point": json.dumps({"wires": [{"base": [[1, 1, 1]], "radius": 2}]}),
            "ok": json.dumps(good),
        }[make]
        path.write_text(content)
        args = ["--wires", str(path), *args]
    assert_render_refused(rod_file, tmp_path, capsys, args, message)


@pytest.mark.usefixtures("no_rendering")
def test_bad_field_scale_is_an_argparse_error(
    rod_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    with pytest.raises(SystemExit) as info:
        main(["render", str(rod_file), "--wires", str(wire_file(tmp_path)), "--field-scale", "3"])
    assert info.value.code == 2
    assert "field scale must be one of 1, 2, 4, 8, 16" in capsys.readouterr().err


def test_help_documents_wires(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit):
        main(["render", "--help"])
    out = capsys.readouterr().out
    for opt in ("--wires", "--field-scale", "--layout", "--masks", "fish_spine_wires.json"):
        assert opt in out


@pytest.mark.parametrize(
    ("name", "sample"), [("fish_spine_wires.json", "fish"), ("tubes_twist_wires.json", "tubes")]
)
def test_bundled_wire_files_load_on_their_samples(name: str, sample: str) -> None:
    from voxwarp.deform.wires.field import WireFieldWarp
    from voxwarp.io.samples import load_sample

    entry = load_wire_file(ROOT / "sample_volumes" / name)
    assert entry["type"] == "wires"
    warp = WireFieldWarp.from_dict(entry)
    vol = load_sample(sample)
    warp.bind_volume(vol)
    st = warp.deformer.stats
    assert st is not None
    assert st.swept > 1000
    assert st.vacated > 0
    assert json.loads((ROOT / "sample_volumes" / name).read_text())["sample"] == sample


# ---------------------------------------------------------------------- rendering
def test_wire_moves_the_rod_and_the_scene_renders_again(rod_file: Path, tmp_path: Path) -> None:
    rest, moved, again = (tmp_path / f"{n}.png" for n in ("rest", "moved", "again"))
    scene = tmp_path / "scene.json"
    size = ["--size", "24x24"]
    render(str(rod_file), "-o", str(rest), *VIEW, *size)
    proc = render(
        str(rod_file),
        "-o",
        str(moved),
        *VIEW,
        *size,
        "--wires",
        str(wire_file(tmp_path)),
        "--save-scene",
        str(scene),
    )
    assert "wires: 1 wire(s)" in proc.stderr
    # +z view: +x to the right
    rows = slice(7, 17)  # swept along the wire, away from its ends
    shift = centroid_x(grey(moved)[rows]) - centroid_x(grey(rest)[rows])
    pixel = Scene.load(scene).resolved_camera().ortho_height / 24  # mm per pixel
    assert abs(shift * pixel - 4.0) < 0.2
    d = json.loads(scene.read_text())
    assert d["warps"][0]["type"] == "wires"
    render(str(scene), "-o", str(again), *size)
    assert np.array_equal(grey(again), grey(moved))
