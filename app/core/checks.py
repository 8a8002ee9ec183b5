"""argparse value types shared by the ``voxwarp`` commands (``voxwarp.cli.main`` and the
benchmark modules that add their own sub-commands)."""

from __future__ import annotations

import argparse


def image_size(text: str) -> tuple[int, int]:
    """argparse type of ``WxH`` image sizes (1..16384 per side)."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"size must look like 512x512; got {text!r}") from exc
    if not (1 <= w <= 16384 and 1 <= h <= 16384):
        raise argparse.ArgumentTypeError(f"size must be 1..16384 per side; got {text!r}")
    return w, h


def positive_int(text: str) -> int:
    """argparse type of integers >= 1."""
    try:
        n = int(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"expected a positive integer; got {text!r}") from exc
    if n < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer; got {text!r}")
    return n
