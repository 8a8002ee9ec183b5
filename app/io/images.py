"""Image output through OpenImageIO (PNG, EXR, TIFF, ... by file extension), atomic."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from voxwarp.core.files import atomic_output, output_error
from voxwarp.errors import OutputError, VoxwarpError

#: Extensions that keep float data (an ``f4`` render is written as float).
FLOAT_FORMATS = (".exr", ".hdr", ".tif", ".tiff")


def check_image_format(path: str | os.PathLike) -> str:
    """The lower-case extension of ``path`` when OpenImageIO can write it; otherwise a
    one-line :class:`~voxwarp.errors.VoxwarpError` naming the formats to use. Call it
    before rendering, so a bad ``-o`` fails before any work (or any other output)."""
    import OpenImageIO as oiio

    ext = Path(path).suffix.lower()
    if not ext:
        raise VoxwarpError(f"output {path} has no extension; use .png, .exr or .tif")
    oiio.geterror()  # clear a stale error of this thread
    if oiio.ImageOutput.create("image" + ext) is None:  # finds a writer, opens nothing
        oiio.geterror()
        raise VoxwarpError(f"cannot write {ext} images ({path}); use .png, .exr or .tif")
    return ext


def write_image(path: str | os.PathLike, image: np.ndarray) -> Path:
    """Write an (H, W, C) uint8 or float32 image, row 0 = top, atomically.

    The format follows the extension; the file appears only once complete (temp file
    in the same folder, then ``os.replace``). Every step of OpenImageIO is checked (its
    results and its error text: a PNG cut short by a full disk reports only the latter);
    a failure raises :class:`~voxwarp.errors.OutputError` and leaves no file behind.
    """
    import OpenImageIO as oiio

    path = Path(path)
    img = np.ascontiguousarray(image)
    if img.ndim != 3 or img.shape[2] not in (1, 3, 4):
        raise VoxwarpError(f"write_image needs an (H, W, 1|3|4) array; got shape {img.shape}")
    ext = check_image_format(path)
    if img.dtype == np.float32 and ext not in FLOAT_FORMATS:
        img = np.clip(np.rint(img * 255.0), 0, 255).astype(np.uint8)
    fmt = oiio.FLOAT if img.dtype == np.float32 else oiio.UINT8
    with atomic_output(path, ext) as tmp:
        oiio.geterror()  # clear a stale error of this thread
        out = oiio.ImageOutput.create(str(tmp))
        if out is None:
            raise VoxwarpError(
                f"OpenImageIO cannot write {ext} files ({oiio.geterror()}); use .png, .exr or .tif"
            )
        spec = oiio.ImageSpec(img.shape[1], img.shape[0], img.shape[2], fmt)
        if img.shape[2] == 4:
            spec.alpha_channel = 3
        if ext in (".tif", ".tiff"):
            # no Exif block: OpenImageIO 3.2 reports a failed (empty) Exif directory at
            # close, which would read as a failed write
            spec.attribute("tiff:write_exif", 0)
        ok = bool(out.open(str(tmp), spec) and out.write_image(img))
        # some formats (PNG) report a short write only through geterror, not the result
        err = out.geterror()
        ok = bool(out.close()) and ok
        err = "\n".join(e for e in (err, out.geterror(), oiio.geterror()) if e)
        if not ok or err or not tmp.is_file() or tmp.stat().st_size == 0:
            raise _image_error(path, err or "the image file is empty", tmp)
    return path


def _image_error(path: Path, text: str, tmp: Path) -> OutputError:
    """One line for a failed image write (the first line of OpenImageIO's text, which
    names the temporary file: it is replaced by ``path``)."""
    text = text.replace(str(tmp), str(path)).strip()
    first = text.splitlines()[0] if text else "OpenImageIO failed"
    if len(first) > 200:
        first = first[:200] + "..."
    return output_error(path, first)


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
