"""Bridge to SimpleITK (``registration`` extra): volumes and warps in ITK's terms.

ITK's physical space is LPS mm; voxwarp's world is RAS mm (a volume without patient
orientation is taken as RAS here too). :func:`to_sitk` and :func:`from_sitk` convert
volumes with their full geometry (spacing, origin, direction); :func:`resample` is the
"resample the whole volume" alternative voxwarp avoids (3D Slicer's way), used as an
oracle by tests and as the reference of ``python -m benchmarks fields``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from voxwarp.core import extras
from voxwarp.core.field_grid import chain_field
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import Warp
from voxwarp.io.fields import field_image, itk_affine

_FLIP3 = np.diag([-1.0, -1.0, 1.0])


def sitk_module(what: str) -> Any:
    """``SimpleITK``, or a one-line error naming the ``registration`` extra."""
    extras.require("registration", what)
    import SimpleITK as sitk

    return sitk


def to_sitk(volume: Volume) -> Any:
    """``volume`` as a SimpleITK image in LPS (values, spacing, origin, direction)."""
    sitk = sitk_module("voxwarp.io.itk.to_sitk")
    img = sitk.GetImageFromArray(np.ascontiguousarray(volume.data.transpose(2, 1, 0)))
    img.SetSpacing([float(s) for s in volume.spacing])
    origin = np.asarray(volume.origin, float) * np.array([-1.0, -1.0, 1.0])
    img.SetOrigin(origin.tolist())
    img.SetDirection((_FLIP3 @ volume.direction).ravel().tolist())
    return img


def from_sitk(image: Any, name: str = "volume", **fields: Any) -> Volume:
    """A SimpleITK scalar image as a :class:`Volume` in RAS (``fields``: more Volume
    fields, e.g. ``units="HU"``)."""
    sitk = sitk_module("voxwarp.io.itk.from_sitk")
    data = sitk.GetArrayFromImage(image).transpose(2, 1, 0)
    a = np.diag([-1.0, -1.0, 1.0, 1.0]) @ itk_affine(image)
    spacing = np.linalg.norm(a[:3, :3], axis=0)
    return Volume(
        data,
        tuple(spacing),
        tuple(a[:3, 3]),
        name=name,
        direction=a[:3, :3] / spacing,
        space=fields.pop("space", "RAS"),
        **fields,
    )


def displacement_transform(warps: Sequence[Warp], reference: Volume) -> Any:
    """An ITK ``DisplacementFieldTransform`` of a warp chain, sampled on ``reference``'s
    grid (the pull-back field ``chain(p) - p``; nodes the chain does not carry hold
    their nearest carried vector, as :func:`voxwarp.core.field_grid.chain_field`)."""
    sitk = sitk_module("voxwarp.io.itk.displacement_transform")
    field, _ = chain_field(warps, reference.affine, reference.shape)
    return sitk.DisplacementFieldTransform(field_image(field))


def resample(volume: Volume, transform: Any, reference: Volume | None = None) -> Volume:
    """``volume`` resampled through an ITK ``transform`` (pull-back) on ``reference``'s
    grid (default its own), linear interpolation, 0 outside: the deformed volume as a
    resampling tool computes it."""
    sitk = sitk_module("voxwarp.io.itk.resample")
    ref = to_sitk(reference if reference is not None else volume)
    moving = sitk.Cast(to_sitk(volume), sitk.sitkFloat32)
    out = sitk.Resample(moving, ref, transform, sitk.sitkLinear, 0.0, sitk.sitkFloat32)
    return from_sitk(out, name=f"{volume.name}-resampled", space=volume.space)
