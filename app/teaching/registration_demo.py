"""``voxwarp demo registration``: a SimpleITK registration viewed through its field.

The bundled colin27 MRI is the *fixed* image. A known smooth deformation (a few seeded
Gaussian displacement bumps, :data:`BUMPS`) makes the *moving* image: the fixed image
resampled through the inverse of the known pull-back field ``w``, so that
``moving(x + w(x)) = fixed(x)`` and ``w`` is the answer a registration should find.
SimpleITK's fast symmetric-forces demons (multi-resolution) then registers fixed and
moving; its field is written with :func:`voxwarp.io.fields.save_displacement_field`
(``.nii.gz`` and ITK ``.h5``), read back with :func:`voxwarp.load_transform` and the
moving image is rendered *through* it (no resampling) beside the fixed image, a
checkerboard of both and the differences before and after. The numbers: mean absolute
difference of the renders and of the volumes (in the head), and the recovered field
against the known one where the deformation is. Then a correction step
(:mod:`voxwarp.teaching.registration_correction`) drags a ChainMail element at the
largest residual, exports the composed field (``registration_corrected.h5``) and
applies it with SimpleITK (sheet ``registration_correction.png``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.core.camera import Camera
from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.io.fields import field_image, itk_affine, load_transform, save_displacement_field
from voxwarp.io.itk import displacement_transform, resample, sitk_module, to_sitk
from voxwarp.io.samples import load_sample
from voxwarp.io.volumes import load_volume, save_volume
from voxwarp.scene import Scene
from voxwarp.teaching import sheets
from voxwarp.teaching.registration_correction import correct_registration, correction_sheet

#: the known deformation: this many Gaussian bumps, centres seeded inside the middle of
#: the head's box, amplitude (mm) and width (sigma, mm)
BUMPS = 5
BUMP_MM: tuple[float, float] = (7.0, 10.0)
BUMP_SIGMA_MM = 20.0
SEED = 18
#: demons: the shrink factor of each level, iterations per level (full, quick) and the
#: field's Gaussian smoothing (voxels of the level)
DEMONS_LEVELS: tuple[int, ...] = (2, 1)
DEMONS_ITERATIONS: tuple[int, int] = (60, 30)
DEMONS_SIGMA = 1.5
#: the renders: an axial slab (mm thick) through the strongest bump, mean along the ray
#: (a slice), orthographic, seen from above; grey window (level, width) of the MRI
SLAB_MM = 4.0
WINDOW = (80.0, 160.0)
#: the volume numbers are taken in the head (fixed image above this value) where the
#: deformation is; the field numbers where the known displacement is above this (mm)
HEAD_THRESHOLD = 20.0
FIELD_MIN_MM = 1.0


def demo_registration(
    quick: bool, out: Path, say: Callable[[str], None]
) -> tuple[list[Path], dict[str, Any], list[sheets.TourStep]]:
    """Run the registration demo into ``out`` (sheets ``registration.png`` and
    ``registration_correction.png``, the moving image ``registration_moving.nii.gz``,
    the recovered field ``registration_field.nii.gz`` / ``.h5`` and the corrected one
    ``registration_corrected.h5``); returns (figures, numbers, tour steps)."""
    fixed = load_sample("colin27")
    if quick:
        fixed = fixed.downsample(2)
    known = known_field(fixed)
    moving_vol = deform_volume(fixed, known)
    moving_path = save_volume(moving_vol, out / "registration_moving.nii.gz")
    moving = load_volume(moving_path)
    t0 = time.perf_counter()
    recovered = register(fixed, moving, DEMONS_LEVELS, DEMONS_ITERATIONS[int(quick)])
    reg_s = time.perf_counter() - t0
    say(f"registration: demons {reg_s:.1f} s on {'x'.join(map(str, fixed.shape))} voxels")
    field_nii = save_displacement_field(recovered, out / "registration_field.nii.gz")
    field_h5 = save_displacement_field(recovered, out / "registration_field.h5")
    warps = load_transform(field_h5)
    size = (256, 300) if quick else (400, 470)
    renders = _renders(fixed, moving, warps, size)
    numbers = _numbers(fixed, moving, known, warps, renders)
    numbers.update(
        registration_seconds=reg_s,
        shape=list(fixed.shape),
        spacing_mm=list(fixed.spacing),
        files=[str(moving_path), str(field_nii), str(field_h5)],
        gl_renderer=renders.pop("gl_renderer"),
    )
    cli = (
        f"voxwarp render {Path(moving_path).resolve()} --displacement"
        f" {Path(field_h5).resolve()} -o registered.png"
    )
    numbers["cli"] = cli
    say(
        f"registration: mean |fixed - moving| {numbers['render_mad_before']:.1f} -> "
        f"{numbers['render_mad_after']:.1f} (render grey levels), volume"
        f" {numbers['volume_mad_before']:.1f} -> {numbers['volume_mad_after']:.1f}; mean |u|"
        f" {numbers['recovered_mean_mm']:.2f} mm recovered vs {numbers['known_mean_mm']:.2f} mm"
        f" known, mean error {numbers['field_error_mm']:.2f} mm, correlation"
        f" {numbers['field_correlation']:.3f}"
    )
    say(f"registration: the same render from the command line: {cli}")
    sheet = _sheet(out / "registration.png", renders, numbers, known, warps[0], fixed)
    fixed_sheet = _correction_step(fixed, moving, warps, known, out, numbers, say)
    steps = _tour(moving, warps, renders["camera"], renders["clip"])
    renders.pop("camera"), renders.pop("clip")
    return [sheet, fixed_sheet], numbers, steps


def _correction_step(
    fixed: Any,
    moving: Any,
    warps: list[Any],
    known: Any,
    out: Path,
    numbers: dict[str, Any],
    say: Callable[[str], None],
) -> Path:
    """The correction step (:mod:`voxwarp.teaching.registration_correction`): its
    numbers go in ``numbers["correction"]``; returns its sheet."""
    c = correct_registration(fixed, moving, warps, known, HEAD_THRESHOLD, out)
    sheet = correction_sheet(out / "registration_correction.png", fixed, c)
    c.pop("maps")
    numbers["correction"] = c
    say(
        f"correction: ChainMail drag {np.linalg.norm(c['drag_mm']):.1f} mm at"
        f" {', '.join(f'{v:.0f}' for v in c['site_mm'])} mm; residual at the site"
        f" {c['site_field_mm_before']:.2f} -> {c['site_field_mm_after']:.2f} mm, |fixed -"
        f" moving| there {c['site_image_before']:.1f} -> {c['site_image_after']:.1f}"
        f" (SimpleITK through {Path(c['file']).name}; {c['seconds']:.1f} s)"
    )
    return sheet


# ---------------------------------------------------------------------- the data
def known_field(fixed: Any) -> Any:
    """The known pull-back field ``w`` on ``fixed``'s grid: :data:`BUMPS` seeded Gaussian
    bumps in the head (a :class:`~voxwarp.deform.fields.displacement.DisplacementFieldWarp`)."""
    rng = np.random.default_rng(SEED)
    xyz = _grid_points(fixed)
    head = xyz[fixed.data > 40]
    lo, hi = head.min(axis=0), head.max(axis=0)
    w = np.zeros((*fixed.shape, 3), dtype=np.float64)
    for _ in range(BUMPS):
        centre = lo + (hi - lo) * rng.uniform(0.2, 0.8, 3)
        d = rng.normal(size=3)
        d *= rng.uniform(*BUMP_MM) / np.linalg.norm(d)
        g = np.exp(-np.sum((xyz - centre) ** 2, axis=-1) / (2 * BUMP_SIGMA_MM**2))
        w += g[..., None] * d
    return DisplacementFieldWarp(w.astype(np.float32), fixed.affine)


def _grid_points(vol: Any) -> np.ndarray:
    """World mm of every voxel centre of ``vol``, shape (nx, ny, nz, 3)."""
    idx = np.stack(np.meshgrid(*[np.arange(n) for n in vol.shape], indexing="ij"), axis=-1)
    a = vol.affine
    return idx.astype(np.float64) @ a[:3, :3].T + a[:3, 3]


def deform_volume(fixed: Any, known: Any) -> Any:
    """The moving image: ``fixed`` resampled (SimpleITK, linear) through the inverse of
    ``known``, so that registering fixed and moving should recover ``known``."""
    sitk = sitk_module("voxwarp demo registration")
    inverse = sitk.InvertDisplacementField(
        field_image(known),
        maximumNumberOfIterations=30,
        maxErrorToleranceThreshold=0.01,
        meanErrorToleranceThreshold=1e-4,
        enforceBoundaryCondition=False,
    )
    moving = resample(fixed, sitk.DisplacementFieldTransform(inverse), fixed)
    data = np.clip(np.rint(moving.data), 0, 255).astype(np.uint8)
    return moving.with_geometry(data)


def register(fixed: Any, moving: Any, levels: tuple[int, ...], iterations: int) -> Any:
    """Demons registration (SimpleITK fast symmetric forces) of ``moving`` to ``fixed``,
    coarse to fine (``levels``: shrink factors); the pull-back field on ``fixed``'s grid
    as a :class:`~voxwarp.deform.fields.displacement.DisplacementFieldWarp`."""
    sitk = sitk_module("voxwarp demo registration")
    f_img = sitk.Cast(to_sitk(fixed), sitk.sitkFloat32)
    m_img = sitk.Cast(to_sitk(moving), sitk.sitkFloat32)
    field = None
    for shrink in levels:
        f_l, m_l = (_level(sitk, img, shrink) for img in (f_img, m_img))
        demons = sitk.FastSymmetricForcesDemonsRegistrationFilter()
        demons.SetNumberOfIterations(iterations)
        demons.SetStandardDeviations(DEMONS_SIGMA)
        if field is None:
            field = demons.Execute(f_l, m_l)
        else:
            field = sitk.Resample(field, f_l, sitk.Transform(), sitk.sitkLinear, 0.0)
            field = demons.Execute(f_l, m_l, field)
    u = sitk.GetArrayFromImage(field).transpose(2, 1, 0, 3)
    return DisplacementFieldWarp(u.astype(np.float32), itk_affine(field), space="LPS")


def _level(sitk: Any, img: Any, shrink: int) -> Any:
    """``img`` smoothed and shrunk by ``shrink`` (itself at 1)."""
    if shrink == 1:
        return img
    sigma = 0.5 * shrink * min(img.GetSpacing())
    return sitk.Shrink(sitk.SmoothingRecursiveGaussian(img, sigma), [shrink] * 3)


# ---------------------------------------------------------------------- renders
def _renders(fixed: Any, moving: Any, warps: list[Any], size: tuple[int, int]) -> dict[str, Any]:
    """Fixed, moving and moving-through-the-field renders of the axial slab through the
    strongest bump (mean along the ray, orthographic, from above), grey (H, W) float."""
    lo, hi = (np.asarray(b, dtype=np.float64) for b in fixed.bounds)
    z = _slab_centre(warps[0], fixed)
    clip = ((lo[0], lo[1], z - SLAB_MM / 2), (hi[0], hi[1], z + SLAB_MM / 2))
    camera = Camera.fit(lo, hi, view="superior", projection="orthographic")

    def scene(vol: Any, ws: list[Any]) -> Any:
        return Scene(
            vol,
            mode="average",
            camera=camera,
            warps=ws,
            window=WINDOW,
            clip_box=clip,
            jitter=False,
            step=0.5,
        )

    with sheets.offscreen_renderer(size) as r:
        out = {
            "fixed": sheets.render_rgb(r, scene(fixed, []), size)[..., 0].astype(np.float64),
            "moving": sheets.render_rgb(r, scene(moving, []), size)[..., 0].astype(np.float64),
            "through": sheets.render_rgb(r, scene(moving, warps), size)[..., 0].astype(np.float64),
            "gl_renderer": sheets.gl_renderer(r),
        }
    out.update(camera=camera, clip=clip, z_mm=z)
    return out


def _slab_centre(field: Any, fixed: Any) -> float:
    """z (mm) of the axial plane where the recovered field is largest on average."""
    mag = np.linalg.norm(field.displacements, axis=-1).mean(axis=(0, 1))
    k = int(np.argmax(mag))
    return float((fixed.affine @ np.array([0.0, 0.0, k, 1.0]))[2])


# ---------------------------------------------------------------------- numbers
def _numbers(
    fixed: Any, moving: Any, known: Any, warps: list[Any], renders: dict[str, Any]
) -> dict[str, Any]:
    """Before/after differences (renders and volumes) and the recovered field against
    the known one."""
    f, m, t = renders["fixed"], renders["moving"], renders["through"]
    head = (f > 0) | (m > 0)
    vf = fixed.data.astype(np.float64)
    vm = moving.data.astype(np.float64)
    vr = resample(moving, displacement_transform(warps, fixed), fixed).data.astype(np.float64)
    u = warps[0].displacements.astype(np.float64)
    w = known.displacements.astype(np.float64)
    where = np.linalg.norm(w, axis=-1) > FIELD_MIN_MM
    mask = (vf > HEAD_THRESHOLD) & where
    return {
        "render_mad_before": float(np.abs(f - m)[head].mean()),
        "render_mad_after": float(np.abs(f - t)[head].mean()),
        "volume_mad_before": float(np.abs(vf - vm)[mask].mean()),
        "volume_mad_after": float(np.abs(vf - vr)[mask].mean()),
        "known_mean_mm": float(np.linalg.norm(w, axis=-1)[where].mean()),
        "known_max_mm": float(np.linalg.norm(w, axis=-1).max()),
        "recovered_mean_mm": float(np.linalg.norm(u, axis=-1)[where].mean()),
        "field_error_mm": float(np.linalg.norm(u - w, axis=-1)[where].mean()),
        "field_correlation": float(np.corrcoef(u[where].ravel(), w[where].ravel())[0, 1]),
        "slab_z_mm": renders["z_mm"],
    }


# ---------------------------------------------------------------------- the sheet
def _grey(img: np.ndarray) -> np.ndarray:
    return np.repeat(np.clip(img, 0, 255).astype(np.uint8)[..., None], 3, axis=-1)


def _checker(a: np.ndarray, b: np.ndarray, tiles: int = 8) -> np.ndarray:
    h, w = a.shape
    yy, xx = np.mgrid[0:h, 0:w]
    side = max(h, w) // tiles
    return np.where(((yy // side + xx // side) % 2) == 0, a, b)


def _field_slice(field: Any, fixed: Any, z: float) -> np.ndarray:
    """|u| (mm) on the axial plane of ``fixed``'s grid nearest ``z``, as the renders show
    it (rows = anterior at the top, patient's right on the right, as seen from above)."""
    k = round(float((np.linalg.inv(fixed.affine) @ np.array([0.0, 0.0, z, 1.0]))[2]))
    mag = np.linalg.norm(field.displacements[:, :, k], axis=-1)
    return mag.T[::-1]


def _sheet(
    path: Path,
    renders: dict[str, Any],
    n: dict[str, Any],
    known: Any,
    recovered: Any,
    fixed: Any,
) -> Path:
    f, m, t = renders["fixed"], renders["moving"], renders["through"]
    fig = sheets.new_figure(
        13.5, 8.6, "A demons registration rendered through its field, no resampling"
    )
    axs = fig.subplots(2, 4)
    sheets.show_image(axs[0, 0], _grey(f), "(a) fixed: colin27")
    sheets.show_image(axs[0, 1], _grey(m), "(b) moving, as stored")
    sheets.show_image(axs[0, 2], _grey(t), "(c) moving rendered through the field")
    sheets.show_image(axs[0, 3], _grey(_checker(f, t)), "(d) checkerboard: (a) | (c)")
    vmax = max(float(np.abs(f - m).max()), 1.0)
    for ax, d, title in (
        (axs[1, 0], np.abs(f - m), f"(e) |a - b|, mean {n['render_mad_before']:.1f}"),
        (axs[1, 1], np.abs(f - t), f"(f) |a - c|, mean {n['render_mad_after']:.1f}"),
    ):
        ax.imshow(d, cmap="magma", vmin=0, vmax=vmax, interpolation="lanczos")
        ax.set_title(title, fontsize=10)
        ax.set_axis_off()
    z = renders["z_mm"]
    top = float(np.linalg.norm(known.displacements, axis=-1).max())
    for ax, fld, title in (
        (axs[1, 2], known, "(g) known |w| (mm)"),
        (axs[1, 3], recovered, "(h) recovered |u| (mm)"),
    ):
        im = ax.imshow(
            _field_slice(fld, fixed, z), cmap="viridis", vmin=0, vmax=top, aspect="equal"
        )
        ax.set_title(title, fontsize=10)
        ax.set_axis_off()
        fig.colorbar(im, ax=ax, shrink=0.7)
    sheets.add_note(
        axs[1, 3],
        f"mean |u| {n['recovered_mean_mm']:.1f} vs {n['known_mean_mm']:.1f} mm, error"
        f" {n['field_error_mm']:.1f} mm, r = {n['field_correlation']:.2f}",
        "lower left",
        34,
    )
    sheets.add_note(
        axs[0, 2],
        f"demons {n['registration_seconds']:.1f} s; axial slab {SLAB_MM:g} mm at z = {z:.0f} mm",
        "lower left",
        40,
    )
    return sheets.save_figure(fig, path)


def _tour(moving: Any, warps: list[Any], camera: Any, clip: Any) -> list[sheets.TourStep]:
    def scene(ws: list[Any]) -> dict[str, Any]:
        s = Scene(moving, mode="average", camera=camera, warps=ws, window=WINDOW, clip_box=clip)
        return s.to_dict()

    return [
        sheets.TourStep(
            "The moving image",
            "The bundled MRI after a known smooth deformation: a few Gaussian bumps push"
            " the anatomy by several millimetres. Compare it with the fixed image in (a).",
            scene([]),
            "b",
        ),
        sheets.TourStep(
            "Through the registration's field",
            "SimpleITK's demons found a pull-back field u (ITK convention, LPS): the fixed"
            " point p samples the moving image at p + u(p). voxwarp renders the stored"
            " moving image through u at every ray sample, without resampling the volume.",
            scene(warps),
            "c",
        ),
        sheets.TourStep(
            "How good is it",
            "The checkerboard (d) and the differences (e, f) show the alignment before and"
            " after; (g) and (h) compare the recovered displacement with the known one.",
            None,
            "f",
        ),
    ]
