"""MetaImage volumes (``.mha``, ``.mhd``) read by SimpleITK (the ``registration`` extra).

The image goes through :func:`voxwarp.io.image_objects.sitk_loaded`, so a 4-D or
multi-component file offers its time points and channels as a SimpleITK image does. A
``.mhd``'s data file must lie in the header's folder or an allowed folder
(:func:`check_mhd_data_file`, shared with the field reader).
"""

from __future__ import annotations

from pathlib import Path

from voxwarp.core import extras
from voxwarp.core import limits as _limits
from voxwarp.core.allowed_folders import allow_hint, outside_allowed
from voxwarp.core.input_files import check_regular
from voxwarp.errors import VolumeError, VoxwarpError
from voxwarp.io.image_objects import sitk_loaded
from voxwarp.io.loaded import Loaded, native_stderr

#: Suffixes read here.
METAIMAGE_SUFFIXES = (".mha", ".mhd")


def mhd_data_file(path: Path) -> str | None:
    """The ``ElementDataFile`` a ``.mhd`` header names (``"LOCAL"``: in the header
    itself), or None when its first 64 KiB name none."""
    with open(path, "rb") as fh:
        head = fh.read(1 << 16).decode("ascii", "ignore")
    for line in head.splitlines():
        key, sep, value = line.partition("=")
        if sep and key.strip() == "ElementDataFile":
            return value.strip()
    return None


def check_mhd_data_file(path: Path, error: type[VoxwarpError]) -> None:
    """Refuse (``error``, one line) a ``.mhd`` whose ``ElementDataFile`` is a list or a
    pattern, lies outside the header's folder (and subfolders) and the allowed folders
    (:mod:`voxwarp.core.allowed_folders`) once links are resolved, or is not a regular
    file: the rule of NRRD's detached data, for volumes and fields alike."""
    name = mhd_data_file(path)
    if name is None or name.upper() == "LOCAL":
        return
    if name.upper().startswith("LIST") or any(c in name for c in "%\x00"):
        raise error(
            f"{path.name} names the data file {name!r}; voxwarp reads a MetaImage's data"
            " only from one file (not a list or a pattern): join the data into one file"
        )
    target = (path.parent / name).resolve()
    if outside_allowed(target, path.parent):
        raise error(
            f"{path.name} names the data file {name!r} ({target}), outside the header's"
            f" folder; move the data beside the header, or allow its folder: {allow_hint(target)}"
        )
    check_regular(target, f"{path.name}'s data file", error)


def read_metaimage(path: Path) -> Loaded:
    """A MetaImage file as a :class:`Loaded` (LPS geometry converted to RAS)."""
    extras.require("registration", f"reading the MetaImage {path.name}")
    import SimpleITK as sitk

    if path.suffix.lower() == ".mhd":
        check_mhd_data_file(path, VolumeError)
    with native_stderr() as said:
        try:
            reader = sitk.ImageFileReader()
            reader.SetFileName(str(path))
            reader.ReadImageInformation()
            size = (*reader.GetSize(), reader.GetNumberOfComponents())
            _limits.check_load_bytes(size, 4, path.name)
            image, error = reader.Execute(), None
        except RuntimeError as exc:
            image, error = None, exc
    if error is not None:
        reason = " ".join(said).strip() or str(error).strip().splitlines()[-1]
        raise VolumeError(f"cannot read the MetaImage {path}: {reason}") from error
    failed = [line for line in said if "fail" in line.lower()]
    if failed:  # MetaIO says so on stderr and returns the undecoded bytes as voxels
        raise VolumeError(
            f"cannot read the MetaImage {path}: {' '.join(failed).strip()} (a header that"
            " says CompressedData = True over data that is not zlib-compressed, or damaged"
            " data): fix the header or the data file"
        )
    return sitk_loaded(image)
