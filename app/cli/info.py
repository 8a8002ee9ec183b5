"""``voxwarp info INPUT``: what a volume file, scene JSON or displacement field holds."""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
from typing import Any

from voxwarp.cli import render_options as ropt
from voxwarp.cli.options import add_field_convention_arg as _add_field_convention_arg
from voxwarp.cli.options import add_volume_args as _add_volume_args
from voxwarp.inputs import load_input


def add_parser(sub: Any) -> None:
    """Add ``info`` to the ``voxwarp`` sub-commands (``sub``: their sub-parsers object)."""
    pi = sub.add_parser(
        "info",
        help="print dims, dtype, spacing, value range, histogram; for a displacement field"
        " or transform file its grid, extent and |u|",
    )
    pi.add_argument("input")
    pi.add_argument("--json", action="store_true", help="machine-readable output")
    _add_field_convention_arg(pi)
    _add_volume_args(pi)
    pi.set_defaults(func=cmd_info)


def cmd_info(args: argparse.Namespace) -> int:
    """``voxwarp info INPUT``: dims, dtype, spacing, value range, histogram."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.io.fields import field_info, field_summary, is_field_file, load_transform
    from voxwarp.io.volumes import dicom_series, volume_info, volume_summary
    from voxwarp.scene import Scene

    # a registration result, not a volume (unless a time point or channel is picked)
    picked = any(getattr(args, k, None) is not None for k in ("frame_index", "channel"))
    if is_field_file(args.input) and not picked:
        warps = load_transform(args.input, convention=args.field_convention)
        stats = [_field_jacobian(w) for w in warps]
        if args.json:
            infos = [field_info(w) for w in warps]
            for info, st in zip(infos, stats, strict=True):
                if st is not None:
                    info["jacobian_determinant"] = dataclasses.asdict(st)
            print(json.dumps(infos, indent=2))
            return 0
        print(field_summary(warps))
        for i, st in enumerate(stats):
            if st is not None:
                print(f"[{i}] {st.line()} (central differences on the nodes)")
        return 0
    # info shows the file's values: padding kept
    obj = load_input(args.input, keep_padding=True, **ropt.load_options(args))
    vol = obj.volume if isinstance(obj, Scene) else obj
    series = dicom_series(args.input) if os.path.isdir(args.input) else []
    if args.json:
        info = volume_info(vol)
        if series:
            info["dicom_series"] = [dataclasses.asdict(s) for s in series]
        print(json.dumps(info, indent=2))
        return 0
    print(volume_summary(vol))
    if len(series) > 1:
        chosen = str(getattr(args, "series", None) or 1)
        print("DICOM series in this folder (choose with --series N or --series UID):")
        for s in series:
            mark = "*" if chosen in (str(s.index), s.uid) else " "
            print(f" {mark} {s.line()}")
    return 0


def _field_jacobian(warp: Any) -> Any:
    """:class:`~voxwarp.core.jacobian.JacobianStats` of a displacement field's nodes
    (central differences, as ITK's filter), or None for another warp."""
    from voxwarp.core.jacobian import JacobianStats, field_determinant
    from voxwarp.deform.fields.displacement import DisplacementFieldWarp

    if not isinstance(warp, DisplacementFieldWarp) or min(warp.shape) < 2:
        return None
    det = field_determinant(warp.displacements, warp.affine)
    return JacobianStats.of(det, warp.affine)
