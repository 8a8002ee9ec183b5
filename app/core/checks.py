"""Checks of values shared across voxwarp: argparse types of the ``voxwarp`` commands
(the modules of ``voxwarp.cli``; the lab's benchmark modules use them for their own
sub-commands too) and :func:`finite_vector` for vectors given in Python or scene JSON."""

from __future__ import annotations

import argparse
import numbers
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np


def image_size(text: str) -> tuple[int, int]:
    """argparse type of ``WxH`` image sizes (1..16384 per side)."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"size must look like 512x512; got {text!r}") from exc
    if not (1 <= w <= 16384 and 1 <= h <= 16384):
        raise argparse.ArgumentTypeError(f"size must be 1..16384 per side; got {text!r}")
    return w, h


#: the coarsest interactive volume resolution (1/16 per axis: the wire paper's 1:4096)
MAX_INTERACTIVE_DOWNSAMPLE = 16


def interactive_downsample(value: Any, error: type[Exception]) -> int:
    """``value`` as the per-axis reduction of the volume in interactive frames, an
    integer in 1..:data:`MAX_INTERACTIVE_DOWNSAMPLE` (1: full resolution); raises
    ``error`` otherwise (``Scene.interactive_downsample``)."""
    ok = isinstance(value, numbers.Integral) and not isinstance(value, bool)
    if not ok or not 1 <= int(value) <= MAX_INTERACTIVE_DOWNSAMPLE:
        raise error(
            "interactive downsample must be an integer from 1 (full resolution) to"
            f" {MAX_INTERACTIVE_DOWNSAMPLE} (the volume reduced per axis while you"
            f" interact); got {value!r}"
        )
    return int(value)


def interactive_downsample_arg(text: str) -> int:
    """argparse type of ``--interactive-downsample N``."""
    try:
        return interactive_downsample(int(text), ValueError)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(
            f"{text!r}: expected an integer from 1 (full resolution) to"
            f" {MAX_INTERACTIVE_DOWNSAMPLE}"
        ) from exc


def positive_int(text: str) -> int:
    """argparse type of integers >= 1."""
    try:
        n = int(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"expected a positive integer; got {text!r}") from exc
    if n < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer; got {text!r}")
    return n


def finite_vector(x: Any, n: int, what: str, error: type[Exception]) -> np.ndarray:
    """``x`` as ``n`` finite float64 numbers; else ``error`` naming ``what``."""
    import numpy as np  # here: the command line imports this module and must start fast

    try:
        a = np.asarray(x, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise error(f"{what} must be {n} numbers; got {x!r:.80}") from exc
    if a.size != n or not np.all(np.isfinite(a)):
        raise error(f"{what} must be {n} finite numbers; got {x!r:.80}")
    return a


def finite_box(value: Any, what: str, error: type[Exception]) -> tuple[np.ndarray, np.ndarray]:
    """``value`` as a box ``(lo, hi)`` of finite 3-vectors with ``hi > lo`` on every
    axis; else ``error`` naming ``what`` (e.g. ``"clip_box"``)."""
    try:
        lo, hi = value
    except (TypeError, ValueError) as exc:
        raise error(f"{what} must be ((x0, y0, z0), (x1, y1, z1))") from exc
    lo = finite_vector(lo, 3, f"{what} low corner", error)
    hi = finite_vector(hi, 3, f"{what} high corner", error)
    if (hi <= lo).any():
        corners = tuple(map(float, lo)), tuple(map(float, hi))
        raise error(
            f"{what} high corner must exceed the low corner; got {corners[0]}, {corners[1]}"
        )
    return lo, hi
