"""Volume wires: bend, twist and scale objects in a volume along curves, without resampling.

About this technique (Journal of WSCG 14, 2006: non-linear, non-reconstructive volume
deformation by sweeping, sections 4-9; an extension of Maya's wire deformer to volumes)
------------------------------------------------------------------------------------------
A :class:`Wire` is a *base* curve laid through an object and a *modified* copy of it
(same curve type) that the user bends, plus a twist angle θ and a scale s keyed at any
points along it. The object is *swept*: the cross-section of the object on the plane
normal to the base wire at arc-length fraction u is shown on the plane normal to the
modified wire at the same fraction u, rotated by θ(u) about the wire and scaled by s(u).
Base and modified wire may differ in length (the object is compressed or stretched along
it). The parameter of every key, table and the attribute field is that arc-length
fraction u in [0, 1] (0 = first control point), the same on both curves: this is the
paper's plane-to-plane mapping by t.

Frames. Twist needs a frame on each curve that has no twist of its own: both curves
carry rotation-minimising frames (double reflection,
:meth:`voxwarp.deform.wires.curves.Curve.frames`);
the base frame starts from ``initial_normal`` (default: the world axis least aligned
with the base tangent), the modified frame from that normal carried by the minimal
rotation between the two start tangents. So a wire that is only translated or bent in
a plane maps cross-sections without rotating them, and θ is exactly the rotation seen.

Mapping (section 6). A deformed-space point p near the modified wire at fraction u has
local coordinates ``(x, y, z) = F_m(u)^T (p - M(u))`` in the modified frame
``F_m = (N_m, B_m, T_m)``. It shows the original point
``q = C(u) + F_b(u) diag(1/s, 1/s, L_b/L_m) R_z(-θ) (x, y, z)`` near the base wire
(C the base wire's point), i.e. ``q = C(u) + A(u) (p - M(u)) = A(u) p + b(u)``. The
along-wire offset z is kept (scaled by the length ratio), so an error in u moves M and
C together along straight parts and the mapping is first-order insensitive to it.
``A`` and ``b`` are tabulated at :data:`LUT_SIZE` equally spaced fractions ("wire point
and frame lookup tables at integer t", section 7.2, 3 RGBA texels per entry) and
interpolated linearly; the CPU reference, the masks and the shader all use these same
tables. The Jacobian of the warp is A(u) (the dependence of u on p is second order;
section 6.1 carries the gradient by it).

Attribute field (section 5). Each ray sample needs to know whether it is swept, by
which wire, and its u. The field holds that per voxel of a grid ``field_scale`` times
coarser than the volume per axis (1:1, 1:8, 1:64, 1:512, 1:4096 in voxels), over the
volume's box grown to hold the modified wires' regions of influence (a bent object may
leave the original box). It is built in deformed space:

1. *Planes* (5, 7.1): one plane per ``mask_resolution`` of modified arc length, normal
   to the modified wire, each carrying a square mask of ``mask_resolution`` pixels
   covering the region of influence (a disc of ``radius``). Each pixel's point is mapped
   to the base side (the mapping above) and classified there by β (a value range of the
   volume by default; any callable on values works).
2. *Plane masks* (7.1): a 2.5D seed fill of the β pixels from a seed on each plane,
   found by searching outward from the wire (the β pixel nearest to it): a pixel joins
   when it connects to a seed within its plane or through the neighbouring planes (so an
   object that forks along the wire, like a tail fin, stays whole); holes are filled (a
   vessel's lumen, a swim bladder move with their object); then ``dilation`` pixels of
   morphological dilation; planes with no object are dropped. Only the object the wire
   runs through is swept, which solves the delineation problem of two nearby objects
   (with ``masks=False`` every β pixel in the disc is swept instead).
3. *Voxel initialisation* (5.1): where the modified wire enters a field cell, its eight
   voxels become seeds with (γ wire id, ε closest u, d distance), keeping the minimum d.
4. *Propagation*: every voxel of the region takes (γ, ε) of its nearest seed, by an
   exact Euclidean distance transform in OpenCL (:mod:`voxwarp.deform.wires.propagation`, PoCL on
   the
   CPU here, any OpenCL GPU elsewhere; scipy when no platform exists, with a warning).
   Distances are discarded. ε is then refined to the closest point of the wire
   (:data:`REFINE_STEPS` Newton steps): the nearest seed's u is off by up to a voxel
   along the wire, which a fast twist would turn into a visible rotation error.
   That is ``propagate="region"`` (the default). The paper propagates only over the
   voxels flagged by the plane masks (5.1, 7.1): ``propagate="flagged"`` first marks the
   voxels holding a set mask pixel (grown by a voxel; the end planes carried along the
   end tangents as far as step 5 reaches), then finds the nearest seed (a k-d tree)
   only for them and their neighbours (which swept samples interpolate t from), and
   keeps step 5's test on them. Same field up to nearest-seed ties; which one builds
   faster depends on the device (docs/benchmarks.md).
5. *Flags*: a voxel is swept where the mask of its plane (at ε) covers its projection;
   the rest of the field is the identity. The original place of the swept object is
   *vacated*: the same propagation from the base wires, tested against the same masks
   (turned and scaled as the sweep does), marks it, and samples landing there (unswept)
   show nothing, so the bent object leaves no copy behind. A field voxel counts when its
   footprint touches a mask (the masks grow by half a field voxel), so coarse fields
   neither cut the object's edges nor leave thin parts of it behind. Where the OpenCL
   device has double precision, steps 4-5 run as one pass on it
   (:mod:`voxwarp.deform.wires.classify`: the nearest-seed indices never leave the device,
   and the refinement and mask tests give the numpy path's bits); else in numpy.

Wire ends (not in the paper). The rigid sweep (``ends="rigid"``) moves nothing past the
end planes and the radius: a wire that ends inside an object, or an object wider than
the radius, is cut there, and the build warns when a moving end lies inside its object.
``ends="smooth"`` (the default) blends the sweep with the identity beyond them:
``warp(p) = p + w(p) (A p + b - p)``, with w = 1 inside the radius and between the end
planes, falling smoothly (a smoothstep) to 0 over ``falloff`` mm beyond each end along
its tangent (the mapping there is the end plane's, extended) and over
:data:`RADIAL_FADE` times the radius beyond the radius. Planes beyond the ends use the
end plane's mask. w is stored per field voxel (float32, trilinearly filtered); the
Jacobian is taken as ``I + w (A - I)`` (the gradient of w is left out, as that of u).
The object's place is vacated only out to the middle of the fades: past it the content
has mostly stayed and shows in place, so a fade leaves no hole; a move larger than the
fade still folds (a doubled strip), so give a falloff of at least twice the end's move.

Storage (7.2). Two layouts, chosen by ``layout``:

* ``"float"``: ``state`` uint8 per voxel (0 identity, 1 vacated, 2 + γ swept) and ``t``
  float32 (u·255, trilinearly filtered by the hardware): 5 bytes per voxel.
* ``"packed"``: the paper's 2 bytes per voxel: bit 15 the swept flag, bits 8-14 the
  wire id γ, bits 0-7 the integer t = round(255 u) (the segment of that t is in the
  wire's lookup table, :attr:`WireTables.segment_base` / ``segment_modified``); unswept
  voxels keep their γ and t so that swept neighbours can interpolate t, and the code
  ``0x7FFF`` marks a vacated voxel. The shader interpolates t itself from the 8
  neighbours of the same wire.
* ``"paper"``: the paper's own 2-byte example (section 7.2): bit 15 the swept flag, bits
  11-14 the wire id γ (16 wires), bits 7-10 the segment index of the modified curve
  holding the voxel's closest point (16 segments; the segments of
  :meth:`voxwarp.deform.wires.curves.Curve.segment_of`, found through the wire's table of
  curve parameters), bits 0-6 the integer t within that segment (128 steps). The t
  steps are equally spaced in arc length within the segment: with ``u_s`` the fraction
  where segment s starts, ``u = u_s + (t / 127) (u_{s+1} - u_s)``, so every code maps
  exactly to the fraction u that indexes the lookup tables (``WireField.segments``
  holds ``u_s`` per wire, in table units; the shader reads it from a 17-texel row per
  wire). The paper caches wire points and frames "at each integer t"; here those are
  the same tables, read at that u. Neighbours are interpolated in u, never in the
  per-segment t (two neighbours in different segments would otherwise mix unrelated t
  values). Unswept voxels keep their wire, segment and t (flag 0), and ``0x7FFF`` marks
  a vacated voxel, as in the packed layout (an unswept code that would collide becomes
  t = 126). At most :data:`PAPER_MAX_WIRES` wires of at most
  :data:`PAPER_MAX_SEGMENTS` segments each.

Mask memory (7.1). The paper counts ``sum_p a(p) s / 8`` bytes per wire: one bit per
mask pixel, ``a(p)`` the area of plane p and ``s`` the pixels per unit area. Here each
kept plane (planes without object are dropped, as in the paper) is a square of K x K
pixels of ``mask_resolution`` mm: ``a(p) = (K mask_resolution)^2`` mm^2 and
``s = 1 / mask_resolution^2`` pixels per mm^2, so a wire needs ``kept planes x K^2 / 8``
bytes (:attr:`WireFieldStats.mask_bytes`).

Rendering: per sample one field fetch decides identity / vacated / swept; a swept
sample adds the t fetch (8 in the packed and paper layouts; the paper layout turns each
into its table coordinate through two entries of a uniform array of segment starts) and
3 fetches of the tiny lookup table (``q = A p + b``, A and b linear in t).
:meth:`WireFieldWarp.displacement_range` bounds ``warp(p) - p`` per box from the field,
so the raycaster keeps skipping empty space through the deformed volume.

Limits: at most :data:`MAX_WIRES` (128) wires per field (the packed layout's 7-bit id);
16 wires of at most 16 segments with ``layout="paper"``.
"""

from __future__ import annotations

import math
import os
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import ndimage

from voxwarp.deform.warp import Warp, WarpError, check_forward, register_warp
from voxwarp.deform.wires.curves import Curve, minimal_rotation

#: most wires in one attribute field (7-bit wire id of the packed layout)
MAX_WIRES = 128
#: entries of each wire's lookup tables ("integer t" 0..255 of the packed layout)
LUT_SIZE = 256
#: allowed field scales (per-axis reduction; 1:1, 1:8, 1:64, 1:512, 1:4096 in voxels)
FIELD_SCALES = (1, 2, 4, 8, 16)
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
#: most voxels of an attribute field (the volume box grown by the wires' reach)
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
)
#: with ``ends="smooth"``, the width of the fade beyond the radius, as a share of it
RADIAL_FADE = 0.25

Beta = Callable[[np.ndarray], np.ndarray]


# ---------------------------------------------------------------------- keys
def _keys(keys: Any, what: str, default: float, positive: bool = False) -> np.ndarray:
    """Parse ``[(u, value), ...]`` into a sorted (K, 2) float array (K >= 1)."""
    if keys is None or (isinstance(keys, Sequence) and len(keys) == 0):
        return np.array([[0.0, default]])
    if isinstance(keys, int | float):
        return np.array([[0.0, float(keys)]])
    try:
        a = np.asarray(keys, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise WarpError(
            f"wire {what} must be a list of (t, value) pairs, t in [0, 1]; got {keys!r:.80}"
        ) from exc
    if a.ndim != 2 or a.shape[1] != 2:
        raise WarpError(
            f"wire {what} must be a list of (t, value) pairs, t in [0, 1]; got shape {a.shape}"
        )
    if not np.all(np.isfinite(a)):
        raise WarpError(f"wire {what} keys contain NaN/Inf; give finite numbers")
    if np.any((a[:, 0] < 0) | (a[:, 0] > 1)):
        raise WarpError(f"wire {what} keys need t in [0, 1] (fraction of the wire's length)")
    if positive and np.any(a[:, 1] <= 0):
        raise WarpError(f"wire {what} values must be > 0; got {a[:, 1].min():g}")
    return a[np.argsort(a[:, 0], kind="stable")]


def _interp_keys(keys: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Linear interpolation of keys at fractions u (constant beyond the first/last key)."""
    return np.interp(u, keys[:, 0], keys[:, 1])


def _beta(beta: Any) -> tuple[float, float] | Beta | None:
    if beta is None or callable(beta):
        return beta
    try:
        lo, hi = (float(v) for v in beta)
    except (TypeError, ValueError) as exc:
        raise WarpError(
            f"wire beta must be a value range (lo, hi), a callable or None; got {beta!r:.80}"
        ) from exc
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi:
        raise WarpError(f"wire beta range needs finite lo <= hi; got ({lo}, {hi})")
    return (lo, hi)


def _positive_mm(value: Any, what: str) -> float:
    """``value`` as a finite length in mm > 0 (a one-line WarpError naming ``what``)."""
    try:
        mm = float(value)
    except (TypeError, ValueError) as exc:
        raise WarpError(f"wire {what} must be a number of mm; got {value!r:.40}") from exc
    if not math.isfinite(mm) or mm <= 0:
        raise WarpError(f"wire {what} must be a finite number of mm > 0; got {value!r}")
    return mm


def _count(points: Any) -> int:
    """Number of control points in ``points`` (0 when it is not a sequence: the curve
    reports that)."""
    try:
        return len(points)
    except TypeError:
        return 0


# ---------------------------------------------------------------------- wires
class Wire:
    """A wire: base curve, modified curve, twist and scale keys, influence and β.

    Parameters
    ----------
    base, modified
        (N, 3) control points (world mm) of the base curve (laid through the object)
        and of the modified curve (where the object goes). Same ``kind``; the counts
        may differ.
    kind
        ``"catmull-rom"`` (interpolates its points) or ``"bezier"`` (3k + 1 points).
    twist
        ``[(t, radians), ...]``: twist about the wire at fractions t of its length,
        linearly interpolated (constant beyond the ends); one number = constant.
    scale
        ``[(t, s), ...]`` (s > 0): scale of the cross-section, keyed the same way.
    radius
        Region of influence (mm): how far from the wire the object is swept (Maya's
        dropoffDistance); the sweep is rigid inside it; beyond it nothing moves
        (``ends="rigid"``) or the sweep fades out (``ends="smooth"``).
    beta
        Object classification: a value range ``(lo, hi)`` of the volume, a callable
        ``values -> bool array``, or ``None`` (everything inside the radius).
    initial_normal
        Normal of the base wire's frame at its start (default: the world axis least
        aligned with the start tangent); twist angles are measured from it.
    name
        Optional label (saved in scene JSON).
    ends
        What happens beyond the wire's ends and its radius: ``"smooth"`` fades the
        sweep's displacement to zero over ``falloff`` mm beyond each end (along the end
        tangents) and over :data:`RADIAL_FADE` times the radius beyond the radius (the
        sweep inside stays rigid), so a wire that ends inside an object, or an object
        wider than the radius, bends without being cut; ``"rigid"`` is the paper's sweep
        (nothing beyond the end planes or the radius moves).
    falloff
        Length (mm) of the fade beyond each end with ``ends="smooth"``; default the
        radius, or twice the largest move of an end's cross-section if that is longer
        (:meth:`end_moves`: a fade shorter than twice the move folds and shows a strip
        twice).
    """

    def __init__(
        self,
        base: Any,
        modified: Any = None,
        kind: str = "catmull-rom",
        twist: Any = None,
        scale: Any = None,
        radius: float = 10.0,
        beta: Any = None,
        initial_normal: Any = None,
        name: str = "",
        ends: str = DEFAULT_ENDS,
        falloff: float | None = None,
    ) -> None:
        for what, points in (("base", base), ("modified", modified)):
            count = len(points.control_points) if isinstance(points, Curve) else _count(points)
            if count > MAX_WIRE_POINTS:
                raise WarpError(
                    f"wire {what} has {count:,} control points, over the limit of"
                    f" {MAX_WIRE_POINTS}; a few dozen describe any bend: thin them out"
                )
        self.base = base if isinstance(base, Curve) else Curve(base, kind)
        if modified is None:
            modified = self.base.control_points.copy()
        self.modified = modified if isinstance(modified, Curve) else Curve(modified, kind)
        if self.modified.kind != self.base.kind:
            raise WarpError(
                f"base and modified wire must be the same kind; got {self.base.kind!r} and"
                f" {self.modified.kind!r}"
            )
        self.twist = _keys(twist, "twist", 0.0)
        self.scale = _keys(scale, "scale", 1.0, positive=True)
        self.radius = _positive_mm(radius, "radius")
        self.beta = _beta(beta)
        if initial_normal is not None:
            n = np.asarray(initial_normal, dtype=np.float64).reshape(-1)
            if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0:
                raise WarpError("wire initial_normal must be a non-zero finite (x, y, z)")
            initial_normal = n
        self.initial_normal = initial_normal
        self.name = str(name)
        if ends not in ENDS:
            raise WarpError(f"wire ends must be one of {ENDS}; got {ends!r:.40}")
        self.ends = ends
        self._end_moves: tuple[Any, tuple[float, float]] | None = None
        self.falloff_mm = None if falloff is None else _positive_mm(falloff, "falloff")

    @property
    def falloff(self) -> float:
        """Length (mm) of the fade beyond each end: as given, else the larger of the
        radius and twice the largest end move (:meth:`end_moves`)."""
        if self.falloff_mm is not None:
            return self.falloff_mm
        return max(self.radius, 2.0 * max(self.end_moves()))

    def end_moves(self) -> tuple[float, float]:
        """How far (mm) the sweep moves each end's cross-section at most: the end point
        and 16 points on the circle of the (scaled) radius around it, in the modified
        wire's end plane, mapped back through the wire's tables. Cached per shape of
        the wire."""
        key = (
            self.base.control_points.tobytes(),
            self.modified.control_points.tobytes(),
            self.twist.tobytes(),
            self.scale.tobytes(),
            self.radius,
        )
        if self._end_moves is None or self._end_moves[0] != key:
            tab = self.tables()
            angle = np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)
            moves = []
            for i, u in ((0, 0.0), (tab.size - 1, 1.0)):
                m, f = tab.modified_points[i], tab.modified_frames[i]
                r = self.radius * float(self.scale_at(u))
                ring = np.cos(angle)[:, None] * f[:, 0] + np.sin(angle)[:, None] * f[:, 1]
                p = np.vstack([m, m + r * ring])
                q = map_points(tab, np.full(len(p), float(i)), p)
                moves.append(float(np.linalg.norm(q - p, axis=1).max()))
            self._end_moves = (key, (moves[0], moves[1]))
        return self._end_moves[1]

    @property
    def influence(self) -> float:
        """How far (mm, before scaling) from the wire anything moves: the radius, and
        the radial fade beyond it with ``ends="smooth"``."""
        return self.radius * (1.0 + RADIAL_FADE) if self.smooth else self.radius

    @property
    def smooth(self) -> bool:
        """Whether the sweep fades out beyond the ends and near the radius."""
        return self.ends == "smooth"

    def end_reach(self, side: str = "modified") -> float:
        """How far (mm) beyond its end planes the wire moves anything (``side``
        ``"modified"``), or vacates the object's place (``"base"``: to the middle of
        the fade, where the content has mostly moved away)."""
        if not self.smooth:
            return 0.0
        return self.falloff if side == "modified" else 0.5 * self.falloff

    @property
    def kind(self) -> str:
        """Curve type of both curves."""
        return self.base.kind

    def twist_at(self, u: Any) -> np.ndarray:
        """Twist angle (radians) at arc-length fractions u."""
        return _interp_keys(self.twist, np.asarray(u, dtype=np.float64))

    def scale_at(self, u: Any) -> np.ndarray:
        """Cross-section scale at arc-length fractions u."""
        return _interp_keys(self.scale, np.asarray(u, dtype=np.float64))

    def classify(self, values: np.ndarray) -> np.ndarray:
        """β: which volume values belong to the object (bool array like ``values``)."""
        if self.beta is None:
            return np.ones(np.shape(values), dtype=bool)
        if callable(self.beta):
            out = np.asarray(self.beta(values))
            if out.shape != np.shape(values):
                raise WarpError(
                    f"wire beta callable must return one bool per value; got shape {out.shape}"
                    f" for {np.shape(values)}"
                )
            return out.astype(bool)
        lo, hi = self.beta
        return (values >= lo) & (values <= hi)

    def tables(self, n: int = LUT_SIZE, precision: float = 1e-4) -> WireTables:
        """Lookup tables of the mapping at ``n`` equally spaced arc-length fractions."""
        return WireTables.build(self, n, precision)

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict[str, Any]:
        """JSON form (a callable β cannot be saved: give a value range instead)."""
        if callable(self.beta):
            raise WarpError(
                "a wire with a callable beta cannot be saved; give beta as a value range (lo, hi)"
            )
        d: dict[str, Any] = {
            "kind": self.kind,
            "base": self.base.control_points.tolist(),
            "modified": self.modified.control_points.tolist(),
            "twist": self.twist.tolist(),
            "scale": self.scale.tolist(),
            "radius": self.radius,
            "beta": None if self.beta is None else list(self.beta),
            "ends": self.ends,
        }
        if self.falloff_mm is not None:
            d["falloff"] = self.falloff_mm
        if self.initial_normal is not None:
            d["initial_normal"] = self.initial_normal.tolist()
        if self.name:
            d["name"] = self.name
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Wire:
        """Inverse of :meth:`to_dict` (``modified`` defaults to ``base``)."""
        if not isinstance(d, Mapping):
            raise WarpError(f"a wire must be a JSON object; got {d!r:.80}")
        unknown = set(d) - set(WIRE_KEYS)
        if unknown:
            raise WarpError(
                f"unknown wire keys {sorted(unknown)}; see voxwarp.deform.wires.field.Wire"
            )
        if "base" not in d:
            raise WarpError("a wire needs 'base': its control points [[x, y, z], ...] in mm")
        if "radius" not in d:
            raise WarpError("a wire needs 'radius': its region of influence in mm")
        return cls(
            base=d["base"],
            modified=d.get("modified"),
            kind=d.get("kind", "catmull-rom"),
            twist=d.get("twist"),
            scale=d.get("scale"),
            radius=d["radius"],
            beta=d.get("beta"),
            initial_normal=d.get("initial_normal"),
            name=d.get("name", ""),
            ends=d.get("ends", SAVED_ENDS),
            falloff=d.get("falloff"),
        )

    def __repr__(self) -> str:
        return (
            f"Wire(kind={self.kind!r}, points={len(self.base.control_points)},"
            f" radius={self.radius:g}, beta={self.beta!r}, ends={self.ends!r})"
        )


@dataclass
class WireTables:
    """A wire's mapping tabulated at ``n`` equally spaced arc-length fractions u_i.

    ``q = C(u) + A(u) (p - M(u))`` maps deformed points near the modified wire to the
    original volume (see the module docstring); M, C, A are interpolated linearly in u.
    """

    #: fractions u_i = i / (n - 1)
    u: np.ndarray
    #: modified wire points M(u_i) (n, 3)
    modified_points: np.ndarray
    #: modified wire frames (n, 3, 3), columns (N, B, T)
    modified_frames: np.ndarray
    #: base wire points C(u_i) (n, 3)
    base_points: np.ndarray
    #: base wire frames (n, 3, 3), columns (N, B, T)
    base_frames: np.ndarray
    #: the linear part A(u_i) (n, 3, 3)
    matrices: np.ndarray
    #: curve parameters of u_i on each curve, and their segment indices
    t_base: np.ndarray
    t_modified: np.ndarray
    segment_base: np.ndarray
    segment_modified: np.ndarray
    #: arc lengths (mm)
    length_base: float
    length_modified: float
    #: b(u_i) = C - A M (n, 3): the mapping is ``q = A p + b``
    offsets: np.ndarray

    @classmethod
    def build(cls, wire: Wire, n: int = LUT_SIZE, precision: float = 1e-4) -> WireTables:
        """Tabulate ``wire`` (see the class docstring)."""
        u = np.linspace(0.0, 1.0, n)
        tb, sb = wire.base.arc_length_table(n, precision)
        tm, sm = wire.modified.arc_length_table(n, precision)
        lb, lm = float(sb[-1]), float(sm[-1])
        tb_, nb_, bb_ = wire.base.frames(tb, initial_normal=wire.initial_normal)
        rot = minimal_rotation(tb_[0], wire.modified.frames(np.array([0.0]))[0][0])
        tm_, nm_, bm_ = wire.modified.frames(tm, initial_normal=rot @ nb_[0])
        fb = np.stack([nb_, bb_, tb_], axis=-1)
        fm = np.stack([nm_, bm_, tm_], axis=-1)
        theta = wire.twist_at(u)
        s = wire.scale_at(u)
        c, si = np.cos(-theta), np.sin(-theta)
        rz = np.zeros((n, 3, 3))
        rz[:, 0, 0], rz[:, 0, 1], rz[:, 1, 0], rz[:, 1, 1] = c, -si, si, c
        rz[:, 2, 2] = 1.0
        d = np.zeros((n, 3, 3))
        d[:, 0, 0] = d[:, 1, 1] = 1.0 / s
        d[:, 2, 2] = lb / lm
        a = fb @ d @ rz @ np.transpose(fm, (0, 2, 1))
        m_pts, b_pts = wire.modified.evaluate(tm), wire.base.evaluate(tb)
        return cls(
            u=u,
            modified_points=m_pts,
            modified_frames=fm,
            base_points=b_pts,
            base_frames=fb,
            matrices=a,
            t_base=tb,
            t_modified=tm,
            segment_base=wire.base.segment_of(tb)[0],
            segment_modified=wire.modified.segment_of(tm)[0],
            length_base=lb,
            length_modified=lm,
            offsets=b_pts - np.einsum("nij,nj->ni", a, m_pts),
        )

    @property
    def size(self) -> int:
        """Number of entries."""
        return len(self.u)

    def lookup(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(A, b) at continuous table coordinates t in [0, n - 1], each linear in t (as
        the shader's filtered lookup table)."""
        return _lerp_table(self.matrices, t), _lerp_table(self.offsets, t)

    def gpu_rows(self) -> np.ndarray:
        """The 3 RGBA32F rows of the shader's lookup table, (3, n, 4) float32: row r holds
        (A[r, 0], A[r, 1], A[r, 2], b[r])."""
        out = np.empty((3, self.size, 4), dtype=np.float32)
        out[:, :, :3] = np.transpose(self.matrices, (1, 0, 2))
        out[:, :, 3] = self.offsets.T
        return out


def map_points(tables: WireTables, t: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The wire mapping ``q = A p + b`` at table coordinates t (deformed -> original)."""
    a, b = tables.lookup(t)
    return np.einsum("nij,nj->ni", a, p) + b


# ---------------------------------------------------------------------- statistics
@dataclass
class WireFieldStats:
    """What :meth:`WireDeformer.build` did (the paper's Tables 1-3 for preprocessing)."""

    field_shape: tuple[int, int, int]
    field_scale: int
    layout: str
    backend: str
    planes: int
    planes_dropped: int
    seeds: int
    region_voxels: int
    swept: int
    vacated: int
    #: field voxels that render as the identity (not swept, not vacated)
    ignored: int
    #: seconds per stage: tables, masks, seeds, propagate, flags, store, total (seeds,
    #: propagation and flags of both sides: the swept voxels and the vacated place)
    timings: dict[str, float] = field(default_factory=dict)
    #: plane-mask memory per wire, bytes: kept planes x K^2 / 8 (section 7.1's
    #: sum_p a(p) s / 8, see the module docstring)
    mask_bytes: tuple[int, ...] = ()
    #: the propagation domain (``WireDeformer(propagate=...)``)
    propagate: str = "region"

    @property
    def voxels(self) -> int:
        """Voxels of the attribute field."""
        return int(np.prod(self.field_shape))

    @property
    def mask_bytes_total(self) -> int:
        """Plane-mask memory of all wires, bytes."""
        return int(sum(self.mask_bytes))

    @property
    def percent_ignored(self) -> float:
        """Share of field voxels a sample ignores (identity), in %."""
        return 100.0 * self.ignored / max(self.voxels, 1)

    def as_dict(self) -> dict[str, Any]:
        """Plain dict (JSON-ready)."""
        return {
            "field_shape": list(self.field_shape),
            "field_scale": self.field_scale,
            "layout": self.layout,
            "backend": self.backend,
            "planes": self.planes,
            "planes_dropped": self.planes_dropped,
            "seeds": self.seeds,
            "region_voxels": self.region_voxels,
            "swept": self.swept,
            "vacated": self.vacated,
            "ignored": self.ignored,
            "voxels": self.voxels,
            "percent_ignored": self.percent_ignored,
            "timings": dict(self.timings),
            "mask_bytes": list(self.mask_bytes),
            "mask_bytes_total": self.mask_bytes_total,
            "propagate": self.propagate,
        }


@dataclass
class WireField:
    """A built attribute field (see the module docstring for the layouts)."""

    lo: np.ndarray
    spacing: np.ndarray
    shape: tuple[int, int, int]
    layout: str
    #: float layout: state (0 identity, 1 vacated, 2 + wire) and t (u * (LUT_SIZE - 1))
    state: np.ndarray | None
    t: np.ndarray | None
    #: packed and paper layouts: the uint16 codes
    code: np.ndarray | None
    tables: list[WireTables]
    #: the propagated region (first voxel, shape): swept voxels lie inside it
    region_lo: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=np.int64))
    region_shape: tuple[int, int, int] = (0, 0, 0)
    #: paper layout: where each segment of each modified wire starts, in table units
    #: (wires, PAPER_MAX_SEGMENTS + 1) float32; entries past a wire's last segment
    #: repeat its end
    segments: np.ndarray | None = None
    #: with any ``ends="smooth"`` wire: float32 weight in [0, 1] per voxel (trilinearly
    #: filtered) by which a swept sample's displacement is scaled; None: all rigid
    weight: np.ndarray | None = None

    @property
    def hi(self) -> np.ndarray:
        """Upper corner of the field box (mm)."""
        return self.lo + self.spacing * np.asarray(self.shape)

    @property
    def nbytes(self) -> int:
        """Bytes of the per-voxel data."""
        arrays = (self.state, self.t, self.code, self.weight)
        return sum(a.nbytes for a in arrays if a is not None)

    def decode(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(state, wire, t) per voxel for either layout: state 0 identity, 1 vacated,
        2 swept; wire id; t in table units (integer for the packed layout)."""
        if self.layout == "float":
            assert self.state is not None
            assert self.t is not None
            s = self.state
            state = np.where(s >= 2, 2, s).astype(np.uint8)
            wire = np.where(s >= 2, s.astype(np.int32) - 2, 0)
            return state, wire, self.t
        assert self.code is not None
        c = self.code.astype(np.int32)
        swept = (c & 0x8000) != 0
        state = np.where(swept, 2, np.where(c == PACKED_VACATED, 1, 0)).astype(np.uint8)
        if self.layout == "paper":
            assert self.segments is not None
            return state, (c >> 11) & 0xF, _paper_t(c, self.segments).astype(np.float32)
        return state, (c >> 8) & 0x7F, (c & 0xFF).astype(np.float32)


# ---------------------------------------------------------------------- deformer
def _volume_parts(volume: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    try:
        data = volume.data
        spacing = np.asarray(volume.spacing, dtype=np.float64).reshape(3)
        origin = np.asarray(volume.origin, dtype=np.float64).reshape(3)
    except (AttributeError, ValueError, TypeError) as exc:
        raise WarpError(
            "WireDeformer needs a volume with data, spacing and origin (app.load_volume or"
            f" a sample); got {type(volume).__name__}"
        ) from exc
    if np.ndim(data) != 3:
        raise WarpError(f"WireDeformer needs a 3D volume; got data of shape {np.shape(data)}")
    return data, spacing, origin


#: what one side's propagation gives: the region's first voxel and shape, wire id and
#: u per region voxel, the mask bits, and the seed count
_SideResult = tuple[np.ndarray, tuple[int, int, int], np.ndarray, np.ndarray, np.ndarray, int]


@dataclass
class _SideJob:
    """One side's propagation and flags in :meth:`WireDeformer.build`: the seeds (flat
    field index, wire, u), the wires' tables, their grown plane masks, the field's box
    corner, voxel size and shape, the side (``"modified"`` or ``"base"``), and the
    stage timings to add to."""

    seeds: tuple[np.ndarray, np.ndarray, np.ndarray]
    tables: list[WireTables]
    grown: list[tuple[np.ndarray, int, float]]
    lo: np.ndarray
    h: np.ndarray
    shape: tuple[int, int, int]
    side: str
    timings: dict[str, float]

    def parts(self) -> tuple[Any, ...]:
        """The fields in order (for unpacking into locals)."""
        return (
            self.seeds,
            self.tables,
            self.grown,
            self.lo,
            self.h,
            self.shape,
            self.side,
            self.timings,
        )


class WireDeformer:
    """Builds the attribute field of a set of wires on a volume (paper sections 5, 7).

    Parameters
    ----------
    volume
        The original volume (``data`` indexed x, y, z; ``spacing``; ``origin``): β
        classifies its values.
    wires
        Up to :data:`MAX_WIRES` :class:`Wire` objects.
    field_scale
        Per-axis reduction of the field against the volume: 1, 2, 4, 8 or 16
        (1:1 ... 1:4096 in voxels).
    ctx
        Optional moderngl context: :meth:`warp` then uploads its textures at once.
    layout
        ``"float"``, ``"packed"`` (2 bytes per voxel) or ``"paper"`` (2 bytes per voxel,
        the paper's wire / segment / t split), see the module docstring.
    masks
        Sweep only the seed-filled cross-section of the object the wire runs through
        (True, the paper's plane masks), or every β voxel in the region (False).
    mask_resolution
        Pixel size of the plane masks and spacing of the planes (mm); default the
        volume's smallest voxel spacing for a 1:1 field, twice that for coarser fields
        (whose voxels sample the masks no finer).
    dilation
        Pixels of morphological dilation of each mask.
    backend
        Propagation backend of :func:`voxwarp.deform.wires.propagation.nearest_seed`.
    precision
        Arc-length precision p (eq. 4) and closest-point precision (in t).
    propagate
        ``"region"``: nearest-seed propagation over the whole box of the wires' reach,
        then the mask test; ``"flagged"``: the paper's order (sections 5.1, 7.1): the
        voxels the plane masks touch are flagged first and only they (and their
        neighbours, which swept samples interpolate) get a nearest seed.
    """

    def __init__(
        self,
        volume: Any,
        wires: Sequence[Wire],
        field_scale: int = 2,
        ctx: Any = None,
        *,
        layout: str = "float",
        masks: bool = True,
        mask_resolution: float | None = None,
        dilation: int = 1,
        backend: str = "auto",
        precision: float = 1e-4,
        propagate: str = "region",
    ) -> None:
        self.data, self.spacing, self.origin = _volume_parts(volume)
        # oblique scans: world <-> index through the volume's rotation
        direction = getattr(volume, "direction", None)
        self._direction = np.eye(3) if direction is None else np.asarray(direction, float)
        wires = list(wires)
        if not wires:
            raise WarpError("WireDeformer needs at least one Wire")
        if len(wires) > MAX_WIRES:
            raise WarpError(
                f"at most {MAX_WIRES} wires fit one attribute field (7-bit wire id); got"
                f" {len(wires)}: split them over several WireDeformers"
            )
        for i, w in enumerate(wires):
            if not isinstance(w, Wire):
                raise WarpError(f"wires[{i}] is a {type(w).__name__}, not a voxwarp.deform.Wire")
        self.wires = wires
        if field_scale not in FIELD_SCALES:
            raise WarpError(
                f"field_scale must be one of {FIELD_SCALES} (per-axis reduction);"
                f" got {field_scale!r}"
            )
        self.field_scale = int(field_scale)
        if layout not in LAYOUTS:
            raise WarpError(f"layout must be one of {LAYOUTS}; got {layout!r}")
        self.layout = layout
        self._check_layout_limits()
        if propagate not in PROPAGATE_MODES:
            raise WarpError(f"propagate must be one of {PROPAGATE_MODES}; got {propagate!r}")
        self.propagate = propagate
        self.masks = bool(masks)
        if mask_resolution is None:
            # the volume's voxel for a 1:1 field; two of them for coarser fields, whose
            # voxels sample the masks at most that finely (8x fewer mask pixels)
            px = float(self.spacing.min()) * min(int(field_scale), 2)
        else:
            px = float(mask_resolution)
        if not math.isfinite(px) or px <= 0:
            raise WarpError(f"mask_resolution must be a length in mm > 0; got {mask_resolution}")
        self.mask_resolution = px
        if int(dilation) != dilation or dilation < 0:
            raise WarpError(f"dilation must be a whole number of pixels >= 0; got {dilation}")
        self.dilation = int(dilation)
        self.backend = backend
        self.precision = float(precision)
        self.ctx = ctx
        self.field: WireField | None = None
        self.stats: WireFieldStats | None = None
        self.propagation_input: tuple[np.ndarray, tuple[float, ...]] | None = None
        self._warp: WireFieldWarp | None = None
        vlo = self.origin - 0.5 * self.spacing
        vhi = self.origin + (np.asarray(self.data.shape) - 0.5) * self.spacing
        if hasattr(volume, "bounds"):  # the axis-aligned box of a (possibly oblique) volume
            vlo, vhi = (np.asarray(b, dtype=np.float64) for b in volume.bounds)
        self.volume_bounds = (vlo, vhi)
        diagonal = float(np.linalg.norm(vhi - vlo))
        for i, w in enumerate(wires):
            reach = w.radius * float(w.scale[:, 1].max())
            if reach > MAX_REACH_DIAGONALS * diagonal:
                raise WarpError(
                    f"wire {i}: radius x largest scale = {reach:.4g} mm, over the volume's"
                    f" diagonal ({diagonal:.4g} mm, the limit): give a radius in mm that"
                    " covers the object, not more"
                )
        for i, w in enumerate(wires):
            blo, bhi = _curve_box(w.base)
            if np.any(bhi < vlo) or np.any(blo > vhi):
                raise WarpError(
                    f"wire {i}'s base curve lies entirely outside the volume box"
                    f" {vlo.round(2).tolist()}..{vhi.round(2).tolist()} mm: lay it through"
                    " the object (control points are world mm, not voxel indices)"
                )

    def _check_layout_limits(self) -> None:
        """The paper layout's 4-bit wire id and segment index (a one-line WarpError)."""
        if self.layout != "paper":
            return
        if len(self.wires) > PAPER_MAX_WIRES:
            raise WarpError(
                f"layout='paper' holds at most {PAPER_MAX_WIRES} wires (4-bit wire id); got"
                f" {len(self.wires)}: use layout='packed' (up to {MAX_WIRES} wires)"
            )
        for i, w in enumerate(self.wires):
            if w.modified.n_segments > PAPER_MAX_SEGMENTS:
                raise WarpError(
                    f"layout='paper' holds at most {PAPER_MAX_SEGMENTS} segments per wire"
                    f" (4-bit segment index); wire {i}'s modified curve has"
                    f" {w.modified.n_segments}: use fewer control points or layout='packed'"
                )

    # ------------------------------------------------------------------ geometry
    def _field_geometry(self) -> tuple[np.ndarray, np.ndarray, tuple[int, int, int]]:
        """Field box lo, voxel spacing and shape: the volume box grown (in whole field
        voxels) to hold each modified wire's region of influence."""
        h = self.spacing * self.field_scale
        vlo, vhi = self.volume_bounds
        lo, hi = vlo.copy(), vhi.copy()
        for w in self.wires:
            clo, chi = _curve_box(w.modified)
            grow = max(w.influence * float(w.scale[:, 1].max()), w.end_reach())
            lo = np.minimum(lo, clo - grow)
            hi = np.maximum(hi, chi + grow)
        grow_lo = np.ceil((vlo - lo) / h - 1e-9)
        lo = vlo - grow_lo * h
        count = np.maximum(np.ceil((hi - lo) / h - 1e-9), 1)
        if float(np.prod(count)) > MAX_FIELD_VOXELS:
            dims = "x".join(f"{v:.0f}" for v in count)
            raise WarpError(
                f"the attribute field would be {dims} voxels, over the limit of"
                f" {MAX_FIELD_VOXELS:,}: the modified wires reach far outside the volume;"
                " keep them near the object or use a larger field_scale"
            )
        shape = count.astype(int)
        return lo, h, (int(shape[0]), int(shape[1]), int(shape[2]))

    # ------------------------------------------------------------------ build
    def build(self) -> WireFieldStats:
        """Build the attribute field (planes, masks, seeds, propagation, flags, storage).

        Returns
        -------
        WireFieldStats
            Field size, planes kept/dropped, seeds, swept/vacated/ignored voxel counts and
            the time of each stage.
        """
        from voxwarp.deform.wires.propagation import last_backend

        t_all = time.perf_counter()
        timings: dict[str, float] = {}
        self._check_layout_limits()  # the wires may have been edited since __init__
        lo, h, shape = self._field_geometry()

        t0 = time.perf_counter()
        tables = [w.tables(LUT_SIZE, self.precision) for w in self.wires]
        timings["tables"] = time.perf_counter() - t0

        # 1-2. planes and their masks (per wire)
        t0 = time.perf_counter()
        masks: list[tuple[np.ndarray, int, float]] = []  # (planes, K, K) masks, K, half
        dropped = 0
        planes_total = 0
        mask_bytes = []
        for w, tab in zip(self.wires, tables, strict=True):
            mask, k_side, n_dropped = self._plane_masks(w, tab)
            masks.append((mask, k_side, (k_side - 1) / 2.0))
            dropped += n_dropped
            planes_total += mask.shape[0]
            # section 7.1: one bit per pixel of every kept plane
            mask_bytes.append(math.ceil((mask.shape[0] - n_dropped) * k_side * k_side / 8))
        timings["masks"] = time.perf_counter() - t0
        self._warn_ends_inside(tables, masks)

        # 3. seeds: the 8 voxels of every field cell a wire enters; the modified wires
        # for the swept voxels, the base wires for the place the object leaves
        t0 = time.perf_counter()
        seeds_m = self._seeds(tables, lo, h, shape, "modified")
        seeds_b = self._seeds(tables, lo, h, shape, "base")
        timings["seeds"] = time.perf_counter() - t0

        # 4-5. propagation of (wire, u) from the seeds over each side's region, then the
        # flags: the mask bit under each voxel's projection on its plane; the swept
        # object's original place (the same masks seen from the base wires) is vacated.
        # A field voxel counts when its footprint touches a mask, not only its centre:
        # the masks grow by half a field voxel (else the object's edges would be cut at
        # coarse field scales, and thin parts of it, such as a fin's edge, would stay
        # behind as a ghost); what this adds is the background around the object
        t0 = time.perf_counter()
        grow = math.ceil(0.5 * float(h.max()) / self.mask_resolution)
        # (a box dilated `grow` times is one box of side 2 grow + 1: separable maxima)
        grown = [
            (ndimage.maximum_filter(m, size=2 * grow + 1, mode="constant"), k, half)
            for m, k, half in masks
        ]
        timings["flags"] = time.perf_counter() - t0
        timings["propagate"] = 0.0
        region_lo, rshape, r_wire, r_u, swept, seed_count = self._side(
            _SideJob(seeds_m, tables, grown, lo, h, shape, "modified", timings)
        )
        b_lo, b_shape, _, _, gone, _ = self._side(
            _SideJob(seeds_b, tables, grown, lo, h, shape, "base", timings)
        )
        backend = last_backend()
        t0 = time.perf_counter()
        region = _box_slices(region_lo, rshape)
        b_region = _box_slices(b_lo, b_shape)
        # vacated: the base side's bits, less the swept voxels (within the base box)
        vacated = gone
        both = _box_overlap(b_lo, b_shape, region_lo, rshape)
        if both is not None:
            vacated[both[0]] &= ~swept[both[1]]
        timings["flags"] += time.perf_counter() - t0

        # 6. storage
        t0 = time.perf_counter()
        tscale = LUT_SIZE - 1
        if self.layout == "float":
            state = np.zeros(shape, dtype=np.uint8, order="F")
            state[b_region] = vacated
            np.copyto(state[region], (2 + r_wire).astype(np.uint8), where=swept)
            tf = np.zeros(shape, dtype=np.float32, order="F")
            tf[region] = r_u * tscale
            fld = WireField(lo, h, shape, "float", state, tf, None, tables, region_lo, rshape)
        elif self.layout == "packed":
            code = np.zeros(shape, dtype=np.uint16, order="F")
            ti = np.clip(np.rint(r_u * tscale), 0, tscale).astype(np.int32)
            c = (r_wire.astype(np.int32) << 8) | ti
            c = np.where(c == PACKED_VACATED, PACKED_VACATED - 1, c)
            c = np.where(swept, c | 0x8000, c)
            code[region] = c.astype(np.uint16)
            np.copyto(code[b_region], PACKED_VACATED, where=vacated)
            fld = WireField(lo, h, shape, "packed", None, None, code, tables, region_lo, rshape)
        elif self.layout == "paper":
            starts = _segment_starts(self.wires, tables)
            code = np.zeros(shape, dtype=np.uint16, order="F")
            counts = np.array([w.modified.n_segments for w in self.wires])
            code[region] = _paper_codes(r_wire, r_u, swept, starts, counts)
            np.copyto(code[b_region], PAPER_VACATED, where=vacated)
            fld = WireField(
                lo, h, shape, "paper", None, None, code, tables, region_lo, rshape, segments=starts
            )
        fld.weight = self._weights(tables, lo, h, shape, region_lo, rshape, r_wire, r_u, swept)
        timings["store"] = time.perf_counter() - t0
        timings["total"] = time.perf_counter() - t_all

        n_swept = int(swept.sum())
        n_vac = int(vacated.sum())
        self.field = fld
        self.stats = WireFieldStats(
            field_shape=shape,
            field_scale=self.field_scale,
            layout=self.layout,
            backend=backend,
            planes=planes_total,
            planes_dropped=dropped,
            seeds=seed_count,
            region_voxels=int(np.prod(rshape)),
            swept=n_swept,
            vacated=n_vac,
            ignored=int(np.prod(shape)) - n_swept - n_vac,
            timings=timings,
            mask_bytes=tuple(mask_bytes),
            propagate=self.propagate,
        )
        if self._warp is not None:
            self._warp._set_field(fld)
        return self.stats

    def _side(self, job: _SideJob) -> _SideResult:
        """Propagation and flags of one side: the region's first voxel and shape, wire
        id and refined u per region voxel, the mask bits and the seed count. One OpenCL
        pass (:mod:`voxwarp.deform.wires.classify`) where the device allows, else numpy;
        adds the stages' seconds to ``timings``."""
        seeds, tables, grown, lo, h, shape, side, timings = job.parts()
        if self.propagate == "flagged":
            flagged = self._flagged_side(job)
            return self._smooth_trim(tables, lo, h, flagged, side)
        fast = self._fast_side(job)
        if fast is not None:
            return self._smooth_trim(tables, lo, h, fast, side)
        t0 = time.perf_counter()
        region_lo, rshape, r_wire, r_u, r_near, count = self._propagate(
            seeds, tables, lo, h, shape, side
        )
        t1 = time.perf_counter()
        bits = self._flags(tables, grown, lo, h, region_lo, rshape, r_wire, r_u, r_near, side)
        timings["propagate"] += t1 - t0
        timings["flags"] += time.perf_counter() - t1
        out = (region_lo, rshape, r_wire, r_u, bits, count)
        return self._smooth_trim(tables, lo, h, out, side)

    def _fast_side(self, job: _SideJob) -> _SideResult | None:
        """:meth:`_side` in one OpenCL pass; None where OpenCL (with double precision)
        is unavailable, not asked for, or fails (the numpy path then runs)."""
        seeds, tables, grown, lo, h, shape, side, timings = job.parts()
        from voxwarp.deform.wires import propagation as prop
        from voxwarp.deform.wires.classify import ClassifyInput, WireGeometry, classify

        if self.backend not in ("auto", "opencl") or not self.classify_on_device():
            return None
        t0 = time.perf_counter()
        c_lo, rshape, grid, flat, s_wire, s_u = self._region(seeds, tables, lo, h, shape, side)
        if max(rshape) > prop.MAX_LINE:
            return None
        order = np.argsort(flat, kind="stable")
        modified = side == "modified"
        reach = self._reach(h, side)
        geoms = []
        for wi, (w, tab) in enumerate(zip(self.wires, tables, strict=True)):
            frames = tab.modified_frames if modified else tab.base_frames
            geoms.append(
                WireGeometry(
                    points=tab.modified_points if modified else tab.base_points,
                    tangents=frames[:, :, 2],
                    frames=frames,
                    length=tab.length_modified if modified else tab.length_base,
                    reach=float(reach[wi]),
                    mask=grown[wi][0],
                    half=grown[wi][2],
                    twist=w.twist,
                    scale=w.scale,
                )
            )
        inp = ClassifyInput(
            seed_idx=flat[order],
            seed_wire=s_wire[order],
            seed_u=s_u[order],
            rshape=rshape,
            lo=lo,
            h=h,
            region_lo=c_lo,
            wires=geoms,
            px=self.mask_resolution,
            # smooth ends reach further (trimmed per wire later)
            cap=self._end_cap() + max(w.end_reach(side) for w in self.wires),
            base_side=not modified,
            refine_steps=REFINE_STEPS,
        )
        sampling = tuple(float(v) for v in h)
        if modified:
            self.propagation_input = (grid, sampling)
        split: list[float] = []

        def use(st: dict[str, Any], buf: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            st["queue"].finish()
            split.append(time.perf_counter())
            return classify(st, buf, inp)

        try:
            r_wire, r_u, bits = prop.on_device_nearest(grid, sampling, use)
        except (prop._opencl_state()["cl"].Error, MemoryError) as exc:  # e.g. out of memory
            if self.backend == "opencl":
                raise WarpError(
                    f"the OpenCL wire field pass failed ({type(exc).__name__}); use"
                    " backend='scipy' or a larger field_scale"
                ) from exc
            return None
        timings["propagate"] += split[0] - t0
        timings["flags"] += time.perf_counter() - split[0]
        return c_lo, rshape, r_wire, r_u, bits, len(flat)

    def classify_on_device(self) -> bool:
        """Whether :meth:`build` propagates and flags in one OpenCL pass (an OpenCL
        device with double precision), rather than with numpy."""
        from voxwarp.deform.wires import propagation as prop
        from voxwarp.deform.wires.classify import classify_available

        return prop.opencl_available() and classify_available(prop._opencl_state())

    def _region(
        self,
        seeds: tuple[np.ndarray, np.ndarray, np.ndarray],
        tables: list[WireTables],
        lo: np.ndarray,
        h: np.ndarray,
        shape: tuple[int, int, int],
        side: str,
    ) -> tuple[np.ndarray, tuple[int, int, int], np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The wires' region on one side (the box of their reach): its first voxel and
        shape, the seed mask over it, and the seeds' flat region indices, wires and u."""
        seed_idx, seed_wire, seed_u = seeds
        c_lo = np.full(3, np.iinfo(np.int64).max)
        c_hi = np.full(3, -1)
        for w, tab in zip(self.wires, tables, strict=True):
            pts = tab.modified_points if side == "modified" else tab.base_points
            smax = float(w.scale[:, 1].max()) if side == "modified" else 1.0
            ends = w.end_reach(side)
            r = max(w.influence * smax, ends) + 2 * self.mask_resolution
            a = np.floor((pts.min(0) - r - lo) / h - 0.5).astype(int) - 1
            b = np.ceil((pts.max(0) + r - lo) / h - 0.5).astype(int) + 1
            c_lo, c_hi = np.minimum(c_lo, a), np.maximum(c_hi, b)
        c_lo = np.clip(c_lo, 0, np.asarray(shape) - 1)
        c_hi = np.clip(c_hi, 0, np.asarray(shape) - 1)
        rshape = (
            int(c_hi[0] - c_lo[0] + 1),
            int(c_hi[1] - c_lo[1] + 1),
            int(c_hi[2] - c_lo[2] + 1),
        )
        grid = np.zeros(rshape, dtype=bool)
        sidx = np.stack(np.unravel_index(seed_idx, shape), -1) - c_lo
        inside = np.all((sidx >= 0) & (sidx < np.asarray(rshape)), axis=1)
        sidx, s_wire, s_u = sidx[inside], seed_wire[inside], seed_u[inside]
        if len(sidx) == 0:
            raise WarpError(
                f"no {side} wire passes through the attribute field: check the control points"
            )
        grid[sidx[:, 0], sidx[:, 1], sidx[:, 2]] = True
        flat = np.ravel_multi_index(sidx.T, rshape)
        return c_lo, rshape, grid, flat, s_wire, s_u

    def _reach(self, h: np.ndarray, side: str) -> np.ndarray:
        """Per wire: how far (mm) from its nearest seed a voxel can still be flagged."""
        modified = side == "modified"
        return np.array(
            [
                math.hypot(
                    w.influence * (float(w.scale[:, 1].max()) if modified else 1.0),
                    w.end_reach(side),
                )
                + 2 * self.mask_resolution
                + float(np.linalg.norm(h))
                for w in self.wires
            ]
        )

    def _end_cap(self) -> float:
        """How far (mm) beyond its end planes a rigid wire still sweeps: the along-wire
        offset of a voxel centre within half a field voxel (and a mask pixel) of them."""
        return float(np.linalg.norm(self.spacing * self.field_scale)) * 0.5 + self.mask_resolution

    def _smooth_trim(
        self,
        tables: list[WireTables],
        lo: np.ndarray,
        h: np.ndarray,
        out: _SideResult,
        side: str,
    ) -> _SideResult:
        """One side's result with the bits of ``ends="smooth"`` wires as they need them.

        A flag beyond an end reaches as far as its own wire's :meth:`Wire.end_reach`
        (the OpenCL pass takes the largest of all wires): the falloff on the modified
        side, half of it on the base side. A smooth wire's place is vacated out to the
        middle of its fades (along the wire and across its radius, plus the half field
        voxel by which masks grow), not beyond: the fades move their content
        continuously, so what lies past their middle mostly stays and is shown.
        """
        region_lo, rshape, r_wire, r_u, bits, count = out
        if not any(w.smooth for w in self.wires):
            return out
        flat = np.flatnonzero(bits)
        wire_of = r_wire.ravel()[flat]
        for wi, w in enumerate(self.wires):
            sel = flat[wire_of == wi]
            if len(sel) == 0:
                continue
            p = _region_centres(lo, h, region_lo, rshape, sel)
            x, y, z, u = _wire_local(tables[wi], side, r_u.ravel()[sel], p)
            ends = (u <= 0.0) | (u >= 1.0)
            drop = ends & (np.abs(z) > self._end_cap() + w.end_reach(side))
            if side == "base" and w.smooth:
                core = (1.0 + 0.5 * RADIAL_FADE) * w.radius + self._end_cap()
                drop |= np.hypot(x, y) > core
            bits.reshape(-1)[sel[drop]] = False
        return region_lo, rshape, r_wire, r_u, bits, count

    def _weights(
        self,
        tables: list[WireTables],
        lo: np.ndarray,
        h: np.ndarray,
        shape: tuple[int, int, int],
        region_lo: np.ndarray,
        rshape: tuple[int, int, int],
        r_wire: np.ndarray,
        r_u: np.ndarray,
        swept: np.ndarray,
    ) -> np.ndarray | None:
        """The field's displacement weights (see :attr:`WireField.weight`): 1 where a
        rigid wire is nearest, the smooth fade of the nearest smooth wire elsewhere;
        None when every wire is rigid. Only the swept voxels and their neighbours (the
        corners a swept sample interpolates) are computed; the rest hold 1, unused."""
        if not any(w.smooth for w in self.wires):
            return None
        weight = np.ones(shape, dtype=np.float32, order="F")
        inner = np.ones(rshape, dtype=np.float32)
        flat_wire = r_wire.ravel()
        need = np.flatnonzero(ndimage.maximum_filter(swept, size=3, mode="constant"))
        for wi, w in enumerate(self.wires):
            if not w.smooth:
                continue
            for start in range(0, len(need), FLAG_CHUNK):
                chunk = need[start : start + FLAG_CHUNK]
                sel = chunk[flat_wire[chunk] == wi]
                if len(sel) == 0:
                    continue
                p = _region_centres(lo, h, region_lo, rshape, sel)
                inner.reshape(-1)[sel] = _fade(w, tables[wi], r_u.ravel()[sel], p)
        weight[_box_slices(region_lo, rshape)] = inner
        return weight

    def _warn_ends_inside(
        self, tables: list[WireTables], masks: list[tuple[np.ndarray, int, float]]
    ) -> None:
        """Warn (one line per end) where a rigid wire ends inside the object it sweeps
        and moves it there: the object under its end plane's mask goes on beyond the
        end, its cross-section moves (by more than half a voxel), and the rigid sweep
        cuts it there. An end at rest inside the object cuts nothing visible."""
        px = self.mask_resolution
        for wi, (w, tab, (mask, _, half)) in enumerate(zip(self.wires, tables, masks, strict=True)):
            if w.smooth:
                continue
            for end, plane, sign in (("start", 0, -1.0), ("end", -1, 1.0)):
                a, b = np.nonzero(mask[plane])
                if len(a) < 4:
                    continue
                i = 0 if plane == 0 else LUT_SIZE - 1
                fm = tab.modified_frames[i]
                step = sign * 3.0 * px * tab.length_modified / tab.length_base
                p = (
                    tab.modified_points[i]
                    + np.outer((a - half) * px, fm[:, 0])
                    + np.outer((b - half) * px, fm[:, 1])
                    + step * fm[:, 2]
                )
                q = p @ tab.matrices[i].T + tab.offsets[i]
                moves = np.linalg.norm(q - p, axis=1).max() > 0.5 * float(self.spacing.min())
                inside = self._beta_at(w, q)
                if moves and inside.sum() > max(4, 0.1 * len(a)):
                    label = f"{w.name!r}" if w.name else str(wi)
                    warnings.warn(
                        f"wire {label}: its {end} lies inside the object it sweeps"
                        f" ({100 * inside.mean():.0f}% of the end's cross-section goes on"
                        " past it), and the rigid sweep cuts the object there; use"
                        " ends='smooth' or extend the wire past the object",
                        stacklevel=3,
                    )

    def _beta_at(self, wire: Wire, q: np.ndarray) -> np.ndarray:
        """β of the volume at world points q (False outside the volume)."""
        rotated = not np.array_equal(self._direction, np.eye(3))
        ijk = ((q - self.origin) @ self._direction) if rotated else q - self.origin
        ijk = ijk / self.spacing
        use = np.all((ijk >= -0.5) & (ijk <= np.asarray(self.data.shape) - 0.5), axis=1)
        out = np.zeros(len(q), dtype=bool)
        if use.any():
            vals = ndimage.map_coordinates(
                self.data, ijk[use].T, order=1, mode="nearest", prefilter=False
            )
            out[use] = wire.classify(vals)
        return out

    def _propagate(
        self,
        seeds: tuple[np.ndarray, np.ndarray, np.ndarray],
        tables: list[WireTables],
        lo: np.ndarray,
        h: np.ndarray,
        shape: tuple[int, int, int],
        side: str,
    ) -> _SideResult:
        """(wire, u) of the nearest seed for every voxel of the wires' region on one
        side (the reference, numpy path): the region's first voxel and shape, the two
        grids, which voxels lie within their wire's reach, and the seed count."""
        from voxwarp.deform.wires.propagation import nearest_seed

        c_lo, rshape, grid, flat, s_wire, s_u = self._region(seeds, tables, lo, h, shape, side)
        wire_of = np.zeros(int(np.prod(rshape)), dtype=np.int16)
        u_of = np.zeros(int(np.prod(rshape)), dtype=np.float32)
        wire_of[flat], u_of[flat] = s_wire, s_u
        sampling = tuple(float(v) for v in h)
        with warnings.catch_warnings():
            warnings.simplefilter("default")
            nearest = nearest_seed(grid, sampling, backend=self.backend).ravel()
        if side == "modified":
            #: the propagation's input (seed mask over the region, voxel spacing), kept
            #: for benchmarks that time other propagations on the same grid
            self.propagation_input = (grid, sampling)
        # voxels farther from their nearest seed than that wire's reach cannot be
        # flagged: only the others are refined and tested against the masks
        reach2 = self._reach(h, side) ** 2
        near = np.zeros(len(nearest), dtype=bool)

        def near_chunk(start: int) -> None:
            # squared distance to the nearest seed, summed over the axes in order
            idx = np.arange(start, min(start + FLAG_CHUNK, len(nearest)))
            own = np.unravel_index(idx, rshape)
            seed = np.unravel_index(nearest[idx], rshape)
            d2 = ((own[0] - seed[0]) * h[0]) ** 2
            d2 += ((own[1] - seed[1]) * h[1]) ** 2
            d2 += ((own[2] - seed[2]) * h[2]) ** 2
            near[idx] = d2 <= reach2[wire_of[nearest[idx]]]

        with ThreadPoolExecutor(MASK_THREADS) as pool:
            list(pool.map(near_chunk, range(0, len(nearest), FLAG_CHUNK)))
        return (
            c_lo,
            rshape,
            wire_of[nearest].reshape(rshape),
            u_of[nearest].reshape(rshape),
            near.reshape(rshape),
            len(flat),
        )

    def _flagged_side(self, job: _SideJob) -> _SideResult:
        """:meth:`_side` the paper's way (sections 5.1, 7.1): flag the voxels that a set
        pixel of a plane mask touches (grown by one voxel, so that planes fanning out
        on the outside of a bend leave no gap), propagate the nearest seed only over
        them and their neighbours (the voxels a swept sample interpolates t from; a
        k-d tree of the seeds, exact Euclidean), then the mask test of the numpy path on
        them: a voxel is swept where both say so."""
        seeds, tables, grown, lo, h, shape, side, timings = job.parts()
        from scipy.spatial import cKDTree

        t0 = time.perf_counter()
        c_lo, rshape, grid, flat, s_wire, s_u = self._region(seeds, tables, lo, h, shape, side)
        if side == "modified":
            self.propagation_input = (grid, tuple(float(v) for v in h))
        touched = self._touched(tables, grown, lo, h, c_lo, rshape, side)
        cand = ndimage.maximum_filter(touched, size=3, mode="constant")
        domain = ndimage.maximum_filter(cand, size=3, mode="constant")
        dom = np.flatnonzero(domain)
        seed_pts = np.stack(np.unravel_index(flat, rshape), -1) * h
        dist, which = cKDTree(seed_pts).query(
            np.stack(np.unravel_index(dom, rshape), -1) * h, workers=-1
        )
        n = int(np.prod(rshape))
        r_wire = np.zeros(n, dtype=np.int16)
        r_u = np.zeros(n, dtype=np.float32)
        near = np.zeros(n, dtype=bool)
        r_wire[dom], r_u[dom] = s_wire[which], s_u[which]
        near[dom] = dist <= self._reach(h, side)[s_wire[which]]
        r_wire, r_u, near = r_wire.reshape(rshape), r_u.reshape(rshape), near.reshape(rshape)
        t1 = time.perf_counter()
        bits = self._flags(tables, grown, lo, h, c_lo, rshape, r_wire, r_u, near, side) & cand
        timings["propagate"] += t1 - t0
        timings["flags"] += time.perf_counter() - t1
        return c_lo, rshape, r_wire, r_u, bits, len(flat)

    def _touched(
        self,
        tables: list[WireTables],
        grown: list[tuple[np.ndarray, int, float]],
        lo: np.ndarray,
        h: np.ndarray,
        c_lo: np.ndarray,
        rshape: tuple[int, int, int],
        side: str,
    ) -> np.ndarray:
        """Region voxels holding a set pixel of a (grown) plane mask: the paper's flags.
        On the base side the pixels are mapped as the sweep maps them (``q = A p + b``).
        The end planes also flag along the end tangents as far as the mask test reaches
        past them (the end cap, plus a smooth wire's :meth:`Wire.end_reach`)."""
        out = np.zeros(rshape, dtype=bool)
        rs = np.asarray(rshape)
        px = self.mask_resolution
        for wi, (w, tab) in enumerate(zip(self.wires, tables, strict=True)):
            mask, k, half = grown[wi]
            n_planes = mask.shape[0]
            tt_all = np.linspace(0.0, LUT_SIZE - 1.0, n_planes)
            reach = self._end_cap() + w.end_reach(side)
            steps = np.arange(1, math.ceil(reach / px) + 1) * px
            block = max(1, TOUCH_BLOCK_PIXELS // (k * k))
            for p0 in range(0, n_planes, block):
                pl, a, b = np.nonzero(mask[p0 : p0 + block])
                pl = pl + p0
                tt = tt_all[pl]
                fm = _lerp_table(tab.modified_frames, tt)
                x, y = (a - half) * px, (b - half) * px
                p = _lerp_table(tab.modified_points, tt)
                p += x[:, None] * fm[:, :, 0] + y[:, None] * fm[:, :, 1]
                tangent = fm[:, :, 2]
                if side == "base":  # where the sweep takes these pixels from
                    a_t, b_t = tab.lookup(tt)
                    p = np.einsum("nij,nj->ni", a_t, p) + b_t
                    tangent = _lerp_table(tab.base_frames, tt)[:, :, 2]
                pts = [p]
                for end, sign in ((0, -1.0), (n_planes - 1, 1.0)):
                    at = pl == end
                    if at.any():
                        pts += [p[at] + sign * d * tangent[at] for d in steps]
                p = np.concatenate(pts)
                idx = np.floor((p - lo) / h).astype(np.int64) - c_lo
                ok = np.all((idx >= 0) & (idx < rs), axis=1)
                out[idx[ok, 0], idx[ok, 1], idx[ok, 2]] = True
        return out

    def _flags(
        self,
        tables: list[WireTables],
        masks: list[tuple[np.ndarray, int, float]],
        lo: np.ndarray,
        h: np.ndarray,
        region_lo: np.ndarray,
        rshape: tuple[int, int, int],
        r_wire: np.ndarray,
        r_u: np.ndarray,
        r_near: np.ndarray,
        side: str,
    ) -> np.ndarray:
        """Mask bits of a region's voxels (refining ``r_u`` in place to the closest
        point): swept voxels on the modified side, the object's place on the base side."""
        out = np.zeros(rshape, dtype=bool)
        centres = [lo[a] + (np.arange(n) + region_lo[a] + 0.5) * h[a] for a, n in enumerate(rshape)]
        near = np.nonzero(r_near.ravel())[0]
        flat_wire = r_wire.ravel()[near]
        order = near[np.argsort(flat_wire, kind="stable")]
        bounds = np.searchsorted(r_wire.ravel()[order], np.arange(len(self.wires) + 1))
        flat_u = r_u.reshape(-1)
        flat_out = out.reshape(-1)

        def run(wi: int, sel: np.ndarray) -> None:
            ii, jj, kk = np.unravel_index(sel, rshape)
            p = np.stack([centres[0][ii], centres[1][jj], centres[2][kk]], -1)
            u, bits = self._mask_bits(self.wires[wi], tables[wi], masks[wi], flat_u[sel], p, side)
            flat_u[sel] = u
            flat_out[sel] = bits

        # chunks of voxels (small temporaries), a few threads (numpy releases the GIL)
        jobs = [
            (wi, order[a : min(a + FLAG_CHUNK, bounds[wi + 1])])
            for wi in range(len(self.wires))
            for a in range(int(bounds[wi]), int(bounds[wi + 1]), FLAG_CHUNK)
        ]
        with ThreadPoolExecutor(MASK_THREADS) as pool:
            list(pool.map(lambda job: run(*job), jobs))
        return out

    def warp(self) -> WireFieldWarp:
        """The warp that renders this deformer's field (built on first call if needed).

        The same object follows later :meth:`build` calls (its revision changes).
        """
        if self.field is None:
            self.build()
        if self._warp is None:
            self._warp = WireFieldWarp(self)
            if self.ctx is not None:
                self._warp.textures(self.ctx)
        return self._warp

    # ------------------------------------------------------------------ stages
    def _plane_masks(self, wire: Wire, tab: WireTables) -> tuple[np.ndarray, int, int]:
        """Masks (planes, K, K) of one wire, K and how many planes were dropped (no
        object)."""
        px = self.mask_resolution
        n_planes = max(2, math.ceil(tab.length_modified / px) + 1)
        smax = float(wire.scale[:, 1].max())
        half = math.ceil(wire.influence * smax / px)
        k = 2 * half + 1
        if n_planes * k * k > MAX_MASK_PIXELS:
            raise WarpError(
                f"wire {wire.name or self.wires.index(wire)}: its masks would need"
                f" {n_planes:,} planes of {k}x{k} pixels, over the limit of"
                f" {MAX_MASK_PIXELS:,}; give a smaller radius or scale, a shorter modified"
                " wire, or a coarser mask_resolution"
            )
        ax = (np.arange(k) - half) * px
        x, y = np.meshgrid(ax, ax, indexing="ij")
        disc = x**2 + y**2 <= (wire.influence * smax) ** 2
        # the radius is the region of influence on the base side: a scaled cross-section
        # covers s * radius on the modified side
        tt = np.linspace(0.0, LUT_SIZE - 1.0, n_planes)
        s_at = wire.scale_at(tt / (LUT_SIZE - 1))
        in_disc = (x[None] ** 2 + y[None] ** 2) <= (wire.influence * s_at[:, None, None]) ** 2
        obj = self._object_pixels(wire, tab, tt, x[disc], y[disc], in_disc[:, disc])
        obj_full = np.zeros((n_planes, k, k), dtype=bool)
        obj_full[:, disc] = obj
        obj = obj_full
        # the object is chosen within the radius (as the rigid sweep does); a smooth
        # wire's fade beyond it takes the parts of the same objects that lie there
        core = (x[None] ** 2 + y[None] ** 2) <= (wire.radius * s_at[:, None, None]) ** 2
        mask, has = self._seed_fill(obj & core, x, y)
        # cavities (a vessel's lumen, a swim bladder) move with their object
        mask = _fill_holes_in_planes(mask)
        structure = np.zeros((3, 3, 3), dtype=bool)
        structure[1] = ndimage.generate_binary_structure(2, 1)
        if self.dilation:
            mask = ndimage.binary_dilation(mask, structure=structure, iterations=self.dilation)
            mask &= in_disc & disc[None]
        if wire.smooth:
            mask |= self._fade_pixels(obj, core, mask, structure) & in_disc
        mask[~has] = False
        return mask, k, int((~has).sum())

    def _seed_fill(
        self, obj: np.ndarray, x: np.ndarray, y: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The object pixels of the planes' masks (before holes and dilation) and which
        planes hold any: with ``masks``, the 2.5D seed fill; else every β pixel."""
        n_planes = obj.shape[0]
        if not self.masks:
            return obj.copy(), obj.reshape(n_planes, -1).any(axis=1)
        # seed: the object pixel nearest the wire on each plane ("searching outward
        # from the wire"); the fill is 2.5D: a plane's pixel joins when it connects,
        # in its plane or through the masks of the neighbouring planes, to a seed, so
        # an object that splits along the wire (a forked tail fin) stays whole,
        # while an object that never touches the seeded one (a neighbouring vessel)
        # stays out
        r2 = np.where(obj, (x**2 + y**2)[None], np.inf)
        flat = r2.reshape(n_planes, -1)
        seed = flat.argmin(axis=1)
        has = np.isfinite(flat[np.arange(n_planes), seed])
        labels, _ = ndimage.label(obj, structure=ndimage.generate_binary_structure(3, 1))
        seed_labels = np.unique(labels.reshape(n_planes, -1)[np.arange(n_planes), seed][has])
        keep = np.zeros(int(labels.max()) + 1, dtype=bool)
        keep[seed_labels[seed_labels > 0]] = True
        mask = keep[labels]
        return mask, mask.reshape(n_planes, -1).any(axis=1)

    def _fade_pixels(
        self, obj: np.ndarray, core: np.ndarray, mask: np.ndarray, structure: np.ndarray
    ) -> np.ndarray:
        """A smooth wire's mask pixels beyond its radius (``core``): the β pixels there
        that connect (2.5D) to the mask within it, or all of them without ``masks``;
        dilated as the mask is."""
        if self.masks:
            labels, _ = ndimage.label(obj, structure=ndimage.generate_binary_structure(3, 1))
            keep = np.zeros(int(labels.max()) + 1, dtype=bool)
            keep[labels[mask & obj]] = True
            keep[0] = False
            extra = keep[labels] & ~core
        else:
            extra = obj & ~core
        if self.dilation:
            extra = ndimage.binary_dilation(extra, structure=structure, iterations=self.dilation)
        return extra

    def _object_pixels(
        self,
        wire: Wire,
        tab: WireTables,
        tt: np.ndarray,
        x: np.ndarray,
        y: np.ndarray,
        in_disc: np.ndarray,
    ) -> np.ndarray:
        """β of the volume under the pixels (x, y) (mm, in the modified frame) of the
        planes at table coordinates ``tt``, (planes, pixels) bool; False outside the
        volume and outside ``in_disc``. Planes go in blocks (their temporaries stay in
        the cache; a few threads sample blocks at once, numpy and scipy release the GIL)
        and only pixels in the disc and the volume are sampled."""
        a, b = tab.lookup(tt)
        m = _lerp_table(tab.modified_points, tt)
        fm = _lerp_table(tab.modified_frames, tt)
        centre = np.einsum("pij,pj->pi", a, m) + b
        vlo = np.zeros(3) - 0.5
        vhi = np.asarray(self.data.shape) - 1.0 + 0.5
        # an identity rotation changes no bit of the product: skip it
        rotated = not np.array_equal(self._direction, np.eye(3))

        def sample(sl: slice) -> tuple[slice, np.ndarray, np.ndarray]:
            # deformed points p = M + x N_m + y B_m -> base points q = C + A (p - M)
            local = x[None, :, None] * fm[sl, None, :, 0] + y[None, :, None] * fm[sl, None, :, 1]
            q = centre[sl, None, :] + np.einsum("pij,pnj->pni", a[sl], local)
            ijk = ((q - self.origin) @ self._direction) if rotated else q - self.origin
            ijk /= self.spacing
            use = np.all((ijk >= vlo) & (ijk <= vhi), axis=-1) & in_disc[sl]
            vals = ndimage.map_coordinates(
                self.data, ijk[use].T, order=1, mode="nearest", prefilter=False
            )
            return sl, use, vals

        out = np.zeros((len(tt), len(x)), dtype=bool)
        step = max(1, MASK_BLOCK_PIXELS // max(len(x), 1))
        blocks = [slice(p0, p0 + step) for p0 in range(0, len(tt), step)]
        with ThreadPoolExecutor(MASK_THREADS) as pool:
            for sl, use, vals in pool.map(sample, blocks):
                block = out[sl]
                block[use] = wire.classify(vals)  # β in this thread: it may be any callable
        return out

    def _seeds(
        self,
        tables: list[WireTables],
        lo: np.ndarray,
        h: np.ndarray,
        shape: tuple[int, int, int],
        side: str,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Seed voxels (flat indices), their wire and closest u (section 5.1): the 8
        voxels of every field cell the wire of ``side`` enters, nearest wire first."""
        shape_a = np.asarray(shape)
        all_idx, all_d, all_w, all_u = [], [], [], []
        for wi, (w, tab) in enumerate(zip(self.wires, tables, strict=True)):
            curve = w.modified if side == "modified" else w.base
            tparam = tab.t_modified if side == "modified" else tab.t_base
            length = tab.length_modified if side == "modified" else tab.length_base
            n = max(2, math.ceil(4 * length / float(h.min())) + 1)
            pts = curve.evaluate(np.interp(np.linspace(0.0, 1.0, n), tab.u, tparam))
            cell = np.floor((pts - lo) / h - 0.5).astype(np.int64)
            corners = (cell[:, None, :] + _CORNERS[None]).reshape(-1, 3)
            ok = np.all((corners >= 0) & (corners < shape_a), axis=1)
            idx = np.unique(np.ravel_multi_index(corners[ok].T, shape))
            if len(idx) == 0:
                continue
            centres = lo + (np.stack(np.unravel_index(idx, shape), -1) + 0.5) * h
            tc, d = curve.closest_point(centres, precision=self.precision)
            all_idx.append(idx)
            all_d.append(d)
            all_w.append(np.full(len(idx), wi))
            all_u.append(np.interp(tc, tparam, tab.u))
        if not all_idx:
            raise WarpError(
                f"no {side} wire passes through the attribute field: check the control points"
            )
        idx = np.concatenate(all_idx)
        d = np.concatenate(all_d)
        wire = np.concatenate(all_w)
        u = np.concatenate(all_u)
        # keep the minimum distance per voxel
        order = np.lexsort((d, idx))
        idx, wire, u = idx[order], wire[order], u[order]
        first = np.ones(len(idx), dtype=bool)
        first[1:] = idx[1:] != idx[:-1]
        return idx[first], wire[first].astype(np.int16), u[first].astype(np.float32)

    def _mask_bits(
        self,
        wire: Wire,
        tab: WireTables,
        mask_geom: tuple[np.ndarray, int, float],
        u: np.ndarray,
        p: np.ndarray,
        side: str,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Refined closest-point fractions u of points p near ``wire`` (on ``side``) and
        whether the plane mask at u covers them.

        On the modified side the mask pixel is p's position in the modified frame; on
        the base side p's base-frame position is turned and scaled as the sweep does
        (``s R(θ)``) into the modified plane's pixels.
        """
        mask, k, half = mask_geom
        n_planes = mask.shape[0]
        px = self.mask_resolution
        if side == "modified":
            points, frames, length = tab.modified_points, tab.modified_frames, tab.length_modified
        else:
            points, frames, length = tab.base_points, tab.base_frames, tab.length_base
        u = _refine_u(points, frames[:, :, 2], length, u, p)
        # the nearest table entry: its spacing (length / 255) is far below a mask pixel
        i = np.rint(u * (LUT_SIZE - 1)).astype(np.int64)
        f = frames.astype(np.float32)[i]
        d = (p - points[i]).astype(np.float32)
        x = np.einsum("ni,ni->n", d, f[:, :, 0])
        y = np.einsum("ni,ni->n", d, f[:, :, 1])
        z = np.einsum("ni,ni->n", d, f[:, :, 2])
        if side == "base":
            theta = wire.twist_at(u)
            s = wire.scale_at(u)
            c, si = np.cos(theta), np.sin(theta)
            x, y = s * (c * x - si * y), s * (si * x + c * y)
        plane = np.clip(np.rint(u * (n_planes - 1)).astype(np.int64), 0, n_planes - 1)
        a = np.rint(x / px + half).astype(np.int64)
        b = np.rint(y / px + half).astype(np.int64)
        ok = (a >= 0) & (a < k) & (b >= 0) & (b < k)
        # beyond the end planes nothing is swept (the along-wire offset stays within a
        # field voxel of the plane)
        cap = self._end_cap() + wire.end_reach(side)
        ends = (u <= 0.0) | (u >= 1.0)
        ok &= ~ends | (np.abs(z) <= cap)
        out = np.zeros(len(u), dtype=bool)
        out[ok] = mask[plane[ok], a[ok], b[ok]]
        return u, out


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


def _refine_u(
    points: np.ndarray, tangents: np.ndarray, length: float, u: np.ndarray, p: np.ndarray
) -> np.ndarray:
    """Closest-point fractions u of points p, refined from the nearest seed's u.

    The nearest seed voxel's u is off by up to about a voxel along the wire, and where
    the wire twists fast that error turns the cross-section (by twist rate x error). Each
    step moves u by the along-wire offset of p from the wire point at u (a Newton step of
    the closest-point condition, ignoring curvature), using the nearest table entry of
    the wire's ``points`` and unit ``tangents`` (equally spaced in arc length).
    """
    n = len(points) - 1
    u = np.asarray(u, dtype=np.float64)
    for _ in range(REFINE_STEPS):
        i = np.clip(np.rint(u * n).astype(np.int64), 0, n)
        z = np.einsum("ni,ni->n", p - points[i], tangents[i])
        u = np.clip(i / n + z / length, 0.0, 1.0)
    return u


def _region_centres(
    lo: np.ndarray,
    h: np.ndarray,
    region_lo: np.ndarray,
    rshape: tuple[int, int, int],
    flat: np.ndarray,
) -> np.ndarray:
    """World centres (mm) of region voxels given by flat region indices."""
    ii = np.stack(np.unravel_index(flat, rshape), -1)
    return lo + (ii + region_lo + 0.5) * h


def _wire_local(
    tab: WireTables, side: str, u: np.ndarray, p: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Coordinates (x, y, z) of points p in the frame of ``side``'s wire at their
    closest point (u refined from the given u), and that u."""
    if side == "modified":
        points, frames, length = tab.modified_points, tab.modified_frames, tab.length_modified
    else:
        points, frames, length = tab.base_points, tab.base_frames, tab.length_base
    u = _refine_u(points, frames[:, :, 2], length, u, p)
    i = np.rint(u * (LUT_SIZE - 1)).astype(np.int64)
    d = p - points[i]
    f = frames[i]
    return (
        np.einsum("ni,ni->n", d, f[:, :, 0]),
        np.einsum("ni,ni->n", d, f[:, :, 1]),
        np.einsum("ni,ni->n", d, f[:, :, 2]),
        u,
    )


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _fade(wire: Wire, tab: WireTables, u: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Displacement weight of deformed points p of a smooth wire: 1 within its (scaled)
    radius and between its end planes, fading smoothly to 0 over :data:`RADIAL_FADE`
    times the radius beyond the radius and over ``falloff`` mm beyond each end plane."""
    x, y, z, u = _wire_local(tab, "modified", u, p)
    rm = wire.radius * wire.scale_at(u)
    radial = 1.0 - _smoothstep((np.hypot(x, y) - rm) / (RADIAL_FADE * rm))
    beyond = np.where(u >= 1.0, np.maximum(z, 0.0), 0.0) + np.where(
        u <= 0.0, np.maximum(-z, 0.0), 0.0
    )
    along = 1.0 - _smoothstep(beyond / wire.falloff)
    return (radial * along).astype(np.float32)


def _box_overlap(
    a_lo: np.ndarray, a_shape: tuple[int, int, int], b_lo: np.ndarray, b_shape: tuple[int, int, int]
) -> tuple[tuple[slice, ...], tuple[slice, ...]] | None:
    """The overlap of boxes a and b (first voxel, shape) as slices into each, or None."""
    first = np.maximum(a_lo, b_lo)
    end = np.minimum(np.asarray(a_lo) + a_shape, np.asarray(b_lo) + b_shape)
    if np.any(end <= first):
        return None
    into_a = tuple(slice(int(f - a), int(e - a)) for f, e, a in zip(first, end, a_lo, strict=True))
    into_b = tuple(slice(int(f - b), int(e - b)) for f, e, b in zip(first, end, b_lo, strict=True))
    return into_a, into_b


def _fill_holes_in_planes(mask: np.ndarray) -> np.ndarray:
    """``mask`` (planes, K, K) with the holes of each plane filled: background pixels
    not 4-connected within their plane to the plane's edge (what
    ``ndimage.binary_fill_holes`` does with an in-plane structure, by one labelling)."""
    in_plane = np.zeros((3, 3, 3), dtype=bool)
    in_plane[1] = ndimage.generate_binary_structure(2, 1)
    labels, n = ndimage.label(~mask, structure=in_plane)
    outside = np.zeros(n + 1, dtype=bool)
    for edge in (labels[:, 0, :], labels[:, -1, :], labels[:, :, 0], labels[:, :, -1]):
        outside[edge] = True
    outside[0] = True  # the mask itself
    return mask | ~outside[labels]


def _box_slices(first: np.ndarray, shape: tuple[int, int, int]) -> tuple[slice, slice, slice]:
    return tuple(slice(int(first[a]), int(first[a]) + shape[a]) for a in range(3))  # type: ignore[return-value]


_CORNERS = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=np.int64)


def _curve_box(curve: Curve) -> tuple[np.ndarray, np.ndarray]:
    pts = curve.evaluate(np.linspace(0.0, 1.0, 257))
    return pts.min(axis=0), pts.max(axis=0)


def _newton_forward(warp: Warp, p: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Newton steps on ``warp.apply(p) = x`` from ``p`` (the base class's iteration from
    a given seed); unconverged points are left for :func:`check_forward`."""
    p = p.copy()
    for _ in range(warp.forward_steps):
        r = warp.apply(p) - x
        bad = np.linalg.norm(r, axis=1) > warp.forward_tolerance
        if not np.any(bad):
            break
        j = warp.jacobian(p[bad])
        ok = np.abs(np.linalg.det(j)) > 1e-12
        step = r[bad].copy()
        step[ok] = np.linalg.solve(j[ok], r[bad][ok][..., None])[..., 0]
        p[bad] -= step
    return p


def _lerp_table(table: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Entries of a table (n, ...) linearly interpolated at table coordinates t (clamped
    to [0, n - 1]); frames come out not re-orthonormalised (neighbouring entries differ
    by well under a degree)."""
    n = table.shape[0]
    t = np.clip(np.asarray(t, dtype=np.float64), 0.0, n - 1)
    i0 = np.minimum(np.floor(t).astype(np.int64), n - 2)
    f = (t - i0).reshape(-1, *([1] * (table.ndim - 1)))
    return table[i0] * (1 - f) + table[i0 + 1] * f


def _segment_starts(wires: Sequence[Wire], tables: Sequence[WireTables]) -> np.ndarray:
    """Where each segment of each modified wire starts, in table units (the paper
    layout's segments): (wires, PAPER_MAX_SEGMENTS + 1) float32, the last real entry
    the wire's end (LUT_SIZE - 1), repeated to the right. A segment s starts at curve
    parameter s / n_segments, turned into a table coordinate through the wire's table
    of curve parameters (the same piecewise-linear map the tables interpolate)."""
    top = float(LUT_SIZE - 1)
    out = np.full((len(wires), PAPER_MAX_SEGMENTS + 1), top, dtype=np.float64)
    for wi, (w, tab) in enumerate(zip(wires, tables, strict=True)):
        n = w.modified.n_segments
        knots = np.arange(n + 1) / n
        out[wi, : n + 1] = np.interp(knots, tab.t_modified, tab.u) * top
        out[wi, 0], out[wi, n] = 0.0, top
    return out.astype(np.float32)


def _paper_codes(
    wire: np.ndarray, u: np.ndarray, swept: np.ndarray, starts: np.ndarray, counts: np.ndarray
) -> np.ndarray:
    """The paper layout's uint16 codes of voxels with wire ids, fractions u and swept
    flags (``starts`` from :func:`_segment_starts`, ``counts`` the wires' segment
    counts): ``flag << 15 | wire << 11 | segment << 7 | t``, t = round(127 x the
    position of u within its segment); an unswept code equal to :data:`PAPER_VACATED`
    takes t = 126."""
    w = wire.astype(np.int64)
    tu = np.asarray(u, dtype=np.float64) * (LUT_SIZE - 1)
    st = starts.astype(np.float64)
    seg = np.zeros(w.shape, dtype=np.int64)
    for k in range(1, PAPER_MAX_SEGMENTS):  # segment = inner starts at or below tu
        seg += st[w, k] <= tu
    seg = np.minimum(seg, np.asarray(counts, dtype=np.int64)[w] - 1)
    a, b = st[w, seg], st[w, seg + 1]
    frac = np.where(b > a, (tu - a) / np.where(b > a, b - a, 1.0), 0.0)
    t = np.clip(np.rint(frac * PAPER_T_MAX), 0, PAPER_T_MAX).astype(np.int64)
    c = (w << 11) | (seg << 7) | t
    c = np.where(c == PAPER_VACATED, PAPER_VACATED - 1, c)
    return np.where(swept, c | 0x8000, c).astype(np.uint16)


def _paper_t(code: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Table coordinate of paper codes: ``u_s + (t / 127) (u_{s+1} - u_s)``."""
    c = np.asarray(code, dtype=np.int64)
    w, seg, t = (c >> 11) & 0xF, (c >> 7) & 0xF, c & 0x7F
    st = starts.astype(np.float64)
    w = np.minimum(w, len(st) - 1)  # the vacated code names wire 15
    a, b = st[w, seg], st[w, seg + 1]
    return a + (b - a) * (t / PAPER_T_MAX)


# ---------------------------------------------------------------------- the warp
def _sample_t_float(t_field: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Trilinear t at continuous voxel coordinates g (voxel i centred at i + 1/2), with
    clamp-to-edge: what GL_LINEAR filtering of the t texture returns."""
    shape = np.asarray(t_field.shape)
    gc = np.clip(g - 0.5, 0.0, shape - 1.0)
    i0 = np.minimum(np.floor(gc).astype(np.int64), np.maximum(shape - 2, 0))
    f = gc - i0
    out = np.zeros(len(g))
    for c in _CORNERS:
        idx = np.minimum(i0 + c, shape - 1)
        w = np.prod(np.where(c == 1, f, 1.0 - f), axis=1)
        out += w * t_field[idx[:, 0], idx[:, 1], idx[:, 2]]
    return out


def _sample_t_packed(code: np.ndarray, g: np.ndarray, wire: np.ndarray) -> np.ndarray:
    """t at g from the 8 packed neighbours of the same wire (vacated ones excluded),
    renormalised; the nearest voxel's integer t where none qualifies (as the shader)."""
    return _sample_t_same_wire(
        code, g, wire, lambda v: (v >> 8) & 0x7F, lambda v: v & 0xFF, PACKED_VACATED
    )


def _sample_t_paper(
    code: np.ndarray, g: np.ndarray, wire: np.ndarray, starts: np.ndarray
) -> np.ndarray:
    """t at g (table units) from the 8 paper-layout neighbours of the same wire (vacated
    ones excluded), each turned into its table coordinate before the weighted mean (so
    neighbours in different segments mix their u, not their per-segment t); the
    nearest voxel's own value where none qualifies (as the shader)."""
    return _sample_t_same_wire(
        code, g, wire, lambda v: (v >> 11) & 0xF, lambda v: _paper_t(v, starts), PAPER_VACATED
    )


def _sample_t_same_wire(
    code: np.ndarray,
    g: np.ndarray,
    wire: np.ndarray,
    wire_of: Callable[[np.ndarray], np.ndarray],
    t_of: Callable[[np.ndarray], np.ndarray],
    vacated: int,
) -> np.ndarray:
    """The trilinear mean of ``t_of(code)`` at field points ``g`` over the neighbours
    whose ``wire_of(code)`` is ``wire`` and which are not ``vacated``, renormalised by
    their weights; the nearest voxel's own t where none qualifies."""
    shape = np.asarray(code.shape)
    gc = np.clip(g - 0.5, 0.0, shape - 1.0)
    i0 = np.floor(gc).astype(np.int64)
    f = gc - i0
    ts = np.zeros(len(g))
    ws = np.zeros(len(g))
    for c in _CORNERS:
        idx = np.minimum(i0 + c, shape - 1)
        v = code[idx[:, 0], idx[:, 1], idx[:, 2]].astype(np.int64)
        ok = (wire_of(v) == wire) & (v != vacated)
        w = np.prod(np.where(c == 1, f, 1.0 - f), axis=1) * ok
        ts += w * t_of(v)
        ws += w
    near = np.floor(g).astype(np.int64)
    own = t_of(code[near[:, 0], near[:, 1], near[:, 2]].astype(np.int64))
    return np.where(ws > 0, ts / np.where(ws > 0, ws, 1.0), own)


@register_warp
class WireFieldWarp(Warp):
    """The warp of a wire attribute field (see the module docstring).

    Made by :meth:`WireDeformer.warp`; loaded from scene JSON it holds the wires and
    field parameters only, and builds its field when the scene binds the volume
    (:meth:`bind_volume`).
    """

    kind = "wires"
    glsl_file = "warp_wire.glsl"

    def __init__(
        self, deformer: WireDeformer | None = None, spec: Mapping[str, Any] | None = None
    ) -> None:
        self._deformer = deformer
        self._spec = dict(spec) if spec is not None else None
        self._field: WireField | None = deformer.field if deformer is not None else None
        self._revision = 0
        self._gpu: dict[int, tuple[Any, int, dict[str, Any]]] = {}
        self._pyramids: tuple[int, tuple[Any, Any]] | None = None

    # ------------------------------------------------------------------ state
    @property
    def deformer(self) -> WireDeformer:
        """The :class:`WireDeformer` behind this warp (after :meth:`bind_volume`)."""
        if self._deformer is None:
            raise WarpError(
                "this wire warp has no volume yet: load it through a scene (Scene.from_dict"
                " binds the volume) or call bind_volume(volume)"
            )
        return self._deformer

    @property
    def wires(self) -> list[Wire]:
        """The wires (live: edit them, then :meth:`rebuild`)."""
        return self.deformer.wires

    @property
    def field(self) -> WireField:
        """The current attribute field."""
        if self._field is None:
            self.deformer.build()
            self._field = self.deformer.field
        assert self._field is not None
        return self._field

    def _set_field(self, fld: WireField) -> None:
        self._field = fld
        self._revision += 1
        self._pyramids = None

    def rebuild(self) -> WireFieldStats:
        """Rebuild the field after editing :attr:`wires` (the revision changes)."""
        return self.deformer.build()

    def bind_volume(self, volume: Any) -> None:
        """Build the field on ``volume`` (scene loading); no-op if already built on it."""
        if self._deformer is not None and self._deformer.data is getattr(volume, "data", None):
            return
        spec = self._spec if self._spec is not None else _deformer_spec(self.deformer)
        wires = [Wire.from_dict(w) for w in spec["wires"]]
        self._deformer = WireDeformer(
            volume,
            wires,
            field_scale=spec.get("field_scale", 2),
            layout=spec.get("layout", "float"),
            masks=spec.get("masks", True),
            mask_resolution=spec.get("mask_resolution"),
            dilation=spec.get("dilation", 1),
            propagate=spec.get("propagate", "region"),
        )
        self._deformer._warp = self
        self._deformer.build()

    @property
    def revision(self) -> int:
        """Changes with every rebuild of the field."""
        return self._revision

    # ------------------------------------------------------------------ CPU reference
    def _lookup(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per point: state (0 identity, 1 vacated, 2 swept), wire id and table t."""
        fld = self.field
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        g = (p - fld.lo) / fld.spacing
        shape = np.asarray(fld.shape)
        inside = np.all((g >= 0) & (g < shape), axis=1)
        state = np.zeros(len(p), dtype=np.uint8)
        wire = np.zeros(len(p), dtype=np.int64)
        t = np.zeros(len(p))
        gi = g[inside]
        v = np.floor(gi).astype(np.int64)
        if fld.layout == "float":
            assert fld.state is not None
            assert fld.t is not None
            s = fld.state[v[:, 0], v[:, 1], v[:, 2]].astype(np.int64)
            st = np.minimum(s, 2)
            sw = s >= 2
            w = np.where(sw, s - 2, 0)
            tt = np.zeros(len(gi))
            if sw.any():
                tt[sw] = _sample_t_float(fld.t, gi[sw])
        elif fld.layout == "packed":
            assert fld.code is not None
            c = fld.code[v[:, 0], v[:, 1], v[:, 2]].astype(np.int64)
            sw = (c & 0x8000) != 0
            st = np.where(sw, 2, np.where(c == PACKED_VACATED, 1, 0))
            w = (c >> 8) & 0x7F
            tt = np.zeros(len(gi))
            if sw.any():
                tt[sw] = _sample_t_packed(fld.code, gi[sw], w[sw])
        else:
            assert fld.code is not None
            assert fld.segments is not None
            c = fld.code[v[:, 0], v[:, 1], v[:, 2]].astype(np.int64)
            sw = (c & 0x8000) != 0
            st = np.where(sw, 2, np.where(c == PAPER_VACATED, 1, 0))
            w = (c >> 11) & 0xF
            tt = np.zeros(len(gi))
            if sw.any():
                tt[sw] = _sample_t_paper(fld.code, gi[sw], w[sw], fld.segments)
        state[inside], wire[inside], t[inside] = st, w, tt
        return state, wire, t

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Deformed -> original, as the shader does (vacated points go to :data:`FAR`)."""
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        state, wire, t = self._lookup(p)
        out = p.copy()
        out[state == 1] = FAR
        for wi in np.unique(wire[state == 2]):
            sel = (state == 2) & (wire == wi)
            out[sel] = map_points(self.field.tables[int(wi)], t[sel], p[sel])
        weight = self._weight(p, state)
        if weight is not None:  # smooth ends: p + w (sweep(p) - p), as the shader
            out[state == 2] = p[state == 2] + weight[:, None] * (out[state == 2] - p[state == 2])
        return out

    def _weight(self, p: np.ndarray, state: np.ndarray) -> np.ndarray | None:
        """Displacement weight of the swept points among p (trilinear, as the GPU's
        filtered texture), or None when every wire is rigid."""
        fld = self.field
        if fld.weight is None:
            return None
        return _sample_t_float(fld.weight, (p[state == 2] - fld.lo) / fld.spacing)

    def forward(self, points: np.ndarray) -> np.ndarray:
        """Original -> deformed for (N, 3) points (mm): meshes follow the swept object.

        A point the deformed volume shows in place (``apply(x) = x``) stays. Any other
        is seeded by the closed-form inverse of the sweep: its fraction u on the base
        wire is where the base wire's normal plane passes through it (``(x - C(u))
        . T_b(u) = 0``, interpolated between table entries), and the seed is
        ``A(u)^-1 (x - b(u))`` near the modified wire; Newton steps with
        :meth:`jacobian` then remove what the field's coarse t adds, down to
        :attr:`forward_tolerance`. Points neither in place nor swept (the vacated
        region, beyond the wire's reach) raise :class:`WarpError`
        (:func:`~voxwarp.deform.warp.check_forward`).
        """
        x = np.atleast_2d(np.asarray(points, dtype=np.float64))
        p = x.copy()
        moved = ~(np.linalg.norm(self.apply(x) - x, axis=1) <= self.forward_tolerance)
        if np.any(moved):
            seed = self._sweep_seed(x[moved])
            p[moved] = _newton_forward(self, seed, x[moved])
        return check_forward(self, p, x)

    def _sweep_seed(self, x: np.ndarray) -> np.ndarray:
        """Closed-form forward of each point by the wire whose base plane through it
        lies nearest to the base wire (the point itself where no plane passes)."""
        best = np.full(len(x), np.inf)
        out = x.copy()
        for tab in self.field.tables:
            normal = tab.base_frames[:, :, 2]  # (n, 3) base tangents
            for lo in range(0, len(x), 4096):
                q = x[lo : lo + 4096]
                side = np.einsum("mnk,nk->mn", q[:, None, :] - tab.base_points[None], normal)
                cross = (side[:, :-1] >= 0) & (side[:, 1:] < 0)
                i = np.arange(tab.size - 1)[None, :]
                frac = side[:, :-1] / np.where(cross, side[:, :-1] - side[:, 1:], 1.0)
                t = np.where(cross, i + frac, np.nan)
                near = _lerp_table(tab.base_points, np.nan_to_num(t).ravel()).reshape(*t.shape, 3)
                dist = np.where(cross, np.linalg.norm(q[:, None, :] - near, axis=2), np.inf)
                k = np.argmin(dist, axis=1)
                d = dist[np.arange(len(q)), k]
                sel = d < best[lo : lo + 4096]
                if not np.any(sel):
                    continue
                a, b = tab.lookup(t[np.arange(len(q)), k][sel])
                seed = np.linalg.solve(a, (q[sel] - b)[..., None])[..., 0]
                rows = np.flatnonzero(sel) + lo
                out[rows], best[rows] = seed, d[sel]
        return out

    def jacobian(self, points: np.ndarray, eps: float = 1e-3) -> np.ndarray:
        """A(t) where swept (section 6.1), the identity elsewhere."""
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        state, wire, t = self._lookup(p)
        out = np.broadcast_to(np.eye(3), (len(p), 3, 3)).copy()
        for wi in np.unique(wire[state == 2]):
            sel = (state == 2) & (wire == wi)
            out[sel] = self.field.tables[int(wi)].lookup(t[sel])[0]
        weight = self._weight(p, state)
        if weight is not None:  # I + w (A - I): the weight's own gradient is left out
            out[state == 2] = np.eye(3) + weight[:, None, None] * (out[state == 2] - np.eye(3))
        return out

    def swept(self, points: np.ndarray) -> np.ndarray:
        """Which deformed-space points are swept by a wire (bool per point)."""
        return self._lookup(points)[0] == 2

    # ------------------------------------------------------------------ bounds
    def deformed_bounds(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The original box grown by the field box (a swept object may leave the box)."""
        fld = self.field
        return np.minimum(lo, fld.lo), np.maximum(hi, fld.hi)

    @property
    def bounds_displacement(self) -> bool:
        """True: intervals come from the field."""
        return True

    def displacement_range(
        self, lo: np.ndarray, hi: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Per box, an interval holding ``apply(p) - p`` over the samples that can show
        something (vacated samples show nothing and are left out).

        A swept voxel contributes the displacement of every point of its box for every t
        its samples can interpolate (the range of t over its 3³ neighbourhood): the
        mapping is linear in p, and linear in t between table entries, so the extremes
        lie at the box's corners and at the entries in that range. Identity voxels and
        boxes reaching outside the propagated region contribute 0.
        """
        lo = np.atleast_2d(np.asarray(lo, dtype=np.float64))
        hi = np.atleast_2d(np.asarray(hi, dtype=np.float64))
        query = self._range_query()
        fld = self.field
        a = np.floor((lo - fld.lo) / fld.spacing).astype(np.int64) - fld.region_lo
        b = np.floor((hi - fld.lo) / fld.spacing).astype(np.int64) - fld.region_lo
        rs = np.asarray(fld.region_shape)
        empty = np.any((b < 0) | (a > rs - 1), axis=1)  # no voxel of the region
        outside = np.any((a < 0) | (b > rs - 1), axis=1)  # some place outside it
        a, b = np.clip(a, 0, rs - 1), np.clip(b, 0, rs - 1)
        rlo, rhi = query(a, b)
        rlo = np.where(empty[:, None], 0.0, rlo)
        rhi = np.where(empty[:, None], 0.0, rhi)
        rlo = np.where(outside[:, None], np.minimum(rlo, 0.0), rlo)
        rhi = np.where(outside[:, None], np.maximum(rhi, 0.0), rhi)
        # boxes holding swept voxels of one wire: bound the mapping over the box itself
        # (tighter than the union of its voxels' boxes, by the box's own size)
        info_lo, info_hi = self._info_query()(a, b)
        one = (~empty) & np.isfinite(info_lo[:, 1]) & (info_lo[:, 1] == info_hi[:, 1])
        if one.any():
            sel = np.nonzero(one)[0]
            t_lo = np.maximum(info_lo[sel, 0], 0.0)
            t_hi = np.minimum(info_hi[sel, 0], LUT_SIZE - 1.0)
            tight_lo, tight_hi = _box_mapping_range(
                fld.tables, info_lo[sel, 1].astype(np.int64), t_lo, t_hi, lo[sel], hi[sel]
            )
            # (a smooth wire's weight scales the displacement towards 0)
            smooth = fld.weight is not None
            keep0 = (outside[sel] | (info_hi[sel, 2] > 0) | smooth)[:, None]
            rlo[sel] = _grow(np.where(keep0, np.minimum(tight_lo, 0.0), tight_lo), -1.0)
            rhi[sel] = _grow(np.where(keep0, np.maximum(tight_hi, 0.0), tight_hi), 1.0)
        none = rlo > rhi  # only vacated voxels: nothing shows; any interval is sound
        rlo[none] = 0.0
        rhi[none] = 0.0
        return rlo, rhi

    def _range_query(self) -> Any:
        """Pyramid of per-voxel displacement intervals over the propagated region."""
        return self._bound_pyramids()[0]

    def _info_query(self) -> Any:
        """Pyramid of (t range over each voxel's 3³ neighbourhood, wire id of swept
        voxels, whether a voxel is the identity) over the propagated region."""
        return self._bound_pyramids()[1]

    def _bound_pyramids(self) -> tuple[Any, Any]:
        """Both pyramids of :meth:`displacement_range`, from one pass over the field (per
        revision). A swept voxel's interval is that of its box for every t its samples
        can interpolate (from its 3³ neighbourhood); identity voxels give [0, 0], vacated
        ones nothing (they show nothing)."""
        if self._pyramids is not None and self._pyramids[0] == self._revision:
            return self._pyramids[1]
        fld = self.field
        rs = fld.region_shape
        region = _box_slices(fld.region_lo, rs)
        state, wire, t_all = fld.decode()
        st, wr = state[region], wire[region]
        tt = np.asarray(t_all[region], dtype=np.float64)
        t_lo = ndimage.minimum_filter(tt, size=3, mode="nearest")
        t_hi = ndimage.maximum_filter(tt, size=3, mode="nearest")
        idx = np.nonzero(st.ravel() == 2)[0]
        ii = np.stack(np.unravel_index(idx, rs), -1)
        centres = fld.lo + (ii + fld.region_lo + 0.5) * fld.spacing
        half = 0.5 * fld.spacing
        d_lo, d_hi = _box_mapping_range(
            fld.tables,
            wr.ravel()[idx],
            t_lo.ravel()[idx],
            t_hi.ravel()[idx],
            centres - half,
            centres + half,
        )
        dlo = np.repeat(np.where(st == 0, 0.0, np.inf)[..., None], 3, axis=-1)
        dhi = np.repeat(np.where(st == 0, 0.0, -np.inf)[..., None], 3, axis=-1)
        if fld.weight is not None:  # weights in [0, 1] scale each displacement towards 0
            d_lo, d_hi = np.minimum(d_lo, 0.0), np.maximum(d_hi, 0.0)
        dlo.reshape(-1, 3)[idx] = _grow(d_lo, -1.0)
        dhi.reshape(-1, 3)[idx] = _grow(d_hi, 1.0)
        ident = (st == 0).astype(np.float64)
        wf = wr.astype(np.float64)
        info_lo = np.stack([t_lo, np.where(st == 2, wf, np.inf), -ident], axis=-1)
        info_hi = np.stack([t_hi, np.where(st == 2, wf, -np.inf), ident], axis=-1)
        pyramids = (_MinMaxPyramid(dlo, dhi), _MinMaxPyramid(info_lo, info_hi))
        self._pyramids = (self._revision, pyramids)
        return pyramids

    # ------------------------------------------------------------------ GPU side
    def glsl_constants(self) -> dict[str, Any]:
        """The layout (``#define WARP_LAYOUT_PACKED 0|1``, ``WARP_LAYOUT_PAPER 0|1``),
        table size and the far point."""
        return {
            "LAYOUT_PACKED": "1" if self.field.layout == "packed" else "0",
            "LAYOUT_PAPER": "1" if self.field.layout == "paper" else "0",
            "SMOOTH": "1" if self.field.weight is not None else "0",
            "LUT_SIZE": LUT_SIZE,
            "FAR": FAR,
        }

    def signature(self) -> str:
        """Kind and layout (the layouts compile differently)."""
        smooth = ":smooth" if self.field.weight is not None else ""
        return f"{self.kind}:{self.field.layout}{smooth}"

    def uniforms(self) -> dict[str, Any]:
        """Field box, shape and lookup-table rows (and the paper layout's segment
        starts, ``PAPER_MAX_WIRES`` rows of ``PAPER_MAX_SEGMENTS + 1``, as one array)."""
        fld = self.field
        out: dict[str, Any] = {
            "lo": tuple(float(v) for v in fld.lo),
            "size": tuple(float(v) for v in fld.hi - fld.lo),
            "shape": tuple(float(v) for v in fld.shape),
            "rows": float(3 * len(fld.tables)),
        }
        if fld.layout == "paper":
            assert fld.segments is not None
            seg = np.zeros((PAPER_MAX_WIRES, PAPER_MAX_SEGMENTS + 1), dtype=np.float32)
            seg[: len(fld.segments)] = fld.segments
            out["seg"] = seg.ravel()
        return out

    def textures(self, ctx: Any) -> dict[str, Any]:
        """The field (``state`` + ``t``, or ``code``) and ``lut`` textures on ``ctx``,
        uploaded on first use and after each rebuild."""
        entry = self._gpu.get(id(ctx))
        if entry is not None and entry[0] is ctx and entry[1] == self._revision:
            return entry[2]
        if entry is not None and entry[0] is ctx:
            for tex in entry[2].values():
                tex.release()
        fld = self.field
        texs: dict[str, Any] = {}
        max_3d = int(ctx.info.get("GL_MAX_3D_TEXTURE_SIZE", 2048))
        if max(fld.shape) > max_3d:  # GL would fail silently (GL_INVALID_VALUE)
            axis = int(np.argmax(fld.shape))
            raise WarpError(
                f"the wire attribute field is {'x'.join(map(str, fld.shape))} voxels: axis"
                f" {axis} ({'xyz'[axis]}) is over the GPU's maximum 3D texture size {max_3d};"
                " use a larger field_scale (--field-scale) or keep the wires near the volume"
            )

        def tex3d(a: np.ndarray, dtype: str, linear: bool) -> Any:
            t = ctx.texture3d(fld.shape, 1, np.asfortranarray(a).tobytes(order="F"), dtype=dtype)
            f = ctx.LINEAR if linear else ctx.NEAREST
            t.filter = (f, f)
            t.repeat_x = t.repeat_y = t.repeat_z = False
            return t

        if fld.layout == "float":
            assert fld.state is not None
            assert fld.t is not None
            texs["state"] = tex3d(fld.state, "u1", False)
            texs["t"] = tex3d(fld.t, "f4", True)
        else:
            assert fld.code is not None
            texs["code"] = tex3d(fld.code, "u2", False)
        if fld.weight is not None:
            texs["weight"] = tex3d(fld.weight, "f4", True)
        rows = np.concatenate([tab.gpu_rows() for tab in fld.tables], axis=0)
        lut = ctx.texture((LUT_SIZE, rows.shape[0]), 4, rows.tobytes(), dtype="f4")
        lut.filter = (ctx.LINEAR, ctx.LINEAR)
        lut.repeat_x = lut.repeat_y = False
        texs["lut"] = lut
        self._gpu[id(ctx)] = (ctx, self._revision, texs)
        return texs

    def release(self) -> None:
        """Free the GPU textures; idempotent."""
        for _, _, texs in self._gpu.values():
            for tex in texs.values():
                tex.release()
        self._gpu.clear()

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict[str, Any]:
        """The wires and field parameters (the field is rebuilt from the volume on load)."""
        spec = self._spec if self._deformer is None else _deformer_spec(self._deformer)
        assert spec is not None
        return {"type": self.kind, **spec}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> WireFieldWarp:
        """An unbuilt warp from :meth:`to_dict` output (validated now, built on
        :meth:`bind_volume`)."""
        wires = d.get("wires")
        if not isinstance(wires, Sequence) or isinstance(wires, str) or not wires:
            raise WarpError("a 'wires' warp needs 'wires': a non-empty list of wire objects")
        if len(wires) > MAX_WIRES:
            raise WarpError(f"at most {MAX_WIRES} wires fit one attribute field; got {len(wires)}")
        unknown = set(d) - {"type", *SPEC_KEYS}
        if unknown:
            raise WarpError(f"unknown keys {sorted(unknown)} in a 'wires' warp")
        for w in wires:
            Wire.from_dict(w)  # validate now: errors name the problem at load time
        scale = d.get("field_scale", 2)
        if scale not in FIELD_SCALES:
            raise WarpError(f"field_scale must be one of {FIELD_SCALES}; got {scale!r}")
        layout = d.get("layout", "float")
        if layout not in LAYOUTS:
            raise WarpError(f"layout must be one of {LAYOUTS}; got {layout!r}")
        if layout == "paper" and len(wires) > PAPER_MAX_WIRES:
            raise WarpError(
                f"layout='paper' holds at most {PAPER_MAX_WIRES} wires (4-bit wire id); got"
                f" {len(wires)}: use layout='packed'"
            )
        propagate = d.get("propagate", "region")
        if propagate not in PROPAGATE_MODES:
            raise WarpError(f"propagate must be one of {PROPAGATE_MODES}; got {propagate!r}")
        spec = {k: d[k] for k in SPEC_KEYS if k in d}
        return cls(spec=spec)


#: keys of a ``"wires"`` warp entry besides ``"type"`` (:meth:`WireFieldWarp.from_dict`)
SPEC_KEYS: tuple[str, ...] = (
    "wires",
    "field_scale",
    "layout",
    "masks",
    "mask_resolution",
    "dilation",
    "propagate",
)


def _deformer_spec(deformer: WireDeformer) -> dict[str, Any]:
    spec = {
        "wires": [w.to_dict() for w in deformer.wires],
        "field_scale": deformer.field_scale,
        "layout": deformer.layout,
        "masks": deformer.masks,
        "mask_resolution": deformer.mask_resolution,
        "dilation": deformer.dilation,
    }
    if deformer.propagate != "region":  # written only when not the default
        spec["propagate"] = deformer.propagate
    return spec


def _grow(bound: np.ndarray, sign: float) -> np.ndarray:
    """A displacement bound moved outwards (``sign``) by :data:`FLOAT32_MARGIN`, except
    where it is 0 up to float64 noise: an identity mapping is exact in float32 too (its
    table holds exact ones and zeros), and a margin there would widen the skip maps'
    windows by a whole cell."""
    exact = np.abs(bound) < 1e-9
    return np.where(exact, 0.0, bound + sign * FLOAT32_MARGIN)


#: t ranges spanning more table entries than this mix wires (interpolation across a
#: wire boundary): their bound is taken over the whole table
MAX_T_STEPS = 64


def _box_mapping_range(
    tables: list[WireTables],
    wire: np.ndarray,
    t_lo: np.ndarray,
    t_hi: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Per box, the range of ``A(t) p + b(t) - p`` over p in [lo, hi] and t in
    [t_lo, t_hi] of one wire.

    For a fixed t the displacement is linear in p, so over the box it is its value at
    the centre plus or minus ``|A - I|`` times the half extent; between table entries it
    is linear in t, so its extremes lie at the table entries from floor(t_lo) to
    ceil(t_hi) (which also hold what the GPU's filtered, 8-bit-weighted lookups of t and
    of the table can return). Ranges over more than :data:`MAX_T_STEPS` entries take the
    whole table.
    """
    out_lo = np.full((len(lo), 3), np.inf)
    out_hi = np.full((len(lo), 3), -np.inf)
    centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    top = LUT_SIZE - 1.0
    first = np.floor(t_lo)
    last = np.minimum(np.ceil(t_hi), top)
    wide = last - first > MAX_T_STEPS
    first, last = np.where(wide, 0.0, first), np.where(wide, top, last)
    for wi in np.unique(wire):
        tab = tables[int(wi)]
        for narrow in (True, False):
            sel = np.nonzero((wire == wi) & (wide != narrow))[0]
            if len(sel) == 0:
                continue
            c, h = centre[sel], half[sel]
            for k in range(int((last[sel] - first[sel]).max()) + 1):
                a_k, b_k = tab.lookup(np.minimum(first[sel] + k, last[sel]))
                d = np.einsum("nij,nj->ni", a_k, c) + b_k - c
                e = np.einsum("nij,nj->ni", np.abs(a_k - np.eye(3)), h)
                out_lo[sel] = np.minimum(out_lo[sel], d - e)
                out_hi[sel] = np.maximum(out_hi[sel], d + e)
    return out_lo, out_hi


class _MinMaxPyramid:
    """Min/max of per-voxel (n, 3) intervals over index boxes, by a mip pyramid: a box
    spanning e voxels is covered by at most 2 cells per axis at level ceil(log2 e)."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray) -> None:
        self.levels = [(lo, hi)]
        while max(lo.shape[:3]) > 1:
            lo = _halve(lo, np.minimum, np.inf)
            hi = _halve(hi, np.maximum, -np.inf)
            self.levels.append((lo, hi))

    def __call__(self, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ext = np.max(b - a + 1, axis=1)
        lev = np.ceil(np.log2(np.maximum(ext, 1))).astype(np.int64)
        lev = np.minimum(lev, len(self.levels) - 1)
        out_lo = np.full((len(a), 3), np.inf)
        out_hi = np.full((len(a), 3), -np.inf)
        for level in np.unique(lev):
            sel = lev == level
            lo_l, hi_l = self.levels[level]
            top = np.asarray(lo_l.shape[:3]) - 1
            ia, ib = np.minimum(a[sel] >> level, top), np.minimum(b[sel] >> level, top)
            r_lo = np.full((int(sel.sum()), 3), np.inf)
            r_hi = np.full((int(sel.sum()), 3), -np.inf)
            for c in _CORNERS:
                ix = np.where(c == 1, ib, ia)
                r_lo = np.minimum(r_lo, lo_l[ix[:, 0], ix[:, 1], ix[:, 2]])
                r_hi = np.maximum(r_hi, hi_l[ix[:, 0], ix[:, 1], ix[:, 2]])
            out_lo[sel], out_hi[sel] = r_lo, r_hi
        return out_lo, out_hi


def _halve(a: np.ndarray, op: Any, fill: float) -> np.ndarray:
    for axis in range(3):
        n = a.shape[axis]
        if n == 1:
            continue
        if n % 2:
            pad = [(0, 0)] * a.ndim
            pad[axis] = (0, 1)
            a = np.pad(a, pad, constant_values=fill)
        sl0 = [slice(None)] * a.ndim
        sl1 = [slice(None)] * a.ndim
        sl0[axis] = slice(0, None, 2)
        sl1[axis] = slice(1, None, 2)
        a = op(a[tuple(sl0)], a[tuple(sl1)])
    return a
