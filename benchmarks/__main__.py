"""``python -m benchmarks NAME [options]``: the lab's benchmarks, from a checkout.

Each sub-command keeps the options and the report of the ``voxwarp bench NAME`` it was;
``python -m benchmarks all --json FILE`` runs every one of them (each in a subprocess of
its own) and makes the whole table, the one command to run on a lent GPU. ``voxwarp
bench render|slices|interactive|detj`` stay installed (this machine's frame rates); their
sub-commands here run the same code.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Sequence

#: the sub-commands, in ``--help`` order
COMMANDS: tuple[str, ...] = (
    "render",
    "massspring",
    "startup",
    "chainmail",
    "wires",
    "wire-tables",
    "wire-ends",
    "lattice",
    "interactive",
    "fields",
    "scale",
    "segments",
    "support",
    "slices",
    "detj",
    "movie",
    "costs",
    "readme",
    "all",
)


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``python -m benchmarks`` (one sub-parser per benchmark)."""
    from benchmarks.all import add_bench_all_parser
    from benchmarks.chainmail import add_bench_chainmail_parser
    from benchmarks.costs import add_bench_costs_parser
    from benchmarks.costs_readme import add_bench_readme_parser
    from benchmarks.fields import add_bench_fields_parser
    from benchmarks.lattice import add_bench_lattice_parser
    from benchmarks.massspring import add_bench_massspring_parser
    from benchmarks.movie import add_bench_movie_parser
    from benchmarks.render import add_bench_render_parser
    from benchmarks.scale import add_bench_scale_parser
    from benchmarks.segments import add_bench_segments_parser
    from benchmarks.startup import add_bench_startup_parser
    from benchmarks.support import add_bench_support_parser
    from benchmarks.wire_ends import add_bench_wire_ends_parser
    from benchmarks.wire_tables import add_bench_wire_tables_parser
    from benchmarks.wires import add_bench_wires_parser
    from voxwarp.bench.detj import add_bench_detj_parser
    from voxwarp.bench.interactive import add_bench_interactive_parser
    from voxwarp.bench.slices import add_bench_slices_parser
    from voxwarp.cli.main import OneLineErrorParser

    p = OneLineErrorParser(
        prog="python -m benchmarks", description=__doc__.split("\n")[0].strip("`")
    )
    bsub = p.add_subparsers(dest="bench", required=True)
    add_bench_render_parser(bsub)
    add_bench_massspring_parser(bsub)
    add_bench_startup_parser(bsub)
    add_bench_chainmail_parser(bsub)
    add_bench_wires_parser(bsub)
    add_bench_wire_tables_parser(bsub)
    add_bench_wire_ends_parser(bsub)
    add_bench_lattice_parser(bsub)
    add_bench_interactive_parser(bsub)
    add_bench_fields_parser(bsub)
    add_bench_scale_parser(bsub)
    add_bench_segments_parser(bsub)
    add_bench_support_parser(bsub)
    add_bench_slices_parser(bsub)
    add_bench_detj_parser(bsub)
    add_bench_movie_parser(bsub)
    add_bench_costs_parser(bsub)
    add_bench_readme_parser(bsub)
    add_bench_all_parser(bsub)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run one benchmark (``argv`` default ``sys.argv[1:]``); a voxwarp error or a failed
    file operation is one line on stderr and exit status 2, as in ``voxwarp``."""
    from voxwarp.errors import VoxwarpError

    args = build_parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    with warnings.catch_warnings():
        warnings.simplefilter("default")
        try:
            return int(args.func(args) or 0)
        except VoxwarpError as exc:
            print(f"benchmarks: error: {exc}", file=sys.stderr)
            return 2
        except OSError as exc:
            where = f"{exc.filename}: " if exc.filename else ""
            print(f"benchmarks: error: {where}{exc.strerror or exc}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            return 130


if __name__ == "__main__":
    sys.exit(main())
