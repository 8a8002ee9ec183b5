"""Modality-aware display defaults (voxwarp.core.modality) and their integration.

Detection on the bundled scans and on arrays that must not pass for CT; the default
transfer function, window and shading per modality in a Scene; CT padding masked by
load_input (and kept with keep_padding / --keep-padding), checked on rendered MIP and
minIP pixels; the iso out-of-range warning; the HU-preset warning only where a HU preset
meets non-HU data in a mode that draws through the transfer function.
"""

from __future__ import annotations

import os
import subprocess
import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from voxwarp.core.camera import Camera, view_rotation
from voxwarp.core.modality import (
    SURFACE_PRESETS,
    WINDOW_PERCENTILES,
    detect_modality,
    display_defaults,
    mask_padding,
    padding_mask,
)
from voxwarp.core.volume import Volume
from voxwarp.inputs import load_input
from voxwarp.io.samples import load_sample
from voxwarp.io.volumes import save_volume
from voxwarp.scene import Scene

REPO = Path(__file__).resolve().parents[2]
PAD = -2048
#: the padded CT: field of view x in [FOV_LO, FOV_HI), padding outside
SHAPE, FOV_LO, FOV_HI = (64, 48, 40), 12, 52


def padded_ct(
    inside: str = "air", *, units: str = "", padding_value: float | None = None
) -> Volume:
    """A CT-like int16 volume: a soft-tissue ball with a bone shell at the centre, in air
    (``inside="air"``, -1000 HU) or water (``"water"``, 0 HU), with noise; columns
    x < 12 and x >= 52 are padding (-2048) outside the field of view."""
    rng = np.random.default_rng(3)
    idx = np.indices(SHAPE, dtype=np.float64)
    centre = (np.asarray(SHAPE, float) - 1)[:, None, None, None] / 2
    r = np.sqrt(((idx - centre) ** 2).sum(axis=0))
    base = -1000.0 if inside == "air" else 0.0
    data = np.where(r < 10, 40.0, base) + np.where((r >= 8) & (r < 10), 760.0, 0.0)
    data = np.maximum(data + rng.normal(0, 8, SHAPE), -1024)  # scanners clamp at -1024
    data[:FOV_LO] = PAD
    data[FOV_HI:] = PAD
    return Volume(
        np.rint(data).astype(np.int16), name="padded", units=units, padding_value=padding_value
    )


def pad_count() -> int:
    return (SHAPE[0] - (FOV_HI - FOV_LO)) * SHAPE[1] * SHAPE[2]


# ---------------------------------------------------------------------- detection
@pytest.mark.parametrize(
    ("name", "kind", "hu", "reason"),
    [
        ("head", "CT", True, "units HU"),
        ("fish", "CT", True, "units HU"),
        ("colin27", "MR", False, "sample metadata"),
        # a real CT stored as 0..32: not HU, so shown as other data (see module docs)
        ("stent", "other", False, "not Hounsfield units"),
    ],
)
def test_bundled_samples(name: str, kind: str, hu: bool, reason: str) -> None:
    m = detect_modality(load_sample(name))
    assert (m.kind, m.hu) == (kind, hu)
    assert reason in m.reason


def test_hu_values_without_units_are_ct() -> None:
    raw = Volume(load_sample("head").data)  # no units, no modality
    m = detect_modality(raw)
    assert (m.kind, m.hu) == ("CT", True)
    assert "look like HU" in m.reason
    assert detect_modality(padded_ct()).kind == "CT"  # padding does not hide it


def test_dicom_modality_field() -> None:
    data = load_sample("head").data
    assert str(detect_modality(Volume(data, modality="CT"))) == "CT (DICOM Modality)"
    assert (
        detect_modality(Volume(np.arange(64, dtype=np.uint8).reshape(4, 4, 4), modality="MR")).kind
        == "MR"
    )
    us = detect_modality(Volume(np.arange(64, dtype=np.uint8).reshape(4, 4, 4), modality="US"))
    assert (us.kind, us.reason) == ("other", "DICOM Modality US")


def _false_positives() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    shape = (48, 48, 48)
    return {
        "float MRI": rng.gamma(2.0, 150.0, shape).astype(np.float32),
        "float MRI shifted negative": (rng.gamma(2.0, 150.0, shape) - 300).astype(np.float32),
        "z-scored": rng.normal(0, 1, shape).astype(np.float32),
        "phase image": rng.integers(-4096, 4096, shape).astype(np.int16),
        "0..32 array": rng.integers(0, 33, shape).astype(np.uint8),
        "uint16 CT without intercept": rng.integers(0, 4096, shape).astype(np.uint16),
    }


@pytest.mark.parametrize("name", list(_false_positives()))
def test_non_ct_data_is_not_ct(name: str) -> None:
    vol = Volume(_false_positives()[name])
    m = detect_modality(vol)
    assert (m.kind, m.hu) == ("other", False), m
    assert padding_mask(vol) is None  # and nothing of it is masked as padding


# ---------------------------------------------------------------------- defaults
@pytest.mark.parametrize(
    ("name", "tf"), [("head", "ct-bone"), ("colin27", "mri"), ("stent", "ramp")]
)
def test_default_tf_window_shading_per_modality(name: str, tf: str) -> None:
    vol = load_sample(name)
    scene = Scene(vol)
    assert scene.transfer_function.name == tf
    assert tf in SURFACE_PRESETS
    assert scene.use_shading() is True  # DVR of a surface preset is shaded
    mip = Scene(vol, mode="mip")
    assert mip.use_shading() is False
    values = vol.data.ravel()
    for mode in ("mip", "minip"):
        lo, hi = np.percentile(values, WINDOW_PERCENTILES[mode])
        level, width = Scene(vol, mode=mode).window
        assert level - width / 2 == pytest.approx(lo, abs=1.0)
        assert level + width / 2 == pytest.approx(hi, abs=1.0)
    # the default TF shows something: some voxel is visible, most background is not
    alpha = scene.transfer_function(values)[:, 3]
    assert 0.001 < np.mean(alpha > 0.05) < 0.6


def test_other_data_never_assumes_hu() -> None:
    rng = np.random.default_rng(1)
    vol = Volume((rng.random((32, 32, 32)) * 32).astype(np.float32))
    tf = Scene(vol).transfer_function
    lo, hi = tf.value_range
    assert tf.name == "ramp"
    assert lo >= 0
    assert hi <= 32  # on the data's own percentiles, not on [-1000, 2000] HU


def test_description_line() -> None:
    text = display_defaults(load_sample("head"), "dvr").description
    assert text == "CT (units HU): tf ct-bone, shaded DVR"
    mip = display_defaults(load_sample("head"), "mip").description
    assert mip.startswith("CT (units HU): MIP window ")
    assert " HU (percentiles 1-99.9" in mip
    masked, _ = mask_padding(padded_ct())
    assert f"padding {PAD} masked (" in Scene(masked).display_note()
    assert f"padding {PAD} kept (" in Scene(padded_ct()).display_note()


def test_explicit_choices_are_kept(tmp_path: Path) -> None:
    vol = load_sample("head")
    scene = Scene(vol, transfer_function="ct-soft", window=(40.0, 400.0), shading=False)
    assert (scene.transfer_function.name, scene.window, scene.use_shading()) == (
        "ct-soft",
        (40.0, 400.0),
        False,
    )
    # a non-surface preset given without shading stays unshaded; ct-skin is shaded
    assert Scene(vol, transfer_function="ct-soft").use_shading() is False
    assert Scene(vol, transfer_function="ct-skin").use_shading() is True
    # scene JSON keeps what it says
    path = scene.save(tmp_path / "s.json")
    back = Scene.load(path)
    assert back.transfer_function.points == scene.transfer_function.points
    assert (back.window, back.use_shading()) == ((40.0, 400.0), False)


# ---------------------------------------------------------------------- padding
def test_mask_padding_replaces_padding_by_the_minimum_inside() -> None:
    vol = padded_ct()
    out, count = mask_padding(vol)
    assert count == pad_count()
    inside_min = vol.data[FOV_LO:FOV_HI].min()
    assert out.data.min() == inside_min
    np.testing.assert_array_equal(out.data[:FOV_LO], inside_min)
    np.testing.assert_array_equal(out.data[FOV_LO:FOV_HI], vol.data[FOV_LO:FOV_HI])
    assert vol.data.min() == PAD  # the input is untouched
    assert (out.spacing, out.origin, out.name, out.units) == (
        vol.spacing,
        vol.origin,
        vol.name,
        vol.units,
    )
    for name in ("colin27", "stent", "head"):  # nothing to mask: the same object back
        sample = load_sample(name)
        assert mask_padding(sample) == (sample, 0)


def test_dicom_padding_value_is_masked_on_water() -> None:
    # a CT whose field of view holds no air: the padding is known from the file only
    vol = padded_ct("water", units="HU", padding_value=PAD)
    out, count = mask_padding(vol)
    assert count == pad_count()
    assert out.data.min() > -100


def test_load_input_masks_and_keep_padding_keeps(tmp_path: Path) -> None:
    path = save_volume(padded_ct(), tmp_path / "padded.npz")
    masked = load_input(str(path))
    kept = load_input(str(path), keep_padding=True)
    assert kept.data.min() == PAD
    assert masked.data.min() == padded_ct().data[FOV_LO:FOV_HI].min()


def aligned_z(vol: Volume) -> tuple[Camera, tuple[int, int]]:
    """Orthographic camera on +z whose pixel centres fall on voxel columns (x, y)."""
    radius = float(np.linalg.norm(vol.size_mm))
    cam = Camera(
        center=vol.center,
        rotation=view_rotation("+z"),
        distance=2 * radius,
        projection="orthographic",
        ortho_height=vol.shape[1] * vol.spacing[1],
        radius=radius,
    )
    return cam, (vol.shape[0], vol.shape[1])


def columns(img: np.ndarray) -> tuple[float, float]:
    """Mean grey of the padding columns and of the in-FOV air columns x 14..17 (the
    padding is symmetric in x, so a mirrored image gives the same numbers)."""
    grey = img[..., 0]
    pad = np.concatenate([grey[:, :FOV_LO], grey[:, FOV_HI:]], axis=1).mean()
    air = np.concatenate([grey[:, 14:18], grey[:, 46:50]], axis=1).mean()
    return float(pad), float(air)


@pytest.mark.parametrize("mode", ["mip", "minip"])
def test_masked_padding_is_not_visible(offscreen: Any, mode: str) -> None:
    for vol in (mask_padding(padded_ct())[0], mask_padding(padded_ct("water", units="HU"))[0]):
        cam, size = aligned_z(vol)
        img = offscreen(*size, dtype="f4").render(Scene(vol, mode=mode, camera=cam, jitter=False))
        pad, air = columns(img)
        # the padding looks like the air (a MIP of noisy air is a little brighter than
        # the constant fill; padding inside the window would differ by about 0.4)
        assert abs(pad - air) < 0.06, (mode, pad, air)
        if mode == "mip":  # and the object is there
            assert img[size[1] // 2, size[0] // 2, 0] > 0.5


def test_keep_padding_keeps_it_visible(offscreen: Any) -> None:
    window = (-1000.0, 2400.0)  # -2200 .. 200: shows the padding apart from the air
    kept = padded_ct()
    masked = mask_padding(kept)[0]
    cam, size = aligned_z(kept)
    r = offscreen(*size, dtype="f4")
    pad_k, air_k = columns(r.render(Scene(kept, mode="mip", camera=cam, window=window)))
    pad_m, air_m = columns(r.render(Scene(masked, mode="mip", camera=cam, window=window)))
    assert pad_k == pytest.approx((PAD + 2200) / 2400, abs=0.01)
    assert air_k > pad_k + 0.3
    assert abs(pad_m - air_m) < 0.06


# ---------------------------------------------------------------------- warnings
def test_iso_value_outside_the_data_range_warns() -> None:
    vol = load_sample("colin27")
    with pytest.warns(UserWarning, match=r"iso value 5000 lies outside the data range 0\.\.247"):
        Scene(vol, mode="iso", iso_value=5000)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        Scene(vol, mode="iso", iso_value=100)
        Scene(vol, mode="dvr", iso_value=5000)  # not drawn: nothing to warn about


def test_hu_warning_only_where_a_hu_preset_meets_non_hu_data_in_a_tf_mode() -> None:
    stent, head = load_sample("stent"), load_sample("head")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for mode in ("mip", "minip", "average"):
            Scene(stent, mode=mode, transfer_function="ct-bone")
        Scene(head, mode="dvr", transfer_function="ct-bone")
        Scene(stent)  # the default is not a HU preset
    with pytest.warns(UserWarning, match="Hounsfield"):
        Scene(stent, mode="dvr", transfer_function="ct-bone")


# ---------------------------------------------------------------------- command line
def run_render(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.run(
        [sys.executable, "-m", "voxwarp.cli.main", "render", *args, "--size", "48x48"],
        capture_output=True,
        text=True,
        env=env,
        cwd=REPO,
        timeout=180,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    return proc


@pytest.mark.usefixtures("gl_ctx")
def test_cli_prints_the_defaults_line(tmp_path: Path) -> None:
    out = str(tmp_path / "x.png")
    err = run_render("sample:colin27", "-o", out).stderr
    assert "MR (sample metadata): tf mri, shaded DVR" in err.splitlines()
    err = run_render("sample:stent", "-o", out, "--mode", "mip", "--tf", "ct-bone").stderr
    assert "is in Hounsfield units but" not in err
    assert "MIP window" in err
    err = run_render("sample:head", "-o", out, "--tf", "ct-skin").stderr
    assert "CT (units HU): tf ct-skin, shaded DVR" in err
    assert "is in Hounsfield units but" not in err
    err = run_render("sample:stent", "-o", out, "--tf", "ct-bone").stderr
    assert "is in Hounsfield units but" in err


@pytest.mark.usefixtures("gl_ctx")
def test_cli_iso_out_of_range_and_padding(tmp_path: Path) -> None:
    out = str(tmp_path / "x.png")
    err = run_render("sample:colin27", "-o", out, "--mode", "iso", "--iso", "5000").stderr
    lines = [line for line in err.splitlines() if "iso value 5000" in line]
    assert len(lines) == 1
    assert "0..247" in lines[0]
    assert "--iso" in lines[0]
    path = str(save_volume(padded_ct(), tmp_path / "padded.npz"))
    err = run_render(path, "-o", out).stderr
    assert f"padding {PAD} masked ({pad_count() / 1e3:.0f} k voxels)" in err
    err = run_render(path, "-o", out, "--keep-padding").stderr
    assert f"padding {PAD} kept" in err


def test_default_xray_window_shows_the_thickest_material_white() -> None:
    """A ball in a mostly empty box: the default xray window starts at the air and puts
    the ball's longest chord near white (the value-percentile window left such
    radiographs dim)."""
    from voxwarp.core.modes import xray_reference_length
    from voxwarp.scene import Scene

    n = 96
    x, y, z = np.indices((n, n, n)) - (n - 1) / 2
    data = np.where(x**2 + y**2 + z**2 <= 20.0**2, 100, 0).astype(np.uint8)
    vol = Volume(data, spacing=(1.0, 1.0, 1.0))
    level, width = Scene(vol, mode="xray").window
    low = level - width / 2
    assert low == pytest.approx(0.0)
    diameter = 40.0 * 100 / xray_reference_length(vol)  # the centre ray's integral / L
    assert 0.9 <= diameter / width <= 1.1
