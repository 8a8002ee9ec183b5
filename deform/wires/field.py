"""The names other code imported from ``voxwarp.deform.wires.field`` when the wire field was
one module; it now lives in modules by role (see :mod:`voxwarp.deform.wires`). New code
imports from the defining modules."""

from __future__ import annotations

from voxwarp.deform.wires.build import WireDeformer
from voxwarp.deform.wires.constants import (
    DEFAULT_ENDS,
    DEFAULT_SIDES,
    ENDS,
    FAR,
    FIELD_SCALES,
    LAYOUTS,
    LUT_SIZE,
    MAX_FIELD_VOXELS,
    MAX_MASK_PIXELS,
    MAX_REACH_DIAGONALS,
    MAX_WIRE_POINTS,
    MAX_WIRES,
    PACKED_VACATED,
    PAPER_MAX_SEGMENTS,
    PAPER_MAX_WIRES,
    PAPER_VACATED,
    PROPAGATE_MODES,
    RADIAL_FADE,
    SIDES,
    VACATED,
)
from voxwarp.deform.wires.layouts import WireField, WireFieldStats
from voxwarp.deform.wires.tables import WireTables, map_points
from voxwarp.deform.wires.warp import WireFieldWarp
from voxwarp.deform.wires.wire import Wire

__all__ = [
    "DEFAULT_ENDS",
    "DEFAULT_SIDES",
    "ENDS",
    "FAR",
    "FIELD_SCALES",
    "LAYOUTS",
    "LUT_SIZE",
    "MAX_FIELD_VOXELS",
    "MAX_MASK_PIXELS",
    "MAX_REACH_DIAGONALS",
    "MAX_WIRES",
    "MAX_WIRE_POINTS",
    "PACKED_VACATED",
    "PAPER_MAX_SEGMENTS",
    "PAPER_MAX_WIRES",
    "PAPER_VACATED",
    "PROPAGATE_MODES",
    "RADIAL_FADE",
    "SIDES",
    "VACATED",
    "Wire",
    "WireDeformer",
    "WireField",
    "WireFieldStats",
    "WireFieldWarp",
    "WireTables",
    "map_points",
]
