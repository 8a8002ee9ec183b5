"""Export oracle of ``Scene.displacement_field``: a warp chain written as an ITK field.

For each deformation family (mass-spring, ChainMail, wires, lattice, affine, and a chain
of three), the scene's warp chain is exported with :meth:`voxwarp.scene.Scene.displacement_field`
and :func:`voxwarp.io.fields.save_displacement_field` (a different file format per case),
read back by SimpleITK itself (``ReadImage`` / ``ReadTransform``), and the volume is
resampled through that ``DisplacementFieldTransform`` (:func:`voxwarp.io.itk.resample`,
ITK's linear resampling). Oracle: the resampled volume rendered undeformed equals the
original rendered through voxwarp's warps, with the same orthographic camera (average,
or MIP for the wire, and unshaded DVR; correlation >= 0.99, mean abs <= 2/255 on [0, 1]
RGB). Each deformation must also be visible: the undeformed render differs from the
deformed one by at least twice the tolerance, so a null field cannot pass. Pixels
whose rays cross space the chain does not carry (the rigid wire's vacated space) are
left out: voxwarp draws nothing there, and the export fills those nodes from their
carried neighbours (so that ITK's interpolation next to them stays right), which ITK's
resampling then shows as the neighbours' tissue.

Volume: the bundled colin27 MRI downsampled by 2 (45 x 54 x 45 voxels of 4 mm), padded
with air beyond every displacement and rendered on its own grid (a finer reference grid
would change DVR's opacity per step). Both renders are clipped to the unpadded box, so
every warped sample stays inside the volume: the raycaster counts no sample that lands
outside it, where the resampled volume has air, which would change an average.
Sheets (ours | ITK | undeformed | 8 x difference) go to /tmp/voxwarp_export_field/.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from benchmarks.lattice_inverse import bent_grid
from voxwarp.core.camera import Camera
from voxwarp.core.volume import Volume
from voxwarp.deform.elements.chainmail import ChainMail
from voxwarp.deform.elements.grid import ElementGrid
from voxwarp.deform.elements.massspring import MassSpring
from voxwarp.deform.lattice.warp import LatticeWarp
from voxwarp.deform.warp import AffineWarp, Warp, chain_apply_carried
from voxwarp.deform.wires.field import Wire, WireDeformer
from voxwarp.io.fields import save_displacement_field
from voxwarp.io.samples import load_sample
from voxwarp.scene import Scene

sitk = pytest.importorskip("SimpleITK")

SIZE = (160, 160)
#: tolerance of the oracle (mean abs on [0, 1] RGB) and the least correlation
MEAN_ABS = 2.0 / 255.0
MIN_CORR = 0.99
#: the deformation must change the picture by this many tolerances
VISIBLE = 2.0
#: voxels of air around the volume: more than any displacement (mm) / 4 mm
PAD = 9
PNG_DIR = Path("/tmp/voxwarp_export_field")


@pytest.fixture(scope="module")
def volume() -> Volume:
    """colin27 at 4 mm, padded by :data:`PAD` voxels of air on every side."""
    vol = load_sample("colin27").downsample(2)
    data = np.pad(np.asarray(vol.data), PAD)
    origin = np.asarray(vol.origin) - PAD * np.asarray(vol.spacing)
    return Volume(data, vol.spacing, tuple(origin), name="colin27-padded", space=vol.space)


def _inner_box(vol: Volume) -> tuple[np.ndarray, np.ndarray]:
    """The unpadded box: the rays' clip box (every warped sample stays inside the volume)."""
    lo, hi = vol.bounds
    margin = PAD * np.asarray(vol.spacing)
    return lo + margin, hi - margin


def _massspring(vol: Volume) -> list[Warp]:
    ms = MassSpring(ElementGrid(vol, shape=6, anchor="corners"))
    ms.fix([(i, j, 0) for i in range(6) for j in range(6)])
    top = [(i, j, 4) for i in range(1, 5) for j in range(1, 5)]
    ms.move(top, np.tile([28.0, 0.0, 0.0], (len(top), 1)))
    ms.settle(max_steps=2000)
    return [ms.warp()]


def _chainmail(vol: Volume) -> list[Warp]:
    cm = ChainMail(ElementGrid(vol, shape=8, anchor="corners"), relax_steps=20)
    cm.move((4, 4, 6), (30.0, 15.0, 0.0))
    return [cm.warp()]


def _wires(vol: Volume) -> list[Warp]:
    c = vol.center
    lo, hi = _inner_box(vol)
    ys = np.linspace(lo[1] + 10, hi[1] - 10, 4)
    base = [[c[0], y, c[2]] for y in ys]
    bent = [[c[0] + dx, y, c[2]] for y, dx in zip(ys, (0.0, 30.0, 30.0, 0.0), strict=True)]
    wire = Wire(
        base, bent, radius=45.0, beta=(60.0, 2000.0), ends="rigid", sides="rigid"
    )  # the paper's sweep
    wd = WireDeformer(vol, [wire])
    wd.build()
    return [wd.warp()]


def _wires_smooth(vol: Volume) -> list[Warp]:
    """The same bend with the default smooth sides: nothing vacated, the head stretches."""
    (warp,) = _wires(vol)
    wire = Wire.from_dict({**warp.wires[0].to_dict(), "sides": "smooth", "ends": "smooth"})
    wd = WireDeformer(vol, [wire])
    wd.build()
    return [wd.warp()]


def _lattice(vol: Volume) -> list[Warp]:
    lo, hi = vol.bounds
    return [LatticeWarp(bent_grid(3, lo, hi, bend=0.12), (lo, hi))]


def _affine(vol: Volume) -> list[Warp]:
    return [AffineWarp.rotation((0, 0, 1), 25.0, center=vol.center)]


def _chain(vol: Volume) -> list[Warp]:
    c = vol.center
    return [
        AffineWarp.scaling((1.1, 0.95, 1.0), center=c),
        *_lattice(vol),
        AffineWarp.rotation((0, 0, 1), -12.0, center=c),
    ]


#: family: (warp chain, file format, grey-value mode besides unshaded dvr). The rigid
#: wire leaves space empty behind the object it moves; the raycaster counts no sample
#: there while the resampled volume has air, which changes an average but not a maximum
#: (smooth sides leave nothing empty: the average compares).
FAMILIES: dict[str, tuple[Callable[[Volume], list[Warp]], str, str]] = {
    "massspring": (_massspring, ".nii.gz", "average"),
    "chainmail": (_chainmail, ".nrrd", "average"),
    "wires": (_wires, ".mha", "mip"),
    "wires_smooth": (_wires_smooth, ".mha", "average"),
    "lattice": (_lattice, ".h5", "average"),
    "affine": (_affine, ".nii", "average"),
    "chain": (_chain, ".h5", "average"),
}


def _itk_transform(path: Path) -> Any:
    """The saved field as SimpleITK reads it (no voxwarp reader involved)."""
    if path.suffix == ".h5":
        return sitk.DisplacementFieldTransform(sitk.ReadTransform(str(path)))
    image = sitk.ReadImage(str(path))  # a NIfTI field (5-D, intent vector) reads as 3-D
    return sitk.DisplacementFieldTransform(sitk.Cast(image, sitk.sitkVectorFloat64))


def _vacated_pixels(
    warps: list[Warp], field: Any, cam: Camera, clip: tuple[np.ndarray, np.ndarray]
) -> np.ndarray:
    """Pixels whose rays cross space in the ``clip`` box that the chain does not carry
    (a rigid wire's vacated space; dilated by 2 pixels): voxwarp draws nothing there,
    while the export holds the nearest carried vectors (so that ITK's interpolation
    beside it stays right) and ITK's resampling shows the neighbours' tissue."""
    from scipy import ndimage

    idx = np.indices(field.shape).reshape(3, -1).T.astype(float)
    p = idx @ field.affine[:3, :3].T + field.affine[:3, 3]
    _, carried = chain_apply_carried(warps, p)
    gone = ~carried & np.all((p >= clip[0]) & (p <= clip[1]), axis=1)
    px = np.rint(cam.project(p[gone], SIZE)).astype(int)
    ok = np.all((px >= 0) & (px < np.asarray(SIZE)), axis=1)
    mask = np.zeros(SIZE[::-1], dtype=bool)
    mask[px[ok, 1], px[ok, 0]] = True
    return ndimage.binary_dilation(mask, iterations=2)


def _scene(vol: Volume, mode: str, **kw: Any) -> Scene:
    lo, hi = (float(v) for v in vol.value_range)
    return Scene(
        vol,
        mode=mode,
        transfer_function=[(lo, 0, 0, 0, 0), (hi, 1, 1, 1, 0.15)],  # data units: shared
        projection="orthographic",
        view="+z",
        window=(0.5 * (lo + hi), hi - lo),
        jitter=False,
        shading=False,
        **kw,
    )


def _rgb(offscreen: Any, scene: Scene) -> np.ndarray:
    return offscreen(*SIZE).render(scene)[..., :3].astype(np.float64) / 255.0


def _save_png(name: str, images: list[np.ndarray]) -> None:
    from voxwarp.io.images import write_image

    PNG_DIR.mkdir(parents=True, exist_ok=True)
    sheet = np.concatenate(images, axis=1)
    write_image(PNG_DIR / f"{name}.png", np.rint(sheet * 255).astype(np.uint8))


@pytest.mark.parametrize("family", list(FAMILIES))
def test_exported_field_resampled_by_itk_matches_the_warped_render(
    family: str, volume: Volume, offscreen: Any, tmp_path: Path
) -> None:
    from voxwarp.io.itk import resample

    make, suffix, grey = FAMILIES[family]
    warps = make(volume)
    cam = Camera.fit(*_inner_box(volume), "+z", "orthographic")  # the head fills it
    deformed = _scene(volume, "average", warps=warps, camera=cam, clip_box=_inner_box(volume))
    field = deformed.displacement_field()
    assert field.shape == volume.shape
    np.testing.assert_allclose(field.affine, volume.affine)
    path = save_displacement_field(field, tmp_path / f"field{suffix}")
    resampled = resample(volume, _itk_transform(path))
    plain = _scene(volume, "average", camera=cam, clip_box=_inner_box(volume))
    rows, failures = [], []
    seen = ~_vacated_pixels(warps, field, cam, _inner_box(volume))
    assert seen.mean() > 0.75  # most of the picture is compared
    for mode in (grey, "dvr"):
        ours = _rgb(offscreen, deformed.copy(mode=mode))
        itk = _rgb(offscreen, plain.copy(volume=resampled, mode=mode))
        undeformed = _rgb(offscreen, plain.copy(mode=mode))
        rows.append(np.concatenate([ours, itk, undeformed, np.abs(ours - itk) * 8], axis=1))
        corr = float(np.corrcoef(ours[seen].ravel(), itk[seen].ravel())[0, 1])
        diff = float(np.abs(ours - itk)[seen].mean())
        moved = float(np.abs(ours - undeformed)[seen].mean())
        line = f"{family} {mode}: corr {corr:.4f}, mean abs {diff * 255:.2f}/255"
        print(f"{line}, deformation {moved * 255:.1f}/255")
        if corr < MIN_CORR or diff > MEAN_ABS:
            failures.append(line)
        if moved < VISIBLE * MEAN_ABS:
            failures.append(f"{family} {mode}: deformation {moved * 255:.1f}/255 too small")
    _save_png(family, [np.concatenate(rows, axis=0)])  # ours | ITK | undeformed | 8 x diff
    assert not failures, "; ".join(failures)


# ---------------------------------------------------------------------- CLI
@pytest.fixture(scope="module")
def massspring_scene(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Volume]:
    """A scene saved by ``voxwarp render --massspring ... --save-scene`` (subprocess)."""
    from tests.cli.test_cli import ball, render
    from voxwarp.io.volumes import save_volume

    folder = tmp_path_factory.mktemp("export_field_cli")
    vol = Volume(ball(), spacing=(1.0, 1.0, 1.5), name="ball")
    src = save_volume(vol, folder / "ball.npz")
    scene = folder / "scene.json"
    render(
        str(src),
        *("-o", str(folder / "r.png"), "--size", "48x48", "--massspring", "4"),
        *("--anchor", "corners", "--drag", "2,2,3:4,0,0", "--save-scene", str(scene)),
    )
    return scene, vol


def test_cli_export_field_writes_a_field_itk_reads(
    massspring_scene: tuple[Path, Volume], tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    from voxwarp import load_displacement_field
    from voxwarp.cli.main import main

    scene, vol = massspring_scene
    out = tmp_path / "field.nii.gz"
    # the voxels' spacing: the default is coarser for an element grid (test_export_field_fast)
    voxels = ["--spacing", "1", "1", "1.5"]
    assert main(["export-field", str(scene), "-o", str(out), *voxels]) == 0
    captured = capsys.readouterr()
    assert captured.out.strip() == str(out)
    assert "field: 24x20x16 nodes" in captured.err
    assert "max |u|" in captured.err
    field = load_displacement_field(out)
    assert field.shape == vol.shape
    np.testing.assert_allclose(field.affine, vol.affine, atol=1e-5)
    assert 1.0 < field.max_displacement() < 8.0  # the 4 mm drag, spread by the springs
    image = sitk.ReadImage(str(out))
    assert image.GetNumberOfComponentsPerPixel() == 3
    assert image.GetSize() == (24, 20, 16)

    coarse = tmp_path / "coarse.mha"
    assert main(["export-field", str(scene), "-o", str(coarse), "--spacing", "2"]) == 0
    small = load_displacement_field(coarse)
    assert small.shape == (12, 10, 12)
    np.testing.assert_allclose(small.spacing, 2.0)
    boxed = tmp_path / "box.h5"
    args = ["--box", "-6", "-5", "-4", "6", "5", "4", "--spacing", "1", "2", "2"]
    assert main(["export-field", str(scene), "-o", str(boxed), *args]) == 0
    transform = sitk.DisplacementFieldTransform(sitk.ReadTransform(str(boxed)))
    assert transform.GetDisplacementField().GetSize() == (12, 5, 4)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["{scene}", "-o", "{tmp}/f.txt"], "cannot write a displacement field as .txt"),
        (["{tmp}/missing.json", "-o", "{tmp}/f.nrrd"], "does not exist"),
        (["{scene}", "-o", "{tmp}/f.nrrd", "--box", "1", "2", "3", "0", "0", "0"], "x0 < x1"),
        (["{scene}", "-o", "{tmp}/f.nrrd", "--spacing", "1", "2"], "one positive number or"),
        (["{scene}", "-o", "{tmp}/f.nrrd", "--spacing", "1e-4"], "over the memory budget"),
        (["{scene}", "-o", "{tmp}/f.nrrd", "--tolerance", "0"], "--tolerance 0: give a positive"),
    ],
)
def test_cli_export_field_bad_input_is_one_line(
    args: list[str],
    message: str,
    massspring_scene: tuple[Path, Volume],
    tmp_path: Path,
    capsys: pytest.CaptureFixture,
) -> None:
    from voxwarp.cli.main import main

    argv = [a.format(scene=massspring_scene[0], tmp=tmp_path) for a in args]
    assert main(["export-field", *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("voxwarp: error:")
    assert err.count("\n") == 1, err
    assert message in err
    assert not list(tmp_path.glob("f.*"))
