"""MetaImage volumes (``.mha``, ``.mhd``) read by SimpleITK (the ``registration`` extra).

The image goes through :func:`voxwarp.io.image_objects.sitk_loaded`, so a 4-D or
multi-component file offers its time points and channels as a SimpleITK image does. A
``.mhd`` must keep its data file beside it (a plain name, not a path or a list).
"""

from __future__ import annotations

from pathlib import Path

from voxwarp.core import extras
from voxwarp.core import limits as _limits
from voxwarp.core.input_files import check_regular
from voxwarp.errors import VolumeError
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


def _check_data_file(path: Path) -> None:
    """Refuse a ``.mhd`` whose ``ElementDataFile`` is not a plain name beside it."""
    name = mhd_data_file(path)
    if name is None or name.upper() == "LOCAL":
        return
    plain = Path(name).name == name and not any(c in name for c in "%\x00")
    if not plain or name.upper().startswith("LIST"):
        raise VolumeError(
            f"{path.name} names the data file {name!r}; voxwarp reads a MetaImage's data"
            " only from one file beside the header: move it there and name it plainly"
        )
    _check_beside(path, name)


def _check_beside(path: Path, name: str) -> None:
    """The data file ``name`` of the header ``path``: inside the header's folder once
    symlinks are resolved, and a regular file (a FIFO would block the read forever)."""
    target = (path.parent / name).resolve()
    if not target.is_relative_to(path.parent.resolve()):
        raise VolumeError(
            f"{path.name} names the data file {name!r}, a link to {target} outside the"
            " header's folder; copy the data beside the header"
        )
    check_regular(target, f"{path.name}'s data file", VolumeError)


def read_metaimage(path: Path) -> Loaded:
    """A MetaImage file as a :class:`Loaded` (LPS geometry converted to RAS)."""
    extras.require("registration", f"reading the MetaImage {path.name}")
    import SimpleITK as sitk

    if path.suffix.lower() == ".mhd":
        _check_data_file(path)
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
    return sitk_loaded(image)
