"""Displacement field files (voxwarp.io.fields) and the import oracle.

Oracles: SimpleITK reads what voxwarp writes (and the reverse) with identical
TransformPoint results; a NIfTI written by nibabel in each intent; ANTs-style composite
transforms in ITK's order; and renders: the original volume rendered through an
imported field against the volume SimpleITK resampled through the same field.
"""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy import ndimage

from tests.cli.test_cli import run_cli
from voxwarp.core.camera import Camera, view_rotation
from voxwarp.core.volume import Volume
from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.deform.warp import AffineWarp, chain_apply, rotation_matrix
from voxwarp.errors import FieldError
from voxwarp.io.fields import (
    load_displacement_field,
    load_transform,
    save_displacement_field,
)
from voxwarp.io.samples import load_sample
from voxwarp.scene import Scene

sitk = pytest.importorskip("SimpleITK")
nib = pytest.importorskip("nibabel")

LPS = np.array([-1.0, -1.0, 1.0])
SAVE_IMAGES = False  # set True to look at the oracle renders under tests/_failures


def smooth(shape: tuple[int, int, int], amplitude: float, seed: int) -> np.ndarray:
    """Random smooth vectors (RAS mm), tapered to 0 at the grid's faces."""
    rng = np.random.default_rng(seed)
    u = np.stack(
        [ndimage.gaussian_filter(rng.normal(size=shape), 2.0, mode="nearest") for _ in range(3)],
        axis=-1,
    )
    w = [np.sin(np.pi * np.linspace(0, 1, n)) ** 0.5 for n in shape]
    u *= (w[0][:, None, None] * w[1][None, :, None] * w[2][None, None, :])[..., None]
    return (u / np.abs(u).max() * amplitude).astype(np.float32)


def field_over(vol: Volume, nodes: tuple[int, int, int], degrees: float, amp: float) -> Any:
    """A field on a grid of ``nodes`` covering ``vol`` (rotated by ``degrees``)."""
    r = rotation_matrix((0.3, 0.2, 1.0), degrees)
    n = np.asarray(nodes, float)
    spacing = 1.15 * np.linalg.norm(vol.size_mm) / n.max()
    a = np.eye(4)
    a[:3, :3] = r * spacing
    a[:3, 3] = vol.center - r @ ((n - 1) / 2 * spacing)
    return DisplacementFieldWarp(smooth(nodes, amp, 0), a)


@pytest.fixture(scope="module")
def field() -> DisplacementFieldWarp:
    return field_over(load_sample("colin27"), (12, 14, 12), 20.0, 8.0)


def sitk_points(t: Any, p_ras: np.ndarray) -> np.ndarray:
    return np.array([t.TransformPoint(tuple(q)) for q in p_ras * LPS]) * LPS


def probe_points(w: DisplacementFieldWarp, n: int = 500) -> np.ndarray:
    c = np.random.default_rng(3).uniform(-1.0, np.asarray(w.shape), (n, 3))
    return c @ w.affine[:3, :3].T + w.affine[:3, 3]


# ---------------------------------------------------------------------------- files
@pytest.mark.parametrize("suffix", [".nii.gz", ".nii", ".nrrd", ".mha", ".h5", ".npz"])
def test_written_fields_read_back_identically(
    field: DisplacementFieldWarp, tmp_path: Path, suffix: str
) -> None:
    path = save_displacement_field(field, tmp_path / f"field{suffix}")
    back = load_displacement_field(path)
    np.testing.assert_allclose(back.displacements, field.displacements, atol=1e-6)
    np.testing.assert_allclose(back.affine, field.affine, atol=1e-5)
    assert back.path == str(path)
    assert not list(tmp_path.glob(".*vwtmp*"))  # no temporary left behind


@pytest.mark.parametrize("suffix", [".nii.gz", ".nrrd", ".mha"])
def test_sitk_reads_written_field_images_as_the_same_transform(
    field: DisplacementFieldWarp, tmp_path: Path, suffix: str
) -> None:
    path = save_displacement_field(field, tmp_path / f"field{suffix}")
    img = sitk.Cast(sitk.ReadImage(str(path)), sitk.sitkVectorFloat64)
    t = sitk.DisplacementFieldTransform(img)
    p = probe_points(field)
    np.testing.assert_allclose(sitk_points(t, p), field.apply(p), atol=1e-4)


def test_sitk_reads_the_written_h5_transform(field: DisplacementFieldWarp, tmp_path: Path) -> None:
    path = save_displacement_field(field, tmp_path / "field.h5")
    t = sitk.ReadTransform(str(path))
    p = probe_points(field)
    np.testing.assert_allclose(sitk_points(t, p), field.apply(p), atol=1e-4)


@pytest.mark.parametrize(("intent", "flip"), [("vector", LPS), ("displacement vector", np.ones(3))])
def test_nibabel_written_nifti_intents(
    field: DisplacementFieldWarp, tmp_path: Path, intent: str, flip: np.ndarray
) -> None:
    # 'vector' (1007): LPS components as ITK writes; 'displacement vector' (1006): RAS,
    # which ITK converts on reading. Both must mean the same transform to SimpleITK.
    u = (field.displacements * flip.astype(np.float32))[:, :, :, None, :]
    img = nib.Nifti1Image(u, field.affine)
    img.header.set_intent(intent)
    img.header.set_sform(field.affine, code=1)
    path = tmp_path / f"{intent.replace(' ', '_')}.nii.gz"
    nib.save(img, str(path))
    ours = load_displacement_field(path)
    t = sitk.DisplacementFieldTransform(
        sitk.Cast(sitk.ReadImage(str(path)), sitk.sitkVectorFloat64)
    )
    p = probe_points(field)
    np.testing.assert_allclose(ours.apply(p), sitk_points(t, p), atol=1e-4)
    np.testing.assert_allclose(ours.apply(p), field.apply(p), atol=1e-4)


def test_a_4d_nifti_without_intent_needs_a_convention(
    field: DisplacementFieldWarp, tmp_path: Path
) -> None:
    u_vox = np.zeros((*field.shape, 3), np.float32)
    u_vox[..., 0] = 0.5  # half a node along i
    img = nib.Nifti1Image(u_vox, field.affine)
    img.header.set_sform(field.affine, code=1)
    path = tmp_path / "voxelmorph.nii.gz"
    nib.save(img, str(path))
    with pytest.raises(FieldError, match="does not say what its vectors mean"):
        load_displacement_field(path)
    w = load_displacement_field(path, convention="voxel")
    np.testing.assert_allclose(w.displacements[0, 0, 0], 0.5 * field.affine[:3, 0], rtol=1e-5)


def test_ants_style_composite_applies_the_last_added_transform_first(
    field: DisplacementFieldWarp, tmp_path: Path
) -> None:
    from voxwarp.io.fields import field_image

    affine = sitk.AffineTransform(3)
    affine.SetMatrix((1.05, 0.02, 0, -0.03, 0.97, 0, 0, 0.01, 1.0))
    affine.SetTranslation((3.0, -2.0, 1.5))
    composite = sitk.CompositeTransform(3)
    composite.AddTransform(affine)  # ANTs: the affine first, then the warp
    composite.AddTransform(sitk.DisplacementFieldTransform(field_image(field)))
    path = tmp_path / "Composite.h5"
    sitk.WriteTransform(composite, str(path))
    warps = load_transform(path)
    assert [type(w) for w in warps] == [DisplacementFieldWarp, AffineWarp]
    p = probe_points(field)
    np.testing.assert_allclose(chain_apply(warps, p), sitk_points(composite, p), atol=1e-4)
    assert load_displacement_field(path).part == 0


def test_a_bspline_transform_is_sampled_to_a_field(tmp_path: Path) -> None:
    vol = load_sample("colin27")
    ref = sitk.Image([int(n) for n in vol.shape], sitk.sitkFloat32)
    ref.SetSpacing(vol.spacing)
    ref.SetOrigin((np.asarray(vol.origin) * LPS).tolist())
    bs = sitk.BSplineTransformInitializer(ref, [4, 4, 4])
    params = np.random.default_rng(5).normal(0, 3.0, len(bs.GetParameters()))
    bs.SetParameters(params.tolist())
    path = tmp_path / "bspline.tfm"
    sitk.WriteTransform(bs, str(path))
    (w,) = load_transform(path)
    p = vol.corners().mean(axis=0) + np.random.default_rng(6).uniform(-60, 60, (400, 3))
    # trilinear between samples ~4 per control-point spacing: measured max 0.05 mm
    np.testing.assert_allclose(w.apply(p), sitk_points(bs, p), atol=0.2)


def test_scene_json_stores_the_field_by_relative_path(
    field: DisplacementFieldWarp, tmp_path: Path
) -> None:
    path = save_displacement_field(field, tmp_path / "fields" / "f.nrrd")
    scene = Scene(load_sample("colin27"), warps=load_transform(path))
    saved = scene.save(tmp_path / "scene.json")
    text = saved.read_text()
    assert '"path": "fields/f.nrrd"' in text
    back = Scene.load(saved)
    np.testing.assert_array_equal(back.warps[0].displacements, field.displacements)
    path.unlink()
    with pytest.raises(Exception, match=r"f\.nrrd") as info:
        Scene.load(saved)
    assert "\n" not in str(info.value)


# ---------------------------------------------------------------------------- bad files
def nifti(path: Path, data: np.ndarray, affine: Any = None, intent: str = "vector") -> Path:
    img = nib.Nifti1Image(data.astype(np.float32), affine)
    img.header.set_intent(intent)
    if affine is not None:
        img.header.set_sform(affine, code=1)
    else:  # no coded transform at all: the grid has no place in patient space
        img.header.set_sform(None, code=0)
        img.header.set_qform(None, code=0)
    nib.save(img, str(path))
    return path


def bad_files(tmp: Path) -> list[tuple[Path, str]]:
    a = np.diag([2.0, 2.0, 2.0, 1.0])
    cases = [
        (nifti(tmp / "two.nii.gz", np.zeros((4, 4, 4, 1, 2)), a), "needs 3"),
        (nifti(tmp / "nan.nii.gz", np.full((4, 4, 4, 1, 3), np.nan), a), "NaN"),
        (nifti(tmp / "flat.nii.gz", np.zeros((4, 4, 1, 1, 3)), a), "2-D field"),
        (nifti(tmp / "six.nii.gz", np.zeros((4, 4, 4, 2, 3)), a), "has shape"),
        (nifti(tmp / "noaffine.nii.gz", np.zeros((4, 4, 4, 1, 3))), "no sform or qform"),
        (tmp / "missing.nii.gz", "no such"),
        (tmp / "field.vtk", "unknown displacement field format"),
    ]
    (tmp / "field.vtk").write_text("x")
    import nrrd

    nrrd.write(
        str(tmp / "nospace.nrrd"),
        np.zeros((3, 4, 4, 4), np.float32),
        {"kinds": ["vector", "domain", "domain", "domain"]},
    )
    cases.append((tmp / "nospace.nrrd", "no patient 'space'"))
    (tmp / "outside.mhd").write_text(
        "ObjectType = Image\nNDims = 3\nDimSize = 2 2 2\nElementNumberOfChannels = 3\n"
        "ElementType = MET_FLOAT\nElementDataFile = ../../etc/passwd\n"
    )
    cases.append((tmp / "outside.mhd", "outside the header.s folder"))
    (tmp / "trunc.nrrd").write_bytes((tmp / "nospace.nrrd").read_bytes()[:60])
    cases.append((tmp / "trunc.nrrd", "cannot read|no patient"))
    return cases


def test_bad_field_files_give_one_line_errors(tmp_path: Path) -> None:
    for path, pattern in bad_files(tmp_path):
        with pytest.raises(FieldError, match=pattern) as info:
            load_transform(path)
        assert "\n" not in str(info.value), path.name


def test_cli_bad_field_is_one_line_on_stderr(tmp_path: Path) -> None:
    path = nifti(tmp_path / "two.nii.gz", np.zeros((4, 4, 4, 1, 2)), np.eye(4))
    run = run_cli(
        "render", "sample:colin27", "--displacement", str(path), "-o", str(tmp_path / "x.png")
    )
    assert run.returncode == 2
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1
    assert "two.nii.gz" in lines[0]
    assert "needs 3" in lines[0]
    assert not (tmp_path / "x.png").exists()


# ---------------------------------------------------------------------------- import oracle
def camera(vol: Volume) -> Camera:
    return Camera(
        center=vol.center,
        rotation=view_rotation("anterior"),
        distance=4 * float(np.linalg.norm(vol.size_mm)),
        projection="orthographic",
        ortho_height=1.1 * float(np.max(vol.size_mm)),
        radius=float(np.linalg.norm(vol.size_mm)),
    )


def oracle_scene(vol: Volume, mode: str, warps: list, clip: Any = None) -> Scene:
    return Scene(
        vol,
        mode=mode,
        transfer_function="mri",
        shading=False,
        projection="orthographic",
        camera=camera(vol),
        jitter=False,
        step=0.5,
        window=(0.0, 255.0),
        warps=warps,
        clip_box=clip,
    )


def resampled(vol: Volume, t: Any) -> Volume:
    from voxwarp.io.itk import resample

    return resample(vol, t)


FIELD_SOURCES = ["array", "nibabel-nifti", "sitk-h5"]


def imported(field: DisplacementFieldWarp, source: str, tmp: Path) -> tuple[Any, Any]:
    """(voxwarp warp, SimpleITK transform) of ``field`` arriving by ``source``."""
    from voxwarp.io.fields import field_image

    if source == "array":
        return field, sitk.DisplacementFieldTransform(field_image(field))
    if source == "nibabel-nifti":
        path = tmp / "f.nii.gz"
        u = (field.displacements * LPS.astype(np.float32))[:, :, :, None, :]
        img = nib.Nifti1Image(u, field.affine)
        img.header.set_intent("vector")
        img.header.set_sform(field.affine, code=1)
        nib.save(img, str(path))
        t = sitk.DisplacementFieldTransform(
            sitk.Cast(sitk.ReadImage(str(path)), sitk.sitkVectorFloat64)
        )
        return load_displacement_field(path), t
    path = tmp / "f.h5"
    sitk.WriteTransform(sitk.DisplacementFieldTransform(field_image(field)), str(path))
    return load_transform(path)[0], sitk.ReadTransform(str(path))


@pytest.mark.parametrize("source", FIELD_SOURCES)
@pytest.mark.parametrize("grid", ["coarse-rotated", "fine-axis-aligned"])
def test_rendering_through_an_imported_field_matches_sitk_resampling(
    offscreen: Any, tmp_path: Path, source: str, grid: str
) -> None:
    vol = load_sample("colin27")
    if grid == "coarse-rotated":
        f = field_over(vol, (10, 12, 10), 25.0, 12.0)
    else:
        f = field_over(vol, (24, 28, 24), 0.0, 10.0)
    warp, t = imported(f, source, tmp_path)
    box = [vol.corners().min(axis=0).tolist(), vol.corners().max(axis=0).tolist()]
    r = offscreen(160, 160, dtype="f4")
    moved = resampled(vol, t)
    for mode in ("dvr", "average"):
        ours = r.render(oracle_scene(vol, mode, [warp], clip=box))[..., :3]
        ref = r.render(oracle_scene(moved, mode, []))[..., :3]
        still = r.render(oracle_scene(vol, mode, []))[..., :3]
        if SAVE_IMAGES:
            from tests.conftest import _write_png

            strip = np.concatenate([still, ours, ref, 4 * np.abs(ours - ref)], axis=1)
            _write_png(
                Path(f"tests/_failures/field_oracle_{source}_{grid}_{mode}.png"),
                np.dstack([strip, np.ones(strip.shape[:2])]),
            )
        corr = np.corrcoef(ours.mean(-1).ravel(), ref.mean(-1).ravel())[0, 1]
        mean_abs = float(np.abs(ours - ref).mean())
        # measured (llvmpipe): corr >= 0.9985, mean abs <= 1.34/255 over these cases;
        # the undeformed render is 2.6-7.4/255 away from the reference
        assert corr >= 0.99, (mode, corr)
        assert mean_abs <= 2 / 255, (mode, mean_abs * 255)
        # the field matters: the undeformed render is far from both
        assert float(np.abs(still - ref).mean()) > 2.5 * mean_abs, mode


@pytest.mark.parametrize("suffix", [".nii.gz", ".nrrd", ".npz", ".h5", ".mha"])
def test_a_field_over_the_memory_budget_is_refused_before_reading(
    field: DisplacementFieldWarp, tmp_path: Path, suffix: str
) -> None:
    from voxwarp.core import limits

    path = save_displacement_field(field, tmp_path / f"field{suffix}")
    with limits.memory_budget(1000), pytest.raises(FieldError, match="memory budget") as info:
        load_transform(path)
    assert "\n" not in str(info.value)
    assert len(load_transform(path)) == 1  # within the default budget it loads


@pytest.mark.parametrize("suffix", [".nii.gz", ".nrrd", ".mha", ".h5", ".npz"])
def test_info_describes_a_field_file(
    field: DisplacementFieldWarp, tmp_path: Path, suffix: str
) -> None:
    import json

    from voxwarp.io.fields import is_field_file

    path = save_displacement_field(field, tmp_path / f"field{suffix}")
    assert is_field_file(path)
    run = run_cli("info", str(path), "--json")
    assert run.returncode == 0, run.stderr
    (info,) = json.loads(run.stdout)
    assert info["shape"] == list(field.shape)
    assert info["max_displacement_mm"] == pytest.approx(field.max_displacement(), rel=1e-5)
    np.testing.assert_allclose(info["affine_ras"], field.affine, atol=1e-5)


def test_volumes_are_not_taken_for_fields(tmp_path: Path) -> None:
    from voxwarp.io.fields import is_field_file
    from voxwarp.io.volumes import save_volume

    vol = load_sample("colin27")
    for suffix in (".nii.gz", ".nrrd", ".npz"):
        assert not is_field_file(save_volume(vol, tmp_path / f"v{suffix}"))


def test_a_damaged_h5_is_one_line_without_the_hdf5_error_stack(
    field: DisplacementFieldWarp, tmp_path: Path
) -> None:
    path = save_displacement_field(field, tmp_path / "field.h5")
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    run = run_cli("info", str(path))
    assert run.returncode == 2
    assert run.stderr.strip().splitlines() == [run.stderr.strip()]  # no HDF5-DIAG stack
    assert "truncated" in run.stderr


def test_an_oblique_volume_through_an_imported_field_matches_sitk_resampling(
    offscreen: Any, tmp_path: Path
) -> None:
    # the volume's own grid rotated 20 degrees (direction), the field's grid rotated
    # another way: world -> texel goes through both. DVR only: average and MIP differ
    # from a resampled copy at the volume's edges by what counts as inside (measured
    # corr 0.978 / 0.985), not by the field
    vol = load_sample("colin27").with_geometry(direction=rotation_matrix((1, 1, 0), 20.0))
    warp, t = imported(field_over(vol, (10, 12, 10), 25.0, 12.0), "sitk-h5", tmp_path)
    c = vol.corners()
    r = offscreen(160, 160, dtype="f4")
    ours = r.render(oracle_scene(vol, "dvr", [warp], clip=[c.min(0).tolist(), c.max(0).tolist()]))
    ref = r.render(oracle_scene(resampled(vol, t), "dvr", []))
    still = r.render(oracle_scene(vol, "dvr", []))
    ours, ref, still = ours[..., :3], ref[..., :3], still[..., :3]
    corr = np.corrcoef(ours.mean(-1).ravel(), ref.mean(-1).ravel())[0, 1]
    mean_abs = float(np.abs(ours - ref).mean())
    assert corr >= 0.99  # measured 0.9963
    assert mean_abs <= 2 / 255  # measured 1.57/255
    assert float(np.abs(still - ref).mean()) > 2.5 * mean_abs  # measured 6.6/255


def test_an_ants_warp_and_affine_pair_composes_in_antsapplytransforms_order(
    field: DisplacementFieldWarp, tmp_path: Path
) -> None:
    # antsApplyTransforms -t 1Warp.nii.gz -t 0GenericAffine.mat adds its -t files to an
    # ITK CompositeTransform last first, so the warp (on the fixed grid) is applied
    # first to a fixed point: q = A(W(p)). voxwarp takes the files in the same order.
    warp_path = tmp_path / "1Warp.nii.gz"
    from voxwarp.io.fields import field_image

    sitk.WriteImage(field_image(field), str(warp_path))  # 5-D NIfTI, intent vector
    affine = sitk.AffineTransform(3)
    affine.SetMatrix((1.05, 0.02, 0, -0.03, 0.97, 0, 0, 0.01, 1.0))
    affine.SetTranslation((3.0, -2.0, 1.5))
    affine.SetCenter((10.0, 20.0, 30.0))
    mat_path = tmp_path / "0GenericAffine.mat"
    sitk.WriteTransform(affine, str(mat_path))
    ants = sitk.CompositeTransform(3)
    ants.AddTransform(sitk.ReadTransform(str(mat_path)))  # the last -t first
    img = sitk.Cast(sitk.ReadImage(str(warp_path)), sitk.sitkVectorFloat64)
    ants.AddTransform(sitk.DisplacementFieldTransform(img))
    chain = load_transform(warp_path) + load_transform(mat_path)
    assert [type(w) for w in chain] == [DisplacementFieldWarp, AffineWarp]
    p = probe_points(field)
    np.testing.assert_allclose(chain_apply(chain, p), sitk_points(ants, p), atol=1e-4)


def test_a_field_that_misses_the_volume_warns_once_on_one_line(
    field: DisplacementFieldWarp, tmp_path: Path
) -> None:
    far = np.array(field.affine)
    far[:3, 3] += 5000.0  # another space
    path = save_displacement_field(
        DisplacementFieldWarp(field.displacements, far), tmp_path / "far.nrrd"
    )
    run = run_cli(
        "render",
        "sample:colin27",
        "--displacement",
        str(path),
        "--size",
        "32x32",
        "-o",
        str(tmp_path / "x.png"),
    )
    assert run.returncode == 0
    warned = [line for line in run.stderr.splitlines() if "misses" in line]
    assert len(warned) == 1
    assert "moves nothing" in warned[0]
    run = run_cli(
        "render",
        "sample:colin27",
        "--displacement",
        str(save_displacement_field(field, tmp_path / "near.nrrd")),
        "--size",
        "32x32",
        "-o",
        str(tmp_path / "y.png"),
    )  # a field over the volume: no such warning
    assert run.returncode == 0
    assert "misses" not in run.stderr


def test_a_field_beyond_the_gpu_texture_limits_is_one_line(gl_ctx: Any) -> None:
    from voxwarp.deform.warp import WarpError

    layers = int(gl_ctx.info.get("GL_MAX_ARRAY_TEXTURE_LAYERS", 2048))
    tall = DisplacementFieldWarp(np.zeros((2, 2, layers + 1, 3), np.float32), np.eye(4))
    with pytest.raises(WarpError, match="texture limits") as info:
        tall.textures(gl_ctx)
    assert "\n" not in str(info.value)


@pytest.mark.slow
def test_info_reads_a_voxelmorph_field_with_a_convention_and_names_bad_components(
    field: DisplacementFieldWarp, tmp_path: Path
) -> None:
    vxm = nifti(tmp_path / "vxm.nii.gz", np.zeros((*field.shape, 3)), field.affine, intent="none")
    two = nifti(tmp_path / "two.nii.gz", np.zeros((*field.shape, 1, 2)), field.affine)

    def info(*args: str) -> subprocess.CompletedProcess:
        return run_cli("info", *args)

    assert "--field-convention" in info(str(vxm)).stderr
    ok = info(str(vxm), "--field-convention", "voxel")
    assert ok.returncode == 0
    assert "displacement field" in ok.stdout
    bad = info(str(two))  # a field with 2 components, not "a 4D NIfTI ... extract one"
    assert bad.returncode == 2
    assert "needs 3" in bad.stderr


def test_the_cli_offers_exactly_the_readers_conventions() -> None:
    from voxwarp.cli.main import build_parser
    from voxwarp.io.fields import CONVENTIONS

    parser = build_parser(bench=False)
    for command in ("render", "info"):
        args = parser.parse_args([command, "x.nii.gz", "--field-convention", CONVENTIONS[-1]])
        assert args.field_convention == CONVENTIONS[-1]
    sub = next(a for a in parser._actions if a.dest == "command" or a.choices)
    for command in ("render", "info"):
        action = next(a for a in sub.choices[command]._actions if a.dest == "field_convention")
        assert tuple(action.choices) == CONVENTIONS
