"""``voxwarp export-volume``: the deformed volume of a scene JSON, resampled to a file.

The deformed volume is sampled one output k-slice per draw on the GPU
(:meth:`voxwarp.render.raycaster.Renderer.slice_values`, the slice views' shader: each
voxel centre goes through the warp chain and the original volume is read there), and
each slice is streamed to the file as it comes (:mod:`voxwarp.io.volume_stream`), so
memory holds one slice, never the output volume.

Output grids (:func:`export_grid`), all along the volume's own index axes (its
direction kept):

* ``input`` (the CLI's default): the input file's own grid, its array axes, direction
  and origin, so ``nib.load(out).get_fdata()`` lines up voxel by voxel with the input
  file's and the affines are equal. voxwarp stores a file in the closest RAS axis order
  (a permutation and flip, :attr:`Volume.file_axes`); this is the ``volume`` grid
  indexed back in the file's order (the same voxel centres, nothing resampled; each
  k-slice of the file's order is drawn directly, so it still streams). A volume
  without a file orientation (arrays, samples) gets the ``volume`` grid.
* ``volume``: the volume's grid as voxwarp stores it (closest RAS order), the same
  shape and affine as ``Volume.affine``; ``--spacing`` resamples the volume's box at
  another voxel size (centred in it, as ``export-field`` does); with ``input`` too.
* ``deformed``: the grid grows, in whole voxels of the lattice through the volume's
  voxel centres, until it holds the deformed box.

Values: ``--dtype same`` rounds and clips to the input's voxel type (as ITK's Resample
keeps the pixel type), ``float32`` keeps the interpolated values; points whose source
lies outside the volume get ``--outside`` (default the volume's minimum, so CT air
stays air).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from voxwarp.cli.options import (
    add_allow_dir_arg,
    add_memory_budget_arg,
    load_scene_json,
    refuse_overwriting_inputs,
)
from voxwarp.core import limits
from voxwarp.core.progress import ProgressBar
from voxwarp.errors import InputError

if TYPE_CHECKING:
    import numpy as np

GRIDS = ("input", "volume", "deformed")


def spacing_arg(text: str) -> tuple[float, float, float]:
    """``--spacing MM`` or ``SX,SY,SZ`` (mm, within :data:`limits.MIN_SPACING_MM` ..
    :data:`limits.MAX_SPACING_MM`)."""
    form = (
        "one voxel size in mm or three SX,SY,SZ, e.g. 1 or 0.8,0.8,2, each from"
        f" {limits.MIN_SPACING_MM:g} to {limits.MAX_SPACING_MM:g}"
    )
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}") from exc
    if len(vals) == 1:
        vals *= 3
    ok = all(limits.spacing_in_range(v) for v in vals)
    if len(vals) != 3 or not ok:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}")
    return vals[0], vals[1], vals[2]


def _finite(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"expected a finite number; got {text!r}")
    return v


def add_parser(sub: Any) -> None:
    """Add ``export-volume`` to the ``voxwarp`` sub-commands."""
    p = sub.add_parser(
        "export-volume",
        help="write a scene's deformed volume, resampled slice by slice, as NIfTI or NRRD",
        description="Resamples the deformed volume of SCENE.json (voxwarp render ..."
        " --save-scene) one slice at a time on the GPU, through the same warp chain the"
        " renderer draws, and streams it to a NIfTI or NRRD file with the output grid's"
        " affine (RAS; memory holds one slice). Default grid: the input file's own (its array"
        " axes, direction and origin), so the result compares voxel by voxel with the input"
        " file.",
    )
    p.add_argument("scene", metavar="SCENE.json")
    p.add_argument("-o", "--output", required=True, metavar="VOLUME", help=".nii.gz, .nii or .nrrd")
    p.add_argument(
        "--spacing",
        type=spacing_arg,
        metavar="MM|SX,SY,SZ",
        help="output voxel size in mm, 1e-06 to 1e+06 (default: the volume's own grid);"
        " a grid over --memory-budget, over 32767 voxels a side for NIfTI, or whose"
        " uncompressed size is over the free disk space or the file-size limit is refused"
        " before any work",
    )
    p.add_argument(
        "--grid",
        choices=GRIDS,
        default="input",
        help="input (default: the input file's own grid, axes, direction and origin, so"
        " the output lines up voxel by voxel with the file; a volume without a file"
        " orientation gets 'volume'), volume (voxwarp's closest-RAS reordering of it) or"
        " deformed (grown along the volume's axes to hold the deformed box)",
    )
    p.add_argument(
        "--dtype",
        choices=("same", "float32"),
        default="same",
        help="same (default: rounded and clipped to the input's voxel type, as ITK's"
        " Resample keeps the pixel type) or float32",
    )
    p.add_argument(
        "--outside",
        type=_finite,
        metavar="VALUE",
        help="value where the deformed point's source lies outside the volume (default:"
        " the volume's minimum, so CT air stays air)",
    )
    p.add_argument("--interpolation", choices=("linear", "nearest"), default="linear")
    p.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="progress on stderr (default on)",
    )
    add_memory_budget_arg(p)
    add_allow_dir_arg(p)
    p.set_defaults(func=cmd_export_volume)


def export_grid(
    scene: Any, spacing: tuple[float, float, float] | None = None, grid: str = "volume"
) -> tuple[np.ndarray, tuple[int, int, int]]:
    """``(affine, (nx, ny, nz))`` of the output grid (see the module docstring)."""
    import numpy as np

    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.deform.warp import box_corners

    vol = scene.volume
    if grid not in GRIDS:
        raise InputError(f"--grid must be one of {', '.join(GRIDS)}; got {grid!r}")
    if grid == "input":
        affine, shape = export_grid(scene, spacing, "volume")
        return in_file_order(vol, affine, shape)
    if grid == "volume" and spacing is None:
        return np.asarray(vol.affine, dtype=np.float64), vol.shape
    if grid == "volume":  # the box at another voxel size, centred in it (as export-field);
        # no memory check: the output is streamed, never held
        s = np.asarray(spacing, dtype=np.float64)
        n = np.maximum(np.rint(np.asarray(vol.shape) * np.asarray(vol.spacing) / s), 1)
        affine = np.eye(4)
        affine[:3, :3] = np.asarray(vol.direction, dtype=np.float64) * s
        affine[:3, 3] = vol.center - affine[:3, :3] @ ((n - 1) / 2.0)
        return affine, (int(n[0]), int(n[1]), int(n[2]))
    d = np.asarray(vol.direction, dtype=np.float64)
    s = np.asarray(vol.spacing if spacing is None else spacing, dtype=np.float64)
    origin = np.asarray(vol.origin, dtype=np.float64)
    # both boxes in mm along the volume's axes, from the centre of voxel 0
    own = (
        (np.zeros(3) - 0.5) * np.asarray(vol.spacing),
        (np.asarray(vol.shape) - 0.5) * np.asarray(vol.spacing),
    )
    local = (box_corners(*scene.deformed_bounds()) - origin) @ d
    lo = np.minimum(own[0], local.min(axis=0))
    hi = np.maximum(own[1], local.max(axis=0))
    first = np.floor(lo / s + 0.5 + 1e-9)  # voxel first's box reaches lo
    last = np.ceil(hi / s - 0.5 - 1e-9)
    shape = (last - first + 1).astype(np.int64)
    affine = np.eye(4)
    affine[:3, :3] = d * s
    affine[:3, 3] = origin + d @ (first * s)
    return affine, (int(shape[0]), int(shape[1]), int(shape[2]))


def drawable_grid(
    scene: Any, spacing: tuple[float, float, float] | None, grid: str, max_side: int
) -> tuple[np.ndarray, tuple[int, int, int], str]:
    """``(affine, shape, grid used)``: :func:`export_grid`, whose k-slices are drawn one
    per draw, so each must fit ``max_side`` voxels a side. An ``input`` grid whose file
    order puts a long axis in its slices falls back to ``volume`` (the same voxels in
    closest-RAS order) with a warning; a volume without a file orientation gets
    ``volume`` silently. Otherwise an :class:`InputError` asks for a coarser spacing."""
    affine, shape = export_grid(scene, spacing, grid)
    if grid == "input" and not scene.volume.file_axes:
        grid = "volume"
    if grid == "input" and max(shape[:2]) > max_side:
        affine, shape = export_grid(scene, spacing, "volume")
        if max(shape[:2]) <= max_side:
            warnings.warn(
                f"the input file's grid has slices over {max_side} voxels a side; writing"
                " --grid volume (the same voxels in closest-RAS order) instead",
                stacklevel=2,
            )
            grid = "volume"
    if max(shape[:2]) > max_side:
        raise InputError(
            f"the output grid {'x'.join(map(str, shape))} has slices over {max_side}"
            " voxels a side; give a coarser --spacing"
        )
    return affine, shape, grid


#: most voxels a side a NIfTI-1 header holds (its ``dim`` entries are int16)
NIFTI_MAX_SIDE = 32767


def check_export_size(out: Path, shape: tuple[int, int, int], dtype: Any) -> None:
    """Refuse, before any work, an output grid the format cannot hold (NIfTI: over
    :data:`NIFTI_MAX_SIDE` a side), whose voxels exceed the memory budget (the bound on
    an export's work and file, ``--memory-budget``), or whose uncompressed bytes (an
    upper bound of a gzip file's) exceed the free disk space or the file-size limit;
    each with the estimate and the fix."""
    import numpy as np

    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.core.field_spacing import HEADER_BYTES, check_room

    dims = "x".join(map(str, shape))
    if out.name.lower().endswith((".nii", ".nii.gz")) and max(shape) > NIFTI_MAX_SIDE:
        raise InputError(
            f"the output grid {dims} has a side over the {NIFTI_MAX_SIDE} voxels a NIfTI"
            " file holds; give a coarser --spacing or write .nrrd"
        )
    itemsize = np.dtype(dtype).itemsize
    over = limits.over_budget(shape, itemsize)
    if over is not None:
        raise InputError(
            f"the output grid {dims} ({np.dtype(dtype).name}) is {over[0]}, over the memory"
            f" budget of {over[1]}; give a coarser --spacing (or raise --memory-budget)"
        )
    # the uncompressed size: exact for .nii, an upper bound for .nii.gz and .nrrd (gzip)
    check_room(out, int(np.prod(shape, dtype=np.float64)) * itemsize + HEADER_BYTES)


def in_file_order(
    volume: Any, affine: np.ndarray, shape: tuple[int, int, int]
) -> tuple[np.ndarray, tuple[int, int, int]]:
    """The grid ``(affine, shape)`` along ``volume``'s stored axes, indexed in its
    file's axis order (:attr:`Volume.file_axes`); unchanged without one."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.core.orientation import grid_in_file_order

    if not volume.file_axes:
        return affine, shape
    return grid_in_file_order(affine, shape, volume.file_axes)


def slice_matrix(affine: np.ndarray, k: int) -> np.ndarray:
    """Pixel -> world of output slice ``k``: columns i, j, the unit k-direction, and
    the centre of voxel (0, 0, k)."""
    import numpy as np

    a = np.asarray(affine, dtype=np.float64)
    m = np.eye(4)
    m[:3, 0] = a[:3, 0]
    m[:3, 1] = a[:3, 1]
    m[:3, 2] = a[:3, 2] / np.linalg.norm(a[:3, 2])
    m[:3, 3] = a[:3, 3] + k * a[:3, 2]
    return m


def resampled_slices(
    renderer: Any,
    scene: Any,
    affine: np.ndarray,
    shape: tuple[int, int, int],
    *,
    dtype: Any,
    outside: float,
    interpolation: str = "linear",
    on_slice: Any = None,
) -> Iterator[np.ndarray]:
    """The output's k-slices, ``(ny, nx)`` arrays indexed ``[j, i]`` in ``dtype`` (integers
    rounded and clipped to its range), drawn by ``renderer`` (a
    :class:`~voxwarp.render.raycaster.Renderer` whose context is current) one per draw;
    ``on_slice()`` is called after each."""
    import numpy as np

    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.render.slice_image import COVERED

    nx, ny, nz = shape
    dt = np.dtype(dtype)
    lo_hi = (np.iinfo(dt).min, np.iinfo(dt).max) if dt.kind in "iu" else None
    for k in range(nz):
        data = renderer.slice_values(
            scene, slice_matrix(affine, k), (nx, ny), interpolation=interpolation
        )
        values = np.where(data[..., 1] > COVERED, data[..., 0], np.float32(outside))
        if lo_hi is not None:
            values = np.clip(np.rint(values), *lo_hi)
        yield values.astype(dt)
        if on_slice is not None:
            on_slice()


def cmd_export_volume(args: argparse.Namespace) -> int:
    """``voxwarp export-volume SCENE.json -o deformed.nii.gz``."""
    import numpy as np

    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.core.files import remove_stale_temps
    from voxwarp.io.volume_stream import stream_format, write_volume_slices
    from voxwarp.render.offscreen import OffscreenRenderer
    from voxwarp.render.slices import MAX_SLICE_SIDE

    out = Path(args.output)
    stream_format(out)  # a bad -o fails before any work
    remove_stale_temps(out.parent, for_name=out.name)  # a killed run's, even if this one fails
    scene = load_scene_json(args.scene, "export-volume")
    refuse_overwriting_inputs(out, scene, args.scene)
    affine, shape, grid = drawable_grid(scene, args.spacing, args.grid, MAX_SLICE_SIDE)
    vol = scene.volume
    dtype = vol.dtype if args.dtype == "same" else np.dtype(np.float32)
    check_export_size(out, shape, dtype)
    if not scene.warps:
        warnings.warn(f"{args.scene} has no warps: the export is the volume itself", stacklevel=1)
    outside = vol.value_range[0] if args.outside is None else args.outside
    t0 = time.perf_counter()
    bar = ProgressBar(shape[2], args.progress, unit="slice")
    try:
        with OffscreenRenderer(16, 16) as r, r.current():
            slices = resampled_slices(
                r.renderer,
                scene,
                affine,
                shape,
                dtype=dtype,
                outside=outside,
                interpolation=args.interpolation,
                on_slice=bar.update,
            )
            write_volume_slices(out, affine, shape, dtype, slices, oriented=vol.space == "RAS")
    except BaseException:
        bar.lines = False  # no closing progress line above the error's one line
        bar.close()
        raise
    bar.close()
    seconds = time.perf_counter() - t0
    spacing = np.linalg.norm(affine[:3, :3], axis=0)
    print(
        f"export-volume: {'x'.join(map(str, shape))} voxels ({grid} grid), spacing"
        f" {' x '.join(f'{v:.4g}' for v in spacing)} mm, {np.dtype(dtype).name},"
        f" {len(scene.warps)} warp(s), {args.interpolation}, outside {outside:g},"
        f" {seconds:.1f} s",
        file=sys.stderr,
    )
    print(out)
    return 0
