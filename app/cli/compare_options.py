"""``--fixed FILE``, ``--show``, ``--blend``, ``--checker-size``: a registration's fixed
image compared with the moving (deformed) volume, for ``voxwarp render`` and
``voxwarp slice`` (see :mod:`voxwarp.core.comparison`)."""

from __future__ import annotations

import argparse
from typing import Any

from voxwarp.cli.options import fraction_arg, mm_arg
from voxwarp.errors import InputError

COMPARE_CHOICES = ("checkerboard", "difference", "blend")
FIXED_HELP = (
    "a registration's fixed image (any volume voxwarp reads, sample:NAME too, on its own"
    " grid): compared at the same world points with INPUT seen through its warps"
)


def add_compare_args(p: Any, *, show: bool) -> None:
    """Add ``--fixed``, ``--blend``, ``--checker-size`` (and ``--show`` for ``render``:
    ``slice`` has its own) to the parser ``p``."""
    p.add_argument("--fixed", metavar="FILE", help=FIXED_HELP)
    if show:
        p.add_argument(
            "--show",
            choices=COMPARE_CHOICES,
            help="with --fixed: checkerboard (default; 3D cells of --checker-size mm"
            " alternate moving and fixed), difference (|moving - fixed| through the"
            " transfer function) or blend (--blend)",
        )
    p.add_argument(
        "--blend",
        type=fraction_arg("--blend"),
        metavar="0..1",
        help="--show blend: the fixed (or rest) image's weight, 0 = moving, 1 = fixed"
        " (default 0.5)",
    )
    p.add_argument(
        "--checker-size",
        dest="checker_mm",
        type=mm_arg("--checker-size"),
        metavar="MM",
        help="--show checkerboard: cell size in world mm (default with --fixed: about 1/8"
        " of the fixed image's longest side; slices without --fixed: 32-pixel tiles)",
    )


def load_fixed(spec: str) -> Any:
    """The Volume of ``--fixed`` (a scene JSON gives its volume)."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.inputs import load_input
    from voxwarp.scene import Scene

    obj = load_input(spec)
    return obj.volume if isinstance(obj, Scene) else obj


def with_comparison(
    scene: Any, args: argparse.Namespace, show: str | None, *, strict: bool = True
) -> Any:
    """``scene`` with ``--fixed`` (loaded) and the comparison settings; ``show`` the
    3D look (None: the scene's, or checkerboard). Without ``--fixed`` a scene's own
    fixed image (scene JSON) keeps its settings but for those given; without either,
    ``strict`` refuses a ``show``."""
    fixed = load_fixed(args.fixed) if args.fixed is not None else scene.fixed
    if fixed is None:
        if show is not None and strict:
            raise InputError(f"--show {show} compares with a fixed image; give --fixed FILE")
        return scene
    old = scene.comparison.settings_dict() if scene.comparison is not None else {}
    given = {"show": show, "blend": args.blend, "checker_mm": args.checker_mm}
    settings = {**old, **{k: v for k, v in given.items() if v is not None}}
    return scene.copy(
        fixed=fixed,
        compare=settings.get("show", "checkerboard"),
        blend=settings.get("blend", 0.5),
        checker_mm=settings.get("checker_mm"),
    )
