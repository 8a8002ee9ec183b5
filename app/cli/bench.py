"""``voxwarp bench``: the benchmarks' parsers and commands (``bench render``,
``massspring``, ``startup``, ``chainmail``; the heavier ones define their own options in
:mod:`voxwarp.bench` and are added only when a ``bench`` command runs)."""

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
from voxwarp.core.checks import int_list
from voxwarp.core.checks import positive_int as _positive_int
from voxwarp.inputs import load_input


def add_parser(sub: Any, *, bench: bool = True) -> None:
    """Add ``bench`` and its sub-commands to the ``voxwarp`` sub-commands; ``bench=False``
    leaves out the heavy ones (:func:`_add_heavy_bench_parsers`)."""
    pb = sub.add_parser("bench", help="benchmarks")
    bsub = pb.add_subparsers(dest="bench", required=True)
    pbr = bsub.add_parser("render", help="raycaster timings vs VTK and no-skipping")
    pbr.add_argument(
        "input",
        nargs="?",
        help="volume (default: the standard run: the real CT upsampled to 256³, a dense CT-like"
        " phantom and the bundled MRI)",
    )
    pbr.add_argument("--input", dest="input_file", metavar="FILE", help="same as INPUT")
    pbr.add_argument("--view", type=_view, help=ropt.VIEW_HELP)
    pbr.add_argument("--size", type=_size, default=(512, 512))
    pbr.add_argument("--frames", type=int, default=10)
    pbr.add_argument("--warmup", type=int, default=2)
    pbr.add_argument("--step", type=float, default=1.0)
    pbr.add_argument(
        "--tf", help=TF_HELP + " (default: suits the bench volume; standard run: sparse)"
    )
    pbr.add_argument("--no-vtk", action="store_true", help="skip the VTK references")
    pbr.add_argument("--markdown", metavar="FILE", help="also write the table to FILE")
    pbr.set_defaults(func=cmd_bench)
    pbm = bsub.add_parser("massspring", help="mass-spring steps/s: numpy, GPU and taichi")
    pbm.add_argument(
        "--sizes",
        type=_sizes,
        default=(16, 32, 64, 128),
        metavar="N,N,...",
        help="grids of N³ elements (default 16,32,64,128)",
    )
    pbm.add_argument(
        "--steps",
        type=_positive_int,
        default=50,
        metavar="N",
        help="steps per timed block (fewer where a block would take over 2 s)",
    )
    pbm.add_argument("--repeats", type=_positive_int, default=5, help="timed blocks per solver")
    pbm.add_argument("--no-taichi", action="store_true", help="skip the taichi reference")
    pbm.add_argument("--no-numpy", action="store_true", help="skip the numpy solver")
    pbm.add_argument(
        "--render",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="also time deformed vs undeformed dvr through the offset warp (default on)",
    )
    pbm.add_argument(
        "--frames", type=_positive_int, default=10, help="timed frames per render (default 10)"
    )
    pbm.add_argument("--markdown", metavar="FILE", help="also write the table to FILE")
    pbm.set_defaults(func=cmd_bench_massspring)
    pbs = bsub.add_parser(
        "startup",
        help="start-up time of voxwarp --help, import voxwarp and a whole render of the"
        " stent sample vs python",
    )
    pbs.add_argument("--repeats", type=_positive_int, default=5, help="runs per case")
    pbs.add_argument("--markdown", metavar="FILE", help="also write the table to FILE")
    pbs.set_defaults(func=cmd_bench_startup)
    pbc = bsub.add_parser(
        "chainmail", help="3D ChainMail: time to settle a local and a large drag vs grid size"
    )
    pbc.add_argument(
        "--sizes",
        type=_sizes,
        default=(16, 32, 64, 128),
        metavar="N,N,...",
        help="grids of N³ elements (default 16,32,64,128)",
    )
    pbc.add_argument(
        "--repeats", type=_positive_int, default=5, help="timed moves per solver (default 5)"
    )
    pbc.add_argument("--no-gpu", action="store_true", help="skip the GPU backend")
    pbc.add_argument("--markdown", metavar="FILE", help="also write the table to FILE")
    pbc.set_defaults(func=cmd_bench_chainmail)
    if bench:
        _add_heavy_bench_parsers(bsub)


def cmd_bench(args: argparse.Namespace) -> int:
    """``voxwarp bench render``: timings against references (see voxwarp.bench.render);
    without an input the standard run: a sparse and two dense cases."""
    from voxwarp.bench.render import RenderCase, bench_render_cases, standard_cases
    from voxwarp.core.files import atomic_write_text

    path = args.input_file or args.input
    if path:
        obj = load_input(path)
        vol = getattr(obj, "volume", obj)
        cases = [RenderCase("", vol, _tf_arg(args.tf, vol), ("dvr", "mip"))]
    else:
        cases = standard_cases()
        if args.tf:  # applies to the sparse case only: the dense ones define their TF
            cases[0].transfer_function = _tf_arg(args.tf, cases[0].volume)
    reports = bench_render_cases(
        cases,
        size=args.size,
        frames=args.frames,
        warmup=args.warmup,
        use_vtk=not args.no_vtk,
        step=args.step,
        view=args.view,
        log=lambda s: print(s, file=sys.stderr),
    )
    command = (
        "voxwarp " + " ".join(sys.argv[1:])
        if sys.argv[0].endswith("voxwarp")
        else ("voxwarp bench render")
    )
    text = "\n".join(report.markdown(command) for report in reports)
    print(text)
    for report in reports:
        for mode in ("dvr", "mip"):
            ratio = report.ratio("VTK fixed-point (CPU)", mode)
            if ratio is not None:
                print(
                    f"{report.label or report.volume} {mode}: voxwarp is {ratio:.2f}x the"
                    " speed of VTK's fixed-point raycaster"
                )
    if args.markdown:
        atomic_write_text(Path(args.markdown), text)
    return 0


#: ``--sizes`` of ``bench massspring`` / ``bench chainmail``: element grids per axis
_sizes = int_list(2, 128, "size", "16,32,64")


def cmd_bench_massspring(args: argparse.Namespace) -> int:
    """``voxwarp bench massspring``: solver steps/s (see voxwarp.bench.massspring)."""
    from voxwarp.bench.massspring import bench_massspring
    from voxwarp.core.files import atomic_write_text

    report = bench_massspring(
        args.sizes,
        steps=args.steps,
        repeats=args.repeats,
        use_taichi=not args.no_taichi,
        use_numpy=not args.no_numpy,
        log=lambda s: print(s, file=sys.stderr),
    )
    command = (
        "voxwarp " + " ".join(sys.argv[1:])
        if sys.argv[0].endswith("voxwarp")
        else "voxwarp bench massspring"
    )
    text = report.markdown(command)
    print(text)
    for n in report.sizes:
        ratio = report.ratio(n, "gpu", "taichi")
        if ratio is not None:
            print(f"{n}³: the GPU solver runs {ratio:.2f}x the steps/s of taichi on the CPU")
        ratio = report.ratio(n, "gpu", "taichi-min")
        if ratio is not None:
            print(f"{n}³: the GPU solver runs {ratio:.2f}x the minimal taichi kernel's steps/s")
    if args.render:
        from voxwarp.bench.render import bench_warp_render

        warp_report = bench_warp_render(
            frames=args.frames, warmup=2, log=lambda s: print(s, file=sys.stderr)
        )
        warp_text = warp_report.markdown(command)
        print(warp_text)
        cost = warp_report.ratio("offset warp, baked")
        if cost is not None:
            print(f"deformed dvr (offset warp, baked inverse) costs {cost:.2f}x undeformed")
        text += "\n" + warp_text
    if args.markdown:
        atomic_write_text(Path(args.markdown), text)
    return 0


def cmd_bench_startup(args: argparse.Namespace) -> int:
    """``voxwarp bench startup``: start-up time of the command line (voxwarp.bench.startup)."""
    from voxwarp.bench.startup import bench_startup, markdown
    from voxwarp.core.files import atomic_write_text

    text = markdown(bench_startup(args.repeats), f"voxwarp bench startup --repeats {args.repeats}")
    print(text)
    if args.markdown:
        atomic_write_text(Path(args.markdown), text)
    return 0


def cmd_bench_chainmail(args: argparse.Namespace) -> int:
    """``voxwarp bench chainmail``: time to settle one drag (see voxwarp.bench.chainmail)."""
    from voxwarp.bench.chainmail import bench_chainmail
    from voxwarp.core.files import atomic_write_text

    report = bench_chainmail(
        args.sizes,
        repeats=args.repeats,
        use_gpu=not args.no_gpu,
        log=lambda s: print(s, file=sys.stderr),
    )
    command = (
        "voxwarp " + " ".join(sys.argv[1:])
        if sys.argv[0].endswith("voxwarp")
        else "voxwarp bench chainmail"
    )
    text = report.markdown(command)
    print(text)
    if args.markdown:
        atomic_write_text(Path(args.markdown), text)
    return 0


def _add_heavy_bench_parsers(bsub: Any) -> None:
    """``bench wires|lattice|interactive|fields|scale|all``: their modules define their options
    (and load numpy, numba, ...), so the parser adds them only when a ``bench`` command runs."""
    from voxwarp.bench.all import add_bench_all_parser
    from voxwarp.bench.fields import add_bench_fields_parser
    from voxwarp.bench.interactive import add_bench_interactive_parser
    from voxwarp.bench.lattice import add_bench_lattice_parser
    from voxwarp.bench.scale import add_bench_scale_parser
    from voxwarp.bench.segments import add_bench_segments_parser
    from voxwarp.bench.slices import add_bench_slices_parser
    from voxwarp.bench.wire_ends import add_bench_wire_ends_parser
    from voxwarp.bench.wire_tables import add_bench_wire_tables_parser
    from voxwarp.bench.wires import add_bench_wires_parser

    add_bench_wires_parser(bsub)
    add_bench_wire_tables_parser(bsub)
    add_bench_wire_ends_parser(bsub)
    add_bench_lattice_parser(bsub)
    add_bench_interactive_parser(bsub)
    add_bench_fields_parser(bsub)
    add_bench_scale_parser(bsub)
    add_bench_segments_parser(bsub)
    add_bench_slices_parser(bsub)
    add_bench_all_parser(bsub)


def wants_bench(argv: Sequence[str] | None) -> bool:
    """Whether ``argv`` (default ``sys.argv[1:]``) runs a ``bench`` command."""
    args = list(sys.argv[1:] if argv is None else argv)
    return bool(args) and args[0] == "bench"
