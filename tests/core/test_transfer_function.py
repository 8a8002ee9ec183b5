"""Tests of voxwarp.core.transfer_function: presets, interpolation, GPU table, visibility, files.

Pure CPU; expected values come from the definitions in the module docstring (piecewise
linear, opacity correction ``1 - (1 - a) ** r``, HU rescaling), computed here
independently.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from voxwarp.core.transfer_function import PRESETS, TABLE_SIZE, TransferFunction
from voxwarp.core.volume import Volume
from voxwarp.errors import SceneError

HU_PRESETS = ("ct-bone", "ct-skin", "ct-soft", "ct-muscle")
RELATIVE_PRESETS = ("mri", "grayscale", "hot")


def uint8_ramp() -> Volume:
    """A non-HU uint8 volume (values 0..255, units unknown), small enough to be unsampled."""
    data = (np.arange(32 * 32 * 16) % 256).astype(np.uint8).reshape(32, 32, 16)
    return Volume(data, name="ramp")


def percentile_range(vol: Volume) -> tuple[float, float]:
    lo, hi = np.percentile(vol.data, [0.5, 99.5])
    return float(lo), float(hi)


# ---------------------------------------------------------------------- presets
def test_presets_cover_the_documented_names() -> None:
    assert set(PRESETS) == {*HU_PRESETS, *RELATIVE_PRESETS}


@pytest.mark.parametrize("name", PRESETS)
def test_every_preset_resolves(name: str) -> None:
    tf = TransferFunction.preset(name)
    assert tf.name == name
    pts = np.asarray(tf.points)
    assert pts.shape[1] == 5
    assert len(pts) >= 2
    assert np.all(np.diff(pts[:, 0]) > 0), "preset values must increase"
    assert np.all((pts[:, 1:] >= 0) & (pts[:, 1:] <= 1))
    assert pts[:, 4].max() > 0, "a preset must show something"
    if name in HU_PRESETS:
        assert (pts[0, 0], pts[-1, 0]) == (-1000.0, 2000.0)
    else:
        assert (pts[0, 0], pts[-1, 0]) == (0.0, 1.0)
    # coerce by name gives the same points
    assert TransferFunction.coerce(name).points == tf.points


@pytest.mark.parametrize("name", HU_PRESETS)
def test_hu_preset_on_hu_volume_is_unchanged_and_silent(name: str) -> None:
    for vol in (
        Volume(np.full((4, 4, 4), 40, np.int16), units="HU"),
        # no units, but an air peak at -1000 and values up to 1890: looks like HU
        Volume(np.where(np.arange(64) < 32, -1000, np.arange(64) * 30).reshape(4, 4, 4)),
    ):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            tf = TransferFunction.preset(name, vol)
        assert tf.points == TransferFunction.preset(name).points


@pytest.mark.parametrize("name", HU_PRESETS)
def test_hu_preset_on_uint8_volume_warns_and_rescales(name: str) -> None:
    vol = uint8_ramp()
    lo, hi = percentile_range(vol)
    with pytest.warns(UserWarning, match="Hounsfield") as rec:
        tf = TransferFunction.preset(name, vol)
    assert "ramp" in str(rec[0].message)
    hu = np.asarray(TransferFunction.preset(name).points)
    pts = np.asarray(tf.points)
    # [-1000, 2000] HU maps linearly onto the 0.5..99.5 percentile range
    np.testing.assert_allclose(pts[:, 0], lo + (hu[:, 0] + 1000) / 3000 * (hi - lo))
    np.testing.assert_array_equal(pts[:, 1:], hu[:, 1:])
    assert pts[0, 0] == pytest.approx(lo)
    assert pts[-1, 0] == pytest.approx(hi)
    assert 0 <= lo < hi <= 255
    # the rescaled preset shows part of the volume's range (not all clamped to one end)
    alpha = tf(np.arange(256))[:, 3]
    assert alpha.max() > 0
    assert alpha.min() == 0


@pytest.mark.parametrize("name", RELATIVE_PRESETS)
def test_relative_preset_maps_onto_the_percentile_range(name: str) -> None:
    vol = Volume(np.linspace(-50.0, 450.0, 4096, dtype=np.float32).reshape(16, 16, 16))
    lo, hi = percentile_range(vol)
    unit = np.asarray(TransferFunction.preset(name).points)
    pts = np.asarray(TransferFunction.preset(name, vol).points)
    np.testing.assert_allclose(pts[:, 0], lo + unit[:, 0] * (hi - lo), rtol=1e-6)
    np.testing.assert_array_equal(pts[:, 1:], unit[:, 1:])


def test_unknown_preset_lists_the_presets() -> None:
    with pytest.raises(SceneError) as info:
        TransferFunction.preset("rainbowz")  # neither preset nor colour map
    for name in PRESETS:
        assert name in str(info.value)


# ---------------------------------------------------------------------- evaluation
def test_halfway_between_two_points_is_the_average() -> None:
    c0 = (0.1, 0.2, 0.9, 0.0)
    c1 = (0.9, 0.6, 0.1, 0.8)
    tf = TransferFunction([(100.0, *c1), (-20.0, *c0)])  # unsorted on purpose
    mid = tf(40.0)
    np.testing.assert_allclose(mid, (np.asarray(c0) + np.asarray(c1)) / 2, atol=1e-12)
    # a quarter of the way, and clamped outside
    np.testing.assert_allclose(tf(10.0), 0.75 * np.asarray(c0) + 0.25 * np.asarray(c1))
    np.testing.assert_allclose(tf(-1e6), c0)
    np.testing.assert_allclose(tf(1e6), c1)
    assert tf(np.zeros((2, 3))).shape == (2, 3, 4)


def test_interpolation_is_piecewise_between_neighbours() -> None:
    rng = np.random.default_rng(1)
    xs = np.sort(rng.choice(1000, 6, replace=False)).astype(float)
    cols = rng.uniform(0, 1, (6, 4))
    tf = TransferFunction([(x, *c) for x, c in zip(xs, cols, strict=True)])
    for i in range(5):
        for t in (0.0, 0.3, 0.5, 0.9):
            v = xs[i] + t * (xs[i + 1] - xs[i])
            np.testing.assert_allclose(tf(v), (1 - t) * cols[i] + t * cols[i + 1], atol=1e-12)


def test_value_range_of_a_single_point_is_non_empty() -> None:
    tf = TransferFunction([(5.0, 1, 1, 1, 0.5)])
    lo, hi = tf.value_range
    assert lo == 5.0
    assert hi > lo
    np.testing.assert_allclose(tf(np.array([-10.0, 5.0, 99.0])), [[1, 1, 1, 0.5]] * 3)


# ---------------------------------------------------------------------- gpu table
def ramp_tf() -> TransferFunction:
    """Alpha rises linearly 0 -> 0.8 over [0, 100]; colour is a constant."""
    return TransferFunction([(0.0, 0.2, 0.5, 1.0, 0.0), (100.0, 0.2, 0.5, 1.0, 0.8)])


def test_table_samples_the_value_range_uniformly() -> None:
    table = ramp_tf().table(11)
    assert table.dtype == np.float32
    assert table.shape == (11, 4)
    np.testing.assert_allclose(table[:, 3], np.linspace(0, 0.8, 11), atol=1e-7)
    np.testing.assert_allclose(table[:, :3], np.tile([0.2, 0.5, 1.0], (11, 1)), atol=1e-7)


def test_gpu_table_ratio_one_is_premultiplied_straight_colour() -> None:
    tf = ramp_tf()
    gpu = tf.gpu_table(1.0)
    assert gpu.shape == (2, TABLE_SIZE, 4)
    assert gpu.dtype == np.float32
    a = np.linspace(0, 0.8, TABLE_SIZE)
    np.testing.assert_allclose(gpu[1, :, 3], a, atol=1e-6)
    np.testing.assert_allclose(gpu[0, :, 3], a, atol=1e-6)
    np.testing.assert_allclose(gpu[0, :, :3], np.outer(a, [0.2, 0.5, 1.0]), atol=1e-6)
    np.testing.assert_allclose(gpu[1, :, :3], np.tile([0.2, 0.5, 1.0], (TABLE_SIZE, 1)), atol=1e-7)


@pytest.mark.parametrize(
    ("alpha", "ratio", "expected"),
    [
        (0.5, 2.0, 0.75),  # two half-transparent layers
        (0.5, 0.5, 1 - np.sqrt(0.5)),
        (0.75, 2.0, 1 - 0.25**2),
        (0.75, 0.5, 0.5),  # sqrt(0.25) = 0.5
        (1.0, 0.5, 1.0),  # opaque stays opaque
        (0.0, 2.0, 0.0),  # transparent stays transparent
    ],
)
def test_opacity_correction_matches_analytic_values(
    alpha: float, ratio: float, expected: float
) -> None:
    tf = TransferFunction([(0.0, 0.4, 0.6, 0.8, alpha), (1.0, 0.4, 0.6, 0.8, alpha)])
    gpu = tf.gpu_table(ratio, size=64)
    np.testing.assert_allclose(gpu[0, :, 3], expected, atol=1e-6)
    np.testing.assert_allclose(
        gpu[0, :, :3], np.outer(np.full(64, expected), [0.4, 0.6, 0.8]), atol=1e-6
    )
    np.testing.assert_allclose(gpu[1, :, 3], alpha, atol=1e-7)  # straight row unchanged


def test_opacity_correction_composes() -> None:
    """Two samples at half the distance absorb as much as one at the full distance."""
    tf = ramp_tf()
    full = tf.gpu_table(1.0)[0, :, 3].astype(np.float64)
    half = tf.gpu_table(0.5)[0, :, 3].astype(np.float64)
    np.testing.assert_allclose(1 - (1 - half) ** 2, full, atol=1e-6)


# ---------------------------------------------------------------------- visible_ranges
def bump_tf() -> TransferFunction:
    """Visible only strictly inside (40, 60); alpha 0 elsewhere on [0, 100]."""
    return TransferFunction(
        [
            (0.0, 1, 0, 0, 0.0),
            (40.0, 1, 1, 0, 0.0),
            (50.0, 1, 1, 1, 1.0),
            (60.0, 0, 1, 1, 0.0),
            (100.0, 0, 0, 1, 0.0),
        ]
    )


def brute_force_visible(tf: TransferFunction, lo: float, hi: float, n: int = 4001) -> bool:
    return bool(np.any(tf(np.linspace(lo, hi, n))[:, 3] > 0))


def test_visible_ranges_is_conservative_and_tight_on_random_ranges() -> None:
    tf = bump_tf()
    rng = np.random.default_rng(7)
    a = rng.uniform(-30, 130, 3000)
    b = a + rng.exponential(8.0, 3000) * (rng.random(3000) < 0.9)  # some empty ranges
    lo, hi = a, b
    vis = tf.visible_ranges(lo, hi)
    assert vis.shape == lo.shape
    assert vis.dtype == bool
    cell = 100.0 / (TABLE_SIZE - 1)
    n_visible = n_invisible = 0
    for i in range(len(lo)):
        if brute_force_visible(tf, lo[i], hi[i]):
            assert vis[i], f"[{lo[i]}, {hi[i]}] shows the bump but was reported invisible"
            n_visible += 1
        # tight: ranges clearly away from (40, 60) are skipped
        if hi[i] < 40 - 2 * cell or lo[i] > 60 + 2 * cell:
            assert not vis[i], f"[{lo[i]}, {hi[i]}] is invisible but reported visible"
            n_invisible += 1
    assert n_visible > 300
    assert n_invisible > 300


def test_visible_ranges_edges_of_the_bump() -> None:
    tf = bump_tf()
    cell = 100.0 / (TABLE_SIZE - 1)
    lo = np.array([59.99, 30.0, 40.0 - 3 * cell, 60.0 + 3 * cell, 45.0, -500.0, 500.0, 50.0])
    hi = np.array([70.00, 40.01, 40.0 - 2 * cell, 90.0, 45.0, -400.0, 600.0, 50.0])
    expected = [True, True, False, False, True, False, False, True]
    assert tf.visible_ranges(lo, hi).tolist() == expected


def test_visible_ranges_accepts_block_grids() -> None:
    tf = bump_tf()
    rng = np.random.default_rng(3)
    lo = rng.uniform(0, 100, (3, 4, 5)).astype(np.float32)
    hi = lo + rng.uniform(0, 10, (3, 4, 5)).astype(np.float32)
    vis = tf.visible_ranges(lo, hi)
    assert vis.shape == (3, 4, 5)
    for idx in np.ndindex(lo.shape):
        if brute_force_visible(tf, float(lo[idx]), float(hi[idx])):
            assert vis[idx]


def test_visible_ranges_of_invisible_and_opaque_functions() -> None:
    lo = np.array([-1e3, 0.0, 0.5, 7.0])
    hi = np.array([-1e2, 0.1, 0.5, 1e4])
    nothing = TransferFunction([(0.0, 1, 1, 1, 0.0), (1.0, 1, 1, 1, 0.0)])
    assert not nothing.visible_ranges(lo, hi).any()
    everything = TransferFunction([(0.0, 1, 1, 1, 0.1), (1.0, 1, 1, 1, 0.1)])
    assert everything.visible_ranges(lo, hi).all()


def test_visible_ranges_outside_the_table_follow_the_clamped_ends() -> None:
    """Values beyond the control points take the end points' opacity (clamping)."""
    tf = TransferFunction([(0.0, 0, 0, 0, 0.0), (10.0, 1, 1, 1, 0.5)])
    vis = tf.visible_ranges(np.array([-50.0, 20.0]), np.array([-40.0, 30.0]))
    assert vis.tolist() == [
        brute_force_visible(tf, -50.0, -40.0),
        brute_force_visible(tf, 20.0, 30.0),
    ]
    assert vis.tolist() == [False, True]


def test_first_visible_value() -> None:
    assert bump_tf().first_visible_value() == 40.0
    assert TransferFunction([(3.0, 1, 1, 1, 0.2), (9.0, 1, 1, 1, 0.0)]).first_visible_value() == 3
    # invisible function: the last value (nothing exceeds it)
    invisible = TransferFunction([(1.0, 1, 1, 1, 0.0), (2.0, 1, 1, 1, 0.0)])
    assert invisible.first_visible_value() == 2.0


# ---------------------------------------------------------------------- bad points
@pytest.mark.parametrize(
    ("points", "pattern"),
    [
        ([], "at least one control point"),
        ([(0, 1, 1, 1)], r"\(value, r, g, b, a\)"),
        ([(0, 1, 1, 1, 1, 1)], r"\(value, r, g, b, a\)"),
        ([(0, 1, 1, 1, 1), (1, 1, 1)], "control points"),
        ([(float("nan"), 1, 1, 1, 1)], "NaN"),
        ([(0, 1, float("nan"), 1, 1)], "NaN"),
        ([(float("inf"), 1, 1, 1, 1)], "NaN/Inf"),
        ([(0, 1.5, 0, 0, 0)], r"\[0, 1\]"),
        ([(0, 0, 0, 0, -0.1)], r"\[0, 1\]"),
        ([(0, 0, 0, 0, 1.01)], r"\[0, 1\]"),
        ([("a", 0, 0, 0, 0)], "number"),
        ([5, 6], "control points"),
        (5, "control points"),
        (None, "control points"),
    ],
)
def test_bad_points_raise_scene_error(points: Any, pattern: str) -> None:
    with pytest.raises(SceneError, match=pattern):
        TransferFunction(points)


def test_coerce_rejects_none_and_accepts_points_and_dicts() -> None:
    with pytest.raises(SceneError, match="None"):
        TransferFunction.coerce(None)
    pts = [(0, 0, 0, 0, 0), (1, 1, 1, 1, 1)]
    assert TransferFunction.coerce(pts).points == [tuple(map(float, p)) for p in pts]
    tf = TransferFunction.coerce({"points": pts, "name": "mine"})
    assert tf.name == "mine"
    same = TransferFunction.coerce(tf)
    assert same is tf
    assert TransferFunction.coerce({"preset": "hot"}).name == "hot"
    with pytest.raises(SceneError, match="'points' or 'preset'"):
        TransferFunction.coerce({"colours": pts})
    with pytest.raises(SceneError, match=r"unknown transfer function keys \['opacity'\]"):
        TransferFunction.coerce({"points": pts, "opacity": 0.5})  # not silently ignored


def test_to_dict_from_dict_round_trip() -> None:
    tf = bump_tf()
    back = TransferFunction.from_dict(json.loads(json.dumps(tf.to_dict())))
    assert back.points == tf.points
    assert back.name == tf.name


# ---------------------------------------------------------------------- files
def test_load_to_dict_file_and_bare_list(tmp_path: Path) -> None:
    tf = TransferFunction(
        [(0, 0, 0, 0, 0), (10, 1, 0.5, 0.25, 0.75), (20, 1, 1, 1, 1)], name="three"
    )
    p = tmp_path / "tf.json"
    p.write_text(json.dumps(tf.to_dict()))
    loaded = TransferFunction.load(str(p))
    assert loaded.points == tf.points
    assert loaded.name == "three"
    np.testing.assert_allclose(loaded(15.0), [1, 0.75, 0.625, 0.875])

    q = tmp_path / "list.json"
    q.write_text(json.dumps([[20, 1, 1, 1, 1], [0, 0, 0, 0, 0]]))
    bare = TransferFunction.load(str(q))
    assert bare.points == [(0.0, 0.0, 0.0, 0.0, 0.0), (20.0, 1.0, 1.0, 1.0, 1.0)]
    assert bare.name == "custom"

    r = tmp_path / "preset.json"
    r.write_text(json.dumps({"preset": "grayscale"}))
    assert TransferFunction.load(str(r)).points == TransferFunction.preset("grayscale").points


@pytest.mark.parametrize(
    ("content", "pattern"),
    [
        (b"{not json", "cannot read"),
        (b"", "cannot read"),
        (b"\x89PNG\r\n\x1a\n\xff\xfe\x00", "cannot read"),  # binary, not UTF-8
        (b"42", "expected a JSON object or list"),
        (b'"ct-bone"', "expected a JSON object or list"),
        (b'{"colours": []}', "'points' or 'preset'"),
        (b'{"points": []}', "at least one control point"),
        (b'{"points": 5}', "control points"),
        (b'{"points": [[0, 2, 0, 0, 0]]}', r"\[0, 1\]"),
        (b"[[0, 1, 1]]", r"\(value, r, g, b, a\)"),
        (b'{"preset": "unicorn"}', "unicorn"),
    ],
)
def test_load_bad_files(tmp_path: Path, content: bytes, pattern: str) -> None:
    p = tmp_path / "bad.json"
    p.write_bytes(content)
    with pytest.raises(SceneError, match=pattern):
        TransferFunction.load(str(p))


def test_load_missing_file_and_folder(tmp_path: Path) -> None:
    with pytest.raises(SceneError, match="no such transfer function file") as info:
        TransferFunction.load(str(tmp_path / "missing.json"))
    assert "missing.json" in str(info.value)
    with pytest.raises(SceneError, match="cannot read"):
        TransferFunction.load(str(tmp_path))


@pytest.mark.parametrize("bad", [123, 1.5, object()])
def test_a_transfer_function_of_the_wrong_type_is_a_scene_error(bad: object) -> None:
    """A number or an object used to surface as Python's "'int' object is not iterable";
    now it is a SceneError naming what a transfer function may be."""
    with pytest.raises(SceneError, match="must be a preset name, a file, control points"):
        TransferFunction.coerce(bad)
