"""``voxwarp slice``: one slice plane of a (deformed) volume as an image.

INPUT is a volume (any format ``voxwarp render`` reads, ``sample:NAME`` too) or a scene
JSON; the deformation options are ``render``'s (``--massspring``/``--chainmail`` drags,
``--wires``, ``--lattice``, ``--displacement``), assembled by the same functions
(:func:`voxwarp.cli.deformation.prepare_deformation`,
:func:`voxwarp.cli.deformation.deformed_scene`).
The plane is sampled through the warp chain on the GPU
(:meth:`voxwarp.render.offscreen.OffscreenRenderer.render_slice`): the volume is never
resampled. Named planes follow the radiological layout (axial: the patient's left on
the image's right, anterior up); see :mod:`voxwarp.core.slice_plane`.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

from voxwarp.cli import render_options as ropt
from voxwarp.cli.compare_options import add_compare_args, with_comparison
from voxwarp.cli.deform_options import add_deform_args, add_field_args, add_wire_args
from voxwarp.cli.deformation import check_deform_options, deformed_scene, prepare_deformation
from voxwarp.cli.options import TF_HELP, WINDOW_HELP, add_volume_args, tf_arg, window_arg
from voxwarp.cli.overlay_options import add_overlay_args, legend_note, overlays
from voxwarp.core.checks import image_size
from voxwarp.core.orientation import axis_letters
from voxwarp.errors import InputError
from voxwarp.inputs import load_input

if TYPE_CHECKING:
    import numpy as np

_NAMES = ("axial", "coronal", "sagittal", "x", "y", "z")
PLANE_FORM = "axial, coronal, sagittal, x, y, z or X,Y,Z:NX,NY,NZ (a point and a normal, mm)"


def plane_arg(text: str) -> str:
    """``--plane``: a plane name or ``X,Y,Z:NX,NY,NZ`` (finite numbers, a non-zero normal)."""
    spec = text.strip().lower()
    if spec in _NAMES:
        return spec
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.core.slice_plane import split_point_normal

    parts = split_point_normal(spec)
    if parts is None or not all(map(math.isfinite, parts[0] + parts[1])):
        raise argparse.ArgumentTypeError(f"{text!r}: expected {PLANE_FORM}")
    if not any(parts[1]):
        raise argparse.ArgumentTypeError(f"{text!r}: the normal must not be 0,0,0")
    return spec


def _mm(what: str, positive: bool) -> Any:
    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            v = math.nan
        if not math.isfinite(v) or (positive and v <= 0) or v < 0:
            bound = "> 0" if positive else ">= 0"
            raise argparse.ArgumentTypeError(f"{what} must be a number of mm {bound}; got {text!r}")
        return v

    return parse


def _finite_mm(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"--at must be a finite number of mm; got {text!r}")
    return v


def add_parser(sub: Any) -> None:
    """Add ``slice`` to the ``voxwarp`` sub-commands (``sub``: their sub-parsers object)."""
    p = sub.add_parser(
        "slice",
        help="one slice plane of INPUT (volume or scene JSON), deformed, to an image",
        description="Samples one plane of INPUT through its warp chain (render's"
        " deformation options apply) and writes it as an image. Named planes are"
        " radiological for volumes with a patient orientation (axial: patient's left on"
        " the image's right, anterior up; coronal: left on the right, superior up;"
        " sagittal: anterior on the left, superior up); x, y, z otherwise. Prints the"
        " plane, its position, size and pixel size on stderr.",
    )
    p.add_argument("input")
    p.add_argument("-o", "--output", default="slice.png", help="PNG, TIFF or EXR by extension")
    p.add_argument(
        "--plane",
        type=plane_arg,
        metavar="NAME|X,Y,Z:NX,NY,NZ",
        help="axial, coronal, sagittal (patient orientation), x, y, z, or a point and a"
        " normal in world mm (default: axial, or z without an orientation)",
    )
    p.add_argument(
        "--at",
        type=_finite_mm,
        metavar="MM",
        help="position in mm along the plane's axis (named: world z/y/x; oblique: a shift"
        " from the point along the normal, turned so its largest component is positive);"
        " default the voxel centre nearest the centre of the deformed volume",
    )
    p.add_argument(
        "--slab",
        dest="slab_mm",
        type=_mm("--slab", positive=False),
        default=0.0,
        metavar="MM",
        help="slab thickness in mm combined by --mode (default 0: a thin slice)",
    )
    p.add_argument(
        "--mode",
        dest="slab_mode",
        choices=("mip", "minip", "average"),
        default="mip",
        help="how a slab's samples combine (default mip)",
    )
    p.add_argument("--interpolation", choices=("linear", "nearest"), default="linear")
    p.add_argument(
        "--look",
        choices=("window", "tf"),
        default="window",
        help="grey window/level (default) or the transfer function's colours",
    )
    p.add_argument(
        "--window",
        type=window_arg,
        metavar="NAME|LEVEL,WIDTH",
        help=WINDOW_HELP,
    )
    p.add_argument("--tf", help=TF_HELP + " (--look tf)")
    p.add_argument(
        "--show",
        choices=("deformed", "rest", "checkerboard", "difference", "blend"),
        default="deformed",
        help="the deformed volume (default), the rest state, a checkerboard of both,"
        " deformed minus rest, or a blend (--blend); with --fixed, 'rest' is the fixed"
        " image and the comparisons are against it",
    )
    add_compare_args(p, show=False)
    size = p.add_mutually_exclusive_group()
    size.add_argument(
        "--pixel",
        type=_mm("--pixel", positive=True),
        metavar="MM",
        help="pixel size in mm (default the volume's smallest voxel size); the image is"
        " sized to hold the deformed volume and its pixel grid runs through voxel"
        " centres, so a plane along the voxel axes at the default size samples the"
        " voxels themselves",
    )
    size.add_argument("--size", type=image_size, metavar="WxH", help="image size in pixels")
    p.add_argument(
        "--json",
        action="store_true",
        help="print the plane and its pixel -> world 4x4 matrix as JSON on stdout",
    )
    add_overlay_args(p)
    add_volume_args(p)
    add_deform_args(p)
    add_wire_args(p)
    add_field_args(p)
    p.set_defaults(func=cmd_slice)


def _compare_look(show: str) -> str | None:
    """The scene's 3D comparison look for a slice's ``--show`` (saved scenes keep it)."""
    return show if show in ("checkerboard", "difference", "blend") else None


def _base_scene(obj: Any, args: argparse.Namespace) -> Any:
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.scene import Scene

    tf = tf_arg(args.tf, obj.volume if isinstance(obj, Scene) else obj)
    if isinstance(obj, Scene):
        return obj if tf is None else obj.copy(transfer_function=tf)
    return Scene(obj, transfer_function=tf)


def resolve_plane_name(spec: str | None, space: str) -> str:
    """The plane to draw: ``spec`` (default axial, or z without an orientation); an
    anatomical name on a volume without one becomes its world axis, with a note."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.core.slice_plane import plane_for_space

    if spec is None:
        return "axial" if space == "RAS" else "z"
    axis = plane_for_space(spec, space)
    if axis != spec:
        print(
            f"voxwarp: note: the volume has no patient orientation; --plane {spec} is"
            f" the plane normal to its {axis} axis (--plane {axis})",
            file=sys.stderr,
        )
    return axis


def slice_plane(scene: Any, args: argparse.Namespace) -> tuple[Any, tuple[int, int]]:
    """The plane of ``--plane``/``--at`` framing the scene's deformed box and the image
    size (``--size``, or ``--pixel`` through :func:`fit_pixels`); an :class:`InputError`
    for a plane that misses the deformed volume."""
    import numpy as np

    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.core.slice_plane import PLANE_AXIS, aligned, fit_pixels, parse_plane, voxel_anchor
    from voxwarp.render.slice_grid import named_slice_grid

    lo, hi = (np.asarray(b, dtype=np.float64) for b in scene.deformed_bounds())
    name = resolve_plane_name(args.plane, scene.volume.space)
    if name in PLANE_AXIS:  # pixel centres on voxel centres (see named_slice_grid)
        plane, size = named_slice_grid(scene, name, at=args.at, size=args.size, pixel_mm=args.pixel)
        _check_hits(plane, lo, hi, name)
        return plane, size
    aspect = 1.0 if args.size is None else args.size[0] / args.size[1]
    plane = parse_plane(name, (lo, hi), at=args.at, aspect=aspect)
    _check_hits(plane, lo, hi, name)
    anchor = voxel_anchor(scene.volume, plane.center)
    if args.size is not None:
        return aligned(plane, args.size, anchor), args.size
    pixel = args.pixel if args.pixel is not None else float(min(scene.volume.spacing))
    return fit_pixels(plane, lo, hi, pixel, anchor=anchor)


def pixel_note(asked: float | None, used: float) -> None:
    """Warn (one line) when ``--pixel`` could not be kept: the image would exceed the
    slice side limit, so :func:`fit_pixels` chose coarser pixels."""
    from voxwarp.core.slice_plane import MAX_SLICE_PIXELS

    if asked is not None and abs(used - asked) > 1e-6 * asked:
        warnings.warn(
            f"--pixel {asked:g} mm would make the image over {MAX_SLICE_PIXELS} pixels a"
            f" side; using {used:.4g} mm pixels (give --pixel {used:.4g} or more)",
            stacklevel=2,
        )


def useful_slab(scene: Any, plane: Any, slab_mm: float) -> float:
    """``slab_mm`` clamped to the deformed box's extent across ``plane`` (twice the
    farthest box corner from it): samples beyond it see nothing, and the slab's
    fixed sample count would only spread thinner. Warns (one line) when it clamps."""
    import numpy as np

    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.deform.warp import box_corners

    lo, hi = (np.asarray(b, dtype=np.float64) for b in scene.deformed_bounds())
    reach = 2.0 * float(np.max(np.abs((box_corners(lo, hi) - plane.center) @ plane.normal)))
    if slab_mm <= reach:
        return slab_mm
    warnings.warn(
        f"--slab {slab_mm:g} mm is thicker than the deformed volume across the plane;"
        f" using {reach:.4g} mm, which holds all of it",
        stacklevel=2,
    )
    return reach


def _check_hits(plane: Any, lo: np.ndarray, hi: np.ndarray, spec: str) -> None:
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.deform.warp import box_corners

    axis = plane.scroll_axis
    span = box_corners(lo, hi) @ axis
    pos = float(plane.center @ axis)
    if span.min() <= pos <= span.max():
        return
    along = _axis_text(axis)
    raise InputError(
        f"--plane {spec} at {pos:g} mm misses the volume, which spans {span.min():g}.."
        f"{span.max():g} mm along {along}; give --at within that range"
    )


def _axis_text(axis: np.ndarray) -> str:
    import numpy as np

    k = int(np.argmax(np.abs(axis)))
    if np.isclose(abs(axis[k]), 1.0):
        return "xyz"[k]
    return "the normal (" + ", ".join(f"{v:.3g}" for v in axis) + ")"


def position_text(plane: Any, space: str) -> str:
    """The plane's position: ``S 12.5 mm`` (the anatomical letter of its side) for a
    named plane of an oriented volume, ``z 12.5 mm`` or ``12.5 mm along (n)`` otherwise."""
    import numpy as np

    pos = plane.position
    axis = plane.scroll_axis
    k = int(np.argmax(np.abs(axis)))
    if not np.isclose(abs(axis[k]), 1.0):
        return f"{pos:.4g} mm along the normal (" + ", ".join(f"{v:.3g}" for v in axis) + ")"
    if space == "RAS":
        return f"{axis_letters(k, pos * axis[k])} {abs(pos):.4g} mm"
    return f"{'xyz'[k]} {pos:.4g} mm"


def cmd_slice(args: argparse.Namespace) -> int:
    """``voxwarp slice INPUT -o slice.png``: one plane of the deformed volume."""
    import numpy as np

    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.core.window_presets import resolve_window
    from voxwarp.io.images import check_image_format, write_image
    from voxwarp.render.offscreen import OffscreenRenderer

    check_deform_options(args)
    ext = check_image_format(args.output)  # a bad -o fails before any work
    if args.look == "tf" and args.window is not None:
        raise InputError("--window sets the grey of --look window; drop it with --look tf")
    obj = load_input(args.input, **ropt.load_options(args))
    look = _compare_look(args.show)
    base = with_comparison(_base_scene(obj, args), args, look, strict=False)
    scene, pending = prepare_deformation(args, base)
    with OffscreenRenderer(16, 16) as r, r.current():
        with deformed_scene(args, scene, pending, r.ctx) as scene:
            plane, size = slice_plane(scene, args)
            pixel_note(args.pixel, plane.pixel_mm(size))
            image = r.render_slice(
                scene,
                plane,
                size=size,
                slab_mm=useful_slab(scene, plane, args.slab_mm),
                slab_mode=args.slab_mode,
                interpolation=args.interpolation,
                look=args.look,
                window=resolve_window(args.window, scene.volume),
                show=args.show,
                checker_mm=args.checker_mm,
                blend=args.blend,
                overlay=overlays(args),
                overlay_opacity=args.overlay_opacity,
                grid_spacing_mm=args.grid_spacing,
                glyph_spacing_mm=args.glyph_spacing,
            )
            for note in image.notes:  # what --overlay grid/glyphs drew
                print(f"slice: {note}", file=sys.stderr)
    rgba = image.rgba
    assert rgba is not None
    if ext in (".exr", ".hdr"):  # float formats: the same colours in [0, 1]
        rgba = rgba.astype(np.float32) / 255.0
    out = write_image(args.output, rgba)
    px = plane.pixel_mm(size)
    print(
        f"slice: {plane.name} at {position_text(plane, scene.volume.space)}, {size[0]}x{size[1]}"
        f" pixels of {px:.4g} mm -> {out}",
        file=sys.stderr,
    )
    ropt.spacing_notice(scene.volume, args)
    legend_note(overlays(args), size)
    if args.json:
        print(json.dumps(slice_json(plane, size, image.pixel_to_world, out), indent=2))
    else:
        print(out)
    return 0


def slice_json(plane: Any, size: tuple[int, int], matrix: np.ndarray, out: Path) -> dict:
    """``--json``: the plane, the image size and the pixel -> world matrix."""
    import numpy as np

    return {
        "output": str(out),
        "plane": plane.name,
        "position_mm": plane.position,
        "center": plane.center.tolist(),
        "right": plane.right.tolist(),
        "up": plane.up.tolist(),
        "normal": plane.normal.tolist(),
        "size": [int(size[0]), int(size[1])],
        "pixel_mm": plane.pixel_mm(size),
        "pixel_to_world": np.asarray(matrix, dtype=np.float64).tolist(),
        "pixel_to_world_note": "(col, row, 0, 1) -> world mm (RAS) of the centre of pixel"
        " [row, col], row 0 at the top",
    }
