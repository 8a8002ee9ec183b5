"""The correction step of ``voxwarp demo registration``: fix the demons field by hand.

After the registration, the demo finds where the recovered field ``u`` is farthest from
the known answer ``w`` (the residual ``w - u``, Gaussian-smoothed over a few voxels so
that one noisy voxel does not win, in the head only), and drags a ChainMail element
there (:func:`voxwarp.editing.correction.drag_correction`, the model's default anchors)
as a user would in the views: the correction acts in the displayed (fixed) space, first
in the chain ``[correction, u]``. To first order the corrected pull-back
``c(p) + u(c(p))`` equals ``p + w(p)`` when ``c(p) - p = w(p) - u(p)``; a ChainMail element
held at ``X + D`` pulls back to ``X``, so the drag is ``D = u(X) - w(X)`` at the element's
rest position ``X``. The composed chain is exported as one ITK field
(:meth:`voxwarp.scene.Scene.displacement_field` on the fixed grid,
:func:`voxwarp.io.fields.save_displacement_field`) and SimpleITK resamples the moving
image through it. The numbers: the field residual ``|chain(p) - p - w(p)|`` and the
image residual ``|fixed - moving o chain|`` within one element spacing of the site and in
the whole head, before and after.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.deform.warp import Warp, chain_apply
from voxwarp.editing.correction import corrected_scene, drag_correction
from voxwarp.io.fields import save_displacement_field
from voxwarp.io.itk import resample, sitk_module
from voxwarp.teaching import sheets

#: ChainMail elements per axis of the correction (its spacing sets the reach of a drag)
CORRECTION_SHAPE = 6
#: smoothing (voxels) of the residual before its largest value is taken
RESIDUAL_SIGMA = 1.5


def correct_registration(
    fixed: Any, moving: Any, warps: list[Warp], known: Any, head: float, out: Path
) -> dict[str, Any]:
    """Drag a ChainMail correction at the largest residual of ``warps`` (the recovered
    field) against ``known``, export the composed field to ``out`` and measure it with
    SimpleITK; returns the numbers and arrays for :func:`correction_sheet`."""
    t0 = time.perf_counter()
    mask = np.asarray(fixed.data) > head
    site = largest_residual(fixed, warps, known, mask)
    model = drag_correction(moving, site, np.zeros(3), shape=CORRECTION_SHAPE)
    index = tuple(model.to_dict()["held"][0]["index"])
    rest = np.asarray(model.grid.rest_positions)[index].reshape(1, 3)
    model.close()
    drag = (chain_apply(warps, rest) - known.apply(rest))[0]
    model = drag_correction(moving, rest[0], drag, shape=CORRECTION_SHAPE)
    scene = corrected_scene(moving, warps, [model.warp()])
    path = save_displacement_field(scene.displacement_field(), out / "registration_corrected.h5")
    near = _near(fixed, rest[0], float(np.max(model.grid.spacing))) & mask
    before = _residuals(fixed, moving, warps, known, near, mask)
    after = _residuals(fixed, moving, scene.warps, known, near, mask, path)
    model.close()
    return {
        "site_mm": rest[0].tolist(),
        "drag_mm": drag.tolist(),
        "file": str(path),
        "seconds": time.perf_counter() - t0,
        **{f"{k}_before": v for k, v in before.items() if k != "maps"},
        **{f"{k}_after": v for k, v in after.items() if k != "maps"},
        "maps": (before["maps"], after["maps"]),
    }


def largest_residual(fixed: Any, warps: list[Warp], known: Any, mask: np.ndarray) -> np.ndarray:
    """World mm of the voxel of ``fixed`` in ``mask`` where the smoothed residual
    ``known - chain`` is largest."""
    from scipy.ndimage import gaussian_filter

    res = _field_residual(fixed, warps, known)
    smooth = np.stack([gaussian_filter(res[..., i], RESIDUAL_SIGMA) for i in range(3)], -1)
    mag = np.where(mask, np.linalg.norm(smooth, axis=-1), -1.0)
    ijk = np.array(np.unravel_index(int(np.argmax(mag)), mag.shape), dtype=np.float64)
    return fixed.index_to_world(ijk.reshape(1, 3))[0]


def _field_residual(fixed: Any, warps: list[Warp], known: Any) -> np.ndarray:
    """``known(p) + p - chain(p)`` (mm, vectors) at every voxel of ``fixed``."""
    idx = np.indices(fixed.shape).reshape(3, -1).T.astype(np.float64)
    p = fixed.index_to_world(idx)
    r = known.apply(p) - chain_apply(warps, p)
    return r.reshape((*fixed.shape, 3))


def _near(fixed: Any, centre: np.ndarray, radius: float) -> np.ndarray:
    """Voxels of ``fixed`` within ``radius`` mm of ``centre``."""
    idx = np.indices(fixed.shape).reshape(3, -1).T.astype(np.float64)
    d = np.linalg.norm(fixed.index_to_world(idx) - centre, axis=1)
    return (d <= radius).reshape(fixed.shape)


def _residuals(
    fixed: Any,
    moving: Any,
    warps: list[Warp],
    known: Any,
    near: np.ndarray,
    mask: np.ndarray,
    path: Path | None = None,
) -> dict[str, Any]:
    """Field and image residuals at the site (``near``) and in the head (``mask``); the
    image through the written ITK transform file ``path`` (SimpleITK reads it) when given."""
    from voxwarp.io.itk import displacement_transform

    sitk = sitk_module("voxwarp demo registration")
    res = np.linalg.norm(_field_residual(fixed, warps, known), axis=-1)
    tx = displacement_transform(warps, fixed) if path is None else sitk.ReadTransform(str(path))
    img = np.abs(fixed.data.astype(np.float64) - resample(moving, tx, fixed).data)
    return {
        "site_field_mm": float(res[near].mean()),
        "head_field_mm": float(res[mask].mean()),
        "site_image": float(img[near].mean()),
        "head_image": float(img[mask].mean()),
        "maps": (res, img),
    }


def correction_sheet(path: Path, fixed: Any, n: dict[str, Any]) -> Path:
    """The sheet of the correction step: field and image residuals on the axial plane
    through the site, before and after, the site and the drag marked."""
    (res0, img0), (res1, img1) = n["maps"]
    site = np.asarray(n["site_mm"])
    ijk = np.linalg.solve(fixed.affine[:3, :3], site - fixed.affine[:3, 3])
    k = round(float(ijk[2]))
    fig = sheets.new_figure(
        11.0, 8.6, "Correcting the registration by hand: a ChainMail drag at the largest residual"
    )
    axs = fig.subplots(2, 2)
    top_f = max(float(res0[:, :, k].max()), 1e-6)
    top_i = max(float(img0[:, :, k].max()), 1e-6)
    panels = (
        (axs[0, 0], res0, top_f, f"(a) |w - u| (mm), site mean {n['site_field_mm_before']:.2f}"),
        (axs[0, 1], res1, top_f, f"(b) after the drag, site mean {n['site_field_mm_after']:.2f}"),
        (axs[1, 0], img0, top_i, f"(c) |fixed - moving o u|, site {n['site_image_before']:.1f}"),
        (axs[1, 1], img1, top_i, f"(d) through the exported field, {n['site_image_after']:.1f}"),
    )
    for ax, arr, top, title in panels:
        im = ax.imshow(arr[:, :, k].T[::-1], cmap="magma", vmin=0, vmax=top)
        ax.plot(ijk[0], fixed.shape[1] - 1 - ijk[1], "c+", ms=14, mew=2)
        d = np.linalg.solve(fixed.affine[:3, :3], np.asarray(n["drag_mm"]))
        ax.arrow(ijk[0], fixed.shape[1] - 1 - ijk[1], d[0], -d[1], color="c", width=0.3)
        ax.set_title(title, fontsize=10)
        ax.set_axis_off()
        fig.colorbar(im, ax=ax, shrink=0.7)
    sheets.add_note(
        axs[1, 1],
        f"drag {np.linalg.norm(n['drag_mm']):.1f} mm at the cross; head: field"
        f" {n['head_field_mm_before']:.2f} -> {n['head_field_mm_after']:.2f} mm, image"
        f" {n['head_image_before']:.2f} -> {n['head_image_after']:.2f}",
        "lower left",
        40,
    )
    return sheets.save_figure(fig, path)
