"""What several of the lab's benchmarks share beyond :mod:`benchmarks`: an argparse type of
integer lists and the best wall time of a few steps (moved here from ``voxwarp.core``,
where no product code used them).

Not in ``benchmarks/__init__.py``: there ``all`` is the ``benchmarks.all`` sub-module once
that is imported, not the builtin.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from typing import Any


def int_list(lo: int, hi: int, what: str, example: str) -> Any:
    """argparse type of comma-separated integers in ``lo..hi``, e.g. ``int_list(2, 128,
    "size", "16,32,64")``; the error names ``what`` and the ``example``."""

    def parse(text: str) -> tuple[int, ...]:
        try:
            values = tuple(int(v) for v in text.split(","))
        except ValueError as exc:
            raise argparse.ArgumentTypeError(
                f"{what}s must be comma-separated integers like {example}; got {text!r}"
            ) from exc
        if not values or not all(lo <= n <= hi for n in values):
            raise argparse.ArgumentTypeError(f"each {what} must be {lo}..{hi}; got {text!r}")
        return values

    return parse


def best_times(repeats: int, *steps: Callable[[], Any]) -> list[float]:
    """The shortest wall time (s) of each of ``steps`` over ``repeats`` rounds (each
    round runs every step once, in order)."""
    best = [math.inf] * len(steps)
    for _ in range(max(1, int(repeats))):
        for i, step in enumerate(steps):
            start = time.perf_counter()
            step()
            best[i] = min(best[i], time.perf_counter() - start)
    return best
