"""Bundled scenes, wires, lattices and animations by ``sample:NAME`` (issue 32, item 7).

Oracles: every JSON file in ``sample_volumes/`` is listed under its kind, resolves to
that file and loads with the reader of its kind; the listing goes through
:mod:`importlib.resources` (shown by reading the same files from a zip archive, the
layout of a zipped install) and the wheel carries them (``pyproject.toml``'s package
data); an unknown name is one line that lists the names."""

from __future__ import annotations

import json
import tomllib
import zipfile
from fnmatch import fnmatch
from pathlib import Path

import pytest

from tests.run_cli import REPO
from voxwarp.errors import InputError, VolumeError
from voxwarp.inputs import load_input, load_lattice_file, load_wire_file
from voxwarp.io.samples import (
    load_sample,
    resolve_sample_path,
    sample_file,
    sample_files,
    sample_names,
)
from voxwarp.scene import Scene

SAMPLES = REPO / "sample_volumes"
ON_DISK = sorted(p.stem for p in SAMPLES.glob("*.json"))


def test_every_bundled_json_is_listed_by_kind() -> None:
    files = sample_files()
    assert sorted(files) == ON_DISK
    assert files["fish_spine_wires"] == "wires"
    assert files["fish_lattice_bend"] == "lattice"
    assert files["fish_swim_anim"] == "animation"
    assert files["lattice_torus_tubes"] == "scene"


@pytest.mark.parametrize("name", ON_DISK)
def test_each_resolves_and_loads(name: str) -> None:
    path = resolve_sample_path(f"sample:{name}")
    assert Path(path).resolve() == (SAMPLES / f"{name}.json").resolve()
    kind = sample_files()[name]
    if kind == "wires":
        assert load_wire_file(f"sample:{name}")["type"] == "wires"
    elif kind == "lattice":
        warp = load_lattice_file(f"sample:{name}", load_sample("fish", shape=(24, 24, 24)))
        assert warp is not None
    else:
        assert isinstance(load_input(f"sample:{name}"), Scene)
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
        assert bool(doc.get("animation")) == (kind == "animation")


def test_listing_reads_through_importlib_resources(tmp_path: Path) -> None:
    """The same listing from a zip archive of the folder (a Traversable, not a Path)."""
    archive = tmp_path / "samples.zip"
    with zipfile.ZipFile(archive, "w") as z:
        for p in SAMPLES.glob("*.json"):
            z.write(p, f"voxwarp/sample_volumes/{p.name}")
    root = zipfile.Path(archive, "voxwarp/sample_volumes/")
    assert sample_files(root) == sample_files()


def test_the_wheel_carries_them() -> None:
    meta = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))
    patterns = meta["tool"]["setuptools"]["package-data"]["voxwarp.sample_volumes"]
    for name in ON_DISK:
        assert any(fnmatch(f"{name}.json", p) for p in patterns), name


def test_unknown_names_list_the_names() -> None:
    with pytest.raises(VolumeError) as err:
        resolve_sample_path("sample:fishy")
    text = str(err.value)
    assert "\n" not in text
    assert "fish_spine_wires" in text
    assert "colin27" in text
    with pytest.raises(VolumeError, match="fish_spine_wires"):
        sample_file("nope")
    with pytest.raises(InputError, match=r"--wires sample:nope: unknown sample 'nope'"):
        load_wire_file("sample:nope")
    assert resolve_sample_path("sample:fish") == "sample:fish"  # a volume: kept
    assert resolve_sample_path("x.json") == "x.json"


def test_samples_command_lists_them_by_kind(capsys: pytest.CaptureFixture) -> None:
    from voxwarp.cli.main import main

    assert main(["samples"]) == 0
    lines = capsys.readouterr().out.splitlines()
    listed = {line.split()[0]: line for line in lines}
    assert "--wires" in listed["sample:fish_spine_wires"]
    assert "animate" in listed["sample:fish_swim_anim"]
    assert "volumes" in listed["sample:colin27"]
    assert set(listed) == {f"sample:{n}" for n in [*ON_DISK, *sample_names()]}
