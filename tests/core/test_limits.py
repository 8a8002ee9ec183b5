"""Bounds on every number that sizes an allocation or a loop (issue 17, finding 5 and the
numeric tracebacks of finding 7): each limit refuses a value over it with a one-line
VoxwarpError *before* allocating (tracemalloc peak, or the reader never called), a value
at the limit still works, and `info` describes volumes of extreme values."""

from __future__ import annotations

import json
import math
import time
import tracemalloc
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import nibabel as nib
import nrrd
import numpy as np
import pytest
import tifffile

from tests.io.test_io import write_dicom_slice
from voxwarp.cli.main import build_parser, main
from voxwarp.core import limits
from voxwarp.core.mesh import GENERATORS, Mesh, tile_mesh
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import WarpError
from voxwarp.deform.wires.field import (
    MAX_MASK_PIXELS,
    MAX_WIRE_POINTS,
    Wire,
    WireDeformer,
)
from voxwarp.errors import MeshError, SceneError, VolumeError, VoxwarpError
from voxwarp.io.samples import load_sample
from voxwarp.io.volumes import load_volume, volume_info, volume_summary
from voxwarp.render.raycaster import _downsample_advice
from voxwarp.sample_volumes import generators
from voxwarp.scene import Scene

#: Most bytes a refused request may allocate while it is checked (a tenth of the
#: smallest bomb below would be 10 MB; the checks allocate a few KB).
SMALL = 2 << 20


@contextmanager
def small_and_fast(peak: int = SMALL, seconds: float = 1.0) -> Iterator[None]:
    """Assert the block allocates at most ``peak`` bytes (Python/numpy allocations seen
    by tracemalloc) and runs under ``seconds``."""
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        yield
    finally:
        elapsed = time.perf_counter() - t0
        _, top = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    assert top < peak, f"allocated {top} bytes"
    assert elapsed < seconds, f"took {elapsed:.2f} s"


def one_line(exc: BaseException) -> str:
    text = str(exc)
    assert "\n" not in text
    assert text
    return text


# ---------------------------------------------------------------------------- samples
def test_sample_shape_over_the_limit_is_refused_before_allocating() -> None:
    with small_and_fast(), pytest.raises(VolumeError) as info:
        load_sample("fish", shape=(3000, 3000, 3000))
    text = one_line(info.value)
    assert "(3000, 3000, 3000)" in text
    assert f"{generators.MAX_SAMPLE_VOXELS:,}" in text


def test_scene_json_sample_shape_is_a_scene_error(tmp_path: Path) -> None:
    path = tmp_path / "big.json"
    scene = {"format": "voxwarp-scene", "volume": {"sample": "head", "shape": [3000] * 3}}
    path.write_text(json.dumps(scene))
    with small_and_fast(), pytest.raises(SceneError) as info:
        Scene.load(path)
    assert "phantom limits" in one_line(info.value)


def test_sample_shape_at_the_limits_passes_the_check() -> None:
    axis, voxels = generators.MAX_SAMPLE_AXIS, generators.MAX_SAMPLE_VOXELS
    assert generators._check_shape((axis, 1, 1)) == (axis, 1, 1)
    at = (1024, 256, voxels // (1024 * 256))
    assert math.prod(at) == voxels
    assert generators._check_shape(at) == at
    with pytest.raises(ValueError, match="phantom limits"):
        generators._check_shape((axis + 1, 1, 1))
    with pytest.raises(ValueError, match="phantom limits"):
        generators._check_shape((at[0], at[1], at[2] + 1))
    assert load_sample("head", shape=(8, 8, 8)).shape == (8, 8, 8)


# ---------------------------------------------------------------------------- meshes
BOMBS: dict[str, dict[str, Any]] = {
    "uv_sphere": {"rows": 100_000, "cols": 100_000},
    "cylinder_mesh": {"sections": 10**9},
    "torus_mesh": {"major_sections": 10**5, "minor_sections": 10**5},
    "tile_mesh": {"nx": 10**5, "ny": 10**5},
    "tube_mesh": {"rings": 10**6, "sections": 10**6},
    "height_tile": {"n": 10**5},
    "box_mesh_tessellated": {"cells": [10**5] * 3},
}


@pytest.mark.parametrize("generator", sorted(BOMBS))
def test_mesh_generator_bombs_are_refused_before_allocating(generator: str) -> None:
    with small_and_fast(), pytest.raises(MeshError) as info:
        Mesh.from_dict({"generator": generator, "args": BOMBS[generator]})
    text = one_line(info.value)
    assert generator in text
    assert f"{limits.MAX_MESH_TRIANGLES:,}" in text


def test_every_generator_with_a_count_argument_is_covered() -> None:
    assert set(BOMBS) == set(GENERATORS) - {"box_mesh"}  # box_mesh has 12 triangles


def test_triangle_counts_checked_are_those_made(monkeypatch: pytest.MonkeyPatch) -> None:
    """The count each generator checks before allocating is the count it then makes (so
    the limit means what it says), for small arguments of every generator."""
    from voxwarp.core import mesh as mesh_module

    checked: list[int] = []
    real = mesh_module._check_triangles
    monkeypatch.setattr(
        mesh_module, "_check_triangles", lambda g, n: (checked.append(n), real(g, n))[1]
    )
    small = {
        "uv_sphere": {"rows": 5, "cols": 7},
        "cylinder_mesh": {"sections": 9},
        "torus_mesh": {"major_sections": 6, "minor_sections": 5},
        "tile_mesh": {"nx": 3, "ny": 4},
        "tube_mesh": {"rings": 6, "sections": 5},
        "height_tile": {"n": 4},
        "box_mesh_tessellated": {"cells": [2, 3, 4]},
    }
    for generator, args in small.items():
        made = GENERATORS[generator](**args).n_faces
        assert checked.pop() == made, generator


def test_triangle_limit_is_inclusive() -> None:
    from voxwarp.core.mesh import _check_triangles

    _check_triangles("tile_mesh", limits.MAX_MESH_TRIANGLES)
    with pytest.raises(MeshError):
        _check_triangles("tile_mesh", limits.MAX_MESH_TRIANGLES + 1)
    side = math.isqrt(limits.MAX_MESH_TRIANGLES // 2)
    with pytest.raises(MeshError):
        tile_mesh(nx=side + 1, ny=side)
    assert tile_mesh(nx=side // 8, ny=side // 8).n_faces == limits.MAX_MESH_TRIANGLES // 64


# ---------------------------------------------------------------------------- wires
def small_volume() -> Volume:
    data = np.zeros((16, 16, 16), dtype=np.int16)
    data[4:12, 6:10, 6:10] = 100
    return Volume(data, spacing=(1.0, 1.0, 1.0))


def line(n: int) -> np.ndarray:
    return np.c_[np.linspace(1.0, 14.0, n), np.full(n, 7.5), np.full(n, 7.5)]


def test_wire_with_a_million_points_is_refused_fast() -> None:
    points = line(10**6)
    with small_and_fast(), pytest.raises(WarpError) as info:
        Wire.from_dict({"base": points, "radius": 3.0})
    assert f"{MAX_WIRE_POINTS}" in one_line(info.value)
    with pytest.raises(WarpError, match="modified has"):
        Wire(line(4), modified=line(MAX_WIRE_POINTS + 1))


def test_wire_at_the_point_limit_is_made() -> None:
    wire = Wire(line(MAX_WIRE_POINTS), radius=3.0)
    assert len(wire.base.control_points) == MAX_WIRE_POINTS


@pytest.mark.parametrize(("radius", "scale"), [(1e9, None), (3.0, 1e5)])
def test_wire_reach_over_the_volume_diagonal_is_refused(radius: float, scale: Any) -> None:
    vol = small_volume()
    wire = Wire(line(6), radius=radius, scale=scale)
    with small_and_fast(), pytest.raises(WarpError) as info:
        WireDeformer(vol, [wire])
    assert "diagonal" in one_line(info.value)


def test_wire_reach_just_under_the_diagonal_builds() -> None:
    vol = small_volume()
    diagonal = float(np.linalg.norm(np.subtract(*vol.bounds[::-1])))
    deformer = WireDeformer(vol, [Wire(line(6), radius=0.95 * diagonal)], field_scale=4)
    stats = deformer.build()
    assert stats.voxels > 0


def test_modified_wire_far_away_is_refused_before_the_field_is_allocated() -> None:
    far = line(6) + np.array([1e8, 0.0, 0.0])
    deformer = WireDeformer(small_volume(), [Wire(line(6), modified=far, radius=3.0)])
    with small_and_fast(), pytest.raises(WarpError) as info:
        deformer.build()
    assert "attribute field" in one_line(info.value)


def test_mask_pixels_over_the_limit_are_refused_before_allocating() -> None:
    deformer = WireDeformer(small_volume(), [Wire(line(6), radius=5.0)], mask_resolution=1e-3)
    with small_and_fast(peak=64 << 20, seconds=5.0), pytest.raises(WarpError) as info:
        deformer.build()
    assert f"{MAX_MASK_PIXELS:,}" in one_line(info.value)


# ---------------------------------------------------------------------------- CLI options
def cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    try:
        code = main(args)
    except SystemExit as exc:  # argparse
        code = int(exc.code or 0)
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return code, err


@pytest.mark.parametrize(
    ("options", "expected"),
    [
        (["--chainmail", "4", "--relax", "100000000"], "at most 1000 relaxation steps"),
        (["--massspring", "4", "--steps", "100001"], "at most 100000 steps"),
        (["--massspring", "4", "--drag", "2,2,2:1e9,0,0"], "at most 60000 mm"),
        (["--memory-budget", "2X"], "--memory-budget must be a size"),
        (["--downsample", "0,1,1"], "expected a positive integer"),
    ],
)
def test_cli_numbers_over_their_limits_exit_2(
    options: list[str], expected: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    t0 = time.perf_counter()
    code, err = cli(["render", "sample:head", *options, "-o", str(tmp_path / "x.png")], capsys)
    assert code == 2
    assert expected in err
    assert time.perf_counter() - t0 < 5
    assert not (tmp_path / "x.png").exists()


def test_cli_numbers_at_their_limits_parse() -> None:
    args = build_parser(bench=False).parse_args(
        [
            "render",
            "in.npy",
            "--chainmail",
            "4",
            "--relax",
            str(limits.MAX_RELAX_STEPS),
            "--drag",
            f"1,1,1:{limits.MAX_DRAG_MM:g},0,0",
            "--downsample",
            "98,1,1",
            "--memory-budget",
            "1.5G",
        ]
    )
    assert args.relax == limits.MAX_RELAX_STEPS
    assert args.drag[0].offset == (limits.MAX_DRAG_MM, 0.0, 0.0)
    assert args.downsample == (98, 1, 1)
    assert args.memory_budget == 1.5 * 2**30
    args = build_parser(bench=False).parse_args(
        ["render", "in.npy", "--massspring", "4", "--steps", str(limits.MAX_MASSSPRING_STEPS)]
    )
    assert args.steps == limits.MAX_MASSSPRING_STEPS


def test_drag_limit_is_the_displacement_texture_range() -> None:
    from voxwarp.deform.node_grid import MAX_DISPLACEMENT_MM

    assert limits.MAX_DRAG_MM == MAX_DISPLACEMENT_MM


def test_zoom_out_of_range_is_a_one_line_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, err = cli(
        ["render", "sample:head", "--zoom", "1e-300", "-o", str(tmp_path / "z.png")], capsys
    )
    assert code == 2
    assert "zoom must lie in [0.001, 1000]" in err
    vol = small_volume()
    for bad in (1e-300, 1e300, math.inf, math.nan, 0.0, -1.0):
        with pytest.raises(SceneError):
            Scene(vol, zoom=bad)
    assert Scene(vol, zoom=limits.MIN_ZOOM).zoom == limits.MIN_ZOOM
    assert Scene(vol, zoom=limits.MAX_ZOOM).zoom == limits.MAX_ZOOM


# ---------------------------------------------------------------------------- memory budget
def write_raw(tmp_path: Path, dims: list[int], size: int | None = None) -> Path:
    raw = tmp_path / "vol.raw"
    with open(raw, "wb") as f:
        f.truncate(math.prod(dims) if size is None else size)  # sparse: no blocks written
    (tmp_path / "vol.raw.json").write_text(json.dumps({"dims": dims, "dtype": "uint8"}))
    return raw


def boom(*args: Any, **kwargs: Any) -> Any:
    raise AssertionError("the voxels were read")


def test_sparse_raw_file_over_the_budget_is_refused_unread(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    raw = write_raw(tmp_path, [4000, 4000, 4000])  # 59.6 GiB claimed, no disk used
    monkeypatch.setattr(np, "fromfile", boom)
    with small_and_fast(), pytest.raises(VolumeError) as info:
        load_volume(raw, memory_budget="1G")
    text = one_line(info.value)
    assert "4000x4000x4000" in text
    assert "59.6 GiB" in text
    assert "--memory-budget" in text


def test_default_budget_is_half_the_physical_memory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(limits, "physical_memory", lambda: 8 << 30)
    assert limits.default_memory_budget() == 4 << 30
    raw = write_raw(tmp_path, [4000, 4000, 4000])
    monkeypatch.setattr(np, "fromfile", boom)
    with pytest.raises(VolumeError, match="over the memory budget of 4 GiB"):
        load_volume(raw)


def test_budget_is_exact_at_the_limit(tmp_path: Path) -> None:
    raw = write_raw(tmp_path, [8, 8, 8])
    assert load_volume(raw, memory_budget=512).shape == (8, 8, 8)
    with pytest.raises(VolumeError, match="memory budget of 511 bytes"):
        load_volume(raw, memory_budget=511)
    assert load_volume(raw, memory_budget="unlimited").shape == (8, 8, 8)


def test_cli_memory_budget_refuses_a_sparse_raw(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    raw = write_raw(tmp_path, [4000, 4000, 4000])
    monkeypatch.setattr(np, "fromfile", boom)
    code, err = cli(["info", str(raw), "--memory-budget", "2G"], capsys)
    assert code == 2
    assert "over the memory budget of 2 GiB" in err
    assert limits.current_memory_budget() == limits.default_memory_budget()  # reset


def save_each_format(tmp_path: Path) -> dict[str, Path]:
    data = np.arange(4 * 5 * 6, dtype=np.uint16).reshape(4, 5, 6)
    paths = {"npy": tmp_path / "v.npy", "npz": tmp_path / "v.npz", "nrrd": tmp_path / "v.nrrd"}
    np.save(paths["npy"], data)
    np.savez(paths["npz"], data=data)
    nrrd.write(str(paths["nrrd"]), data, index_order="F")
    paths["nii"] = tmp_path / "v.nii"
    nib.save(nib.Nifti1Image(data, np.eye(4)), str(paths["nii"]))
    folder = tmp_path / "dicom"
    folder.mkdir()
    for k in range(3):
        pixels = np.full((5, 4), k, dtype=np.uint16)
        write_dicom_slice(
            folder / f"s{k}.dcm", pixels, z=float(k), instance=k + 1, series_uid="9.9"
        )
    paths["dicom"] = folder
    multi = tmp_path / "multi.dcm"
    write_dicom_slice(
        multi, np.zeros((3, 5, 4), np.uint16), z=0.0, instance=1, series_uid="8.8", frames=3
    )
    paths["dcm"] = multi
    stack = np.zeros((5, 6, 7), np.uint16)  # (z, y, x)
    paths["tif"] = tmp_path / "stack.tif"
    tifffile.imwrite(paths["tif"], stack)
    paths["tif pages"] = tmp_path / "pages.tif"
    with tifffile.TiffWriter(paths["tif pages"]) as tw:
        for plane in stack:
            tw.write(plane)  # each page its own series
    paths["tif folder"] = tmp_path / "tiffs"
    paths["tif folder"].mkdir()
    for k, plane in enumerate(stack):
        tifffile.imwrite(paths["tif folder"] / f"s{k}.tif", plane)
    return paths


READERS: dict[str, tuple[Any, str]] = {
    "npy": (np, "load"),
    "npz": (np.lib.npyio.NpzFile, "__getitem__"),
    "nrrd": (nrrd, "read"),
    "nii": (nib.arrayproxy.ArrayProxy, "get_unscaled"),
    "tif": (tifffile.TiffPageSeries, "asarray"),
    "tif pages": (tifffile.TiffPage, "asarray"),
}


def test_every_format_checks_the_budget_before_reading(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    paths = save_each_format(tmp_path)
    for fmt, path in paths.items():
        assert load_volume(path).data.size > 0, fmt  # they load under the default budget
        with monkeypatch.context() as m:
            if fmt in READERS:
                m.setattr(*READERS[fmt], boom)
            with pytest.raises(VolumeError, match="over the memory budget of 100 bytes") as info:
                load_volume(path, memory_budget=100)
        one_line(info.value)


# ---------------------------------------------------------------------------- info, dtype, NRRD
EXTREMES: dict[str, Callable[[], np.ndarray]] = {
    "constant 1e30": lambda: np.full((4, 4, 4), 1e30, np.float32),
    "constant 3e38": lambda: np.full((4, 4, 4), 3e38, np.float32),
    "constant -3.4e38": lambda: np.full((4, 4, 4), -3.4e38, np.float32),
    "+-3.4e38": lambda: np.resize(np.array([-3.4e38, 3.4e38], np.float32), (4, 4, 4)),
    "float32 max and min": lambda: np.resize(
        np.array([np.finfo(np.float32).min, 0.0, np.finfo(np.float32).max], np.float32), (4, 4, 4)
    ),
    "constant 1e7 int32": lambda: np.full((4, 4, 4), 10**7, np.int32),
}


@pytest.mark.parametrize("name", sorted(EXTREMES))
def test_info_on_extreme_values(name: str) -> None:
    data = EXTREMES[name]()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the int32 -> float32 note
        vol = load_volume(data)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow RuntimeWarning either
        info = volume_info(vol)
        text = volume_summary(vol)
    counts, edges = info["histogram"]["counts"], info["histogram"]["edges"]
    assert sum(counts) == data.size
    assert all(math.isfinite(e) for e in edges)
    assert edges == sorted(edges)
    assert info["min"] == float(data.min())
    assert info["max"] == float(data.max())
    assert edges[0] <= info["min"]
    assert info["max"] <= edges[-1]
    assert all(math.isfinite(v) for v in info["percentiles"].values())
    assert "histogram (16 bins" in text


def test_histogram_matches_numpy_on_ordinary_data() -> None:
    data = np.random.default_rng(3).normal(100, 30, (20, 20, 20)).astype(np.float32)
    info = volume_info(load_volume(data))
    counts, edges = np.histogram(data, bins=16)
    assert np.allclose(info["histogram"]["edges"], edges, rtol=1e-6)
    assert np.abs(np.subtract(info["histogram"]["counts"], counts)).sum() <= 2  # edge ties


def test_cli_info_on_float32_near_its_maximum(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "big.npy"
    np.save(path, EXTREMES["+-3.4e38"]())
    code = main(["info", str(path)])
    out = capsys.readouterr()
    assert code == 0
    assert "range:       [-3.4e+38, 3.4e+38]" in out.out
    assert "Traceback" not in out.err


def test_int64_conversion_says_when_it_loses_precision() -> None:
    with pytest.warns(UserWarning, match="with LOSS") as rec:
        vol = load_volume(np.full((2, 2, 2), 2**40 + 1, np.int64))
    assert "2**24" in str(rec[0].message)
    assert float(vol.data[0, 0, 0]) != 2**40 + 1  # it really was rounded
    with pytest.warns(UserWarning, match=r"exact: every value is within \+-2\*\*24"):
        vol = load_volume(np.full((2, 2, 2), 2**24, np.int64))
    assert float(vol.data[0, 0, 0]) == 2**24


def test_nrrd_nan_spacing_warns_and_is_assumed(tmp_path: Path) -> None:
    path = tmp_path / "nan.nrrd"
    nrrd.write(str(path), np.zeros((2, 3, 4), np.uint8), {"spacings": [math.nan, 2.0, 2.0]})
    with pytest.warns(UserWarning, match="'spacings'.*1 mm assumed"):
        vol = load_volume(path)
    assert vol.spacing == (1.0, 1.0, 1.0)
    assert vol.spacing_source == "assumed"
    assert "assumed" in volume_summary(vol)


# ---------------------------------------------------------------------------- downsample advice
def test_downsample_advice_for_a_long_thin_volume_works() -> None:
    shape = (200_000, 2, 2)
    factor = _downsample_advice(shape, (2048, 2048, 2048), math.prod(shape), 512 << 20)
    assert factor == (98, 1, 1)
    vol = Volume(np.zeros(shape, np.uint8))
    reduced = vol.downsample(factor)
    assert max(reduced.shape) <= 2048
    assert min(reduced.shape) >= 1
    with pytest.warns(UserWarning, match=r"downsampled by \(98, 1, 1\)"):
        loaded = load_volume(np.zeros(shape, np.uint8), downsample=factor)
    assert loaded.shape == reduced.shape


@pytest.mark.parametrize(
    "shape", [(4096, 4096, 4096), (512, 512, 1100), (3000, 40, 5), (2049, 1, 1)]
)
def test_downsample_advice_fits_size_and_budget(shape: tuple[int, int, int]) -> None:
    budget = 256 << 20
    need = math.prod(shape) * 2
    factor = _downsample_advice(shape, (2048, 2048, 2048), need, budget)
    reduced = [n // f for n, f in zip(shape, factor, strict=True)]
    assert max(factor) >= 2
    assert min(reduced) >= 1
    assert max(reduced) <= 2048
    assert math.prod(reduced) * 2 <= budget


def test_errors_are_voxwarp_errors() -> None:
    assert issubclass(WarpError, VoxwarpError)
    assert issubclass(MeshError, VoxwarpError)


@pytest.mark.parametrize("command", ["info", "render", "demo"])
def test_memory_budget_option_is_documented(
    command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit):
        build_parser(bench=False).parse_args([command, "--help"])
    assert "--memory-budget SIZE" in capsys.readouterr().out
