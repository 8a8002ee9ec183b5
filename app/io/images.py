"""Image output through OpenImageIO (PNG, EXR, TIFF, ... by file extension), atomic."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from voxwarp.core.files import atomic_write
from voxwarp.errors import VoxwarpError

#: Extensions that keep float data (an ``f4`` render is written as float).
FLOAT_FORMATS = (".exr", ".hdr", ".tif", ".tiff")


def write_image(path: str | os.PathLike, image: np.ndarray) -> Path:
    """Write an (H, W, C) uint8 or float32 image, row 0 = top, atomically.

    The format follows the extension; the file appears only once complete (temp file
    in the same folder, then ``os.replace``).
    """
    import OpenImageIO as oiio

    path = Path(path)
    img = np.ascontiguousarray(image)
    if img.ndim != 3 or img.shape[2] not in (1, 3, 4):
        raise VoxwarpError(f"write_image needs an (H, W, 1|3|4) array; got shape {img.shape}")
    ext = path.suffix.lower()
    if not ext:
        raise VoxwarpError(f"output {path} has no extension; use .png, .exr or .tif")
    if img.dtype == np.float32 and ext not in FLOAT_FORMATS:
        img = np.clip(np.rint(img * 255.0), 0, 255).astype(np.uint8)
    fmt = oiio.FLOAT if img.dtype == np.float32 else oiio.UINT8
    path.parent.mkdir(parents=True, exist_ok=True)

    def write(tmp: Path) -> None:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None:
            raise VoxwarpError(
                f"OpenImageIO cannot write {ext} files ({oiio.geterror()}); use .png, .exr or .tif"
            )
        spec = oiio.ImageSpec(img.shape[1], img.shape[0], img.shape[2], fmt)
        if img.shape[2] == 4:
            spec.alpha_channel = 3
        ok = out.open(str(tmp), spec) and out.write_image(img)
        err = out.geterror()
        out.close()
        if not ok:
            raise VoxwarpError(f"could not write {path}: {err}")

    atomic_write(path, ext, write)
    return path


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read an image as (H, W, C) array (uint8 for 8-bit files, float32 otherwise)."""
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise VoxwarpError(f"cannot read image {path}: {oiio.geterror()}")
    try:
        spec = inp.spec()
        fmt = oiio.UINT8 if spec.format == oiio.TypeDesc("uint8") else oiio.FLOAT
        data = inp.read_image(fmt)
    finally:
        inp.close()
    return np.asarray(data).reshape(spec.height, spec.width, spec.nchannels)
