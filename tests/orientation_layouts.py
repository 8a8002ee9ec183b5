"""One scan written in the file layouts real tools produce, for orientation tests.

:func:`write_layouts` takes a volume in RAS axis order with its RAS affine and writes
it as RAS, LAS and LIA NIfTI (nibabel), LPS NRRD (pynrrd), an axial DICOM series in
LPS (pydicom, files in shuffled order), and an oblique NIfTI (the scan resampled here,
with scipy, onto a grid rotated 20 degrees about two axes). The axis-aligned layouts
hold exactly the same voxels at the same patient positions (permuted and flipped by
numpy here, independently of voxwarp's own reorientation), so a correct reader renders
them pixel-equal; a reader that ignores the orientation renders a mirror image.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: Layout name -> the patient direction each file index axis grows towards.
AXIS_LAYOUTS = {"ras": "RAS", "las": "LAS", "lia": "LIA", "lps_nrrd": "LPS", "dicom": "LPS"}
OBLIQUE_DEGREES = 20.0

_AXES = {"R": (0, 1), "L": (0, -1), "A": (1, 1), "P": (1, -1), "S": (2, 1), "I": (2, -1)}


def relayout(data: np.ndarray, affine: np.ndarray, code: str) -> tuple[np.ndarray, np.ndarray]:
    """``data`` (RAS order, RAS ``affine``) re-indexed so its axes grow towards ``code``.

    Returns the new array and its RAS affine: voxel values stay at the same points.
    """
    order = [_AXES[c][0] for c in code]
    signs = [_AXES[c][1] for c in code]
    out = np.transpose(data, order)
    new = np.eye(4)
    new[:3, 3] = affine[:3, 3]
    for i, (w, sgn) in enumerate(zip(order, signs, strict=True)):
        col = affine[:3, w].copy()
        if sgn < 0:
            new[:3, 3] += col * (data.shape[w] - 1)
            col = -col
        new[:3, i] = col
        if sgn < 0:
            out = np.flip(out, axis=i)
    return np.ascontiguousarray(out), new


def rotation(degrees_x: float, degrees_z: float) -> np.ndarray:
    """Rotation by ``degrees_z`` about z after ``degrees_x`` about x."""
    a, b = np.radians(degrees_x), np.radians(degrees_z)
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    rz = np.array([[np.cos(b), -np.sin(b), 0], [np.sin(b), np.cos(b), 0], [0, 0, 1]])
    return rz @ rx


def oblique(data: np.ndarray, affine: np.ndarray, fill: float) -> tuple[np.ndarray, np.ndarray]:
    """The scan resampled (trilinear) onto a grid rotated 20 deg about x and z, same
    spacing and centre, large enough to hold the whole scan; values outside: ``fill``."""
    from scipy import ndimage

    sp = np.linalg.norm(affine[:3, :3], axis=0)
    rot = rotation(OBLIQUE_DEGREES, OBLIQUE_DEGREES)
    n = np.asarray(data.shape)
    centre = affine[:3, :3] @ ((n - 1) / 2) + affine[:3, 3]
    half = np.abs(rot.T) @ (np.abs(affine[:3, :3]) @ (n / 2))  # rotated box half-extent
    shape = np.ceil(2 * half / sp).astype(int) + 1
    new = np.eye(4)
    new[:3, :3] = rot * sp
    new[:3, 3] = centre - new[:3, :3] @ ((shape - 1) / 2)
    ijk = np.indices(shape).reshape(3, -1).astype(np.float64)
    world = new[:3, :3] @ ijk + new[:3, 3:4]
    src = np.linalg.solve(affine[:3, :3], world - affine[:3, 3:4])
    values = ndimage.map_coordinates(
        data.astype(np.float32), src, order=1, mode="constant", cval=fill, prefilter=False
    )
    return values.reshape(shape).astype(data.dtype), new


def write_nifti(path: Path, data: np.ndarray, affine: np.ndarray) -> Path:
    import nibabel as nib

    img = nib.Nifti1Image(data, affine)
    img.set_sform(affine, code=1)
    img.set_qform(affine, code=1)
    nib.save(img, str(path))
    return path


def write_nrrd_lps(path: Path, data: np.ndarray, affine_ras: np.ndarray) -> Path:
    import nrrd

    lps = np.diag([-1.0, -1.0, 1.0, 1.0]) @ affine_ras
    header = {
        "space": "left-posterior-superior",
        "space directions": lps[:3, :3].T,  # one row per index axis
        "space origin": lps[:3, 3],
        "kinds": ["domain"] * 3,
    }
    nrrd.write(str(path), data, header, index_order="F")
    return path


def write_dicom_series(
    folder: Path, data: np.ndarray, affine_ras: np.ndarray, modality: str = "CT"
) -> Path:
    """Axial slices ``data[:, :, k]`` (LPS index axes) as one series, shuffled names.

    Values are stored as uint16 with RescaleIntercept = min(data) (so CT HU survive).
    """
    from pydicom.dataset import FileDataset, FileMetaDataset
    from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid

    folder.mkdir(parents=True, exist_ok=True)
    lps = np.diag([-1.0, -1.0, 1.0, 1.0]) @ affine_ras
    sp = np.linalg.norm(lps[:3, :3], axis=0)
    row_dir, col_dir = lps[:3, 0] / sp[0], lps[:3, 1] / sp[1]
    intercept = int(np.floor(data.min()))
    names = np.random.default_rng(0).permutation(data.shape[2])
    series = generate_uid()
    for k in range(data.shape[2]):
        meta = FileMetaDataset()
        meta.MediaStorageSOPClassUID = CTImageStorage
        meta.MediaStorageSOPInstanceUID = generate_uid()
        meta.TransferSyntaxUID = ExplicitVRLittleEndian
        path = folder / f"IM{names[k]:04d}.dcm"
        ds = FileDataset(str(path), {}, file_meta=meta, preamble=b"\0" * 128)
        ds.SOPClassUID = CTImageStorage
        ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
        ds.StudyInstanceUID = "1.2.3"
        ds.SeriesInstanceUID = series
        ds.Modality = modality
        ds.InstanceNumber = k + 1
        ds.ImagePositionPatient = [float(v) for v in lps[:3, :3] @ [0, 0, k] + lps[:3, 3]]
        ds.ImageOrientationPatient = [float(v) for v in (*row_dir, *col_dir)]
        ds.PixelSpacing = [float(sp[1]), float(sp[0])]  # row spacing, column spacing
        ds.SliceThickness = float(sp[2])
        ds.Rows, ds.Columns = data.shape[1], data.shape[0]
        ds.SamplesPerPixel = 1
        ds.PhotometricInterpretation = "MONOCHROME2"
        ds.BitsAllocated = ds.BitsStored = 16
        ds.HighBit = 15
        ds.PixelRepresentation = 0
        ds.RescaleSlope = 1
        ds.RescaleIntercept = intercept
        stored = (data[:, :, k].T.astype(np.int64) - intercept).astype("<u2")
        ds.PixelData = stored.tobytes()
        ds.save_as(path, enforce_file_format=True)
    return folder


def write_layouts(
    folder: Path,
    data: np.ndarray,
    affine_ras: np.ndarray,
    *,
    oblique_fill: float | None = None,
    modality: str = "CT",
) -> dict[str, Path]:
    """Write the scan (RAS order, RAS affine) in every layout; returns name -> path."""
    folder.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    for name, code in AXIS_LAYOUTS.items():
        arr, aff = relayout(data, affine_ras, code)
        if name == "lps_nrrd":
            paths[name] = write_nrrd_lps(folder / "scan_lps.nrrd", arr, aff)
        elif name == "dicom":
            paths[name] = write_dicom_series(folder / "dicom", arr, aff, modality)
        else:
            paths[name] = write_nifti(folder / f"scan_{name}.nii.gz", arr, aff)
    fill = float(data.min()) if oblique_fill is None else oblique_fill
    arr, aff = oblique(data, affine_ras, fill)
    paths["oblique"] = write_nifti(folder / "scan_oblique.nii.gz", arr, aff)
    return paths
