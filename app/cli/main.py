"""The ``voxwarp`` command: the top-level parser, built from one module per command
(each module of :mod:`voxwarp.cli` adds its command with ``add_parser(sub)``), and
:func:`main`, the entry point of the console script and of ``python -m voxwarp``."""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Sequence

from voxwarp.cli import (
    animate,
    demo,
    export_field,
    export_volume,
    gui,
    info,
    render,
    reproduce,
    samples,
)
from voxwarp.cli import bench as bench_command
from voxwarp.cli import slice as slice_command
from voxwarp.cli.bench import wants_bench
from voxwarp.cli.options import OneLineErrorParser, VersionAction, join_negative_views
from voxwarp.core import limits
from voxwarp.errors import VoxwarpError

#: ``voxwarp --help``'s description
DESCRIPTION = "The ``voxwarp`` command line: info, render, demo, samples, bench."


def build_parser(*, bench: bool = True) -> argparse.ArgumentParser:
    """The argument parser of the ``voxwarp`` command.

    ``bench=False`` leaves out the benchmarks whose modules are heavy to import (``bench
    wires``, ``lattice``, ``interactive``): :func:`main` does so unless a ``bench``
    command runs, which keeps ``voxwarp --help`` and every other command quick to start.
    """
    p = OneLineErrorParser(prog="voxwarp", description=DESCRIPTION)
    p.add_argument("--version", action=VersionAction)
    sub = p.add_subparsers(dest="command", required=True)
    info.add_parser(sub)
    render.add_parser(sub)
    animate.add_parser(sub)
    export_field.add_parser(sub)
    slice_command.add_parser(sub)
    export_volume.add_parser(sub)
    demo.add_parser(sub)
    reproduce.add_parser(sub)
    samples.add_parser(sub)
    bench_command.add_parser(sub, bench=bench)
    gui.add_parser(sub)  # after demo: it completes demo NAME --gui
    return p


def main(argv: Sequence[str] | None = None, parser: argparse.ArgumentParser | None = None) -> int:
    """Entry point of the ``voxwarp`` console script (and of ``python -m voxwarp``).

    ``argv`` defaults to ``sys.argv[1:]``; ``parser`` replaces :func:`build_parser`'s.
    """
    parser = parser or build_parser(bench=wants_bench(argv))
    args = parser.parse_args(join_negative_views(list(sys.argv[1:] if argv is None else argv)))
    with warnings.catch_warnings():
        warnings.simplefilter("default")
        old_format = warnings.formatwarning
        warnings.formatwarning = lambda msg, cat, *a, **k: f"voxwarp: warning: {msg}\n"
        try:
            limits.set_memory_budget(getattr(args, "memory_budget", None))
            return int(args.func(args) or 0)
        except VoxwarpError as exc:  # OutputError too: a write that failed, cleaned up
            print(f"voxwarp: error: {exc}", file=sys.stderr)
            return 2
        except OSError as exc:  # a file operation outside the checked writers: one line
            where = f"{exc.filename}: " if exc.filename else ""
            print(f"voxwarp: error: {where}{exc.strerror or exc}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            return 130
        finally:
            limits.set_memory_budget(None)
            warnings.formatwarning = old_format


if __name__ == "__main__":
    sys.exit(main())
