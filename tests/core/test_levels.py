"""The default levels of ``iso`` and ``flm`` (voxwarp.core.levels): the object/background
split lands between the noise and the object on MRI-like and CT-like phantoms with known
noise, shifted and scaled, and with almost no background; MR/other data use the split, a
CT the transfer function's level above it; the line says which."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from voxwarp.core.levels import Level, default_level, object_split, otsu_split
from voxwarp.core.transfer_function import TransferFunction
from voxwarp.core.volume import Volume
from voxwarp.scene import Scene

N = 48


def sphere_mask(radius: float, n: int = N) -> np.ndarray:
    """An n³ boolean ball of ``radius`` voxels about the centre."""
    c = (n - 1) / 2
    i, j, k = np.meshgrid(*(np.arange(n) - c,) * 3, indexing="ij")
    return i * i + j * j + k * k <= radius * radius


def phantom(kind: str, radius: float = 14.0, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``(data, mask)``: a ball (mask) in noise. ``mri``: Rician background (sigma 25)
    around 0, the ball 420 +- 60 with Rician noise; ``ct``: air -1000 +- 25 HU, the ball
    bone-like 700 +- 60 HU (int16)."""
    rng = np.random.default_rng(seed)
    mask = sphere_mask(radius)
    shape = mask.shape
    if kind == "mri":
        clean = np.where(mask, 420.0 + 60.0 * rng.standard_normal(shape), 0.0)
        data = np.hypot(
            clean + 25.0 * rng.standard_normal(shape), 25.0 * rng.standard_normal(shape)
        )
        return data.astype(np.float32), mask
    data = np.where(mask, 700.0 + 60.0 * rng.standard_normal(shape), -1000.0)
    data = data + 25.0 * rng.standard_normal(shape)
    return np.round(data).astype(np.int16), mask


def between(split: float, data: np.ndarray, mask: np.ndarray) -> None:
    """``split`` lies above 99.99 % of the background's values (no speckle of noise) and
    below 99 % of the object's (the object shows)."""
    noise_top = float(np.percentile(data[~mask], 99.99))
    object_bottom = float(np.percentile(data[mask], 1.0))
    assert noise_top < split < object_bottom, (noise_top, split, object_bottom)


CASES = {
    "mri": lambda d: d,
    "mri x10": lambda d: 10.0 * d,
    "mri x0.01 + 3": lambda d: 0.01 * d + 3.0,
    "ct": lambda d: d,
    "ct stored +2000": lambda d: (d.astype(np.int32) + 2000).astype(np.uint16),
}


@pytest.mark.parametrize("case", CASES)
def test_split_lands_between_noise_and_object(case: str) -> None:
    data, mask = phantom("ct" if case.startswith("ct") else "mri")
    data = CASES[case](data)
    between(object_split(Volume(data, name=case)), data, mask)


@pytest.mark.parametrize("kind", ["mri", "ct"])
def test_split_with_almost_no_background(kind: str) -> None:
    # a ball of radius 0.65 n about the centre: only the corners (10 % of voxels) are
    # background
    data, mask = phantom(kind, radius=0.65 * N)
    assert 0.05 < np.mean(~mask) < 0.15
    between(object_split(Volume(data, name="full")), data, mask)


def test_split_moves_with_the_data() -> None:
    """Shifted and scaled data: the split is shifted and scaled alike (within a bin)."""
    data, _ = phantom("mri")
    base = object_split(Volume(data))
    moved = object_split(Volume(7.5 * data - 300.0))
    bin_width = 7.5 * float(np.ptp(np.percentile(data, [0.5, 99.5]))) / 256
    assert abs(moved - (7.5 * base - 300.0)) <= bin_width


def test_otsu_split_on_integers_is_half_way() -> None:
    values = np.array([0] * 500 + [1] * 300 + [2] * 50 + [9] * 80 + [10] * 70)
    assert otsu_split(values) == 5.5  # between the classes 0..2 and 9..10
    assert otsu_split(np.full(10, 3.0)) == 3.0


def test_otsu_split_of_two_gaussians_lies_between_them() -> None:
    rng = np.random.default_rng(1)
    values = np.concatenate([rng.normal(0, 1, 50_000), rng.normal(10, 1, 50_000)])
    split = otsu_split(values)  # in the gap: above 99.9 % of the first, below 99.9 % of the second
    assert 3.1 < split < 6.9, split


def test_mr_and_other_use_the_split() -> None:
    data, _ = phantom("mri")
    for modality in ("MR", ""):
        vol = Volume(data, modality=modality)
        split = object_split(vol)
        for mode in ("iso", "flm"):
            scene = Scene(vol, mode=mode)
            level = scene.resolved_level()
            assert level.value == split
            assert "object/background split" in level.source
        assert Scene(vol, mode="iso").resolved_iso_value() == split
        assert Scene(vol, mode="flm").resolved_flm_threshold() == split


def test_ct_follows_the_transfer_function_above_the_split() -> None:
    data, mask = phantom("ct")
    vol = Volume(data, units="HU")
    tf = TransferFunction.preset("ct-bone", vol)
    iso = default_level(vol, tf, "iso")
    flm = default_level(vol, tf, "flm")
    assert flm.value == 150.0  # ct-bone's lowest visible value
    # opacity a quarter of its maximum (0.85): 150 HU (0) .. 300 HU (0.25), linear
    assert iso.value == pytest.approx(150.0 + 150.0 * 0.85, abs=1.0)
    assert iso.source.startswith("tf ct-bone")
    between(iso.value, data, mask)
    # a transfer function that starts in the air: raised to the split
    low = TransferFunction([(-1000, 0, 0, 0, 0), (-990, 1, 1, 1, 1)])
    assert default_level(vol, low, "flm").value == object_split(vol)
    assert default_level(vol, low, "iso").value == object_split(vol)


def test_a_ct_tagged_file_in_other_units_follows_its_transfer_function() -> None:
    """Like the bundled stent (a CT stored as 0..32): the file says CT, the values are not HU."""
    data, _ = phantom("mri")
    vol = Volume(data, modality="CT")
    tf = TransferFunction([(0, 0, 0, 0, 0), (300, 1, 1, 1, 0), (400, 1, 1, 1, 1)])
    assert default_level(vol, tf, "flm").value == 300.0
    assert default_level(vol, tf, "iso").value == pytest.approx(325.0, abs=0.1)
    assert default_level(Volume(data), tf, "iso").value == object_split(Volume(data))


def test_given_values_win_and_say_so() -> None:
    data, _ = phantom("mri")
    scene = Scene(Volume(data), mode="flm", flm_threshold=123.0, iso_value=77.0)
    assert scene.resolved_level() == Level(123.0, "given")
    assert scene.resolved_level("iso") == Level(77.0, "given")
    assert Level(123.0, "given").text("flm") == "threshold 123 (given)"


@pytest.mark.parametrize(("mode", "flag"), [("iso", "--iso"), ("flm", "--flm-threshold")])
def test_display_note_prints_the_level_used(mode: str, flag: str) -> None:
    data, _ = phantom("mri")
    scene = Scene(Volume(data), mode=mode)
    note = scene.display_note()
    value = scene.resolved_iso_value() if mode == "iso" else scene.resolved_flm_threshold()
    word = "iso" if mode == "iso" else "threshold"
    assert (
        f", {word} {value:.4g} (the histogram's object/background split; set with {flag})" in note
    )


def test_no_level_in_the_note_of_other_modes() -> None:
    data: Any = phantom("mri")[0]
    assert "split" not in Scene(Volume(data), mode="dvr").display_note()
