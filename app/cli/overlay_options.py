"""``--overlay`` and ``--overlay-opacity``: what ``render`` and ``slice`` draw over the
image. The names come from :data:`voxwarp.render.overlay_options.OVERLAYS` (one place);
``--overlay`` repeats or takes a comma list (``--overlay jacobian``)."""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any

from voxwarp.render.overlay_options import OVERLAYS

#: ``--overlay-opacity`` default (the det J colour at full |log2 det J|)
DEFAULT_OVERLAY_OPACITY = 0.6


def overlay_arg(text: str) -> list[str]:
    """One ``--overlay`` value: a name or a comma list of names of :data:`OVERLAYS`."""
    names = [n.strip().lower() for n in text.split(",") if n.strip()]
    bad = [n for n in names if n not in OVERLAYS]
    if bad or not names:
        raise argparse.ArgumentTypeError(
            f"{text!r}: expected one or more of {', '.join(OVERLAYS)} (comma list)"
        )
    return names


def opacity_arg(text: str) -> float:
    """``--overlay-opacity``: a number in 0..1."""
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not (math.isfinite(v) and 0.0 <= v <= 1.0):
        raise argparse.ArgumentTypeError(f"--overlay-opacity must be in 0..1; got {text!r}")
    return v


def add_overlay_args(p: Any) -> None:
    """Add ``--overlay`` (repeatable) and ``--overlay-opacity`` to parser ``p``."""
    p.add_argument(
        "--overlay",
        type=overlay_arg,
        action="append",
        default=[],
        metavar="NAME[,NAME]",
        help="draw over the image (repeat or comma list): jacobian = det J of the warp"
        " chain as a colour map on log2(det J): blue > 1 (shown shrunk), orange < 1"
        " (shown enlarged), clear at 1, solid green folds (det J <= 0), with a legend"
        " (render: modes dvr, mip, minip, iso)",
    )
    p.add_argument(
        "--overlay-opacity",
        type=opacity_arg,
        default=DEFAULT_OVERLAY_OPACITY,
        metavar="0..1",
        help=f"strength of the overlay colours (default {DEFAULT_OVERLAY_OPACITY:g})",
    )


def overlays(args: argparse.Namespace) -> tuple[str, ...]:
    """The overlay names of ``args.overlay`` (lists of names), in order, no repeats."""
    out: list[str] = []
    for group in getattr(args, "overlay", None) or []:
        out += [n for n in group if n not in out]
    return tuple(out)


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
