"""``voxwarp slice``: array-slice oracles, radiological layout, --json, and bad inputs.

Volume: a small uint8 NIfTI stored in LPS voxel order (as DICOM-derived files often are),
every voxel a distinct value in 16..239, with two markers: 250 on the patient's right
and 245 anterior. The slice is drawn with nearest interpolation and ``--window
127.5,255``, so a grey level *is* the voxel value (0 = outside). Oracle for each
anatomical plane: every pixel's centre (from ``--json``'s pixel -> world matrix) mapped
to the nearest voxel of the loaded volume gives the pixel's grey (pixels within 1e-3
voxel of a voxel boundary, where either neighbour is right, are left out). Layout:
patient right on the image's left for axial and coronal, anterior at the top of the
axial image and on the left of the sagittal one. Commands run in a subprocess (see
tests/cli/test_cli.py: an in-process render would disturb the session's GL context);
the PNGs are kept in /tmp/voxwarp_cli_slice/ to look at.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.run_cli import run_cli
from voxwarp.cli.main import main
from voxwarp.io.images import read_image
from voxwarp.io.volumes import load_volume

REPO = Path(__file__).resolve().parents[2]
PNG_DIR = Path("/tmp/voxwarp_cli_slice")
SHAPE = (9, 8, 6)  # file voxels (i: towards L, j: towards P, k: towards S)
RIGHT_MARK, ANTERIOR_MARK = 250, 245


@pytest.fixture(autouse=True)
def _keep_warning_state(monkeypatch: pytest.MonkeyPatch) -> None:
    """main() replaces warnings.formatwarning for good; undo it after each test."""
    monkeypatch.setattr(warnings, "formatwarning", warnings.formatwarning)


@pytest.fixture(scope="module")
def lps_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    import nibabel as nib

    rng = np.random.default_rng(3)
    data = (rng.permutation(int(np.prod(SHAPE))) % 224 + 16).reshape(SHAPE).astype(np.uint8)
    data[0, 4, 3] = RIGHT_MARK  # i = 0: the patient's rightmost column (x = -2 i + 8)
    data[5, 0, 3] = ANTERIOR_MARK  # j = 0: the most anterior row (y = -2.5 j + 10)
    affine = np.array([[-2.0, 0, 0, 8.0], [0, -2.5, 0, 10.0], [0, 0, 3.0, -7.0], [0, 0, 0, 1]])
    path = tmp_path_factory.mktemp("slice_cli") / "lps.nii.gz"
    img = nib.Nifti1Image(data, affine)
    img.set_sform(affine, code=1)
    img.set_qform(affine, code=1)
    nib.save(img, str(path))
    return path


def slice_cli(src: Path, name: str, *args: str) -> tuple[np.ndarray, dict[str, Any], str]:
    """Grey image (H, W), the --json document and stderr of one ``voxwarp slice``."""
    PNG_DIR.mkdir(parents=True, exist_ok=True)
    out = PNG_DIR / f"{name}.png"
    proc = run_cli("slice", str(src), "-o", str(out), "--json", *args)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    doc = json.loads(proc.stdout)
    img = read_image(out)
    assert img.dtype == np.uint8
    assert np.array_equal(img[..., 0], img[..., 1])  # grey
    return img[..., 0].astype(np.int64), doc, proc.stderr


def expected_grey(
    vol: Any, matrix: np.ndarray, size: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """Nearest-voxel values at every pixel centre (0 outside) and the pixels to compare."""
    w, h = size
    cols, rows = np.meshgrid(np.arange(w), np.arange(h))
    pix = np.stack([cols, rows, np.zeros_like(cols), np.ones_like(cols)], -1).astype(float)
    world = (pix @ np.asarray(matrix).T)[..., :3]
    q = vol.world_to_index(world) + 0.5  # texel units: voxel i spans [i, i + 1]
    n = np.asarray(vol.shape)
    inside = np.all((q >= 0) & (q <= n), axis=-1)
    idx = np.clip(np.floor(q).astype(int), 0, n - 1)
    values = np.where(inside, vol.data[idx[..., 0], idx[..., 1], idx[..., 2]], 0)
    frac = q - np.floor(q)
    clear = np.all((frac > 1e-3) & (frac < 1 - 1e-3), axis=-1)  # away from voxel faces
    return values, clear


@pytest.mark.parametrize("plane", ["axial", "coronal", "sagittal"])
def test_named_planes_are_the_array_slices(gl_ctx: Any, lps_file: Path, plane: str) -> None:
    vol = load_volume(lps_file)
    axis = {"axial": 2, "coronal": 1, "sagittal": 0}[plane]
    at = vol.index_to_world([4, 3, 2])[axis]  # a voxel centre: no tie in depth
    extra = ["--at", f"{at:g}"]
    grey, doc, err = slice_cli(
        lps_file,
        f"lps_{plane}",
        "--plane",
        plane,
        "--interpolation",
        "nearest",
        "--window",
        "127.5,255",
        "--pixel",
        "0.7",
        *extra,
    )
    size = tuple(doc["size"])
    assert grey.shape == (size[1], size[0])
    want, clear = expected_grey(vol, np.asarray(doc["pixel_to_world"]), size)
    # the pixel grid runs through voxel centres, so every 10th 0.7 mm pixel lies on a
    # face of a 2 mm voxel (7 mm = 3.5 voxels): a tie, left out
    assert clear.mean() > 0.85
    np.testing.assert_array_equal(grey[clear], want[clear])
    assert np.count_nonzero(grey) > 0.3 * grey.size  # the volume fills the image
    assert err.count("\n") == 1
    assert err.startswith(f"slice: {plane} at ")


def _marker_pixels(grey: np.ndarray, value: int) -> np.ndarray:
    rows, cols = np.nonzero(grey == value)
    assert rows.size, f"marker {value} not in the image"
    return np.array([cols.mean(), rows.mean()])


def test_radiological_layout(gl_ctx: Any, lps_file: Path) -> None:
    """The marker on the patient's right shows on the image's left (axial, coronal);
    the anterior marker at the top (axial) and on the left (sagittal)."""
    vol = load_volume(lps_file)
    assert vol.orientation == "RAS"
    z = vol.index_to_world(np.argwhere(vol.data == RIGHT_MARK)[0])
    common = ["--interpolation", "nearest", "--window", "127.5,255", "--pixel", "0.5"]
    grey, doc, err = slice_cli(lps_file, "mark_axial", *common, "--at", f"{z[2]:g}")
    assert doc["plane"] == "axial"  # the default for an oriented volume
    w, h = doc["size"]
    col, _ = _marker_pixels(grey, RIGHT_MARK)
    assert col < 0.25 * w, "patient right must be on the image's left"
    assert "at S " in err or "at I " in err
    col, row = _marker_pixels(grey, ANTERIOR_MARK)
    assert row < 0.25 * h, "anterior must be at the top of an axial image"
    grey, doc, _ = slice_cli(
        lps_file, "mark_coronal", *common, "--plane", "coronal", "--at", f"{z[1]:g}"
    )
    assert _marker_pixels(grey, RIGHT_MARK)[0] < 0.25 * doc["size"][0]
    a = vol.index_to_world(np.argwhere(vol.data == ANTERIOR_MARK)[0])
    grey, doc, _ = slice_cli(
        lps_file, "mark_sagittal", *common, "--plane", "sagittal", "--at", f"{a[0]:g}"
    )
    assert _marker_pixels(grey, ANTERIOR_MARK)[0] < 0.25 * doc["size"][0]


def test_json_mapping_inverts(gl_ctx: Any, lps_file: Path) -> None:
    """A world point mapped through the inverse of --json's matrix lands on the pixel
    that shows it, on the plane (third coordinate 0), for an oblique plane too."""
    vol = load_volume(lps_file)
    mark = vol.index_to_world(np.argwhere(vol.data == RIGHT_MARK)[0])
    normal = "0.2,0.1,1"
    grey, doc, err = slice_cli(
        lps_file,
        "oblique",
        "--plane",
        f"{mark[0]:g},{mark[1]:g},{mark[2]:g}:{normal}",
        "--interpolation",
        "nearest",
        "--window",
        "127.5,255",
        "--pixel",
        "0.25",
    )
    assert doc["plane"] == "oblique"
    assert "along the normal" in err
    m = np.asarray(doc["pixel_to_world"])
    col, row, depth, one = np.linalg.inv(m) @ np.r_[mark, 1.0]
    assert abs(depth) < 1e-6
    assert one == pytest.approx(1.0)
    assert grey[round(row), round(col)] == RIGHT_MARK
    back = m @ np.array([col, row, 0.0, 1.0])
    np.testing.assert_allclose(back[:3], mark, atol=1e-9)
    n = np.asarray(doc["normal"])
    np.testing.assert_allclose(m[:3, 2], n)
    # the given normal, or its opposite (the tilted axial plane keeps its viewing side)
    assert abs(n @ np.array([0.2, 0.1, 1])) == pytest.approx(np.linalg.norm([0.2, 0.1, 1]))


@pytest.mark.slow
def test_deformation_options_apply(gl_ctx: Any, lps_file: Path, tmp_path: Path) -> None:
    """--massspring/--drag bend the slice (render's options, shared assembly); the rest
    view of the same command is the undeformed slice."""
    args = ["--interpolation", "nearest", "--window", "127.5,255", "--pixel", "0.5"]
    # on the volume's box: with a margin the (shared) slice extent grows by the drag
    drag = ["--massspring", "4", "--drag", "1,1,2:4,0,0", "--steps", "300", "--grid-margin", "0"]
    rest, _, _ = slice_cli(lps_file, "rest", *args)
    bent, _, err = slice_cli(lps_file, "bent", *args, *drag)
    shown_rest, _, _ = slice_cli(lps_file, "bent_rest", *args, *drag, "--show", "rest")
    assert "massspring: 4x4x4" in err
    np.testing.assert_array_equal(shown_rest, rest)
    assert np.mean(bent != rest) > 0.05


def test_axis_names_without_orientation(gl_ctx: Any, tmp_path: Path) -> None:
    from voxwarp.core.volume import Volume
    from voxwarp.io.volumes import save_volume

    path = save_volume(
        Volume(np.arange(60, dtype=np.uint8).reshape(5, 4, 3) + 10), tmp_path / "v.npz"
    )
    _, doc, err = slice_cli(path, "plain_axial", "--plane", "axial", "--window", "127.5,255")
    assert doc["plane"] == "z"
    assert "no patient orientation" in err
    assert "--plane z" in err
    assert "slice: z at z " in err


def _refused(capsys: pytest.CaptureFixture, args: list[str], out: Path, text: str) -> None:
    try:
        code = main(["slice", *args, "-o", str(out)])
    except SystemExit as exc:  # argparse's errors (one line: OneLineErrorParser)
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith("voxwarp"), err
    assert err.count("\n") == 1, err
    assert text in err, err
    assert not out.exists()


@pytest.mark.parametrize(
    ("args", "text"),
    [
        (["--plane", "diagonal"], "expected axial, coronal"),
        (["--plane", "1,2:0,0,1"], "expected axial, coronal"),
        (["--plane", "0,0,0:0,0,0"], "normal must not be 0,0,0"),
        (["--window", "40"], "LEVEL,WIDTH"),
        (["--window", "40,-5"], "LEVEL,WIDTH"),
        (["--pixel", "0"], "--pixel must be a number of mm > 0"),
        (["--size", "64x64", "--pixel", "1"], "not allowed with argument"),
    ],
)
def test_bad_options_are_one_line(
    capsys: pytest.CaptureFixture, lps_file: Path, tmp_path: Path, args: list[str], text: str
) -> None:
    _refused(capsys, [str(lps_file), *args], tmp_path / "s.png", text)


def test_missing_input_and_bad_format(
    capsys: pytest.CaptureFixture, tmp_path: Path, lps_file: Path
) -> None:
    _refused(capsys, [str(tmp_path / "nope.nii.gz")], tmp_path / "s.png", "nope.nii.gz")
    _refused(capsys, [str(lps_file)], tmp_path / "s.xyz", "cannot write .xyz")
    # a wire or lattice file given as INPUT: say what it is and how to use it
    for name, option in (
        ("fish_spine_wires.json", "--wires"),
        ("fish_lattice_bend.json", "--lattice"),
    ):
        path = str(REPO / "sample_volumes" / name)
        _refused(capsys, [path], tmp_path / "s.png", f"voxwarp render INPUT {option} {path}")


def test_refusals_after_loading(gl_ctx: Any, lps_file: Path, tmp_path: Path) -> None:
    """--at outside the volume names its range; an unwritable -o (its folder is a file)
    is one line; neither leaves a file."""
    proc = run_cli("slice", str(lps_file), "--at", "500", "-o", str(tmp_path / "a.png"))
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1, proc.stderr
    assert "misses the volume, which spans -8.5..9.5 mm along z" in proc.stderr
    assert not (tmp_path / "a.png").exists()
    blocker = tmp_path / "file"
    blocker.write_text("x")
    proc = run_cli("slice", str(lps_file), "-o", str(blocker / "s.png"))
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1, proc.stderr
    assert "voxwarp: error: cannot write" in proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_real_scans(gl_ctx: Any) -> None:
    """The bundled real CT and MRI slice without error (PNGs kept to look at); the
    stent CT, which states no orientation, gets the z plane."""
    grey, doc, _ = slice_cli(Path("sample:colin27"), "colin27_sagittal", "--plane", "sagittal")
    assert doc["plane"] == "sagittal"
    assert np.count_nonzero(grey) > 0.3 * grey.size
    grey, doc, _ = slice_cli(Path("sample:stent"), "stent", "--slab", "10", "--mode", "mip")
    assert doc["plane"] == "z"
    assert grey.max() > 200


@pytest.mark.slow
def test_scene_json_input_is_the_same_slice(gl_ctx: Any, tmp_path: Path) -> None:
    """A scene JSON saved by ``render --wires ... --save-scene`` slices as the volume with
    the same --wires option (the shared scene assembly), and the wire bends the slice."""
    wires = str(REPO / "sample_volumes" / "fish_spine_wires.json")
    scene = tmp_path / "fish_wires.json"
    proc = run_cli(
        "render", "sample:fish", "--wires", wires, "--size", "16x16", "--save-scene", str(scene),
        "-o", str(tmp_path / "r.png"),
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    common = ["--plane", "z", "--interpolation", "nearest", "--window", "127.5,255"]
    from_json, doc_json, _ = slice_cli(scene, "fish_scene_json", *common)
    inline, doc_inline, err = slice_cli(
        Path("sample:fish"), "fish_wires", *common, "--wires", wires
    )
    rest, _, _ = slice_cli(
        Path("sample:fish"), "fish_wires_rest", *common, "--wires", wires, "--show", "rest"
    )
    assert "wires: 1 wire(s)" in err
    assert doc_json["pixel_to_world"] == doc_inline["pixel_to_world"]
    np.testing.assert_array_equal(from_json, inline)
    assert np.mean(inline != rest) > 0.01


def test_negative_values_parse() -> None:
    """``--plane -10,0,0:1,0,0`` and ``--window -100,400`` start with "-" and still parse
    as values (render's two-value ``--window -100 400`` too)."""
    from voxwarp.cli.main import build_parser
    from voxwarp.cli.options import join_negative_views as _join_negative_views

    parser = build_parser(bench=False)
    argv = ["slice", "v.nii", "--plane", "-10,0,0:1,0,0", "--window", "-100,400", "--at", "-5"]
    args = parser.parse_args(_join_negative_views(argv))
    assert args.plane == "-10,0,0:1,0,0"
    assert args.window == (-100.0, 400.0)
    assert args.at == -5.0
    args = parser.parse_args(_join_negative_views(["render", "v.nii", "--window", "-100", "400"]))
    assert args.window == [-100.0, 400.0]
