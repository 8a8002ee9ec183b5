"""The wire field's limits and tuning constants (one place for the numbers
that :mod:`voxwarp.deform.wires` and :mod:`voxwarp.core.limits` quote)."""

from __future__ import annotations

import os

#: most wires in one attribute field (7-bit wire id of the packed layout)
MAX_WIRES = 128
#: entries of each wire's lookup tables ("integer t" 0..255 of the packed layout)
LUT_SIZE = 256
#: allowed field scales (per-axis reduction; 1:1, 1:8, 1:64, 1:512, 1:4096 in voxels)
FIELD_SCALES = (1, 2, 4, 8, 16)
#: attribute field boxes (:class:`WireDeformer`'s ``box``)
FIELD_BOXES = ("content", "reach")
#: attribute field layouts
LAYOUTS = ("float", "packed", "paper")
#: packed code of a vacated voxel (flag 0, wire 127, t 255)
PACKED_VACATED = 0x7FFF
#: the paper layout's limits: 4-bit wire id, 4-bit segment index, 7-bit t per segment
PAPER_MAX_WIRES = 16
PAPER_MAX_SEGMENTS = 16
PAPER_T_MAX = 127
#: paper code of a vacated voxel (flag 0, wire 15, segment 15, t 127)
PAPER_VACATED = 0x7FFF
#: propagation domains of :class:`WireDeformer` (``propagate``)
PROPAGATE_MODES = ("region", "flagged")
#: a vacated sample is sent this far away (it then lies outside every volume)
FAR = 1.0e20
#: most control points of a wire's base or modified curve (its tables cost time per point)
MAX_WIRE_POINTS = 1024
#: most a wire's reach (radius times its largest scale) may be, in volume diagonals:
#: a larger region of influence covers nothing more
MAX_REACH_DIAGONALS = 1.0
#: most voxels of an attribute field (the volume box grown where the wires can bring
#: content, see :mod:`voxwarp.deform.wires.field_box`)
MAX_FIELD_VOXELS = 1 << 27
#: most mask pixels (planes x K x K) of one wire; each costs ~100 bytes while built
MAX_MASK_PIXELS = 1 << 25
#: what float32 arithmetic can add to a mapped point (mm): displacement bounds grow by it
#: (the filtered lookups of t and of the tables need none, see _box_mapping_range)
FLOAT32_MARGIN = 1e-4
#: what a wire does beyond its ends and near its radius (see :class:`Wire`)
ENDS = ("smooth", "rigid")
#: the default of :attr:`Wire.ends`
DEFAULT_ENDS = "smooth"
#: :attr:`Wire.ends` of a wire saved without it (files from before the option: the
#: paper's rigid sweep, as they were made)
SAVED_ENDS = "rigid"
#: keys of a wire object (:meth:`Wire.from_dict`); ``base`` and ``radius`` are required
WIRE_KEYS: tuple[str, ...] = (
    "kind",
    "base",
    "modified",
    "twist",
    "scale",
    "radius",
    "beta",
    "initial_normal",
    "name",
    "ends",
    "falloff",
    "sides",
    "side_falloff",
    "vacated",
)
#: with ``ends="smooth"``, the width of the fade beyond the radius, as a share of it
RADIAL_FADE = 0.25
#: what a wire does around its radius (see :class:`Wire`): the tissue around the swept
#: cylinder stretches (``"smooth"``) or the paper's rigid sweep with masks
SIDES = ("smooth", "rigid")
#: the default of :attr:`Wire.sides`, also for a wire saved without it
DEFAULT_SIDES = "smooth"
#: what the vacated place of a rigid sweep shows: nothing (the paper) or the rest content
VACATED = ("empty", "rest")
#: the default of :attr:`Wire.vacated`
DEFAULT_VACATED = "empty"
#: a smooth side fade of width F folds where F < FOLD_RATIO x the displacement it fades
#: (smoothstep's steepest slope is 1.5 / F: det(I + d (x) grad w) = 1 - 1.5 |d| / F)
FOLD_RATIO = 1.5
#: the default side falloff is this many times the wire's largest move (or the radius)
SIDE_FALLOFF_MOVES = 2.0

#: mask pixels per block of planes while the masks are sampled (keeps temporaries small)
MASK_BLOCK_PIXELS = 1 << 16
#: voxels per chunk of the numpy classification (keeps temporaries small)
FLAG_CHUNK = 1 << 16
#: mask pixels per block while the flagged propagation rasterises the planes
TOUCH_BLOCK_PIXELS = 1 << 18
#: threads sampling the mask blocks (and classifying chunks on the numpy path)
MASK_THREADS = max(1, min(4, os.cpu_count() or 1))
#: Newton steps that refine the propagated u to the closest point of the wire
REFINE_STEPS = 2

#: t ranges spanning more table entries than this mix wires (interpolation across a
#: wire boundary): their bound is taken over the whole table
MAX_T_STEPS = 64
#: a 6-neighbour pair of a smooth-sides wire's field is a seam when its closest point
#: moves along the wire by more than this many field voxels between them (near the wire
#: it moves about one voxel per voxel, R / (R - r) at distance r on the concave side of a
#: bend of radius R, so 3 flags r > 2R/3 and every jump at the medial axis)
SEAM_STEP_VOXELS = 3.0
