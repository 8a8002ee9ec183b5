"""``voxwarp demo``: a teaching demo's figure sheet (``demo NAME``), or a volume rendered
in every mode and bent by a mass-spring drag and by a wire (``demo [INPUT]``, ``make run``
without a display). ``demo NAME --gui`` is completed by :mod:`voxwarp.cli.gui`."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from voxwarp.cli.deform_options import MASSSPRING_SETTLE_MAX_STEPS, MASSSPRING_SETTLE_TOL
from voxwarp.cli.options import TF_HELP, CliOptionError, add_allow_dir_arg, add_memory_budget_arg
from voxwarp.cli.options import tf_arg as _tf_arg
from voxwarp.cli.options import view_arg as _view
from voxwarp.core.checks import image_size as _size
from voxwarp.core.minip_hint import SLAB_MM, minip_advice
from voxwarp.core.modes import MODES
from voxwarp.inputs import load_input
from voxwarp.io.samples import DEFAULT_SAMPLE, suggested_transfer_function
from voxwarp.teaching import DEMO_TITLES, DEMOS


def add_parser(sub: Any) -> None:
    """Add ``demo`` to the ``voxwarp`` sub-commands (``sub``: their sub-parsers object)."""
    pd = sub.add_parser(
        "demo",
        help=f"teaching demo NAME ({', '.join(DEMOS)}): a figure sheet; or render a volume"
        " in every mode into a folder",
        description="voxwarp demo NAME writes the figure sheet of a teaching demo to"
        " OUT/NAME.png: "
        + "; ".join(f"{n}: {t}" for n, t in DEMO_TITLES.items())
        + ". voxwarp demo [INPUT] (a volume, scene JSON or sample:NAME; default the bundled"
        " real CT) renders it in every mode, bent by a mass-spring drag and by a wire.",
    )
    add_memory_budget_arg(pd)
    add_allow_dir_arg(pd)
    pd.add_argument(
        "input",
        nargs="?",
        metavar="NAME|INPUT",
        help=f"a teaching demo ({', '.join(DEMOS)}) or a volume (default: the bundled real CT)",
    )
    pd.add_argument(
        "-o", "--output", "--out", dest="out", default="out", help="output folder (default out)"
    )
    pd.add_argument("--size", type=_size, default=(512, 512), help="INPUT: image WxH")
    pd.add_argument("--tf", help=TF_HELP + " (default: suits the sample)")
    pd.add_argument(
        "--view", type=_view, help="INPUT: view (default anterior for oriented volumes, else -y)"
    )
    pd.add_argument(
        "--quick",
        action="store_true",
        help="NAME: small volumes, grids and images (seconds instead of a minute)",
    )
    pd.add_argument(
        "--gui",
        action="store_true",
        help="NAME: also write OUT/NAME_tour.json, the steps of a guided walk through the"
        " model (title, explanation, scene JSON per step) for the desktop GUI",
    )
    pd.set_defaults(func=cmd_demo)


def cmd_demo(args: argparse.Namespace) -> int:
    """``voxwarp demo NAME``: a teaching demo's figure sheet (:mod:`voxwarp.teaching.demos`);
    ``voxwarp demo [INPUT]``: render INPUT (default the bundled sample) in every mode
    into a folder."""
    if args.input in DEMOS:
        return _teaching_demo(args)
    if args.quick or args.gui:
        raise CliOptionError(
            f"--quick and --gui are options of the teaching demos ({', '.join(DEMOS)}),"
            " e.g. voxwarp demo massspring --quick"
        )
    if (
        args.input is not None
        and not args.input.startswith("sample:")
        and not Path(args.input).exists()
    ):
        raise CliOptionError(
            f"{args.input!r} is neither a demo ({', '.join(DEMOS)}) nor a volume file or"
            " folder; e.g. voxwarp demo massspring, or voxwarp demo sample:fish"
        )
    return _demo_volume(args)


def _teaching_demo(args: argparse.Namespace) -> int:
    """``voxwarp demo NAME``: write the figure sheet (and with --gui the tour)."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.teaching.demos import run_demo

    res = run_demo(
        args.input,
        args.out,
        quick=args.quick,
        tour=args.gui,
        log=lambda s: print(s, file=sys.stderr),
    )
    for path in res.figures:
        print(path)
    if res.tour is not None:
        print(res.tour)
        print(
            f"voxwarp: step through the demo in the desktop GUI with: voxwarp gui --tour"
            f" {res.tour}",
            file=sys.stderr,
        )
    return 0


def _demo_volume(args: argparse.Namespace) -> int:
    """``voxwarp demo [INPUT]``: render INPUT in every mode into a folder."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.io.images import write_image
    from voxwarp.render.offscreen import OffscreenRenderer
    from voxwarp.scene import Scene

    spec = args.input or f"sample:{DEFAULT_SAMPLE}"
    obj = load_input(spec)
    vol = obj.volume if isinstance(obj, Scene) else obj
    out = Path(args.out)
    tf = _tf_arg(args.tf, vol)
    if tf is None:
        # samples: a function tuned to them; files: the modality's default (None)
        tf = suggested_transfer_function(vol.name) if spec.startswith("sample:") else None
    paths = []
    with OffscreenRenderer(*args.size) as r:
        for mode in MODES:
            scene = Scene(vol, mode=mode, transfer_function=tf, view=args.view, zoom=1.3)
            if mode == "minip":
                scene = _minip_slab(scene)
            img = r.render(scene)
            paths.append(write_image(out / f"{vol.name}_{mode}.png", img))
        scene.save(out / f"{vol.name}_scene.json")
        # the point of voxwarp: the same volume bent at render time, not resampled
        dvr = Scene(vol, mode="dvr", transfer_function=tf, view=args.view, zoom=1.3)
        dvr.warps.append(_demo_bend(vol))
        paths.append(write_image(out / f"{vol.name}_dvr_massspring.png", r.render(dvr)))
        dvr.save(out / f"{vol.name}_massspring_scene.json")
        wired = Scene(vol, mode="dvr", transfer_function=tf, view=args.view, zoom=1.3)
        wire_warp = _demo_wire(vol, wired.resolved_camera().rotation[:, 2])
        if wire_warp is not None:
            wired.warps.append(wire_warp)
            paths.append(write_image(out / f"{vol.name}_dvr_wires.png", r.render(wired)))
            wired.save(out / f"{vol.name}_wires_scene.json")
    for p in paths:
        print(p)
    return 0


def _minip_slab(scene: Any) -> Any:
    """``scene`` cut to a slab across the view when its minIP would be nearly all dark
    (:func:`voxwarp.core.minip_hint.minip_advice`: the air on the way is every ray's
    minimum), with one line on stderr saying so."""
    back = scene.resolved_camera().rotation[:, 2]
    box = scene.ray_bounds()
    advice = minip_advice(scene.volume, scene.window, back, box)
    if advice is None:
        return scene
    print(
        f"voxwarp: demo: minip through a {SLAB_MM:g} mm slab across the view (through the"
        f" whole {advice.thickness:.0f} mm it is {advice.share:.0%} dark)",
        file=sys.stderr,
    )
    return scene.copy(clip_box=advice.slab_box(box))


def _demo_bend(vol: Any) -> Any:
    """A settled mass-spring bend of ``vol``: an 8³ grid, the bottom quarter (lowest z)
    fixed, the centre elements of the top two layers dragged sideways by 30% of the box
    width."""
    # loads scipy: only when used
    from voxwarp.deform import ElementGrid, MassSpring

    grid = ElementGrid(vol, shape=(8, 8, 8), anchor="corners")
    ms = MassSpring(grid, integrator="semi-implicit", shear=True)
    z = grid.rest_positions[..., 2]
    ms.fix(z < grid.lo[2] + 0.25 * (grid.hi[2] - grid.lo[2]))
    drag = 0.3 * float(grid.hi[0] - grid.lo[0])
    ms.move([(i, j, k) for i in (3, 4) for j in (3, 4) for k in (6, 7)], (drag, 0.0, 0.0))
    ms.settle(max_steps=MASSSPRING_SETTLE_MAX_STEPS, tol=MASSSPRING_SETTLE_TOL)
    return ms.warp()  # a CPU model: nothing to release


def _demo_wire(vol: Any, view: Any) -> Any:
    """A wire bend of ``vol`` laid where it is safe (:mod:`voxwarp.teaching.auto_wire`:
    along the largest object's principal axis, ends outside it, bent across ``view``),
    built; None, with one line on stderr saying why, when no object stands out."""
    # loads scipy: only when used
    from voxwarp.deform.wires.field import WireDeformer
    from voxwarp.teaching.auto_wire import auto_wire

    auto = auto_wire(vol, view)
    print(f"voxwarp: demo: {auto.message}", file=sys.stderr)
    if auto.wire is None:
        return None
    wd = WireDeformer(vol, [auto.wire], field_scale=2)
    wd.build()
    return wd.warp()
