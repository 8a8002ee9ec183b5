"""``voxwarp export-field SCENE.json -o field.nii.gz``: a scene's warp chain as a
displacement field in the ITK convention (for ITK, ANTs, SimpleITK, Slicer)."""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path
from typing import Any

from voxwarp.cli.options import CliOptionError, add_memory_budget_arg, load_scene_json


def add_parser(sub: Any) -> None:
    """Add ``export-field`` to the ``voxwarp`` sub-commands."""
    p = sub.add_parser(
        "export-field",
        help="write a scene's warp chain as a displacement field (ITK, ANTs, Slicer)",
        description="Samples the warp chain of SCENE.json (voxwarp render ... --save-scene)"
        " as the pull-back field u(p) = warp(p) - p and writes it in the ITK convention (LPS"
        " vectors in mm): SimpleITK.Resample(volume, DisplacementFieldTransform(field))"
        " reproduces the deformed volume voxwarp draws. Default grid: the volume's own.",
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
        help="node spacing in mm, one number or three (default: the volume's voxels)",
    )
    p.add_argument(
        "--box",
        nargs=6,
        type=float,
        metavar=("X0", "Y0", "Z0", "X1", "Y1", "Z1"),
        help="sample this world box (RAS mm, axis-aligned) instead of the volume's",
    )
    p.add_argument(
        "--convention",
        choices=("itk",),
        default="itk",
        help="the written convention: itk (pull-back, LPS vectors in mm; the only one for now)",
    )
    add_memory_budget_arg(p)
    p.set_defaults(func=cmd_export_field)


def cmd_export_field(args: argparse.Namespace) -> int:
    """``voxwarp export-field SCENE.json -o field.nii.gz``: the scene's warp chain as a
    displacement field in the ITK convention (:meth:`voxwarp.scene.Scene.displacement_field`)."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.io.fields import WRITE_SUFFIXES, field_suffix, save_displacement_field

    out = Path(args.output)
    if field_suffix(out) not in WRITE_SUFFIXES:
        raise CliOptionError(
            f"-o {out}: cannot write a displacement field as {field_suffix(out) or '(no suffix)'};"
            f" use one of {', '.join(WRITE_SUFFIXES)}"
        )
    scene = load_scene_json(args.scene, "export-field")
    box = None if args.box is None else (args.box[:3], args.box[3:])
    if not scene.warps:
        warnings.warn(f"{args.scene} has no warps: the exported field is zero", stacklevel=1)
    field = scene.displacement_field(spacing=args.spacing, box=box)
    save_displacement_field(field, out)
    grid = "x".join(str(n) for n in field.shape)
    spacing = " x ".join(f"{s:g}" for s in field.spacing)
    print(
        f"field: {grid} nodes, spacing {spacing} mm, max |u| {field.max_displacement():.3g} mm"
        f" ({len(scene.warps)} warp(s); ITK pull-back, LPS vectors)",
        file=sys.stderr,
    )
    print(out)
    return 0
