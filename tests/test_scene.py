"""Tests of voxwarp.scene: argument validation, JSON round trips, atomic save, bad scene files.

Pure CPU. The hypothesis fuzz feeds mutated scene dicts to ``Scene.from_dict``: it must
return a Scene or raise SceneError, never anything else.
"""

from __future__ import annotations

import base64
import copy
import json
import math
import os
import shutil
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from voxwarp.core.camera import PROJECTIONS, VIEWS, Camera
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import AffineWarp, IdentityWarp, chain_apply
from voxwarp.errors import SceneError
from voxwarp.io.volumes import save_volume
from voxwarp.scene import MODES, SCENE_FORMAT, SCENE_VERSION, Scene


# ---------------------------------------------------------------------- helpers
def small_volume(shape: tuple[int, int, int] = (3, 4, 5), dtype: Any = np.int16) -> Volume:
    """Distinct values per voxel so any axis or order mix-up changes the data."""
    data = (np.arange(np.prod(shape)).reshape(shape) * 7 - 300).astype(dtype)
    return Volume(
        data, spacing=(0.5, 0.75, 1.25), origin=(-3.0, 2.0, 10.0), name="tiny", units="HU"
    )


def full_scene(volume: Volume) -> Scene:
    """A scene with every optional setting away from its default."""
    cam = Camera.fit((-5, -4, -3), (6, 7, 8), view=(30.0, 20.0), projection="orthographic")
    return Scene(
        volume,
        mode="mip",
        transfer_function=[(-300, 0, 0, 0, 0), (0, 0.5, 0.25, 0.1, 0.3), (500, 1, 1, 1, 0.9)],
        view=(33.0, -12.5),
        projection="orthographic",
        step=0.5,
        warps=[
            AffineWarp.rotation((0, 0, 1), 30, center=(1, 2, 3)),
            IdentityWarp(),
            AffineWarp.translation((4, -5, 6)),
        ],
        window=(100.0, 400.0),
        clip_box=((-10, -11, -12), (10, 11, 12)),
        jitter=False,
        seed=1234,
        shading=True,
        iso_value=250.0,
        flm_threshold=75.0,
        background=(0.1, 0.2, 0.3, 0.4),
        camera=cam,
        zoom=1.7,
        fov=42.0,
    )


def assert_same_scene(a: Scene, b: Scene) -> None:
    """Field-by-field comparison (volume data included)."""
    assert a.mode == b.mode
    assert a.view == b.view
    assert a.projection == b.projection
    assert a.step == b.step
    assert a._window == b._window
    assert a.clip_box == b.clip_box
    assert a.jitter == b.jitter
    assert a.seed == b.seed
    assert a.shading == b.shading
    assert a.iso_value == b.iso_value
    assert a.flm_threshold == b.flm_threshold
    assert a.background == b.background
    assert a.zoom == b.zoom
    assert a.fov == b.fov
    assert a.transfer_function.points == b.transfer_function.points
    assert (a.camera is None) == (b.camera is None)
    if a.camera is not None:
        np.testing.assert_array_equal(a.camera.center, b.camera.center)
        np.testing.assert_array_equal(a.camera.rotation, b.camera.rotation)
        assert a.camera.distance == b.camera.distance
        assert a.camera.projection == b.camera.projection
        assert a.camera.ortho_height == b.camera.ortho_height
    assert [type(w) for w in a.warps] == [type(w) for w in b.warps]
    pts = np.random.default_rng(3).uniform(-20, 20, (50, 3))
    np.testing.assert_allclose(chain_apply(a.warps, pts), chain_apply(b.warps, pts), atol=1e-12)
    assert a.volume.shape == b.volume.shape
    assert a.volume.dtype == b.volume.dtype
    assert a.volume.spacing == b.volume.spacing
    assert a.volume.origin == b.volume.origin
    np.testing.assert_array_equal(a.volume.data, b.volume.data)


# ---------------------------------------------------------------------- validation
@pytest.mark.parametrize(
    ("kwargs", "needles"),
    [
        ({"mode": "radiograph"}, MODES),
        ({"mode": None}, MODES),
        ({"projection": "fisheye"}, PROJECTIONS),
        ({"view": "top"}, (*VIEWS, "azimuth")),
        ({"view": (1.0, 2.0, 3.0)}, (*VIEWS, "azimuth")),
        ({"view": (float("nan"), 0.0)}, ("finite",)),
        ({"step": 0}, ("step", "positive")),
        ({"step": -1.0}, ("step", "positive")),
        ({"step": float("nan")}, ("step", "finite")),
        ({"step": float("inf")}, ("step", "finite")),
        ({"step": 1e6}, ("step", "0.01", "100")),
        ({"step": 1e-4}, ("step", "0.01", "100")),
        ({"step": "fast"}, ("step", "number")),
        ({"window": (0.0, 0.0)}, ("window width", "positive")),
        ({"window": (0.0, -5.0)}, ("window width", "positive")),
        ({"window": (1.0,)}, ("window", "2")),
        ({"clip_box": ((0, 0, 0), (1, -1, 1))}, ("clip_box", "exceed")),
        ({"clip_box": ((0, 0, 0), (0, 1, 1))}, ("clip_box", "exceed")),
        ({"clip_box": ((0, 0), (1, 1))}, ("clip_box", "3")),
        ({"clip_box": 5}, ("clip_box", "(x0, y0, z0)")),
        ({"background": (1.5, 0, 0, 1)}, ("background", "[0, 1]")),
        ({"background": (-0.1, 0, 0)}, ("background", "[0, 1]")),
        ({"background": (0, 0, 0, float("nan"))}, ("background", "finite")),
        ({"zoom": 0}, ("zoom", "positive")),
        ({"zoom": -2.0}, ("zoom", "positive")),
        ({"fov": 0}, ("fov", "positive")),
        ({"fov": 179.5}, ("fov", "179")),
        ({"transfer_function": "rainbowz"}, ("ct-bone", "mri", "control points")),
    ],
)
def test_bad_argument_raises_scene_error_naming_allowed_values(
    kwargs: dict[str, Any], needles: tuple[str, ...]
) -> None:
    with pytest.raises(SceneError) as info:
        Scene(small_volume(), **kwargs)
    msg = str(info.value)
    for needle in needles:
        assert needle in msg, f"{needle!r} not in error message {msg!r}"


def test_scene_needs_a_volume() -> None:
    with pytest.raises(SceneError, match="Volume"):
        Scene(np.zeros((4, 4, 4)))  # type: ignore[arg-type]


def test_setters_validate_after_construction() -> None:
    scene = Scene(small_volume())
    with pytest.raises(SceneError, match="mode"):
        scene.mode = "radiograph"
    with pytest.raises(SceneError, match="step"):
        scene.step = -1
    assert scene.mode == "dvr"
    assert scene.step == 1.0


def test_valid_arguments_are_normalised() -> None:
    scene = Scene(
        small_volume(),
        view=[10, 20],
        step="2.5",
        background=(0.25, 0.5, 0.75),
        clip_box=([0, 0, 0], [1, 2, 3]),
        window=[10, 20],
    )
    assert scene.view == (10.0, 20.0)
    assert scene.step == 2.5
    assert scene.background == (0.25, 0.5, 0.75, 1.0)  # RGB gets opaque alpha
    assert scene.clip_box == ((0.0, 0.0, 0.0), (1.0, 2.0, 3.0))
    assert scene.window == (10.0, 20.0)


@pytest.mark.parametrize("kwargs", [{"view": 5}, {"background": 5}, {"view": ("a", "b")}])
def test_wrongly_typed_view_or_background_raises_scene_error(kwargs: dict[str, Any]) -> None:
    try:
        Scene(small_volume(), **kwargs)
    except SceneError:
        return
    pytest.fail("no SceneError")


def test_ray_bounds_are_clipped() -> None:
    vol = small_volume()
    # volume box: x in [-3.25, -1.75], y in [1.625, 4.625], z in [9.375, 15.625]
    scene = Scene(vol, clip_box=((-100, 2.5, -100), (-2.0, 100, 100)))
    lo, hi = scene.ray_bounds()
    np.testing.assert_allclose(lo, [-3.25, 2.5, 9.375])
    np.testing.assert_allclose(hi, [-2.0, 4.625, 15.625])


# ---------------------------------------------------------------------- round trips
@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.uint16, np.float32])
def test_embedded_volume_round_trip_keeps_data_dtype_and_order(dtype: Any) -> None:
    values = np.arange(60).reshape(3, 4, 5) * 3
    data = {
        np.uint8: values.astype(np.uint8),
        np.int16: (values * 100 - 9000).astype(np.int16),
        np.uint16: (values * 1000 + 7).astype(np.uint16),
        np.float32: (values / 7.0 - 0.125).astype(np.float32),
    }[dtype]
    vol = Volume(data, spacing=(1, 2, 3))
    scene = Scene(vol, transfer_function=[(0, 0, 0, 0, 0), (1, 1, 1, 1, 1)])
    d = json.loads(json.dumps(scene.to_dict()))
    assert "embedded" in d["volume"]
    back = Scene.from_dict(d)
    assert back.volume.dtype == vol.dtype
    assert back.volume.shape == vol.shape
    assert back.volume.data.flags.f_contiguous
    np.testing.assert_array_equal(back.volume.data, vol.data)
    # element [i, j, k] really is the one at the same index, not a transposed copy
    assert back.volume.data[2, 1, 4] == vol.data[2, 1, 4]
    assert back.volume.spacing == vol.spacing


def test_full_scene_round_trip_through_dict_and_file(tmp_path: Path) -> None:
    scene = full_scene(small_volume())
    back = Scene.from_dict(json.loads(json.dumps(scene.to_dict())))
    assert_same_scene(scene, back)

    path = scene.save(tmp_path / "scene.json")
    assert path == tmp_path / "scene.json"
    loaded = Scene.load(path)
    assert_same_scene(scene, loaded)
    assert loaded.volume.name == "tiny"
    assert loaded.volume.units == "HU"


def test_default_scene_round_trip() -> None:
    scene = Scene(small_volume())
    d = scene.to_dict()
    assert d["format"] == SCENE_FORMAT
    assert d["version"] == SCENE_VERSION
    assert d["camera"] is None
    assert d["window"] is None  # default window is not frozen into the file
    back = Scene.from_dict(d)
    assert_same_scene(scene, back)
    assert back.window == scene.window


def test_warps_round_trip() -> None:
    warps = [
        AffineWarp.scaling((1.5, 0.5, 2.0), center=(1, 1, 1)),
        AffineWarp.rotation((1, 1, 0), 73.0),
        IdentityWarp(),
        AffineWarp.translation((-2, 0, 9)),
    ]
    scene = Scene(small_volume(), warps=warps)
    back = Scene.from_dict(json.loads(json.dumps(scene.to_dict())))
    assert [type(w) for w in back.warps] == [type(w) for w in warps]
    for w, b in zip(warps, back.warps, strict=True):
        if isinstance(w, AffineWarp):
            np.testing.assert_array_equal(w.forward_matrix, b.forward_matrix)
    pts = np.random.default_rng(0).uniform(-10, 10, (100, 3))
    np.testing.assert_allclose(chain_apply(back.warps, pts), chain_apply(warps, pts), atol=1e-12)
    np.testing.assert_allclose(back.deformed_bounds(), scene.deformed_bounds())


def test_path_volume_is_referenced_relatively_and_survives_a_move(tmp_path: Path) -> None:
    src = tmp_path / "a"
    vol_path = save_volume(small_volume(), src / "data" / "vol.npz")
    from voxwarp.io.volumes import load_volume

    vol = load_volume(vol_path)
    scene = Scene(vol, mode="average", view="+x")
    scene.save(src / "scene.json")
    d = json.loads((src / "scene.json").read_text())
    assert "embedded" not in d["volume"]
    assert d["volume"]["path"] == os.path.join("data", "vol.npz")

    dst = tmp_path / "b" / "moved"
    shutil.move(str(src), str(dst))
    assert not vol_path.exists()
    loaded = Scene.load(dst / "scene.json")
    assert Path(loaded.volume.source).resolve() == (dst / "data" / "vol.npz").resolve()
    np.testing.assert_array_equal(loaded.volume.data, vol.data)
    assert loaded.mode == "average"
    assert loaded.view == "+x"


def test_path_volume_in_a_sibling_folder(tmp_path: Path) -> None:
    from voxwarp.io.volumes import load_volume

    vol = load_volume(save_volume(small_volume(), tmp_path / "volumes" / "v.nrrd"))
    Scene(vol).save(tmp_path / "scenes" / "s.json")
    d = json.loads((tmp_path / "scenes" / "s.json").read_text())
    # outside the scene's folder: absolute and sealed (voxwarp.core.scene_seal), so it
    # reopens from anywhere without a warning
    assert d["volume"]["path"] == str((tmp_path / "volumes" / "v.nrrd").resolve())
    assert "path_seal" in d
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        back = Scene.load(tmp_path / "scenes" / "s.json")
    np.testing.assert_array_equal(back.volume.data, vol.data)


def test_sample_volume_is_referenced_by_name() -> None:
    from voxwarp.io.samples import load_sample, sample_names

    assert "stent" in sample_names()

    vol = load_sample("stent")
    d = json.loads(json.dumps(Scene(vol, transfer_function="grayscale").to_dict()))
    assert d["volume"]["sample"] == "stent"
    assert "embedded" not in d["volume"]
    assert "path" not in d["volume"]
    back = Scene.from_dict(d)
    assert back.volume.source == "sample:stent"
    assert back.volume.shape == vol.shape
    np.testing.assert_array_equal(back.volume.data, vol.data)


def test_sample_generated_at_a_small_shape_round_trips() -> None:
    from voxwarp.io.samples import load_sample, sample_names

    assert "fish" in sample_names()

    vol = load_sample("fish", shape=(24, 12, 10))
    back = Scene.from_dict(Scene(vol).to_dict())
    assert back.volume.shape == (24, 12, 10)
    np.testing.assert_allclose(back.volume.size_mm, vol.size_mm)


# ---------------------------------------------------------------------- atomic save
def _listing(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_save_leaves_no_temp_files(tmp_path: Path) -> None:
    scene = Scene(small_volume())
    scene.save(tmp_path / "s.json")
    scene.copy(mode="mip").save(tmp_path / "s.json")  # overwrite
    assert _listing(tmp_path) == ["s.json"]
    assert Scene.load(tmp_path / "s.json").mode == "mip"


def test_save_creates_missing_folders(tmp_path: Path) -> None:
    Scene(small_volume()).save(tmp_path / "x" / "y" / "s.json")
    assert (tmp_path / "x" / "y" / "s.json").is_file()


@pytest.mark.parametrize("target", ["replace", "dumps", "fsync"])
def test_failing_save_keeps_the_previous_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, target: str
) -> None:
    path = tmp_path / "s.json"
    Scene(small_volume(), mode="mip").save(path)
    before = path.read_bytes()

    def boom(*args: Any, **kwargs: Any) -> Any:
        raise OSError("disk full (simulated)")

    if target == "replace":
        monkeypatch.setattr(os, "replace", boom)
    elif target == "fsync":
        monkeypatch.setattr(os, "fsync", boom)
    else:
        monkeypatch.setattr(json, "dumps", boom)
    with pytest.raises(OSError, match="simulated"):
        Scene(small_volume(), mode="minip").save(path)
    monkeypatch.undo()
    assert path.read_bytes() == before
    assert _listing(tmp_path) == ["s.json"]
    assert Scene.load(path).mode == "mip"


# ---------------------------------------------------------------------- bad scene files
def _write(tmp_path: Path, content: Any, name: str = "bad.json") -> Path:
    p = tmp_path / name
    if isinstance(content, bytes):
        p.write_bytes(content)
    elif isinstance(content, str):
        p.write_text(content)
    else:
        p.write_text(json.dumps(content))
    return p


def _valid_dict() -> dict[str, Any]:
    return json.loads(json.dumps(Scene(small_volume()).to_dict()))


def test_load_missing_file(tmp_path: Path) -> None:
    with pytest.raises(SceneError, match="no such scene file") as info:
        Scene.load(tmp_path / "nope.json")
    assert "nope.json" in str(info.value)


def test_load_not_json(tmp_path: Path) -> None:
    p = _write(tmp_path, "{this is not json")
    with pytest.raises(SceneError, match="not valid JSON") as info:
        Scene.load(p)
    assert str(p) in str(info.value)


def test_load_binary_file(tmp_path: Path) -> None:
    p = _write(tmp_path, b"\x89PNG\r\n\x1a\n\xff\xfe\x00\x00")
    with pytest.raises(SceneError, match=r"bad\.json"):
        Scene.load(p)


def test_load_directory(tmp_path: Path) -> None:
    (tmp_path / "d.json").mkdir()
    with pytest.raises(SceneError, match="cannot read"):
        Scene.load(tmp_path / "d.json")


@pytest.mark.parametrize(
    ("change", "pattern"),
    [
        ({"format": "something-else"}, "not a voxwarp scene"),
        ({"version": SCENE_VERSION + 1}, "newer.*upgrade"),
        ({"version": 99}, "99"),
        ({"version": "one"}, "version"),
    ],
)
def test_wrong_format_or_newer_version(
    tmp_path: Path, change: dict[str, Any], pattern: str
) -> None:
    d = _valid_dict()
    d.update(change)
    with pytest.raises(SceneError, match=pattern):
        Scene.load(_write(tmp_path, d))


@pytest.mark.parametrize("content", [[], [1, 2], "scene", 3, None])
def test_scene_json_that_is_not_an_object(tmp_path: Path, content: Any) -> None:
    with pytest.raises(SceneError, match="JSON object"):
        Scene.load(_write(tmp_path, json.dumps(content)))


def test_missing_volume_entry(tmp_path: Path) -> None:
    d = _valid_dict()
    del d["volume"]
    with pytest.raises(SceneError, match="no 'volume'"):
        Scene.load(_write(tmp_path, d))


def test_volume_entry_without_source(tmp_path: Path) -> None:
    d = _valid_dict()
    d["volume"] = {"spacing": [1, 1, 1]}
    with pytest.raises(SceneError, match="'path', 'sample' or 'embedded'"):
        Scene.load(_write(tmp_path, d))


def test_missing_volume_file_names_it(tmp_path: Path) -> None:
    d = _valid_dict()
    d["volume"] = {"path": "gone/volume.nrrd"}
    with pytest.raises(SceneError) as info:
        Scene.load(_write(tmp_path, d))
    msg = str(info.value)
    assert "volume.nrrd" in msg
    assert "no such file" in msg


def test_unknown_sample(tmp_path: Path) -> None:
    d = _valid_dict()
    d["volume"] = {"sample": "unicorn"}
    with pytest.raises(SceneError, match="unicorn"):
        Scene.load(_write(tmp_path, d))


@pytest.mark.parametrize(
    ("embedded", "pattern"),
    [
        ("raw bytes", "'embedded' must be an object"),
        ({"dtype": "int16", "shape": [4, 4, 4]}, "malformed"),
        ({"dtype": "int16", "shape": [4, 4, 4], "data": "***not base64***"}, "malformed"),
        ({"dtype": "int16", "shape": [4, 4, 4], "data": "AAAA"}, "bytes"),
        ({"dtype": "int16", "shape": [4, 4], "data": ""}, "shape"),
        ({"dtype": "int16", "shape": [4, 0, 4], "data": ""}, "shape"),
        ({"dtype": "object", "shape": [1, 1, 1], "data": "AAAAAAAAAAA="}, "numeric"),
        ({"dtype": "complex64", "shape": [1, 1, 1], "data": "AAAAAAAAAAA="}, "numeric"),
        ({"dtype": "no-such-type", "shape": [1, 1, 1], "data": ""}, "malformed"),
        ({"dtype": "int16", "shape": "big", "data": ""}, "malformed"),
    ],
)
def test_bad_embedded_data(tmp_path: Path, embedded: Any, pattern: str) -> None:
    d = _valid_dict()
    d["volume"]["embedded"] = embedded
    with pytest.raises(SceneError, match=pattern):
        Scene.load(_write(tmp_path, d))


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("spacing", "abc"),
        ("spacing", {"x": 1}),
        ("spacing", [1, 2]),
        ("spacing", [0, 1, 1]),
        ("origin", [[1], [1, 2]]),
        ("origin", [1, float("nan"), 2]),
    ],
)
def test_bad_volume_geometry(key: str, value: Any) -> None:
    d = _valid_dict()
    d["volume"][key] = value
    with pytest.raises(SceneError, match="scene volume"):
        Scene.from_dict(d)


# (2**62 + 15) * 4 wraps to 60 voxels in int64: exactly the 120 bytes of the (3, 4, 5) data
@pytest.mark.parametrize("shape", [[float("inf"), 4, 4], [2**62 + 15, 4, 1], [1.5e300, 1, 1]])
def test_absurd_embedded_shape(shape: list[Any]) -> None:
    d = _valid_dict()
    d["volume"]["embedded"]["shape"] = shape
    with pytest.raises(SceneError):
        Scene.from_dict(d)


def test_embedded_float_nan_is_rejected() -> None:
    d = _valid_dict()
    raw = np.full((2, 2, 2), np.nan, dtype=np.float32).tobytes(order="F")
    d["volume"]["embedded"] = {
        "dtype": "float32",
        "shape": [2, 2, 2],
        "data": base64.b64encode(raw).decode(),
    }
    # NaN voxels are not silently rendered: a SceneError, or a volume without NaN
    try:
        scene = Scene.from_dict(d)
    except SceneError:
        return
    assert np.all(np.isfinite(scene.volume.data)), "embedded NaN voxels accepted"


SINGULAR = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, 0], [0, 0, 0, 1]]


@pytest.mark.parametrize(
    ("key", "value", "pattern"),
    [
        ("jitter", "yes", "jitter"),
        ("seed", 1.5, "seed"),
        ("seed", True, "seed"),
        ("shading", "on", "shading"),
        ("camera", [1, 2, 3], "camera"),
        ("camera", {"fov": "wide"}, "camera"),
        ("warps", [{"type": "twirl"}], "warp.*twirl"),
        (
            "warps",
            [{"type": "affine", "matrix": SINGULAR}],
            "singular",
        ),
        ("transfer_function", {"colors": []}, "points"),
        ("transfer_function", {"preset": "nope"}, "nope"),
        ("warps", 5, "warp"),
        ("warps", [{"type": ["affine"]}], "unknown warp type"),
        ("transfer_function", {"points": 5}, "control point"),
        ("transfer_function", {"points": None}, "control point"),
        ("step", None, "step"),
        ("mode", "radiograph", "mode"),
        ("view", "top", "view"),
    ],
)
def test_bad_scene_entries(key: str, value: Any, pattern: str) -> None:
    d = _valid_dict()
    d[key] = value
    with pytest.raises(SceneError, match=pattern):
        Scene.from_dict(d)


# ---------------------------------------------------------------------- fuzz
json_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(min_value=-(2**70), max_value=2**70)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=8),
    lambda children: (
        st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=6), children, max_size=4)
    ),
    max_leaves=12,
)
# numeric triples/quads etc. reach deeper validation than arbitrary values do
near_values = st.lists(
    st.integers(min_value=-3, max_value=10) | st.floats(min_value=-1e3, max_value=1e3),
    max_size=5,
)


def _base_dict() -> dict[str, Any]:
    vol = Volume(
        (np.arange(64).reshape(4, 4, 4) * 5 - 250).astype(np.int16), spacing=(1, 2, 3), units="HU"
    )
    scene = Scene(
        vol,
        mode="iso",
        warps=[AffineWarp.rotation((0, 1, 0), 20), IdentityWarp()],
        window=(0, 100),
        clip_box=((-1, -1, -1), (3, 3, 3)),
        camera=Camera.fit((0, 0, 0), (4, 8, 12), view="+z"),
        transfer_function=[(-250, 0, 0, 0, 0), (0, 1, 0.5, 0.2, 0.4), (65, 1, 1, 1, 0.9)],
    )
    return json.loads(json.dumps(scene.to_dict()))


BASE = _base_dict()


def _paths(d: Any, prefix: tuple = ()) -> list[tuple]:
    out = []
    if isinstance(d, dict):
        for k, v in d.items():
            out.append((*prefix, k))
            out += _paths(v, (*prefix, k))
    elif isinstance(d, list) and any(isinstance(v, dict | list) for v in d):
        for i, v in enumerate(d):
            out.append((*prefix, i))
            out += _paths(v, (*prefix, i))
    return out


PATHS = _paths(BASE)


@st.composite
def mutated_scene_dicts(draw: st.DrawFn) -> dict[str, Any]:
    d = copy.deepcopy(BASE)
    for _ in range(draw(st.integers(min_value=1, max_value=3))):
        path = draw(st.sampled_from(PATHS))
        parent = d
        try:
            for k in path[:-1]:
                parent = parent[k]
            parent[path[-1]]  # still present after earlier mutations?
        except (KeyError, IndexError, TypeError):
            continue
        if draw(st.integers(min_value=0, max_value=9)) == 0 and isinstance(parent, dict):
            del parent[path[-1]]
        else:
            parent[path[-1]] = draw(json_values | near_values)
    return d


@pytest.mark.filterwarnings("ignore::UserWarning")
@settings(
    max_examples=200,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(mutated_scene_dicts())
def test_from_dict_fuzz_returns_scene_or_raises_scene_error(d: dict[str, Any]) -> None:
    try:
        scene = Scene.from_dict(d)
    except SceneError as exc:
        message = str(exc)
    else:
        message = None
    if message is not None:
        assert message, "SceneError without a message"
        return
    assert isinstance(scene, Scene)
    # what was accepted is usable: serialisable and its derived values are computable
    json.dumps(scene.to_dict())
    try:
        lo, hi = scene.ray_bounds()
        scene.resolved_camera()
        scene.resolved_iso_value()
        scene.resolved_flm_threshold()
    except SceneError:
        return
    assert lo.shape == hi.shape == (3,)


def test_fuzz_base_dict_is_valid() -> None:
    scene = Scene.from_dict(copy.deepcopy(BASE))
    assert scene.mode == "iso"
    assert len(scene.warps) == 2
    assert len(PATHS) > 20  # the fuzz reaches nested entries
    assert math.isclose(scene.step, 1.0)


@pytest.mark.parametrize("source", ["sample", "file"])
def test_a_scene_of_a_downsampled_volume_reloads_downsampled(tmp_path: Path, source: str) -> None:
    from voxwarp.io.samples import load_sample
    from voxwarp.io.volumes import load_volume, save_volume

    full = load_sample("colin27")
    if source == "file":
        full = load_volume(save_volume(full, tmp_path / "head.nrrd"))
    small = full.downsample(2)
    back = Scene.load(Scene(small).save(tmp_path / "s.json")).volume
    assert back.shape == small.shape
    np.testing.assert_allclose(back.spacing, small.spacing)
    np.testing.assert_allclose(back.origin, small.origin)
    np.testing.assert_array_equal(back.data, small.data)
    if source == "file":  # the file changed since (no integer factor explains it)
        save_volume(full.with_geometry(full.data[:50]), tmp_path / "head.nrrd")
        with pytest.raises(SceneError, match="changed since"):
            Scene.load(tmp_path / "s.json")


@pytest.mark.parametrize("shape", [(64, 32, 32), (96, 96, 96)])
def test_a_larger_file_of_the_same_voxel_size_is_a_changed_file(
    tmp_path: Path, shape: tuple[int, int, int]
) -> None:
    """A scene saved from a whole 32³ file whose file now holds a larger field of view at
    the same voxel size (2x along one axis, 3x along all) is refused, not read as a
    downsampled copy squeezed into the saved box."""
    from voxwarp.core.volume import Volume
    from voxwarp.io.volumes import load_volume, save_volume

    rng = np.random.default_rng(3)
    path = tmp_path / "vol.nrrd"
    vol = load_volume(save_volume(Volume(rng.random((32, 32, 32), np.float32)), path))
    Scene(vol).save(tmp_path / "s.json")
    save_volume(Volume(rng.random(shape, np.float32)), path)
    with pytest.raises(SceneError, match="changed since"):
        Scene.load(tmp_path / "s.json")


def test_transfer_function_file_in_python_but_not_in_scene_json(tmp_path: Path) -> None:
    """``Scene(..., transfer_function="FILE:NAME")`` reads the file as ``--tf`` does; a
    scene JSON naming a file is refused in one line (it would read outside the scene)."""
    from voxwarp.core.transfer_function import TransferFunction

    tf_file = tmp_path / "maps.json"
    tf_file.write_text(
        json.dumps(
            [
                {"Name": "A", "ColorSpace": "RGB", "RGBPoints": [0, 0, 0, 0, 10, 1, 0, 0]},
                {"Name": "B", "ColorSpace": "RGB", "RGBPoints": [0, 0, 0, 1, 10, 0, 1, 0]},
            ]
        ),
        encoding="utf-8",
    )
    vol = small_volume()
    scene = Scene(vol, transfer_function=f"{tf_file}:B")
    expected = TransferFunction.load(str(tf_file), vol, name="B")
    assert scene.transfer_function.points == expected.points
    assert scene.transfer_function(10.0)[:3].tolist() == [0.0, 1.0, 0.0]
    with pytest.raises(SceneError, match=r"no such|cannot read"):
        Scene(vol, transfer_function=str(tmp_path / "missing.json"))
    d = Scene(vol).to_dict()
    d["transfer_function"] = f"{tf_file}:B"
    with pytest.raises(SceneError, match="names a file"):
        Scene.from_dict(d)
