"""The :class:`Wire`: base and modified curve, twist and scale keys, radius,
β and ends, and its JSON form."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from voxwarp.deform.warp import WarpError
from voxwarp.deform.wires.constants import (
    DEFAULT_ENDS,
    DEFAULT_SIDES,
    DEFAULT_VACATED,
    ENDS,
    FOLD_RATIO,
    LUT_SIZE,
    MAX_WIRE_POINTS,
    RADIAL_FADE,
    SAVED_ENDS,
    SIDE_FALLOFF_MOVES,
    SIDES,
    VACATED,
    WIRE_KEYS,
)
from voxwarp.deform.wires.curves import Curve
from voxwarp.deform.wires.tables import WireTables, map_points

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
        dropoffDistance); the sweep is rigid inside it; beyond it the sweep fades out
        over ``side_falloff`` mm (``sides="smooth"``), or, with ``sides="rigid"``,
        nothing moves (``ends="rigid"``) or a short fade (``ends="smooth"``).
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
    sides
        What happens around the swept cylinder: ``"smooth"`` (the default) moves
        everything within ``radius + side_falloff`` mm of the modified wire, with no
        masks: the displacement is the sweep's inside the radius and fades (a
        smoothstep, C1) to 0 over ``side_falloff`` mm beyond it, so the surrounding
        tissue stretches, nothing is cut at the radius and no place is vacated;
        ``"rigid"`` is the paper's sweep of the masked object (its original place is
        vacated, section 5), kept for the reproductions.
    side_falloff
        Width (mm) of the fade beyond the radius with ``sides="smooth"``; default
        :attr:`side_falloff` (the radius, or twice the wire's largest move if longer).
    vacated
        With ``sides="rigid"``: what the swept object's original place shows:
        ``"empty"`` (the paper: nothing) or ``"rest"`` (its unmoved content).
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
        sides: str = DEFAULT_SIDES,
        side_falloff: float | None = None,
        vacated: str = DEFAULT_VACATED,
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
        if sides not in SIDES:
            raise WarpError(f"wire sides must be one of {SIDES}; got {sides!r:.40}")
        self.sides = sides
        self.side_falloff_mm = (
            None if side_falloff is None else _positive_mm(side_falloff, "side_falloff")
        )
        if vacated not in VACATED:
            raise WarpError(f"wire vacated must be one of {VACATED}; got {vacated!r:.40}")
        self.vacated = vacated
        self._largest_move: tuple[Any, float] | None = None

    @property
    def falloff(self) -> float:
        """Length (mm) of the fade beyond each end: as given, else the larger of the
        radius and twice the largest end move (:meth:`end_moves`)."""
        if self.falloff_mm is not None:
            return self.falloff_mm
        return max(self.radius, 2.0 * max(self.end_moves()))

    @property
    def side_falloff(self) -> float:
        """Width (mm) of the fade beyond the radius with ``sides="smooth"``: as given,
        else the larger of the radius and :data:`SIDE_FALLOFF_MOVES` (2) times
        :meth:`largest_move`.

        Why: across the fade the warp is ``p + w(r) d`` with d the sweep's displacement
        (|d| <= the largest move m) and w a smoothstep of width F, whose steepest slope
        is 1.5 / F; its Jacobian ``I + d (x) grad w`` has determinant down to
        ``1 - 1.5 m / F``, which folds (shows content twice) once F < 1.5 m
        (:data:`FOLD_RATIO`). 2 m keeps a margin (det >= 0.25); the radius keeps a
        small move's stretch gentle (a fade as wide as the swept cylinder)."""
        if self.side_falloff_mm is not None:
            return self.side_falloff_mm
        return max(self.radius, SIDE_FALLOFF_MOVES * self.largest_move())

    def side_fold_warning(self) -> str | None:
        """A one-line warning when a given ``side_falloff`` is short enough to fold
        (below :data:`FOLD_RATIO` times :meth:`largest_move`), else None."""
        if not self.smooth_sides or self.side_falloff_mm is None:
            return None
        move = self.largest_move()
        if self.side_falloff_mm >= FOLD_RATIO * move:
            return None
        label = repr(self.name) if self.name else "wire"
        return (
            f"{label}: side_falloff {self.side_falloff_mm:g} mm is below {FOLD_RATIO:g} x its"
            f" largest move ({move:.3g} mm): the fade folds (shows tissue twice); give at"
            f" least {FOLD_RATIO * move:.3g} mm or leave it out (default"
            f" {max(self.radius, SIDE_FALLOFF_MOVES * move):.3g} mm)"
        )

    def largest_move(self) -> float:
        """How far (mm) the sweep moves any point within the (scaled) radius at most:
        the wire point and 16 points on the circle of the radius around it, in the
        modified wire's planes at every 8th table entry and the ends, mapped back
        through the tables. Cached per shape of the wire."""
        key = self._shape_key()
        if self._largest_move is None or self._largest_move[0] != key:
            tab = self.tables()
            angle = np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)
            idx = np.unique(np.r_[np.arange(0, tab.size, 8), tab.size - 1])
            u = idx / (tab.size - 1)
            r = self.radius * self.scale_at(u)
            f = tab.modified_frames[idx]  # (n, 3, 3): columns N, B, T
            ring = np.cos(angle)[None, :, None] * f[:, None, :, 0]
            ring = ring + np.sin(angle)[None, :, None] * f[:, None, :, 1]
            m = tab.modified_points[idx]
            p = np.concatenate([m[:, None, :], m[:, None, :] + r[:, None, None] * ring], 1)
            t = np.repeat(idx.astype(np.float64), p.shape[1])
            q = map_points(tab, t, p.reshape(-1, 3))
            move = float(np.linalg.norm(q - p.reshape(-1, 3), axis=1).max())
            self._largest_move = (key, move)
        return self._largest_move[1]

    def _shape_key(self) -> tuple[Any, ...]:
        """What the moves depend on (curves, twist, scale, radius)."""
        return (
            self.base.control_points.tobytes(),
            self.modified.control_points.tobytes(),
            self.twist.tobytes(),
            self.scale.tobytes(),
            self.radius,
        )

    def end_moves(self) -> tuple[float, float]:
        """How far (mm) the sweep moves each end's cross-section at most: the end point
        and 16 points on the circle of the (scaled) radius around it, in the modified
        wire's end plane, mapped back through the wire's tables. Cached per shape of
        the wire."""
        key = self._shape_key()
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
        the radial fade beyond it (``side_falloff`` with ``sides="smooth"``, else
        :data:`RADIAL_FADE` x the radius with ``ends="smooth"``)."""
        return self.reach_at(1.0)

    def reach_at(self, scale: Any) -> Any:
        """How far (mm) from the modified wire anything moves where the cross-section
        scale is ``scale``: ``radius x scale + side_falloff`` (smooth sides), else the
        scaled :attr:`influence` of the rigid sweep."""
        if self.smooth_sides:
            return self.radius * scale + self.side_falloff
        return self.radius * scale * ((1.0 + RADIAL_FADE) if self.smooth else 1.0)

    @property
    def smooth(self) -> bool:
        """Whether the sweep fades out beyond the ends (``ends="smooth"``)."""
        return self.ends == "smooth"

    @property
    def smooth_sides(self) -> bool:
        """Whether everything around the radius moves with a fade (``sides="smooth"``:
        no masks, nothing vacated)."""
        return self.sides == "smooth"

    @property
    def fades(self) -> bool:
        """Whether the wire's displacement is weighted (smooth ends or sides)."""
        return self.smooth or self.smooth_sides

    @property
    def vacates(self) -> bool:
        """Whether the swept object's original place shows nothing (the paper's rigid
        sweep with ``vacated="empty"``)."""
        return self.sides == "rigid" and self.vacated == "empty"

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
            "sides": self.sides,
        }
        if self.falloff_mm is not None:
            d["falloff"] = self.falloff_mm
        if self.side_falloff_mm is not None:
            d["side_falloff"] = self.side_falloff_mm
        if self.vacated != DEFAULT_VACATED:
            d["vacated"] = self.vacated
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
            sides=d.get("sides", DEFAULT_SIDES),
            side_falloff=d.get("side_falloff"),
            vacated=d.get("vacated", DEFAULT_VACATED),
        )

    def __repr__(self) -> str:
        return (
            f"Wire(kind={self.kind!r}, points={len(self.base.control_points)},"
            f" radius={self.radius:g}, beta={self.beta!r}, ends={self.ends!r},"
            f" sides={self.sides!r})"
        )
