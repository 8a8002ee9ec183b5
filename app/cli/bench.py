"""``voxwarp bench``: this machine's frame rates (``bench render``, and ``slices`` and
``interactive``, whose options their modules in :mod:`voxwarp.bench` define and which are
added only when a ``bench`` command runs). The peer comparisons and studies are the lab's
(``python -m benchmarks NAME`` from a checkout); their old names here say so in one line."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from voxwarp.cli import render_options as ropt
from voxwarp.cli.options import TF_HELP
from voxwarp.cli.options import tf_arg as _tf_arg
from voxwarp.cli.options import view_arg as _view
from voxwarp.core.checks import image_size as _size
from voxwarp.core.files import atomic_write_text
from voxwarp.inputs import load_input

#: ``voxwarp bench`` commands that moved to the lab in the checkout (``benchmarks/``)
MOVED_BENCHMARKS = (
    "massspring",
    "startup",
    "chainmail",
    "wires",
    "wire-tables",
    "wire-ends",
    "lattice",
    "fields",
    "scale",
    "segments",
    "all",
)


def add_parser(sub: Any, *, bench: bool = True) -> None:
    """Add ``bench`` and its sub-commands to the ``voxwarp`` sub-commands; ``bench=False``
    leaves out the heavy ones (:func:`_add_heavy_bench_parsers`)."""
    pb = sub.add_parser("bench", help="benchmarks")
    bsub = pb.add_subparsers(dest="bench", required=True)
    pbr = bsub.add_parser("render", help="raycaster timings vs no-skipping")
    add_render_bench_args(pbr)
    pbr.add_argument(
        "--no-vtk", action="store_true", help="no effect: VTK is in 'python -m benchmarks render'"
    )
    pbr.add_argument(
        "--deformed", action="store_true", help="also time dvr through a mass-spring offset warp"
    )
    pbr.add_argument(
        "--grid-margin",
        type=float,
        metavar="MM",
        help="with --deformed: also time the baked warp on an element grid padded by MM"
        " beyond the volume's box (the cost of a grid margin, same run)",
    )
    pbr.add_argument("--markdown", metavar="FILE", help="also write the table to FILE")
    pbr.set_defaults(func=cmd_bench)
    for name in MOVED_BENCHMARKS:  # no option of theirs is parsed here ("\0": none is one)
        help_ = f"moved: python -m benchmarks {name} (from a checkout)"
        pmv = bsub.add_parser(name, help=help_, add_help=False, prefix_chars="\0")
        pmv.add_argument("rest", nargs="*")
        pmv.set_defaults(func=cmd_bench_moved)
    if bench:
        _add_heavy_bench_parsers(bsub)


def add_render_bench_args(p: argparse.ArgumentParser) -> None:
    """The options every render benchmark takes (``voxwarp bench render`` and the lab's
    ``python -m benchmarks render``): the volume, view, image size, frames, sample
    distance and transfer function."""
    p.add_argument(
        "input",
        nargs="?",
        help="volume (default: the standard run: the real CT upsampled to 256³, a dense CT-like"
        " phantom and the bundled MRI)",
    )
    p.add_argument("--input", dest="input_file", metavar="FILE", help="same as INPUT")
    p.add_argument("--view", type=_view, help=ropt.VIEW_HELP)
    p.add_argument("--size", type=_size, default=(512, 512))
    p.add_argument("--frames", type=int, default=10)
    p.add_argument("--warmup", type=int, default=2)
    p.add_argument("--step", type=float, default=1.0)
    p.add_argument(
        "--tf", help=TF_HELP + " (default: suits the bench volume; standard run: sparse)"
    )


def render_bench_cases(args: argparse.Namespace) -> list[Any]:
    """The cases a render benchmark times (:func:`add_render_bench_args`' options): the
    input volume alone, or without one the standard run (a sparse and two dense cases;
    ``--tf`` applies to the sparse one, the dense ones define their own)."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.bench.render import RenderCase, standard_cases

    path = args.input_file or args.input
    if path:
        obj = load_input(path)
        vol = getattr(obj, "volume", obj)
        return [RenderCase("", vol, _tf_arg(args.tf, vol), ("dvr", "mip"))]
    cases = standard_cases()
    if args.tf:
        cases[0].transfer_function = _tf_arg(args.tf, cases[0].volume)
    return cases


def cmd_bench(args: argparse.Namespace) -> int:
    """``voxwarp bench render``: this machine's frame rates (see voxwarp.bench.render);
    without an input the standard run: a sparse and two dense cases."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.bench.render import bench_render_cases

    if args.grid_margin is not None and not args.deformed:
        from voxwarp.errors import InputError

        raise InputError("--grid-margin times the deformed render: add --deformed")
    path = args.input_file or args.input
    cases = render_bench_cases(args)

    def log(message: str) -> None:
        print(message, file=sys.stderr)

    reports = bench_render_cases(
        cases,
        size=args.size,
        frames=args.frames,
        warmup=args.warmup,
        step=args.step,
        view=args.view,
        log=log,
    )
    command = (
        "voxwarp " + " ".join(sys.argv[1:])
        if sys.argv[0].endswith("voxwarp")
        else ("voxwarp bench render")
    )
    text = "\n".join(report.markdown(command) for report in reports)
    print(text)
    if args.deformed:
        # loaded when used: voxwarp --help stays light (see voxwarp.cli)
        from voxwarp.bench.render import bench_warp_render

        warp_report = bench_warp_render(
            cases[0].volume if path else None,  # None: the standard run's 256³ CT
            size=args.size,
            frames=args.frames,
            warmup=args.warmup,
            transfer_function=cases[0].transfer_function if path else None,
            margin=args.grid_margin,
            log=log,
        )
        text += "\n" + warp_report.print_summary(command)
    if args.markdown:
        atomic_write_text(Path(args.markdown), text)
    return 0


def cmd_bench_moved(args: argparse.Namespace) -> int:
    """A ``voxwarp bench`` command that moved to the lab: one line saying where, exit 2."""
    print(
        f"voxwarp: error: 'voxwarp bench {args.bench}' moved out of the installed package:"
        f" run 'python -m benchmarks {args.bench}' from a checkout of voxwarp",
        file=sys.stderr,
    )
    return 2


def _add_heavy_bench_parsers(bsub: Any) -> None:
    """``bench interactive|slices|detj|exports``: their modules define their options (and
    load numpy, numba, ...), so the parser adds them only when a ``bench`` command runs."""
    from voxwarp.bench.detj import add_bench_detj_parser
    from voxwarp.bench.exports import add_bench_exports_parser
    from voxwarp.bench.interactive import add_bench_interactive_parser
    from voxwarp.bench.slices import add_bench_slices_parser

    add_bench_interactive_parser(bsub)
    add_bench_slices_parser(bsub)
    add_bench_detj_parser(bsub)
    add_bench_exports_parser(bsub)


def wants_bench(argv: Sequence[str] | None) -> bool:
    """Whether ``argv`` (default ``sys.argv[1:]``) runs a ``bench`` command."""
    args = list(sys.argv[1:] if argv is None else argv)
    return bool(args) and args[0] == "bench"
