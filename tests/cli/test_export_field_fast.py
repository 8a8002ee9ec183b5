"""``voxwarp export-field``: the fast sampling, the default spacing and the size estimate.

Oracles:

* **Same numbers.** :func:`~voxwarp.core.field_check.sample_carried` (whole first-axis
  slabs, :meth:`Warp.apply_carried`) equals the earlier one-k-slice-at-a-time sampler
  (kept below as :func:`_reference_sample`, through ``apply`` and ``carried`` called
  apart) on every family's chain, to float32 rounding, with the same outside nodes.
* **Default spacing.** For an element model it is coarser than the voxels, and the
  exported field, read back by SimpleITK, lands within the field check's tolerance
  (:data:`~voxwarp.core.field_check.TOLERANCE_MM`) of the chain at 99 % of random
  points the chain carries into the volume (and within 1.25 times it at all: the check
  samples two points a cell, so its maximum may sit a little under the true one); a
  wire keeps the voxels, an affine map gets :data:`~voxwarp.core.field_spacing.MIN_NODES`
  nodes per axis.
* **Estimate.** The printed estimate is at least the written ``.nii``'s size and at
  most :data:`~voxwarp.core.field_spacing.HEADER_BYTES` over it; over a small
  ``--memory-budget`` the export is refused with one line naming ``--spacing``.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from benchmarks.lattice_inverse import bent_grid
from voxwarp.core.field_check import sample_carried
from voxwarp.core.field_spacing import HEADER_BYTES, MIN_NODES, default_spacing
from voxwarp.core.volume import Volume
from voxwarp.deform.elements.chainmail import ChainMail
from voxwarp.deform.elements.grid import ElementGrid
from voxwarp.deform.elements.massspring import MassSpring
from voxwarp.deform.lattice.warp import LatticeWarp
from voxwarp.deform.warp import AffineWarp, Warp, chain_apply_carried
from voxwarp.deform.wires.field import Wire, WireDeformer
from voxwarp.scene import Scene

sitk = pytest.importorskip("SimpleITK")


@pytest.fixture(scope="module")
def volume() -> Volume:
    """A 30 x 26 x 22 blob at 1 x 1.2 x 1.5 mm, off the origin."""
    idx = np.indices((30, 26, 22)).astype(float)
    r = np.sqrt(((idx[0] - 15) / 12) ** 2 + ((idx[1] - 13) / 10) ** 2 + ((idx[2] - 11) / 8) ** 2)
    data = (1000 * (r < 1) + 50 * idx[0]).astype(np.int16)
    return Volume(data, (1.0, 1.2, 1.5), (-10.0, 5.0, 3.0), name="blob")


def _massspring(vol: Volume) -> list[Warp]:
    ms = MassSpring(ElementGrid(vol, shape=5, anchor="corners"))
    ms.fix([(i, j, 0) for i in range(5) for j in range(5)])
    ms.move([(2, 2, 3)], np.array([[2.0, -1.0, 1.0]]))
    ms.settle(max_steps=1500)
    return [ms.warp()]


def _chainmail(vol: Volume) -> list[Warp]:
    cm = ChainMail(ElementGrid(vol, shape=6, anchor="corners"), relax_steps=10)
    cm.move((3, 3, 4), (2.0, 1.5, 0.0))
    return [cm.warp()]


def _wire(vol: Volume, sides: str = "rigid") -> list[Warp]:
    c = np.asarray(vol.center)
    ys = np.linspace(c[1] - 12, c[1] + 12, 4)
    base = [[c[0], y, c[2]] for y in ys]
    bent = [[c[0] + dx, y, c[2]] for y, dx in zip(ys, (0.0, 5.0, 5.0, 0.0), strict=True)]
    wd = WireDeformer(vol, [Wire(base, bent, radius=9.0, sides=sides, ends="rigid")])
    wd.build()
    return [wd.warp()]


def _lattice(vol: Volume) -> list[Warp]:
    lo, hi = vol.bounds
    return [LatticeWarp(bent_grid(3, lo, hi, bend=0.1), (lo, hi))]


def _chain(vol: Volume) -> list[Warp]:
    c = vol.center
    rot = AffineWarp.rotation((0, 0, 1), 10.0, center=c)
    return [rot, *_lattice(vol), *_massspring(vol)]


FAMILIES = {
    "massspring": _massspring,
    "chainmail": _chainmail,
    "wire-rigid": _wire,
    "lattice": _lattice,
    "affine+lattice+massspring": _chain,
}


def _reference_sample(
    warps: list[Warp], affine: np.ndarray, shape: tuple[int, int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """The sampler before the speed-up: one k-slice at a time, apply and carried apart."""
    nx, ny, nz = shape
    u = np.zeros((nx, ny, nz, 3), dtype=np.float32)
    outside = np.zeros((nx, ny, nz), dtype=bool)
    ii, jj = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    for k in range(nz):
        idx = np.stack([ii.ravel(), jj.ravel(), np.full(ii.size, k)], axis=1).astype(float)
        p = idx @ affine[:3, :3].T + affine[:3, 3]
        q, ok = p, np.ones(len(p), dtype=bool)
        for w in warps:
            mask = w.carried(q)
            if mask is not None:
                ok &= mask
            q = w.apply(q)
        ok &= np.all(np.abs(q - p) < 1e5, axis=1)
        u[:, :, k] = np.where(ok[:, None], q - p, 0.0).reshape(nx, ny, 3)
        outside[:, :, k] = ~ok.reshape(nx, ny)
    return u, outside


@pytest.mark.parametrize("family", list(FAMILIES))
def test_fast_sampling_gives_the_same_field(family: str, volume: Volume) -> None:
    warps = FAMILIES[family](volume)
    affine, shape = np.asarray(volume.affine, float), tuple(volume.shape)
    u, outside = sample_carried(warps, affine, shape)
    ref_u, ref_out = _reference_sample(warps, affine, shape)
    assert np.array_equal(outside, ref_out)
    assert float(np.abs(ref_u).max()) > 1.0  # the chain moves something
    np.testing.assert_allclose(u, ref_u, rtol=0, atol=1e-4)
    if family == "wire-rigid":
        assert outside.any()  # the rigid sweep vacates some nodes


def test_wire_apply_carried_equals_apply_and_carried(volume: Volume) -> None:
    (warp,) = _wire(volume)
    pts = np.random.default_rng(1).uniform(*volume.bounds, size=(4000, 3))
    q, ok = warp.apply_carried(pts)
    assert np.array_equal(q, warp.apply(pts))
    assert np.array_equal(ok, warp.carried(pts))
    assert not ok.all()


def test_default_spacing_per_family(volume: Volume) -> None:
    voxels = np.asarray(volume.spacing)
    ms = default_spacing(volume, _massspring(volume))
    assert ms.spacing is not None
    assert np.all(ms.spacing >= voxels)
    assert np.any(ms.spacing > voxels)  # coarser than the voxels
    assert default_spacing(volume, _wire(volume)).spacing is None
    assert default_spacing(volume, []).spacing is None
    rot = [AffineWarp.rotation((0, 0, 1), 10.0, center=volume.center)]
    aff = default_spacing(volume, rot).spacing
    extent = np.asarray(volume.shape) * voxels
    np.testing.assert_allclose(aff, np.maximum(extent / (MIN_NODES - 1), voxels))


@pytest.mark.parametrize("family", ["massspring", "chainmail", "lattice"])
def test_default_spacing_field_reproduces_the_chain(
    family: str, volume: Volume, tmp_path: Path
) -> None:
    from voxwarp.io.fields import save_displacement_field

    warps = FAMILIES[family](volume)
    export = Scene(volume, warps=warps).export_field()
    assert np.all(np.asarray(export.field.spacing) >= np.asarray(volume.spacing) - 1e-9)
    assert np.prod(export.field.shape) < np.prod(volume.shape)  # fewer nodes than voxels
    assert export.check.met
    out = tmp_path / "f.nii.gz"
    save_displacement_field(export.field, out)
    tx = sitk.DisplacementFieldTransform(
        sitk.Cast(sitk.ReadImage(str(out)), sitk.sitkVectorFloat64)
    )
    pts = np.random.default_rng(2).uniform(*volume.bounds, size=(3000, 3))
    q, ok = chain_apply_carried(warps, pts)
    inv = np.linalg.inv(np.asarray(volume.affine, float))
    vi = q @ inv[:3, :3].T + inv[:3, 3]
    keep = ok & np.all((vi >= -0.5) & (vi <= np.asarray(volume.shape) - 0.5), axis=1)
    lps = np.array([-1.0, -1.0, 1.0])
    got = np.array([tx.TransformPoint(tuple(p * lps)) for p in pts[keep]]) * lps
    err = np.linalg.norm(got - q[keep], axis=1)
    assert keep.sum() > 1000
    # the check measures two points a cell: its maximum may sit a little under the true one
    tol = export.check.tolerance
    assert np.percentile(err, 99) <= tol, f"{family}: p99 {np.percentile(err, 99):.3f} mm"
    assert err.max() <= 1.25 * tol, f"{family}: {err.max():.3f} mm"


def _scene_file(volume: Volume, warps: list[Warp], folder: Path) -> Path:
    """The scene saved as JSON (the small volume embedded)."""
    return Scene(volume, warps=warps).save(folder / "scene.json")


def test_estimate_matches_the_written_nii(
    volume: Volume, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    from voxwarp.cli.main import main

    scene = _scene_file(volume, _massspring(volume), tmp_path)
    out = tmp_path / "field.nii"
    spacing = ["--spacing", "1.5"]  # kept as given: the estimate is the written grid's
    assert main(["export-field", str(scene), "-o", str(out), *spacing]) == 0
    err = capsys.readouterr().err
    m = re.search(r"(\d+)x(\d+)x(\d+) nodes, about ([\d.]+) (\w+) uncompressed", err)
    assert m, err
    unit = {"B": 1, "KiB": 1 << 10, "MiB": 1 << 20, "GiB": 1 << 30}[m.group(5)]
    estimate = float(m.group(4)) * unit
    size = out.stat().st_size
    # the estimate is printed to 3 digits: 0.5 % either way, plus the header allowance
    assert size * 0.995 <= estimate <= (size + HEADER_BYTES) * 1.005, (estimate, size)


def test_export_over_a_small_memory_budget_is_refused(
    volume: Volume, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    from voxwarp.cli.main import main

    scene = _scene_file(volume, _massspring(volume), tmp_path)
    out = tmp_path / "field.nii"
    argv = ["export-field", str(scene), "-o", str(out), "--memory-budget", "20K"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("voxwarp: error:")
    assert err.count("\n") == 1, err
    assert "over the memory budget" in err
    assert "--spacing" in err
    assert not out.exists()
