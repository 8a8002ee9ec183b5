"""Issue 33: one JSON loader (voxwarp.core.json_input) with a size and a depth limit,
strict about NaN and duplicate keys, tolerant of a UTF-8 BOM, used by every JSON reader;
and one rule for named files: FIFOs, devices and sockets are refused, never opened."""

from __future__ import annotations

import argparse
import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from tests.run_cli import run_cli
from voxwarp.core import json_input
from voxwarp.core.json_input import (
    MAX_JSON_DEPTH,
    JsonFileError,
    JsonLimitError,
    json_depth,
    parse_json_text,
    read_json,
)
from voxwarp.errors import VoxwarpError

SCENE = {"format": "voxwarp-scene", "volume": {"sample": "tubes", "shape": [8, 8, 8]}}


def _nested(depth: int) -> str:
    return "[" * depth + "]" * depth


def test_depth_limit_is_exact() -> None:
    assert parse_json_text(_nested(MAX_JSON_DEPTH)) is not None
    with pytest.raises(JsonLimitError, match=f"nested {MAX_JSON_DEPTH + 1} levels"):
        parse_json_text(_nested(MAX_JSON_DEPTH + 1))


def test_depth_counts_brackets_outside_strings_only() -> None:
    assert json_depth('{"a": "[[[[{{{{", "b": [1, [2]]}') == 3
    assert json_depth(r'["\"[[[", [[]]]') == 3
    assert json_depth(json.dumps(json.loads(_nested(40)))) == 40


def test_a_million_deep_is_refused_without_recursion() -> None:
    with pytest.raises(JsonLimitError, match="1000000 levels"):
        parse_json_text(_nested(1_000_000))


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ('{"iso_value": NaN}', "NaN is not a JSON number"),
        ('{"a": [Infinity]}', "Infinity is not a JSON number"),
        ('{"a": 1, "a": 2}', "duplicate key 'a'"),
    ],
)
def test_strictness(text: str, match: str) -> None:
    with pytest.raises(JsonLimitError, match=match):
        parse_json_text(text)


def test_bom_is_accepted(tmp_path: Path) -> None:
    path = tmp_path / "s.json"
    path.write_bytes(b"\xef\xbb\xbf" + json.dumps(SCENE).encode())
    assert read_json(path) == SCENE


def test_size_limit_is_checked_before_reading(tmp_path: Path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    path = tmp_path / "big.json"
    path.write_text("[" + "0," * 600 + "0]")
    monkeypatch.setattr(json_input, "MAX_JSON_BYTES", path.stat().st_size)
    assert len(read_json(path)) == 601
    monkeypatch.setattr(json_input, "MAX_JSON_BYTES", path.stat().st_size - 1)
    with pytest.raises(JsonFileError, match="at most"):
        read_json(path)


@pytest.mark.timeout(20)
def test_fifo_is_refused_without_opening_it(tmp_path: Path) -> None:
    fifo = tmp_path / "s.json"
    os.mkfifo(fifo)
    with pytest.raises(JsonFileError, match=r"pipe \(FIFO\)"):
        read_json(fifo)


# ---------------------------------------------------------------------------- every reader
def _scene(p: Path) -> Any:
    from voxwarp.scene import read_scene_dict

    return read_scene_dict(p)


def _tf(p: Path) -> Any:
    from voxwarp.core.tf_formats import read_file

    return read_file(str(p))


def _wires(p: Path) -> Any:
    from voxwarp.inputs import load_wire_file

    return load_wire_file(p)


def _lattice(p: Path) -> Any:
    from voxwarp.inputs import read_json_option

    return read_json_option("--lattice", p)


def _camera(p: Path) -> Any:
    from voxwarp.cli.render_options import camera_arg

    return camera_arg(str(p))


def _tour(p: Path) -> Any:
    from voxwarp.teaching.tour import read_tour

    return read_tour(p)


def _napari(p: Path) -> Any:
    from voxwarp.napari_plugin.reader import read_scene

    return read_scene(str(p))


READERS: dict[str, Callable[[Path], Any]] = {
    "scene": _scene,
    "transfer function": _tf,
    "wires": _wires,
    "lattice": _lattice,
    "camera": _camera,
    "tour": _tour,
    "napari scene": _napari,
}


@pytest.mark.timeout(20)
@pytest.mark.parametrize("reader", list(READERS))
@pytest.mark.parametrize("case", ["deep", "duplicate", "fifo"])
def test_every_json_reader_refuses_in_one_line(reader: str, case: str, tmp_path: Path) -> None:
    path = tmp_path / "x.json"
    if case == "fifo":
        os.mkfifo(path)
    elif case == "deep":
        path.write_text('{"format": "voxwarp-scene", "volume": ' + _nested(50_000) + "}")
    else:
        path.write_text('{"format": "voxwarp-scene", "format": "voxwarp-scene"}')
    with pytest.raises((VoxwarpError, argparse.ArgumentTypeError)) as info:
        READERS[reader](path)
    message = str(info.value)
    assert "\n" not in message
    expected = {"deep": "64 deep", "duplicate": "duplicate key", "fifo": "FIFO"}[case]
    assert expected in message, message


@pytest.mark.timeout(20)
def test_cli_tf_fifo_and_deep_tf_are_one_line(tmp_path: Path) -> None:
    """A FIFO given to --tf hung; a deeply nested TF was a RecursionError (slice --look tf too)."""
    fifo = tmp_path / "tf.json"
    os.mkfifo(fifo)
    deep = tmp_path / "deep.json"
    deep.write_text(_nested(100_000))
    out = str(tmp_path / "o.png")
    for argv in (
        ("render", "sample:tubes", "--tf", str(fifo), "-o", out),
        ("slice", "sample:tubes", "--look", "tf", "--tf", str(deep), "-o", out),
    ):
        proc = run_cli(*argv, timeout=20)
        assert proc.returncode == 2, proc.stderr
        assert "Traceback" not in proc.stderr
        lines = [x for x in proc.stderr.splitlines() if x.strip()]
        assert len(lines) == 1, proc.stderr
        assert "FIFO" in lines[0] or "64 deep" in lines[0], proc.stderr


def test_scene_nan_iso_refused_bom_accepted(tmp_path: Path) -> None:
    from voxwarp.scene import Scene

    path = tmp_path / "s.json"
    path.write_text(json.dumps(SCENE)[:-1] + ', "iso_value": NaN}')
    with pytest.raises(VoxwarpError, match="NaN"):
        Scene.load(path)
    path.write_bytes(b"\xef\xbb\xbf" + json.dumps({**SCENE, "iso_value": 0.5}).encode())
    assert Scene.load(path).iso_value == 0.5
