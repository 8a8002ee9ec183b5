"""The lattice warp: a grid of trilinear cells deforms a box of the volume, inverted per sample.

About this technique (Knuth, Kohlhammer, Kuijper, "Embedding hierarchical deformation
within a realtime scene graph", GRAPP 2010, sections 3-6)
------------------------------------------------------------------------------------
The paper deforms geometry with *trilinear transformations*: the unit cube mapped by
the trilinear interpolation of 8 corner points (section 3, eq. 1), a grid of them for
finer control, composed along a scene graph (sections 4-5) and evaluated in the vertex
shader (section 6). A mesh's vertices are pushed forward. A volume raycaster needs the
opposite direction: it marches in deformed space and must know, per sample ``p``, which
original point ``q`` is seen there. This module is that inverse, as a
:class:`~voxwarp.deform.warp.Warp`.

A :class:`~voxwarp.deform.lattice.trilinear.TrilinearGrid` ``grid`` deforms the content of the box
``[lo, hi]`` (original world, mm): the original point ``x`` has lattice coordinates
``u = (x - lo) / (hi - lo)`` in the unit cube and appears at ``grid(u)``. The warp
solves ``grid(u) = p`` and returns ``q = lo + u (hi - lo)``:

* *Seed* (``inverse="baked"``, and the start of ``"newton"``): ``grid^-1`` is baked on
  the CPU (:meth:`~voxwarp.deform.lattice.trilinear.TrilinearGrid.inverse`) at the nodes of a
  regular
  grid over the deformed lattice's bounding box, :data:`BAKE_FACTOR` nodes per lattice
  cell and axis (:data:`MIN_BAKE_NODES` to :data:`MAX_BAKE_NODES` per axis), stored as
  an RGBA32F 3D texture (xyz = u) and sampled with one hardware-trilinear fetch. Baked
  nodes outside the lattice hold the inverse of the lattice continued linearly beyond
  its surface, so seeds stay smooth across it. Their alpha marks nodes *near* the
  lattice: 1 when a baked cell touching the node overlaps the bounding box of some
  lattice cell's corners (a trilinear cell lies in the convex hull of its corners); a
  sample whose 8 baked corners are all 0 is outside the lattice for sure and skips the
  Newton steps.
* *Newton* (``inverse="newton"``): steps ``u <- u - du``, ``du = J(u)^-1 (grid(u) -
  p)``, until one moves the original point by at most ``tolerance`` (``|du (hi - lo)|``,
  mm; default :data:`DEFAULT_TOLERANCE`), at most ``max_iterations`` of them (default
  :data:`DEFAULT_MAX_ITERATIONS`): a loop with an early exit in the shader, the same
  rule in :meth:`LatticeWarp.solve`. With ``iterations=k`` instead, k fixed steps,
  written out in the shader (the former default was 2). ``grid(u)`` and ``J`` come from
  the 8 corners of u's cell, read with ``texelFetch`` from an RGBA32F texture of the
  nodes (:meth:`~voxwarp.deform.lattice.trilinear.TrilinearGrid.texture_data`). The alternative,
  a hardware-filtered fetch for ``grid(u)`` plus forward differences towards the cell
  centre for ``J`` (exact, the map being linear along each axis within a cell), needs 4
  filtered fetches per step (32 texel reads); the 8 plain fetches read a quarter of
  that, give ``grid`` and ``J`` together and are exact in float32 on every GPU (filtered
  fetches interpolate with 8-bit weights on most hardware: a 2^-9 cell error Newton
  would converge to). Outside ``[0, 1]³`` the boundary cell's polynomial is
  extrapolated, so steps may cross the surface.
  A singular ``J`` (folded lattice) leaves u unchanged.

The point is inside the lattice when the final u lies in ``[0, 1]³``. Outside:

* the *identity* where the lattice's boundary is the box itself (every boundary node
  on its face plane of the box, :attr:`LatticeWarp.boundary_on_box`: content around
  the box stays, and the lattice only moves what is inside it);
* otherwise *nothing* (``q`` far away, :data:`FAR`): the content of the box left its
  place, which shows nothing (like the vacated region of the wire warp), and content
  outside the box is hidden as well. Give the box a margin around the part of the
  volume that is to move, or use the volume's whole box.

A *linear* lattice (``grid.is_linear``, e.g. a translation or rotation of the box) is one
affine map of all space, folded by the raycaster into the ray
(:attr:`LatticeWarp.is_affine`): content around the box moves with it, as with
:class:`~voxwarp.deform.warp.AffineWarp`. For a box holding the whole volume (the usual case)
this equals the rule above, since nothing lies outside the box. The identity lattice
renders exactly like no warp.

The CPU reference (:meth:`LatticeWarp.apply`, :meth:`LatticeWarp.jacobian`) computes
what the shader computes, in float64: the same baked seed, the same trilinear seed
interpolation, the same Newton steps, stopping rule and outside rule (the tests bound
their difference).

Empty-space skipping through deformed space (:meth:`LatticeWarp.displacement_range`):
within a baked cell the seed's displacement ``q - p`` is the trilinear interpolation of
the baked nodes' displacements, so it lies in their range; the Newton steps move q by a
per-cell margin measured once (:meth:`LatticeWarp.cell_margins`: large only in the
cells that the lattice's cell faces, its kinks, cross). The intervals are local (a few
mm), so the raycaster keeps skipping empty space.

Accuracy
--------
The GRAPP paper leaves the inverse aside (its conclusion points to Gomes et al. for it,
and names the inversion a drawback of trilinear transformations); here it is Newton's
method. The baked seed is good almost everywhere but poor where the lattice map has kinks
(its cells' faces: the inverse of a piecewise-trilinear map is not smooth there), so a
fixed number of steps leaves some points far off on some lattices. Newton converges
quadratically near a root where J is regular: the last step, at most ``tolerance``, is
to first order the error of the point before it, and the error after it is of the order
of its square. So a point stopped by the rule lies within ``tolerance`` (mm) of its true
original point, and its residual ``|grid(u) - p|`` within ``tolerance`` times the
lattice's stretch ``|J diag(1 / (hi - lo))|``: the bound the tests assert on random
lattices proven not to fold (``random_lattice``, ``certified_nonfolding`` in the
lab's ``benchmarks/lattice_inverse.py``).
Where J is singular or the lattice folds, the iteration may stop at its cap:
:meth:`LatticeWarp.solve` reports those points, and only their residual bounds the
error. The default tolerance, 1e-3 mm, is a thousandth of a 1 mm voxel and well above
float32's rounding of coordinates of a few hundred mm (~1e-5 mm); below that the GPU
cannot meet the rule and runs to the cap. Each Newton step costs 8 texel fetches per
sample, the seed one filtered fetch.

Measurements (error distribution over random lattices per variant, render cost against
the seed alone and the former 2 fixed steps, CPU preparation): docs/benchmarks.md,
section 'voxwarp.deform.lattice.warp: inverse accuracy and render cost', from
``python -m benchmarks lattice --inverse-only`` (the lab, in the checkout).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from scipy import ndimage

from voxwarp.deform import gl_holders
from voxwarp.deform.lattice.trilinear import TrilinearGrid
from voxwarp.deform.node_grid import cell_reduce, window_reduce
from voxwarp.deform.warp import Warp, WarpError, box_corners, register_warp

#: Inverse modes: the baked seed alone, or the seed refined by Newton steps.
INVERSE_MODES: tuple[str, ...] = ("newton", "baked")
#: keys of a lattice warp entry (:meth:`LatticeWarp.from_dict`), and those it needs
LATTICE_KEYS: tuple[str, ...] = (
    "type", "grid", "box", "inverse", "iterations", "tolerance", "max_iterations",
    "fold_linear",
)  # fmt: skip
LATTICE_REQUIRED: tuple[str, ...] = ("grid", "box")
#: Newton stops once a step moves the original point ``q`` by at most this (mm): a
#: thousandth of a 1 mm voxel, about 100 float32 roundings of a 100 mm coordinate
#: (see "Accuracy" in the module docstring).
DEFAULT_TOLERANCE = 1e-3
#: Most Newton steps of the default ``inverse="newton"`` (the loop's cap).
DEFAULT_MAX_ITERATIONS = 8
#: Most Newton steps of any mode (the cap of the loop, or fixed steps written out).
MAX_ITERATIONS = 8
#: Fixed Newton steps of the former default (``iterations=2``; the benchmark's reference).
DEFAULT_ITERATIONS = 2
#: Baked inverse nodes per lattice cell and axis (on the deformed bounding box) when
#: Newton steps follow the seed, and for the seed alone (``iterations=0``).
BAKE_FACTOR = 4
SEED_ONLY_BAKE_FACTOR = 8
#: Fewest and most baked nodes per axis.
MIN_BAKE_NODES = 9
MAX_BAKE_NODES = 65
#: Baked grids up to this many nodes per axis get per-cell displacement margins
#: (:meth:`LatticeWarp.cell_margins`); larger ones one margin for all cells.
MAX_CELL_MARGIN_NODES = 33
#: Newton steps of the CPU solve beyond the lattice's surface (the baked outside nodes).
EXTEND_ITERATIONS = 30
#: A sample outside a lattice whose boundary is not the box is sent this far (it then
#: lies outside every volume and shows nothing).
FAR = 1.0e20
#: Relative tolerance of "a boundary node lies on its face of the box".
BOX_TOLERANCE = 1e-9
#: A Newton step is skipped where ``|det J| <= SINGULAR * |J_0| |J_1| |J_2|``.
SINGULAR = 1e-6


def _box(box: Any) -> tuple[np.ndarray, np.ndarray]:
    try:
        a = np.asarray(box, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise WarpError(
            f"LatticeWarp box must be (lo, hi), two points (x, y, z) in mm; got {box!r:.80}"
        ) from exc
    if a.shape != (2, 3):
        raise WarpError(
            f"LatticeWarp box must be (lo, hi), two points (x, y, z) in mm; got shape {a.shape}"
        )
    if not np.all(np.isfinite(a)):
        raise WarpError(f"LatticeWarp box has NaN/Inf entries: {a.tolist()}")
    if np.any(a[1] <= a[0]):
        raise WarpError(
            f"LatticeWarp box is degenerate: it needs lo < hi on every axis; got"
            f" lo={a[0].tolist()}, hi={a[1].tolist()} (give the volume's box, e.g."
            " volume.bounds)"
        )
    return a[0].copy(), a[1].copy()


def _iterations(value: Any, inverse: str) -> int | None:
    if value is None:
        return None if inverse == "newton" else 0
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise WarpError(f"iterations must be an integer 0..{MAX_ITERATIONS}; got {value!r}")
    low = 1 if inverse == "newton" else 0
    if not low <= int(value) <= MAX_ITERATIONS:
        raise WarpError(
            f"iterations of inverse={inverse!r} must be {low}..{MAX_ITERATIONS}; got {value}"
            + (" (the seed alone is inverse='baked')" if inverse == "newton" else "")
        )
    return int(value)


def _convergence(
    tolerance: Any, max_iterations: Any, inverse: str, iterations: int | None
) -> tuple[float | None, int | None]:
    """The checked ``(tolerance, max_iterations)``; ``(None, None)`` for fixed steps."""
    if iterations is not None:
        if tolerance is not None or max_iterations is not None:
            what = "the seed alone" if inverse == "baked" else f"{iterations} fixed Newton steps"
            raise WarpError(
                f"tolerance/max_iterations do not apply to {what}: give inverse='newton'"
                " without iterations to iterate until the step is below the tolerance"
            )
        return None, None
    if tolerance is None:
        tol = DEFAULT_TOLERANCE
    elif isinstance(tolerance, bool) or not isinstance(tolerance, int | float | np.number):
        raise WarpError(f"tolerance must be a number of mm > 0 (e.g. 1e-3); got {tolerance!r}")
    else:
        tol = float(tolerance)
    if not (np.isfinite(tol) and tol > 0.0):
        raise WarpError(f"tolerance must be a finite number of mm > 0 (e.g. 1e-3); got {tol}")
    if max_iterations is None:
        return tol, DEFAULT_MAX_ITERATIONS
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, int | np.integer):
        raise WarpError(
            f"max_iterations must be an integer 1..{MAX_ITERATIONS}; got {max_iterations!r}"
        )
    if not 1 <= int(max_iterations) <= MAX_ITERATIONS:
        raise WarpError(f"max_iterations must be 1..{MAX_ITERATIONS}; got {max_iterations}")
    return tol, int(max_iterations)


def lattice_eval(
    nodes: np.ndarray, u: np.ndarray, jacobian: bool = True
) -> tuple[np.ndarray, np.ndarray | None]:
    """The lattice map and its Jacobian as the shader evaluates them.

    Parameters
    ----------
    nodes
        ``(nx + 1, ny + 1, nz + 1, 3)`` node points (mm).
    u
        ``(N, 3)`` unit-cube coordinates; outside ``[0, 1]³`` the polynomial of the
        boundary cell (the cell of ``clip(u, 0, 1)``) is extrapolated.
    jacobian
        Also return ``d grid / d u``.

    Returns
    -------
    (F, J)
        ``(N, 3)`` points and ``(N, 3, 3)`` Jacobians (``None`` without ``jacobian``).
    """
    cells = np.asarray(nodes.shape[:3]) - 1
    g = u * cells
    # (a NaN/inf u, e.g. from a wild Newton step, picks a border cell and gives NaN/inf)
    i = np.clip(np.floor(np.nan_to_num(g)), 0, cells - 1).astype(np.intp)
    f = g - i
    c = {}
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                c[dx, dy, dz] = nodes[i[:, 0] + dx, i[:, 1] + dy, i[:, 2] + dz]
    fx, fy, fz = f[:, 0:1], f[:, 1:2], f[:, 2:3]

    def mix(a: np.ndarray, b: np.ndarray, t: np.ndarray) -> np.ndarray:
        return a + (b - a) * t

    x00 = mix(c[0, 0, 0], c[1, 0, 0], fx)
    x10 = mix(c[0, 1, 0], c[1, 1, 0], fx)
    x01 = mix(c[0, 0, 1], c[1, 0, 1], fx)
    x11 = mix(c[0, 1, 1], c[1, 1, 1], fx)
    y0 = mix(x00, x10, fy)
    y1 = mix(x01, x11, fy)
    out = mix(y0, y1, fz)
    if not jacobian:
        return out, None
    dx = mix(
        mix(c[1, 0, 0] - c[0, 0, 0], c[1, 1, 0] - c[0, 1, 0], fy),
        mix(c[1, 0, 1] - c[0, 0, 1], c[1, 1, 1] - c[0, 1, 1], fy),
        fz,
    )
    dy = mix(x10 - x00, x11 - x01, fz)
    dz = y1 - y0
    jac = np.stack([dx * cells[0], dy * cells[1], dz * cells[2]], axis=-1)
    return out, jac


def _newton_update(u: np.ndarray, r: np.ndarray, j: np.ndarray) -> np.ndarray:
    """``u - J^-1 r`` by Cramer's rule (as the shader); rows with a (nearly) singular J
    (``|det J| <= SINGULAR |J_0| |J_1| |J_2|``) stay."""
    return u - _newton_delta(r, j)


def _regular(j: np.ndarray) -> np.ndarray:
    """Rows where J is not (nearly) singular: ``|det J| > SINGULAR |J_0| |J_1| |J_2|``."""
    det = np.sum(j[:, :, 0] * np.cross(j[:, :, 1], j[:, :, 2]), axis=1)
    return np.abs(det) > SINGULAR * np.prod(np.linalg.norm(j, axis=1), axis=1)


def _newton_delta(r: np.ndarray, j: np.ndarray) -> np.ndarray:
    """``J^-1 r`` by Cramer's rule (as the shader); 0 where J is (nearly) singular."""
    j0, j1, j2 = j[:, :, 0], j[:, :, 1], j[:, :, 2]
    a = np.cross(j1, j2)
    det = np.sum(j0 * a, axis=1)
    ok = _regular(j)
    num = np.stack(
        [
            np.sum(a * r, axis=1),
            np.sum(np.cross(j2, j0) * r, axis=1),
            np.sum(np.cross(j0, j1) * r, axis=1),
        ],
        axis=1,
    )
    return np.where(ok[:, None], num / np.where(ok, det, 1.0)[:, None], 0.0)


def _newton_step(nodes: np.ndarray, u: np.ndarray, p: np.ndarray) -> np.ndarray:
    """One Newton step of the shader on ``grid(u) = p``."""
    f, j = lattice_eval(nodes, u)
    assert j is not None
    return _newton_update(u, f - p, j)


def _check_not_flat(nodes: np.ndarray) -> None:
    """WarpError when the lattice has (almost) no volume: it cannot be inverted."""
    cells = np.asarray(nodes.shape[:3]) - 1
    idx = np.stack(np.meshgrid(*(np.arange(c) for c in cells), indexing="ij"), -1)
    _, j = lattice_eval(nodes, (idx.reshape(-1, 3) + 0.5) / cells)
    assert j is not None
    volume = abs(float(np.mean(np.linalg.det(j))))
    pts = nodes.reshape(-1, 3)
    extent = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
    if not volume > 1e-9 * extent**3:
        raise WarpError(
            "the lattice is flat (zero volume): it has no inverse; move its nodes so that"
            " its cells span a volume"
        )


def _trilinear_sample(field: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Trilinear value of a node field ``(nx, ny, nz, C)`` at ``s`` in ``[0, 1]³`` of its box
    (node-centred texture coordinates with clamp-to-edge: what GL_LINEAR returns)."""
    n = np.asarray(field.shape[:3])
    g = np.clip(s * (n - 1), 0.0, n - 1.0)
    i0 = np.minimum(np.floor(g).astype(np.intp), n - 2)
    f = g - i0
    out = np.zeros((len(s), field.shape[3]))
    for c in range(8):
        o = np.array([(c >> 0) & 1, (c >> 1) & 1, (c >> 2) & 1])
        w = np.prod(np.where(o == 1, f, 1.0 - f), axis=1)
        idx = i0 + o
        out += w[:, None] * field[idx[:, 0], idx[:, 1], idx[:, 2]]
    return out


@register_warp
class LatticeWarp(Warp):
    """Warp by a trilinear lattice (see the module docstring).

    Parameters
    ----------
    grid
        The :class:`~voxwarp.deform.lattice.trilinear.TrilinearGrid`: unit cube -> deformed world
        (mm).
    box
        ``(lo, hi)``: the box (original world, mm) whose content the lattice deforms,
        mapped onto the unit cube; usually the volume's box (``volume.bounds``).
    inverse
        ``"newton"`` (default): the baked seed refined by Newton steps until a step moves
        the original point by at most ``tolerance`` (or by ``iterations`` fixed steps);
        ``"baked"``: the seed alone (``iterations`` fixed steps may still be added).
    iterations
        Fixed Newton steps instead of iterating to the tolerance: 1..8 for
        ``"newton"`` (default None: iterate), 0..8 for ``"baked"`` (default 0).
    tolerance
        ``"newton"`` without ``iterations``: stop once a step moves ``q`` by at most this
        many mm (default :data:`DEFAULT_TOLERANCE`).
    max_iterations
        ... and after at most this many steps, 1..8 (default
        :data:`DEFAULT_MAX_ITERATIONS`).
    fold_linear
        True (default): a linear lattice is an affine warp that the raycaster folds into
        the ray. False: it is inverted per sample like any other (for tests and
        benchmarks of the general path).
    """

    kind = "lattice"
    glsl_file = "warp_lattice.glsl"

    def __init__(
        self,
        grid: TrilinearGrid,
        box: Any,
        inverse: str = "newton",
        iterations: int | None = None,
        *,
        tolerance: float | None = None,
        max_iterations: int | None = None,
        fold_linear: bool = True,
    ) -> None:
        if not isinstance(grid, TrilinearGrid):
            raise WarpError(
                "LatticeWarp needs a voxwarp.deform.lattice.trilinear.TrilinearGrid;"
                f" got {type(grid).__name__}"
                " (build one with TrilinearGrid(nodes) or TrilinearGrid.from_function)"
            )
        if not isinstance(inverse, str) or inverse not in INVERSE_MODES:
            raise WarpError(f"inverse must be one of {list(INVERSE_MODES)}; got {inverse!r}")
        self.grid = grid
        self.lo, self.hi = _box(box)
        self.inverse = inverse
        #: fixed Newton steps (None: iterate to :attr:`tolerance`)
        self.iterations = _iterations(iterations, inverse)
        #: the stopping rule of the iteration (both None with fixed steps)
        self.tolerance, self.max_iterations = _convergence(
            tolerance, max_iterations, inverse, self.iterations
        )
        self.fold_linear = bool(fold_linear)
        self._nodes = np.asarray(grid.nodes, dtype=np.float64)
        if self._nodes.ndim != 4 or self._nodes.shape[3] != 3 or min(self._nodes.shape[:3]) < 2:
            raise WarpError(
                f"the lattice's nodes must have shape (nx + 1, ny + 1, nz + 1, 3); got"
                f" {self._nodes.shape}"
            )
        if not np.all(np.isfinite(self._nodes)):
            raise WarpError("the lattice's nodes have NaN/Inf entries")
        _check_not_flat(self._nodes)
        self._linear = bool(grid.is_linear)
        #: the warp is one affine map of all space (folded by the raycaster)
        self._affine = self._linear and self.fold_linear
        self._bake: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._cell_boxes: tuple[np.ndarray, np.ndarray] | None = None
        self._cell_ranges: tuple[np.ndarray, np.ndarray] | None = None
        self._margin: float | None = None
        self._cell_margins: np.ndarray | None = None
        # id(ctx) -> (ctx, {name: texture})
        self._gpu: dict[int, tuple[Any, dict[str, Any]]] = {}

    # ---------------------------------------------------------------- properties
    @property
    def size(self) -> np.ndarray:
        """``hi - lo`` of the box (mm)."""
        return self.hi - self.lo

    @property
    def cells(self) -> tuple[int, int, int]:
        """Lattice cells per axis."""
        n = self._nodes.shape[:3]
        return (n[0] - 1, n[1] - 1, n[2] - 1)

    @property
    def steps(self) -> int:
        """Most Newton steps after the seed: the fixed :attr:`iterations`, or the cap
        :attr:`max_iterations` of the iteration to the tolerance."""
        return self.iterations if self.iterations is not None else int(self.max_iterations or 0)

    @property
    def adaptive(self) -> bool:
        """True when Newton iterates until its step is below :attr:`tolerance`."""
        return self.iterations is None

    @property
    def boundary_on_box(self) -> bool:
        """True when every boundary node lies on its face plane of the box: the
        lattice's surface is the box's, and outside it the warp is the identity."""
        n = self._nodes
        tol = BOX_TOLERANCE * float(np.max(self.size))
        for axis in range(3):
            low = np.take(n, 0, axis=axis)[..., axis]
            high = np.take(n, -1, axis=axis)[..., axis]
            if np.max(np.abs(low - self.lo[axis])) > tol:
                return False
            if np.max(np.abs(high - self.hi[axis])) > tol:
                return False
        return True

    def _box_matrix(self) -> np.ndarray:
        """4x4: unit cube -> box (original world)."""
        s = np.eye(4)
        s[:3, :3] = np.diag(self.size)
        s[:3, 3] = self.lo
        return s

    def forward_matrix(self) -> np.ndarray:
        """4x4 original -> deformed of a linear lattice: ``grid.matrix() @ box^-1``."""
        if not self._linear:
            raise WarpError("forward_matrix(): the lattice is not linear (use forward())")
        return np.asarray(self.grid.matrix(), dtype=np.float64) @ np.linalg.inv(self._box_matrix())

    # ---------------------------------------------------------------- affine case
    @property
    def is_affine(self) -> bool:
        """True for a linear lattice (unless ``fold_linear=False``)."""
        return self._affine

    def affine_matrix(self) -> np.ndarray:
        """Deformed -> original 4x4 matrix of a linear lattice."""
        if not self._linear:
            raise WarpError("LatticeWarp is not affine: its lattice is not linear")
        m = self.forward_matrix()
        if abs(np.linalg.det(m[:3, :3])) < 1e-12:
            raise WarpError("the linear lattice is singular (flat): it cannot be inverted")
        return np.linalg.inv(m)

    # ---------------------------------------------------------------- CPU reference
    def forward(self, points: np.ndarray) -> np.ndarray:
        """Original -> deformed: ``grid((x - lo) / (hi - lo))`` for points of the box."""
        x = np.atleast_2d(np.asarray(points, dtype=np.float64))
        return lattice_eval(self._nodes, (x - self.lo) / self.size, jacobian=False)[0]

    def lattice_coordinates(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The shader's inverse of deformed points: ``(u, inside)``.

        ``u`` (N, 3): the seed refined by Newton steps (0 where the seed says the point
        is far from the lattice); ``inside``: u in ``[0, 1]³`` and near the lattice.
        (Also for a linear lattice: what ``fold_linear=False`` renders.)
        """
        u, inside, _, _ = self.solve(points)
        return u, inside

    def solve(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`lattice_coordinates`, the Newton steps each point took and whether the
        iteration stopped by its rule: ``(u, inside, steps, converged)``.

        Fixed steps: :attr:`iterations` everywhere. Iterating: each step
        ``du = J(u)^-1 (grid(u) - p)`` is applied, and the point stops once
        ``|du (hi - lo)| <= tolerance`` (mm), or after :attr:`max_iterations` steps; a
        point stopped by the cap has not converged (near a fold, a singular J): there,
        only its residual ``|grid(u) - p|`` says how far off it is. A singular J gives
        ``du = 0``: the point stops where it is, not converged. ``steps`` is 0 where the
        seed says the point is far from the lattice; ``converged`` is False there and
        everywhere with fixed steps (no rule).
        """
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        seed, seed_lo, seed_hi = self.baked_inverse()
        s = (p - seed_lo) / (seed_hi - seed_lo)
        near = np.all((s >= 0.0) & (s <= 1.0), axis=1)
        val = np.zeros((len(p), 4))
        if np.any(near):
            val[near] = _trilinear_sample(seed, s[near])
        near &= val[:, 3] != 0.0
        u = np.where(near[:, None], val[:, :3], 0.0)
        steps = np.zeros(len(p), dtype=np.int64)
        converged = np.zeros(len(p), dtype=bool)
        if np.any(near):
            un, pn = u[near], p[near]
            if self.adaptive:
                un, steps[near], converged[near] = self._iterate(un, pn)
            else:
                for _ in range(self.steps):
                    un = _newton_step(self._nodes, un, pn)
                steps[near] = self.steps
            u[near] = un
        inside = near & np.all((u >= 0.0) & (u <= 1.0), axis=1)
        return u, inside, steps, converged

    def _iterate(self, u: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Newton from ``u`` on ``grid(u) = p`` until the step is below the tolerance (the
        shader's loop); returns u, the steps taken and whether the rule stopped them."""
        u = u.copy()
        steps = np.zeros(len(u), dtype=np.int64)
        converged = np.zeros(len(u), dtype=bool)
        active = np.arange(len(u))
        tol2 = float(self.tolerance or 0.0) ** 2
        for _ in range(self.steps):
            f, j = lattice_eval(self._nodes, u[active])
            assert j is not None
            du = _newton_delta(f - p[active], j)
            u[active] -= du
            steps[active] += 1
            # a singular J gives du = 0: the point stops (as in the shader), unconverged
            small = np.sum((du * self.size) ** 2, axis=1) <= tol2
            converged[active[small & _regular(j)]] = True
            active = active[~small]
            if len(active) == 0:
                break
        return u, steps, converged

    def export_resolution(self) -> float:
        """The shortest cell edge (mm) of the deformed lattice: its inverse, which the
        volume is drawn with, bends at the deformed cells' faces."""
        return _shortest_edge(np.asarray(self._nodes))

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Deformed -> original, as the GLSL computes it (outside: the identity or
        :data:`FAR`, see the module docstring)."""
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        if self._affine:
            m = self.affine_matrix()
            return p @ m[:3, :3].T + m[:3, 3]
        u, inside = self.lattice_coordinates(p)
        out = p.copy() if self.boundary_on_box else np.full(p.shape, FAR)
        out[inside] = self.lo + u[inside] * self.size
        return out

    def jacobian(self, points: np.ndarray, eps: float = 1e-3) -> np.ndarray:
        """``diag(hi - lo) J(u)^-1`` inside the lattice (J = d grid / d u at the computed
        u), the identity outside and where J is singular; the linear part for a linear
        lattice. ``eps`` is unused (kept for the base-class signature)."""
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        if self._affine:
            m = self.affine_matrix()
            return np.broadcast_to(m[:3, :3], (len(p), 3, 3)).copy()
        u, inside = self.lattice_coordinates(p)
        out = np.broadcast_to(np.eye(3), (len(p), 3, 3)).copy()
        if np.any(inside):
            _, j = lattice_eval(self._nodes, u[inside])
            assert j is not None
            j0, j1, j2 = j[:, :, 0], j[:, :, 1], j[:, :, 2]
            det = np.sum(j0 * np.cross(j1, j2), axis=1)
            scale = np.prod(np.linalg.norm(j, axis=1), axis=1)
            ok = np.abs(det) > SINGULAR * scale
            sel = np.flatnonzero(inside)[ok]
            out[sel] = self.size[None, :, None] * np.linalg.inv(j[ok])
        return out

    # ---------------------------------------------------------------- the baked seed
    @property
    def bake_shape(self) -> tuple[int, int, int]:
        """Baked nodes per axis: ``factor * max(cells) + 1``, clipped to
        :data:`MIN_BAKE_NODES`..:data:`MAX_BAKE_NODES` (the same on every axis); factor
        :data:`BAKE_FACTOR`, or :data:`SEED_ONLY_BAKE_FACTOR` without Newton steps."""
        factor = BAKE_FACTOR if self.steps > 0 else SEED_ONLY_BAKE_FACTOR
        n = int(np.clip(factor * max(self.cells) + 1, MIN_BAKE_NODES, MAX_BAKE_NODES))
        return (n, n, n)

    def seed_box(self) -> tuple[np.ndarray, np.ndarray]:
        """The baked nodes' box: the lattice nodes' bounding box (deformed mm), widened
        where it is flat."""
        pts = self._nodes.reshape(-1, 3)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        pad = 1e-6 * max(float(np.max(hi - lo)), 1e-9)
        return lo - pad, hi + pad

    def baked_inverse(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The baked seed: ``(field, lo, hi)``.

        ``field`` is ``bake_shape + (4,)``: xyz = u at the baked nodes
        (:meth:`~voxwarp.deform.lattice.trilinear.TrilinearGrid.inverse` inside the lattice, the
        inverse
        of the lattice continued linearly beyond its surface outside), w = 1 for nodes
        near the lattice (see the module docstring), else 0. ``lo``, ``hi``: the box
        the nodes span (:meth:`seed_box`). Computed once.
        """
        if self._bake is not None:
            return self._bake
        lo, hi = self.seed_box()
        shape = self.bake_shape
        axes = [np.linspace(lo[a], hi[a], shape[a]) for a in range(3)]
        x = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        u, converged, _folded = self.grid.inverse(x, return_info=True)
        u = np.asarray(u, dtype=np.float64)
        ok = np.asarray(converged, bool) & np.all(np.isfinite(u), axis=1)
        ok &= np.all((u >= -1e-9) & (u <= 1.0 + 1e-9), axis=1)
        out = u.copy()
        rest = ~ok
        if np.any(rest):
            start = np.where(np.isfinite(u[rest]), u[rest], 0.5)
            out[rest] = self._extended_inverse(x[rest], start)
        field = np.zeros((*shape, 4))
        field[..., :3] = out.reshape(*shape, 3)
        field[..., 3] = self._near_flags(lo, hi, shape)
        self._bake = (field, lo, hi)
        return self._bake

    def _extended_inverse(self, x: np.ndarray, start: np.ndarray) -> np.ndarray:
        """u with ``G(u) = x``, G the lattice continued linearly beyond its surface:
        ``G(u) = grid(c) + J(c) (u - c)``, ``c = clip(u, 0, 1)`` (Newton, at most
        :data:`EXTEND_ITERATIONS` steps; points that do not converge keep an affine
        fit's inverse, clipped to a margin around the cube)."""
        fit = self._affine_fit()
        u0 = np.clip(x @ fit[:3, :3].T + fit[:3, 3], -2.0, 3.0)
        u = np.where(np.all(np.abs(start - 0.5) < 2.0, axis=1)[:, None], start, u0)
        tol = 1e-7 * float(np.max(self.size))
        active = np.arange(len(u))
        for _ in range(EXTEND_ITERATIONS):
            ua, xa = u[active], x[active]
            c = np.clip(ua, 0.0, 1.0)
            f, j = lattice_eval(self._nodes, c)
            assert j is not None
            r = f + np.einsum("nij,nj->ni", j, ua - c) - xa
            done = np.linalg.norm(r, axis=1) <= tol
            u[active[done]] = ua[done]
            keep = ~done
            active, ua, r, j = active[keep], ua[keep], r[keep], j[keep]
            if len(active) == 0:
                break
            u[active] = np.clip(_newton_update(ua, r, j), -2.0, 3.0)
        u[active] = u0[active]  # not converged
        return u

    def _affine_fit(self) -> np.ndarray:
        """4x4 world -> unit cube: the inverse of the least-squares affine fit of the nodes."""
        n = self._nodes
        idx = np.stack(
            np.meshgrid(*(np.linspace(0, 1, k) for k in n.shape[:3]), indexing="ij"), -1
        ).reshape(-1, 3)
        a = np.c_[idx, np.ones(len(idx))]
        coef, *_ = np.linalg.lstsq(a, n.reshape(-1, 3), rcond=None)
        m = np.eye(4)
        m[:3, :3] = coef[:3].T
        m[:3, 3] = coef[3]
        try:
            return np.linalg.inv(m)
        except np.linalg.LinAlgError:
            return np.linalg.pinv(m)

    def _cell_corner_boxes(self) -> tuple[np.ndarray, np.ndarray]:
        """Per lattice cell, the bounding box of its 8 corners (cells..., 3) each."""
        if self._cell_boxes is None:
            n = self._nodes
            lo, hi = n, n
            for axis in range(3):
                a_lo, a_hi = np.moveaxis(lo, axis, 0), np.moveaxis(hi, axis, 0)
                lo = np.moveaxis(np.minimum(a_lo[:-1], a_lo[1:]), 0, axis)
                hi = np.moveaxis(np.maximum(a_hi[:-1], a_hi[1:]), 0, axis)
            self._cell_boxes = (lo, hi)
        return self._cell_boxes

    def _near_flags(self, lo: np.ndarray, hi: np.ndarray, shape: Sequence[int]) -> np.ndarray:
        """1 at baked nodes touching a baked cell that overlaps some lattice cell's corner
        bounding box, else 0 (a conservative "the lattice may be here")."""
        shape = np.asarray(shape)
        h = (hi - lo) / (shape - 1)
        clo, chi = self._cell_corner_boxes()
        clo, chi = clo.reshape(-1, 3), chi.reshape(-1, 3)
        slack = 1e-6 * float(np.max(hi - lo))
        ncell = shape - 1
        a = np.clip(np.floor((clo - slack - lo) / h), 0, ncell - 1).astype(np.intp)
        b = np.clip(np.floor((chi + slack - lo) / h), 0, ncell - 1).astype(np.intp)
        # mark baked cells a..b of every lattice cell: inclusion-exclusion, then prefix sums
        diff = np.zeros(tuple(ncell + 1), dtype=np.int64)
        for corner in range(8):
            o = [(corner >> k) & 1 for k in range(3)]
            idx = np.where(np.array(o, bool), b + 1, a)
            sign = -1 if sum(o) % 2 else 1
            np.add.at(diff, (idx[:, 0], idx[:, 1], idx[:, 2]), sign)
        marked = diff.cumsum(0).cumsum(1).cumsum(2)[: ncell[0], : ncell[1], : ncell[2]] > 0
        near = np.zeros(tuple(shape), dtype=bool)
        for corner in range(8):
            o = [(corner >> k) & 1 for k in range(3)]
            near[o[0] : o[0] + ncell[0], o[1] : o[1] + ncell[1], o[2] : o[2] + ncell[2]] |= marked
        return near.astype(np.float64)

    # ---------------------------------------------------------------- bounds
    def deformed_bounds(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Box in deformed space holding everything mapped into ``[lo, hi]``.

        Linear lattice: the forward image of ``[lo, hi]``'s corners. Otherwise the
        lattice nodes' bounding box (the deformed lattice lies in it), joined with
        ``[lo, hi]`` where the outside is the identity (:attr:`boundary_on_box`).
        """
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        if self._affine:
            m = self.forward_matrix()
            c = box_corners(lo, hi) @ m[:3, :3].T + m[:3, 3]
            return c.min(axis=0), c.max(axis=0)
        pts = self._nodes.reshape(-1, 3)
        nlo, nhi = pts.min(axis=0), pts.max(axis=0)
        if self.boundary_on_box:
            return np.minimum(lo, nlo), np.maximum(hi, nhi)
        return nlo, nhi

    @property
    def bounds_displacement(self) -> bool:
        """True: :meth:`displacement_range` bounds the displacement from the lattice."""
        return True

    def displacement_range(
        self, lo: np.ndarray, hi: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Per box, an interval holding ``apply(p) - p`` for the p of the box that show
        something.

        Within a baked cell both the seed's ``q = lo + u (hi - lo)`` and p itself are
        the trilinear interpolation of their values at the cell's 8 corners, so the
        seed's displacement ``q - p`` is too: it lies in the range of the baked nodes'
        displacements ``q_node - x_node``. The Newton steps move q by at most
        :meth:`cell_margins` in that cell. So a sample of the box lies in the range over
        the baked cells the box touches (those with a node near the lattice), each
        widened by its margin. The interval holds 0 where the outside is the identity;
        baked cells far from the lattice show nothing. Linear lattice: exact, from the corners (as
        :class:`~voxwarp.deform.warp.AffineWarp`).
        """
        blo = np.atleast_2d(np.asarray(lo, dtype=np.float64))
        bhi = np.atleast_2d(np.asarray(hi, dtype=np.float64))
        if self._affine:
            m = self.affine_matrix()
            d = m[:3, :3] - np.eye(3)
            a = np.full(blo.shape, np.inf)
            b = np.full(blo.shape, -np.inf)
            for corner in range(8):
                pick = np.array([(corner >> k) & 1 for k in range(3)], dtype=bool)
                v = np.where(pick, bhi, blo) @ d.T + m[:3, 3]
                np.minimum(a, v, out=a)
                np.maximum(b, v, out=b)
            return a, b
        cell_lo, cell_hi = self._seed_cell_ranges()
        field, slo, shi = self.baked_inverse()
        n = np.asarray(field.shape[:3])
        h = (shi - slo) / (n - 1)
        a = np.full(blo.shape, np.inf)
        b = np.full(blo.shape, -np.inf)
        touches = np.all((bhi >= slo) & (blo <= shi), axis=1)
        if np.any(touches):
            sel = np.flatnonzero(touches)
            i0 = np.clip(np.floor((blo[sel] - slo) / h), 0, n - 2).astype(np.int64)
            i1 = np.clip(np.floor((bhi[sel] - slo) / h), 0, n - 2).astype(np.int64)
            # windows rounded up to powers of two (wider only loosens the range)
            width = 1 << np.ceil(np.log2(i1 - i0 + 1)).astype(np.int64)
            sizes, which = np.unique(width, axis=0, return_inverse=True)
            cache_lo: dict[tuple, np.ndarray] = {}
            cache_hi: dict[tuple, np.ndarray] = {}
            for k, size in enumerate(sizes):
                rows = np.flatnonzero(which.ravel() == k)
                i = i0[rows]
                w = tuple(int(v) for v in size)
                ql = window_reduce(cell_lo, w, np.minimum, cache_lo)[i[:, 0], i[:, 1], i[:, 2]]
                qh = window_reduce(cell_hi, w, np.maximum, cache_hi)[i[:, 0], i[:, 1], i[:, 2]]
                a[sel[rows]] = ql
                b[sel[rows]] = qh
        if self.boundary_on_box:
            a, b = np.minimum(a, 0.0), np.maximum(b, 0.0)
        none = ~(a <= b)  # far from the lattice: nothing shows; any interval is sound
        a[none] = 0.0
        b[none] = 0.0
        return a, b

    def _seed_cell_ranges(self) -> tuple[np.ndarray, np.ndarray]:
        """Per baked cell, the range (mm) of the displacement ``lo + u (hi - lo) - x``
        over its 8 corners x; ``+inf``/``-inf`` for cells without a node near the
        lattice."""
        if self._cell_ranges is None:
            field, slo, shi = self.baked_inverse()
            axes = [np.linspace(slo[a], shi[a], field.shape[a]) for a in range(3)]
            x = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
            q = self.lo + field[..., :3] * self.size - x
            near = field[..., 3] > 0
            # a cell counts when any corner is near (the seed's alpha is then > 0)
            masked = np.where(near[..., None], q, np.inf)
            valid = np.isfinite(cell_reduce(masked, np.minimum)).all(axis=-1)
            m = self.cell_margins()[..., None]
            c_lo = cell_reduce(q, np.minimum) - m
            c_hi = cell_reduce(q, np.maximum) + m
            self._cell_ranges = (
                np.where(valid[..., None], c_lo, np.inf),
                np.where(valid[..., None], c_hi, -np.inf),
            )
        return self._cell_ranges

    def cell_margins(self) -> np.ndarray:
        """Per baked cell, how far (mm) the Newton steps may move a sample's q from its
        seed (``bake_shape - 1`` per axis).

        Measured once on the baked grid refined twice (27 points per cell, where
        :attr:`bake_shape` is at most :data:`MAX_CELL_MARGIN_NODES`): twice the largest
        move ``|lo + u (hi - lo) - seed|`` among the points of the cell and of its 26
        neighbours that come out inside, plus 0.01 mm (float32). The moves are large
        only in cells that the lattice's cell faces (its kinks) cross, so most cells get
        a small margin. Larger bakes use :meth:`inverse_margin` everywhere; without
        Newton steps q is the seed (0.01 mm).
        """
        if self._cell_margins is not None:
            return self._cell_margins
        field, slo, shi = self.baked_inverse()
        n = np.asarray(field.shape[:3])
        if self.steps == 0 or self._affine:
            self._cell_margins = np.full(tuple(n - 1), 0.01)
        elif n.max() > MAX_CELL_MARGIN_NODES:
            self._cell_margins = np.full(tuple(n - 1), self.inverse_margin())
        else:
            m = 2 * n - 1
            axes = [np.linspace(slo[a], shi[a], m[a]) for a in range(3)]
            p = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
            seed = _trilinear_sample(field, (p - slo) / (shi - slo))[:, :3]
            u, inside = self.lattice_coordinates(p)
            err = np.where(inside, np.abs((u - seed) * self.size).max(axis=1), 0.0)
            err = err.reshape(tuple(m))
            cell = np.zeros(tuple(n - 1))
            for o in np.ndindex(3, 3, 3):
                np.maximum(
                    cell,
                    err[o[0] : o[0] + m[0] - 2 : 2, o[1] : o[1] + m[1] - 2 : 2,
                        o[2] : o[2] + m[2] - 2 : 2],
                    out=cell,
                )  # fmt: skip
            cell = ndimage.maximum_filter(cell, size=3, mode="nearest")
            self._cell_margins = 2.0 * cell + 0.01
        return self._cell_margins

    def inverse_margin(self) -> float:
        """How far (mm) a rendered sample's q may lie from its seed: twice the largest
        ``|lo + u (hi - lo) - seed|`` of :meth:`lattice_coordinates` over a sample of
        points (lattice points, points on the lattice's cell faces and points around
        it) that come out inside, plus 0.01 mm (float32) — measured once."""
        if self._margin is not None:
            return self._margin
        if self._affine:
            self._margin = 0.0
            return 0.0
        rng = np.random.default_rng(0)
        u_true = rng.uniform(0.0, 1.0, (6000, 3))
        # a third on the cells' faces, where the lattice map has kinks
        cells = np.asarray(self.cells)
        face = rng.integers(0, 3, 2000)
        rows = np.arange(2000)
        u_true[rows, face] = rng.integers(0, cells[face] + 1) / cells[face]
        p = lattice_eval(self._nodes, u_true, jacobian=False)[0]
        slo, shi = self.seed_box()
        p = np.vstack([p, rng.uniform(slo, shi, (4000, 3))])
        field, _, _ = self.baked_inverse()
        s = (p - slo) / (shi - slo)
        seed = _trilinear_sample(field, s)[:, :3]
        u, inside = self.lattice_coordinates(p)
        err = np.abs((u - seed) * self.size).max(axis=1)
        self._margin = 2.0 * float(np.max(err[inside], initial=0.0)) + 0.01
        return self._margin

    # ---------------------------------------------------------------- GPU side
    def glsl_constants(self) -> dict[str, Any]:
        """``LINEAR``, ``OUTSIDE_IDENTITY`` and ``ADAPTIVE`` (``#define`` 0/1),
        ``ITERATIONS`` (the most steps: the loop's cap when adaptive), the far point and
        ``ITERATE``, the fixed Newton steps written out (empty when adaptive)."""
        fixed = 0 if self.adaptive else int(self.steps)
        return {
            "LINEAR": "1" if self._affine else "0",
            "OUTSIDE_IDENTITY": "1" if self.boundary_on_box else "0",
            "ADAPTIVE": "1" if self.adaptive else "0",
            "ITERATIONS": int(self.steps),
            "FAR": FAR,
            "ITERATE": " ".join(["WARP_NEWTON(u, p)"] * fixed),
        }

    def signature(self) -> str:
        """``lattice:linear``, or ``lattice:lattice:<identity|far>:<steps>`` with
        ``steps`` ``k`` (fixed) or ``<=k`` (iterating, at most k) (the compile-time
        constants; the tolerance is a uniform)."""
        if self._affine:
            return f"{self.kind}:linear"
        outside = "identity" if self.boundary_on_box else "far"
        steps = f"<={self.steps}" if self.adaptive else str(self.steps)
        return f"{self.kind}:lattice:{outside}:{steps}"

    def uniforms(self) -> dict[str, Any]:
        """Linear lattice: ``matrix`` (deformed -> original). Otherwise the box (``lo``,
        ``size``), ``cells``, the baked seed's box and node counts and the ``tolerance``
        (mm; 0 with fixed steps)."""
        if self._affine:
            return {"matrix": self.affine_matrix()}
        _, slo, shi = self.baked_inverse()
        return {
            "lo": self.lo.copy(),
            "size": self.size.copy(),
            "cells": np.asarray(self.cells, dtype=np.float64),
            "seed_lo": slo.copy(),
            "seed_size": shi - slo,
            "seed_shape": np.asarray(self.bake_shape, dtype=np.float64),
            "tolerance": float(self.tolerance or 0.0),
        }

    def textures(self, ctx: Any) -> dict[str, Any]:
        """``nodes`` (RGBA32F 3D, the lattice nodes, read with texelFetch) and ``seed``
        (RGBA32F 3D, the baked inverse, linear filtering, clamp to edge); none for a
        linear lattice (folded). Made on first use per context."""
        if self._affine:
            return {}
        entry = self._gpu.get(id(ctx))
        if entry is not None and entry[0] is ctx:
            return entry[1]
        nodes = np.ascontiguousarray(self.grid.texture_data(), dtype=np.float32)
        n = self._nodes.shape[:3]
        node_tex = ctx.texture3d(n, 4, nodes.tobytes(), dtype="f4")
        node_tex.filter = (ctx.NEAREST, ctx.NEAREST)
        node_tex.repeat_x = node_tex.repeat_y = node_tex.repeat_z = False
        field, _, _ = self.baked_inverse()
        data = np.ascontiguousarray(field.transpose(2, 1, 0, 3), dtype=np.float32)
        seed_tex = ctx.texture3d(self.bake_shape, 4, data.tobytes(), dtype="f4")
        seed_tex.filter = (ctx.LINEAR, ctx.LINEAR)
        seed_tex.repeat_x = seed_tex.repeat_y = seed_tex.repeat_z = False
        texs = {"nodes": node_tex, "seed": seed_tex}
        self._gpu[id(ctx)] = (ctx, texs)
        gl_holders.hold(ctx, self)
        return texs

    def release(self) -> None:
        """Free the GPU textures; idempotent (call with their context current)."""
        for _, texs in self._gpu.values():
            for tex in texs.values():
                tex.release()
        self._gpu.clear()

    def release_context(self, ctx: Any) -> None:
        """Free the textures on ``ctx`` alone (``ctx`` current); idempotent."""
        entry = self._gpu.pop(id(ctx), None)
        if entry is not None and entry[0] is ctx:
            for tex in entry[1].values():
                tex.release()

    # ---------------------------------------------------------------- serialisation
    def to_dict(self) -> dict[str, Any]:
        """``{"type": "lattice", "grid": ..., "box": [lo, hi], "inverse"}`` with
        ``"tolerance"`` and ``"max_iterations"`` when iterating, else ``"iterations"``
        (and ``"fold_linear": false`` when set)."""
        d: dict[str, Any] = {
            "type": self.kind,
            "grid": self.grid.to_dict(),
            "box": [self.lo.tolist(), self.hi.tolist()],
            "inverse": self.inverse,
        }
        if self.adaptive:
            d["tolerance"] = self.tolerance
            d["max_iterations"] = self.max_iterations
        else:
            d["iterations"] = self.iterations
        if not self.fold_linear:
            d["fold_linear"] = False
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> LatticeWarp:
        """Build from :meth:`to_dict`'s form (``inverse``, ``iterations``, ``tolerance``,
        ``max_iterations`` optional)."""
        missing = [k for k in LATTICE_REQUIRED if k not in d]
        if missing:
            raise WarpError(
                f"a lattice warp entry needs {missing}: 'grid' (a TrilinearGrid dict with"
                " 'nodes') and 'box' ([lo, hi] in mm)"
            )
        unknown = set(d) - set(LATTICE_KEYS)
        if unknown:
            raise WarpError(
                f"unknown keys {sorted(unknown)} in a lattice warp entry; allowed:"
                f" {', '.join(LATTICE_KEYS)}"
            )
        if not isinstance(d["grid"], Mapping):
            raise WarpError(
                f"a lattice warp's 'grid' must be an object with 'nodes'; got {d['grid']!r:.80}"
            )
        try:
            grid = TrilinearGrid.from_dict(d["grid"])
        except WarpError:
            raise
        except (TypeError, ValueError, KeyError) as exc:
            raise WarpError(f"a lattice warp's 'grid' is invalid: {exc}") from exc
        warp = cls(
            grid,
            d["box"],
            inverse=d.get("inverse", "newton"),
            iterations=d.get("iterations"),
            tolerance=d.get("tolerance"),
            max_iterations=d.get("max_iterations"),
            fold_linear=bool(d.get("fold_linear", True)),
        )
        warn_if_folded(grid)
        return warp

    def __repr__(self) -> str:
        return (
            f"LatticeWarp(cells={self.cells}, box=({self.lo.tolist()}, {self.hi.tolist()}),"
            f" inverse={self.inverse!r}, iterations={self.iterations},"
            f" tolerance={self.tolerance}, max_iterations={self.max_iterations},"
            f" linear={self._linear})"
        )


# ---------------------------------------------------------------------- folded lattices
class FoldedLatticeWarning(UserWarning):
    """A lattice read from a file has cells that fold (turn inside out)."""


def warn_if_folded(grid: TrilinearGrid, what: str = "the lattice") -> None:
    """One warning naming the first folded cell of ``grid`` (``det J`` vanishing or of the
    wrong sign on a 3x3x3 sample of a cell, :meth:`TrilinearGrid.folded_cells`): such a
    lattice still renders, but where it folds two places of the volume land on one point
    and the inverse picks one of them."""
    cells = grid.folded_cells()
    if len(cells) == 0:
        return
    i, j, k = (int(v) for v in cells[0])
    more = f" and {len(cells) - 1} more of its {grid.n_cells} cells" if len(cells) > 1 else ""
    warnings.warn(
        f"{what} folds: its cell ({i}, {j}, {k}){more} turns inside out (Jacobian"
        " determinant <= 0), so the volume renders with overlapping parts there; move the"
        " cell's nodes back so that it keeps its orientation",
        FoldedLatticeWarning,
        stacklevel=3,
    )


def _shortest_edge(points: np.ndarray) -> float:
    """The shortest distance (mm) between neighbouring nodes of a (nx, ny, nz, 3) grid."""
    edges = [np.linalg.norm(np.diff(points, axis=a), axis=-1).min() for a in range(3)]
    return float(min(edges))
