"""``voxwarp render INPUT -o out.png``: one image, headless, with every render and
deformation option (:mod:`voxwarp.cli.render_options`, :mod:`voxwarp.cli.deform_options`)."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from voxwarp.cli import render_options as ropt
from voxwarp.cli.compare_options import add_compare_args, with_comparison
from voxwarp.cli.deform_options import add_deform_args as _add_deform_args
from voxwarp.cli.deform_options import add_field_args as _add_field_args
from voxwarp.cli.deform_options import add_wire_args as _add_wire_args
from voxwarp.cli.deformation import check_deform_options as _check_deform_options
from voxwarp.cli.deformation import deformed_scene, prepare_deformation
from voxwarp.cli.options import TF_HELP, CliOptionError, window_pair_arg
from voxwarp.cli.options import add_volume_args as _add_volume_args
from voxwarp.cli.options import tf_arg as _tf_arg
from voxwarp.cli.options import view_arg as _view
from voxwarp.cli.overlay_options import (
    add_overlay_args,
    grid_spacing,
    legend_note,
    overlays,
    set_overlays,
)
from voxwarp.core.checks import image_size as _size
from voxwarp.core.modes import MODES
from voxwarp.inputs import load_input


def add_parser(sub: Any) -> None:
    """Add ``render`` to the ``voxwarp`` sub-commands (``sub``: their sub-parsers object)."""
    pr = sub.add_parser("render", help="render INPUT (volume or scene JSON) to an image")
    pr.add_argument("input")
    pr.add_argument("-o", "--output", default="out.png", help="PNG/EXR/TIFF by extension")
    pr.add_argument("--mode", choices=MODES)
    pr.add_argument("--projection", choices=("perspective", "orthographic"))
    pr.add_argument("--view", type=_view, help=ropt.VIEW_HELP)
    pr.add_argument("--size", type=_size, default=(512, 512), help="WxH pixels")
    pr.add_argument("--tf", help=TF_HELP)
    pr.add_argument("--step", type=float, help="sample distance in voxels (default 1)")
    pr.add_argument(
        "--window",
        type=window_pair_arg,
        metavar="NAME|LEVEL,WIDTH",
        help="grey window of the mip, minip, average and xray modes: a preset (CT in HU:"
        " lung, mediastinum, bone, brain; any volume: percentile) or LEVEL,WIDTH in data"
        " units, e.g. 40,400 (also LEVEL WIDTH: two numbers)",
    )
    pr.add_argument(
        "--iso",
        dest="iso_value",
        type=float,
        metavar="VALUE",
        help="isovalue for --mode iso, data units (default from the histogram: the split of"
        " object and background, on a CT the transfer function's surface above it; printed)",
    )
    pr.add_argument(
        "--flm-threshold",
        dest="flm_threshold",
        type=float,
        metavar="VALUE",
        help="threshold for --mode flm, data units: the first local maximum above it is"
        " shown (default as --iso, on a CT the lowest value the transfer function shows;"
        " printed)",
    )
    pr.add_argument("--zoom", type=float)
    pr.add_argument("--seed", type=int, help="jitter seed")
    pr.add_argument("--jitter", action=argparse.BooleanOptionalAction, default=None)
    pr.add_argument("--shading", action=argparse.BooleanOptionalAction, default=None)
    pr.add_argument(
        "--keep-padding",
        action="store_true",
        help="keep the padding outside a CT's field of view (default: shown as air)",
    )
    pr.add_argument("--save-scene", metavar="JSON", help="also write the scene JSON")
    pr.add_argument(
        "--marker", action="store_true", help="draw an orientation marker (bottom left)"
    )
    _add_volume_args(pr)
    ropt.add_render_options(pr)
    _add_deform_args(pr)
    _add_wire_args(pr)
    _add_field_args(pr)
    add_compare_args(pr, show=True)
    add_overlay_args(pr, three_d=True)
    pr.set_defaults(func=cmd_render)


def _scene_from_args(obj: Any, args: argparse.Namespace) -> Any:
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.core.window_presets import preset_window
    from voxwarp.scene import Scene

    volume = obj.volume if isinstance(obj, Scene) else obj
    tf = _tf_arg(args.tf, volume)
    if isinstance(args.window, str):  # a preset: its window for this volume
        args.window = list(preset_window(args.window, volume))
    if isinstance(obj, Scene):
        changes: dict[str, Any] = {}
        if tf is not None:
            changes["transfer_function"] = tf  # resolved by the scene, knowing the mode
        keys = ("mode", "projection", "view", "step", "window", "seed", "zoom")
        for key in (*keys, "iso_value", "flm_threshold"):
            val = getattr(args, key)
            if val is not None:
                changes[key] = val
        if args.jitter is not None:
            changes["jitter"] = args.jitter
        if args.shading is not None:
            changes["shading"] = args.shading
        if changes.keys() & {"view", "projection", "zoom"}:
            changes["camera"] = None
        return obj.copy(**changes)
    kw: dict[str, Any] = {
        "mode": args.mode or "dvr",
        "transfer_function": tf,  # None: the modality's default
        "view": args.view,
        "projection": args.projection or "perspective",
        "step": args.step if args.step is not None else 1.0,
        "window": args.window,
        "jitter": True if args.jitter is None else args.jitter,
        "seed": args.seed if args.seed is not None else 0,
        "shading": args.shading,
        "iso_value": args.iso_value,
        "flm_threshold": args.flm_threshold,
        "zoom": args.zoom if args.zoom is not None else 1.0,
    }
    return Scene(obj, **kw)


def _with_overlays(scene: Any, args: argparse.Namespace) -> Any:
    """``scene`` with the meshes of ``--overlay grid``/``glyphs`` added, seen by the
    camera of the scene without them (notes on stderr)."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.render.warp_meshes import camera_pixel_mm, facing_plane, overlay_meshes
    from voxwarp.render.warp_overlays import WARP_OVERLAYS

    wanted = [o for o in args.overlays if o in WARP_OVERLAYS]
    if not wanted:
        return scene
    spacing = grid_spacing(args, scene.volume)
    camera = scene.resolved_camera()
    plane = args.grid_plane or facing_plane(camera)
    pixel = camera_pixel_mm(camera, tuple(args.size))
    extra = overlay_meshes(scene, wanted, spacing, plane, pixel_mm=pixel)
    print(f"render: {', '.join(wanted)} every {spacing:g} mm ({plane})", file=sys.stderr)
    return scene.copy(meshes=[*scene.meshes, *extra], camera=camera)


def _check_distinct_outputs(args: argparse.Namespace) -> None:
    """``-o``, ``--save-scene`` and ``--save-camera`` must name different files (one
    would overwrite the other); checked before anything is rendered."""
    named = [
        (flag, getattr(args, attr, None))
        for flag, attr in (
            ("-o", "output"),
            ("--save-scene", "save_scene"),
            ("--save-camera", "save_camera"),
        )
    ]
    seen: dict[str, str] = {}
    for flag, value in named:
        if value is None:
            continue
        key = os.path.normcase(os.path.realpath(os.path.expanduser(os.fspath(value))))
        if key in seen:
            raise CliOptionError(
                f"{seen[key]} and {flag} both name {value}; give each output its own file"
                " (e.g. -o image.png --save-scene scene.json)"
            )
        seen[key] = flag


def cmd_render(args: argparse.Namespace) -> int:
    """``voxwarp render INPUT -o out.png``: render one image headless."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.io.images import check_image_format, write_image
    from voxwarp.render.offscreen import OffscreenRenderer

    _check_deform_options(args)
    ropt.check_render_options(args)
    _check_distinct_outputs(args)
    check_image_format(args.output)  # a bad -o fails before any work or other output
    obj = load_input(args.input, keep_padding=args.keep_padding, **ropt.load_options(args))
    base = with_comparison(_scene_from_args(obj, args), args, args.show)
    scene, pending = prepare_deformation(args, base)
    out = Path(args.output)
    dtype = "f4" if out.suffix.lower() in (".exr", ".hdr") else "u1"
    with OffscreenRenderer(*args.size, dtype=dtype) as r:
        # one frame: the per-cell octant distance maps (CPU-built) cost more than they
        # save on a single draw, so skip by 4³ blocks (the same image; docs/benchmarks.md);
        # likewise the gradient texture (a pass over every voxel) for shading
        r.renderer.cell_skipping = False
        r.renderer.gradient_texture = False
        set_overlays(r.renderer, scene, args)
        # the GPU backends run on the renderer's context (made current here)
        with r.current(), deformed_scene(args, scene, pending, r.ctx) as scene:
            img = r.render(_with_overlays(scene, args))
            if args.save_scene:  # inside: a GPU-owned field is read back to save it
                scene.save(args.save_scene)
    # what was chosen, once the image exists (a refused render prints only its error)
    print(scene.display_note(), file=sys.stderr)
    ropt.spacing_notice(scene.volume, args)
    legend_note(overlays(args), args.size)
    if args.marker:  # the orientation triad (R/L, A/P, S/I letters when oriented)
        # loaded when used: voxwarp --help stays light (see voxwarp.cli)
        from voxwarp.render.orientation_marker import draw_scene_marker

        draw_scene_marker(img, scene)
    write_image(out, img)
    ropt.save_camera(scene, args)
    if args.save_scene:
        print(f"scene: {args.save_scene}")
    print(out)
    return 0
