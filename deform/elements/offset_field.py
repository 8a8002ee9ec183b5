"""The offset-field warp: a grid of displaced nodes, inverted per sample.

About this technique (Knoche 2008, 3.5; the mass-spring model's output)
-----------------------------------------------------------------------
A grid of ``n_x x n_y x n_z`` *elements* (nodes) spans the box ``[lo, hi]``; node
``(i, j, k)`` rests at ``X = lo + (i, j, k) * spacing`` with
``spacing = (hi - lo) / (shape - 1)`` and is displaced by ``u_ijk`` (mm). Between nodes
``u(X)`` is trilinear; outside the grid box ``u = 0``. The material point ``X`` appears
at ``X + u(X)`` (the *forward* map). The raycaster needs the inverse: for a sample
``p`` in deformed space, the original point ``q`` with ``q + u(q) = p``. It is found by
the fixed point ``q_{n+1} = p - u(q_n)`` from ``q_0 = p``; one step is the thesis'
approximation ``q = p - u(p)``. The iteration converges where the field is a
contraction (``|grad u| < 1``: no folding), with error shrinking roughly like
``|grad u|^n``.

On the GPU the field is an RGBA16F 2D array texture whose layers are the z-slices of
the node grid (xyz = u in mm, a = material), sampled at node-centred texture
coordinates by two hardware-bilinear fetches (layers k and k + 1) and a lerp: the
trilinear value. The field can be owned by this warp (uploaded from numpy) or by a GPU
simulation (``texture_source``), whose passes write its layers. The baked inverse
(``inverse="baked"``) is written by this warp's own compute pass into an RGBA16F 3D
texture and sampled by one hardware-trilinear fetch.

Measurements (inverse error per mode and iteration count, GPU costs): docs/benchmarks.md,
section 'voxwarp.deform.elements.offset_field: inverse accuracy and cost'.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from voxwarp import shaders
from voxwarp.deform import gl_holders, gl_programs
from voxwarp.deform.elements.field_support import field_support
from voxwarp.deform.elements.folds import fold_summary
from voxwarp.deform.node_grid import cell_reduce, check_vectors, window_reduce
from voxwarp.deform.warp import (
    ForwardMapError,
    Warp,
    WarpError,
    register_warp,
    solve_forward,
)

#: Inverse modes: one step (thesis), the fixed-point iteration from ``q_0 = p``, or the
#: fixed-point iteration seeded by a baked inverse field.
INVERSE_MODES: tuple[str, ...] = ("approx", "exact", "baked")
#: Allowed range of fixed-point iterations.
MAX_ITERATIONS = 64
#: Default number of fixed-point iterations of ``inverse="exact"``: the fewest whose
#: worst residual in the lab's ``inverse_error_table`` stays below 1 % of the node spacing
#: (docs/benchmarks.md, section 'voxwarp.deform.elements.offset_field: inverse accuracy and cost').
DEFAULT_ITERATIONS = 6
#: Default fixed-point corrections of ``inverse="baked"`` after the baked seed, when the
#: inverse is baked at least 3x finer than the field (grids up to 43 nodes per axis):
#: more accurate than ``"exact"`` with :data:`DEFAULT_ITERATIONS` on the error study, with
#: 2 texture fetches instead of 6; coarser bakes get one more correction
#: (:attr:`OffsetFieldWarp.iterations`).
DEFAULT_BAKED_ITERATIONS = 1
#: Fixed-point steps that bake the inverse at the nodes (converged to float precision
#: for fields without folds).
BAKE_ITERATIONS = 32
#: The baked inverse is sampled this many times finer than the field per axis (at most;
#: see :attr:`OffsetFieldWarp.bake_factor`), its nodes capped at :data:`MAX_BAKE_NODES`.
MAX_BAKE_FACTOR = 4
#: Most baked-inverse nodes per axis (a 128³ RGBA16F texture is 16 MB).
MAX_BAKE_NODES = 128

#: ``callable() -> (model dict, displacements or None)``: see :class:`OffsetFieldWarp`.
ModelSource = Callable[[], tuple[Mapping[str, Any], Any]]


def _fixed_point(x: np.ndarray, offset: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """``BAKE_ITERATIONS`` steps ``q <- x - offset(q)`` from ``q = x`` per row, each row
    stopped once a step leaves it unchanged (every later step would give it again:
    bit-identical to all steps, as the GPU bake; rows the field does not move stop
    after two)."""
    q = x.copy()
    active = np.arange(len(x))
    for _ in range(BAKE_ITERATIONS):
        nxt = x[active] - offset(q[active])
        moving = np.any(nxt != q[active], axis=1)
        q[active] = nxt
        active = active[moving]
        if not active.size:
            break
    return q


def _vec3(x: Any, what: str) -> np.ndarray:
    try:
        a = np.asarray(x, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise WarpError(f"{what} must be three numbers (x, y, z) in mm; got {x!r:.80}") from exc
    if a.shape != (3,):
        raise WarpError(f"{what} must be three numbers (x, y, z) in mm; got {a.size} values")
    if not np.all(np.isfinite(a)):
        raise WarpError(f"{what} has NaN/Inf entries: {a.tolist()}")
    return a


def _shape3(x: Any) -> tuple[int, int, int]:
    try:
        vals = list(x)
    except TypeError as exc:
        raise WarpError(f"shape must be three node counts (nx, ny, nz); got {x!r:.80}") from exc
    if len(vals) != 3 or not all(
        isinstance(v, int | np.integer) and not isinstance(v, bool) for v in vals
    ):
        raise WarpError(f"shape must be three integer node counts (nx, ny, nz); got {x!r:.80}")
    if min(vals) < 2:
        raise WarpError(
            f"shape must have at least 2 nodes per axis (a node at lo and one at hi); got {vals}"
        )
    return int(vals[0]), int(vals[1]), int(vals[2])


def _field(displacements: Any, shape: tuple[int, int, int] | None) -> np.ndarray:
    try:
        u = np.array(displacements, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise WarpError(
            "displacements must be a numeric (nx, ny, nz, 3) array (mm per node)"
        ) from exc
    if u.ndim != 4 or u.shape[3] != 3:
        raise WarpError(
            f"displacements must have shape (nx, ny, nz, 3) (one xyz offset per node);"
            f" got {u.shape}"
        )
    grid = _shape3(tuple(int(s) for s in u.shape[:3]))
    if shape is not None and grid != shape:
        raise WarpError(f"displacements have {grid} nodes but shape={shape} was given")
    check_vectors(u, "check the units (mm expected)")
    return u


def _model_dict(model: Any) -> dict[str, Any] | None:
    """A model entry (``{"type": ..., ...}``) as a plain dict; ``None`` stays ``None``."""
    if model is None:
        return None
    if not isinstance(model, Mapping) or not isinstance(model.get("type"), str):
        raise WarpError(
            "an offset_field warp's 'model' must be an object with a 'type' string,"
            f' e.g. {{"type": "massspring", ...}}; got {model!r:.80}'
        )
    return dict(model)


def _material(material: Any, grid: tuple[int, int, int]) -> np.ndarray | None:
    if material is None:
        return None
    try:
        m = np.array(material, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise WarpError("material must be a numeric (nx, ny, nz) array") from exc
    if m.shape != grid:
        raise WarpError(f"material must have one value per node, shape {grid}; got {m.shape}")
    if not np.all(np.isfinite(m)):
        raise WarpError("material has NaN/Inf entries")
    return m


@register_warp
class OffsetFieldWarp(Warp):
    """Warp by a displacement (offset) field on a regular grid of nodes.

    Give it the grid box and a ``(nx, ny, nz, 3)`` field of node displacements in mm,
    or a GPU texture owned by a simulation (``texture_source``); add it to a scene's
    ``warps``. The deformation models build one for you
    (:meth:`voxwarp.deform.elements.massspring.MassSpring.warp`). Change a CPU field with
    :meth:`update` or :meth:`update_region`; the texture follows on the next draw.

    How it works: for a sample ``p`` in deformed space the warp finds the original
    point ``q`` with ``q + u(q) = p`` (``u`` trilinear between nodes). ``"approx"``
    takes one step ``q = p - u(p)`` (the thesis); ``"exact"`` repeats
    ``q <- p - u(q)`` from ``q = p``, each step one field lookup per sample;
    ``"baked"`` starts the same steps from ``p - v(p)``, where ``v`` is the inverse
    solved once per field change on a grid :attr:`bake_factor` times finer
    (:meth:`baked_inverse`), so one or two corrections are enough. Outside the grid
    box ``u = 0`` and the warp is the identity: content cannot leave the box (what is
    dragged across a face is cut off there), so give the grid a margin around the
    part of the volume that is to move.

    Measurements: docs/benchmarks.md, section 'voxwarp.deform.elements.offset_field: inverse
    accuracy and cost'.

    Parameters
    ----------
    lo, hi
        Corners of the grid box in world mm (node ``(0, 0, 0)`` at ``lo``, the last node
        at ``hi``); ``lo < hi`` per axis.
    displacements
        ``(nx, ny, nz, 3)`` node displacements in mm (the CPU-held field), or ``None``
        when ``texture_source`` provides the field.
    shape
        Node counts ``(nx, ny, nz)``, each >= 2; required with ``texture_source``, and
        must match ``displacements`` when both are given.
    texture_source
        ``callable(ctx) -> moderngl.TextureArray`` returning an RGBA16F 2D array
        texture (z-slices as layers) of ``shape`` texels (xyz = displacement in mm,
        a = material) owned by someone else, e.g. a GPU mass-spring simulation; this
        warp never releases it. Such a warp has no CPU field: :meth:`apply`,
        :meth:`forward` and :meth:`jacobian` read it back through ``field_reader``
        (once per revision; an error without one), and :meth:`to_dict` round trips
        need ``displacements``.
    inverse
        ``"approx"``, ``"exact"`` (default) or ``"baked"``, as described above.
        ``"approx"`` is ``"exact"`` with one iteration. ``"baked"`` is the default of
        :meth:`voxwarp.deform.elements.massspring.MassSpring.warp` and of ``voxwarp render
        --massspring``.
    iterations
        Fixed-point steps of ``"exact"`` (1..64), or corrections after the seed of
        ``"baked"`` (0..64; 0: the seed alone, one trilinear lookup per sample instead
        of two, ~4x the default's worst inverse error: for interaction); ``None``
        chooses :data:`DEFAULT_ITERATIONS` or :data:`DEFAULT_BAKED_ITERATIONS`. Ignored
        (1) for ``"approx"``.
    material
        Optional ``(nx, ny, nz)`` per-node material value, uploaded to the texture's
        alpha channel (0 without it).
    model_source
        Optional ``callable() -> (model, displacements)``, set by the model that drives
        this warp (e.g. :meth:`voxwarp.deform.elements.massspring.MassSpring.warp`) so that
        :meth:`to_dict` saves the model with the field: ``model`` is a JSON-serialisable
        dict with a ``"type"`` key; ``displacements`` is the current field read back
        from the GPU, or ``None`` when this warp holds a CPU field. Called once per
        :meth:`to_dict`, never while rendering.
    model_state
        The model dict a loaded scene entry carried (see :attr:`model_state`).
    field_reader, revision_source
        For a ``texture_source`` field: ``field_reader()`` reads the ``(nx, ny, nz, 3)``
        field back from the GPU; ``revision_source()`` returns a counter that changes
        whenever the field does (no read-back). With both, the warp can bound its
        displacement (:meth:`displacement_range`) so the renderer can skip empty space;
        the renderer asks only when the same field state is drawn again
        (``warped_skip_maps`` of voxwarp.render.raycaster), never while the field
        changes every frame.

    Attributes
    ----------
    model_state : dict or None
        The ``"model"`` entry of the scene JSON this warp was loaded from (e.g.
        ``{"type": "massspring", ...}``), or ``None``. It lets an application resume
        the simulation that produced the saved field
        (:meth:`voxwarp.deform.elements.massspring.MassSpring.from_warp`). The warp never reads
        it; :meth:`to_dict` writes it back unchanged (also after :meth:`update`).
    model_source : callable or None
        See the parameter of the same name.
    """

    kind = "offset_field"
    glsl_file = "warp_offset_field.glsl"

    def __init__(
        self,
        lo: Sequence[float],
        hi: Sequence[float],
        displacements: np.ndarray | None = None,
        *,
        shape: Sequence[int] | None = None,
        texture_source: Callable[[Any], Any] | None = None,
        inverse: str = "exact",
        iterations: int | None = None,
        material: np.ndarray | None = None,
        model_source: ModelSource | None = None,
        model_state: Mapping[str, Any] | None = None,
        field_reader: Callable[[], np.ndarray] | None = None,
        revision_source: Callable[[], int] | None = None,
    ) -> None:
        if model_source is not None and not callable(model_source):
            raise WarpError("model_source must be a callable () -> (model dict, displacements)")
        self.model_source = model_source
        if field_reader is not None and not callable(field_reader):
            raise WarpError("field_reader must be a callable () -> (nx, ny, nz, 3) array")
        if revision_source is not None and not callable(revision_source):
            raise WarpError("revision_source must be a callable () -> int")
        if (field_reader is None) != (revision_source is None):
            raise WarpError("give field_reader and revision_source together")
        self._field_reader = field_reader
        self._revision_source = revision_source
        self._read_cache: tuple[int, np.ndarray] | None = None
        self.model_state: dict[str, Any] | None = _model_dict(model_state)
        self.lo = _vec3(lo, "OffsetFieldWarp lo")
        self.hi = _vec3(hi, "OffsetFieldWarp hi")
        if np.any(self.lo >= self.hi):
            raise WarpError(
                f"OffsetFieldWarp needs lo < hi on every axis; got lo={self.lo.tolist()},"
                f" hi={self.hi.tolist()}"
            )
        if inverse not in INVERSE_MODES:
            raise WarpError(f"inverse must be one of {list(INVERSE_MODES)}; got {inverse!r}")
        self.inverse = inverse
        self._iterations: int | None = None
        self.iterations = iterations  # type: ignore[assignment]
        grid = None if shape is None else _shape3(shape)
        if displacements is None and texture_source is None:
            raise WarpError(
                "OffsetFieldWarp needs displacements (nx, ny, nz, 3) or a texture_source"
            )
        if displacements is not None and texture_source is not None:
            raise WarpError("give either displacements or texture_source, not both")
        self._source = texture_source
        self._u: np.ndarray | None = None
        self._material: np.ndarray | None = None
        # id(ctx) -> (ctx, texture, field version it holds); one texture per context
        self._textures: dict[int, tuple[Any, Any, int]] = {}
        # id(ctx) -> (ctx, bake program, inverse texture, field version it holds)
        self._baked: dict[int, tuple[Any, Any, Any, int]] = {}
        self._baked_cpu: tuple[int, np.ndarray] | None = None
        self._version = 0
        #: last version set by a whole-field change; later ones by update_region
        self._full_version = 0
        #: (version, lo, hi) node blocks of update_region calls
        self._regions: list[tuple[int, np.ndarray, np.ndarray]] = []
        if texture_source is not None:
            if not callable(texture_source):
                raise WarpError("texture_source must be a callable ctx -> moderngl texture")
            if grid is None:
                raise WarpError("a texture_source warp needs shape=(nx, ny, nz) (its node counts)")
            self.shape = grid
            if material is not None:
                raise WarpError("material belongs in the texture_source's alpha channel")
        else:
            self._u = _field(displacements, grid)
            self.shape = _shape3(self._u.shape[:3])
            self._material = _material(material, self.shape)

    # ---------------------------------------------------------------- properties
    @property
    def spacing(self) -> np.ndarray:
        """Node spacing per axis in mm: ``(hi - lo) / (shape - 1)``."""
        return (self.hi - self.lo) / (np.asarray(self.shape, float) - 1.0)

    @property
    def iterations(self) -> int:
        """Fixed-point steps of ``"exact"``, or corrections after the seed of ``"baked"``.

        Unless set explicitly, the mode's default (:data:`DEFAULT_ITERATIONS`,
        :data:`DEFAULT_BAKED_ITERATIONS`); kept when :attr:`inverse` changes.
        """
        if self._iterations is not None:
            return self._iterations
        if self.inverse == "baked":
            return DEFAULT_BAKED_ITERATIONS + (1 if self.bake_factor < 3 else 0)
        return DEFAULT_ITERATIONS

    @iterations.setter
    def iterations(self, value: int | None) -> None:
        if value is None:
            self._iterations = None
            return
        if isinstance(value, bool) or not isinstance(value, int | np.integer):
            raise WarpError(f"iterations must be an integer 0..{MAX_ITERATIONS}; got {value!r}")
        if not 0 <= int(value) <= MAX_ITERATIONS:
            raise WarpError(f"iterations must be 0..{MAX_ITERATIONS}; got {value}")
        self._iterations = int(value)

    @property
    def steps(self) -> int:
        """Fixed-point steps actually taken: 1 for ``"approx"``, else :attr:`iterations`
        (at least 1 for ``"exact"``; 0 for ``"baked"`` is the baked seed alone)."""
        if self.inverse == "approx":
            return 1
        return self.iterations if self.inverse == "baked" else max(self.iterations, 1)

    @property
    def gpu_owned(self) -> bool:
        """True when the field lives in a texture owned by ``texture_source``."""
        return self._source is not None

    @property
    def displacements(self) -> np.ndarray:
        """A copy of the ``(nx, ny, nz, 3)`` CPU field (mm)."""
        return self._cpu_field("displacements").copy()

    def _cpu_field(self, what: str) -> np.ndarray:
        if self._u is None:
            raise WarpError(
                f"{what}: this OffsetFieldWarp's field is owned by a GPU texture"
                " (texture_source); there is no CPU copy. Read the field back from its"
                " simulation and build a warp from those displacements."
            )
        return self._u

    def update(self, displacements: np.ndarray, material: np.ndarray | None = None) -> None:
        """Replace the CPU-held field (and optionally the material).

        The texture is re-uploaded on the next :meth:`textures` call, into the same
        texture object when the node counts are unchanged. The grid box stays.

        Parameters
        ----------
        displacements
            New ``(nx, ny, nz, 3)`` displacements in mm.
        material
            New ``(nx, ny, nz)`` material, or ``None`` to keep the current one (dropped
            when the node counts change).
        """
        if self._source is not None:
            raise WarpError(
                "update(): this OffsetFieldWarp reads its field from texture_source;"
                " update the owning simulation instead"
            )
        u = _field(displacements, None)
        grid = _shape3(u.shape[:3])
        if material is not None:
            self._material = _material(material, grid)
        elif grid != self.shape:
            self._material = None
        self._u = u
        self.shape = grid
        self._version += 1
        self._full_version = self._version

    def update_region(self, start: Sequence[int], values: np.ndarray) -> None:
        """Replace the displacements of one block of nodes (the rest stays).

        The texture then rewrites only that block instead of re-uploading the whole
        field, which keeps a local drag on a large grid cheap.

        Parameters
        ----------
        start
            ``(i, j, k)`` of the block's first node.
        values
            ``(bx, by, bz, 3)`` displacements in mm; the block must lie inside the grid.
        """
        u = self._cpu_field("update_region()")
        v = np.asarray(values, dtype=np.float64)
        lo = np.asarray(start, dtype=np.int64).reshape(3)
        if v.ndim != 4 or v.shape[3] != 3:
            raise WarpError(f"update_region: values must be (bx, by, bz, 3); got {v.shape}")
        hi = lo + np.asarray(v.shape[:3])
        if np.any(lo < 0) or np.any(hi > np.asarray(self.shape)):
            raise WarpError(
                f"update_region: block {lo.tolist()}..{(hi - 1).tolist()} leaves the"
                f" {self.shape} node grid"
            )
        if not np.all(np.isfinite(v)):
            raise WarpError("update_region: values have NaN/Inf entries")
        u[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]] = v
        self._version += 1
        self._regions.append((self._version, lo, hi))
        del self._regions[:-64]  # older ones fall back to a full upload

    def max_displacement(self) -> float:
        """Largest displacement length ``max |u_ijk|`` in mm (CPU field only)."""
        u = self._cpu_field("max_displacement()")
        return float(np.sqrt(np.max(np.sum(u * u, axis=-1))))

    @property
    def revision(self) -> int:
        """Changes with every :meth:`update`, and for a GPU-owned field with its
        ``revision_source`` (without one such a field changes unseen)."""
        if self._revision_source is not None:
            return self._version * 2**32 + int(self._revision_source())
        return self._version

    @property
    def bounds_displacement(self) -> bool:
        """True when :meth:`displacement_range` gives intervals: a CPU field, or a
        GPU-owned one with a ``field_reader``."""
        return self._u is not None or self._field_reader is not None

    def _range_field(self) -> np.ndarray | None:
        """The field the displacement range is computed from (read back once per
        revision for a GPU-owned field)."""
        if self._u is not None:
            return self._u
        if self._field_reader is None:
            return None
        rev = self.revision
        if self._read_cache is None or self._read_cache[0] != rev:
            u = np.asarray(self._field_reader(), dtype=np.float64)
            if u.shape != (*self.shape, 3) or not np.all(np.isfinite(u)):
                raise WarpError(
                    f"field_reader returned shape {u.shape} (or non-finite values);"
                    f" expected {(*self.shape, 3)}"
                )
            self._read_cache = (rev, u)
        return self._read_cache[1]

    def displacement_range(
        self, lo: np.ndarray, hi: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Per box and axis, an interval ``[a, b]`` holding ``warp(p) - p`` (mm).

        Interval arithmetic through the inverse as the shader runs it: the iterate
        ``q_k = p + d_k`` has ``d_0 = 0`` (or, baked, ``-v(p)``: within the range of
        ``-u`` over the box widened by ``max |u|`` and one node spacing) and
        ``d_{k+1} = -u(q_k)``, so
        ``d_{k+1}`` lies in the range of ``-u`` over the nodes of the grid cells that
        the box moved by ``d_k``'s interval touches (0 included where that region
        leaves the grid box, where u = 0). Each range is widened by the RGBA16F
        rounding of the textures. The result is local and signed: a drag bounds only
        its neighbourhood, and a region moved by ~d reads through a window around -d
        as wide as u varies there. ``None`` for a GPU-owned field without a
        ``field_reader``; with one, the field is read back once per revision.
        """
        u = self._range_field()
        if u is None:
            return None
        lo, hi = np.atleast_2d(lo).astype(float), np.atleast_2d(hi).astype(float)
        a, b = np.zeros(lo.shape), np.zeros(lo.shape)
        if self.inverse == "baked":
            # the seed blends v(X) = u(q(X)) of baked nodes X within a node spacing of
            # the box, q(X) within max |u| of X: the range of -u over the box widened
            # by both (no need to bake on the CPU, which takes seconds on big grids)
            reach = np.abs(u).reshape(-1, 3).max(axis=0) * (1.0 + 2.0**-10) + self.spacing
            a, b = self._negated_range(u, lo - reach, hi + reach)
        for _ in range(self.steps):
            a, b = self._negated_range(u, lo + a, hi + b)
        return a, b

    def support_bricks(self, lo: np.ndarray, hi: np.ndarray, tol: float) -> np.ndarray:
        """Boxes where the warp may move a point by more than ``tol`` mm: those within
        ``max |u|`` of the cells whose nodes moved more than ``tol``, widened by one cell
        (:func:`voxwarp.deform.elements.field_support.field_support`), and whose
        :meth:`displacement_range` leaves ``[-tol, tol]`` (both bounds hold; the first
        is cheap and exact about untouched regions, the second local about how far);
        every box for a GPU-owned field without a ``field_reader``."""
        u = self._range_field()
        if u is None:
            return np.ones(np.atleast_2d(lo).shape[0], dtype=bool)
        lo, hi = np.atleast_2d(lo), np.atleast_2d(hi)
        moved = field_support(u, self.lo, self.spacing, lo, hi, tol)
        sel = np.flatnonzero(moved)
        if len(sel):  # both bounds hold: keep what both mark (the intervals are local)
            moved[sel] = super().support_bricks(lo[sel], hi[sel], tol)
        return moved

    def _negated_range(
        self, field: np.ndarray, lo: np.ndarray, hi: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Per box [lo, hi] (mm), the range of ``-field`` (trilinear, 0 outside the grid
        box) over the box, from the nodes of the cells it touches, with half-float
        rounding slack."""
        n = np.asarray(field.shape[:3])
        cells = np.maximum(n - 1, 1)
        h = (self.hi - self.lo) / np.maximum(n - 1, 1)
        # RGBA16F rounding: 2^-11 relative, or a subnormal step (6e-8); 0 stays 0
        slack = np.abs(field) * 2.0**-10 + np.where(field != 0, 6e-8, 0.0)
        cell_lo = cell_reduce(-field - slack, np.minimum)
        cell_hi = cell_reduce(-field + slack, np.maximum)
        ilo = np.clip(np.floor((lo - self.lo) / h), 0, cells - 1).astype(np.int64)
        ihi = np.clip(np.floor((hi - self.lo) / h), 0, cells - 1).astype(np.int64)
        # windows rounded up to powers of two (a wider window only loosens the range):
        # few distinct sizes, each reduced by doubling, shared passes cached
        width = 1 << np.ceil(np.log2(ihi - ilo + 1)).astype(np.int64)
        out_lo = np.empty(lo.shape)
        out_hi = np.empty(lo.shape)
        # one integer per window shape (exponents < 64 each): a 1D unique, far cheaper
        # than np.unique(..., axis=0) on many boxes
        exps = np.log2(width).astype(np.int64)
        codes, which = np.unique(
            (exps[:, 0] * 64 + exps[:, 1]) * 64 + exps[:, 2], return_inverse=True
        )
        sizes = 1 << np.stack([codes // 4096, codes // 64 % 64, codes % 64], axis=1)
        cache_lo: dict[tuple, np.ndarray] = {}
        cache_hi: dict[tuple, np.ndarray] = {}
        for s, size in enumerate(sizes):
            sel = np.flatnonzero(which.ravel() == s)
            i = ilo[sel]
            w = tuple(int(v) for v in size)
            out_lo[sel] = window_reduce(cell_lo, w, np.minimum, cache_lo)[i[:, 0], i[:, 1], i[:, 2]]
            out_hi[sel] = window_reduce(cell_hi, w, np.maximum, cache_hi)[i[:, 0], i[:, 1], i[:, 2]]
        # where the box leaves the grid box the field is 0
        outside = np.any((lo < self.lo) | (hi > self.hi), axis=1)
        out_lo[outside] = np.minimum(out_lo[outside], 0.0)
        out_hi[outside] = np.maximum(out_hi[outside], 0.0)
        return out_lo, out_hi

    # ---------------------------------------------------------------- CPU reference
    def _interpolate(
        self, q: np.ndarray, gradient: bool = False, field: np.ndarray | None = None
    ) -> Any:
        """Trilinear ``u(q)`` (N, 3), and with ``gradient`` also ``du/dq`` (N, 3, 3).

        ``field``: another node field over the same box (the baked inverse, on its own
        node counts) instead of u; 0 outside the box as well.
        """
        u = self._reference_field() if field is None else field
        n = np.asarray(u.shape[:3])
        s = (q - self.lo) / (self.hi - self.lo)
        inside = np.all((s >= 0.0) & (s <= 1.0), axis=1)
        x = np.clip(s, 0.0, 1.0) * (n - 1)
        i0 = np.minimum(np.floor(x).astype(np.intp), n - 2)
        f = x - i0
        g = 1.0 - f
        val = np.zeros((len(q), 3))
        grad = np.zeros((len(q), 3, 3)) if gradient else None
        flat = u.reshape(-1, 3)  # one gather per corner (a view where u is contiguous)
        base = (i0[:, 0] * n[1] + i0[:, 1]) * n[2] + i0[:, 2]
        for c in range(8):
            o = ((c >> 0) & 1, (c >> 1) & 1, (c >> 2) & 1)
            corner = np.take(flat, base + ((o[0] * n[1] + o[1]) * n[2] + o[2]), axis=0)
            w = [f[:, a] if o[a] else g[:, a] for a in range(3)]
            val += (w[0] * w[1] * w[2])[:, None] * corner
            if grad is not None:
                for a in range(3):
                    dw = 1.0 if o[a] else -1.0
                    others = w[(a + 1) % 3] * w[(a + 2) % 3]
                    grad[:, :, a] += (dw * others)[:, None] * corner
        val[~inside] = 0.0
        if grad is None:
            return val
        grad /= ((self.hi - self.lo) / (n - 1.0))[None, None, :]
        grad[~inside] = 0.0
        return val, grad

    def _reference_field(self) -> np.ndarray:
        """The field the CPU reference evaluates: the CPU field, or a GPU-owned field
        read back through ``field_reader`` (once per revision)."""
        u = self._range_field()
        if u is None:
            raise WarpError(
                "this OffsetFieldWarp's field is owned by a GPU texture (texture_source)"
                " without a field_reader, so apply/forward/jacobian have no CPU copy; give"
                " the warp field_reader and revision_source (MassSpring.warp() does)"
            )
        return u

    def offset(self, points: np.ndarray) -> np.ndarray:
        """The interpolated field ``u(X)`` (N, 3) at original-space points (mm)."""
        x = np.atleast_2d(np.asarray(points, dtype=np.float64))
        return self._interpolate(x)

    def field_forward(self, points: np.ndarray) -> np.ndarray:
        """The field's own map ``X + u(X)`` for (N, 3) points in mm: exact, no iteration;
        the seed of :meth:`forward` (which follows the inverse the volume is drawn with)."""
        x = np.atleast_2d(np.asarray(points, dtype=np.float64))
        return x + self._interpolate(x)

    def forward(self, points: np.ndarray) -> np.ndarray:
        """Original -> deformed as the volume is drawn: the point ``p`` whose
        :meth:`apply` (the inverse of the current mode, as the raycaster samples it) is
        ``X``, for (N, 3) points in mm (meshes, picking).

        ``"approx"`` and ``"exact"``: the field's own map ``X + u(X)`` refined by Newton
        steps on :meth:`apply` (:func:`~voxwarp.deform.warp.solve_forward`), so a mesh
        vertex lands where the volume shows its voxel. ``"baked"`` (converged: the bake
        is the inverse to float precision) takes ``X + u(X)`` itself, which needs no CPU
        bake (seconds per field change while dragging) and is within the bake's accuracy
        (hundredths of a mm) of it, and checks it in closed form. Where no such point
        exists it raises :class:`~voxwarp.deform.warp.ForwardMapError` (with the
        estimates): ``X + u(X)`` leaves the grid box (content cut at the box: pad the
        grid, ``ElementGrid(margin=...)``) or the field folds at ``X``. A GPU-owned field
        is read back through its ``field_reader`` once per revision; without one this
        raises :class:`WarpError`.
        """
        x = np.atleast_2d(np.asarray(points, dtype=np.float64))
        if self.inverse != "baked":
            return solve_forward(self, x, self.field_forward(x))
        u, grad = self._interpolate(x, gradient=True)
        p = x + u
        cut = np.any((p < self.lo) | (p > self.hi), axis=1) & np.any(u != 0.0, axis=1)
        folded = np.linalg.det(np.eye(3) + grad) <= 0.0
        bad = cut | folded
        if np.any(bad):
            raise ForwardMapError(
                f"the {self.kind} warp has no forward map at {int(bad.sum())} of {len(x)}"
                f" points ({int(cut.sum())} carried outside the field's grid box, where the"
                f" volume is cut: pad the grid, e.g. --grid-margin; {int(folded.sum())} in a"
                " fold, det J <= 0)",
                p,
                bad,
            )
        return p

    def export_resolution(self) -> float:
        """The shortest element edge (mm), at rest or deformed (``X + u(X)`` of the
        nodes): the field is trilinear between elements, its inverse (which the volume
        is drawn with) bends at the deformed elements' faces."""
        n = self.shape
        axes = [np.linspace(a, b, k) for a, b, k in zip(self.lo, self.hi, n, strict=True)]
        rest = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
        moved = rest + self._reference_field()[..., :3]
        edges = [np.linalg.norm(np.diff(moved, axis=a), axis=-1).min() for a in range(3)]
        return float(min(min(edges), np.min(self.spacing)))

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Deformed -> original: ``q`` with ``q + u(q) = p``, as the GLSL computes it.

        ``q_0 = p``, ``q_{n+1} = p - u(q_n)`` for :attr:`steps` steps (one for
        ``"approx"``). Points outside the grid box map to themselves.
        """
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        q = p.copy()
        if self.inverse == "baked":
            q = p - self._interpolate(p, field=self.baked_inverse())
        for _ in range(self.steps):
            q = p - self._interpolate(q)
        return q

    @property
    def bake_factor(self) -> int:
        """How much finer than the field the inverse is baked: the largest factor up to
        :data:`MAX_BAKE_FACTOR` that keeps :data:`MAX_BAKE_NODES` nodes per axis."""
        f = min((MAX_BAKE_NODES - 1) // max(n - 1, 1) for n in self.shape)
        return int(max(1, min(MAX_BAKE_FACTOR, f)))

    @property
    def bake_shape(self) -> tuple[int, int, int]:
        """Node counts of the baked inverse: ``(n - 1) * bake_factor + 1`` per axis."""
        f = self.bake_factor
        return tuple((n - 1) * f + 1 for n in self.shape)  # type: ignore[return-value]

    def baked_inverse(self) -> np.ndarray:
        """The inverse offsets ``v = X - q(X)`` at the baked nodes X (mm).

        The baked nodes cover the grid box :attr:`bake_factor` times finer than the
        field (:attr:`bake_shape`); ``q(X)`` solves ``q + u(q) = X`` by
        :data:`BAKE_ITERATIONS` fixed-point steps. ``"baked"`` seeds its iteration with
        ``q_0 = p - v(p)`` (v trilinear, 0 outside the grid box); the GPU bakes the same
        field with a compute shader (``shaders/offset_field_bake.comp.glsl``). Cached per
        field version. Returns ``bake_shape + (3,)``.
        """
        return self._baked_inverse_of(self._reference_field())

    def _baked_inverse_of(self, u: np.ndarray) -> np.ndarray:
        if self._baked_cpu is not None and self._baked_cpu[0] == self.revision:
            return self._baked_cpu[1]
        shape = self.bake_shape
        axes = [np.linspace(a, b, n) for a, b, n in zip(self.lo, self.hi, shape, strict=True)]
        x = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        q = _fixed_point(x, lambda q: self._interpolate(q, field=u))
        v = (x - q).reshape(*shape, 3)
        self._baked_cpu = (self.revision, v)
        return v

    def jacobian(self, points: np.ndarray, eps: float = 1e-3) -> np.ndarray:
        """Jacobians (N, 3, 3) ``(I + grad u(q))^-1`` at ``q = apply(p)``.

        ``grad u`` is the analytic gradient of the trilinear interpolant (one-sided at
        cell faces: the cell of the lower node). Where ``I + grad u`` is singular
        (``|det| <= 1e-6``: a folded field) the identity is returned, as on the GPU.
        ``eps`` is unused (kept for the base-class signature).
        """
        q = self.apply(points)
        _, grad = self._interpolate(q, gradient=True)
        a = np.eye(3) + grad
        det = np.linalg.det(a)
        ok = np.abs(det) > 1e-6
        out = np.broadcast_to(np.eye(3), a.shape).copy()
        if np.any(ok):
            out[ok] = np.linalg.inv(a[ok])
        return out

    def fold_summary(self) -> str | None:
        """One line saying where the field folds (``det(I + grad u) <= 0`` at a cell
        corner, :mod:`voxwarp.deform.elements.folds`), or None when it does not (or a
        GPU-owned field has no reader)."""
        u = self._range_field()
        return None if u is None else fold_summary(u, self.lo, self.spacing)

    def deformed_bounds(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Box in deformed space holding every point the warp maps into ``[lo, hi]``.

        Outside the grid box the warp is the identity, and inside it every step moves
        ``p`` by ``u`` of some point, so ``|p - q| <= max |u|`` per axis. The result is
        the bounding box of ``[lo, hi]`` and of ``[lo, hi]`` expanded by ``max |u_axis|``
        clipped to the grid box (content cannot leave the grid box). A GPU-owned field
        has no known maximum: the whole grid box is added.
        """
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        if self._u is None:
            elo, ehi = self.lo, self.hi
        else:
            m = np.max(np.abs(self._u), axis=(0, 1, 2))
            elo, ehi = np.maximum(lo - m, self.lo), np.minimum(hi + m, self.hi)
        if np.any(elo > ehi):
            return lo.copy(), hi.copy()
        return np.minimum(lo, elo), np.maximum(hi, ehi)

    # ---------------------------------------------------------------- GPU side
    def uniforms(self) -> dict[str, Any]:
        """``lo``, ``size`` (hi - lo), ``shape`` (node counts as floats); for
        ``"baked"`` also ``inverse_shape`` (:attr:`bake_shape`)."""
        out = {
            "lo": self.lo.copy(),
            "size": self.hi - self.lo,
            "shape": np.asarray(self.shape, dtype=np.float64),
        }
        if self.inverse == "baked":
            out["inverse_shape"] = np.asarray(self.bake_shape, dtype=np.float64)
        return out

    def glsl_constants(self) -> dict[str, Any]:
        """``ITERATIONS`` (fixed-point steps), ``SEEDED`` (start from the baked inverse)
        and ``ITERATE``, the steps unrolled as a macro (the last one ``WARP_offset_last``,
        which keeps grad u for shading: shaders/warp_offset_field.glsl).

        Unrolled in the text because llvmpipe (Mesa 22) keeps even a loop with a
        constant trip count of 1 as a loop, which is slower than straight-line code
        (docs/benchmarks.md, section 'voxwarp.deform.elements.offset_field: inverse accuracy and
        cost').
        """
        return {
            "ITERATIONS": int(self.steps),
            "SEEDED": self.inverse == "baked",
            "ITERATE": " ".join(
                ["q = p - WARP_offset(q);"] * (int(self.steps) - 1)
                + ["q = p - WARP_offset_last(q);"] * min(int(self.steps), 1)
            ),
        }

    def texture_data(self) -> np.ndarray:
        """The RGBA16F upload: ``(nz, ny, nx, 4)`` float16, x fastest (xyz = u, a = material)."""
        u = self._cpu_field("texture_data()")
        rgba = np.zeros((*self.shape, 4), dtype=np.float32)
        rgba[..., :3] = u
        if self._material is not None:
            rgba[..., 3] = self._material
        return np.ascontiguousarray(rgba.transpose(2, 1, 0, 3).astype(np.float16))

    def textures(self, ctx: Any) -> dict[str, Any]:
        """``{"displacement": texture}``: the uploaded field, or ``texture_source(ctx)``;
        with ``inverse="baked"`` also ``"inverse"``, the baked inverse offsets.

        The CPU field becomes an RGBA16F 2D array texture (layers = z) with linear
        filtering and clamp-to-edge, created on first use on ``ctx`` and rewritten after
        :meth:`update`. The inverse is baked on the GPU from that texture by a compute
        shader (once per field version; on every call for a ``texture_source``, whose
        changes this warp cannot see).
        """
        field = self._field_texture(ctx)
        out = {"displacement": field}
        if self.inverse == "baked":
            out["inverse"] = self._bake(ctx, field)
        return out

    def _bake(self, ctx: Any, field: Any) -> Any:
        entry = self._baked.get(id(ctx))
        if entry is not None and entry[0] is not ctx:
            entry = None  # a dead context's id reused
        if entry is not None and tuple(entry[2].size) != self.bake_shape:
            entry[1].release()
            entry[2].release()
            entry = None
        if entry is None:
            # one compiled bake shader per context, shared by every warp (gl_programs)
            hold = gl_programs.compute_shader(ctx, shaders.source("offset_field_bake.comp.glsl"))
            tex = ctx.texture3d(self.bake_shape, 4, dtype="f2")
            tex.filter = (ctx.LINEAR, ctx.LINEAR)
            tex.repeat_x = tex.repeat_y = tex.repeat_z = False
        else:
            _, hold, tex, version = entry
            if self._source is None and version == self._version:
                return tex
        field.use(0)
        self.run_bake(ctx, hold.program, tex)
        self._baked[id(ctx)] = (ctx, hold, tex, self._version)
        gl_holders.hold(ctx, self)
        return tex

    def run_bake(self, ctx: Any, program: Any, target: Any) -> None:
        """Run the bake compute ``program`` (shaders/offset_field_bake.comp.glsl, or a
        variant of it) over the field texture bound to unit 0, into the RGBA16F 3D
        texture ``target`` of :attr:`bake_shape`; returns after its memory barrier."""
        program["u_field"].value = 0
        program["u_shape"].value = tuple(int(n) for n in self.bake_shape)
        program["u_field_shape"].value = tuple(int(n) for n in self.shape)
        program["u_size"].value = tuple(float(v) for v in self.hi - self.lo)
        program["u_iterations"].value = BAKE_ITERATIONS
        target.bind_to_image(0, read=False, write=True)
        program.run(*[-(-int(n) // 4) for n in self.bake_shape])
        ctx.memory_barrier()

    def _field_texture(self, ctx: Any) -> Any:
        if self._source is not None:
            return self._source(ctx)
        entry = self._textures.get(id(ctx))
        if entry is not None and entry[0] is not ctx:
            entry = None  # a dead context's id reused: its texture died with it
        if entry is not None and tuple(entry[1].size) != self.shape:
            entry[1].release()  # node counts changed (ctx is current: we are drawing)
            entry = None
        if entry is None:
            tex = ctx.texture_array(self.shape, 4, self.texture_data().tobytes(), dtype="f2")
            tex.filter = (ctx.LINEAR, ctx.LINEAR)
            tex.repeat_x = tex.repeat_y = False  # clamp to edge
        else:
            tex = entry[1]
            if entry[2] != self._version:
                self._write_changes(tex, entry[2])
        self._textures[id(ctx)] = (ctx, tex, self._version)
        gl_holders.hold(ctx, self)
        return tex

    def _write_changes(self, tex: Any, since: int) -> None:
        """Bring ``tex`` (holding version ``since``) up to date: only the node blocks of
        later :meth:`update_region` calls when nothing else changed, else all."""
        later = [(lo, hi) for v, lo, hi in self._regions if v > since]
        oldest = self._regions[0][0] if self._regions else self._version + 1
        if self._full_version > since or not later or oldest > since + 1:
            tex.write(self.texture_data().tobytes())
            return
        lo = np.min([b[0] for b in later], axis=0)
        hi = np.max([b[1] for b in later], axis=0)
        u = self._cpu_field("textures()")
        rgba = np.zeros((*(hi - lo), 4), dtype=np.float32)
        rgba[..., :3] = u[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]]
        if self._material is not None:
            rgba[..., 3] = self._material[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]]
        data = np.ascontiguousarray(rgba.transpose(2, 1, 0, 3).astype(np.float16))
        size = hi - lo
        tex.write(data.tobytes(), viewport=(*(int(v) for v in lo), *(int(v) for v in size)))

    def release(self) -> None:
        """Free the textures this warp created (never a ``texture_source``'s); idempotent.

        Call it with the context the textures were made on current.
        """
        for _, tex, _ in self._textures.values():
            tex.release()
        self._textures.clear()
        for _, hold, tex, _ in self._baked.values():
            hold.release()  # the shared bake shader stays for other warps
            tex.release()
        self._baked.clear()

    def release_context(self, ctx: Any) -> None:
        """Free this warp's textures on ``ctx`` alone (``ctx`` current); idempotent."""
        field = self._textures.pop(id(ctx), None)
        if field is not None and field[0] is ctx:
            field[1].release()
        baked = self._baked.pop(id(ctx), None)
        if baked is not None and baked[0] is ctx:
            baked[1].release()
            baked[2].release()

    def signature(self) -> str:
        """``offset_field:<inverse>:<steps>`` (both are compile-time in the GLSL)."""
        return f"{self.kind}:{self.inverse}:{self.steps}"

    # ---------------------------------------------------------------- serialisation
    def to_dict(self) -> dict[str, Any]:
        """JSON form: lo, hi, shape, inverse, iterations, displacements (nested lists).

        With a :attr:`model_source` (a warp driven by a model such as
        :class:`~voxwarp.deform.elements.massspring.MassSpring`) the entry also holds ``"model"``,
        the
        model's own dict, and a GPU-owned field is read back once (through the
        model source) so that ``"displacements"`` hold exactly the field that is
        rendered; :meth:`from_dict` then rebuilds a warp that renders the same image.
        A warp loaded with a :attr:`model_state` writes it back as ``"model"``.
        A GPU-owned field without a model source is written with
        ``"displacements": None``; such an entry cannot be loaded by :meth:`from_dict`.
        """
        u = self._u
        model = self.model_state
        if self.model_source is not None:
            model, field = self.model_source()
            model = _model_dict(model)
            if u is None and field is not None:
                u = _field(field, self.shape)
        d: dict[str, Any] = {
            "type": self.kind,
            "lo": self.lo.tolist(),
            "hi": self.hi.tolist(),
            "shape": list(self.shape),
            "inverse": self.inverse,
            "iterations": self.iterations,
            "displacements": None if u is None else u.tolist(),
        }
        if self._material is not None:
            d["material"] = self._material.tolist()
        if model is not None:
            d["model"] = model
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> OffsetFieldWarp:
        """Build from :meth:`to_dict`'s form (``material`` and ``model`` optional).

        The warp always holds a CPU field (the saved ``displacements``), also for an
        entry a GPU simulation wrote, so it renders the saved image exactly. A
        ``"model"`` entry is kept, unchanged, as :attr:`model_state`.
        """
        missing = [k for k in ("lo", "hi", "shape") if k not in d]
        if missing:
            raise WarpError(f"an offset_field warp entry needs {missing}")
        if d.get("displacements") is None:
            raise WarpError(
                "this offset_field warp has no displacements: its field was owned by a GPU"
                " simulation (e.g. MassSpring), which saves and restores the field itself;"
                " a warp entry alone cannot rebuild it"
            )
        shape = d["shape"]
        if isinstance(shape, list):
            shape = tuple(shape)
        return cls(
            d["lo"],
            d["hi"],
            d["displacements"],
            shape=shape,
            inverse=d.get("inverse", "exact"),
            iterations=d.get("iterations"),
            material=d.get("material"),
            model_state=d.get("model"),
        )

    def __repr__(self) -> str:
        src = "texture_source" if self._source is not None else "cpu"
        return (
            f"OffsetFieldWarp(shape={self.shape}, lo={self.lo.tolist()}, hi={self.hi.tolist()},"
            f" inverse={self.inverse!r}, iterations={self.iterations}, field={src})"
        )


def texture_field(tex: Any, shape: Sequence[int]) -> np.ndarray | None:
    """The ``(nx, ny, nz, 3)`` float64 field an RGBA16F 2D array texture (layers = z)
    or 3D texture of ``shape`` holds -- what the warp renders, read back -- or ``None``
    when ``tex`` is not such a texture (e.g. a stand-in solver in tests)."""
    nx, ny, nz = (int(n) for n in shape)
    try:
        if tuple(tex.size) != (nx, ny, nz) or tex.components != 4 or tex.dtype != "f2":
            return None
        raw = np.frombuffer(tex.read(), dtype=np.float16).reshape(nz, ny, nx, 4)
    except (AttributeError, TypeError, ValueError):
        return None
    return raw.transpose(2, 1, 0, 3)[..., :3].astype(np.float64)


def saved_model(
    warp: Any, kind: str, label: str, owner: str, error: type[Exception]
) -> tuple[Mapping[str, Any], np.ndarray]:
    """The model entry and element positions behind a warp loaded from scene JSON.

    Parameters
    ----------
    warp
        An :class:`OffsetFieldWarp` whose :attr:`OffsetFieldWarp.model_state` has
        ``"type": kind``.
    kind, label, owner
        The model's type name in scene JSON, its name in messages and its class.
    error
        The model's exception class.

    Returns
    -------
    (state, positions)
        The model dict and ``rest + displacements`` (the saved field) of its grid.
    """
    from voxwarp.deform.elements.grid import grid_from_entry  # grid imports scipy

    state = getattr(warp, "model_state", None)
    if not isinstance(state, Mapping) or state.get("type") != kind:
        raise error(
            f"this warp carries no {label} model (its model_state is not"
            f" {{'type': {kind!r}, ...}}); only warps saved from a {owner} can be resumed"
        )
    u = np.asarray(warp.displacements, dtype=np.float64)
    grid = grid_from_entry(state, kind, error)
    if u.shape != (*grid.shape, 3):
        raise error(
            f"the warp's field has shape {u.shape} but its model's grid is"
            f" {grid.shape}; the scene entry is inconsistent"
        )
    return state, grid.rest_positions + u


def element_model_warp(
    warp: OffsetFieldWarp | None,
    grid: Any,
    *,
    displacements: Callable[[], np.ndarray],
    solver: Callable[[], Any] | None,
    model_source: ModelSource,
    inverse: str | None,
    iterations: int | None,
    error: type[Exception] = WarpError,
) -> OffsetFieldWarp:
    """The offset-field warp of an element model (mass-spring, ChainMail): made once,
    then reconfigured.

    Parameters
    ----------
    warp
        The model's warp so far (``None``: make it).
    grid
        The :class:`~voxwarp.deform.elements.grid.ElementGrid` (``lo``, ``hi``, ``shape``).
    displacements
        ``() -> (nx, ny, nz, 3)`` the model's displacements (mm): the CPU field, or for
        a GPU solver the read-back that bounds the field for empty-space skipping.
    solver
        ``() -> the model's current GPU solver`` (one with ``displacement_texture()`` and
        ``revision``; a getter, since a model may rebuild its solver): the warp then
        samples its texture and nothing is uploaded. ``None`` for a CPU field.
    model_source
        See :class:`OffsetFieldWarp` (the model's dict for scene JSON).
    inverse, iterations
        New inverse mode / iterations, or ``None`` to keep them (``"baked"`` with its
        default iterations when the warp is made).
    error
        Exception class for bad ``inverse`` / ``iterations`` (the model's own).
    """
    if warp is None:
        lo, hi = np.asarray(grid.lo, float).copy(), np.asarray(grid.hi, float).copy()
        if solver is not None:
            warp = OffsetFieldWarp(
                lo,
                hi,
                shape=grid.shape,
                texture_source=lambda ctx=None: solver().displacement_texture(),
                model_source=model_source,
                inverse="baked",
                # lets the renderer bound the field for empty-space skipping: it reads
                # back only once a field state is drawn twice (not while it changes)
                field_reader=displacements,
                revision_source=lambda: solver().revision,
            )
        else:
            warp = OffsetFieldWarp(
                lo,
                hi,
                displacements(),
                shape=grid.shape,
                model_source=model_source,
                inverse="baked",
            )
    if inverse is not None:
        if inverse not in INVERSE_MODES:
            raise error(f"inverse must be one of {list(INVERSE_MODES)}; got {inverse!r}")
        warp.inverse = inverse
    if iterations is not None:
        ok = isinstance(iterations, int | np.integer) and not isinstance(iterations, bool)
        if not ok or not 0 <= int(iterations) <= MAX_ITERATIONS:
            raise error(f"iterations must be an integer 0..{MAX_ITERATIONS}; got {iterations!r}")
        warp.iterations = int(iterations)
    return warp
