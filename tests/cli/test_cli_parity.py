"""``voxwarp render`` options that match the Python API (issue 16, CLI parity): --clip and
--slab, --camera / --save-camera, --frame, --drag-at, --axis-order, the spacing notice,
--series and compressed DICOM.

Renders run in a subprocess (see tests/cli/test_cli.py's docstring: an in-process render
would make its own EGL context current); errors found before any GL work run in-process
through ``main``. Images are 64x64 of tiny volumes, orthographic where pixels are checked
against a projected box.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.cli.test_cli import (  # noqa: F401  (fixtures used by name)
    _keep_warning_state,
    assert_render_refused,
    no_rendering,
    run_cli,
)
from voxwarp.cli import render_options as ropt
from voxwarp.cli.main import main
from voxwarp.core.camera import Camera
from voxwarp.core.volume import Volume
from voxwarp.deform.elements.grid import ElementGrid
from voxwarp.deform.warp import AffineWarp
from voxwarp.errors import InputError, SceneError
from voxwarp.io.images import read_image
from voxwarp.io.volumes import load_volume, save_volume
from voxwarp.scene import Scene

SHAPE = (32, 24, 16)
SIZE = "64x64"
#: MIP shown through a window that maps 0 -> black and 100 -> white
MIP = ["--mode", "mip", "--window", "50", "100", "--size", SIZE, "--no-jitter"]
ORTHO_TOP = ["--projection", "orthographic", "--view", "+z"]


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """``solid``: a volume of 100 everywhere (.npy, no spacing: 1 mm assumed, voxel
    centres at 0..31, 0..23, 0..15 mm); ``cube``: an 8-voxel cube of 100 in the middle of
    a 32³ volume of zeros (.nrrd, 1 mm); ``cube_moved``: a scene of it moved 6 mm along +x
    by an affine warp."""
    folder = tmp_path_factory.mktemp("parity")
    np.save(folder / "solid.npy", np.full(SHAPE, 100, np.uint8))
    cube = np.zeros((32, 32, 32), np.uint8)
    cube[12:20, 12:20, 12:20] = 100
    cube_path = save_volume(Volume(cube, spacing=(1, 1, 1), name="cube"), folder / "cube.nrrd")
    vol = load_volume(cube_path)
    moved = Scene(vol, warps=[AffineWarp.translation((6.0, 0.0, 0.0))])
    return {
        "folder": folder,
        "solid": folder / "solid.npy",
        "cube": cube_path,
        "cube_moved": moved.save(folder / "cube_moved.json"),
    }


def render(tmp_path: Path, name: str, *args: str) -> tuple[np.ndarray, str]:
    """Render ``args`` to ``tmp_path/name`` in a subprocess: (image, stderr)."""
    out = tmp_path / name
    proc = run_cli("render", *args, "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    return read_image(out)[..., :3].astype(np.float64), proc.stderr


def projected_rect(camera: Camera, lo: Any, hi: Any, size: int = 64) -> tuple[float, ...]:
    """Pixel rectangle (col0, col1, row0, row1) of the box [lo, hi] seen by an
    orthographic camera looking along -z (rows from the top)."""
    m = camera.view_projection(1.0)
    xs, ys = [], []
    for corner in ((lo[0], lo[1], lo[2]), (hi[0], hi[1], hi[2])):
        c = m @ np.array([*corner, 1.0])
        xs.append((c[0] / c[3] + 1) / 2 * size)
        ys.append((1 - c[1] / c[3]) / 2 * size)
    return min(xs), max(xs), min(ys), max(ys)


def assert_bright_where(img: np.ndarray, rect: tuple[float, ...], margin: float = 1.0) -> None:
    """Pixels whose centre lies ``margin`` px inside ``rect`` are white, those ``margin``
    px outside it black (the rim in between is interpolated)."""
    grey = img.mean(axis=-1)
    rows, cols = np.mgrid[0 : grey.shape[0], 0 : grey.shape[1]] + 0.5
    c0, c1, r0, r1 = rect
    inside = (
        (cols > c0 + margin) & (cols < c1 - margin) & (rows > r0 + margin) & (rows < r1 - margin)
    )
    outside = (
        (cols < c0 - margin) | (cols > c1 + margin) | (rows < r0 - margin) | (rows > r1 + margin)
    )
    assert inside.sum() > 20
    assert outside.sum() > 20
    assert grey[inside].min() > 200, "the clip box's region is not all bright"
    assert grey[outside].max() < 30, "something outside the clip box's region shows"


def centroid(img: np.ndarray) -> np.ndarray:
    grey = img.mean(axis=-1)
    rows, cols = np.mgrid[0 : grey.shape[0], 0 : grey.shape[1]]
    w = grey / grey.sum()
    return np.array([(cols * w).sum(), (rows * w).sum()])


# ---------------------------------------------------------------------- clip and slab
@pytest.mark.slow
def test_clip_cuts_the_projected_box(
    files: dict[str, Path], tmp_path: Path, gl_ctx: object
) -> None:
    cam = tmp_path / "cam.json"
    common = [str(files["solid"]), *MIP, *ORTHO_TOP]
    full, err = render(tmp_path, "full.png", *common, "--save-camera", str(cam))
    assert "assuming 1 x 1 x 1 mm" in err  # an .npy states no spacing
    camera = Camera.from_dict(json.loads(cam.read_text()))
    vlo, vhi = np.array([-0.5, -0.5, -0.5]), np.array([31.5, 23.5, 15.5])
    assert_bright_where(full, projected_rect(camera, vlo, vhi))  # the convention holds

    clipped, err = render(
        tmp_path, "clip.png", *common, "--clip=4,12,-50,50,-50,50", "--spacing", "1", "1", "1"
    )
    assert "assuming" not in err  # --spacing given
    assert_bright_where(clipped, projected_rect(camera, (4, -0.5, -0.5), (12, 23.5, 15.5)))

    # the same region as a slab: 8 mm around x = 8, along x, R, and L (counted along -x)
    for slab in ("x:8:8", "R:8:8", "L:-8:8"):
        img, _ = render(tmp_path, "slab.png", *common, "--slab", slab)
        np.testing.assert_array_equal(img, clipped, err_msg=f"--slab {slab}")

    # --clip and --slab intersect: x 0..20 and 10..18 leave 10..18, and y 5..9 of --clip
    both, _ = render(tmp_path, "both.png", *common, "--clip", "0,20,5,9,-50,50", "--slab", "x:14:8")
    assert_bright_where(both, projected_rect(camera, (10, 5, -0.5), (18, 9, 15.5)))


def test_clip_that_misses_the_volume_is_one_line(
    files: dict[str, Path], tmp_path: Path, gl_ctx: object
) -> None:
    proc = run_cli(
        "render", str(files["solid"]), *MIP, "--clip", "100,120,0,10,0,10", "-o",
        str(tmp_path / "x.png"),
    )  # fmt: skip
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    err = proc.stderr.strip().splitlines()[-1]
    assert err.startswith("voxwarp: error: --clip: the box (x 100..120")
    assert "misses the volume" in err
    assert "x -0.5..31.5, y -0.5..23.5, z -0.5..15.5" in err
    assert not (tmp_path / "x.png").exists()


def _scene() -> Scene:
    return Scene(Volume(np.zeros(SHAPE, np.uint8)))


def _ns(**kw: Any) -> argparse.Namespace:
    return argparse.Namespace(**{"clip": None, "slab": None, **kw})


def test_clip_box_for_slabs_and_errors() -> None:
    scene = _scene()  # box -0.5..31.5, -0.5..23.5, -0.5..15.5
    slab = ropt.slab_arg
    box = ropt.clip_box_for(scene, _ns(slab=[slab("z:4:2"), slab("A:10:4")]))
    assert box == ((-0.5, 8.0, 3.0), (31.5, 12.0, 5.0))
    # a scene's own clip box meets --slab; --clip replaces it
    boxed = scene.copy(clip_box=((0, 0, 0), (10, 10, 10)))
    assert ropt.clip_box_for(boxed, _ns(slab=[slab("x:2:2")])) == ((1, 0, 0), (3, 10, 10))
    clip = ((20.0, 0.0, 0.0), (30.0, 5.0, 5.0))
    assert ropt.clip_box_for(boxed, _ns(clip=clip)) == clip
    assert ropt.clip_box_for(boxed, _ns()) == boxed.clip_box  # neither given
    with pytest.raises(InputError, match=r"--slab z:40:10: the slab \(z 35..45 mm\) lies outside"):
        ropt.clip_box_for(scene, _ns(slab=[slab("z:40:10")]))
    with pytest.raises(InputError, match=r"does not overlap --clip \(x 20..30 mm\): the clip box"):
        ropt.clip_box_for(scene, _ns(clip=clip, slab=[slab("x:5:2")]))
    with pytest.raises(InputError, match="does not overlap the other slabs"):
        ropt.clip_box_for(scene, _ns(slab=[slab("x:5:2"), slab("x:10:2")]))
    with pytest.raises(InputError, match="misses the volume"):
        ropt.clip_box_for(scene, _ns(clip=((-9, -9, 20), (-1, 5, 30))))


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--clip", "1,2,3,4,5"], "argument --clip: '1,2,3,4,5': expected X0,X1,Y0,Y1,Z0,Z1"),
        (["--clip", "5,1,0,4,0,4"], "the box is empty along x (5 >= 1)"),
        (["--clip", "0,1,0,nan,0,4"], "numbers must be finite"),
        (["--clip", "a,b,c,d,e,f"], "expected X0,X1,Y0,Y1,Z0,Z1"),
        (["--slab", "q:1:2"], "argument --slab: 'q:1:2': expected AXIS:CENTRE:THICKNESS"),
        (["--slab", "z:1"], "expected AXIS:CENTRE:THICKNESS"),
        (["--slab", "z:1:0"], "the thickness must be > 0 mm"),
        (["--slab", "z:x:2"], "expected AXIS:CENTRE:THICKNESS"),
        (["--drag-at", "1,2:0,0,1"], "argument --drag-at: '1,2:0,0,1': expected X,Y,Z:DX,DY,DZ"),
        (["--drag-at", "1,2,3"], "expected X,Y,Z:DX,DY,DZ"),
        (["--axis-order", "yxz"], "argument --axis-order: invalid choice"),
        (["--frame", "both"], "argument --frame: invalid choice"),
        (["--series", " "], "argument --series: expected a SeriesInstanceUID or a series index"),
    ],
)
def test_malformed_values_are_one_argparse_line(
    files: dict[str, Path], capsys: pytest.CaptureFixture, args: list[str], message: str
) -> None:
    with pytest.raises(SystemExit) as info:
        main(["render", str(files["solid"]), *args])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    last = err.strip().splitlines()[-1]
    assert last.startswith("voxwarp render: error: ")
    assert message in last


# ---------------------------------------------------------------------- camera
def test_save_camera_then_camera_gives_the_same_image(
    files: dict[str, Path], tmp_path: Path, gl_ctx: object
) -> None:
    cam = tmp_path / "cam.json"
    common = [str(files["cube"]), "--size", SIZE, "--tf", "grayscale", "--seed", "3"]
    first, _ = render(tmp_path, "a.png", *common, "--view", "30,20", "--save-camera", str(cam))
    d = json.loads(cam.read_text())
    assert sorted(d) == sorted(ropt.CAMERA_KEYS)
    again, _ = render(tmp_path, "b.png", *common, "--camera", str(cam))
    np.testing.assert_array_equal(again, first)
    default, _ = render(tmp_path, "c.png", *common)  # the default view differs
    assert np.abs(default - first).max() > 50

    # a scene JSON's camera entry works alike
    scene = Scene(load_volume(files["cube"]), camera=Camera.from_dict(d))
    scene_json = scene.save(tmp_path / "scene.json")
    from_scene, _ = render(tmp_path, "d.png", *common, "--camera", str(scene_json))
    np.testing.assert_array_equal(from_scene, first)


def test_bad_camera_files_are_one_line(
    files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    no_camera = Scene(load_volume(files["cube"])).save(tmp_path / "fitted.json")
    partial = tmp_path / "partial.json"
    partial.write_text(json.dumps({"center": [0, 0, 0], "rotation": np.eye(3).tolist()}))
    bad_rotation = tmp_path / "bad.json"
    d = Camera().to_dict()
    d["rotation"] = (2 * np.eye(3)).tolist()
    bad_rotation.write_text(json.dumps(d))
    not_json = tmp_path / "notjson.json"
    not_json.write_text("{")
    cases = [
        (tmp_path / "none.json", "none.json: no such file"),
        (not_json, "not valid JSON"),
        (no_camera, "this scene has no saved camera"),
        (partial, "a camera JSON lacks distance, fov, projection, ortho_height, radius"),
        (bad_rotation, "rotation"),
    ]
    for path, message in cases:
        with pytest.raises(SystemExit) as info:
            main(["render", str(files["cube"]), "--camera", str(path)])
        assert info.value.code == 2
        last = capsys.readouterr().err.strip().splitlines()[-1]
        assert last.startswith("voxwarp render: error: argument --camera: ")
        assert message in last


@pytest.mark.usefixtures("no_rendering")
@pytest.mark.parametrize("option", [["--view", "+x"], ["--zoom", "2"], ["--frame", "deformed"]])
def test_camera_excludes_the_fitting_options(
    files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture, option: list[str]
) -> None:
    cam = tmp_path / "cam.json"
    cam.write_text(json.dumps(Camera().to_dict()))
    assert_render_refused(
        files["cube"],
        tmp_path,
        capsys,
        ["--camera", str(cam), *option],
        f"{option[0]} cannot be combined with --camera",
    )


# ---------------------------------------------------------------------- framing
def test_undeformed_frame_shows_a_translation_as_a_shift(
    files: dict[str, Path], tmp_path: Path, gl_ctx: object
) -> None:
    cam = tmp_path / "cam.json"
    args = [*MIP, *ORTHO_TOP]
    before, _ = render(tmp_path, "before.png", str(files["cube"]), *args, "--save-camera", str(cam))
    after, _ = render(tmp_path, "after.png", str(files["cube_moved"]), *args)
    ortho_height = json.loads(cam.read_text())["ortho_height"]
    expected = 6.0 * 64 / ortho_height  # 6 mm along +x = screen right in the +z view
    shift = centroid(after) - centroid(before)
    assert shift[0] == pytest.approx(expected, abs=0.25)
    assert abs(shift[1]) < 0.25
    # the cube moves as a whole: the same picture, 6 mm further right
    assert after.sum() == pytest.approx(before.sum(), rel=0.05)

    # --frame deformed refits the camera to the moved box: no shift
    refit, _ = render(tmp_path, "refit.png", str(files["cube_moved"]), *args, "--frame", "deformed")
    assert np.abs(centroid(refit) - centroid(before)).max() < 0.25


def test_scene_frame_is_saved_and_old_scenes_load() -> None:
    vol = Volume(np.zeros((8, 8, 8), np.uint8))
    moved = Scene(vol, warps=[AffineWarp.translation((5.0, 0.0, 0.0))])
    assert moved.frame == "undeformed"
    np.testing.assert_allclose(moved.resolved_camera().center, [3.5, 3.5, 3.5])
    deformed = moved.copy(frame="deformed")
    np.testing.assert_allclose(deformed.resolved_camera().center, [8.5, 3.5, 3.5])
    d = json.loads(json.dumps(deformed.to_dict()))
    assert d["frame"] == "deformed"
    assert Scene.from_dict(d).frame == "deformed"
    del d["frame"]  # a scene written before the frame existed
    assert Scene.from_dict(d).frame == "undeformed"
    with pytest.raises(SceneError, match="frame must be one of undeformed, deformed; got 'box'"):
        Scene.from_dict({**d, "frame": "box"})


# ---------------------------------------------------------------------- drag-at
def test_pick_elements_skip_fixed_elements() -> None:
    grid = ElementGrid(((0.0, 0.0, 0.0), (30.0, 30.0, 30.0)), shape=4)  # shell fixed
    (pick,) = ropt.pick_elements(grid, [ropt.drag_at_arg("1,2,29:0,1,0")])
    assert pick.index == (1, 1, 2)  # the nearest inner element, not the corner
    (pick,) = ropt.pick_elements(grid, [ropt.drag_at_arg("21,18,9:0,1,0")])
    assert pick.index == (2, 2, 1)


def test_pick_elements_nearest_and_outside() -> None:
    grid = ElementGrid(((0.0, 0.0, 0.0), (30.0, 20.0, 10.0)), shape=(4, 3, 2), anchor="none")
    # elements at x 0, 10, 20, 30; y 0, 10, 20; z 0, 10
    drags = [ropt.drag_at_arg("11,8,3:0,1,0"), ropt.drag_at_arg("-9,25,14:1,0,0")]
    near, edge = ropt.pick_elements(grid, drags)
    assert near.index == (1, 1, 0)
    assert near.position == (10.0, 10.0, 0.0)
    assert near.distance == pytest.approx(np.sqrt(1 + 4 + 9))
    assert near.summary() == (
        "--drag-at 11,8,3:0,1,0: element (1, 1, 0) at (10, 10, 0) mm, 3.74 mm from the point"
    )
    assert edge.index == (0, 2, 1)  # outside, but within one spacing of the grid box
    # brute force over every element
    rest = grid.rest_positions.reshape(-1, 3)
    rng = np.random.default_rng(1)
    for p in rng.uniform((-5, -5, -5), (35, 25, 15), size=(50, 3)):
        d = ropt.DragAt("p", tuple(p), (0.0, 0.0, 0.0))
        (pick,) = ropt.pick_elements(grid, [d])
        best = np.unravel_index(np.argmin(np.linalg.norm(rest - p, axis=1)), grid.shape)
        assert pick.index == tuple(int(v) for v in best)
    with pytest.raises(InputError, match=r"--drag-at 0,0,21\.5:0,1,0: the point lies more than"):
        ropt.pick_elements(grid, [ropt.drag_at_arg("0,0,21.5:0,1,0")])


def test_drag_at_equals_the_drag_of_its_element(
    files: dict[str, Path], tmp_path: Path, gl_ctx: object
) -> None:
    """A world point near element (2, 1, 1) of a 4³ grid over the cube volume (box
    -0.5..31.5 mm, elements every 32/3 mm) drags that element: the same image as
    ``--drag 2,1,1`` and a line saying which element and how far."""
    common = [str(files["cube"]), *MIP, *ORTHO_TOP, "--massspring", "4", "--grid-margin", "0"]
    common += ["--steps", "60"]
    by_index, _ = render(tmp_path, "i.png", *common, "--drag", "2,1,1:0,6,0")
    by_point, err = render(tmp_path, "p.png", *common, "--drag-at", "21,10,10:0,6,0")
    np.testing.assert_array_equal(by_point, by_index)
    assert "--drag-at 21,10,10:0,6,0: element (2, 1, 1) at (20.83, 10.17, 10.17) mm" in err
    undragged, _ = render(tmp_path, "u.png", *common[:-2], "--steps", "1")
    assert np.abs(by_index - undragged).max() > 50  # the drag shows


@pytest.mark.usefixtures("no_rendering")
@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["--massspring", "4", "--drag-at", "80,10,10:0,6,0"],
            "--drag-at 80,10,10:0,6,0: the point lies more than one element spacing",
        ),
        (
            ["--chainmail", "4", "--anchor", "corners", "--drag", "0,0,0:0,6,0"],
            "--drag 0,0,0:0,6,0: element (0, 0, 0) is on the 4x4x4 grid's corners",
        ),
        (  # a 2-element axis is all shell: nothing can be dragged
            ["--chainmail", "4,4,2", "--anchor", "shell", "--drag-at", "0,0,0:0,6,0"],
            "element (0, 0, 0) is on the 4x4x2 grid's shell (--anchor shell fixes it)",
        ),
        (
            ["--massspring", "4", "--drag", "2,1,1:1,0,0", "--drag-at", "21,10,10:0,6,0"],
            "element (2, 1, 1) is already dragged by --drag 2,1,1:1,0,0",
        ),
        (["--drag-at", "21,10,10:0,6,0"], "--drag-at needs --massspring"),
    ],
)
def test_drag_at_errors(
    files: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture,
    args: list[str],
    message: str,
) -> None:
    """Refused before any GL work with one error line (the volume is read first, so
    notes about it may come before that line)."""
    out = tmp_path / "x.png"
    assert main(["render", str(files["cube"]), "-o", str(out), *args]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    errors = [line for line in err.splitlines() if line.startswith("voxwarp: error:")]
    assert len(errors) == 1
    assert errors[0] == err.splitlines()[-1]
    assert message in errors[0]
    assert not out.exists()


# ---------------------------------------------------------------------- input options
def test_axis_order_zyx(files: dict[str, Path], capsys: pytest.CaptureFixture) -> None:
    zyx = files["folder"] / "zyx.npy"
    data = np.arange(2 * 3 * 4, dtype=np.int16).reshape(2, 3, 4)  # (z, y, x)
    np.save(zyx, data)
    assert main(["info", str(zyx), "--json", "--axis-order", "zyx"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["dims"] == [4, 3, 2]
    assert main(["info", str(zyx), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["dims"] == [2, 3, 4]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--axis-order", "zyx"], "--axis-order applies to .npy/.npz arrays; sample:fish is a"),
        (["--series", "1"], "--series applies to DICOM folders; sample:fish is a bundled sample"),
    ],
)
def test_input_options_refused_for_samples(
    capsys: pytest.CaptureFixture, args: list[str], message: str
) -> None:
    assert main(["info", "sample:fish", *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert message in err


def test_load_options_pass_only_what_is_given() -> None:
    p = argparse.ArgumentParser()
    ropt.add_input_args(p)
    assert ropt.load_options(p.parse_args([])) == {}
    got = ropt.load_options(p.parse_args(["--axis-order", "zyx", "--series", "2"]))
    assert got == {"axis_order": "zyx", "series": 2}
    uid = "1.2.826.0.1.3680043.8.498.1"
    assert ropt.load_options(p.parse_args(["--series", uid])) == {"series": uid}


def test_spacing_notice(capsys: pytest.CaptureFixture) -> None:
    vol = Volume(np.zeros((2, 2, 2), np.uint8), name="v", spacing_source="assumed")
    ropt.spacing_notice(vol, argparse.Namespace(spacing=None))
    err = capsys.readouterr().err
    assert err == (
        "voxwarp: note: v states no voxel spacing; assuming 1 x 1 x 1 mm (give the real one"
        " with --spacing SX SY SZ)\n"
    )
    ropt.spacing_notice(vol.with_geometry(spacing_source="file"), argparse.Namespace(spacing=None))
    ropt.spacing_notice(vol, argparse.Namespace(spacing=(1, 1, 1)))
    assert capsys.readouterr().err == ""


# ---------------------------------------------------------------------- compressed DICOM
def _rle_series(
    folder: Path, slices: int = 3, source: str = "MR_small_RLE.dcm", prefix: str = "s"
) -> tuple[np.ndarray, str]:
    """``slices`` copies of one of pydicom's test slices (default the RLE-compressed MR)
    as one series in ``folder`` (positions 2 mm apart); returns the uncompressed pixels
    of that slice (pydicom's MR_small.dcm) and the series' UID."""
    import pydicom
    from pydicom.data import get_testdata_file
    from pydicom.uid import generate_uid

    folder.mkdir(exist_ok=True)
    series = generate_uid()
    for k in range(slices):
        ds = pydicom.dcmread(get_testdata_file(source))
        ds.SeriesInstanceUID = series
        ds.SOPInstanceUID = generate_uid()
        ds.file_meta.MediaStorageSOPInstanceUID = ds.SOPInstanceUID
        ds.InstanceNumber = k + 1
        ds.ImagePositionPatient = [0.0, 0.0, 2.0 * k]
        ds.ImageOrientationPatient = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
        ds.save_as(folder / f"{prefix}{k}.dcm")
    return pydicom.dcmread(get_testdata_file("MR_small.dcm")).pixel_array, series


def test_compressed_dicom_series_loads_with_the_dicom_extra(tmp_path: Path) -> None:
    pytest.importorskip("pylibjpeg")
    pytest.importorskip("rle")  # pylibjpeg-rle: the extra's RLE decoder
    plain, _ = _rle_series(tmp_path / "rle")
    vol = load_volume(tmp_path / "rle")
    assert vol.shape == (64, 64, 3)
    assert vol.spacing[2] == pytest.approx(2.0)
    # (x, y, z) order: each slice is the decoded image transposed (columns along x), its
    # axes flipped as the reorientation from LPS to RAS does
    flips = [np.flip(plain.T, axes) for axes in ((), (0,), (1,), (0, 1))]
    for k in range(3):
        sl = np.asarray(vol.data[:, :, k])
        assert any(np.array_equal(sl, f) for f in flips), f"slice {k} decodes wrongly"


def test_compressed_dicom_without_a_decoder_names_the_extra(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import pydicom

    _rle_series(tmp_path / "rle")

    def no_decoder(self: Any) -> Any:
        raise NotImplementedError("no decoder for RLE Lossless")

    monkeypatch.setattr(pydicom.dataset.Dataset, "pixel_array", property(no_decoder))
    with pytest.raises(Exception, match=r"pip install 'voxwarp\[dicom\]'"):
        load_volume(tmp_path / "rle")


def test_dicom_extra_is_declared() -> None:
    import tomllib

    from voxwarp.core import extras

    root = Path(__file__).resolve().parents[2]
    config = tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))
    extra = " ".join(config["project"]["optional-dependencies"]["dicom"])
    for package in ("pylibjpeg", "pylibjpeg-libjpeg", "pylibjpeg-openjpeg", "pylibjpeg-rle"):
        assert package in extra
    assert "dicom" in config["project"]["optional-dependencies"]["all"][0]
    assert extras.EXTRAS["dicom"] == ("pylibjpeg", "libjpeg", "openjpeg", "rle")


def test_series_picks_one_of_several(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """A folder with a 3-slice and a 2-slice series (uncompressed): the largest by
    default (with a warning naming --series), the other by --series 2 or its UID."""
    folder = tmp_path / "two"
    _rle_series(folder, 3, "MR_small.dcm", "a")
    _, second = _rle_series(folder, 2, "MR_small.dcm", "b")
    with pytest.warns(UserWarning, match="--series"):
        assert main(["info", str(folder), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["dims"] == [64, 64, 3]
    for pick in ("2", second):
        assert main(["info", str(folder), "--json", "--series", pick]) == 0
        assert json.loads(capsys.readouterr().out)["dims"] == [64, 64, 2]
    assert main(["info", str(folder), "--series", "7"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "has no DICOM series '7'" in err


def test_gui_takes_series(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``voxwarp gui FOLDER --series N`` opens that series (the window itself is tested in
    tests/ui; here run_gui is replaced and the session loader called directly)."""
    pytest.importorskip("PySide6")
    import voxwarp.ui.app as ui_app
    from voxwarp.cli import main as ui_cli
    from voxwarp.ui.main_window import load_session_input

    folder = tmp_path / "two"
    _rle_series(folder, 3, "MR_small.dcm", "a")
    _rle_series(folder, 2, "MR_small.dcm", "b")
    seen: dict[str, Any] = {}
    monkeypatch.setattr(ui_app, "run_gui", lambda spec, **kw: seen.update(spec=spec, **kw) or 0)
    monkeypatch.setenv("DISPLAY", ":99")
    assert ui_cli.main(["gui", str(folder), "--series", "2"]) == 0
    assert seen["spec"] == str(folder)
    assert seen["series"] == 2
    assert load_session_input(str(folder), series=2).scene.volume.shape == (64, 64, 2)


def test_a_bad_output_format_fails_before_rendering_or_saving_the_scene(tmp_path: Path) -> None:
    run = run_cli(
        "render",
        "sample:colin27",
        "--size",
        "16x16",
        "-o",
        str(tmp_path / "image.json"),
        "--save-scene",
        str(tmp_path / "scene.json"),
    )
    assert run.returncode == 2
    assert run.stderr.strip().splitlines() == [
        f"voxwarp: error: cannot write .json images ({tmp_path / 'image.json'}); use .png,"
        " .exr or .tif"
    ]
    assert list(tmp_path.iterdir()) == []  # no scene, no temporary file


def test_interactive_downsample_goes_to_the_gui_and_the_saved_scene(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``gui --interactive-downsample N`` hands N to the window; ``render ...
    --interactive-downsample N --save-scene`` stores it, and the image is the same still
    as without it (full resolution); a bad N is one argparse line."""
    pytest.importorskip("PySide6")
    import voxwarp.ui.app as ui_app
    from voxwarp.cli import main as ui_cli

    seen: dict[str, Any] = {}
    monkeypatch.setattr(ui_app, "run_gui", lambda spec, **kw: seen.update(spec=spec, **kw) or 0)
    monkeypatch.setenv("DISPLAY", ":99")
    assert ui_cli.main(["gui", "sample:fish", "--interactive-downsample", "3"]) == 0
    assert seen["interactive_downsample"] == 3
    images = []
    for extra in ([], ["--interactive-downsample", "4", "--save-scene", str(tmp_path / "s.json")]):
        out = tmp_path / f"image{len(images)}.png"
        run = run_cli("render", "sample:colin27", "--size", "32x32", "-o", str(out), *extra)
        assert run.returncode == 0, run.stderr
        images.append(read_image(out))
    assert np.array_equal(images[0], images[1])
    assert json.loads((tmp_path / "s.json").read_text())["interactive_downsample"] == 4
    assert Scene.load(tmp_path / "s.json").interactive_downsample == 4
    bad = run_cli("render", "sample:colin27", "--interactive-downsample", "0")
    assert bad.returncode == 2
    assert "--interactive-downsample: '0': expected an integer from 1" in bad.stderr
