"""``voxwarp samples``: the bundled sample volumes, one ``sample:NAME`` a line."""

from __future__ import annotations

import argparse
from typing import Any

from voxwarp.io.samples import sample_names


def add_parser(sub: Any) -> None:
    """Add ``samples`` to the ``voxwarp`` sub-commands (``sub``: their sub-parsers object)."""
    ps = sub.add_parser("samples", help="list bundled sample volumes")
    ps.set_defaults(func=cmd_samples)


def cmd_samples(args: argparse.Namespace) -> int:
    """``voxwarp samples``: list bundled samples."""
    for name in sample_names():
        print(f"sample:{name}")
    return 0
