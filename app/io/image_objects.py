"""In-memory images of other libraries as volumes: SimpleITK and nibabel.

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
from voxwarp.io.loaded import Loaded

#: Names an image object gives its volume (``Volume.name`` and ``Volume.source``).
SITK_SOURCE = "SimpleITK image"
NIBABEL_SOURCE = "nibabel image"


def image_kind(obj: Any) -> str:
    """``"sitk"`` for a SimpleITK image, ``"nibabel"`` for a nibabel spatial image
    (NIfTI-1/2, MGH, Analyze, ...), ``""`` for anything else; imports neither library."""
    for cls in type(obj).__mro__:
        package = (getattr(cls, "__module__", "") or "").split(".")[0]
        if package == "SimpleITK" and cls.__name__ == "Image":
            return "sitk"
        if package == "nibabel" and cls.__name__ == "SpatialImage":
            return "nibabel"
    return ""


def sitk_loaded(image: Any) -> Loaded:
    """A 3-D scalar SimpleITK image as voxels ``(i, j, k)`` (x fastest in ITK's index)
    and its RAS index -> world affine (ITK's LPS with x and y negated)."""
    import SimpleITK as sitk  # already imported: the caller passed one of its images

    dim, comps = image.GetDimension(), image.GetNumberOfComponentsPerPixel()
    if dim != 3 or comps != 1:
        raise VolumeError(
            f"voxwarp loads a 3-D scalar SimpleITK image; got {dim}-D with {comps}"
            f" component(s) per voxel (size {image.GetSize()}). Pass one 3-D scalar volume,"
            " e.g. sitk.VectorIndexSelectionCast(img, 0) or img[:, :, :, 0]."
        )
    data = sitk.GetArrayFromImage(image).transpose(2, 1, 0)  # a copy, (z, y, x) -> (i, j, k)
    lps = np.eye(4)
    direction = np.asarray(image.GetDirection(), dtype=np.float64).reshape(3, 3)
    lps[:3, :3] = direction * np.asarray(image.GetSpacing(), dtype=np.float64)
    lps[:3, 3] = image.GetOrigin()
    return Loaded(data, affine=affine_to_ras(lps, "LPS"), space="RAS")
