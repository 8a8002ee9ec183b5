"""Issue 33: transfer-function files are bounded by their point count (counted before
the numbers are parsed), and Slicer XML with a DTD anywhere in it is refused."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest

from voxwarp.core import tf_formats
from voxwarp.core.tf_formats import MAX_TF_POINTS, read_file
from voxwarp.errors import SceneError


def _paraview(path: Path, n: int) -> Path:
    x = np.linspace(0.0, 1.0, n)
    rgb = np.column_stack([x, x, x, x]).ravel()
    path.write_text(json.dumps([{"Name": "big", "RGBPoints": [round(v, 6) for v in rgb]}]))
    return path


def test_paraview_point_limit_is_exact(tmp_path: Path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    assert MAX_TF_POINTS == 65_536
    monkeypatch.setattr(tf_formats, "MAX_TF_POINTS", 100)
    maps, _ = read_file(str(_paraview(tmp_path / "ok.json", 100)))
    assert maps is not None
    assert len(maps[0].colour) == 100
    with pytest.raises(SceneError, match=r"101 points; .* at most 100"):
        read_file(str(_paraview(tmp_path / "big.json", 101)))


def test_paraview_map_of_600000_points_is_refused_at_once(tmp_path: Path) -> None:
    path = tmp_path / "big.json"
    path.write_text('[{"Name": "big", "RGBPoints": [' + ", ".join(["0"] * 2_400_000) + "]}]")
    t0 = time.perf_counter()
    with pytest.raises(SceneError, match="600,000 points"):
        read_file(str(path))
    assert time.perf_counter() - t0 < 3.0


def test_slicer_attribute_of_400000_points_is_refused_at_once(tmp_path: Path) -> None:
    """The issue's 400,000-point scalarOpacity ran past 25 s; now refused by its count."""
    n = 400_000
    values = " ".join(["0 0.5"] * n)
    path = tmp_path / "presets.xml"
    path.write_text(
        f'<MRML><VolumeProperty name="x" scalarOpacity="{2 * n} {values}"'
        ' colorTransfer="8 0 0 0 0 1 1 1 1"/></MRML>'
    )
    t0 = time.perf_counter()
    with pytest.raises(SceneError, match="400,000 points"):
        read_file(str(path))
    assert time.perf_counter() - t0 < 2.0


def test_a_dtd_after_4096_characters_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "presets.xml"
    path.write_text(
        "<!-- " + "x" * 5000 + " -->\n<!DOCTYPE MRML [<!ELEMENT MRML ANY>]>\n"
        '<MRML><VolumeProperty name="x" scalarOpacity="4 0 0 1 1"'
        ' colorTransfer="8 0 0 0 0 1 1 1 1"/></MRML>'
    )
    with pytest.raises(SceneError, match="DTD"):
        read_file(str(path))
