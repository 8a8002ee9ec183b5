"""``voxwarp demo registration`` (voxwarp.teaching.registration_demo): a SimpleITK
demons registration of colin27 against a known deformation, rendered through its field.

The quick demo runs once, headless; the tests check the files it wrote with independent
readers (SimpleITK reads the field it wrote and resamples the moving image through it),
the alignment before and after, and the recovered field against the known one.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from voxwarp.cli.main import main
from voxwarp.io.images import read_image
from voxwarp.teaching.demos import DemoResult, run_demo
from voxwarp.teaching.registration_demo import HEAD_THRESHOLD, known_field

pytest.importorskip("SimpleITK")


@pytest.fixture(autouse=True)
def _keep_warning_state(monkeypatch: pytest.MonkeyPatch) -> None:
    """main() replaces warnings.formatwarning for good; undo it after each test."""
    monkeypatch.setattr(warnings, "formatwarning", warnings.formatwarning)


@pytest.fixture(scope="module")
def demo(gl_ctx: Any, tmp_path_factory: pytest.TempPathFactory) -> DemoResult:
    out = tmp_path_factory.mktemp("registration")
    return run_demo("registration", out, quick=True, tour=True)


def _fixed() -> Any:
    from voxwarp.io.samples import load_sample

    return load_sample("colin27").downsample(2)  # the quick demo's fixed image


@pytest.mark.slow
def test_the_demo_writes_the_sheet_the_moving_image_and_the_field(demo: DemoResult) -> None:
    out = demo.figure.parent
    assert demo.figure == out / "registration.png"
    img = read_image(demo.figure)
    assert img.shape[1] >= 900
    assert img.shape[0] >= 600
    assert img[..., :3].std() > 30
    for name in (
        "registration_moving.nii.gz",
        "registration_field.nii.gz",
        "registration_field.h5",
    ):
        assert (out / name).stat().st_size > 1000, name
    assert not [p for p in out.iterdir() if p.name.startswith(".")]
    json.dumps(demo.numbers, allow_nan=False)
    assert "--displacement" in demo.numbers["cli"]


def test_the_field_files_agree_and_simpleitk_reads_them_as_itk_fields(demo: DemoResult) -> None:
    """Both written files hold the same field, and SimpleITK itself (no voxwarp reader)
    resampling the moving image through the .nii.gz aligns it with the fixed image."""
    import SimpleITK as sitk

    from voxwarp.io.fields import load_displacement_field, load_transform

    out = demo.figure.parent
    nii = load_displacement_field(out / "registration_field.nii.gz")
    (h5,) = load_transform(out / "registration_field.h5")
    np.testing.assert_allclose(h5.displacements, nii.displacements, atol=1e-4)
    np.testing.assert_allclose(h5.affine, nii.affine, atol=1e-6)

    moving = sitk.Cast(sitk.ReadImage(str(out / "registration_moving.nii.gz")), sitk.sitkFloat32)
    field = sitk.Cast(
        sitk.ReadImage(str(out / "registration_field.nii.gz")), sitk.sitkVectorFloat64
    )
    tx = sitk.DisplacementFieldTransform(field)
    back = sitk.GetArrayFromImage(sitk.Resample(moving, moving, tx, sitk.sitkLinear, 0.0))
    f = _fixed().data.transpose(2, 1, 0).astype(np.float64)
    m = sitk.GetArrayFromImage(moving).astype(np.float64)
    w = np.linalg.norm(known_field(_fixed()).displacements, axis=-1).transpose(2, 1, 0)
    where = (f > HEAD_THRESHOLD) & (w > 1.0)
    before = np.abs(f - m)[where].mean()
    after = np.abs(f - back)[where].mean()
    # measured (quick, 4 mm voxels): 8.9 -> 5.3; the floor is the blur of two linear
    # resamplings at 4 mm (the known field itself gets about 5)
    assert after < 0.75 * before, (before, after)


def test_rendering_through_the_field_aligns_moving_with_fixed(demo: DemoResult) -> None:
    n = demo.numbers
    # measured (quick): renders 3.9 -> 1.9 grey levels (0.49x); full size 5.5 -> 1.3
    assert n["render_mad_before"] > 2.0  # the known deformation shows in the slab
    assert n["render_mad_after"] < 0.6 * n["render_mad_before"], n
    assert n["volume_mad_after"] < 0.75 * n["volume_mad_before"], n


def test_the_recovered_field_matches_the_known_one(demo: DemoResult) -> None:
    from voxwarp.io.fields import load_displacement_field

    u = load_displacement_field(demo.figure.parent / "registration_field.nii.gz")
    w = known_field(_fixed())
    np.testing.assert_allclose(u.affine, w.affine, atol=1e-6)  # the fixed image's grid
    uu, ww = u.displacements.astype(np.float64), w.displacements.astype(np.float64)
    where = np.linalg.norm(ww, axis=-1) > 1.0
    assert where.sum() > 1000
    corr = np.corrcoef(uu[where].ravel(), ww[where].ravel())[0, 1]
    err = np.linalg.norm(uu - ww, axis=-1)[where].mean()
    known = np.linalg.norm(ww, axis=-1)[where].mean()
    # measured (quick): r = 0.95, mean error 1.05 mm of a mean 3.25 mm displacement
    assert corr > 0.9, corr
    assert err < 0.45 * known, (err, known)
    assert corr == pytest.approx(demo.numbers["field_correlation"], abs=1e-6)


def test_the_printed_command_line_renders_the_registered_image(
    demo: DemoResult, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = demo.numbers["cli"].split()[1:]
    out = tmp_path / "registered.png"
    args[args.index("-o") + 1] = str(out)
    assert main([*args, "--size", "96x96"]) == 0
    img = read_image(out)
    assert img.shape[:2] == (96, 96)
    assert img[..., :3].max() > 50  # the head, not an empty frame


def test_the_correction_reduces_the_residual_at_its_site(demo: DemoResult) -> None:
    """The correction step: a ChainMail drag at the largest residual of the demons field,
    exported as one ITK transform that SimpleITK reads and applies."""
    import SimpleITK as sitk

    c = demo.numbers["correction"]
    out = demo.figure.parent
    assert demo.figures[1] == out / "registration_correction.png"
    assert read_image(demo.figures[1])[..., :3].std() > 30
    assert Path(c["file"]) == out / "registration_corrected.h5"
    assert sitk.ReadTransform(str(out / "registration_corrected.h5")) is not None
    assert 0.5 < float(np.linalg.norm(c["drag_mm"])) < 15.0  # the residual, a few mm
    # measured (quick): at the site 1.58 -> 0.85 mm; in the head 0.378 -> 0.346 mm
    assert c["site_field_mm_after"] < 0.75 * c["site_field_mm_before"], c
    assert c["head_field_mm_after"] < c["head_field_mm_before"], c
    assert c["site_image_after"] < c["site_image_before"], c
