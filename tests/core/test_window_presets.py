"""Window presets (issue 32, item 7): the CT reading windows, what opens by default,
and ``--window NAME|LEVEL,WIDTH`` parsing.

Oracles: the radiology table (level/width in HU), the modality detector's verdict (a
CT in HU gets the CT presets and opens at mediastinum; an MR keeps its percentile
window, the one :func:`display_defaults` computes), and one-line refusals."""

from __future__ import annotations

import numpy as np
import pytest

from voxwarp.core.modality import display_defaults
from voxwarp.core.volume import Volume
from voxwarp.core.window_presets import (
    default_slice_window,
    parse_window,
    preset_of,
    preset_window,
    presets_for,
    resolve_window,
)
from voxwarp.errors import InputError
from voxwarp.render.slice_grid import slice_window
from voxwarp.scene import Scene


def _ct() -> Volume:
    rng = np.random.default_rng(0)
    data = rng.normal(40, 30, (24, 24, 24)).astype(np.int16)
    data[:, :6] = -1000  # air
    return Volume(data, (1.0, 1.0, 1.0), units="HU", modality="CT", space="RAS")


def _mr() -> Volume:
    rng = np.random.default_rng(1)
    data = rng.gamma(3.0, 100.0, (24, 24, 24)).astype(np.float32)
    return Volume(data, (2.0, 2.0, 2.0), modality="MR", space="RAS")


def test_ct_presets_are_the_reading_windows() -> None:
    ct = _ct()
    table = {"lung": (-600, 1500), "mediastinum": (40, 400), "bone": (400, 1800)}
    table["brain"] = (40, 80)
    for name, window in table.items():
        assert preset_window(name, ct) == window
        assert preset_of(window, ct) == name
    assert presets_for(ct) == (*table, "percentile")


def test_ct_opens_at_mediastinum_mr_at_its_percentile_window() -> None:
    ct, mr = _ct(), _mr()
    assert default_slice_window(ct) == (40.0, 400.0)
    assert default_slice_window(mr) == display_defaults(mr).window
    assert default_slice_window(ct) != display_defaults(ct).window  # was the percentile
    assert presets_for(mr) == ("percentile",)
    assert slice_window(Scene(ct)) == (40.0, 400.0)
    assert slice_window(Scene(ct, window=(10.0, 20.0))) == (10.0, 20.0)  # the scene's own


def test_hu_preset_on_an_mr_is_one_line() -> None:
    with pytest.raises(InputError, match=r"'lung' is in HU.*MR.*percentile") as err:
        preset_window("lung", _mr())
    assert "\n" not in str(err.value)


@pytest.mark.parametrize(
    ("text", "want"),
    [("lung", "lung"), ("Bone", "bone"), ("-600,1500", (-600.0, 1500.0)), ("40, 400", (40, 400))],
)
def test_parse_window(text: str, want: object) -> None:
    assert parse_window(text) == want


@pytest.mark.parametrize("text", ["lungs", "40", "40,0", "40,-5", "a,b", "nan,4"])
def test_bad_windows_name_the_presets(text: str) -> None:
    with pytest.raises(InputError, match=r"mediastinum.*LEVEL,WIDTH"):
        parse_window(text)


def test_resolve_window() -> None:
    ct = _ct()
    assert resolve_window(None, ct) is None
    assert resolve_window("bone", ct) == (400.0, 1800.0)
    assert resolve_window((1.0, 2.0), ct) == (1.0, 2.0)
