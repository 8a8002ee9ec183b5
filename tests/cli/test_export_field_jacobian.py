"""``voxwarp export-field --jacobian`` and the det J lines of ``voxwarp info FIELD``.

Oracle: SimpleITK's ``DisplacementFieldJacobianDeterminant`` on the field that
``export-field`` writes for the same scene and grid. ITK's filter differentiates along
the index axes and ignores the image direction (voxwarp's exports have the LPS
direction ``diag(-1, -1, 1)``), so the vectors are first turned into the index frame
(``D^T u``) and the direction set to the identity: then it computes ``det(I + grad u)``.
``--jacobian`` is analytic (the warps' Jacobians), the filter central differences on
the nodes: they agree where the map is smooth over a node's stencil; the lattice's
trilinear cells have kinks at their faces (det J jumps there), so the comparison is
at interior nodes whose six stencil neighbours' analytic det J are within 1 % of the
node's (measured there: relative difference 0.21 % at the 99th percentile, 2.2 % at
most, correlation 0.9996; central differences err as h^2 where smooth).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from benchmarks.lattice_inverse import bent_grid
from voxwarp.cli.main import main
from voxwarp.core.volume import Volume
from voxwarp.deform.elements.grid import ElementGrid
from voxwarp.deform.elements.massspring import MassSpring
from voxwarp.deform.lattice.warp import LatticeWarp
from voxwarp.deform.warp import AffineWarp, Warp
from voxwarp.io.volumes import load_volume, save_volume
from voxwarp.scene import Scene

sitk = pytest.importorskip("SimpleITK")
nib = pytest.importorskip("nibabel")

#: stencil neighbours' det J within this of the node's: the map is smooth there
SMOOTH = 0.01
#: analytic vs central differences at those nodes: 99th percentile and largest relative
#: difference (measured 0.21 % and 2.2 %: a cell face inside a stencil still differs)
REL_P99 = 0.01
REL_MAX = 0.05


def _lattice_chain(vol: Volume) -> list[Warp]:
    lo, hi = vol.bounds
    c = vol.center
    return [
        AffineWarp.scaling((1.1, 0.95, 1.0), center=c),
        LatticeWarp(bent_grid(3, lo, hi, bend=0.3), (lo, hi)),
        AffineWarp.rotation((0, 0, 1), -12.0, center=c),
    ]


def _folded(vol: Volume) -> list[Warp]:
    """A mass-spring whose middle node is pushed past its neighbour (not settled)."""
    ms = MassSpring(ElementGrid(vol, shape=5, anchor="corners"))
    ms.move([(2, 2, 2)], np.array([[30.0, 0.0, 0.0]]))
    return [ms.warp()]


def _scene(folder: Path, warps: object) -> Path:
    vol = Volume(np.zeros((30, 36, 30), np.float32), spacing=(2.0, 2.0, 2.0), name="box")
    vol = load_volume(save_volume(vol, folder / "box.npz"))
    path = folder / "scene.json"
    Scene(vol, warps=warps(vol)).save(path)  # type: ignore[operator]
    return path


def _itk_det(field: Path) -> np.ndarray:
    """SimpleITK's filter on ``field`` turned into its index frame, (nx, ny, nz)."""
    img = sitk.ReadImage(str(field), sitk.sitkVectorFloat64)
    d = np.asarray(img.GetDirection()).reshape(3, 3)
    idx = sitk.GetImageFromArray(sitk.GetArrayFromImage(img) @ d, isVector=True)
    idx.SetSpacing(img.GetSpacing())
    idx.SetOrigin(img.GetOrigin())
    return sitk.GetArrayFromImage(sitk.DisplacementFieldJacobianDeterminant(idx)).T


def _export(scene: Path, out: Path, capsys: pytest.CaptureFixture, *args: str) -> str:
    assert main(["export-field", str(scene), "-o", str(out), "--spacing", "2", *args]) == 0
    return capsys.readouterr().err


def _smooth_interior(det: np.ndarray) -> np.ndarray:
    """Interior nodes whose 6 stencil neighbours' det J are within SMOOTH of theirs."""
    c = det[1:-1, 1:-1, 1:-1]
    ok = np.isfinite(c)
    for ax in range(3):
        for step in (0, 2):
            sl = [slice(1, -1)] * 3
            sl[ax] = slice(step, det.shape[ax] - 2 + step)
            ok &= np.abs(det[tuple(sl)] - c) <= SMOOTH * np.abs(c)
    return ok


def test_jacobian_matches_simpleitk_on_the_exported_field(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    scene = _scene(tmp_path, _lattice_chain)
    _export(scene, tmp_path / "u.nii.gz", capsys)
    err = _export(scene, tmp_path / "detj.nii.gz", capsys, "--jacobian")
    ours_img = sitk.ReadImage(str(tmp_path / "detj.nii.gz"))
    field_img = sitk.ReadImage(str(tmp_path / "u.nii.gz"))
    assert ours_img.GetPixelID() == sitk.sitkFloat32
    assert ours_img.GetSize() == field_img.GetSize()
    np.testing.assert_allclose(ours_img.GetOrigin(), field_img.GetOrigin(), atol=1e-4)
    np.testing.assert_allclose(ours_img.GetSpacing(), field_img.GetSpacing(), atol=1e-5)
    np.testing.assert_allclose(ours_img.GetDirection(), field_img.GetDirection(), atol=1e-6)
    ours = nib.load(tmp_path / "detj.nii.gz").get_fdata()  # NaN kept (ITK's reader: 0)
    assert np.isnan(ours).any()  # the lattice's outside nodes
    theirs = _itk_det(tmp_path / "u.nii.gz")
    ok = _smooth_interior(ours)
    a, b = ours[1:-1, 1:-1, 1:-1][ok], theirs[1:-1, 1:-1, 1:-1][ok]
    assert a.size > 0.3 * ours.size  # most of the grid is compared
    assert np.ptp(a) > 0.1  # det J varies: a wrong frame or sign would show
    rel = np.abs(a - b) / np.abs(b)
    assert np.percentile(rel, 99) <= REL_P99
    assert rel.max() <= REL_MAX
    assert np.corrcoef(a, b)[0, 1] >= 0.99
    lo, hi = (float(v) for v in re.search(r"min (\S+), max (\S+) over", err).groups())
    assert lo == pytest.approx(np.nanmin(ours), rel=1e-3)
    assert hi == pytest.approx(np.nanmax(ours), rel=1e-3)


@pytest.mark.filterwarnings("ignore:--spacing 2:UserWarning")  # a fold: expected
def test_folded_field_counts_folded_voxels(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """A fold is counted in the line (count and volume) and in the written image."""
    scene = _scene(tmp_path, _folded)
    err = _export(scene, tmp_path / "detj.nrrd", capsys, "--jacobian")
    det = sitk.GetArrayFromImage(sitk.ReadImage(str(tmp_path / "detj.nrrd")))
    m = re.search(r"(\d+) folded \(det J <= 0\) \((\S+) mm\^3\)", err)
    assert m is not None, err
    folded = int(m.group(1))
    assert folded > 0
    assert folded == int(np.sum(det <= 0))
    assert float(m.group(2)) == pytest.approx(folded * 8.0)  # 2 mm nodes


@pytest.mark.filterwarnings("ignore:--spacing 2:UserWarning")  # a fold: expected
def test_info_on_a_field_prints_simpleitk_stats(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """``info FIELD``: min/max det J and the folded count equal SimpleITK's filter."""
    scene = _scene(tmp_path, _folded)
    _export(scene, tmp_path / "u.nii.gz", capsys)
    assert main(["info", str(tmp_path / "u.nii.gz")]) == 0
    out = capsys.readouterr().out
    theirs = _itk_det(tmp_path / "u.nii.gz")
    m = re.search(r"min (\S+), max (\S+) over \d+ node\(s\); (\d+) folded", out)
    assert m is not None, out
    assert float(m.group(1)) == pytest.approx(theirs.min(), rel=1e-3, abs=1e-4)
    assert float(m.group(2)) == pytest.approx(theirs.max(), rel=1e-3, abs=1e-4)
    assert int(m.group(3)) == int(np.sum(theirs <= 0)) > 0


def test_jacobian_refuses_a_field_format(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    scene = _scene(tmp_path, _lattice_chain)
    assert main(["export-field", str(scene), "-o", str(tmp_path / "d.h5"), "--jacobian"]) != 0
    err = capsys.readouterr().err.strip()
    assert ".nii.gz" in err
    assert len(err.splitlines()) == 1
    assert not (tmp_path / "d.h5").exists()
