"""``voxwarp reproduce``: every teaching demo's measurements and a report with the papers'
numbers beside them (:mod:`voxwarp.teaching.reproduce`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any


def add_parser(sub: Any) -> None:
    """Add ``reproduce`` to the ``voxwarp`` sub-commands (``sub``: their sub-parsers object)."""
    prp = sub.add_parser(
        "reproduce",
        help="run every teaching demo and write the papers' numbers beside ours",
        description="Regenerates the papers' tables and figures on this machine (the"
        " teaching demos' measurements) and writes a markdown report with the hardware,"
        " the papers' numbers beside ours, and the figure sheets in a folder beside it.",
    )
    prp.add_argument("--quick", action="store_true", help="small sizes (seconds; not comparable)")
    prp.add_argument(
        "-o",
        "--output",
        "--out",
        dest="out",
        default="docs/reproduction.md",
        metavar="FILE",
        help="the report (default docs/reproduction.md; figures in docs/reproduction/)",
    )
    prp.set_defaults(func=cmd_reproduce)


def cmd_reproduce(args: argparse.Namespace) -> int:
    """``voxwarp reproduce``: every demo's measurements and the report beside the
    papers' numbers (see :mod:`voxwarp.teaching.reproduce`)."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.teaching.reproduce import DEFAULT_REPORT, reproduce

    command = "voxwarp reproduce" + (" --quick" if args.quick else "")
    if Path(args.out) != DEFAULT_REPORT:
        command += f" --out {args.out}"
    path = reproduce(
        args.out, quick=args.quick, log=lambda s: print(s, file=sys.stderr), command=command
    )
    print(path)
    return 0
