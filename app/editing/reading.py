"""Texts a slice view draws for reading: the window in its corner and a readout that
fits a narrow view, without Qt.

:func:`window_text` is the corner label (``"W 400 L 40"``, with the preset's name when
the window is one: ``"mediastinum  W 400 L 40"``); :func:`split_readout` splits
:func:`~voxwarp.editing.slice_views.readout`'s line into a position line and a value line, so
each fits a slice view of a 1280-pixel wide window (about 300 pixels).
"""

from __future__ import annotations

from collections.abc import Sequence


def window_text(window: Sequence[float], preset: str | None = None) -> str:
    """``"W 400 L 40"`` (4 significant digits), after the preset's name if given."""
    level, width = (float(v) for v in window)
    text = f"W {width:.4g} L {level:.4g}"
    return f"{preset}  {text}" if preset else text


def split_readout(text: str) -> tuple[str, str]:
    """A :func:`~voxwarp.editing.slice_views.readout` line as two: the position
    (``L 12.2  A 3.0  S 0.0 mm``) and the values (``deformed 12   rest 12``)."""
    position, _, values = text.partition(" mm ")
    return f"{position} mm", values.strip()
