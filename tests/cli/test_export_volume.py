"""``voxwarp export-volume``: the deformed volume resampled slice by slice and streamed.

Oracles:

* identity: a scene without warps exports the input voxel for voxel (nearest, the
  input's dtype) and within float rounding (linear, float32), on an axis-aligned and
  on an oblique volume;
* SimpleITK: a mass-spring push and a wire bend of colin27 (4 mm, padded with air)
  exported as float32 with linear interpolation and 0 outside equal
  ``sitk.Resample(volume, DisplacementFieldTransform(scene.displacement_field()))``
  (linear, 0 outside), at the voxels the chain carries (the wire's vacated space is 0
  in the export; the field holds its nearest carried vectors there). Both read the
  volume at the same points: the field's nodes are the output voxel centres, where
  ITK's interpolated field is the sampled chain itself.
  What differs is the trilinear filter: GPU texture units (llvmpipe too) weigh the 8
  texels with 8-bit fractions, an error of at most 1/512 of the local texel difference
  per axis, so the tolerance is ``3 * range / 512`` per voxel (range: the volume's
  value range, the largest possible texel difference) and a tenth of it on average.
  The one-voxel border is left out (edge rules differ: ITK's half-voxel padding vs the
  texture's clamp). The deformation must move the values by ten times the mean
  tolerance, so a null export cannot pass;
* ``render_slice`` on an output grid plane (same pixel -> world) equals that slice of
  the export exactly (the same shader draws both);
* the written NIfTI (nibabel) and NRRD (pynrrd) carry the volume's affine, also for an
  oblique volume whose file was stored in LPS order;
* a write failing mid-way (disk full, Ctrl-C) leaves neither the file nor a temporary
  one, with a one-line error.
"""

from __future__ import annotations

import errno
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.model_scenes import massspring_push, padded_colin, wire_bend
from tests.run_cli import run_cli
from voxwarp.cli.export_volume import export_grid, resampled_slices, slice_matrix
from voxwarp.cli.main import main
from voxwarp.core.slice_plane import SlicePlane
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import AffineWarp, Warp, chain_apply_carried
from voxwarp.errors import OutputError
from voxwarp.io.volume_stream import write_volume_slices
from voxwarp.io.volumes import load_volume, save_volume
from voxwarp.scene import Scene

sitk = pytest.importorskip("SimpleITK")

PAD = 9  # voxels of air around colin27 at 4 mm: more than any displacement


@pytest.fixture(autouse=True)
def _keep_warning_state(monkeypatch: pytest.MonkeyPatch) -> None:
    """main() replaces warnings.formatwarning for good; undo it after each test."""
    monkeypatch.setattr(warnings, "formatwarning", warnings.formatwarning)


@pytest.fixture(scope="module")
def colin() -> Volume:
    return padded_colin(PAD)


def _massspring(vol: Volume) -> list[Warp]:
    return massspring_push(vol, 6, 2000)


def _wires(vol: Volume) -> list[Warp]:
    return wire_bend(vol, 30.0, 45.0, PAD)


def export_array(
    renderer: Any, scene: Scene, *, dtype: Any = np.float32, outside: float = 0.0, **kw: Any
) -> np.ndarray:
    """The whole export as an (nx, ny, nz) array (tests only: the CLI streams it)."""
    affine, shape = export_grid(scene, kw.pop("spacing", None), kw.pop("grid", "volume"))
    slices = resampled_slices(renderer, scene, affine, shape, dtype=dtype, outside=outside, **kw)
    return np.stack(list(slices), axis=-1).transpose(1, 0, 2)


@pytest.fixture(scope="module")
def renderer(offscreen: Any) -> Any:
    return offscreen(16, 16)


def test_identity_export_is_the_input(renderer: Any, colin: Volume) -> None:
    scene = Scene(colin)
    same = export_array(renderer.renderer, scene, dtype=colin.dtype, interpolation="nearest")
    assert same.dtype == np.uint8
    np.testing.assert_array_equal(same, colin.data)
    lin = export_array(renderer.renderer, scene, interpolation="linear")
    np.testing.assert_allclose(lin, colin.data, atol=1e-3)


def _oblique_lps_file(folder: Path) -> Path:
    """An int16 NIfTI stored in LPS order, rotated 20 degrees about z and 10 about x."""
    import nibabel as nib

    rng = np.random.default_rng(5)
    data = rng.integers(-1000, 2000, (10, 9, 7)).astype(np.int16)
    rz, rx = np.radians(20), np.radians(10)
    rot_z = np.array([[np.cos(rz), -np.sin(rz), 0], [np.sin(rz), np.cos(rz), 0], [0, 0, 1]])
    rot_x = np.array([[1, 0, 0], [0, np.cos(rx), -np.sin(rx)], [0, np.sin(rx), np.cos(rx)]])
    affine = np.eye(4)
    affine[:3, :3] = rot_z @ rot_x @ np.diag([-1.5, -2.0, 2.5])  # LPS voxel axes
    affine[:3, 3] = (12.0, 20.0, -9.0)
    img = nib.Nifti1Image(data, affine)
    img.set_sform(affine, code=1)
    path = folder / "oblique_lps.nii.gz"
    nib.save(img, str(path))
    return path


@pytest.mark.parametrize("suffix", [".nii.gz", ".nrrd"])
def test_written_affine_and_voxels_oblique(renderer: Any, tmp_path: Path, suffix: str) -> None:
    import nibabel as nib
    import nrrd

    vol = load_volume(_oblique_lps_file(tmp_path))
    assert vol.is_oblique
    scene = Scene(vol)
    affine, shape = export_grid(scene)
    out = tmp_path / f"out{suffix}"
    slices = resampled_slices(
        renderer.renderer, scene, affine, shape, dtype=vol.dtype, outside=0, interpolation="nearest"
    )
    write_volume_slices(out, affine, shape, vol.dtype, slices, oriented=True)
    if suffix == ".nrrd":
        data, header = nrrd.read(str(out))
        assert header["space"] == "right-anterior-superior"
        np.testing.assert_allclose(header["space directions"].T, vol.affine[:3, :3], atol=1e-12)
        np.testing.assert_allclose(header["space origin"], vol.affine[:3, 3], atol=1e-12)
    else:
        img = nib.load(str(out))
        data = np.asarray(img.dataobj)
        np.testing.assert_allclose(img.affine, vol.affine, atol=1e-5)  # float32 header
        assert int(img.header["sform_code"]) == 1
    assert data.dtype == np.int16
    np.testing.assert_array_equal(data, vol.data)
    back = load_volume(out)  # voxwarp reads its own output back to the same geometry
    np.testing.assert_allclose(back.affine, vol.affine, atol=1e-5)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["oblique_lps.nii.gz", out.name])


def _carried_voxels(scene: Scene) -> np.ndarray:
    """Voxels the chain carries: voxwarp exports the outside value elsewhere (a rigid
    wire's vacated space), where the exported field holds its nearest carried vector."""
    vol = scene.volume
    idx = np.indices(vol.shape).reshape(3, -1).T.astype(float)
    _, ok = chain_apply_carried(scene.warps, vol.index_to_world(idx))
    return ok.reshape(vol.shape)


@pytest.mark.parametrize("family", ["massspring", "wires"])
def test_matches_simpleitk_resampling(renderer: Any, colin: Volume, family: str) -> None:
    from voxwarp.io.fields import field_image
    from voxwarp.io.itk import resample

    scene = Scene(colin, warps=(_massspring if family == "massspring" else _wires)(colin))
    ours = export_array(renderer.renderer, scene, interpolation="linear", outside=0.0)
    field = sitk.Cast(field_image(scene.displacement_field()), sitk.sitkVectorFloat64)
    itk = resample(colin, sitk.DisplacementFieldTransform(field)).data
    inner = (slice(1, -1),) * 3
    carried = _carried_voxels(scene)[inner]
    assert carried.mean() > 0.95
    diff = np.abs(ours.astype(np.float64) - itk)[inner][carried]
    moved = np.abs(ours.astype(np.float64) - colin.data)[inner][carried]
    value_range = float(np.ptp(colin.data))
    tol = 3 * value_range / 512
    print(
        f"{family}: max |ours - itk| {diff.max():.3f}, mean {diff.mean():.4f} (tolerance"
        f" {tol:.3f}, mean {tol / 10:.3f}); deformation moves values by {moved.mean():.2f}"
    )
    assert diff.max() <= tol
    assert diff.mean() <= tol / 10
    assert moved.mean() >= 10 * tol / 10


def test_render_slice_equals_the_export_slice(renderer: Any, colin: Volume) -> None:
    scene = Scene(colin, warps=_massspring(colin))
    affine, (nx, ny, nz) = export_grid(scene)
    export = export_array(renderer.renderer, scene, outside=np.nan)
    k = nz // 2
    s = colin.spacing[0]  # isotropic: square pixels
    m = slice_matrix(affine, k)
    centre = m[:3, 3] + m[:3, 0] * (nx - 1) / 2 + m[:3, 1] * (ny - 1) / 2
    plane = SlicePlane(centre, (1.0, 0.0, 0.0), (0.0, -1.0, 0.0), height_mm=ny * s)
    image = renderer.render_slice(scene, plane, size=(nx, ny), interpolation="linear")
    np.testing.assert_allclose(image.pixel_to_world[:, [0, 1, 3]], m[:, [0, 1, 3]], atol=1e-9)
    np.testing.assert_array_equal(image.values, export[:, :, k].T)


def test_deformed_grid_holds_the_shifted_volume(renderer: Any, colin: Volume) -> None:
    """A 10 mm shift along +x: the deformed grid grows by 3 voxels of 4 mm at the high x
    end, and there holds the input shifted by 10 mm (its values, nearest)."""
    scene = Scene(colin, warps=[AffineWarp.translation((10.0, 0.0, 0.0))])
    assert np.allclose(scene.deformed_bounds()[0], colin.bounds[0] + (10, 0, 0))
    affine, shape = export_grid(scene, grid="deformed")
    assert shape == (colin.shape[0] + 3, colin.shape[1], colin.shape[2])
    np.testing.assert_allclose(affine, colin.affine)  # the same lattice, grown
    out = export_array(
        renderer.renderer, scene, grid="deformed", dtype=np.uint8, interpolation="nearest"
    )
    # output x_i = x0 + 4 i reads the input at x_i - 10 mm: 2.5 voxels back, nearest 2 or 3
    src = out[3:-1]
    assert np.mean((src == colin.data[1:]) | (src == colin.data[:-1])) == 1.0
    assert np.all(out[:2] == 0)  # the vacated low end: outside (0, the volume's minimum)


def _slices_then(failure: BaseException, n: int = 6) -> Iterator[np.ndarray]:
    for k in range(n):
        if k == 3:
            raise failure
        yield np.full((4, 5), k, dtype=np.uint8)


@pytest.mark.parametrize("suffix", [".nii.gz", ".nii", ".nrrd"])
def test_write_failing_midway_leaves_nothing(tmp_path: Path, suffix: str) -> None:
    out = tmp_path / f"v{suffix}"
    full = OSError(errno.ENOSPC, "No space left on device")
    with pytest.raises(OutputError, match="disk full") as info:
        write_volume_slices(out, np.eye(4), (5, 4, 6), "uint8", _slices_then(full), oriented=False)
    assert "\n" not in str(info.value)
    with pytest.raises(KeyboardInterrupt):
        write_volume_slices(
            out, np.eye(4), (5, 4, 6), "uint8", _slices_then(KeyboardInterrupt()), oriented=False
        )
    assert list(tmp_path.iterdir()) == []


@pytest.fixture(scope="module")
def scene_json(colin: Volume, tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("export_volume")
    vol = load_volume(save_volume(colin, folder / "colin.nii.gz"))
    return Scene(vol, warps=_massspring(vol)).save(folder / "scene.json")


def test_cli_exports_and_summarises(gl_ctx: Any, scene_json: Path, tmp_path: Path) -> None:
    import nibabel as nib

    out = tmp_path / "deformed.nii.gz"
    proc = run_cli(
        "export-volume", str(scene_json), "-o", str(out), "--spacing", "8", "--dtype", "float32"
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == str(out)
    summary = proc.stderr.strip().splitlines()[-1]
    assert summary.startswith("export-volume: 32x36x32 voxels (input grid), spacing 8 x 8 x 8 mm,")
    assert "float32, 1 warp(s)" in summary
    img = nib.load(str(out))
    assert img.shape == (32, 36, 32)
    assert img.get_data_dtype() == np.float32
    np.testing.assert_allclose(img.affine[:3, :3], np.eye(3) * 8)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["deformed.nii.gz"]


def test_cli_unwritable_output(gl_ctx: Any, scene_json: Path, tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    proc = run_cli("export-volume", str(scene_json), "-o", str(blocker / "v.nii.gz"))
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1, proc.stderr
    assert proc.stderr.startswith("voxwarp: error: cannot write")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


class _NoRendering:
    def __init__(self, *args: Any, **kwargs: Any) -> None:
        raise AssertionError("this test must fail before rendering")


@pytest.mark.parametrize(
    ("what", "text"),
    [
        ("bad-suffix", "cannot write a volume with this ending; use one of .nii.gz, .nii, .nrrd"),
        ("missing", "does not exist; export-volume reads a scene JSON"),
        ("volume", "is not a .json file; export-volume reads a scene JSON"),
    ],
)
def test_cli_refuses_before_any_work(
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture,
    scene_json: Path,
    tmp_path: Path,
    what: str,
    text: str,
) -> None:
    monkeypatch.setattr("voxwarp.render.offscreen.OffscreenRenderer", _NoRendering)
    scene = {
        "bad-suffix": scene_json,
        "missing": tmp_path / "nope.json",
        "volume": scene_json.parent / "colin.nii.gz",
    }[what]
    out = tmp_path / ("v.mha" if what == "bad-suffix" else "v.nii.gz")
    assert main(["export-volume", str(scene), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert text in err
    assert not out.exists()


@pytest.mark.parametrize("command", ["export-volume", "export-field"])
@pytest.mark.parametrize("which", ["volume", "scene", "linked volume"])
def test_cli_refuses_to_overwrite_the_scenes_own_input(
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture,
    scene_json: Path,
    tmp_path: Path,
    command: str,
    which: str,
) -> None:
    """-o naming the scene's volume (or the scene, or a link to the volume) is refused in
    one line before any work, and the file is left as it was."""
    monkeypatch.setattr("voxwarp.render.offscreen.OffscreenRenderer", _NoRendering)
    volume = scene_json.parent / "colin.nii.gz"
    out = {"volume": volume, "scene": scene_json, "linked volume": tmp_path / "link.nii.gz"}[which]
    if which == "linked volume":
        out.symlink_to(volume)
    if which == "scene":  # refused by its ending first: no JSON volumes or fields
        assert main([command, str(scene_json), "-o", str(out)]) == 2
        assert "cannot write" in capsys.readouterr().err
        return
    before = volume.read_bytes(), scene_json.read_bytes()
    assert main([command, str(scene_json), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "is a file" in err
    assert "reads" in err
    assert "write to another file" in err
    assert (volume.read_bytes(), scene_json.read_bytes()) == before
