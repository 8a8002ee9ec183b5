"""Fuzz the command line: ``voxwarp info`` and ``voxwarp render`` with generated argument
lists (each option with a bad, odd or valid value, in any order and combination).

:func:`voxwarp.cli.main.main` runs in this process; the contract checked by
:func:`tests.fuzz._support.cli_outcome` is exit 0, or exit 2 with one ``voxwarp: error:``
line (argparse's usage lines may come before it) and never a traceback, within the
per-case time limit. Renders are 16x16 or smaller, on an (8, 6, 5) volume. Values that a
known finding turned into a traceback or a hang are pinned by the tests at the end.
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.fuzz._support import cli_outcome, fuzz_settings

NUMBERS = ["0", "-1", "nan", "inf", "-inf", "1e308", "x", "", "2", "0.5", "1,2"]


@pytest.fixture(scope="module")
def workdir() -> Iterator[Path]:
    """A folder with a tiny volume and some good and bad side files."""
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        np.save(d / "v.npy", np.arange(8 * 6 * 5, dtype=np.uint8).reshape(8, 6, 5))
        np.save(d / "nan.npy", np.full((4, 4, 4), np.nan, np.float32))
        np.save(d / "v4d.npy", np.zeros((2, 2, 2, 2), np.uint8))
        (d / "bad.json").write_text("{not json")
        (d / "list.json").write_text("[1, 2, 3]")
        (d / "tf.json").write_text(json.dumps([[0, 0, 0, 0, 0], [255, 1, 1, 1, 1]]))
        (d / "wires.json").write_text(json.dumps({"wires": [{"base": [[0, 0, 0]]}]}))
        (d / "dir.png").mkdir()
        yield d


def option_values(d: Path) -> dict[str, st.SearchStrategy[list[str]]]:
    """Per option: the argument lists it may add (option and values)."""
    files = [str(d / n) for n in ("bad.json", "list.json", "tf.json", "wires.json", "none.json")]
    files += [str(d / "v.npy"), str(d), ""]
    num = st.sampled_from(NUMBERS)

    def opt(name: str, *values: st.SearchStrategy[str]) -> st.SearchStrategy[list[str]]:
        return st.tuples(*values).map(lambda v: [name, *v])

    return {
        "--spacing": opt("--spacing", num, num, num),
        "--downsample": opt("--downsample", st.sampled_from(["0", "-1", "2", "3", "x", "1"])),
        "--nan": opt("--nan", st.sampled_from(["raise", "mask", "zero"])),
        "--axis-order": opt("--axis-order", st.sampled_from(["xyz", "zyx", "yxz"])),
        "--series": opt("--series", st.sampled_from(["1", "0", "-1", "1.2.3", ""])),
        "--memory-budget": opt("--memory-budget", st.sampled_from(["1", "0", "-1", "x", "1e9"])),
        "--mode": opt("--mode", st.sampled_from(["dvr", "mip", "iso", "flm", "xray", "nope"])),
        "--projection": opt("--projection", st.sampled_from(["orthographic", "fisheye"])),
        "--view": opt("--view", st.sampled_from(["+x", "-y", "anterior", "30,20", "nan,0", "up"])),
        "--size": opt("--size", st.sampled_from(["16x16", "8x4", "0x0", "-4x4", "x", "16", ""])),
        "--tf": opt("--tf", st.sampled_from(["ct-bone", "mri", "nope", *files])),
        "--step": opt("--step", st.sampled_from(["0", "-1", "nan", "inf", "0.5", "x", "1e9"])),
        "--window": opt("--window", num, num),
        "--iso": opt("--iso", num),
        "--zoom": opt("--zoom", st.sampled_from(["0", "-1", "nan", "inf", "2", "x", "0.5"])),
        "--seed": opt("--seed", st.sampled_from(["0", "-1", str(2**80), "x"])),
        "--jitter": st.sampled_from([["--jitter"], ["--no-jitter"]]),
        "--marker": st.just(["--marker"]),
        "--keep-padding": st.just(["--keep-padding"]),
        "-o": opt(
            "-o",
            st.sampled_from(
                [
                    str(d / "o.png"),
                    str(d / "o.xyz"),
                    str(d / "dir.png"),
                    str(d / "no" / "o.png"),
                    str(d / "o.exr"),
                ]
            ),
        ),
        "--save-scene": opt(
            "--save-scene",
            st.sampled_from([str(d / "s.json"), str(d / "o.png"), str(d / "no" / "s.json")]),
        ),
        "--camera": opt("--camera", st.sampled_from(files)),
        "--save-camera": opt("--save-camera", st.sampled_from([str(d / "c.json"), str(d)])),
        "--frame": opt("--frame", st.sampled_from(["undeformed", "deformed", "x"])),
        "--clip": opt("--clip", st.sampled_from(["0,0,0:4,4,4", "4,4,4:0,0,0", "nan", "x", "1,2"])),
        "--slab": opt("--slab", st.sampled_from(["z:2:1", "x", "q:0:1", "z:nan:1", "z:2:-1"])),
        "--lattice": opt("--lattice", st.sampled_from(files)),
        "--wires": opt("--wires", st.sampled_from(files)),
        "--field-scale": opt("--field-scale", st.sampled_from(["0", "1", "3", "-1", "x"])),
        # the deformation models: small grids and step counts (big ones are bounds tests)
        "--massspring": opt("--massspring", st.sampled_from(["3", "0", "-1", "x", "3,3", ""])),
        "--chainmail": opt("--chainmail", st.sampled_from(["3", "0", "1x1", "x"])),
        "--drag": opt("--drag", st.sampled_from(["1,1,1:1,0,0", "9,9,9:1,0,0", "x", "1,1:0"])),
        "--drag-at": opt("--drag-at", st.sampled_from(["3,2,2:1,0,0", "-50,0,0:1,0,0", "x"])),
        "--fix": opt("--fix", st.sampled_from(["x0", "z1", "bottom", "x", ""])),
        "--steps": opt("--steps", st.sampled_from(["1", "5", "0", "-1", "x"])),
        "--relax": opt("--relax", st.sampled_from(["0", "1", "3", "-1", "x"])),
    }


INFO_OPTIONS = ["--spacing", "--downsample", "--nan", "--axis-order", "--series", "--memory-budget"]


@fuzz_settings(60)
@given(
    source=st.sampled_from(["v.npy", "nan.npy", "v4d.npy", "bad.json", "none.npy", ".", "", "-"]),
    names=st.lists(st.sampled_from(INFO_OPTIONS), max_size=4, unique=True),
    as_json=st.booleans(),
    data=st.data(),
)
def test_info(workdir, source, names, as_json, data) -> None:
    """``voxwarp info INPUT [options]``."""
    values = option_values(workdir)
    argv = ["info", str(workdir / source) if source not in ("", "-") else source]
    for name in names:
        argv += data.draw(values[name])
    if as_json:
        argv.append("--json")
    cli_outcome("cli info", argv)


@fuzz_settings(120)
@given(
    source=st.sampled_from(["v.npy", "v.npy", "v.npy", "nan.npy", "v4d.npy", "bad.json", "."]),
    names=st.lists(st.sampled_from(sorted(option_values(Path("/x")))), max_size=5, unique=True),
    data=st.data(),
)
def test_render(workdir, source, names, data) -> None:
    """``voxwarp render INPUT [options]``: at most 16x16 pixels, output in the work folder."""
    values = option_values(workdir)
    argv = ["render", str(workdir / source), "-o", str(workdir / "out.png"), "--size", "8x8"]
    for name in names:
        argv += data.draw(values[name])
    cli_outcome("cli render", argv)


@pytest.mark.parametrize(
    ("extra", "finding"),
    [
        (["--zoom", "1e-300"], "--zoom 1e-300 ended in a traceback (issue 17, finding 7)"),
        (
            ["--massspring", "4", "--drag", "2,2,2:1e9,0,0"],
            "--drag 2,2,2:1e9,0,0 raised an uncaught WarpError (issue 17, finding 7)",
        ),
    ],
)
def test_known_cli_findings(workdir, extra: list[str], finding: str) -> None:
    """Inputs of issue 17's findings the generator leaves out (now fixed: one line)."""
    argv = ["render", str(workdir / "v.npy"), "-o", str(workdir / "k.png"), "--size", "8x8"]
    cli_outcome("cli known findings", [*argv, *extra])
