"""``voxwarp export-field SCENE.json -o field.nii.gz``: a scene's warp chain as a
displacement field in the ITK convention (for ITK, ANTs, SimpleITK, Slicer)."""

from __future__ import annotations

import argparse
import contextlib
import sys
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from voxwarp.cli.deform_options import add_deform_args, add_field_args, add_wire_args
from voxwarp.cli.options import (
    CliOptionError,
    add_allow_dir_arg,
    add_memory_budget_arg,
    load_scene_json,
    refuse_overwriting_inputs,
)
from voxwarp.core.field_check import TOLERANCE_MM

if TYPE_CHECKING:
    from voxwarp.core.field_grid import FieldExport


def add_parser(sub: Any) -> None:
    """Add ``export-field`` to the ``voxwarp`` sub-commands."""
    p = sub.add_parser(
        "export-field",
        help="write a scene's warp chain as a displacement field (ITK, ANTs, Slicer)",
        description="Samples the warp chain of SCENE.json (voxwarp render ... --save-scene)"
        " as the pull-back field u(p) = warp(p) - p and writes it in the ITK convention (LPS"
        " vectors in mm): SimpleITK.Resample(volume, DisplacementFieldTransform(field))"
        " reproduces the deformed volume voxwarp draws. ITK interpolates trilinearly"
        " between nodes: the command measures that against the chain at cell centres in the"
        " deformed volume and, by default, starts from the volume's grid and refines the"
        " spacing until it is within --tolerance where the chain is continuous (up to a"
        " node cap). Nodes the chain does not carry (a rigid wire's vacated space, outside"
        " every support) hold their nearest carried node's vector, so they cannot bleed"
        " into their neighbours' interpolation; nodes bordering a tear (a discontinuity no"
        " spacing interpolates) are counted. Both counts and the measured error are printed"
        " and recorded in the file's metadata (not in .h5). The deformation options of"
        " render (--displacement, --chainmail, --massspring, --wires, --lattice) add to the"
        " scene's chain as they do for render: with --displacement the model corrects the"
        " registration in the displayed space (it comes before the fields), so the file is"
        " the corrected registration.",
    )
    p.add_argument("scene", metavar="SCENE.json")
    p.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="FIELD",
        help="the field file: .nii.gz, .nii, .nrrd, .mha, .h5 (ITK transform) or .npz",
    )
    p.add_argument(
        "--spacing",
        nargs="+",
        type=float,
        metavar="S",
        help="node spacing in mm, one number or three, kept as given (a warning names the"
        " spacing that would meet --tolerance); default: a quarter of the finest element or"
        " lattice cell for element grids, lattices and affine maps (16 nodes per axis at"
        " least, never finer than the voxels), the volume's voxels for wires and imported"
        " fields; refined until --tolerance is met. The chosen spacing, why, and the"
        " file's estimated size are printed first; an export over the free disk space"
        " or --memory-budget is refused",
    )
    p.add_argument(
        "--tolerance",
        type=float,
        default=TOLERANCE_MM,
        metavar="MM",
        help=f"how close ITK's trilinear interpolation must stay to the chain between nodes"
        f" (default {TOLERANCE_MM:g} mm)",
    )
    p.add_argument(
        "--box",
        nargs=6,
        type=float,
        metavar=("X0", "Y0", "Z0", "X1", "Y1", "Z1"),
        help="sample this world box (RAS mm, axis-aligned) instead of the volume's",
    )
    p.add_argument(
        "--grid",
        choices=("input", "volume"),
        default="input",
        help="input (default: nodes indexed as the input file's voxels, its axes, direction"
        " and origin, so the field's affine equals the file's; a volume without a file"
        " orientation gets 'volume') or volume (voxwarp's closest-RAS reordering); the same"
        " nodes either way. Not used with --box",
    )
    p.add_argument(
        "--convention",
        choices=("itk",),
        default="itk",
        help="the written convention: itk (pull-back, LPS vectors in mm; the only one for now)",
    )
    p.add_argument(
        "--jacobian",
        action="store_true",
        help="write the Jacobian determinant det J = det(I + grad u) of the chain instead of"
        " the field (from the warps' analytic Jacobians, on the same grid and affine; float32;"
        " .nii.gz, .nii or .nrrd; NaN at nodes the chain does not carry) and print min/max"
        " and the folded (det J <= 0), compressed (< 0.5) and expanded (> 2) voxels",
    )
    p.add_argument(
        "--sampler",
        choices=("gpu", "cpu"),
        default=None,
        help="where the chain is sampled on the nodes: gpu (the raycaster's GLSL chain, planes"
        " of nodes drawn on an offscreen context; float32 and some half-float textures,"
        " within 0.05 mm of the CPU) or cpu (the exact numpy chain, in blocks); default: gpu"
        " for grids of 2^22 nodes or more when an OpenGL 4.3 context opens (smaller grids"
        " take longer to start a context for), else cpu. The field check always measures"
        " against the exact CPU chain",
    )
    add_memory_budget_arg(p)
    add_allow_dir_arg(p)
    add_deform_args(p)
    add_wire_args(p)
    add_field_args(p)
    p.set_defaults(func=cmd_export_field)


def cmd_export_field(args: argparse.Namespace) -> int:
    """``voxwarp export-field SCENE.json -o field.nii.gz``: the scene's warp chain as a
    displacement field in the ITK convention (:meth:`voxwarp.scene.Scene.displacement_field`)."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.core.files import remove_stale_temps
    from voxwarp.io.fields import WRITE_SUFFIXES, field_suffix, save_displacement_field

    out = Path(args.output)
    if args.jacobian:
        return _export_jacobian(args, out)
    if field_suffix(out) not in WRITE_SUFFIXES:
        raise CliOptionError(
            f"-o {out}: cannot write a displacement field as {field_suffix(out) or '(no suffix)'};"
            f" use one of {', '.join(WRITE_SUFFIXES)}"
        )
    if not args.tolerance > 0:
        raise CliOptionError(f"--tolerance {args.tolerance:g}: give a positive distance in mm")
    remove_stale_temps(out.parent, for_name=out.name)  # a killed run's, even if this one fails
    box = None if args.box is None else (args.box[:3], args.box[3:])
    with _chain_scene(args) as (scene, ctx):
        _plan(args, scene, out, box, components=3)
        if not scene.warps:
            warnings.warn(f"{args.scene} has no warps: the exported field is zero", stacklevel=1)
        with _sampler(args, ctx) as sampler:
            export = scene.export_field(
                spacing=args.spacing,
                box=box,
                tolerance=args.tolerance,
                grid=args.grid,
                sampler=sampler,
            )
    field = export.field
    save_displacement_field(field, out, export.metadata())
    grid = "x".join(str(n) for n in field.shape)
    spacing = " x ".join(f"{s:g}" for s in field.spacing)
    print(
        f"field: {grid} nodes, spacing {spacing} mm, max |u| {field.max_displacement():.3g} mm"
        f" ({len(scene.warps)} warp(s); ITK pull-back, LPS vectors)",
        file=sys.stderr,
    )
    print(export.report(), file=sys.stderr)
    if not export.check.met:
        warnings.warn(_unmet(export, args.spacing is not None), stacklevel=1)
    print(out)
    return 0


def _export_jacobian(args: argparse.Namespace, out: Path) -> int:
    """``export-field --jacobian``: det J of the chain on the export grid (a scalar image)."""
    from voxwarp.io.volume_stream import stream_format, write_volume_slices

    stream_format(out)  # a bad -o fails before any work
    if not args.tolerance > 0:
        raise CliOptionError(f"--tolerance {args.tolerance:g}: give a positive distance in mm")
    box = None if args.box is None else (args.box[:3], args.box[3:])
    with _chain_scene(args) as (scene, _):
        _plan(args, scene, out, box, components=1)
        jac = scene.jacobian_determinant(
            spacing=args.spacing, box=box, tolerance=args.tolerance, grid=args.grid
        )
    det = jac.det
    slices = (det[:, :, k].T for k in range(det.shape[2]))
    oriented = scene.volume.space == "RAS"
    write_volume_slices(out, jac.affine, det.shape, "float32", slices, oriented=oriented)
    grid = "x".join(str(n) for n in det.shape)
    spacing = " x ".join(f"{s:.4g}" for s in np.linalg.norm(jac.affine[:3, :3], axis=0))
    warps = len(scene.warps)
    print(f"det J: {grid} nodes, spacing {spacing} mm ({warps} warp(s))", file=sys.stderr)
    print(jac.stats.line(), file=sys.stderr)
    print(out)
    return 0


def _deformation_given(args: argparse.Namespace) -> bool:
    """Whether any of render's deformation options was given."""
    names = ("displacement", "massspring", "chainmail", "wires", "lattice")
    return any(getattr(args, n, None) is not None for n in names)


@contextlib.contextmanager
def _chain_scene(args: argparse.Namespace) -> Iterator[tuple[Any, Any]]:
    """The scene of SCENE.json with the deformation options of render added to its chain
    (:func:`voxwarp.cli.deformation.compose_chain`), and the small offscreen context the
    element models run on (their GPU backend too; current in the block), else ``None``."""
    scene = load_scene_json(args.scene, "export-field")
    if not _deformation_given(args):
        yield scene, None
        return
    from voxwarp.cli.deformation import check_deform_options, deformed_scene, prepare_deformation
    from voxwarp.render.offscreen import OffscreenRenderer

    check_deform_options(args)
    scene, pending = prepare_deformation(args, scene)
    with (
        OffscreenRenderer(16, 16) as r,
        r.current(),
        deformed_scene(args, scene, pending, r.ctx) as s,
    ):
        yield s, r.ctx


@contextlib.contextmanager
def _sampler(args: argparse.Namespace, ctx: Any) -> Iterator[Any]:
    """``--sampler``'s sampler (released after the block): ``None`` (the CPU) for cpu; for
    gpu the GPU on every grid (on ``ctx`` where given); by default the GPU on grids of
    :data:`~voxwarp.render.field_sampling.GPU_MIN_NODES` nodes or more where a context
    opens, else the CPU."""
    if args.sampler == "cpu":
        yield None
        return
    from voxwarp.render.field_sampling import FieldSampler

    def log(text: str) -> None:
        print(f"export-field: {text}", file=sys.stderr)

    forced = args.sampler == "gpu"
    sampler = (
        FieldSampler(ctx, min_nodes=0, required=True) if forced else FieldSampler(ctx, log=log)
    )
    try:
        yield sampler
    finally:
        sampler.release()


def _plan(args: argparse.Namespace, scene: Any, out: Path, box: Any, components: int) -> None:
    """Refuse an output that is one of the scene's inputs; print the starting spacing
    (and why, when it is the default) and the size estimate; refuse one over the free
    disk space or the file-size limit (the memory budget is checked by the grid itself)."""
    from voxwarp.core.field_grid import field_grid
    from voxwarp.core.field_spacing import check_room, default_spacing, estimate_bytes
    from voxwarp.core.limits import format_bytes

    refuse_overwriting_inputs(out, scene, args.scene)
    if args.spacing is None:
        choice = default_spacing(scene.volume, scene.warps)
        start, why = choice.spacing, f"default: {choice.reason}"
    else:
        start, why = args.spacing, "--spacing"
    affine, shape = field_grid(scene.volume, start, box, args.grid)
    # SimpleITK writes .mha and .h5 vectors as float64 (field_image)
    itemsize = 8 if components == 3 and out.name.lower().endswith((".mha", ".h5")) else 4
    size = estimate_bytes(shape, components, itemsize)
    step = " x ".join(f"{v:.4g}" for v in np.linalg.norm(affine[:3, :3], axis=0))
    dims = "x".join(str(n) for n in shape)
    check_room(out, size)  # first: a refusal is the one line printed
    print(
        f"spacing {step} mm ({why}): {dims} nodes, about {format_bytes(size)} uncompressed"
        + (" before any refinement the field check asks for" if args.spacing is None else ""),
        file=sys.stderr,
    )


def _unmet(export: FieldExport, given: bool) -> str:
    """The one-line warning of an export whose interpolation misses the tolerance."""
    c = export.check
    now = " x ".join(f"{s:.4g}" for s in export.field.spacing)
    need = " ".join(f"{np.floor(s * 1000) / 1000:g}" for s in export.needed_spacing)
    which = f"--spacing {now}" if given else f"spacing {now} mm (the finest within the node cap)"
    fix = f"--spacing {need} meets it" if export.needed_met else f"try --spacing {need}"
    return (
        f"{which} leaves ITK's trilinear interpolation up to {c.max_error:.3g} mm from the"
        f" chain between nodes (tolerance {c.tolerance:g} mm); {fix}"
        + ("" if given else " (within --memory-budget)")
    )
