"""``voxwarp render MOVING --displacement FIELD --chainmail N --drag-at P:D --save-scene``
then ``voxwarp export-field SCENE.json`` (or ``export-field`` with the same options): a
registration corrected from the command line.

Oracles: the saved chain puts the correction before the field (it acts in the displayed
space) and maps the dragged element's held position to where the field alone maps its
rest position (what was seen at the element is now seen where it was dragged); SimpleITK's
``DisplacementFieldTransform`` of the exported file (LPS, as ITK reads it) maps the
export grid's nodes near the drag as voxwarp's chain does (at nodes the trilinear field
is the chain itself), and there it differs from the field alone by about the drag.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from voxwarp.cli.deformation import compose_chain
from voxwarp.cli.main import main
from voxwarp.core.volume import Volume
from voxwarp.deform.elements.chainmail import ChainMail
from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.deform.warp import chain_apply
from voxwarp.io.fields import load_displacement_field, save_displacement_field
from voxwarp.io.volumes import save_volume
from voxwarp.scene import Scene

sitk = pytest.importorskip("SimpleITK")

LPS = np.array([-1.0, -1.0, 1.0])


@pytest.fixture(autouse=True)
def _keep_warning_state(monkeypatch: pytest.MonkeyPatch) -> None:
    """main() replaces warnings.formatwarning for good; undo it after each test."""
    monkeypatch.setattr(warnings, "formatwarning", warnings.formatwarning)


def test_compose_chain_puts_the_correction_on_top_of_fields() -> None:
    assert compose_chain(["s"], ["f1", "f2"], ["m", "w"]) == ["m", "w", "f1", "f2", "s"]
    assert compose_chain(["s"], [], ["m"]) == ["s", "m"]  # no fields: as before


def _files(folder: Path) -> tuple[Path, Path, DisplacementFieldWarp]:
    rng = np.random.default_rng(3)
    data = rng.uniform(0, 100, (24, 20, 22)).astype(np.float32)
    vol = Volume(data, spacing=(2.0, 2.0, 2.0), origin=(-23.0, -19.0, -21.0))
    idx = np.indices(vol.shape).transpose(1, 2, 3, 0).astype(np.float64)
    xyz = idx @ vol.affine[:3, :3].T + vol.affine[:3, 3]
    u = np.stack([3.0 * np.sin(xyz[..., 1] / 9.0), 0 * xyz[..., 0], 2.0 + 0 * xyz[..., 0]], -1)
    field = DisplacementFieldWarp(u.astype(np.float32), vol.affine)
    moving = save_volume(vol, folder / "moving.nii.gz")
    return moving, save_displacement_field(field, folder / "reg.nii.gz"), field


@pytest.mark.gl
def test_render_then_export_field_writes_the_corrected_registration(
    gl_ctx: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    moving, reg, field = _files(tmp_path)
    scene_path, out = tmp_path / "corrected.json", tmp_path / "corrected.nii.gz"
    args = ["render", str(moving), "--displacement", str(reg), "--chainmail", "6"]
    args += ["--drag-at", "2,0,0:0,5,0", "--save-scene", str(scene_path)]
    assert main([*args, "-o", str(tmp_path / "r.png"), "--size", "32x32"]) == 0
    kinds = [w["type"] for w in json.loads(scene_path.read_text())["warps"]]
    assert kinds == ["offset_field", "displacement_field"]
    assert main(["export-field", str(scene_path), "-o", str(out), "--spacing", "1"]) == 0
    capsys.readouterr()
    scene = Scene.load(scene_path)
    cm = ChainMail.from_warp(scene.warps[0])
    held = cm.to_dict()["held"][0]
    rest = np.asarray(cm.grid.rest_positions)[tuple(held["index"])].reshape(1, 3)
    dragged = rest + np.asarray(held["offset"])
    np.testing.assert_allclose(chain_apply(scene.warps, dragged), field.apply(rest), atol=0.05)
    image = sitk.ReadImage(str(out), sitk.sitkVectorFloat64)
    m = np.reshape(image.GetDirection(), (3, 3)) * np.asarray(image.GetSpacing())
    origin = np.asarray(image.GetOrigin())
    t = sitk.DisplacementFieldTransform(image)  # takes the image's buffer
    centre = np.round(np.linalg.solve(m, dragged[0] * LPS - origin))
    near = centre + np.indices((3, 3, 3)).reshape(3, -1).T - 1  # nodes around the drag
    nodes = near @ m.T + origin
    itk = np.array([t.TransformPoint(p.tolist()) for p in nodes]) * LPS
    ours = chain_apply(scene.warps, nodes * LPS)
    np.testing.assert_allclose(itk, ours, atol=1e-3)
    assert np.linalg.norm(ours - field.apply(nodes * LPS), axis=1).min() > 2.0
    cm.close()
    # export-field takes the same options on a plain scene: the same file
    plain = Scene(scene.volume).save(tmp_path / "plain.json")
    direct = tmp_path / "direct.nii.gz"
    args = ["export-field", str(plain), "--displacement", str(reg), "--chainmail", "6"]
    assert main([*args, "--drag-at", "2,0,0:0,5,0", "-o", str(direct), "--spacing", "1"]) == 0
    a = load_displacement_field(out)
    b = load_displacement_field(direct)
    np.testing.assert_array_equal(a.displacements, b.displacements)
    np.testing.assert_array_equal(a.affine, b.affine)


@pytest.mark.gl
@pytest.mark.parametrize("model", ["chainmail", "massspring"])
def test_the_gpu_backends_export_the_same_correction(
    gl_ctx: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str], model: str
) -> None:
    moving, reg, _ = _files(tmp_path)
    from voxwarp.io.volumes import load_volume

    plain = Scene(load_volume(moving)).save(tmp_path / "plain.json")
    fields = []
    for backend in ("cpu", "gpu"):
        out = tmp_path / f"{backend}.nii.gz"
        args = ["export-field", str(plain), "--displacement", str(reg), f"--{model}", "6"]
        args += ["--drag-at", "2,0,0:0,5,0", "--backend", backend, "--spacing", "1"]
        assert main([*args, "-o", str(out)]) == 0
        fields.append(load_displacement_field(out).displacements)
    capsys.readouterr()
    assert np.abs(fields[0] - fields[1]).max() < 1e-3  # mm: float32 on both sides
    assert np.abs(fields[0]).max() > 2.0  # the field and the drag are in it
