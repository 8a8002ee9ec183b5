"""The element grid of the mass-spring model: rest positions, constraints and materials.

About this technique (Knoche 2008, 3.5, 3.6)
--------------------------------------------
An ``n_x x n_y x n_z`` grid of *elements* (point masses) is spread evenly over the
volume's box, faces included: element ``(i, j, k)`` (indices along x, y, z) rests at
``lo + (i, j, k) * spacing`` with ``spacing = (hi - lo) / (shape - 1)``.

A *margin* (mm) pads the grid's box beyond the volume's on every side (``lo`` and ``hi``
are then the padded corners; ``volume_lo``/``volume_hi`` keep the volume's): content
pushed across a face of the volume's box stays inside the grid, so it is carried out
of the box and rendered there instead of being cut off. The element count per axis
stays what was asked; the spacing grows with the box (docs/concepts/margin.md).

Each element carries a material (``stiffness`` in [0, 1], ``damping`` >= 0, ``mass`` > 0) and may be
*fixed* (it never moves). Which elements are fixed by default is the grid's *anchor*
mode (:mod:`voxwarp.deform.elements.anchors`): the outer shell (default), the thesis's
8 corners, or none. While elements are dragged, those beyond the region of influence
(``fix_outside``) are *anchored* at rest (:attr:`ElementGrid.anchored`). Stiffness 1
means rigid: such an element does not move by itself either (:meth:`ElementGrid.pinned`).

Materials can vary over the grid; :meth:`ElementGrid.materials_from_volume` derives the
stiffness from the volume's values, e.g. bone stiffer than soft tissue.

This module only describes the grid; :class:`voxwarp.deform.elements.massspring.MassSpring`
simulates it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from scipy import ndimage

from voxwarp.deform.elements import anchors
from voxwarp.deform.elements.margin import AUTO_MARGIN, auto_margin
from voxwarp.deform.elements.materials import preset_stiffness
from voxwarp.errors import VoxwarpError

#: most elements along one axis
MAX_ELEMENTS_PER_AXIS = 128
#: fewest elements along one axis (one on each face)
MIN_ELEMENTS_PER_AXIS = 2
#: largest grid margin, as a multiple of the volume box's largest side
MAX_MARGIN_FACTOR = 4.0
#: default material of every element
DEFAULT_STIFFNESS = 0.5
DEFAULT_DAMPING = 1.0
DEFAULT_MASS = 1.0

#: (anchor, fix_outside) of a saved grid without those keys: the thesis's set-up
LEGACY_ANCHORS = ("corners", None)
#: a selection of elements: bool mask of the grid shape, one (i, j, k), or (m, 3) indices
Selection = Any


class ElementGridError(VoxwarpError, ValueError):
    """An element grid was given invalid parameters (the message names the fix)."""


class ElementGrid:
    """A regular grid of mass-spring elements over a box, with constraints and materials.

    Parameters
    ----------
    volume_or_bounds
        Either an object with a ``bounds`` attribute giving ``(lo, hi)`` corners in mm
        (such as the app's ``Volume``), or the pair ``(lo, hi)`` itself.
    shape
        Elements per axis ``(n_x, n_y, n_z)``, each an int in
        [2, :data:`MAX_ELEMENTS_PER_AXIS`]; one int means the same on all axes.
    margin
        mm the grid's box reaches beyond the volume's box on every side (>= 0, at most
        :data:`MAX_MARGIN_FACTOR` times the box's largest side); 0 (the default) is the
        volume's box itself; ``"auto"`` (:data:`AUTO_MARGIN`) is :func:`auto_margin`,
        10 % of the box's largest side (the desktop window's default).
    anchor
        The fixed elements of the new grid: ``"shell"`` (default: the outer faces),
        ``"corners"`` (the thesis's 8) or ``"none"``.
    fix_outside
        Region of influence: while elements are held, those farther than this many mm
        from every held element are anchored at rest. ``"auto"``
        (:func:`~voxwarp.deform.elements.anchors.influence_radius`), a radius in mm,
        or 0 / ``"off"`` / None (no region). Default: ``"auto"`` with the shell
        anchor, no region with the others (``"corners"`` is the thesis's set-up).

    Attributes
    ----------
    shape : tuple[int, int, int]
        Elements per axis.
    lo, hi : numpy.ndarray
        (3,) corners of the grid's box in mm (the volume's box padded by ``margin``).
    margin : float
        The padding in mm (``"auto"`` resolved).
    volume_lo, volume_hi : numpy.ndarray
        (3,) corners of the box given (the volume's), without the margin.
    spacing : numpy.ndarray
        (3,) rest distance between neighbouring elements per axis.
    rest_positions : numpy.ndarray
        (n_x, n_y, n_z, 3) float64 rest position of each element.
    fixed : numpy.ndarray
        (n_x, n_y, n_z) bool; True for elements that never move (the user's, and the
        anchor mode's at first).
    anchored : numpy.ndarray
        (n_x, n_y, n_z) bool; elements held at rest by the region of influence of the
        current drag (:meth:`anchor_around`); recomputed by every drag.
    stiffness, damping, mass : numpy.ndarray
        (n_x, n_y, n_z) float32 materials; defaults 0.5, 1.0 and 1.0.

    Examples
    --------
    >>> grid = ElementGrid(((0, 0, 0), (100, 50, 50)), shape=(11, 6, 6), anchor="corners")
    >>> grid.spacing.tolist()
    [10.0, 10.0, 10.0]
    >>> int(grid.fixed.sum())
    8
    """

    def __init__(
        self,
        volume_or_bounds: Any,
        shape: int | Sequence[int] = (16, 16, 16),
        margin: float | str = 0.0,
        anchor: str = anchors.DEFAULT_ANCHOR,
        fix_outside: float | str | None = anchors.DEFAULT,
    ) -> None:
        vlo, vhi = _parse_bounds(volume_or_bounds)
        self.margin: float = resolve_margin(margin, vhi - vlo)
        self.volume_lo: np.ndarray = vlo
        self.volume_hi: np.ndarray = vhi
        lo, hi = padded_box(vlo, vhi, self.margin)
        self.shape: tuple[int, int, int] = _parse_shape(shape)
        self.lo: np.ndarray = lo
        self.hi: np.ndarray = hi
        n = np.asarray(self.shape, dtype=np.float64)
        self.spacing: np.ndarray = (hi - lo) / (n - 1)
        idx = np.stack(np.indices(self.shape, dtype=np.float64), axis=-1)
        self.rest_positions: np.ndarray = lo + idx * self.spacing
        # the faces land exactly on the box, not off by round-off
        for a in range(3):
            sl: list[Any] = [slice(None)] * 3
            sl[a] = -1
            self.rest_positions[(*sl, a)] = hi[a]
        self.fixed: np.ndarray = np.zeros(self.shape, dtype=bool)
        self.stiffness: np.ndarray = np.full(self.shape, DEFAULT_STIFFNESS, dtype=np.float32)
        self.damping: np.ndarray = np.full(self.shape, DEFAULT_DAMPING, dtype=np.float32)
        self.mass: np.ndarray = np.full(self.shape, DEFAULT_MASS, dtype=np.float32)
        self.anchor: str = anchors.check_anchor(anchor)
        self.fix_outside: float | str | None = anchors.check_fix_outside(fix_outside, anchor)
        self.anchored: np.ndarray = np.zeros(self.shape, dtype=bool)
        #: elements the user freed from the region: never anchored again
        self.unanchored: np.ndarray = np.zeros(self.shape, dtype=bool)
        self.fixed[anchors.anchor_mask(self.shape, self.anchor)] = True

    # ------------------------------------------------------------------ selections
    @property
    def count(self) -> int:
        """Total number of elements."""
        return int(np.prod(self.shape))

    def corner_mask(self) -> np.ndarray:
        """Bool mask of the 8 corner elements.

        Returns
        -------
        numpy.ndarray
            (n_x, n_y, n_z) bool, True at the corners.
        """
        m = np.zeros(self.shape, dtype=bool)
        m[:: self.shape[0] - 1, :: self.shape[1] - 1, :: self.shape[2] - 1] = True
        return m

    def mask(self, sel: Selection) -> np.ndarray:
        """Turn a selection into a bool mask of the grid shape.

        Parameters
        ----------
        sel
            A bool array of the grid shape, a single index ``(i, j, k)``, or an (m, 3)
            int array (or list) of indices. ``None`` selects every element.

        Returns
        -------
        numpy.ndarray
            (n_x, n_y, n_z) bool mask (a new array).

        Raises
        ------
        ElementGridError
            When the selection has the wrong shape or type, or an index is outside
            the grid (negative indices are not wrapped around).
        """
        if sel is None:
            return np.ones(self.shape, dtype=bool)
        arr = np.asarray(sel)
        if arr.dtype == bool:
            if arr.shape != self.shape:
                raise ElementGridError(
                    f"a bool selection mask must have the grid shape {self.shape}; "
                    f"got shape {arr.shape}"
                )
            return arr.copy()
        out = np.zeros(self.shape, dtype=bool)
        idx = self.indices(arr)
        out[idx[:, 0], idx[:, 1], idx[:, 2]] = True
        return out

    def indices(self, sel: Selection) -> np.ndarray:
        """Element indices (m, 3) int64 of a selection given as indices.

        Parameters
        ----------
        sel
            A single index ``(i, j, k)`` or an (m, 3) int array / list of indices.

        Returns
        -------
        numpy.ndarray
            (m, 3) int64 indices, validated to lie inside the grid.

        Raises
        ------
        ElementGridError
            When the selection is not made of integer triples, or an index is outside
            the grid.
        """
        arr = np.asarray(sel)
        if arr.size == 0:
            return np.zeros((0, 3), dtype=np.int64)
        if arr.dtype == bool or not np.issubdtype(arr.dtype, np.integer):
            if not (np.issubdtype(arr.dtype, np.floating) and np.all(arr == np.round(arr))):
                raise ElementGridError(
                    "element indices must be integers (i, j, k); got "
                    f"{np.asarray(sel).tolist()!r:.80} of dtype {arr.dtype}"
                )
        idx = arr.astype(np.int64)
        if idx.shape == (3,):
            idx = idx.reshape(1, 3)
        if idx.ndim != 2 or idx.shape[1] != 3:
            raise ElementGridError(
                "select elements by a bool mask of the grid shape "
                f"{self.shape}, one index (i, j, k) or an (m, 3) index array; "
                f"got an array of shape {arr.shape}"
            )
        bad = np.any((idx < 0) | (idx >= np.asarray(self.shape)), axis=1)
        if np.any(bad):
            first = tuple(int(v) for v in idx[np.argmax(bad)])
            raise ElementGridError(
                f"element index {first} is outside the grid of shape {self.shape}; "
                f"indices run from (0, 0, 0) to {tuple(n - 1 for n in self.shape)}"
            )
        return idx

    # ------------------------------------------------------------------ constraints
    def fix(self, sel: Selection) -> None:
        """Fix elements: they stay at their rest positions.

        Parameters
        ----------
        sel
            Bool mask of the grid shape, one index ``(i, j, k)`` or (m, 3) indices.
        """
        self.fixed |= self.mask(sel)

    def free(self, sel: Selection) -> None:
        """Unfix elements (they move again, unless their stiffness is 1); anchored ones
        leave the region's anchors too, and later drags do not anchor them again.

        Parameters
        ----------
        sel
            Bool mask of the grid shape, one index ``(i, j, k)`` or (m, 3) indices.
        """
        m = self.mask(sel)
        self.unanchored |= m & self.anchored
        self.anchored &= ~m
        self.fixed &= ~m

    def pinned(self) -> np.ndarray:
        """Elements that do not move by themselves: fixed, anchored, or rigid
        (stiffness >= 1).

        Returns
        -------
        numpy.ndarray
            (n_x, n_y, n_z) bool mask (a new array).
        """
        return self.constrained() | (self.stiffness >= 1.0)

    def constrained(self) -> np.ndarray:
        """Elements held at rest by a boundary condition: fixed or anchored (a new mask)."""
        return self.fixed | self.anchored

    def anchor_around(
        self, held: np.ndarray, offsets: Any, candidates: np.ndarray | None = None
    ) -> np.ndarray:
        """Recompute :attr:`anchored` for a drag: the elements farther than the region
        radius (``fix_outside``; ``"auto"`` from the spacing and the largest of the
        held ``offsets``, mm) from every ``held`` element, never fixed, held or
        :attr:`unanchored` ones, and (if given) only ``candidates`` (e.g. elements at
        rest). Returns the new mask (also stored); nothing held anchors nothing.
        """
        held = np.asarray(held, dtype=bool).reshape(self.shape)
        off = np.asarray(offsets, dtype=np.float64).reshape((*self.shape, 3))[held]
        radius = anchors.region_radius(self.fix_outside, self.spacing, off)
        if radius is None:
            new = np.zeros(self.shape, dtype=bool)
        else:
            new = anchors.outside_mask(self.spacing, held, radius)
            new &= ~(self.fixed | held | self.unanchored)
            if candidates is not None:
                new &= np.asarray(candidates, dtype=bool).reshape(self.shape)
        self.anchored = new
        return new.copy()

    def describe_anchors(self, drag_mm: float | None = None) -> str:
        """The boundary conditions in one phrase (for the CLI's and the GUI's line);
        ``drag_mm``: the largest drag, to name the automatic radius it gives."""
        return anchors.describe(self.anchor, self.fix_outside, self.spacing, drag_mm)

    # ------------------------------------------------------------------ materials
    def set_material(
        self,
        sel: Selection = None,
        stiffness: float | np.ndarray | None = None,
        damping: float | np.ndarray | None = None,
        mass: float | np.ndarray | None = None,
    ) -> None:
        """Set the material of some (default all) elements; ``None`` leaves a property.

        Parameters
        ----------
        sel
            Elements to change (see :meth:`mask`); ``None`` means all.
        stiffness
            In [0, 1]; 1 makes the elements rigid (pinned at rest).
        damping
            Velocity damping, >= 0 (force ``-damping * velocity``).
        mass
            Element mass, > 0.

        Each value is a number, or an array of the grid shape whose selected entries
        are used. Every value is validated before anything changes.

        Raises
        ------
        ElementGridError
            When a value is out of its range, not finite, or of a wrong shape.
        """
        m = self.mask(sel)
        new = {}
        for name, value, ok, rule in (
            ("stiffness", stiffness, lambda a: (a >= 0) & (a <= 1), "in [0, 1]"),
            ("damping", damping, lambda a: a >= 0, ">= 0"),
            ("mass", mass, lambda a: a > 0, "> 0"),
        ):
            if value is None:
                continue
            a = self._material_values(name, value, m)
            if not np.all(np.isfinite(a)) or not np.all(ok(a)):
                bad = a[~(np.isfinite(a) & ok(a))][0]
                raise ElementGridError(f"{name} must be {rule} (finite); got {float(bad)!r}")
            new[name] = a
        for name, a in new.items():
            getattr(self, name)[m] = a

    def _material_values(self, name: str, value: Any, m: np.ndarray) -> np.ndarray:
        try:
            a = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ElementGridError(f"{name} must be a number or an array of numbers") from exc
        if a.ndim == 0:
            return np.full(int(m.sum()), float(a))
        if a.shape != self.shape:
            raise ElementGridError(
                f"{name} must be a number or an array of the grid shape {self.shape}; "
                f"got shape {a.shape}"
            )
        return a[m]

    def materials_from_volume(
        self,
        data: Any,
        bounds: Sequence[Sequence[float]] | None = None,
        mapping: Callable[[np.ndarray], np.ndarray] | Sequence[Sequence[float]] | None = None,
    ) -> np.ndarray:
        """Set every element's stiffness from the volume value at its rest position.

        The volume is sampled trilinearly (clamped at the border) at each element's
        rest position, and the sampled value is mapped to a stiffness.

        Parameters
        ----------
        data
            (X, Y, Z) voxel values covering ``bounds``: voxel ``i`` along x lies at
            ``lo + i * (hi - lo) / (X - 1)`` (like the elements; an axis of size 1
            lies at ``lo``). Or a volume (an object with ``data``, ``spacing`` and
            ``origin``, e.g. :class:`voxwarp.core.volume.Volume`), whose voxel centres give
            the bounds.
        bounds
            ``(lo, hi)`` corners in mm of the box the voxel centres span; ``None``
            with a volume.
        mapping
            A callable taking the sampled values (array) and returning stiffnesses,
            or control points ``[(value, stiffness), ...]`` interpolated piecewise
            linearly (constant beyond the first and last point, as ``numpy.interp``).

        Returns
        -------
        numpy.ndarray
            The new (n_x, n_y, n_z) float32 stiffness (also stored in ``stiffness``).

        Raises
        ------
        ElementGridError
            On malformed data, bounds or control points, or stiffnesses outside [0, 1].

        Examples
        --------
        A CT-like volume, soft tissue around 40 HU and bone above 400 HU; bone is made
        rigid-ish, soft tissue soft, with a ramp in between:

        >>> data = np.zeros((20, 10, 10), np.float32)
        >>> data[10:] = 1000.0                      # the upper half in x is bone
        >>> grid = ElementGrid(((0, 0, 0), (19, 9, 9)), shape=(6, 3, 3))
        >>> s = grid.materials_from_volume(data, ((0, 0, 0), (19, 9, 9)),
        ...                                [(100.0, 0.2), (400.0, 0.95)])
        >>> [round(float(v), 2) for v in s[:, 0, 0]]
        [0.2, 0.2, 0.2, 0.95, 0.95, 0.95]
        """
        if mapping is None:
            raise ElementGridError(
                "materials_from_volume needs a mapping: control points [(value,"
                " stiffness), ...] or a callable values -> stiffnesses"
            )
        if all(hasattr(data, a) for a in ("data", "spacing", "origin")):
            if bounds is None:
                origin = np.asarray(data.origin, dtype=np.float64)
                n = np.maximum(np.asarray(np.shape(data.data)) - 1, 1)
                bounds = (origin, origin + np.asarray(data.spacing, dtype=np.float64) * n)
            data = data.data
        if bounds is None:
            raise ElementGridError(
                "materials_from_volume needs bounds (lo, hi) of the voxel centres for a"
                " plain array; pass a volume to take them from its spacing and origin"
            )
        vol = np.asarray(data)
        if vol.ndim != 3 or min(vol.shape) < 1:
            raise ElementGridError(f"volume data must be a 3-D (X, Y, Z) array; got {vol.shape}")
        if not np.issubdtype(vol.dtype, np.number) or np.iscomplexobj(vol):
            raise ElementGridError(f"volume data must be real numbers; got dtype {vol.dtype}")
        lo, hi = _parse_bounds(bounds)
        size = np.asarray(vol.shape, dtype=np.float64)
        # continuous voxel index of each element's rest position
        coords = (self.rest_positions - lo) / (hi - lo) * (size - 1)
        values = ndimage.map_coordinates(
            vol.astype(np.float64),
            coords.reshape(-1, 3).T,
            order=1,
            mode="nearest",
        ).reshape(self.shape)
        stiff = _apply_mapping(mapping, values)
        self.set_material(stiffness=stiff)
        return self.stiffness.copy()

    def materials_from_preset(self, volume: Any, preset: str) -> np.ndarray:
        """Set every element's stiffness from ``volume`` by a tissue preset: ``"ct"``
        (Hounsfield units) or ``"mr"`` (the volume's own histogram); see
        :func:`voxwarp.deform.elements.materials.preset_stiffness`. ``volume`` has
        ``data``, ``spacing`` and ``origin``. Returns the new stiffness."""
        values = np.asarray(volume.data)
        return self.materials_from_volume(volume, mapping=preset_stiffness(values, preset))

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable description (plain lists and numbers).

        Returns
        -------
        dict
            ``lo``, ``hi`` (the volume's box, without the margin), ``shape``, ``fixed``
            (list of fixed ``[i, j, k]``), ``margin`` (mm, when it is not 0),
            ``anchor`` and ``fix_outside`` (mm, ``"auto"`` or None; both left out when
            they are the thesis's ``"corners"`` and None, so such a grid saves as it
            did before they existed), and ``stiffness``, ``damping``, ``mass``: a
            number when uniform, else a nested list of the grid shape.
        """
        d: dict[str, Any] = {
            "lo": self.volume_lo.tolist(),
            "hi": self.volume_hi.tolist(),
            "shape": list(self.shape),
            "fixed": np.argwhere(self.fixed).tolist(),
        }
        if (self.anchor, self.fix_outside) != LEGACY_ANCHORS:
            d["anchor"], d["fix_outside"] = self.anchor, self.fix_outside
        for name in ("stiffness", "damping", "mass"):
            a = getattr(self, name)
            d[name] = float(a.flat[0]) if np.all(a == a.flat[0]) else a.tolist()
        if self.margin > 0.0:
            d["margin"] = self.margin
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ElementGrid:
        """Rebuild a grid from its :meth:`to_dict` form.

        Parameters
        ----------
        d
            Mapping with ``lo``, ``hi`` and ``shape``; optionally ``margin`` (mm,
            default 0: files saved before the margin existed load unchanged), ``fixed`` (list of
            indices; default the anchor's), ``anchor`` (default ``"corners"``, as every
            grid saved before anchors existed), ``fix_outside`` (default None: no
            region) and ``stiffness``, ``damping``, ``mass``.

        Returns
        -------
        ElementGrid

        Raises
        ------
        ElementGridError
            When a key is missing or a value is invalid.
        """
        if not isinstance(d, Mapping):
            raise ElementGridError(f"an element grid entry must be an object; got {d!r:.80}")
        missing = [k for k in ("lo", "hi", "shape") if k not in d]
        if missing:
            raise ElementGridError(f"an element grid entry needs the keys {missing}")
        try:
            grid = cls(
                (d["lo"], d["hi"]),
                shape=d["shape"],
                margin=d.get("margin", 0.0),
                anchor=d.get("anchor", LEGACY_ANCHORS[0]),
                fix_outside=d.get("fix_outside", LEGACY_ANCHORS[1]),
            )
        except anchors.AnchorError as exc:
            raise ElementGridError(str(exc)) from exc
        if "fixed" in d:
            grid.fixed[:] = False
            grid.fix(np.asarray(d["fixed"], dtype=np.int64).reshape(-1, 3))
        grid.set_material(
            stiffness=d.get("stiffness"), damping=d.get("damping"), mass=d.get("mass")
        )
        return grid

    def __repr__(self) -> str:
        return (
            f"ElementGrid(shape={self.shape}, lo={self.lo.tolist()}, hi={self.hi.tolist()}, "
            f"margin={self.margin:g}, fixed={int(self.fixed.sum())}, anchor={self.anchor!r})"
        )


def grid_from_entry(d: Mapping[str, Any], model: str, error: type[Exception]) -> ElementGrid:
    """The ``"grid"`` of a saved element model (``model``: its name in messages) as an
    :class:`ElementGrid`; problems raise ``error`` (the model's own exception)."""
    if "grid" not in d:
        raise error(
            f"a {model} entry needs the key 'grid' (an ElementGrid.to_dict() object"
            " with 'lo', 'hi' and 'shape')"
        )
    try:
        return ElementGrid.from_dict(d["grid"])
    except ElementGridError as exc:
        raise error(f"{model} 'grid': {exc}") from exc


def check_margin(margin: Any, size: np.ndarray) -> float:
    """``margin`` as a float in mm, checked: finite, >= 0 and at most
    :data:`MAX_MARGIN_FACTOR` times the largest side of a box of ``size`` (3,) mm."""
    most = MAX_MARGIN_FACTOR * float(np.max(size))
    fix = f"give a margin in mm in [0, {most:g}] ({MAX_MARGIN_FACTOR:g} x the box's largest side)"
    if isinstance(margin, bool | np.bool_):
        raise ElementGridError(f"grid margin must be a number of mm; got {margin!r}; {fix}")
    try:
        m = float(margin)
    except (TypeError, ValueError) as exc:
        raise ElementGridError(
            f"grid margin must be a number of mm; got {margin!r:.40}; {fix}"
        ) from exc
    if not np.isfinite(m) or m < 0.0 or m > most:
        raise ElementGridError(f"grid margin {m:g} mm is out of range; {fix}")
    return m


def default_margin(offsets: Any) -> float:
    """The default grid margin (mm) for drags of the given offsets ((m, 3) mm): the
    largest offset component, 0 without drags.

    No element moves farther than the farthest dragged one: a ChainMail follower moves
    only as far as restores its link to a moved neighbour (Gibson 1997), and a settled
    mass-spring grid is a weighted average of its held neighbours (the maximum
    principle of the discrete spring Laplacian). So content at a face of the volume's
    box stays inside a grid padded by this much.
    """
    a = np.abs(np.asarray(offsets, dtype=np.float64).reshape(-1, 3))
    return float(a.max()) if a.size else 0.0


def resolve_margin(margin: Any, size: Any) -> float:
    """A margin setting as mm for a box of ``size`` (3,) mm: :data:`AUTO_MARGIN` gives
    :func:`auto_margin`, a number is checked by :func:`check_margin`."""
    if isinstance(margin, str) and margin == AUTO_MARGIN:
        return auto_margin(size)
    return check_margin(margin, np.asarray(size, dtype=np.float64))


def padded_box(lo: np.ndarray, hi: np.ndarray, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """The box ``[lo, hi]`` grown by ``margin`` mm on every side (copies)."""
    return np.asarray(lo, np.float64) - margin, np.asarray(hi, np.float64) + margin


def _apply_mapping(mapping: Any, values: np.ndarray) -> np.ndarray:
    if callable(mapping):
        out = np.asarray(mapping(values), dtype=np.float64)
        if out.shape != values.shape:
            out = np.broadcast_to(out, values.shape)
        return out
    try:
        pts = np.asarray(mapping, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ElementGridError(
            "mapping must be a callable or a list of (value, stiffness) control points"
        ) from exc
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 1:
        raise ElementGridError(
            "mapping control points must be a list of (value, stiffness) pairs; "
            f"got an array of shape {pts.shape}"
        )
    if not np.all(np.isfinite(pts)):
        raise ElementGridError("mapping control points must be finite numbers")
    if np.any((pts[:, 1] < 0) | (pts[:, 1] > 1)):
        raise ElementGridError("mapping stiffnesses must be in [0, 1]")
    order = np.argsort(pts[:, 0], kind="stable")
    xs, ys = pts[order, 0], pts[order, 1]
    if np.any(np.diff(xs) == 0):
        raise ElementGridError("mapping control points must have distinct values")
    return np.interp(values, xs, ys)


def _parse_shape(shape: Any) -> tuple[int, int, int]:
    fix = (
        f"give 1 or 3 ints in [{MIN_ELEMENTS_PER_AXIS}, {MAX_ELEMENTS_PER_AXIS}], "
        "e.g. shape=(16, 16, 16)"
    )
    if isinstance(shape, bool | np.bool_):
        raise ElementGridError(f"element grid shape must be ints; got {shape!r}; {fix}")
    if isinstance(shape, int | np.integer):
        shape = (int(shape),) * 3
    try:
        vals = list(shape)
    except TypeError as exc:
        raise ElementGridError(f"element grid shape must be ints; got {shape!r}; {fix}") from exc
    if len(vals) != 3 or not all(
        isinstance(v, int | np.integer) and not isinstance(v, bool | np.bool_) for v in vals
    ):
        raise ElementGridError(f"element grid shape must be 3 ints; got {shape!r}; {fix}")
    if any(v < MIN_ELEMENTS_PER_AXIS or v > MAX_ELEMENTS_PER_AXIS for v in vals):
        raise ElementGridError(f"element grid shape {tuple(vals)} is out of range; {fix}")
    return tuple(int(v) for v in vals)  # type: ignore[return-value]


def _parse_bounds(volume_or_bounds: Any) -> tuple[np.ndarray, np.ndarray]:
    b = getattr(volume_or_bounds, "bounds", volume_or_bounds)
    fix = "pass a volume (with .bounds) or (lo, hi) corners in mm, each 3 finite numbers"
    try:
        lo_in, hi_in = b
        lo = np.asarray(lo_in, dtype=np.float64)
        hi = np.asarray(hi_in, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ElementGridError(f"bad bounds {b!r:.80}; {fix}") from exc
    if lo.shape != (3,) or hi.shape != (3,):
        raise ElementGridError(
            f"bounds corners must be 3-vectors; got shapes {lo.shape} and {hi.shape}; {fix}"
        )
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise ElementGridError(f"bounds must be finite; got lo={lo.tolist()}, hi={hi.tolist()}")
    if np.any(hi <= lo):
        raise ElementGridError(
            f"bounds are empty: need hi > lo on every axis; got lo={lo.tolist()}, "
            f"hi={hi.tolist()}; {fix}"
        )
    return lo, hi
