"""``voxwarp export-field`` between nodes: what ITK interpolates is the chain, within 0.5 mm.

Scenes are saved by ``voxwarp render ... --save-scene`` on the bundled samples (the fish
with its spine wires, rigid and with smooth ends, its lattice bend, mass-spring and
ChainMail drags; colin27 with a mass-spring drag), exported with the defaults, and read
back by SimpleITK alone. Oracle: at random points between the nodes that the chain
carries into the volume (the deformed volume), SimpleITK's
``DisplacementFieldTransform.TransformPoint`` on the written file lands within 0.5 mm
of :func:`~voxwarp.deform.warp.chain_apply`. Points near a tear are left out by a test
of the chain alone: on a grid 4 times finer than the field's over the point's cell, two
neighbouring points that the chain carries differ by more than the tolerance (a jump no
node spacing interpolates). Before the export filled the nodes the chain does not
carry, the rigid wire case missed by up to 133 mm.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from voxwarp.deform.warp import chain_apply
from voxwarp.scene import Scene

sitk = pytest.importorskip("SimpleITK")

SAMPLES = Path(__file__).resolve().parents[2] / "sample_volumes"
TOLERANCE = 0.5
POINTS = 6000
#: probe nodes per cell axis of the tear test
PROBE = 4
_LPS = np.array([-1.0, -1.0, 1.0])
_FISH_DRAG = ("--fix", "0..2,0..7,0..7", "--drag", "6,4,3:0,10,0", "--drag", "6,3,3:0,10,0")

#: name: (volume, render options; a wire file's per-wire changes for a wire case). A
#: smooth-sided wire is one more entry: ("sample:fish", {"sides": "smooth"}).
CASES: dict[str, tuple[str, Any]] = {
    "wires-rigid": ("sample:fish", {}),
    "wires-smooth-ends": ("sample:fish", {"ends": "smooth"}),
    "massspring": ("sample:fish", ("--massspring", "8", *_FISH_DRAG, "--settle")),
    "chainmail": ("sample:fish", ("--chainmail", "8", *_FISH_DRAG)),
    "lattice": ("sample:fish", ("--lattice", str(SAMPLES / "fish_lattice_bend.json"))),
    "colin27-massspring": (
        "sample:colin27",
        ("--massspring", "8", "--drag-at", "0,60,0:0,15,0", "--settle"),
    ),
}


def _scene(name: str, folder: Path) -> Path:
    """``voxwarp render VOLUME OPTIONS --save-scene`` for case ``name``."""
    from tests.cli.test_cli import render

    volume, options = CASES[name]
    if isinstance(options, dict):  # a wire case: the fish's spine wires, changed
        d = json.loads((SAMPLES / "fish_spine_wires.json").read_text())
        for wire in d["wires"]:
            wire.update(options)
        wires = folder / f"{name}.json"
        wires.write_text(json.dumps(d))
        options = ("--wires", str(wires))
    scene = folder / f"{name}-scene.json"
    render(
        volume, *options, "--save-scene", str(scene), "-o", str(folder / "r.png"), "--size", "24x24"
    )
    return scene


def _export(scene: Path, out: Path, capsys: pytest.CaptureFixture, *args: str) -> str:
    from voxwarp.cli.main import main

    assert main(["export-field", str(scene), "-o", str(out), *args]) == 0
    return capsys.readouterr().err


def _itk(path: Path) -> tuple[Any, np.ndarray, np.ndarray]:
    """SimpleITK's transform of the file, its RAS index -> world affine and shape."""
    image = sitk.ReadImage(str(path))
    transform = sitk.DisplacementFieldTransform(sitk.Cast(image, sitk.sitkVectorFloat64))
    spacing = np.asarray(image.GetSpacing())
    a = np.eye(4)
    a[:3, :3] = np.asarray(image.GetDirection()).reshape(3, 3) * spacing
    a[:3, 3] = image.GetOrigin()
    return transform, np.diag([*_LPS, 1.0]) @ a, np.asarray(image.GetSize())


def _carried(scene: Scene, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The chain at ``p`` and where it carries ``p`` (finite, not sent far away)."""
    q = chain_apply(scene.warps, p)
    with np.errstate(invalid="ignore"):
        return q, np.all(np.abs(q - p) < 1e4, axis=1)


def _near_tear(scene: Scene, a: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Per cell (lower corner indices): a jump over :data:`TOLERANCE` between
    neighbouring carried points of a grid :data:`PROBE` times finer over it."""
    s = np.arange(PROBE + 1) / PROBE
    sub = np.stack(np.meshgrid(s, s, s, indexing="ij"), axis=-1).reshape(-1, 3)
    pts = (cells[:, None] + sub[None]).reshape(-1, 3) @ a[:3, :3].T + a[:3, 3]
    q, ok = _carried(scene, pts)
    shape = (len(cells), PROBE + 1, PROBE + 1, PROBE + 1)
    u, ok = (q - pts).reshape(*shape, 3), ok.reshape(shape)
    jump = np.zeros(len(cells), dtype=bool)
    for ax in range(1, 4):
        d = np.linalg.norm(np.diff(u, axis=ax), axis=-1)
        both = np.take(ok, range(PROBE), axis=ax) & np.take(ok, range(1, PROBE + 1), axis=ax)
        jump |= np.any(np.where(both, d, 0.0) > TOLERANCE, axis=(1, 2, 3))
    return jump


def off_node_errors(scene_path: Path, field: Path, n: int = POINTS) -> tuple[np.ndarray, int]:
    """|ITK - chain| (mm) at random off-node points in the deformed volume away from
    tears, and how many random points were drawn."""
    scene = Scene.load(scene_path)
    transform, a, size = _itk(field)
    idx = np.random.default_rng(7).uniform(0, size - 1, (n, 3))
    p = idx @ a[:3, :3].T + a[:3, 3]
    q, ok = _carried(scene, p)
    vi = scene.volume.world_to_index(np.where(ok[:, None], q, 0.0))
    inside = ok & np.all((vi >= -0.5) & (vi <= np.asarray(scene.volume.shape) - 0.5), axis=1)
    keep = inside & ~_near_tear(scene, a, np.floor(idx))
    itk = np.array([transform.TransformPoint(tuple(x * _LPS)) for x in p[keep]]) * _LPS
    return np.linalg.norm(itk - q[keep], axis=1), n


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CASES))
def test_itk_interpolates_the_exported_chain_within_half_a_mm(
    name: str, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    scene = _scene(name, tmp_path)
    field = tmp_path / "field.nii.gz"
    err = _export(scene, field, capsys)
    assert "field check: trilinear within" in err
    errors, drawn = off_node_errors(scene, field)
    print(f"{name}: {errors.size} of {drawn} points, max {errors.max():.3f} mm")
    assert errors.size > drawn // 4  # the deformed volume fills much of the grid
    assert errors.max() <= TOLERANCE, f"{name}: max {errors.max():.3f} mm"


@pytest.mark.slow
def test_vacated_nodes_are_bounded_and_counted(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """The rigid wire's vacated nodes hold values within the carried nodes' range, and
    the command prints how many there are (counted here by the chain itself)."""
    scene_path = _scene("wires-rigid", tmp_path)
    field = tmp_path / "field.npz"
    err = _export(scene_path, field, capsys)
    with np.load(field) as npz:
        u, affine = npz["displacement"].astype(np.float64), npz["affine"]
        assert float(npz["voxwarp_max_error_mm"]) <= TOLERANCE
        recorded = int(npz["voxwarp_outside_nodes"])
    idx = np.indices(u.shape[:3]).reshape(3, -1).T.astype(float)
    p = idx @ affine[:3, :3].T + affine[:3, 3]
    _, ok = _carried(Scene.load(scene_path), p)
    vacated = int((~ok).sum())
    assert vacated > 100  # the sweep leaves space behind
    assert f"; {vacated} outside node(s) not carried" in err
    assert recorded == vacated
    size = np.linalg.norm(u.reshape(-1, 3), axis=1)
    assert size[~ok].max() <= size[ok].max() + 1e-4
    np.testing.assert_allclose(
        u.reshape(-1, 3)[ok], (chain_apply(Scene.load(scene_path).warps, p[ok]) - p[ok]), atol=2e-3
    )


@pytest.mark.slow
def test_a_coarse_spacing_warns_with_the_spacing_that_meets_the_tolerance(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """``--spacing 4`` on the ChainMail drag misses 0.5 mm: one warning line with the
    measured error and a spacing; at that spacing the export meets it, and ITK agrees."""
    import warnings

    scene = _scene("chainmail", tmp_path)
    coarse = tmp_path / "coarse.nrrd"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _export(scene, coarse, capsys, "--spacing", "4")
    lines = [str(w.message) for w in caught if "--spacing" in str(w.message)]
    assert len(lines) == 1, lines
    assert "\n" not in lines[0]
    assert "--spacing 4 x 4 x 4 leaves ITK's trilinear interpolation up to" in lines[0]
    need = lines[0].split("; --spacing ")[1].split(" meets it")[0].split()
    errors, _ = off_node_errors(scene, coarse)
    assert errors.max() > TOLERANCE  # the warning is true
    fine = tmp_path / "fine.mha"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _export(scene, fine, capsys, "--spacing", *need)
    assert not [w for w in caught if "--spacing" in str(w.message)]
    errors, _ = off_node_errors(scene, fine)
    assert errors.max() <= TOLERANCE
    assert float(sitk.ReadImage(str(fine)).GetMetaData("voxwarp_max_error_mm")) <= TOLERANCE
