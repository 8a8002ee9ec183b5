"""``--overlay`` and its options, shared by ``voxwarp slice`` and ``voxwarp render``.

``--overlay NAME`` (repeatable, or a comma list) draws what the warp chain does over
the picture. The names come from :data:`voxwarp.render.overlay_options.OVERLAYS` (one
place): ``jacobian`` (det J colour map, :mod:`voxwarp.render.jacobian_overlay`, with
``--overlay-opacity``), ``grid`` and ``glyphs`` (drawn by
:mod:`voxwarp.render.warp_overlays` on slices and :mod:`voxwarp.render.warp_meshes` in
3D, with ``--grid-spacing``, ``--glyph-spacing`` and ``--grid-plane``).
Importing this loads no numpy.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from voxwarp.cli.options import fraction_arg, mm_arg
from voxwarp.render.overlay_options import OVERLAYS

#: ``--overlay-opacity`` default (the det J colour at full |log2 det J|)
DEFAULT_OVERLAY_OPACITY = 0.6
#: ``--grid-plane`` choices (as voxwarp.core.warp_grid.GRID_PLANES).
GRID_PLANES: tuple[str, ...] = ("axial", "coronal", "sagittal", "all")


def overlay_arg(text: str) -> list[str]:
    """One ``--overlay`` value: a name of :data:`OVERLAYS` or a comma list of them."""
    names = [t.strip().lower() for t in text.split(",") if t.strip()]
    bad = [n for n in names if n not in OVERLAYS]
    if bad or not names:
        raise argparse.ArgumentTypeError(
            f"{text!r}: expected one or more of {', '.join(OVERLAYS)} (comma separated)"
        )
    return names


class _Extend(argparse.Action):
    """Append the names of each ``--overlay`` value, without repeats."""

    def __call__(self, parser: Any, namespace: Any, values: Any, option: Any = None) -> None:
        have = list(getattr(namespace, self.dest, None) or [])
        setattr(namespace, self.dest, have + [v for v in values if v not in have])


def add_overlay_args(p: argparse.ArgumentParser, three_d: bool = False) -> None:
    """``--overlay``, ``--overlay-opacity``, ``--grid-spacing`` and ``--glyph-spacing``
    (and ``--grid-plane``
    for the 3D ``render``)."""
    p.add_argument(
        "--overlay",
        dest="overlays",
        type=overlay_arg,
        action=_Extend,
        default=[],
        metavar="NAME[,NAME]",
        help="draw over the picture (repeatable or comma separated): jacobian (det J of"
        " the warp chain as a colour map on log2(det J): blue > 1 (shown shrunk), orange"
        " < 1 (shown enlarged), clear at 1, solid green folds (det J <= 0), with a legend;"
        " render: modes dvr, mip, minip, iso), grid (the rest-space"
        " grid carried by the warp chain, lines every --grid-spacing mm), glyphs (arrows"
        " of the displacement u = chain(x) - x, the vector an exported field holds, with a"
        " legend in mm)",
    )
    p.add_argument(
        "--overlay-opacity",
        type=fraction_arg("--overlay-opacity"),
        default=DEFAULT_OVERLAY_OPACITY,
        metavar="0..1",
        help=f"strength of the det J colours (default {DEFAULT_OVERLAY_OPACITY:g})",
    )
    p.add_argument(
        "--grid-spacing",
        type=mm_arg("--grid-spacing"),
        metavar="MM",
        help="grid line spacing in mm (default about 1/16 of the volume's largest side,"
        " at least 12 pixels on a slice, rounded to 1, 2 or 5 x 10^k mm)",
    )
    p.add_argument(
        "--glyph-spacing",
        type=mm_arg("--glyph-spacing"),
        metavar="MM",
        help="distance between glyph arrows in mm (default the grid spacing, doubled"
        " until it is at least 20 pixels on a slice)",
    )
    if three_d:
        p.add_argument(
            "--grid-plane",
            choices=GRID_PLANES,
            help="3D grid: the lines of one plane through the volume's centre (default"
            " the named plane that faces the camera most), or all: the 3D lattice;"
            " glyphs lie on that plane (axial for all)",
        )


def grid_spacing(args: argparse.Namespace, volume: Any, pixel_mm: float = 0.0) -> float:
    """``--grid-spacing``, or the default from the volume's box (on a slice of
    ``pixel_mm`` pixels, at least 12 pixels between lines)."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.core.warp_grid import MIN_CELL_PX, nice_spacing

    if args.grid_spacing is not None:
        return float(args.grid_spacing)
    return nice_spacing(*volume.bounds, at_least_mm=MIN_CELL_PX * pixel_mm)


def overlays(args: argparse.Namespace) -> tuple[str, ...]:
    """The overlay names of ``--overlay``, in order, no repeats."""
    return tuple(getattr(args, "overlays", None) or ())


def set_overlays(renderer: Any, scene: Any, args: argparse.Namespace) -> None:
    """Switch on the 3D overlays of ``args`` on a :class:`~voxwarp.render.raycaster.Renderer`
    for ``scene`` (a one-line error for a mode the overlay does not colour)."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.render.jacobian_overlay import JacobianOverlay, check_detj_mode

    if "jacobian" in overlays(args):
        check_detj_mode(scene.mode)
        renderer.jacobian_overlay = JacobianOverlay(opacity=args.overlay_opacity)


def legend_note(overlay_names: tuple[str, ...], size: tuple[int, int]) -> None:
    """One stderr note when the det J legend does not fit an image of ``size`` (W, H)."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.render.jacobian_overlay import legend_fits

    if "jacobian" in overlay_names and not legend_fits(*size):
        print(
            f"voxwarp: note: the det J legend needs a larger image than {size[0]}x{size[1]}"
            " pixels; give a smaller --pixel or a --size",
            file=sys.stderr,
        )


__all__ = [
    "GRID_PLANES",
    "OVERLAYS",
    "add_overlay_args",
    "grid_spacing",
    "legend_note",
    "overlay_arg",
    "overlays",
    "set_overlays",
]
