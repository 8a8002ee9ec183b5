"""The same anatomy in every file layout renders the same image in patient space.

A smooth torso phantom is defined in RAS world mm (spleen on the patient's left, liver
on the right, spine posterior, a marker towards the head) and written as RAS, LAS and
LIA NIfTI, LPS NRRD, an axial DICOM series (LPS) and an oblique NIfTI
(tests/orientation_layouts.py). Oracles: the axis-aligned layouts render pixel-equal
(the same voxels at the same world points; within 1e-4, as a uint16 DICOM and an int16
NIfTI normalise differently in the texture: 1/40 of an 8-bit grey level), the oblique
one correlates >= 0.99 with the canonical image, and anatomy lands where the view's
convention puts it. A mirrored image fails each check.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.orientation_layouts import AXIS_LAYOUTS, write_layouts
from voxwarp.core.camera import Camera
from voxwarp.io.volumes import load_volume
from voxwarp.scene import Scene

SHAPE = (44, 36, 40)
SPACING = (3.0, 2.5, 3.5)
CENTRE = np.array([12.0, -25.0, 40.0])  # patient position of the torso's centre (RAS mm)
# organ centres relative to CENTRE (RAS: +x is the patient's right)
SPLEEN = np.array([-32.0, -5.0, 15.0])  # patient's left
LIVER = np.array([30.0, 5.0, 10.0])  # patient's right
SPINE_Y = -28.0  # posterior
HEAD_MARK = np.array([0.0, 0.0, 52.0])  # superior


def _blob(p: np.ndarray, centre: np.ndarray, radius: float) -> np.ndarray:
    d = np.linalg.norm(p - centre, axis=-1)
    return 0.5 * (1 - np.tanh((d - radius) / 2.0))


def torso(world: np.ndarray) -> np.ndarray:
    """Phantom value (0..~300) at RAS points (..., 3)."""
    p = world - CENTRE
    body = 0.5 * (1 - np.tanh((np.linalg.norm(p / (55.0, 38.0, 60.0), axis=-1) - 1) * 20))
    spine = 0.5 * (1 - np.tanh((np.hypot(p[..., 0], p[..., 1] - SPINE_Y) - 6.0) / 2.0))
    return (
        40 * body
        + 160 * _blob(p, SPLEEN, 9.0)
        + 80 * _blob(p, LIVER, 15.0)
        + 260 * spine * (np.abs(p[..., 2]) < 50)
        + 220 * _blob(p, HEAD_MARK, 5.0)
    )


def canonical() -> tuple[np.ndarray, np.ndarray]:
    """The phantom sampled on a RAS grid: (data int16, RAS affine)."""
    n = np.asarray(SHAPE)
    affine = np.diag([*SPACING, 1.0])
    affine[:3, 3] = CENTRE - np.asarray(SPACING) * (n - 1) / 2
    ijk = np.indices(SHAPE).reshape(3, -1).T.astype(float)
    world = ijk @ affine[:3, :3].T + affine[:3, 3]
    return np.rint(torso(world)).reshape(SHAPE).astype(np.int16), affine


@pytest.fixture(scope="module")
def layouts(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    data, affine = canonical()
    return write_layouts(tmp_path_factory.mktemp("layouts"), data, affine, oblique_fill=0.0)


def camera(view: str) -> Camera:
    lo = CENTRE - np.asarray(SPACING) * np.asarray(SHAPE) / 2
    return Camera.fit(lo, 2 * CENTRE - lo, view, projection="orthographic")


def render(offscreen: Any, path: Path, view: str, mode: str = "mip", **kw: Any) -> np.ndarray:
    vol = load_volume(path)
    scene = Scene(
        vol,
        mode=mode,
        transfer_function="grayscale",
        view=view,
        window=(150.0, 300.0),
        jitter=False,
        step=0.5,
        camera=camera(view),
        shading=False,
        **kw,
    )
    return offscreen.render(scene)[..., :3].astype(np.float64)


def correlation(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.corrcoef(a.ravel(), b.ravel())[0, 1])


@pytest.fixture(scope="module")
def offscreen() -> Any:
    from voxwarp.render.offscreen import OffscreenRenderer

    with OffscreenRenderer(96, 96, dtype="f4") as r:
        yield r


@pytest.mark.parametrize("name", [n for n in AXIS_LAYOUTS if n != "ras"])
def test_every_file_layout_reads_to_the_same_patient_geometry(
    layouts: dict[str, Path], name: str
) -> None:
    ref = load_volume(layouts["ras"])
    vol = load_volume(layouts[name])
    assert vol.file_axes == AXIS_LAYOUTS[name]
    assert (vol.space, vol.orientation) == ("RAS", "RAS")
    np.testing.assert_allclose(vol.affine, ref.affine, atol=1e-4)
    np.testing.assert_array_equal(vol.data, ref.data)


@pytest.mark.parametrize("view", ["anterior", "superior", "left"])
@pytest.mark.parametrize("name", [n for n in AXIS_LAYOUTS if n != "ras"])
def test_axis_aligned_layouts_render_pixel_equal(
    offscreen: Any, layouts: dict[str, Path], name: str, view: str
) -> None:
    ref = render(offscreen, layouts["ras"], view)
    img = render(offscreen, layouts[name], view)
    np.testing.assert_allclose(img, ref, atol=1e-4)
    # a mirrored render would fail: the phantom is not left-right symmetric
    assert np.abs(np.flip(ref, axis=1) - ref).max() > 0.2


@pytest.mark.parametrize("view", ["anterior", "superior"])
def test_oblique_nifti_renders_the_same_anatomy(
    offscreen: Any, layouts: dict[str, Path], view: str
) -> None:
    vol = load_volume(layouts["oblique"])
    assert vol.is_oblique
    assert 20.0 <= vol.obliquity <= 30.0  # 20 deg about x and z
    ref = render(offscreen, layouts["ras"], view)
    img = render(offscreen, layouts["oblique"], view)
    assert correlation(img, ref) >= 0.99
    # a mirror image fails: it correlates less and differs several times more
    mirrored = np.flip(img, axis=1)
    assert correlation(mirrored, ref) < 0.98
    assert np.abs(mirrored - ref).mean() > 3 * np.abs(img - ref).mean()


def _column_of_brightest(img: np.ndarray, rows: slice) -> float:
    band = img[rows].mean(axis=2)
    return float(np.unravel_index(np.argmax(band), band.shape)[1])


def test_anterior_view_shows_the_patient_left_on_the_image_right(
    offscreen: Any, layouts: dict[str, Path]
) -> None:
    """Anterior view: looking at the patient's face, their left (spleen) on our right,
    head (marker) at the top. Image row 0 is the top."""
    img = render(offscreen, layouts["las"], "anterior")
    h, w, _ = img.shape
    cam = camera("anterior")
    spleen_px, liver_px, head_px = cam.project(
        np.array([CENTRE + SPLEEN, CENTRE + LIVER, CENTRE + HEAD_MARK]), (w, h)
    )
    assert spleen_px[0] > w / 2 > liver_px[0]
    assert head_px[1] < h / 2
    # and the image agrees: the spleen (brightest organ off the midline) is on the right
    r = int(spleen_px[1])
    assert img[r, int(spleen_px[0])].mean() > img[r, w - 1 - int(spleen_px[0])].mean() + 0.1


def test_inferior_view_is_radiological_and_superior_neurological(offscreen: Any) -> None:
    for view, right_on_left in (("inferior", True), ("superior", False)):
        cam = camera(view)
        offsets = np.array([[50.0, 0, 0], [0, 50.0, 0]])
        px = cam.project(CENTRE + offsets, (96, 96))
        patient_right, anterior = px
        assert (patient_right[0] < 48) == right_on_left
        assert anterior[1] < 48  # anterior up in both axial views


@pytest.mark.parametrize("name", ["las", "lps_nrrd", "dicom", "oblique"])
def test_one_clip_box_cuts_the_same_anatomy(
    offscreen: Any, layouts: dict[str, Path], name: str
) -> None:
    """Keep the patient's left half (x below the centre): the liver goes, the spleen stays."""
    lo = CENTRE - 200
    hi = CENTRE + np.array([0.0, 200, 200])
    clip = (tuple(lo), tuple(hi))
    ref = render(offscreen, layouts["ras"], "anterior", clip_box=clip)
    img = render(offscreen, layouts[name], "anterior", clip_box=clip)
    if name == "oblique":
        assert correlation(img, ref) >= 0.99
    else:
        np.testing.assert_allclose(img, ref, atol=1e-4)
    h, w, _ = img.shape
    liver_px = camera("anterior").project(np.array([CENTRE + LIVER]), (w, h))[0]
    assert img[int(liver_px[1]), : w // 2 - 2].max() == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("name", ["lia", "dicom", "oblique"])
def test_one_wire_file_bends_the_same_anatomy(
    offscreen: Any, layouts: dict[str, Path], name: str
) -> None:
    """A wire through the spine, its end pulled towards the patient's right, in world mm."""
    from voxwarp.deform.wires.field import WireFieldWarp

    z0, z1 = CENTRE[2] - 45, CENTRE[2] + 45
    base = [[CENTRE[0], CENTRE[1] + SPINE_Y, z] for z in np.linspace(z0, z1, 5)]
    bend = 12.0 * np.linspace(0, 1, 5) ** 2  # towards the patient's right
    moved = [[p[0] + b, p[1], p[2]] for p, b in zip(base, bend, strict=True)]
    entry = {"type": "wires", "wires": [{"base": base, "modified": moved, "radius": 14.0}]}
    images = {}
    for key in ("ras", name):
        vol = load_volume(layouts[key])
        warp = WireFieldWarp.from_dict(entry)
        warp.bind_volume(vol)
        scene = Scene(
            vol,
            mode="mip",
            transfer_function="grayscale",
            view="anterior",
            window=(150.0, 300.0),
            jitter=False,
            step=0.5,
            camera=camera("anterior"),
            warps=[warp],
        )
        images[key] = offscreen.render(scene)[..., :3].astype(np.float64)
    still = render(offscreen, layouts["ras"], "anterior")
    assert np.abs(images["ras"] - still).max() > 0.2  # the wire moved something
    if name == "oblique":
        assert correlation(images[name], images["ras"]) >= 0.99
    else:
        np.testing.assert_allclose(images[name], images["ras"], atol=2e-3)


@pytest.mark.parametrize("name", ["lia", "dicom", "oblique"])
def test_one_drag_at_a_world_point_moves_the_same_anatomy(
    layouts: dict[str, Path], name: str, tmp_path: Path
) -> None:
    """``voxwarp render --chainmail --drag-at`` pulls the spleen towards the patient's
    right in every layout (one camera, saved from the RAS render)."""
    from voxwarp.cli.main import main
    from voxwarp.io.images import read_image

    spleen = CENTRE + SPLEEN
    drag = f"{spleen[0]:.3f},{spleen[1]:.3f},{spleen[2]:.3f}:15,0,0"
    common = ["--mode", "mip", "--tf", "grayscale", "--window", "150", "300", "--size", "96x96"]
    common += ["--no-jitter", "--chainmail", "6"]
    camera_file = tmp_path / "camera.json"
    images = {}
    for key in ("ras", name):
        out = tmp_path / f"{key}.png"
        args = ["render", str(layouts[key]), "-o", str(out), *common, "--drag-at", drag]
        if key == "ras":
            args += ["--projection", "orthographic", "--save-camera", str(camera_file)]
        else:
            args += ["--camera", str(camera_file)]
        assert main(args) == 0
        images[key] = read_image(out)[..., :3].astype(np.float64) / 255

    def still(key: str) -> np.ndarray:
        out = tmp_path / f"still_{key}.png"
        args = ["render", str(layouts[key]), "-o", str(out), *common[:-2]]
        assert main([*args, "--camera", str(camera_file)]) == 0
        return read_image(out)[..., :3].astype(np.float64) / 255

    moved = {key: images[key] - still(key) for key in images}
    assert np.abs(moved["ras"]).max() > 0.2  # the drag moved something
    for key, diff in moved.items():
        # the spleen went towards the patient's right: screen left in the anterior view
        gain = np.clip(diff.mean(axis=2), 0, None)
        loss = np.clip(-diff.mean(axis=2), 0, None)
        cols = np.arange(diff.shape[1])
        gain_x = (gain.sum(axis=0) * cols).sum() / gain.sum()
        loss_x = (loss.sum(axis=0) * cols).sum() / loss.sum()
        assert gain_x < loss_x - 2, key
    # the element grid spans the volume's world box, which is larger for an oblique
    # scan: other elements move, so only the direction is the same there
    if name != "oblique":
        assert np.abs(images[name] - images["ras"]).max() <= 1 / 255 + 1e-9
