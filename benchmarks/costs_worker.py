"""``python -m benchmarks.costs_worker --tree DIR [--quick] [--tf NAME]``: the measuring side of
``python -m benchmarks costs``.

Imports ``voxwarp`` from the source tree ``DIR`` (:func:`benchmarks.costs_tree.use_tree`),
then reads requests from stdin, one JSON object a line (``{"row": KEY, "volume": SPEC}``),
and answers each with one line ``@@costs {JSON}`` on stdout: the repeat's numbers
(``{"values": {...}}``) or its one-line error (``{"error": "..."}``). Anything else the
libraries print is not an answer. Its first line, before any request, says where its
``voxwarp`` was imported from (``{"voxwarp": FOLDER}``). The worker lives for the whole
run, so its context, volumes and models are made once
(:class:`benchmarks.costs_measure.Lab`).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any, TextIO

#: the prefix of an answer line
MARK = "@@costs "


def one_line(exc: BaseException) -> str:
    """``Type: first line of the message``."""
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}".strip().rstrip(":")


def answer(lab: Any, request: dict[str, Any]) -> dict[str, Any]:
    """The answer to one request (an exception is an ``error`` answer)."""
    try:
        values = lab.measure(str(request["row"]), str(request["volume"]))
    except Exception as exc:  # one row failing is reported, the others still run
        return {"error": one_line(exc)}
    bad = {k: v for k, v in values.items() if not (math.isfinite(v) and v >= 0)}
    if bad:
        return {"values": values, "error": f"not finite and >= 0: {bad}"}
    return {"values": values}


def serve(lab: Any, requests: TextIO, out: TextIO) -> None:
    """Answer every request line of ``requests`` on ``out`` until end of input."""
    for line in requests:
        if not line.strip():
            continue
        reply = answer(lab, json.loads(line))
        out.write(MARK + json.dumps(reply) + "\n")
        out.flush()


def main(argv: list[str] | None = None) -> int:
    """Serve requests with the ``voxwarp`` of ``--tree`` (see the module docstring)."""
    p = argparse.ArgumentParser(prog="benchmarks.costs_worker")
    p.add_argument("--tree", required=True, help="the source tree imported as voxwarp")
    p.add_argument("--quick", action="store_true")
    p.add_argument("--tf", default=None, help="every volume's transfer function")
    args = p.parse_args(argv)
    from benchmarks.costs_tree import use_tree

    use_tree(Path(args.tree))
    import voxwarp  # after use_tree: the tree's
    from benchmarks.costs_measure import Lab

    # the handshake: where this worker's voxwarp comes from
    sys.stdout.write(MARK + json.dumps({"voxwarp": str(Path(voxwarp.__file__).parent)}) + "\n")
    sys.stdout.flush()
    lab = Lab(args.quick, transfer_function=args.tf)
    try:
        serve(lab, sys.stdin, sys.stdout)
    finally:
        lab.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
