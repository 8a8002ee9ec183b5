"""What the ``voxwarp bench NAME`` commands share: their sub-parser and their report output."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def add_bench_parser(bsub: Any, name: str, help: str, doc: str | None) -> argparse.ArgumentParser:
    """Add ``name`` to the ``bench`` sub-commands: ``help`` in the list, and the second
    paragraph of ``doc`` (the benchmark module's docstring) as its description."""
    return bsub.add_parser(name, help=help, description=doc.split("\n\n")[1] if doc else None)


def emit_report(text: str, markdown: str | None) -> int:
    """Print a benchmark's markdown report and, with a path, also write it there
    (atomically); the command's exit status (0)."""
    from voxwarp.core.files import atomic_write_text

    print(text)
    if markdown:
        atomic_write_text(Path(markdown), text)
    return 0
