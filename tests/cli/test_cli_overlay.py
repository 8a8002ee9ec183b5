"""``--overlay jacobian`` of ``voxwarp slice`` and ``voxwarp render``.

Oracles: without a warp det J is 1 everywhere, so the slice with the overlay equals
the plain slice pixel for pixel outside the legend's corner; a linear displacement
field ``u(x) = M x`` has det J = det(I + M) everywhere, so every pixel showing the
volume is the plain grey blended with the CPU colour map of that value; a mode the 3D
overlay does not colour and an unknown overlay name fail with one line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.run_cli import run_cli
from voxwarp.io.images import read_image
from voxwarp.render.jacobian_overlay import JacobianOverlay, detj_rgba

M = np.array([[0.25, 0.05, 0.0], [0.0, 0.15, 0.0], [0.05, 0.0, 0.2]])


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    import nibabel as nib

    from voxwarp.deform.fields.displacement import DisplacementFieldWarp
    from voxwarp.io.fields import save_displacement_field

    d = tmp_path_factory.mktemp("overlay_cli")
    rng = np.random.default_rng(2)
    data = rng.integers(30, 220, (24, 22, 20)).astype(np.uint8)
    affine = np.diag([2.0, 2.0, 2.0, 1.0])
    affine[:3, 3] = (-23.0, -21.0, -19.0)
    vol = d / "vol.nii.gz"
    nib.save(nib.Nifti1Image(data, affine), str(vol))
    grid = np.eye(4)
    grid[:3, :3] *= 2.0
    grid[:3, 3] = -40.0
    idx = np.stack(np.meshgrid(*(np.arange(41),) * 3, indexing="ij"), axis=-1)
    x = idx * 2.0 - 40.0
    field = DisplacementFieldWarp((x @ M.T).astype(np.float32), grid)
    path = save_displacement_field(field, d / "field.nii.gz")
    return vol, path


def _slice(vol: Path, out: Path, *args: str) -> np.ndarray:
    proc = run_cli("slice", str(vol), "-o", str(out), "--pixel", "0.25", *args)
    assert proc.returncode == 0, proc.stderr
    return read_image(out)[..., :3].astype(np.float64)


@pytest.mark.slow
def test_identity_overlay_leaves_the_slice_unchanged(files: tuple[Path, Path]) -> None:
    vol, _ = files
    out = vol.parent
    plain = _slice(vol, out / "plain.png")
    over = _slice(vol, out / "over.png", "--overlay", "jacobian")
    h, w = plain.shape[:2]
    legend = np.zeros((h, w), bool)
    legend[h - 40 :, w - 170 :] = True
    np.testing.assert_array_equal(over[~legend], plain[~legend])
    assert np.any(over[legend] != plain[legend])  # the legend is drawn


@pytest.mark.slow
def test_linear_field_tints_every_pixel_by_det_i_plus_m(files: tuple[Path, Path]) -> None:
    vol, field = files
    out = vol.parent
    plain = _slice(vol, out / "fplain.png", "--displacement", str(field))
    over = _slice(
        vol,
        out / "fover.png",
        "--displacement",
        str(field),
        "--overlay",
        "jacobian",
        "--overlay-opacity",
        "0.9",
    )
    c = detj_rgba(np.array(np.linalg.det(np.eye(3) + M)), JacobianOverlay(opacity=0.9))
    expect = plain * (1 - c[3]) + c[:3] * 255 * c[3]
    h = plain.shape[0] // 2  # above the legend
    shown = plain[:h].sum(axis=2) > 0
    assert shown.sum() > 100
    np.testing.assert_allclose(over[:h][shown], expect[:h][shown], atol=1.01)


@pytest.mark.slow
def test_bad_overlay_and_mode_fail_in_one_line(files: tuple[Path, Path]) -> None:
    vol, _ = files
    proc = run_cli("slice", str(vol), "-o", str(vol.parent / "x.png"), "--overlay", "bogus")
    assert proc.returncode == 2
    assert "expected one or more of jacobian" in proc.stderr
    proc = run_cli(
        "render", str(vol), "-o", str(vol.parent / "x.png"), "--overlay", "jacobian",
        "--mode", "average", "--size", "32x32",
    )  # fmt: skip
    assert proc.returncode != 0
    assert "jacobian overlay colours" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
