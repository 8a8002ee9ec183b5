"""Imported displacement fields (ITK, ANTs, SimpleITK, voxelmorph) as a warp.

About this technique
--------------------
Registration tools describe a non-linear transform by a *displacement field*: a vector
``u`` per node of a regular grid, trilinear between nodes. ITK, ANTs and SimpleITK use
the **pull-back** convention: a point ``p`` of the fixed image takes its value from the
moving image at ``p + u(p)``. That is exactly the map the raycaster needs (deformed ->
original, :mod:`voxwarp.deform.warp`), so rendering the moving image through the field
shows it registered to the fixed image, sampled where it lies, without resampling it
and without inverting the field: ``warp(p) = p + u(p)``.

The field lives on its own grid: ``affine`` maps a node's index ``(i, j, k)`` to world
mm (voxwarp's world is RAS+), with any spacing, orientation and extent, unrelated to
the volume's grid. As in ITK's ``DisplacementFieldTransform`` (linear interpolator), a
point whose continuous index lies within half a node of the grid uses the edge nodes'
values (clamped) and a point farther out is not moved (``u = 0``).

ITK stores physical points and vectors in LPS; voxwarp converts a field given in LPS
(``space="LPS"``) to RAS by negating the first two components of its vectors and its
affine's rows. voxelmorph-style fields in voxel units (``units="voxel"``) are carried
to mm by the affine's linear part.

Meshes and handles need the *forward* map (moving -> fixed): the point ``p`` with
``p + u(p) = x``, found by the fixed point ``p <- x - u(p)`` (a contraction where
``|grad u| < 1``, i.e. where the field does not fold), finished by Newton steps.

On the GPU the field is an RGBA16F 2D array texture whose layers are the grid's
z-slices (as the offset field's), sampled by two hardware-bilinear fetches and a lerp.
"""

from __future__ import annotations

import base64
import binascii
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar

import numpy as np

from voxwarp.deform import gl_holders
from voxwarp.deform.node_grid import MAX_DISPLACEMENT_MM as MAX_DISPLACEMENT_MM
from voxwarp.deform.node_grid import cell_reduce, check_vectors, window_reduce
from voxwarp.deform.warp import Warp, WarpError, box_corners, check_forward, register_warp

#: Spaces a field's affine and vectors may be given in.
FIELD_SPACES: tuple[str, ...] = ("RAS", "LPS")
#: Units of the vectors: mm (ITK, ANTs, SimpleITK) or voxels of the field's grid
#: (voxelmorph's spatial transformer).
FIELD_UNITS: tuple[str, ...] = ("mm", "voxel")
#: Fixed-point steps of :meth:`DisplacementFieldWarp.forward` before Newton takes over.
FORWARD_FIXED_POINT_STEPS = 40
#: A field held without a file is embedded in scene JSON up to this many bytes.
MAX_EMBEDDED_BYTES = 64 << 20
_LPS = np.diag([-1.0, -1.0, 1.0, 1.0])

#: ``reader(path, part) -> DisplacementFieldWarp``: how a scene entry's ``path`` (and
#: ``part``: which field of a transform file) is read. The application layer sets it
#: (``voxwarp.io.fields``); deform reads no file formats.
FieldReader = Callable[[str, "int | None"], "DisplacementFieldWarp"]
_reader: list[FieldReader] = []


def set_field_reader(reader: FieldReader) -> None:
    """Install the function that reads a field file named by a scene entry."""
    _reader[:] = [reader]


def _affine(affine: Any) -> np.ndarray:
    try:
        a = np.asarray(affine, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise WarpError("the field's affine must be a 4x4 matrix of numbers") from exc
    if a.shape != (4, 4):
        raise WarpError(f"the field's affine must be 4x4 (index -> world mm); got {a.shape}")
    if not np.all(np.isfinite(a)) or not np.allclose(a[3], [0, 0, 0, 1]):
        raise WarpError("the field's affine must be finite with last row (0, 0, 0, 1)")
    if abs(np.linalg.det(a[:3, :3])) < 1e-12:
        raise WarpError(
            "the field's affine is singular (zero spacing or parallel axes); check the"
            " file's spacing and direction"
        )
    return a


def _vectors(displacements: Any) -> np.ndarray:
    try:
        u = np.asarray(displacements, dtype=np.float32)
    except (TypeError, ValueError) as exc:
        raise WarpError("a displacement field must be a numeric (nx, ny, nz, 3) array") from exc
    if u.ndim != 4:
        raise WarpError(
            f"a displacement field must be 3-D with 3 components, shape (nx, ny, nz, 3);"
            f" got {u.ndim - 1}-D shape {u.shape}"
        )
    if u.shape[3] != 3:
        raise WarpError(
            f"a displacement field needs 3 components per node (x, y, z); got {u.shape[3]}"
        )
    if min(u.shape[:3]) < 2:
        raise WarpError(
            f"a displacement field needs at least 2 nodes per axis; got {u.shape[:3]}"
            " (a 2-D field cannot deform a volume)"
        )
    check_vectors(u, "check the units: mm expected (voxel units: --field-convention voxel)")
    return u


@register_warp
class DisplacementFieldWarp(Warp):
    """Warp by a displacement field from a registration tool (pull-back, ITK convention).

    ``warp(p) = p + u(p)``: the volume is drawn as the *moving* image resampled into the
    *fixed* image's space, as ``SimpleITK.Resample(moving, DisplacementFieldTransform(u))``
    would compute it, but at render time. Read a file with
    :func:`voxwarp.io.fields.load_displacement_field`; build one from arrays here.

    Parameters
    ----------
    displacements
        ``(nx, ny, nz, 3)`` vectors, one per grid node (x index fastest in memory does
        not matter; axis 0 is the grid's i axis).
    affine
        4x4 map from node index ``(i, j, k, 1)`` to world mm of the field's grid.
    space
        ``"RAS"`` (voxwarp's world, default) or ``"LPS"`` (ITK's physical space): the
        space of both ``affine`` and the vectors. LPS is converted on construction.
    units
        ``"mm"`` (default) or ``"voxel"``: vectors in index units of the field's grid
        (voxelmorph), converted by the affine's linear part.
    path
        The file the field came from; scene JSON then stores this path instead of the
        field's values.
    part
        Which non-linear transform of a transform file ``path`` this field is (scene
        JSON stores it with the path); ``None`` for a field image.

    Attributes
    ----------
    displacements : numpy.ndarray
        The ``(nx, ny, nz, 3)`` float32 vectors in RAS mm (read-only view).
    affine : numpy.ndarray
        The 4x4 index -> world (RAS mm) matrix of the field's grid.
    """

    kind = "displacement_field"
    glsl_file = "warp_displacement_field.glsl"
    file_keys: ClassVar[tuple[str, ...]] = ("path",)
    forward_tolerance: ClassVar[float] = 1e-3

    def __init__(
        self,
        displacements: Any,
        affine: Any,
        *,
        space: str = "RAS",
        units: str = "mm",
        path: str | None = None,
        part: int | None = None,
    ) -> None:
        if space not in FIELD_SPACES:
            raise WarpError(f"space must be one of {list(FIELD_SPACES)}; got {space!r}")
        if units not in FIELD_UNITS:
            raise WarpError(f"units must be one of {list(FIELD_UNITS)}; got {units!r}")
        a = _affine(affine)
        u = _vectors(displacements)
        if units == "voxel":
            u = _vectors(u @ a[:3, :3].T.astype(np.float32))
        if space == "LPS":
            a = _LPS @ a
            u = u * np.array([-1.0, -1.0, 1.0], dtype=np.float32)
        self._u = np.ascontiguousarray(u, dtype=np.float32)
        self._u.flags.writeable = False
        self.affine = a
        self._to_index = np.linalg.inv(a)
        self.path = None if path is None else str(path)
        self.part = None if part is None else int(part)
        self._textures: dict[int, tuple[Any, Any]] = {}
        self._ranges: dict[tuple[int, int, int], tuple[np.ndarray, np.ndarray]] = {}
        self._cells: tuple[np.ndarray, np.ndarray] | None = None

    # ---------------------------------------------------------------- properties
    @property
    def displacements(self) -> np.ndarray:
        """The ``(nx, ny, nz, 3)`` vectors in RAS mm (read-only)."""
        return self._u

    @property
    def shape(self) -> tuple[int, int, int]:
        """Nodes per axis ``(nx, ny, nz)``."""
        return tuple(int(n) for n in self._u.shape[:3])  # type: ignore[return-value]

    @property
    def spacing(self) -> np.ndarray:
        """Node spacing per grid axis (mm): the lengths of the affine's columns."""
        return np.linalg.norm(self.affine[:3, :3], axis=0)

    def max_displacement(self) -> float:
        """Largest vector length ``max |u|`` in mm (squared lengths summed in float32,
        without a float64 copy of the field)."""
        u = self._u.reshape(-1, 3)
        return float(np.sqrt(np.max(np.einsum("ij,ij->i", u, u), initial=0.0)))

    def magnitude(self) -> np.ndarray:
        """``|u|`` per node (mm), shape ``(nx, ny, nz)``: what the field slice view shows."""
        return np.sqrt(np.sum(self._u.astype(np.float64) ** 2, axis=-1))

    def support_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """World box (mm) around the grid's half-node border, where ``u`` may be non-zero."""
        corners = box_corners(np.full(3, -0.5), np.asarray(self.shape) - 0.5)
        world = corners @ self.affine[:3, :3].T + self.affine[:3, 3]
        return world.min(axis=0), world.max(axis=0)

    # ---------------------------------------------------------------- CPU reference
    def index_of(self, points: np.ndarray) -> np.ndarray:
        """Continuous node indices (N, 3) of world points (mm)."""
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        return p @ self._to_index[:3, :3].T + self._to_index[:3, 3]

    def displacement_at(self, points: np.ndarray, gradient: bool = False) -> Any:
        """``u(p)`` (N, 3) in mm at world points; with ``gradient`` also ``du/dp`` (N, 3, 3).

        Trilinear between nodes, edge values within half a node outside the grid, 0
        beyond (ITK's ``DisplacementFieldTransform``).
        """
        c = self.index_of(points)
        n = np.asarray(self.shape)
        inside = np.all((c >= -0.5) & (c <= n - 0.5), axis=1)
        x = np.clip(c, 0.0, n - 1.0)
        i0 = np.minimum(np.floor(x).astype(np.intp), n - 2)
        f, u = x - i0, self._u.reshape(-1, 3)
        step = np.array([n[1] * n[2], n[2], 1], dtype=np.intp)
        base = i0 @ step  # each corner is one flat gather (the same values)
        val = np.zeros((len(c), 3))
        grad = np.zeros((len(c), 3, 3)) if gradient else None
        for corner in range(8):
            o = [(corner >> a) & 1 for a in range(3)]
            node = u[base + int(np.dot(o, step))].astype(np.float64)
            w = [f[:, a] if o[a] else 1.0 - f[:, a] for a in range(3)]
            val += (w[0] * w[1] * w[2])[:, None] * node
            if grad is not None:
                for a in range(3):
                    sign = 1.0 if o[a] else -1.0
                    grad[:, :, a] += (sign * w[(a + 1) % 3] * w[(a + 2) % 3])[:, None] * node
        val[~inside] = 0.0
        if grad is None:
            return val
        clamped = (c < 0.0) | (c > n - 1.0)  # constant across the half-node border
        grad[np.repeat(clamped[:, None, :], 3, axis=1)] = 0.0
        grad = grad @ self._to_index[:3, :3]  # d/d index -> d/d world
        grad[~inside] = 0.0
        return val, grad

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Deformed (fixed) -> original (moving): ``p + u(p)`` for (N, 3) points in mm."""
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        return p + self.displacement_at(p)

    def jacobian(self, points: np.ndarray, eps: float = 1e-3) -> np.ndarray:
        """``I + du/dp`` (N, 3, 3), analytic (the lower node's cell on cell faces)."""
        _, grad = self.displacement_at(points, gradient=True)
        return np.eye(3) + grad

    def forward(self, points: np.ndarray) -> np.ndarray:
        """Original (moving) -> deformed (fixed): ``p`` with ``p + u(p) = x``.

        :data:`FORWARD_FIXED_POINT_STEPS` steps of ``p <- x - u(p)``, then Newton steps
        (:meth:`voxwarp.deform.warp.Warp.forward`) for points not yet within
        :attr:`forward_tolerance` mm. Raises :class:`WarpError` where the field folds.
        """
        x = np.atleast_2d(np.asarray(points, dtype=np.float64))
        p = x.copy()
        for _ in range(FORWARD_FIXED_POINT_STEPS):
            p = x - self.displacement_at(p)
        err = np.linalg.norm(self.apply(p) - x, axis=1)
        bad = ~(err <= self.forward_tolerance)
        if np.any(bad):
            p[bad] = self._newton(p[bad], x[bad])
        return check_forward(self, p, x)

    def _newton(self, p: np.ndarray, x: np.ndarray) -> np.ndarray:
        p = np.where(np.isfinite(p), p, x)
        for _ in range(self.forward_steps):
            r = self.apply(p) - x
            j = self.jacobian(p)
            ok = np.abs(np.linalg.det(j)) > 1e-9
            step = r.copy()
            step[ok] = np.linalg.solve(j[ok], r[ok][..., None])[..., 0]
            p = p - step
        return p

    def deformed_bounds(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Box in deformed space holding every ``p`` with ``p + u(p)`` in ``[lo, hi]``.

        Outside the field's support ``u = 0``; inside, ``p = x - u(p)`` lies within the
        box moved by ``-u``'s range, clipped to the support.
        """
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        s_lo, s_hi = self.support_bounds()
        u = self._u.reshape(-1, 3).astype(np.float64)
        elo = np.maximum(lo - u.max(axis=0), s_lo)
        ehi = np.minimum(hi - u.min(axis=0), s_hi)
        if np.any(elo > ehi):
            return lo.copy(), hi.copy()
        return np.minimum(lo, elo), np.maximum(hi, ehi)

    @property
    def bounds_displacement(self) -> bool:
        """Always True: the field's values bound its displacement."""
        return True

    def displacement_range(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per box and axis, an interval holding ``u(p)`` over the box (mm).

        The box's corners go to index space; the nodes of the cells they span bound the
        trilinear values (widened by the RGBA16F rounding), and 0 joins the interval
        where the box reaches past the grid's half-node border.
        """
        lo, hi = np.atleast_2d(lo).astype(float), np.atleast_2d(hi).astype(float)
        n = np.asarray(self.shape)
        cmin = np.full(lo.shape, np.inf)
        cmax = np.full(lo.shape, -np.inf)
        for corner in range(8):
            pick = np.array([(corner >> a) & 1 for a in range(3)], dtype=bool)
            c = self.index_of(np.where(pick, hi, lo))
            np.minimum(cmin, c, out=cmin)
            np.maximum(cmax, c, out=cmax)
        cells = n - 1
        ilo = np.clip(np.floor(cmin), 0, cells - 1).astype(np.int64)
        # the cells from floor(cmin) to floor(cmax): at most ceil(cmax - cmin) + 1 of
        # them, the same count for boxes of one size wherever they lie; rounded up to a
        # power of two (a wider window only loosens a range), so there are few widths,
        # their min/max grids cached per width (the field never changes)
        span = np.minimum(np.ceil(cmax - cmin), cells)
        k = np.ceil(np.log2(span + 1)).astype(np.int64)
        key = (k[:, 0] * 16 + k[:, 1]) * 16 + k[:, 2]
        out_lo, out_hi = np.empty(lo.shape), np.empty(lo.shape)
        for code in np.unique(key):
            sel = np.flatnonzero(key == code)
            width = (1 << int(code // 256), 1 << int(code // 16 % 16), 1 << int(code % 16))
            win_lo, win_hi = self._window_ranges(width)
            i = ilo[sel].T
            out_lo[sel] = win_lo[i[0], i[1], i[2]]
            out_hi[sel] = win_hi[i[0], i[1], i[2]]
        leaves = np.any((cmin < -0.5) | (cmax > n - 0.5), axis=1)
        away = np.any((cmax < -0.5) | (cmin > n - 0.5), axis=1)
        out_lo[leaves] = np.minimum(out_lo[leaves], 0.0)
        out_hi[leaves] = np.maximum(out_hi[leaves], 0.0)
        out_lo[away] = 0.0
        out_hi[away] = 0.0
        return out_lo, out_hi

    def _window_ranges(self, width: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
        """Per cell, the min and max of ``u`` (with RGBA16F rounding slack) over the
        nodes of the ``width`` cells starting there; cached per width (the field never
        changes)."""
        hit = self._ranges.get(width)
        if hit is None:
            cell_lo, cell_hi = self._cell_ranges()
            hit = (
                window_reduce(cell_lo, width, np.minimum),
                window_reduce(cell_hi, width, np.maximum),
            )
            self._ranges[width] = hit
        return hit

    def _cell_ranges(self) -> tuple[np.ndarray, np.ndarray]:
        """Per grid cell, the min and max of ``u`` over its 8 nodes, widened by the
        RGBA16F rounding of the texture (``|u| 2^-10``, or a subnormal step)."""
        if self._cells is None:
            u = self._u
            slack = np.abs(u) * np.float32(2.0**-10) + np.where(u != 0, 6e-8, 0).astype(np.float32)
            self._cells = (cell_reduce(u - slack, np.minimum), cell_reduce(u + slack, np.maximum))
        return self._cells

    # ---------------------------------------------------------------- GPU side
    def uniforms(self) -> dict[str, Any]:
        """``world_to_grid`` (4x4 world mm -> node index) and ``shape`` (nodes per axis)."""
        return {
            "world_to_grid": self._to_index,
            "shape": np.asarray(self.shape, dtype=np.float64),
        }

    def texture_data(self) -> np.ndarray:
        """The RGBA16F upload: ``(nz, ny, nx, 4)`` float16, x fastest (xyz = u in mm)."""
        rgba = np.zeros((*self.shape, 4), dtype=np.float16)
        rgba[..., :3] = self._u
        return np.ascontiguousarray(rgba.transpose(2, 1, 0, 3))

    def textures(self, ctx: Any) -> dict[str, Any]:
        """``{"displacement": texture}``: the field as an RGBA16F 2D array texture (layers =
        z-slices, linear filtering, clamp to edge), uploaded once per context."""
        entry = self._textures.get(id(ctx))
        if entry is None or entry[0] is not ctx:
            _check_texture_size(ctx, self.shape)
            tex = ctx.texture_array(self.shape, 4, self.texture_data().tobytes(), dtype="f2")
            tex.filter = (ctx.LINEAR, ctx.LINEAR)
            tex.repeat_x = tex.repeat_y = False
            entry = (ctx, tex)
            self._textures[id(ctx)] = entry
            gl_holders.hold(ctx, self)
        return {"displacement": entry[1]}

    def bind_volume(self, volume: Any) -> None:
        """Warn (one line) when the field's grid does not reach the volume at all: the
        field then moves nothing, which usually means it belongs to another image."""
        lo, hi = self.support_bounds()
        c = np.asarray(volume.corners(), float)
        if np.any(lo > c.max(axis=0)) or np.any(hi < c.min(axis=0)):
            warnings.warn(
                f"the displacement field {self.path or ''} covers RAS"
                f" {np.round(lo, 1).tolist()}..{np.round(hi, 1).tolist()} mm, which misses"
                f" the volume {getattr(volume, 'name', '')!r} entirely: it moves nothing"
                " (a field for another image, or another space?)",
                UserWarning,
                stacklevel=2,
            )

    def release(self) -> None:
        """Free the field's textures (call with their context current); idempotent."""
        for _, tex in self._textures.values():
            tex.release()
        self._textures.clear()

    def release_context(self, ctx: Any) -> None:
        """Free the field's texture on ``ctx`` alone (``ctx`` current); idempotent."""
        entry = self._textures.pop(id(ctx), None)
        if entry is not None and entry[0] is ctx:
            entry[1].release()

    # ---------------------------------------------------------------- serialisation
    def to_dict(self) -> dict[str, Any]:
        """``{"type": "displacement_field", "path": ...}`` for a field read from a file;
        otherwise the field embedded (``affine``, ``shape``, base64 little-endian float32
        ``data`` in C order), up to :data:`MAX_EMBEDDED_BYTES`."""
        if self.path is not None:
            out: dict[str, Any] = {"type": self.kind, "path": self.path}
            return out if self.part is None else {**out, "part": self.part}
        if self._u.nbytes > MAX_EMBEDDED_BYTES:
            raise WarpError(
                f"a {self._u.nbytes >> 20} MiB displacement field is too big to embed in a"
                " scene; write it with voxwarp.save_displacement_field and load it from"
                " that file"
            )
        data = base64.b64encode(self._u.astype("<f4").tobytes()).decode("ascii")
        return {
            "type": self.kind,
            "affine": self.affine.tolist(),
            "shape": list(self.shape),
            "data": data,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> DisplacementFieldWarp:
        """Build from :meth:`to_dict` output (a ``path`` is read by the installed reader)."""
        if "path" in d:
            part = d.get("part")
            if part is not None and (not isinstance(part, int) or isinstance(part, bool)):
                raise WarpError(f"a displacement_field 'part' must be an integer; got {part!r}")
            if not _reader:
                raise WarpError(
                    "reading a displacement field file needs voxwarp.io.fields"
                    " (load scenes with voxwarp.Scene.load)"
                )
            return _reader[0](str(d["path"]), part)
        try:
            shape = [int(v) for v in d["shape"]]
            raw = base64.b64decode(str(d["data"]), validate=True)
            affine = d["affine"]
        except (KeyError, TypeError, ValueError, binascii.Error) as exc:
            raise WarpError(
                "a displacement_field entry needs 'path', or 'affine', 'shape' and"
                f" base64 'data'; {exc}"
            ) from exc
        if len(shape) != 3 or len(raw) != 12 * int(np.prod(shape)):
            raise WarpError(
                f"a displacement_field entry's data ({len(raw)} bytes) does not fit shape"
                f" {shape} x 3 float32"
            )
        u = np.frombuffer(raw, dtype="<f4").reshape(*shape, 3)
        return cls(u, affine)


def _check_texture_size(ctx: Any, shape: tuple[int, int, int]) -> None:
    """Raise :class:`WarpError` when a field of ``shape`` nodes exceeds the context's 2D
    texture size or array layers (its texture is a 2D array of z-slices)."""
    side = int(ctx.info.get("GL_MAX_TEXTURE_SIZE", 16384))
    layers = int(ctx.info.get("GL_MAX_ARRAY_TEXTURE_LAYERS", 2048))
    if max(shape[:2]) > side or shape[2] > layers:
        raise WarpError(
            f"a {shape[0]}x{shape[1]}x{shape[2]} displacement field exceeds this GPU's"
            f" texture limits ({side} per slice side, {layers} slices); resample it"
            " coarser (e.g. SimpleITK.Resample of the field image, or voxwarp"
            " export-field --spacing)"
        )


def sample_chain_field(
    apply: Callable[[np.ndarray], np.ndarray], affine: np.ndarray, shape: Sequence[int]
) -> np.ndarray:
    """``apply(p) - p`` at every node of a grid (``affine``, ``shape``): (nx, ny, nz, 3) mm.

    The pull-back field of any warp chain; nodes are evaluated a slab of z at a time.
    """
    nx, ny, nz = (int(v) for v in shape)
    out = np.empty((nx, ny, nz, 3), dtype=np.float32)
    ii, jj = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    for k in range(nz):
        idx = np.stack([ii.ravel(), jj.ravel(), np.full(ii.size, k)], axis=1).astype(float)
        p = idx @ affine[:3, :3].T + affine[:3, 3]
        out[:, :, k] = (apply(p) - p).reshape(nx, ny, 3)
    return out
