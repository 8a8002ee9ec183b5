"""What the edit session and its family adapters share: the editor's error, choices,
display toggles and overlay colours."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from voxwarp.errors import VoxwarpError

BACKENDS: tuple[str, ...] = ("cpu", "gpu")
INTEGRATORS: tuple[str, ...] = ("semi-implicit", "explicit")
CHAINMAIL_VARIANTS: tuple[str, ...] = ("enhanced", "gibson")
WIRE_KINDS: tuple[str, ...] = ("catmull-rom", "bezier")


class EditorError(VoxwarpError, ValueError):
    """An edit the session cannot make (names the problem and the fix)."""


def choice(value: Any, allowed: Sequence[str], what: str) -> str:
    """``value`` if it is one of ``allowed``, else an :class:`EditorError` naming them."""
    if not isinstance(value, str) or value not in allowed:
        raise EditorError(f"{what} must be one of {', '.join(allowed)}; got {value!r}")
    return value


def resolution(value: Any) -> tuple[int, int, int]:
    """A grid resolution (elements per axis, 2..64) from one or three integers."""
    try:
        r = np.broadcast_to(np.asarray(value, dtype=np.int64), (3,))
    except (TypeError, ValueError) as exc:
        raise EditorError(f"grid resolution must be 1 or 3 integers; got {value!r}") from exc
    if np.any(r < 2) or np.any(r > 64):
        raise EditorError(
            f"grid resolution must be 2..64 elements per axis here; got {tuple(r.tolist())}"
        )
    return (int(r[0]), int(r[1]), int(r[2]))


@dataclass
class DisplayOptions:
    """What the viewport draws besides the volume (every feature can be toggled)."""

    volume: bool = True
    elements: bool = True
    links: bool = True
    fixed: bool = True
    wires_base: bool = True
    wires_modified: bool = True
    lattice_cells: bool = True
    grid_box: bool = True
    clip_box: bool = False
    selection: bool = True
    #: the slice views' planes as outlines in the 3D view (when slice views are shown)
    slice_planes: bool = True


COLORS = {
    "element": (0.30, 0.80, 1.00, 0.9),
    "fixed": (1.00, 0.30, 0.25, 0.95),
    #: elements anchored at rest by the region of influence of a drag
    "anchored": (0.60, 0.45, 1.00, 0.9),
    "selected": (1.00, 0.85, 0.10, 1.0),
    "reference": (1.00, 1.00, 1.00, 1.0),
    "link": (0.30, 0.80, 1.00, 0.35),
    "wire_base": (0.55, 0.55, 0.60, 0.8),
    "wire_modified": (0.20, 1.00, 0.40, 0.95),
    "lattice": (1.00, 0.55, 0.10, 0.6),
    "box": (0.80, 0.80, 0.80, 0.5),
    "pending": (1.00, 0.40, 1.00, 1.0),
}
