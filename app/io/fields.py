"""Displacement field and transform files: what registration tools write, read and written.

Conventions (ITK, ANTs, SimpleITK, Slicer)
------------------------------------------
A displacement field is a **pull-back** map: a point ``p`` of the fixed image samples the
moving image at ``p + u(p)``. ITK keeps points and vectors in **LPS** mm; voxwarp's world
is RAS, so both the grid's affine and the vectors are converted on reading (x and y
negated) and back on writing. :class:`~voxwarp.deform.fields.displacement.DisplacementFieldWarp`
then renders the moving volume through the field without resampling it.

Formats (by suffix):

* ``.nii``/``.nii.gz``: a 5-D (x, y, z, 1, 3) or 4-D (x, y, z, 3) image. Intent
  ``vector`` (1007) holds LPS vectors as ITK and ANTs write them; intent ``dispvect``
  (1006) holds RAS vectors (ITK converts those, as voxwarp does). Any other 4-D image
  needs ``convention=``. The grid comes from the sform/qform (nibabel's precedence).
* ``.nrrd``/``.nhdr``: a 3-component ``vector`` axis plus three domain axes; vectors in
  the header's ``space`` (RAS, LPS, LAS), through its ``measurement frame`` if any.
  Detached data only beside the header, as for volumes.
* ``.mha``/``.mhd``: MetaImage vector image (LPS), read by SimpleITK (``registration``
  extra); a ``.mhd``'s data file must lie in its folder or an allowed one.
* ``.h5``/``.hdf5``/``.tfm``/``.txt``/``.mat``: ITK transform files (SimpleITK; ANTs
  writes its affine as ``0GenericAffine.mat``): a
  ``DisplacementFieldTransform``, a ``BSplineTransform`` (sampled to a field over its
  domain), linear transforms, or a ``CompositeTransform`` of them (ANTs'
  ``Composite.h5``). :func:`load_transform` returns the chain in voxwarp's order.
* ``.npz``: ``displacement`` (nx, ny, nz, 3), ``affine`` (4x4) and optional ``space``
  (``"RAS"`` default, or ``"LPS"``) and ``units`` (``"mm"``, or ``"voxel"``).

``convention=`` says what vectors of a file without that information mean: ``"itk"``
(LPS mm), ``"ras"`` (RAS mm) or ``"voxel"`` (index units of the field's grid, as
voxelmorph's spatial transformer; its grid axes give the directions).

Writing (:func:`save_displacement_field`) always uses the ITK convention, so that
``SimpleITK.DisplacementFieldTransform`` on the written image, ANTs'
``antsApplyTransforms`` or Slicer reproduce voxwarp's deformation.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.core import extras
from voxwarp.core import limits as _limits
from voxwarp.core.files import atomic_output, ensure_room
from voxwarp.core.input_files import check_regular
from voxwarp.core.orientation import PATIENT_SPACES
from voxwarp.deform.fields.displacement import DisplacementFieldWarp, set_field_reader
from voxwarp.deform.warp import AffineWarp, Warp, WarpError
from voxwarp.errors import FieldError, VolumeError
from voxwarp.io.inflation import check_inflation
from voxwarp.io.itk_probe import probe_binary_transform
from voxwarp.io.loaded import native_stderr, quiet_nibabel, warn
from voxwarp.io.metaimage import check_mhd_data_file
from voxwarp.io.transform_sizes import check_transform_text
from voxwarp.io.volumes import (
    _check_nrrd_budget,
    _check_nrrd_data_files,
    _nifti_affine,
    _nrrd_space,
)

#: Suffixes of displacement field images.
IMAGE_SUFFIXES = (".nii", ".nii.gz", ".nrrd", ".nhdr", ".mha", ".mhd", ".npz")
#: Suffixes of ITK transform files.
TRANSFORM_SUFFIXES = (".h5", ".hdf5", ".tfm", ".txt", ".mat")
#: What a file's vectors mean when its header does not say (see the module docstring).
CONVENTIONS = ("itk", "ras", "voxel")
#: Most nodes per axis when a B-spline transform is sampled to a field.
MAX_BSPLINE_SAMPLES = 128
_FLIP = np.array([-1.0, -1.0, 1.0])
_LPS = np.diag([-1.0, -1.0, 1.0, 1.0])


def field_suffix(path: str | os.PathLike[str]) -> str:
    """The format suffix of ``path`` (``".nii.gz"`` counts as one), lower case."""
    name = Path(path).name.lower()
    return ".nii.gz" if name.endswith(".nii.gz") else Path(name).suffix


def _checked_path(path: str | os.PathLike[str]) -> Path:
    p = Path(path)
    if not p.exists():
        raise FieldError(f"no such displacement field or transform file: {p}")
    check_regular(p, "the field or transform file", FieldError)
    suffix = field_suffix(p)
    if suffix not in IMAGE_SUFFIXES + TRANSFORM_SUFFIXES:
        raise FieldError(
            f"{p.name}: unknown displacement field format {suffix or '(no suffix)'};"
            f" use one of {', '.join(IMAGE_SUFFIXES + TRANSFORM_SUFFIXES)}"
        )
    return p


def load_transform(path: str | os.PathLike[str], *, convention: str | None = None) -> list[Warp]:
    """Read a field image or an ITK transform file as a chain of warps (voxwarp's order).

    A field image gives one :class:`DisplacementFieldWarp`; a transform file gives one
    warp per transform it holds (a composite's last-added transform first, as ITK
    applies them). Put the result in a scene's ``warps``. Raises :class:`FieldError`.
    """
    p = _checked_path(path)
    if field_suffix(p) in TRANSFORM_SUFFIXES:
        return _read_transform_file(p)
    return [load_displacement_field(p, convention=convention)]


def _check_file_budget(path: Path) -> None:
    """Refuse a file larger than the memory budget before a library reads all of it."""
    try:
        _limits.check_load_bytes((path.stat().st_size,), 1, path.name)
    except VolumeError as exc:
        raise FieldError(str(exc)) from exc


def load_displacement_field(
    path: str | os.PathLike[str], *, convention: str | None = None, part: int | None = None
) -> DisplacementFieldWarp:
    """Read one displacement field (see the module docstring for formats and conventions).

    ``part`` picks the non-linear transform of that index in a transform file's chain
    (as :func:`load_transform` orders it); a file holding one needs none.
    Raises :class:`FieldError` with a one-line message.
    """
    if convention is not None and convention not in CONVENTIONS:
        raise FieldError(f"convention must be one of {list(CONVENTIONS)}; got {convention!r}")
    p = _checked_path(path)
    suffix = field_suffix(p)
    try:
        if suffix in TRANSFORM_SUFFIXES:
            return _field_of_transform(p, part)
        reader = {".npz": _read_npz, ".nrrd": _read_nrrd, ".nhdr": _read_nrrd}.get(suffix)
        if reader is not None:
            u, affine, space, units = reader(p, convention)
        elif suffix in (".mha", ".mhd"):
            u, affine, space, units = _read_metaimage(p)
        else:
            u, affine, space, units = _read_nifti(p, convention)
        return DisplacementFieldWarp(u, affine, space=space, units=units, path=str(p))
    except WarpError as exc:
        raise FieldError(f"{p.name}: {exc}") from exc
    except VolumeError as exc:  # over the memory budget
        raise FieldError(str(exc)) from exc


def _read_field_entry(path: str, part: int | None = None) -> DisplacementFieldWarp:
    """The reader of scene entries (``{"type": "displacement_field", "path": ...}``)."""
    return load_displacement_field(path, part=part)


set_field_reader(_read_field_entry)


def _convention(convention: str | None, default: str | None, where: str) -> tuple[str, str]:
    """``(space, units)`` of a file's vectors from the caller's or the header's convention."""
    chosen = convention or default
    if chosen is None:
        raise FieldError(
            f"{where} does not say what its vectors mean; for a displacement field pass"
            " --field-convention (convention= in Python) itk (LPS mm, as ITK/ANTs write), ras"
            " (RAS mm) or voxel (voxelmorph); for a volume of 3 time points or channels pick"
            " one with --frame-index or --channel"
        )
    return {"itk": ("LPS", "mm"), "ras": ("RAS", "mm"), "voxel": ("RAS", "voxel")}[chosen]


# ---------------------------------------------------------------------------- NIfTI
def _read_nifti(path: Path, convention: str | None) -> tuple[np.ndarray, Any, str, str]:
    with quiet_nibabel() as said:  # nibabel's log lines: one warning each, or the error
        out = _read_nifti_quiet(path, convention)
    for line in said:
        warn(f"{path.name}: {line} (nibabel); fix the header")
    return out


def _read_nifti_quiet(path: Path, convention: str | None) -> tuple[np.ndarray, Any, str, str]:
    import nibabel as nib

    try:
        img = nib.load(str(path))
        shape = tuple(int(s) for s in img.shape)
        hdr = img.header
        intent = int(hdr["intent_code"]) if "intent_code" in hdr else 0
    except Exception as exc:
        raise FieldError(f"cannot read the NIfTI field {path}: {exc}") from exc
    if len(shape) == 5 and shape[3] == 1:
        grid = shape[:3]
    elif len(shape) == 4:
        grid = shape[:3]
    else:
        raise FieldError(
            f"{path.name} has shape {shape}; a displacement field is (x, y, z, 1, 3) as ITK"
            " writes it, or (x, y, z, 3)"
        )
    if shape[-1] != 3:
        raise FieldError(
            f"{path.name} has {shape[-1]} components per voxel; a 3-D displacement field"
            " needs 3 (x, y, z)"
        )
    default = {1007: "itk", 1006: "ras"}.get(intent)
    space, units = _convention(convention, default, path.name)
    affine = _nifti_affine(hdr, path.name)
    if affine is None:
        raise FieldError(
            f"{path.name} has no sform or qform, so the field's grid has no place in patient"
            " space; write it with a coded sform (nibabel: img.header.set_sform(affine, 1))"
        )
    _limits.check_load_bytes((*grid, 3), 4, path.name)
    if field_suffix(path) == ".nii.gz":
        need = int(np.prod(shape, dtype=np.float64)) * int(hdr.get_data_dtype().itemsize)
        check_inflation(need, path.stat().st_size, path.name)
    try:
        data = np.asarray(img.dataobj, dtype=np.float32).reshape(*grid, 3, order="F")
    except Exception as exc:
        raise FieldError(f"cannot read the vectors of {path}: {exc} (truncated?)") from exc
    ras_affine = affine  # nibabel's affine is RAS
    return data, (_LPS @ ras_affine if space == "LPS" else ras_affine), space, units


# ---------------------------------------------------------------------------- NRRD
def _read_nrrd(path: Path, convention: str | None) -> tuple[np.ndarray, Any, str, str]:
    import nrrd

    try:
        _check_nrrd_data_files(path)
        _check_nrrd_budget(path)
    except VolumeError as exc:
        raise FieldError(str(exc)) from exc
    _check_nrrd_inflation(path)
    try:
        data, header = nrrd.read(str(path), index_order="F")
    except Exception as exc:
        raise FieldError(f"cannot read the NRRD field {path}: {exc}") from exc
    space = _nrrd_space(header, path.name)
    if space is None:
        raise FieldError(
            f"{path.name} has no patient 'space' (RAS, LPS or LAS), so its vectors and grid"
            " cannot be placed; write it with space: left-posterior-superior"
        )
    vec_axis = _nrrd_vector_axis(data.shape, header, path.name)
    data = np.moveaxis(np.asarray(data, dtype=np.float32), vec_axis, -1)
    affine = _nrrd_field_affine(header, vec_axis, path.name)
    frame = header.get("measurement frame")
    if frame is not None:  # vectors in the measurement frame -> the header's space
        data = data @ _measurement_frame(frame, path.name).T
    fx, fy = PATIENT_SPACES[space]
    flip = np.array([fx, fy, 1.0, 1.0])
    if convention == "voxel":  # vectors along the grid's index axes: no flip
        return data, np.diag(flip) @ affine, "RAS", "voxel"
    return data * flip[:3].astype(np.float32), np.diag(flip) @ affine, "RAS", "mm"


def _check_nrrd_inflation(path: Path) -> None:
    """A gzip/bzip2 NRRD field's header size against :func:`check_inflation` (the
    stored bytes: the attached file, or its one detached data file)."""
    import nrrd

    try:
        with open(path, "rb") as f:
            header = nrrd.read_header(f)
        sizes = [int(n) for n in header["sizes"]]
        from nrrd.reader import _determine_datatype

        itemsize = int(_determine_datatype(header).itemsize)
    except Exception:
        return  # nrrd.read names what is wrong
    encoding = str(header.get("encoding", "raw")).lower()
    codec = {"gzip": "deflate", "gz": "deflate", "bzip2": "bzip2", "bz2": "bzip2"}.get(encoding)
    if codec is None:
        return
    name = header.get("data file") or header.get("datafile")
    stored = path.parent / str(name) if name else path
    size = stored.stat().st_size if stored.is_file() else path.stat().st_size
    need = int(np.prod(sizes, dtype=np.float64)) * itemsize
    check_inflation(need, size, path.name, codec)


def _nrrd_field_affine(header: dict[str, Any], vec_axis: int, where: str) -> np.ndarray:
    """The 4x4 grid affine (in the header's space) of an NRRD field: ``space
    directions`` of its three domain axes and ``space origin``; one line when damaged."""
    try:
        dirs = np.asarray(header.get("space directions"), dtype=np.float64)
        origin = np.asarray(header.get("space origin", np.zeros(3)), dtype=np.float64)
        domain = [a for a in range(4) if a != vec_axis]
        rows = dirs[domain] if dirs.shape == (4, 3) else None
    except (TypeError, ValueError, IndexError):
        rows = origin = None
    if rows is None or origin is None or origin.shape != (3,):
        raise FieldError(
            f"{where}: damaged 'space directions' or 'space origin'; a field needs 'none' for"
            " its vector axis and three 3-vectors, e.g. space directions: none (1,0,0)"
            " (0,1,0) (0,0,1), and space origin: (0,0,0)"
        )
    if not (np.all(np.isfinite(rows)) and np.all(np.isfinite(origin))):
        raise FieldError(f"{where}: 'space directions'/'space origin' must be finite numbers")
    affine = np.eye(4)
    affine[:3, :3] = rows.T
    affine[:3, 3] = origin
    return affine


def _measurement_frame(frame: Any, where: str) -> np.ndarray:
    """An NRRD ``measurement frame`` as a finite 3x3 matrix; one line otherwise."""
    try:
        m = np.asarray(frame, dtype=np.float32)
    except (TypeError, ValueError):
        m = np.zeros(0)
    if m.shape != (3, 3) or not np.all(np.isfinite(m)):
        raise FieldError(
            f"{where}: its 'measurement frame' must be three finite 3-vectors, e.g."
            " measurement frame: (1,0,0) (0,1,0) (0,0,1)"
        )
    return m


def _nrrd_vector_axis(shape: Sequence[int], header: dict[str, Any], where: str) -> int:
    if len(shape) != 4:
        raise FieldError(
            f"{where} has {len(shape)} axes {tuple(shape)}; a displacement field has a"
            " 3-component vector axis and three domain axes"
        )
    kinds = [str(k).lower() for k in (header.get("kinds") or [])]
    vector_kinds = ("vector", "covariant-vector", "normal", "3-vector", "list")
    for axis, kind in enumerate(kinds):
        if kind in vector_kinds:
            if shape[axis] != 3:
                raise FieldError(
                    f"{where}: its vector axis has {shape[axis]} components; a 3-D"
                    " displacement field needs 3"
                )
            return axis
    raise FieldError(f"{where} has no 'vector' axis (kinds {kinds}); it is not a vector field")


# ---------------------------------------------------------------------------- npz
def _read_npz(path: Path, convention: str | None) -> tuple[np.ndarray, Any, str, str]:
    try:
        with np.load(path, allow_pickle=False) as npz:
            keys = set(npz.files)
            if not {"displacement", "affine"} <= keys:
                raise FieldError(
                    f"{path.name} needs arrays 'displacement' (nx, ny, nz, 3) and 'affine'"
                    f" (4x4); it has {sorted(keys)}"
                )
            _check_npz_member(npz.zip, "displacement.npy", path.name)
            u = np.asarray(npz["displacement"], dtype=np.float32)
            affine = np.asarray(npz["affine"], dtype=np.float64)
            space = str(npz["space"]) if "space" in keys else "RAS"
            units = str(npz["units"]) if "units" in keys else "mm"
    except FieldError:
        raise
    except VolumeError as exc:
        raise FieldError(str(exc)) from exc
    except Exception as exc:
        raise FieldError(f"cannot read the field {path}: {exc}") from exc
    if convention is not None:
        space, units = _convention(convention, None, path.name)
    return u, affine, space, units


def _check_npz_member(archive: Any, member: str, where: str) -> None:
    """The npy header's shape and dtype of ``member`` against the budget, and its
    deflated size against :func:`check_inflation`, before ``np.load`` inflates it."""
    info = archive.getinfo(member)
    _limits.check_load_bytes((info.file_size,), 1, where)
    with archive.open(member) as fh:
        fmt = np.lib.format
        v1 = fmt.read_magic(fh) == (1, 0)
        shape, _, dtype = (fmt.read_array_header_1_0 if v1 else fmt.read_array_header_2_0)(fh)
    if dtype.kind not in "iuf":
        raise FieldError(f"{where}: {member} holds {dtype} values; write real numbers (float32)")
    _limits.check_load_bytes(tuple(shape), max(int(dtype.itemsize), 4), where)
    need = int(np.prod(shape, dtype=np.float64)) * int(dtype.itemsize)
    check_inflation(need, info.compress_size, f"{where} ({member})")


# ---------------------------------------------------------------------------- ITK files
def _sitk(what: str) -> Any:
    extras.require("registration", what)
    import SimpleITK as sitk

    return sitk


def _check_metaimage_inflation(path: Path, values: int) -> None:
    """A compressed MetaImage's ``values`` (header size, float32 at least) against
    :func:`check_inflation` of its stored bytes (the ``.mha``, or the ``.mhd``'s data)."""
    with open(path, "rb") as fh:
        head = fh.read(1 << 16).decode("ascii", "ignore")
    tags = {
        k.strip(): v.strip() for k, sep, v in (x.partition("=") for x in head.splitlines()) if sep
    }
    if tags.get("CompressedData", "").lower() != "true":
        return
    name = tags.get("ElementDataFile", "LOCAL")
    stored = path if name.upper() == "LOCAL" else path.parent / name
    if stored.is_file():  # a missing data file: SimpleITK's read names it
        check_inflation(values * 4, stored.stat().st_size, path.name)


def _sitk_field(image: Any, where: str) -> tuple[np.ndarray, np.ndarray]:
    """Vectors (nx, ny, nz, 3) and LPS affine of a SimpleITK vector image."""
    if image.GetDimension() != 3 or image.GetNumberOfComponentsPerPixel() != 3:
        raise FieldError(
            f"{where} is a {image.GetDimension()}-D image with"
            f" {image.GetNumberOfComponentsPerPixel()} components; a displacement field is"
            " 3-D with 3 components"
        )
    sitk = _sitk(where)
    arr = sitk.GetArrayViewFromImage(image)  # (z, y, x, 3)
    u = np.ascontiguousarray(np.asarray(arr, dtype=np.float32).transpose(2, 1, 0, 3))
    return u, itk_affine(image)


def itk_affine(image: Any) -> np.ndarray:
    """The 4x4 index -> LPS world matrix of a SimpleITK image (spacing, direction, origin)."""
    a = np.eye(4)
    d = np.asarray(image.GetDirection(), dtype=np.float64).reshape(3, 3)
    a[:3, :3] = d * np.asarray(image.GetSpacing(), dtype=np.float64)
    a[:3, 3] = image.GetOrigin()
    return a


def _read_metaimage(path: Path) -> tuple[np.ndarray, Any, str, str]:
    sitk = _sitk(f"reading the MetaImage field {path.name}")
    if field_suffix(path) == ".mhd":
        check_mhd_data_file(path, FieldError)
    with native_stderr() as said:
        try:
            reader = sitk.ImageFileReader()
            reader.SetFileName(str(path))
            reader.ReadImageInformation()
            size = reader.GetSize()
            comps = reader.GetNumberOfComponents()
            _limits.check_load_bytes((*size, comps), 4, path.name)
            _check_metaimage_inflation(path, int(np.prod([*size, comps], dtype=np.float64)))
            image, error = reader.Execute(), None
        except RuntimeError as exc:
            image, error = None, exc
    if error is not None:
        raise FieldError(
            f"cannot read the MetaImage field {path}: {_library_reason(said, error)}"
        ) from error
    u, affine = _sitk_field(image, path.name)
    return u, affine, "LPS", "mm"


def _library_reason(said: list[str], exc: BaseException) -> str:
    """The most telling line of what ITK/HDF5 printed (held back) or raised."""
    for line in reversed(said):
        if "():" in line:  # an HDF5 stack entry: "... in H5F__super_read(): truncated file"
            return line.split("():", 1)[1].strip()
    return _first_line(exc)


def _first_line(exc: BaseException) -> str:
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    return lines[-1] if lines else type(exc).__name__


def _read_transform_file(path: Path) -> list[Warp]:
    sitk = _sitk(f"reading the ITK transform file {path.name}")
    _check_file_budget(path)
    check_transform_text(path)  # the grid its FixedParameters imply, before ITK allocates it
    if field_suffix(path) in (".h5", ".hdf5", ".mat"):
        probe_binary_transform(sitk, path)  # binary: a forked child reads it first
    with native_stderr() as said:
        try:
            transform = sitk.ReadTransform(str(path))
        except RuntimeError as exc:
            transform, error = None, exc
    if transform is None:
        raise FieldError(
            f"cannot read the ITK transform {path}: damaged, truncated or not an ITK"
            f" transform file ({_library_reason(said, error)})"
        ) from error
    parts = _flatten(sitk, transform)
    warps: list[Warp] = []
    fields = 0
    for t in reversed(parts):  # ITK applies a composite's last-added transform first
        warps.append(_warp_of(sitk, t, path, fields))
        fields += isinstance(warps[-1], DisplacementFieldWarp)
    return warps


def _flatten(sitk: Any, transform: Any) -> list[Any]:
    """The transforms of a (nested) composite in the order they were added."""
    if transform.GetName() != "CompositeTransform":
        return [transform]
    comp = sitk.CompositeTransform(transform)
    out: list[Any] = []
    for i in range(comp.GetNumberOfTransforms()):
        out += _flatten(sitk, comp.GetNthTransform(i))
    return out


def _warp_of(sitk: Any, t: Any, path: Path, index: int) -> Warp:
    name = t.GetName()
    if t.GetDimension() != 3:
        raise FieldError(f"{path.name} holds a {t.GetDimension()}-D {name}; voxwarp needs 3-D")
    if name == "DisplacementFieldTransform":
        u, affine = _sitk_field(
            sitk.DisplacementFieldTransform(t).GetDisplacementField(), path.name
        )
    elif name == "BSplineTransform":
        u, affine = _sample_bspline(sitk, sitk.BSplineTransform(t))
    elif t.IsLinear():
        return AffineWarp(_inverse(_linear_ras(t), f"{path.name} ({name})"))
    else:
        raise FieldError(
            f"{path.name} holds a {name}, which voxwarp cannot render; convert it to a"
            " displacement field (SimpleITK.TransformToDisplacementField)"
        )
    try:
        return DisplacementFieldWarp(u, affine, space="LPS", path=str(path), part=index)
    except WarpError as exc:
        raise FieldError(f"{path.name}: {exc}") from exc


def _inverse(m: np.ndarray, where: str) -> np.ndarray:
    """The inverse of a linear transform's matrix ``m``; one line when it has none."""
    inv = None
    if np.all(np.isfinite(m)) and abs(np.linalg.det(m[:3, :3])) > 1e-12 * max(
        1.0, float(np.abs(m[:3, :3]).max()) ** 3
    ):
        try:
            inv = np.linalg.inv(m)
        except np.linalg.LinAlgError:
            inv = None
    if inv is None or not np.all(np.isfinite(inv)):
        raise FieldError(
            f"{where}: its matrix is singular or not finite (it flattens space), so it"
            " cannot be rendered; check the transform's Parameters"
        )
    return inv


def _linear_ras(t: Any) -> np.ndarray:
    """The 4x4 RAS matrix of a linear ITK transform (fixed -> moving point map)."""
    origin = np.zeros(3)
    m = np.eye(4)
    m[:3, 3] = t.TransformPoint(tuple(origin))
    for a in range(3):
        e = np.zeros(3)
        e[a] = 1.0
        m[:3, a] = np.asarray(t.TransformPoint(tuple(e))) - m[:3, 3]
    return _LPS @ m @ _LPS


def _sample_bspline(sitk: Any, t: Any) -> tuple[np.ndarray, np.ndarray]:
    """A B-spline transform as a field over its domain, ~4 samples per control-point
    spacing (at most :data:`MAX_BSPLINE_SAMPLES` per axis), in LPS."""
    origin = np.asarray(t.GetTransformDomainOrigin(), float)
    extent = np.asarray(t.GetTransformDomainPhysicalDimensions(), float)
    direction = np.asarray(t.GetTransformDomainDirection(), float).reshape(3, 3)
    mesh = np.asarray(t.GetTransformDomainMeshSize(), float)
    n = np.clip(np.ceil(4 * mesh).astype(int) + 1, 2, MAX_BSPLINE_SAMPLES)
    spacing = extent / (n - 1)
    ref = sitk.Image([int(v) for v in n], sitk.sitkUInt8)
    ref.SetOrigin(origin.tolist())
    ref.SetSpacing(spacing.tolist())
    ref.SetDirection(direction.ravel().tolist())
    field = sitk.TransformToDisplacementField(
        t,
        sitk.sitkVectorFloat64,
        ref.GetSize(),
        ref.GetOrigin(),
        ref.GetSpacing(),
        ref.GetDirection(),
    )
    return _sitk_field(field, "the B-spline transform")


def _field_of_transform(path: Path, part: int | None) -> DisplacementFieldWarp:
    fields = [w for w in _read_transform_file(path) if isinstance(w, DisplacementFieldWarp)]
    if not fields:
        raise FieldError(f"{path.name} holds no displacement field or B-spline transform")
    if part is None and len(fields) > 1:
        raise FieldError(
            f"{path.name} holds {len(fields)} non-linear transforms; load them all with"
            " voxwarp.load_transform (render --displacement does)"
        )
    i = 0 if part is None else int(part)
    if not 0 <= i < len(fields):
        raise FieldError(f"{path.name} has no non-linear transform number {i}")
    return fields[i]


# ---------------------------------------------------------------------------- writing
#: Bytes of an ITK ``.h5`` transform beside its float64 vectors (measured: 8.4 KiB), with margin.
H5_HEADER_BYTES = 64 * 1024

#: Suffixes :func:`save_displacement_field` writes.
WRITE_SUFFIXES = (".nii", ".nii.gz", ".nrrd", ".mha", ".h5", ".npz")


def save_displacement_field(
    field: DisplacementFieldWarp,
    path: str | os.PathLike[str],
    metadata: Mapping[str, str] | None = None,
) -> Path:
    """Write ``field`` in the ITK convention (LPS vectors, pull-back), atomically.

    The format follows the suffix (:data:`WRITE_SUFFIXES`): NIfTI (5-D, intent vector,
    as SimpleITK writes), NRRD (space left-posterior-superior), MetaImage and ITK
    ``.h5`` transform (``registration`` extra), or ``.npz`` (voxwarp's arrays, RAS).
    ``metadata`` (e.g. :meth:`voxwarp.core.field_grid.FieldExport.metadata`) is
    recorded with keys prefixed ``voxwarp_``: NRRD fields, MetaImage tags, ``.npz``
    entries, and ``key=value`` pairs in a NIfTI's ``descrip`` (80 characters); an
    ``.h5`` transform has no place for it.
    Returns the path. Raises :class:`FieldError` or :class:`~voxwarp.errors.OutputError`.
    """
    final = Path(path)
    suffix = field_suffix(final)
    if suffix not in WRITE_SUFFIXES:
        raise FieldError(
            f"cannot write a displacement field as {suffix or '(no suffix)'}; use one of"
            f" {', '.join(WRITE_SUFFIXES)}"
        )
    if suffix in (".mha", ".h5"):
        _sitk(f"writing {final.name}")
    if suffix == ".h5":  # HDF5 crashes at exit after running out of room: check first
        ensure_room(final, int(np.prod(field.shape)) * 3 * 8 + H5_HEADER_BYTES)
    writer = {
        ".nii": _write_nifti,
        ".nii.gz": _write_nifti,
        ".nrrd": _write_nrrd,
        ".mha": _write_sitk,
        ".h5": _write_sitk,
        ".npz": _write_npz,
    }[suffix]
    notes = {f"voxwarp_{k}": str(v) for k, v in (metadata or {}).items()}
    with atomic_output(final, suffix) as tmp:
        writer(field, tmp, notes)
    return final


def _lps(field: DisplacementFieldWarp) -> tuple[np.ndarray, np.ndarray]:
    """Vectors and affine of ``field`` in LPS (ITK's physical space)."""
    return field.displacements * _FLIP.astype(np.float32), _LPS @ field.affine


def _write_nifti(field: DisplacementFieldWarp, tmp: Path, notes: Mapping[str, str]) -> None:
    import nibabel as nib

    u_lps, _ = _lps(field)
    img = nib.Nifti1Image(u_lps[:, :, :, None, :].astype(np.float32, copy=False), field.affine)
    if notes:
        pairs = " ".join(f"{k.removeprefix('voxwarp_')}={v}" for k, v in notes.items())
        img.header["descrip"] = f"voxwarp {pairs}"[:79].encode("ascii", "replace")
    img.header.set_intent("vector")
    img.header.set_sform(field.affine, code=1)
    img.header.set_qform(field.affine, code=1)
    img.header.set_xyzt_units("mm")
    nib.save(img, str(tmp))


def _write_nrrd(field: DisplacementFieldWarp, tmp: Path, notes: Mapping[str, str]) -> None:
    import nrrd

    u_lps, a = _lps(field)
    header = {
        "kinds": ["vector", "domain", "domain", "domain"],
        "space": "left-posterior-superior",
        "space directions": np.vstack([np.full(3, np.nan), a[:3, :3].T]),
        "space origin": a[:3, 3],
        "encoding": "gzip",
        **notes,
    }
    nrrd.write(str(tmp), np.moveaxis(u_lps, -1, 0), header, index_order="F")


def field_image(field: DisplacementFieldWarp) -> Any:
    """``field`` as a SimpleITK vector image (LPS vectors and geometry, float64)."""
    sitk = _sitk("a SimpleITK field image")
    u_lps, a = _lps(field)
    img = sitk.GetImageFromArray(u_lps.transpose(2, 1, 0, 3).astype(np.float64), isVector=True)
    spacing = np.linalg.norm(a[:3, :3], axis=0)
    img.SetSpacing(spacing.tolist())
    img.SetDirection((a[:3, :3] / spacing).ravel().tolist())
    img.SetOrigin(a[:3, 3].tolist())
    return img


def _write_sitk(field: DisplacementFieldWarp, tmp: Path, notes: Mapping[str, str]) -> None:
    sitk = _sitk(f"writing {tmp.name}")
    img = field_image(field)
    for key, value in notes.items():
        img.SetMetaData(key, value)
    # HDF5 and MetaImage print their own diagnostics (23-54 lines on a full disk): hold
    # them back and report one line (atomic_output words it with the path and the fix)
    with native_stderr() as said:
        try:
            if field_suffix(tmp) == ".h5":
                sitk.WriteTransform(sitk.DisplacementFieldTransform(img), str(tmp))
            else:
                sitk.WriteImage(img, str(tmp), True)
        except RuntimeError as exc:
            error: RuntimeError | None = exc
        else:
            error = None
    if error is not None:
        raise OSError(_library_reason(said, error)) from error


def _write_npz(field: DisplacementFieldWarp, tmp: Path, notes: Mapping[str, str]) -> None:
    extra = {k: np.str_(v) for k, v in notes.items()}
    with open(tmp, "wb") as fh:
        np.savez_compressed(
            fh,
            displacement=field.displacements,
            affine=field.affine,
            space=np.str_("RAS"),
            units=np.str_("mm"),
            **extra,
        )


# ---------------------------------------------------------------------------- info
def is_field_file(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` holds a displacement field or transform rather than a volume:
    an ITK transform file, a vector NIfTI/NRRD/MetaImage, or an ``.npz`` with a
    ``displacement`` array (headers only are read)."""
    p = Path(path)
    suffix = field_suffix(p)
    if not p.is_file() or suffix not in IMAGE_SUFFIXES + TRANSFORM_SUFFIXES:
        return False
    if suffix in TRANSFORM_SUFFIXES:
        return True
    try:
        if suffix == ".npz":
            with np.load(p, allow_pickle=False) as npz:
                return "displacement" in npz.files
        if suffix in (".nii", ".nii.gz"):
            import nibabel as nib

            with quiet_nibabel():
                hdr = nib.load(str(p)).header
            shape = hdr.get_data_shape()
            vector_intent = int(hdr["intent_code"]) in (1006, 1007)
            itk_layout = len(shape) == 5 and shape[3] == 1  # (x, y, z, 1, c): ITK vectors
            return vector_intent or itk_layout or (len(shape) == 4 and shape[-1] == 3)
        if suffix in (".nrrd", ".nhdr"):
            import nrrd

            header = nrrd.read_header(str(p))
            return any(
                str(k).lower() in ("vector", "covariant-vector", "3-vector")
                for k in header.get("kinds") or []
            )
        with open(p, "rb") as fh:  # MetaImage: a header line says the channels
            return b"ElementNumberOfChannels = 3" in fh.read(1 << 16)
    except Exception:
        return False


def field_info(warp: Warp) -> dict[str, Any]:
    """JSON-ready facts about one warp read from a field or transform file."""
    if not isinstance(warp, DisplacementFieldWarp):
        m = warp.affine_matrix().tolist() if warp.is_affine else None
        return {"type": warp.kind, "matrix_fixed_to_moving_ras": m}
    lo, hi = warp.support_bounds()
    return {
        "type": warp.kind,
        "shape": list(warp.shape),
        "spacing": warp.spacing.tolist(),
        "affine_ras": warp.affine.tolist(),
        "support_ras": [lo.tolist(), hi.tolist()],
        "max_displacement_mm": warp.max_displacement(),
        "mean_displacement_mm": float(warp.magnitude().mean()),
    }


def field_summary(warps: Sequence[Warp]) -> str:
    """Lines describing a chain read from a field or transform file (``voxwarp info``)."""
    lines = []
    if len(warps) > 1:
        lines.append(f"{len(warps)} transforms, applied in this order to a fixed point:")
    for i, w in enumerate(warps):
        if isinstance(w, DisplacementFieldWarp):
            lo, hi = w.support_bounds()
            lines += [
                f"[{i}] displacement field (ITK pull-back), {w.shape[0]}x{w.shape[1]}x"
                f"{w.shape[2]} nodes, spacing {np.round(w.spacing, 4).tolist()} mm",
                f"    grid covers RAS {np.round(lo, 2).tolist()} .. {np.round(hi, 2).tolist()} mm",
                f"    |u| max {w.max_displacement():.3g} mm, mean {w.magnitude().mean():.3g} mm",
            ]
        else:
            m = np.round(w.affine_matrix(), 5).tolist() if w.is_affine else None
            lines.append(f"[{i}] {w.kind} warp (fixed -> moving, RAS): {m}")
    return "\n".join(lines)
