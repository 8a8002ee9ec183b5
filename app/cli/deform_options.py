"""The deformation options of ``render`` and ``slice``: their argument types and option
groups (``--massspring``/``--chainmail`` with ``--drag``, ``--drag-at``, ``--fix``,
``--cut``, ...; ``--wires``; ``--lattice``; ``--displacement``).

:mod:`voxwarp.cli.deformation` checks them and turns them into a model and a warp.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence

from voxwarp.cli import render_options as ropt
from voxwarp.cli.options import add_field_convention_arg, mm_arg
from voxwarp.core import limits
from voxwarp.deform.elements.anchors import ANCHOR_MODES
from voxwarp.deform.elements.materials import PRESETS
from voxwarp.editing.model_settings import FIXED_STEPS, SETTLE_MAX_STEPS, SETTLE_SPEED

# ---------------------------------------------------------------------- mass-spring options
#: Steps ``render --massspring`` runs without ``--settle`` (and no ``--steps``), the most
#: steps ``--settle`` runs when ``--steps`` is not given, and the speed (mm/s) below which
#: every element counts as settled: the model builder's (voxwarp.editing.model_settings).
MASSSPRING_STEPS = FIXED_STEPS
MASSSPRING_SETTLE_MAX_STEPS = SETTLE_MAX_STEPS
MASSSPRING_SETTLE_TOL = SETTLE_SPEED
#: the names --stiffness-from-volume takes besides VALUE:STIFFNESS points
STIFFNESS_PRESETS = (*PRESETS, "auto")


class Drag(tuple):
    """One ``--drag I,J,K:DX,DY,DZ``: ``(text, (i, j, k), (dx, dy, dz))``, or one
    ``--drag-at`` resolved to its element: ``(text, (i, j, k), (dx, dy, dz), "--drag-at")``."""

    @property
    def flag(self) -> str:
        return self[3] if len(self) > 3 else "--drag"

    @property
    def text(self) -> str:
        return self[0]

    @property
    def index(self) -> tuple[int, int, int]:
        return self[1]

    @property
    def offset(self) -> tuple[float, float, float]:
        return self[2]


def _grid_shape(text: str) -> tuple[int, int, int]:
    # loads scipy: only when used
    from voxwarp.deform.elements.grid import MAX_ELEMENTS_PER_AXIS as hi
    from voxwarp.deform.elements.grid import MIN_ELEMENTS_PER_AXIS as lo

    form = f"N or NX,NY,NZ elements per axis ({lo}..{hi}), e.g. 16 or 16,8,8"
    try:
        vals = tuple(int(v) for v in text.split(","))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}") from exc
    if len(vals) == 1:
        vals = vals * 3
    if len(vals) != 3:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}")
    if any(not lo <= v <= hi for v in vals):
        raise argparse.ArgumentTypeError(f"{text!r}: out of range; expected {form}")
    return vals  # type: ignore[return-value]


def _drag(text: str) -> Drag:
    form = "I,J,K:DX,DY,DZ (element index, then its offset in mm along x, y, z), e.g. 6,4,4:0,12,0"
    try:
        left, right = text.split(":")
        idx = tuple(int(v) for v in left.split(","))
        off = tuple(float(v) for v in right.split(","))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}") from exc
    if len(idx) != 3 or len(off) != 3:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}")
    if not all(math.isfinite(v) for v in off):
        raise argparse.ArgumentTypeError(f"{text!r}: offsets must be finite mm; expected {form}")
    if max(abs(v) for v in off) > limits.MAX_DRAG_MM:
        raise argparse.ArgumentTypeError(
            f"{text!r}: offsets must be at most {limits.MAX_DRAG_MM:g} mm (the displacement"
            " texture's range); check the units (mm expected)"
        )
    return Drag((text, idx, off))


def _fix(text: str) -> tuple[str, tuple[tuple[int, int], ...]]:
    form = "I,J,K with each an index or a range A..B, e.g. 3,4,4 or 0..1,0..7,0..7"
    ranges = []
    try:
        parts = text.split(",")
        for part in parts:
            a, _, b = part.partition("..")
            lo, hi = int(a), int(b if b else a)
            if lo < 0 or hi < lo:
                raise ValueError(part)
            ranges.append((lo, hi))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}") from exc
    if len(ranges) != 3:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}")
    return text, tuple(ranges)


class Cut(tuple):
    """One ``--cut PX,PY,PZ:NX,NY,NZ[:RADIUS]``: ``(text, point, normal, radius)``."""

    @property
    def text(self) -> str:
        return self[0]

    @property
    def point(self) -> tuple[float, float, float]:
        return self[1]

    @property
    def normal(self) -> tuple[float, float, float]:
        return self[2]

    @property
    def radius(self) -> float | None:
        return self[3]


def _cut(text: str) -> Cut:
    form = (
        "PX,PY,PZ:NX,NY,NZ[:RADIUS] (a point on the plane in world mm, its normal,"
        " optionally the radius in mm of the disk on it), e.g. 48,24,20:1,0,0"
    )
    parts = text.split(":")
    try:
        if len(parts) not in (2, 3):
            raise ValueError(text)
        point = tuple(float(v) for v in parts[0].split(","))
        normal = tuple(float(v) for v in parts[1].split(","))
        radius = float(parts[2]) if len(parts) == 3 else None
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}") from exc
    if len(point) != 3 or len(normal) != 3:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}")
    values = [*point, *normal, *([] if radius is None else [radius])]
    if not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"{text!r}: numbers must be finite; expected {form}")
    if not any(normal):
        raise argparse.ArgumentTypeError(f"{text!r}: the normal must not be 0,0,0; expected {form}")
    if radius is not None and radius <= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: the radius must be > 0 mm; expected {form}")
    return Cut((text, point, normal, radius))


def _relax(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = -1
    if n < 0:
        raise argparse.ArgumentTypeError(
            f"{text!r}: expected a number of relaxation steps >= 0, e.g. 4"
        )
    if n > limits.MAX_RELAX_STEPS:
        raise argparse.ArgumentTypeError(
            f"{text!r}: at most {limits.MAX_RELAX_STEPS} relaxation steps (each smooths the"
            " whole grid); a few (e.g. 4) smooth a drag"
        )
    return n


def _stiffness_points(text: str) -> list[tuple[float, float]]:
    form = (
        "VALUE:STIFFNESS[,VALUE:STIFFNESS...] in data units and 0..1, e.g. 100:0.2,400:0.95"
        " (write --stiffness-from-volume=-500:0.1,... for a negative first value)"
    )
    try:
        pts = [tuple(float(v) for v in pair.split(":")) for pair in text.split(",")]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}") from exc
    if not pts or any(len(p) != 2 or not all(math.isfinite(v) for v in p) for p in pts):
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}")
    if any(not 0.0 <= s <= 1.0 for _, s in pts):
        raise argparse.ArgumentTypeError(f"{text!r}: stiffnesses must be in 0..1; expected {form}")
    if len({v for v, _ in pts}) != len(pts):
        raise argparse.ArgumentTypeError(f"{text!r}: values must differ; expected {form}")
    return pts  # type: ignore[return-value]


def _stiffness_arg(text: str) -> list[tuple[float, float]] | str:
    """``--stiffness-from-volume``: a tissue preset name or VALUE:STIFFNESS points."""
    if text in STIFFNESS_PRESETS:
        return text
    return _stiffness_points(text)


def _fix_outside(text: str) -> float:
    """``--fix-outside MM``: a radius in mm; 0 or ``off`` (read as 0) turns the region off."""
    if text.strip().lower() == "off":
        return 0.0
    try:
        r = float(text)
    except ValueError:
        r = -1.0
    if not math.isfinite(r) or r < 0:
        raise argparse.ArgumentTypeError(
            f"{text!r}: expected a radius in mm >= 0 (0 or off: no region), e.g. 60"
        )
    return r


def _steps(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = -1
    if n < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a step count >= 0, e.g. 1000")
    if n > limits.MAX_MASSSPRING_STEPS:
        raise argparse.ArgumentTypeError(
            f"{text!r}: at most {limits.MAX_MASSSPRING_STEPS} steps; use --settle to stop"
            " once the grid is at rest"
        )
    return n


def _grid_margin(text: str) -> float:
    try:
        mm = float(text)
    except ValueError:
        mm = -1.0
    if not (math.isfinite(mm) and mm >= 0.0):
        raise argparse.ArgumentTypeError(f"{text!r}: expected a margin in mm >= 0, e.g. 20")
    return mm


def grid_text(shape: Sequence[int]) -> str:
    """An element grid's shape as ``8x8x8``."""
    return "x".join(str(n) for n in shape)


def _field_scale(text: str) -> int:
    # loads scipy: only when used
    from voxwarp.deform.wires.field import FIELD_SCALES

    try:
        v = int(text)
    except ValueError:
        v = -1
    if v not in FIELD_SCALES:
        raise argparse.ArgumentTypeError(
            f"field scale must be one of {', '.join(map(str, FIELD_SCALES))} (per-axis"
            f" reduction of the attribute field); got {text!r}"
        )
    return v


def add_field_args(p: argparse.ArgumentParser) -> None:
    """``--displacement FILE`` (repeatable) and ``--field-convention``."""
    g = p.add_argument_group(
        "displacement fields (--displacement FILE)",
        "Render the volume through registration results without resampling it: the"
        " volume is the moving image, shown in the fixed image's space. ITK/ANTs/SimpleITK"
        " fields (pull-back, LPS) as NIfTI, NRRD, MetaImage, .npz, or ITK transform files"
        " (.h5, .tfm, ANTs' .mat: displacement fields, B-splines, affines, composites). Repeat the"
        " option to compose: the first file is applied first to the displayed (fixed)"
        " point, the order antsApplyTransforms takes its -t files in (e.g. --displacement"
        " 1Warp.nii.gz --displacement 0GenericAffine.mat). With --massspring, --chainmail,"
        " --wires or --lattice the model corrects the registration in the displayed space"
        " (it comes before the fields in the chain): --drag-at P --drag D moves what is seen"
        " at P by D; save it with --save-scene and write the corrected field with"
        " export-field.",
    )
    g.add_argument(
        "--displacement",
        action="append",
        metavar="FILE",
        help="a displacement field or ITK transform file (repeatable)",
    )
    add_field_convention_arg(g)


def add_wire_args(p: argparse.ArgumentParser) -> None:
    """``--wires FILE`` with its options, and ``--lattice FILE``."""
    g = p.add_argument_group(
        "wires (--wires FILE)",
        "Bend, twist and scale objects along curves (the WSCG 2006 wire deformer for"
        " volumes): each wire is a base curve laid through an object and a modified copy;"
        " the object's cross-sections are swept from the base to the modified curve."
        ' A wire file is JSON: {"wires": [{"kind": "catmull-rom"|"bezier", "base":'
        ' [[x, y, z], ...], "modified": [...], "twist": [[t, radians], ...], "scale":'
        ' [[t, s], ...], "radius": mm, "beta": [lo, hi]}], "field_scale": 2}'
        " (points in world mm, t the fraction of the wire's length). Example:"
        " voxwarp render sample:fish --view +z --wires"
        " sample_volumes/fish_spine_wires.json -o bent.png",
    )
    g.add_argument("--wires", metavar="FILE", help="deform with the wires of this wire file")
    g.add_argument(
        "--field-scale",
        type=_field_scale,
        metavar="N",
        help="attribute field N times coarser than the volume per axis: 1, 2, 4, 8 or 16"
        " (1:1 ... 1:4096 voxels; default: the file's, else 2)",
    )
    g.add_argument(
        "--layout",
        choices=("float", "packed", "paper"),
        help="attribute field storage: float (5 bytes/voxel, hardware-filtered t), packed"
        " (2 bytes/voxel: flag, 7-bit wire, 8-bit t) or paper (2 bytes/voxel, the wire"
        " paper's flag, 4-bit wire, 4-bit segment, 7-bit t); default: the file's, else float",
    )
    p.add_argument(
        "--lattice",
        metavar="FILE",
        help="deform with a lattice of trilinear cells over the volume (a JSON 'lattice' warp"
        " entry; e.g. sample_volumes/fish_lattice_bend.json on sample:fish)",
    )
    g.add_argument(
        "--masks",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="plane masks: sweep only the connected cross-section the wire runs through"
        " (default on; --no-masks sweeps every object voxel within the radius)",
    )
    g.add_argument(
        "--sides",
        choices=("smooth", "rigid"),
        help="for every wire: smooth moves everything within radius + side falloff, the"
        " surroundings stretching continuously (no masks, nothing left empty); rigid is"
        " the wire paper's sweep of the masked object, whose old place is vacated;"
        " default: each wire's 'sides', else smooth",
    )
    g.add_argument(
        "--side-falloff",
        type=mm_arg("--side-falloff"),
        metavar="MM",
        help="for every wire with smooth sides: width (mm) of the fade beyond the radius;"
        " default: each wire's 'side_falloff', else the radius or twice the wire's largest"
        " move if longer (narrower than 1.5 x the move folds: a warning says so)",
    )
    g.add_argument(
        "--vacated",
        choices=("empty", "rest"),
        help="for every wire with rigid sides: what the swept object's old place shows:"
        " empty (the paper) or rest (the unmoved content); default: each wire's"
        " 'vacated', else empty",
    )


def add_deform_args(p: argparse.ArgumentParser) -> None:
    """``--massspring``/``--chainmail`` and their options (drags, fixes, cuts, ...)."""
    g = p.add_argument_group(
        "deformation (--massspring or --chainmail)",
        (
            "Deform the volume before rendering: an element grid spans the volume's box"
            " (its outer shell fixed for mass-spring, its corners for ChainMail, see"
            " --anchor), --drag holds elements at offsets from rest, the model moves the"
            " others along, and the resulting offset field warps the volume at render time."
            " --massspring runs a mass-spring simulation (springs pull the rest along over"
            " time steps); --chainmail runs 3D ChainMail (links with slack: each drag is"
            " settled at once, moving every other element as little as the links allow)."
            " With --save-scene the JSON keeps the field and the model (grid, materials,"
            " held elements; ChainMail also its limits and cuts), so rendering it again"
            " gives the same image. Examples (bend the fish's tail sideways, head held, the"
            " thesis's corners fixed): voxwarp render sample:fish --view +z --massspring 8"
            " --anchor corners --fix 0..2,0..7,0..7 --drag 6,4,3:0,10,0 --drag"
            " 6,3,3:0,10,0 --settle -o bent.png; voxwarp render sample:fish --view +z"
            " --chainmail 8 --anchor corners --fix 0..2,0..7,0..7 --drag 6,4,3:0,10,0"
            " --drag 6,3,3:0,10,0 --relax 4 -o poked.png"
        ),
    )
    g.add_argument(
        "--massspring",
        type=_grid_shape,
        metavar="N|NX,NY,NZ",
        help="deform with a mass-spring model: its element grid over the volume's"
        " bounding box (2..128 per axis, e.g. 16)",
    )
    g.add_argument(
        "--chainmail",
        type=_grid_shape,
        metavar="N|NX,NY,NZ",
        help="deform with 3D ChainMail: its element grid over the volume's bounding box"
        " (2..128 per axis, e.g. 16)",
    )
    g.add_argument(
        "--drag",
        type=_drag,
        action="append",
        metavar="I,J,K:DX,DY,DZ",
        help="hold element (i, j, k) at its rest position + (dx, dy, dz) mm (world x, y, z"
        " axes); repeatable; indices run 0..N-1 along x, y, z; fixed elements (the"
        " --anchor set and --fix) cannot be dragged",
    )
    g.add_argument(
        "--drag-at",
        type=ropt.drag_at_arg,
        action="append",
        metavar="X,Y,Z:DX,DY,DZ",
        help="as --drag, on the element nearest the world point (x, y, z) mm that is not"
        " fixed (at rest; it"
        " says which and how far); the point may lie at most one element spacing outside"
        " the grid; repeatable",
    )
    g.add_argument(
        "--fix",
        type=_fix,
        action="append",
        metavar="I,J,K",
        help="also fix these elements at rest (besides the --anchor set); each index may"
        " be a range A..B, e.g. --fix 0..2,0..7,0..7 holds the x = low end; repeatable",
    )
    g.add_argument(
        "--backend",
        choices=("cpu", "gpu"),
        help="solve on the CPU (default: numpy for mass-spring, numba for ChainMail) or"
        " in shaders on the renderer's context (gpu)",
    )
    g.add_argument(
        "--inverse",
        choices=("approx", "exact", "baked"),
        help="offset-field inverse: baked (default: fixed point seeded by the inverse baked"
        " on a finer grid, 2 fetches), exact (fixed point from p, 6 fetches) or approx (one"
        " step, q = p - u(p), the thesis')",
    )
    g.add_argument(
        "--stiffness-from-volume",
        type=_stiffness_arg,
        metavar="ct|mr|auto|V:S,...",
        help="element stiffness from the volume value at each element: a tissue preset"
        " (ct: Hounsfield units, air free, fat and soft tissue soft, bone stiff; mr: from"
        " the volume's own histogram, background free, tissue soft; auto: ct for a CT in"
        " HU, else mr) or piecewise linear through VALUE:STIFFNESS points (data units :"
        " 0..1; constant beyond the ends), e.g. 100:0.2,400:0.95; stiffness 1 is rigid"
        " (default: 0.5 everywhere); ChainMail's link slack is 1 - stiffness",
    )
    g.add_argument(
        "--anchor",
        choices=ANCHOR_MODES,
        help="the grid elements fixed at rest: shell (mass-spring's default: every element"
        " on the grid's outer faces, so springs cannot carry a drag to the whole volume),"
        " corners (ChainMail's default and the thesis's set-up: ChainMail moves an element"
        " only once a link to it runs out of slack, so its drags stay local; a mass-spring"
        " drag then moves everything) or none",
    )
    g.add_argument(
        "--fix-outside",
        type=_fix_outside,
        metavar="MM",
        help="region of influence: elements farther than MM from every dragged element"
        " are anchored at rest (0 or off: none); default with --anchor shell: the larger"
        " of 30 mm, 4 element spacings and 3 x the largest drag, so a push fades over a"
        " few centimetres; default with corners or none: off",
    )
    # -- the grid margin (one block: other options go before or after it)
    g.add_argument(
        "--grid-margin",
        type=_grid_margin,
        metavar="MM",
        help="pad the element grid's box beyond the volume's box by MM on every side, so"
        " that content pushed across a face is carried out of the box and rendered there"
        " (the element count stays; their spacing grows). Default: the largest --drag /"
        " --drag-at offset component (no element moves farther than a dragged one), 0"
        " without drags; --grid-margin 0 keeps the volume's box",
    )

    m = p.add_argument_group("mass-spring options (with --massspring)")
    m.add_argument(
        "--settle",
        action="store_true",
        default=None,
        help=f"run until every element is slower than {MASSSPRING_SETTLE_TOL:g} mm/s, at"
        f" most --steps steps (default {MASSSPRING_SETTLE_MAX_STEPS})",
    )
    m.add_argument(
        "--steps",
        type=_steps,
        metavar="N",
        help=f"time steps to run (default {MASSSPRING_STEPS}: a smooth, nearly settled"
        " deformation); with --settle the most steps",
    )
    m.add_argument(
        "--integrator",
        choices=("explicit", "semi-implicit"),
        help="semi-implicit (default; ~10x larger stable steps) or explicit Euler (the thesis')",
    )
    m.add_argument(
        "--shear",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="face-diagonal shear springs (default on; without them the grid does not"
        " resist shearing and a sideways drag tears it)",
    )
    m.add_argument(
        "--bend",
        action="store_true",
        default=None,
        help="second-neighbour bend springs (default off)",
    )

    c = p.add_argument_group(
        "3D ChainMail options (with --chainmail)",
        "Each link lets its two elements stretch or compress by up to half a spacing and"
        " shear by up to half a spacing, each times 1 - stiffness (0.5 by default); a drag"
        " moves other elements only once a link is taut, which leaves straight, sheared"
        " blocks; --relax smooths them within the same limits.",
    )
    c.add_argument(
        "--relax",
        type=_relax,
        metavar="K",
        help="relaxation steps after each drag (default 0; the thesis shows 0, 1 and 4):"
        " constrained Laplacian smoothing that keeps every link within its limits",
    )
    c.add_argument(
        "--variant",
        choices=("gibson", "enhanced"),
        help="propagation: enhanced (default; Schill et al.'s priority queue) or gibson"
        " (Gibson's sponsor lists); a single drag ends in the same state",
    )
    c.add_argument(
        "--cut",
        type=_cut,
        action="append",
        metavar="PX,PY,PZ:NX,NY,NZ[:R]",
        help="before the drags, remove the links crossing the plane through point P (world"
        " mm) with normal N, or only a disk of radius R mm on it; the two sides then move"
        " independently; repeatable, e.g. --cut 48,24,20:1,0,0",
    )
    c.add_argument(
        "--join",
        type=_cut,
        action="append",
        metavar="PX,PY,PZ:NX,NY,NZ[:R]",
        help="after the cuts, link again the cut links crossing this plane or disk (the"
        " inverse of --cut): --cut 48,24,20:1,0,0 --join 48,24,20:1,0,0:10 leaves the"
        " sides joined by a bridge of radius 10 mm; repeatable",
    )
