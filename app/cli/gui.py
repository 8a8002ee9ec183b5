"""``voxwarp gui`` and ``voxwarp demo NAME --gui``: the commands that open the desktop window.

``voxwarp gui [INPUT] [--screenshot PATH]`` opens the desktop window on INPUT (a volume
file, a scene JSON or ``sample:NAME``; default the bundled sample). With
``--screenshot`` it waits for the first frame, saves a picture of the whole window and
quits (for scripts and checks). ``--interactive-downsample N`` draws the frames taken
while the user interacts from the volume reduced to 1/N per axis (the scene's
``interactive_downsample``). Without a display it renders headless instead
(``voxwarp demo``) and says so, unless ``--screenshot`` asked for the window.

This is the one door from the command line up to ``voxwarp.ui``: :mod:`voxwarp.ui.app`
(and with it Qt) is imported inside the commands, only when a window opens; the
import-linter contracts in pyproject.toml name this door.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from voxwarp.cli import demo
from voxwarp.cli.options import CliOptionError, add_allow_dir_arg, add_memory_budget_arg
from voxwarp.cli.render_options import add_series_arg
from voxwarp.core.checks import (
    MAX_INTERACTIVE_DOWNSAMPLE,
    image_size,
    interactive_downsample_arg,
)
from voxwarp.core.extras import require
from voxwarp.io.samples import DEFAULT_SAMPLE
from voxwarp.teaching import DEMOS
from voxwarp.teaching.tour import read_tour


def has_display() -> bool:
    """Whether a window can open: an X11 or a Wayland display is set."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _demo_args(out: str) -> argparse.Namespace:
    """The options of ``voxwarp demo -o OUT`` (the headless fallback of ``gui``)."""
    parser = argparse.ArgumentParser(prog="voxwarp")
    demo.add_parser(parser.add_subparsers())
    return parser.parse_args(["demo", "-o", out])


def cmd_gui(args: argparse.Namespace) -> int:
    """``voxwarp gui``: the desktop window (see the module docstring)."""
    if not has_display():
        if args.screenshot:
            raise CliOptionError(
                "gui --screenshot needs a display and none is set ($DISPLAY is empty); run"
                " it under a virtual X server: xvfb-run -a voxwarp gui --screenshot PATH"
            )
        print(
            "voxwarp: no display ($DISPLAY is not set), so no window: rendering the sample"
            " headless into out/ instead (voxwarp demo -o out)",
            file=sys.stderr,
        )
        return demo.cmd_demo(_demo_args(args.fallback_out))
    require("gui", "voxwarp gui")
    # Qt: only when a window opens (see the module docstring)
    from voxwarp.ui.app import run_gui

    pick = {k: getattr(args, k) for k in ("frame_index", "channel") if getattr(args, k) is not None}
    return run_gui(
        args.input,
        screenshot=args.screenshot,
        size=args.size,
        tour=args.tour,
        series=args.series,
        interactive_downsample=args.interactive_downsample,
        **pick,
    )


def cmd_demo_gui(args: argparse.Namespace) -> int:
    """``voxwarp demo NAME --gui``: the teaching demo (figure sheet and tour, by
    :func:`voxwarp.cli.demo.cmd_demo`), then its guided step-through in the desktop window."""
    code = demo.cmd_demo(args)
    if code != 0 or not getattr(args, "gui", False) or args.input not in DEMOS:
        return code
    tour_path = Path(args.out) / f"{args.input}_tour.json"
    if not has_display():
        print(
            f"voxwarp: no display ($DISPLAY is not set), so no window; the tour is"
            f" {tour_path}: open it on a desktop with voxwarp gui --tour {tour_path}",
            file=sys.stderr,
        )
        return 0
    require("gui", "voxwarp demo --gui")
    # Qt: only when a window opens (see the module docstring)
    from voxwarp.ui.app import run_gui

    tour = read_tour(tour_path)
    first = next((str(s.scene) for s in tour.steps if s.scene is not None), None)
    return run_gui(first or f"sample:{DEFAULT_SAMPLE}", tour=str(tour_path))


def add_parser(sub: Any) -> None:
    """Add ``gui`` to the ``voxwarp`` sub-commands, and make ``demo`` (added before it)
    run :func:`cmd_demo_gui`, which opens the window for ``demo NAME --gui``."""
    pg = sub.add_parser("gui", help="open the desktop window (INPUT: volume, scene or sample:NAME)")
    pg.add_argument("input", nargs="?", default=f"sample:{DEFAULT_SAMPLE}")
    pg.add_argument(
        "--screenshot", metavar="PATH", help="save a PNG of the window after the first frame, quit"
    )
    pg.add_argument("--size", type=image_size, default=(1280, 820), help="window WxH")
    pg.add_argument(
        "--tour", metavar="FILE", help="step through a teaching demo's tour (NAME_tour.json)"
    )
    pg.add_argument(
        "--interactive-downsample",
        type=interactive_downsample_arg,
        metavar="N",
        help="draw the frames taken while you drag or orbit from the volume reduced to 1/N"
        f" per axis (1-{MAX_INTERACTIVE_DOWNSAMPLE}, over the same box; default: the"
        " scene's setting, else 1 = full); the view at rest, screenshots and exports stay at"
        " full resolution. The Volume panel's Interaction box changes it",
    )
    add_series_arg(pg)
    add_memory_budget_arg(pg)
    add_allow_dir_arg(pg)
    pg.add_argument("--fallback-out", default="out", help=argparse.SUPPRESS)
    pg.set_defaults(func=cmd_gui)
    sub.choices["demo"].set_defaults(func=cmd_demo_gui)
