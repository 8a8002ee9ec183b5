"""Issue 33, reader side: sizes a transform or field file implies are checked before a
native library allocates them; damaged transforms and headers are one line; compressed
fields that inflate past any real field's ratio are refused before inflating; DICOM
slices whose Rows/Columns contradict their pixel data are refused; nibabel's log lines
stay off stderr."""

from __future__ import annotations

import gzip
import io
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from tests.run_cli import run_cli
from voxwarp.core import limits
from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.errors import FieldError, VolumeError
from voxwarp.io import inflation
from voxwarp.io.fields import load_transform, save_displacement_field
from voxwarp.io.inflation import INFLATION_FLOOR, MAX_INFLATION, check_inflation
from voxwarp.io.transform_sizes import check_grid

sitk = pytest.importorskip("SimpleITK")

IDENTITY_FIXED = "0 0 0 1 1 1 1 0 0 0 1 0 0 0 1"


def _tfm(path: Path, name: str, params: str, fixed: str) -> Path:
    path.write_text(
        "#Insight Transform File V1.0\n#Transform 0\n"
        f"Transform: {name}\nParameters: {params}\nFixedParameters: {fixed}\n"
    )
    return path


def _one_error_line(proc) -> str:  # type: ignore[no-untyped-def]
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert "Traceback" not in proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, proc.stderr
    return lines[0]


@pytest.mark.timeout(20)
def test_bspline_grid_of_100000_cubed_is_one_line_not_an_abort(tmp_path: Path) -> None:
    """The 150-byte file of the issue: ITK aborted the process (rc 134, nothing said)."""
    path = _tfm(
        tmp_path / "b.tfm",
        "BSplineTransform_double_3_3",
        "0 0 0",
        f"100000 100000 100000 {IDENTITY_FIXED}",
    )
    line = _one_error_line(run_cli("info", str(path), timeout=20))
    assert "100000x100000x100000" in line
    assert "memory budget" in line
    assert "TiB" in line


def test_bspline_parameter_count_must_fit_the_grid(tmp_path: Path) -> None:
    path = _tfm(
        tmp_path / "b.tfm", "BSplineTransform_double_3_3", "0 0 0", f"4 4 4 {IDENTITY_FIXED}"
    )
    with pytest.raises(FieldError, match=r"holds 3 numbers .* needs 192"):
        load_transform(path)


def test_constant_bspline_moves_every_point_by_its_coefficient(tmp_path: Path) -> None:
    """Oracle: B-splines sum to 1, so all x coefficients 1.5 (LPS) move the whole domain
    by 1.5 mm along L, i.e. -1.5 along RAS x; the check lets this grid through."""
    coeffs = np.zeros((3, 64))
    coeffs[0] = 1.5
    params = " ".join(f"{v:g}" for v in coeffs.ravel())
    path = _tfm(
        tmp_path / "b.txt", "BSplineTransform_double_3_3", params, f"4 4 4 {IDENTITY_FIXED}"
    )
    (warp,) = load_transform(path)
    assert isinstance(warp, DisplacementFieldWarp)
    u = warp.displacements
    np.testing.assert_allclose(u[..., 0], -1.5, atol=1e-9)
    np.testing.assert_allclose(u[..., 1:], 0.0, atol=1e-9)


def test_grid_budget_is_exact() -> None:
    """A 10x10x10 grid needs 1000 x 3 x 8 = 24,000 bytes: a budget of exactly that
    passes, one byte less refuses it."""
    fixed = [10.0, 10.0, 10.0, *map(float, IDENTITY_FIXED.split())]
    with limits.memory_budget(24_000):
        check_grid("BSplineTransform", fixed, 3000, "t")
    with limits.memory_budget(23_999), pytest.raises(FieldError, match="memory budget"):
        check_grid("BSplineTransform", fixed, 3000, "t")


@pytest.mark.parametrize(
    "fixed",
    ["0 4 4", "4 4 4.5", "-4 4 4", "nan 4 4", "4 4"],
    ids=["zero", "fraction", "negative", "nan", "short"],
)
def test_bad_grid_sizes_are_one_line(fixed: str, tmp_path: Path) -> None:
    rest = IDENTITY_FIXED if fixed != "4 4" else ""
    path = _tfm(tmp_path / "b.tfm", "BSplineTransform_double_3_3", "0", f"{fixed} {rest}")
    with pytest.raises(FieldError) as info:
        load_transform(path)
    assert "\n" not in str(info.value)
    assert "b.tfm" in str(info.value)


def test_singular_affine_tfm_is_one_line(tmp_path: Path) -> None:
    path = _tfm(
        tmp_path / "a.tfm", "AffineTransform_double_3_3", "1 0 0 0 0 0 0 0 1 0 0 0", "0 0 0"
    )
    line = _one_error_line(run_cli("info", str(path), timeout=20))
    assert "singular" in line
    assert "a.tfm" in line


@pytest.mark.parametrize("suffix", [".txt", ".mat"])
def test_singular_affine_txt_and_mat(suffix: str, tmp_path: Path) -> None:
    t = sitk.AffineTransform(3)
    t.SetMatrix([1, 0, 0, 0, 0, 0, 0, 0, 1])
    path = tmp_path / f"a{suffix}"
    sitk.WriteTransform(t, str(path))
    with pytest.raises(FieldError, match="singular"):
        load_transform(path)


def _field(tmp_path: Path, name: str = "f.nrrd") -> Path:
    w = DisplacementFieldWarp(np.zeros((4, 4, 4, 3), np.float32), np.eye(4))
    return save_displacement_field(w, tmp_path / name)


@pytest.mark.parametrize(
    "line",
    [b"space directions: none (1,0,0) (0,1,0)", b"space directions: none (1,0) (0,1) (0,0)"],
    ids=["two-vectors", "2-d-vectors"],
)
def test_damaged_nrrd_space_directions_is_one_line(line: bytes, tmp_path: Path) -> None:
    path = _field(tmp_path)
    raw = path.read_bytes()
    i = raw.index(b"space directions")
    path.write_bytes(raw[:i] + line + raw[raw.index(b"\n", i) :])
    with pytest.raises(FieldError, match=r"^f\.nrrd: damaged 'space directions'") as info:
        load_transform(path)
    assert "\n" not in str(info.value)


# ---------------------------------------------------------------------------- inflation
@pytest.mark.parametrize("codec", ["deflate", "bzip2"])
def test_inflation_limit_is_exact(codec: str) -> None:
    limit = MAX_INFLATION[codec]
    stored = INFLATION_FLOOR // limit + 1  # stored x limit is over the floor: the ratio decides
    check_inflation(stored * limit, stored, "f", codec)
    with pytest.raises(FieldError, match="decompression bomb"):
        check_inflation(stored * limit + 1, stored, "f", codec)
    check_inflation(INFLATION_FLOOR, 1, "f", codec)  # small data is always read


@pytest.fixture
def small_floor(monkeypatch):  # type: ignore[no-untyped-def]
    """The inflation floor at 32 MiB, so that bombs in tests stay small and fast."""
    monkeypatch.setattr(inflation, "INFLATION_FLOOR", 32 << 20)


def test_deflate_limit_lies_between_zeros_and_a_compact_support_field(
    tmp_path: Path, monkeypatch
) -> None:  # type: ignore[no-untyped-def]
    """Oracle for the 900-fold limit, both gzipped at level 9 (the tightest deflate): a
    field that is zero outside a ball (a local deformation on a large grid) loads; an
    all-zero field (deflate's ~1030-fold ceiling) is refused. The floor is lowered."""
    monkeypatch.setattr(inflation, "INFLATION_FLOOR", 1 << 20)
    n = 128  # 24 MiB of vectors: ball ~470-fold, zeros ~1030-fold
    x, y, z = np.ogrid[:n, :n, :n]
    r2 = ((x - 64) ** 2 + (y - 64) ** 2 + (z - 64) ** 2).astype(np.float32)
    u = np.zeros((n, n, n, 3), np.float32)
    u[..., 0] = np.where(r2 < 16**2, 3 * np.exp(-r2 / (2 * 12.0**2)), 0)
    paths = []
    for name, vectors in (("ball", u), ("zero", 0 * u)):
        plain = save_displacement_field(
            DisplacementFieldWarp(vectors, np.eye(4)), tmp_path / f"{name}.nii"
        )
        paths.append(tmp_path / f"{name}.nii.gz")
        paths[-1].write_bytes(gzip.compress(plain.read_bytes(), compresslevel=9))
    (back,) = load_transform(paths[0])
    np.testing.assert_allclose(back.displacements, u, atol=1e-6)
    with pytest.raises(FieldError, match="decompression bomb"):
        load_transform(paths[1])


def _zeros_gz(fh, nbytes: int) -> None:  # type: ignore[no-untyped-def]
    block = b"\0" * (1 << 22)
    for _ in range(nbytes // len(block)):
        fh.write(block)


@pytest.mark.timeout(20)
def test_nii_gz_bomb_is_refused_before_inflating(tmp_path: Path, small_floor: None) -> None:
    """A ~100 KB .nii.gz whose header claims 96 MiB of zeros: refused in well under a
    second (inflating it took minutes at the issue's 1.2 GB)."""
    import nibabel as nib

    hdr = nib.Nifti1Header()
    hdr.set_data_shape((256, 256, 128, 1, 3))
    hdr.set_data_dtype(np.float32)
    hdr.set_intent("vector")
    hdr.set_sform(np.eye(4), 1)
    path = tmp_path / "bomb.nii.gz"
    with gzip.open(path, "wb", compresslevel=9) as fh:
        fh.write(hdr.binaryblock + b"\0" * 4)
        _zeros_gz(fh, 256 * 256 * 128 * 3 * 4)
    t0 = time.perf_counter()
    with pytest.raises(FieldError, match="decompression bomb"):
        load_transform(path)
    assert time.perf_counter() - t0 < 1.0


def _npz_with_header(path: Path, shape: tuple[int, ...], payload: bytes) -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        with zf.open("displacement.npy", "w", force_zip64=True) as fh:
            np.lib.format.write_array_header_1_0(
                fh, {"descr": "<f4", "fortran_order": False, "shape": shape}
            )
            fh.write(payload)
        buf = io.BytesIO()
        np.save(buf, np.eye(4))
        zf.writestr("affine.npy", buf.getvalue())
    return path


def test_npz_member_header_over_the_budget_is_refused_before_np_load(tmp_path: Path) -> None:
    """The npy header claims 4000^3 x 3 floats over 1 KiB of data: the budget error
    names the header's shape (before: np.load's own error)."""
    path = _npz_with_header(tmp_path / "f.npz", (4000, 4000, 4000, 3), b"\0" * 1024)
    with pytest.raises(FieldError, match=r"4000x4000x4000x3 voxels need .* memory budget"):
        load_transform(path)


@pytest.mark.timeout(20)
def test_npz_deflate_bomb_is_refused(tmp_path: Path, small_floor: None) -> None:
    shape = (256, 256, 128, 3)
    path = tmp_path / "bomb.npz"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as zf:
        with zf.open("displacement.npy", "w", force_zip64=True) as fh:
            np.lib.format.write_array_header_1_0(
                fh, {"descr": "<f4", "fortran_order": False, "shape": shape}
            )
            _zeros_gz(fh, int(np.prod(shape)) * 4)
        buf = io.BytesIO()
        np.save(buf, np.eye(4))
        zf.writestr("affine.npy", buf.getvalue())
    with pytest.raises(FieldError, match=r"displacement\.npy.*decompression bomb"):
        load_transform(path)


@pytest.mark.timeout(20)
def test_compressed_mha_bomb_is_refused(tmp_path: Path, small_floor: None) -> None:
    path = tmp_path / "bomb.mha"
    sitk.WriteImage(sitk.Image([256, 256, 128], sitk.sitkVectorFloat32, 3), str(path), True)
    with pytest.raises(FieldError, match="decompression bomb"):
        load_transform(path)


def test_compressed_field_of_a_real_ratio_loads(tmp_path: Path) -> None:
    """A gzip NRRD and an .npz of noisy vectors load (the ratio check passes them)."""
    rng = np.random.default_rng(1)
    u = rng.normal(0, 2, (6, 5, 4, 3)).astype(np.float32)
    w = DisplacementFieldWarp(u, np.eye(4))
    for name in ("f.nrrd", "f.npz", "f.nii.gz", "f.mha"):
        (back,) = load_transform(save_displacement_field(w, tmp_path / name))
        np.testing.assert_allclose(back.displacements, u, atol=1e-6)


# ---------------------------------------------------------------------------- NIfTI, DICOM
def test_zero_pixdim_prints_one_voxwarp_line_not_nibabel_logs(tmp_path: Path) -> None:
    """nibabel logged ``pixdim[1,2,3] should be non-zero`` straight to stderr (twice for a
    field); now it is one voxwarp warning line, for a field and for a volume."""
    import nibabel as nib

    for name, shape in (("f.nii", (4, 4, 4, 1, 3)), ("v.nii", (4, 4, 4))):
        img = nib.Nifti1Image(np.zeros(shape, np.float32), np.eye(4))
        img.header.set_intent("vector" if len(shape) == 5 else "none")
        img.header.set_sform(None, 0)
        path = tmp_path / name
        nib.save(img, path)
        raw = bytearray(path.read_bytes())
        raw[80:92] = np.zeros(3, "<f4").tobytes()  # pixdim[1:4] = 0
        path.write_bytes(bytes(raw))
        proc = run_cli("info", str(path), timeout=20)
        assert proc.returncode == 0, proc.stderr
        lines = [x for x in proc.stderr.splitlines() if x.strip()]
        assert len(lines) == 1, proc.stderr
        assert lines[0].startswith(f"voxwarp: warning: {name}: pixdim"), proc.stderr


def test_dicom_rows_not_matching_the_pixel_data_is_refused(tmp_path: Path) -> None:
    """One slice of 8 x 10 pixels (160 bytes) holds 4 more rows of data: refused, naming
    the bytes (before: pydicom dropped the excess and the series loaded, rc 0)."""
    import pydicom

    from tests.io.test_io import write_series
    from voxwarp.io.volumes import load_volume

    write_series(tmp_path)
    load_volume(tmp_path)  # the untouched series loads
    p = sorted(tmp_path.glob("IM*"))[2]
    ds = pydicom.dcmread(p)
    ds.PixelData = ds.PixelData + b"\x01\x00" * 40
    ds.save_as(p)
    with pytest.raises(VolumeError, match=r"pixel data holds 240 bytes .* need 160"):
        load_volume(tmp_path)


@pytest.mark.parametrize(
    ("name", "params", "fixed", "match"),
    [
        ("Euler3DTransform_double_3_3", "0 0 0", "0 0 0", "3 Parameters .* has 6"),
        ("AffineTransform_double_3_3", "1 0 0 0 1 0 0 0 1 0 0 0", "0", "1 FixedParameters"),
        ("AffineTransform_double_3_3", "1 0 0 0 1 0 0 0 1 0 0 inf", "0 0 0", "NaN or infinity"),
        ("AffineTransform_double_2_2", "1 0 0 1 0 0", "0 0", "2-D"),
        ("KernelTransform_double_3_3", "0", "0", "convert it"),
    ],
    ids=["short-euler", "short-fixed", "inf", "2d", "unknown"],
)
def test_linear_parameter_counts_are_checked_before_itk(
    name: str, params: str, fixed: str, match: str, tmp_path: Path
) -> None:
    """ITK trusts the counts: an Euler3DTransform with 3 Parameters corrupted its heap
    (found by the fuzz suite)."""
    path = _tfm(tmp_path / "t.tfm", name, params, fixed)
    with pytest.raises(FieldError, match=match):
        load_transform(path)


def test_euler_transform_as_sitk_writes_it_loads(tmp_path: Path) -> None:
    """Oracle: a 90° rotation about z read back equals SimpleITK's own matrix."""
    t = sitk.Euler3DTransform((0, 0, 0), 0, 0, np.pi / 2, (1, 2, 3))
    path = tmp_path / "e.tfm"
    sitk.WriteTransform(t, str(path))
    (warp,) = load_transform(path)
    m = warp.affine_matrix()  # fixed -> moving, RAS (as voxwarp info reports it)
    lps = np.diag([-1.0, -1.0, 1.0, 1.0])
    expect = np.eye(4)
    expect[:3, :3] = np.asarray(t.GetMatrix()).reshape(3, 3)
    expect[:3, 3] = t.GetTranslation()
    np.testing.assert_allclose(m, lps @ expect @ lps, atol=1e-9)


def _bspline_h5(path: Path, size: float) -> Path:
    """An ITK .h5 B-spline (6x6x6 control points) whose grid size doubles say ``size``."""
    import struct

    t = sitk.BSplineTransformInitializer(sitk.Image([8, 8, 8], sitk.sitkFloat32), [3, 3, 3])
    sitk.WriteTransform(t, str(path))
    raw = path.read_bytes()
    six = struct.pack("<d", 6.0) * 3
    assert raw.count(six) == 1
    path.write_bytes(raw.replace(six, struct.pack("<d", size) * 3))
    return path


@pytest.mark.timeout(20)
def test_h5_bspline_grid_that_aborts_itk_is_one_line(tmp_path: Path) -> None:
    """The .h5 form of the 100000³ grid: ITK aborted voxwarp (rc 134); now a forked
    child reads it first and the process reports one line."""
    path = _bspline_h5(tmp_path / "b.h5", 100000.0)
    line = _one_error_line(run_cli("info", str(path), timeout=20))
    assert "b.h5" in line
    # the capped child either aborts or throws std::bad_alloc, as its allocator decides
    assert "SIGABRT" in line or "bad_alloc" in line
    assert "memory budget" in line
    (warp,) = load_transform(_bspline_h5(tmp_path / "ok.h5", 6.0))  # the untouched grid
    assert isinstance(warp, DisplacementFieldWarp)
