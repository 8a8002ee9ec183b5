"""A registration corrected by hand (voxwarp.editing.correction): colin27 (4 mm, padded
with air) seen through an imported ITK field, a ChainMail drag or a lattice edit on top.

Oracles:

* order: the drag moves what is seen where it is dragged: the chain at the dragged
  element's held position reads the moving image where the uncorrected chain read it at
  the element's rest position;
* SimpleITK: the composed chain exported as ONE field (written to NIfTI, read back by
  SimpleITK) and applied by ``sitk.Resample`` equals voxwarp's own GPU resampling of the
  corrected scene, within the tolerance of the export tests
  (tests/cli/test_export_volume.py: ``3 * range / 512`` per voxel, a tenth of it on
  average), and the correction changes the picture by far more than that;
* locality: where the correction's warp is the identity, the exported field equals the
  imported one to float tolerance; where it moves, they differ.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.cli.test_export_volume import export_array
from tests.model_scenes import padded_colin
from voxwarp.core.volume import Volume
from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.deform.lattice.trilinear import TrilinearGrid
from voxwarp.deform.lattice.warp import LatticeWarp
from voxwarp.deform.warp import Warp, chain_apply
from voxwarp.editing.correction import (
    CorrectionError,
    corrected_scene,
    correction_chain,
    drag_correction,
)
from voxwarp.io.fields import load_transform, save_displacement_field

sitk = pytest.importorskip("SimpleITK")

PAD = 9  # voxels of air: more than any displacement (mm) / 4 mm
DRAG = np.array([0.0, 8.0, 0.0])


@pytest.fixture(scope="module")
def colin() -> Volume:
    return padded_colin(PAD)


@pytest.fixture(scope="module")
def registration(colin: Volume, tmp_path_factory: pytest.TempPathFactory) -> list[Warp]:
    """A smooth field of a few mm on colin's grid, written and read back as a file."""
    idx = np.indices(colin.shape).transpose(1, 2, 3, 0).astype(np.float64)
    xyz = idx @ colin.affine[:3, :3].T + colin.affine[:3, 3]
    u = np.zeros_like(xyz)
    u[..., 0] = 4.0 * np.sin(xyz[..., 1] / 25.0)
    u[..., 2] = 3.0 * np.cos(xyz[..., 0] / 30.0)
    field = DisplacementFieldWarp(u.astype(np.float32), colin.affine)
    path = save_displacement_field(field, tmp_path_factory.mktemp("reg") / "reg.nii.gz")
    return load_transform(path)


@pytest.fixture(scope="module")
def chainmail(colin: Volume) -> Any:
    return drag_correction(colin, np.asarray(colin.center) + np.array([10.0, 0.0, 0.0]), DRAG)


def _lattice(colin: Volume) -> LatticeWarp:
    lo, hi = colin.bounds
    nodes = TrilinearGrid.from_box(lo, hi, 4).nodes.copy()
    nodes[2, 2, 2] += (6.0, 0.0, -4.0)
    return LatticeWarp(TrilinearGrid(nodes), (lo, hi))


@pytest.mark.slow  # the ChainMail model on colin27: ~20 s on two busy cores
def test_the_drag_moves_what_is_seen_where_it_is_dragged(
    chainmail: Any, registration: list[Warp]
) -> None:
    held = chainmail.to_dict()["held"][0]
    rest = np.asarray(chainmail.grid.rest_positions)[tuple(held["index"])].reshape(1, 3)
    corrected = correction_chain([chainmail.warp()], registration)
    seen_before = chain_apply(registration, rest)
    seen_after = chain_apply(corrected, rest + DRAG)
    # within the baked inverse's error of the offset field (a few % of the drag)
    np.testing.assert_allclose(seen_after, seen_before, atol=0.03 * np.linalg.norm(DRAG))
    # the other order (the model deforming the moving image) would not do that
    wrong = chain_apply([*registration, chainmail.warp()], rest + DRAG)
    assert np.linalg.norm(wrong - seen_before) > 1.0


def _simpleitk_matches(
    offscreen: Any,
    colin: Volume,
    registration: list[Warp],
    correction: list[Warp],
    out: Path,
    spacing: float | None = None,
) -> None:
    from voxwarp.io.itk import resample

    scene = corrected_scene(colin, registration, correction)
    export = scene.export_field(spacing=spacing)
    path = save_displacement_field(export.field, out / "corrected.nii.gz")
    field = sitk.ReadImage(str(path), sitk.sitkVectorFloat64)
    itk = resample(colin, sitk.DisplacementFieldTransform(field)).data
    r = offscreen(16, 16).renderer
    ours = export_array(r, scene, interpolation="linear", outside=0.0).astype(np.float64)
    before = export_array(r, corrected_scene(colin, registration, []), interpolation="linear")
    inner = (slice(1, -1),) * 3
    diff = np.abs(ours - itk)[inner]
    tol = 3 * float(np.ptp(colin.data)) / 512
    change = np.abs(ours - before)[inner]
    print(
        f"max |voxwarp - SimpleITK| {diff.max():.3f}, mean {diff.mean():.4f}, p99"
        f" {np.percentile(diff, 99):.3f} (tolerance {tol:.3f}); the correction changes"
        f" up to {change.max():.1f}"
    )
    assert diff.max() <= tol
    assert diff.mean() <= tol / 10
    assert np.sum(change > 10 * tol) > 100  # a null or misplaced correction fails


@pytest.mark.slow
def test_chainmail_correction_exported_is_what_simpleitk_applies(
    offscreen: Any, colin: Volume, registration: list[Warp], chainmail: Any, tmp_path: Path
) -> None:
    # 2 mm nodes (the refined default goes to 1.6 mm here: a minute on two cores)
    _simpleitk_matches(offscreen, colin, registration, [chainmail.warp()], tmp_path, 2.0)


@pytest.mark.slow
def test_lattice_correction_exported_is_what_simpleitk_applies(
    offscreen: Any, colin: Volume, registration: list[Warp], tmp_path: Path
) -> None:
    # the default export: its spacing refined until ITK's interpolation meets the tolerance
    _simpleitk_matches(offscreen, colin, registration, [_lattice(colin)], tmp_path)


@pytest.mark.slow
def test_the_correction_changes_the_field_only_where_it_moves(
    colin: Volume, registration: list[Warp], chainmail: Any
) -> None:
    scene = corrected_scene(colin, registration, [chainmail.warp()])
    exported = scene.displacement_field()  # on the volume's grid: the imported field's
    imported = registration[0].displacements
    idx = np.indices(colin.shape).reshape(3, -1).T.astype(np.float64)
    x = colin.index_to_world(idx)
    still = np.all(chainmail.warp().apply(x) == x, axis=1).reshape(colin.shape)
    assert 0.5 < still.mean() < 1.0
    du = np.linalg.norm(np.asarray(exported.displacements) - imported, axis=-1)
    assert du[still].max() <= 1e-4
    assert du[~still].max() > 2.0


def test_bad_corrections_are_one_line_errors(colin: Volume) -> None:
    with pytest.raises(CorrectionError, match="model must be one of"):
        drag_correction(colin, colin.center, DRAG, model="spline")
    with pytest.raises(CorrectionError, match="3 finite numbers"):
        drag_correction(colin, (1.0, 2.0), DRAG)
