"""The lab: voxwarp's peer comparisons (VTK, taichi, pygfx), studies and the benchmark
table for a GPU. It lives in the checkout only and is never installed (``pip install
voxwarp`` leaves it out; nothing in ``voxwarp`` imports it): run it from the repository
root as ``python -m benchmarks NAME`` (``python -m benchmarks all --json FILE`` makes the
whole table on a lent GPU; ``make bench`` runs it).

What the installed package keeps is ``voxwarp bench render|slices|interactive|detj``: this
machine's frame rates (:mod:`voxwarp.bench`).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

#: the checkout's root: the folder that holds ``benchmarks/``
ROOT = Path(__file__).resolve().parent.parent


def child_env() -> dict[str, str]:
    """The environment of a child ``python -m benchmarks...`` process: this one's, with
    the checkout's root first on ``PYTHONPATH`` (so that it imports ``benchmarks`` from
    any working directory)."""
    path = os.environ.get("PYTHONPATH", "")
    return {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(ROOT), path) if p)}


def gpu_context(ctx: Any, use_gpu: bool) -> tuple[Any, bool, str]:
    """The GL context a benchmark's GPU rows run on: ``(ctx, own, skip)``. ``ctx`` as
    given, else a new headless one when ``use_gpu`` (``own``: the caller releases it);
    ``skip`` is why GPU rows are skipped ("" when they run)."""
    if not use_gpu:
        return ctx, False, "skipped (not asked for)"
    if ctx is not None:
        return ctx, False, ""
    from voxwarp.errors import RenderError
    from voxwarp.render.context import create_context

    try:
        return create_context(), True, ""
    except RenderError as exc:
        return None, False, f"skipped: {exc}"
