"""In-memory images of other libraries as volumes: SimpleITK, ITK (``itk``) and nibabel.

:func:`image_kind` tells such an object apart by its class's module name, so neither
library is imported until an image of it is passed. :func:`sitk_loaded` reads a
SimpleITK image (LPS geometry, ``(z, y, x)`` array) into a :class:`Loaded` in file index
order ``(i, j, k)`` with a RAS affine, as the NRRD reader does for an LPS file; nibabel
images go through the NIfTI reader's own code (:mod:`voxwarp.io.volumes`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from voxwarp.core.orientation import affine_to_ras
from voxwarp.errors import VolumeError
from voxwarp.io.frames import CHANNEL, FRAME, ExtraAxis
from voxwarp.io.loaded import Loaded

#: Names an image object gives its volume (``Volume.name`` and ``Volume.source``).
SITK_SOURCE = "SimpleITK image"
NIBABEL_SOURCE = "nibabel image"
ITK_SOURCE = "ITK image"


def image_kind(obj: Any) -> str:
    """``"sitk"`` for a SimpleITK image, ``"itk"`` for an ITK Python image
    (``itk.Image``, ``itk.VectorImage``), ``"nibabel"`` for a nibabel spatial image
    (NIfTI-1/2, MGH, Analyze, ...), ``""`` for anything else; imports no library."""
    for cls in type(obj).__mro__:
        package = (getattr(cls, "__module__", "") or "").split(".")[0]
        if package == "SimpleITK" and cls.__name__ == "Image":
            return "sitk"
        if package == "itk" and cls.__name__.startswith(("itkImage", "itkVectorImage")):
            return "itk"
        if package == "nibabel" and cls.__name__ == "SpatialImage":
            return "nibabel"
    return ""


def sitk_loaded(image: Any) -> Loaded:
    """A 3-D or 4-D SimpleITK image, scalar or vector, as voxels ``(i, j, k)`` (x
    fastest in ITK's index) followed by its time and component axes, and its RAS
    index -> world affine (ITK's LPS with x and y negated)."""
    import SimpleITK as sitk  # already imported: the caller passed one of its images

    array = sitk.GetArrayFromImage(image)  # a copy, (t,) z, y, x (, c)
    return _itk_like(
        array,
        image.GetDimension(),
        image.GetNumberOfComponentsPerPixel(),
        (image.GetSpacing(), image.GetOrigin(), image.GetDirection()),
        "SimpleITK image",
    )


def itk_loaded(image: Any) -> Loaded:
    """An ITK Python image (``itk`` package) as :func:`sitk_loaded` reads a SimpleITK one."""
    import itk  # already imported: the caller passed one of its images

    direction = itk.array_from_matrix(image.GetDirection())
    return _itk_like(
        itk.array_from_image(image),
        int(image.GetImageDimension()),
        int(image.GetNumberOfComponentsPerPixel()),
        (tuple(image.GetSpacing()), tuple(image.GetOrigin()), direction),
        "ITK image",
    )


def _itk_like(array: Any, dim: int, comps: int, geometry: tuple, what: str) -> Loaded:
    """Voxels and geometry of an ITK-style image: ``array`` is ``(t,) z, y, x (, c)``;
    ``geometry`` is (spacing, origin, direction) of the ``dim``-D image in LPS."""
    array = np.asarray(array)
    if dim not in (3, 4):
        raise VolumeError(
            f"voxwarp loads a 3-D (or 4-D, one time point) {what}; got {dim}-D with"
            f" shape {array.shape}. Pass a 3-D volume."
        )
    spatial = list(range(dim))[::-1]  # (t, z, y, x) -> (x, y, z, t)
    order = spatial + ([dim] if comps > 1 else [])
    data = array.transpose(order)
    spacing, origin, direction = geometry
    d = np.asarray(direction, dtype=np.float64).reshape(dim, dim)[:3, :3]
    lps = np.eye(4)
    lps[:3, :3] = d * np.asarray(spacing, dtype=np.float64)[:3]
    lps[:3, 3] = np.asarray(origin, dtype=np.float64)[:3]
    extra = []
    if dim == 4:
        extra.append(ExtraAxis(FRAME, int(data.shape[3]), float(spacing[3]), ""))
    if comps > 1:
        extra.append(ExtraAxis(CHANNEL, comps))
    field = ""
    if dim == 3 and comps == 3 and array.dtype.kind == "f":
        field = f"a {what} of 3 float components per voxel"
    return Loaded(
        data,
        affine=affine_to_ras(lps, "LPS"),
        space="RAS",
        extra=tuple(extra),
        vector_field=field,
    )
