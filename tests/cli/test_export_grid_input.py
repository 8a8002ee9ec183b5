"""``--grid input``: exports on the input file's own grid (issue 32, item 5).

Oracles: nibabel (the written array and affine against the input file's own
``get_fdata()``/affine), the ``--grid volume`` export indexed back in the file's order
(the same voxel centres, so the same values), and SimpleITK (the written field's
``TransformPoint`` against the ``--grid volume`` field's at random points).

Inputs: an LIA and an oblique LPS NIfTI of a small asymmetric int16 array (every axis a
different length, so a wrong permutation cannot pass).
"""

from __future__ import annotations

import itertools
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.run_cli import run_cli
from voxwarp.cli.export_volume import drawable_grid, export_grid, resampled_slices
from voxwarp.core.orientation import (
    axis_code,
    data_in_file_order,
    grid_in_file_order,
    to_closest_ras,
)
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import AffineWarp
from voxwarp.errors import InputError
from voxwarp.io.fields import save_displacement_field
from voxwarp.io.volume_stream import write_volume_slices
from voxwarp.io.volumes import load_volume
from voxwarp.scene import Scene

nib = pytest.importorskip("nibabel")
sitk = pytest.importorskip("SimpleITK")


def _rotation(rz: float, rx: float) -> np.ndarray:
    rz, rx = np.radians(rz), np.radians(rx)
    cz, sz, cx, sx = np.cos(rz), np.sin(rz), np.cos(rx), np.sin(rx)
    return np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]]) @ np.array(
        [[1, 0, 0], [0, cx, -sx], [0, sx, cx]]
    )


#: file index -> world columns: LIA (i left, j inferior, k anterior), LPS rotated 20/10 deg
FILE_LINEARS = {
    "LIA": np.array([[-1.2, 0, 0], [0, 0, 2.0], [0, -1.5, 0]]),
    "LPS": _rotation(20.0, 10.0) @ np.diag([-1.5, -2.0, 2.5]),
}


def _file(folder: Path, code: str) -> Path:
    """An int16 NIfTI of axis code ``code``: smooth plus noise, 11 x 9 x 7 voxels."""
    rng = np.random.default_rng(7)
    i, j, k = np.indices((11, 9, 7), dtype=float)
    data = (40 * i + 25 * j**1.5 - 30 * k + rng.integers(0, 50, (11, 9, 7))).astype(np.int16)
    affine = np.eye(4)
    affine[:3, :3] = FILE_LINEARS[code]
    affine[:3, 3] = (12.0, -20.0, 9.0)
    img = nib.Nifti1Image(data, affine)
    img.set_sform(affine, code=1)
    img.set_qform(affine, code=1)
    path = folder / f"{code.lower()}.nii.gz"
    nib.save(img, str(path))
    assert axis_code(nib.load(str(path)).affine[:3, :3]) == code
    return path


@pytest.fixture(scope="module", params=sorted(FILE_LINEARS))
def input_file(request: Any, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _file(tmp_path_factory.mktemp("grid_input"), request.param)


@pytest.mark.parametrize("perm", list(itertools.permutations(range(3))))
def test_grid_in_file_order_undoes_closest_ras(perm: tuple[int, int, int]) -> None:
    """Every permutation with every flip: the stored grid re-indexed in the file's order
    is the file's affine, and its voxels the file's array."""
    data = np.arange(4 * 5 * 6).reshape(4, 5, 6)
    for signs in itertools.product((1.0, -1.0), repeat=3):
        affine = np.eye(4)
        for i, w in enumerate(perm):
            affine[w, i] = signs[i] * (1.0 + i)
        affine[:3, 3] = (3.0, -4.0, 5.0)
        stored, stored_affine = to_closest_ras(data, affine)
        code = axis_code(affine[:3, :3])
        back, shape = grid_in_file_order(stored_affine, stored.shape, code)
        np.testing.assert_allclose(back, affine, atol=1e-12)
        assert shape == data.shape
        np.testing.assert_array_equal(data_in_file_order(stored, code), data)


def _export(renderer: Any, scene: Scene, grid: str, path: Path, dtype: Any = np.float32) -> Any:
    affine, shape = export_grid(scene, None, grid)
    slices = resampled_slices(
        renderer, scene, affine, shape, dtype=dtype, outside=0.0, interpolation="linear"
    )
    write_volume_slices(path, affine, shape, dtype, slices, oriented=True)
    return nib.load(str(path))


def _deformed(vol: Any) -> Scene:
    rot = AffineWarp.rotation((0.3, 0.2, 1.0), 12.0, center=vol.center)
    return Scene(vol, warps=[rot])


@pytest.fixture(scope="module")
def renderer(offscreen: Any) -> Any:
    return offscreen(16, 16).renderer


def test_undeformed_input_grid_is_the_input_file(
    renderer: Any, input_file: Path, tmp_path: Path
) -> None:
    original = nib.load(str(input_file))
    vol = load_volume(input_file)
    assert vol.file_axes == axis_code(original.affine[:3, :3]) != "RAS"
    out = _export(renderer, Scene(vol), "input", tmp_path / "same.nii.gz", vol.dtype)
    np.testing.assert_allclose(out.affine, original.affine, atol=1e-5)  # float32 header
    assert out.get_data_dtype() == np.int16
    np.testing.assert_array_equal(out.get_fdata(), original.get_fdata())
    stored = _export(renderer, Scene(vol), "volume", tmp_path / "stored.nii.gz")
    assert stored.shape != original.shape or not np.allclose(stored.affine, original.affine)


def test_deformed_input_grid_is_the_volume_grid_reindexed(
    renderer: Any, input_file: Path, tmp_path: Path
) -> None:
    vol = load_volume(input_file)
    scene = _deformed(vol)
    ours = _export(renderer, scene, "input", tmp_path / "input.nii.gz")
    stored = _export(renderer, scene, "volume", tmp_path / "volume.nii.gz")
    affine, _ = grid_in_file_order(stored.affine, stored.shape, vol.file_axes)
    np.testing.assert_allclose(ours.affine, affine, atol=1e-5)
    np.testing.assert_allclose(ours.affine, nib.load(str(input_file)).affine, atol=1e-5)
    expected = data_in_file_order(stored.get_fdata(), vol.file_axes)
    moved = np.abs(expected - nib.load(str(input_file)).get_fdata()).max()
    assert moved > 100  # the rotation moved the voxels: not a trivial comparison
    np.testing.assert_allclose(ours.get_fdata(), expected, atol=0.05)


def test_field_on_input_grid_transforms_points_as_the_volume_grid(
    input_file: Path, tmp_path: Path
) -> None:
    vol = load_volume(input_file)
    scene = _deformed(vol)
    paths = {}
    for grid in ("input", "volume"):
        export = scene.export_field(spacing=None, grid=grid)
        paths[grid] = save_displacement_field(
            export.field, tmp_path / f"{grid}.nii.gz", export.metadata()
        )
    written = nib.load(str(paths["input"]))
    np.testing.assert_allclose(written.affine, nib.load(str(input_file)).affine, atol=1e-5)
    t_input, t_volume = (
        sitk.DisplacementFieldTransform(
            sitk.Cast(sitk.ReadImage(str(paths[g])), sitk.sitkVectorFloat64)
        )
        for g in ("input", "volume")
    )
    rng = np.random.default_rng(3)
    inside = rng.uniform(0.0, np.asarray(vol.shape) - 1.0, (200, 3))  # between nodes
    moved = []
    for p in vol.index_to_world(inside):
        lps = (-p[0], -p[1], p[2])
        a = np.array(t_input.TransformPoint(lps))
        np.testing.assert_allclose(a, t_volume.TransformPoint(lps), atol=1e-3)
        moved.append(np.linalg.norm(a - lps))
    assert np.median(moved) > 0.5  # the field is not zero: a real comparison


def test_cli_defaults_to_the_input_grid(gl_ctx: Any, input_file: Path, tmp_path: Path) -> None:
    """Both commands, no --grid: the written affine is the input file's."""
    scene_json = _deformed(load_volume(input_file)).save(tmp_path / "scene.json")
    original = nib.load(str(input_file))
    for command in ("export-volume", "export-field"):
        out = tmp_path / f"{command}.nii.gz"
        proc = run_cli(command, str(scene_json), "-o", str(out))
        assert proc.returncode == 0, proc.stderr
        np.testing.assert_allclose(nib.load(str(out)).affine, original.affine, atol=1e-5)
        assert command == "export-field" or "(input grid)" in proc.stderr


def test_jacobian_lies_on_the_field_export_grid(
    gl_ctx: Any, input_file: Path, tmp_path: Path
) -> None:
    """``export-field --jacobian`` writes det J on the grid the field export writes (the
    input file's, by default): same shape and affine, so the two files line up."""
    scene_json = _deformed(load_volume(input_file)).save(tmp_path / "scene.json")
    outs = {}
    for name, extra in (("field", []), ("detj", ["--jacobian"])):
        outs[name] = tmp_path / f"{name}.nii.gz"
        proc = run_cli("export-field", str(scene_json), "-o", str(outs[name]), *extra)
        assert proc.returncode == 0, proc.stderr
    field, detj = (nib.load(str(p)) for p in outs.values())
    np.testing.assert_allclose(detj.affine, field.affine, atol=1e-5)
    np.testing.assert_allclose(detj.affine, nib.load(str(input_file)).affine, atol=1e-5)
    assert detj.shape == field.shape[:3]


def test_input_grid_with_too_long_slices_falls_back_to_volume() -> None:
    """A file whose first axis runs along z (stored last): its own slices are 30 voxels
    wide, the stored grid's 5, so under a 10-voxel cap the export falls back with a
    warning; under a 3-voxel cap neither fits: one line asking for a coarser spacing."""
    vol = Volume(np.zeros((4, 5, 30), np.uint8), space="RAS", file_axes="SRA")
    scene = Scene(vol)
    assert export_grid(scene, None, "input")[1] == (30, 4, 5)
    with pytest.warns(UserWarning, match="--grid volume"):
        affine, shape, grid = drawable_grid(scene, None, "input", 10)
    assert (shape, grid) == ((4, 5, 30), "volume")
    np.testing.assert_allclose(affine, vol.affine)
    with pytest.raises(InputError, match="coarser --spacing"):
        drawable_grid(scene, None, "input", 3)
    plain = Scene(Volume(np.zeros((4, 5, 30), np.uint8)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert drawable_grid(plain, None, "input", 64)[1:] == ((4, 5, 30), "volume")
    assert drawable_grid(scene, None, "input", 64)[1:] == ((30, 4, 5), "input")


def test_nrrd_in_lps_space_round_trips_on_its_own_grid(renderer: Any, tmp_path: Path) -> None:
    """An LPS-space NRRD (as a CT scanner writes it), exported to NRRD on --grid input:
    SimpleITK reads the same array, origin and direction as from the input."""
    import nrrd

    rng = np.random.default_rng(11)
    data = rng.integers(-1000, 1500, (10, 8, 6)).astype(np.int16)
    header = {
        "space": "left-posterior-superior",
        "space directions": np.diag([0.7, 0.9, 2.0]),
        "space origin": np.array([-40.0, 55.0, 110.0]),
        "kinds": ["domain"] * 3,
    }
    src = tmp_path / "ct_lps.nrrd"
    nrrd.write(str(src), data, header)
    vol = load_volume(src)
    assert vol.file_axes == "LPS"
    out = tmp_path / "out.nrrd"
    affine, shape = export_grid(Scene(vol), None, "input")
    slices = resampled_slices(
        renderer, Scene(vol), affine, shape, dtype=vol.dtype, outside=0.0, interpolation="linear"
    )
    write_volume_slices(out, affine, shape, vol.dtype, slices, oriented=True)
    want, got = sitk.ReadImage(str(src)), sitk.ReadImage(str(out))
    np.testing.assert_array_equal(sitk.GetArrayFromImage(got), sitk.GetArrayFromImage(want))
    np.testing.assert_allclose(got.GetOrigin(), want.GetOrigin(), atol=1e-9)
    np.testing.assert_allclose(got.GetDirection(), want.GetDirection(), atol=1e-9)
    np.testing.assert_allclose(got.GetSpacing(), want.GetSpacing(), atol=1e-9)
    np.testing.assert_array_equal(nrrd.read(str(out))[0], data)
