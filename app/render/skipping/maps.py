"""Empty-space skipping maps: which parts of a volume a compositing mode can see, and
how far a ray may jump from each place without missing any of them.

Two resolutions, both computed on the CPU from the volume and the scene:

* **blocks** of ``BLOCK``³ voxels (with a one-voxel apron): value range per block,
  visibility for the mode and the chessboard distance to the nearest visible block.
  Used by warped (non-affine) rays and by the dynamic mip/minip skips.
* **trilinear cells** (cell ``c`` spans texel coordinates ``[c - 1/2, c + 1/2]`` per
  axis and interpolates voxels ``c - 1`` and ``c``): value range per cell, visibility,
  and per **ray-direction octant** the size of the largest invisible cube that starts
  at the cell and extends in that octant's direction (:func:`octant_skip_distances`).
  A ray travelling in that octant can leave the whole cube in one jump. Compared with
  a cube centred on the cell (isotropic chessboard distance), the directional cube
  does not waste half of its extent behind the ray: on the benchmark CT it cuts the
  loop iterations per pixel from 30 to 21 (Deakin & Knackstedt 2020, "Efficient ray
  casting of volumetric images using distance maps for empty space skipping").

:func:`octant_regions` splits the image into the regions whose rays share an octant,
so the renderer can draw each region with its octant's map. When the maps are built,
kept and dropped is :mod:`voxwarp.render.skipping.cache`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from voxwarp.deform.warp import chain_displacement_range
from voxwarp.render.skipping import numpy_maps as skip_numpy

if TYPE_CHECKING:
    from voxwarp.core.transfer_function import TransferFunction
    from voxwarp.scene import Scene

#: Voxels per block edge of the block grid.
BLOCK = 4
#: Exact cell-level octant distances are computed up to this many cells; beyond it the
#: block-level octant distance (exact in blocks) takes over (see octant_skip_distances).
CELL_CAP = 8

#: A direction component counts as negative only below ``-OCTANT_EPS * max_i |d_i|``
#: (also ``OCTANT_EPS`` in the raycaster), so axis-aligned rays, whose other components
#: are rounding noise of either sign, fall in one well-defined octant.
OCTANT_EPS = 1e-5

Octant = tuple[int, int, int]
"""Signs (+1 or -1) of a ray direction's x, y and z components (see OCTANT_EPS)."""

#: Arrays of at least this many elements (voxels, cells, blocks) are classified and
#: measured by the compiled kernels of :mod:`voxwarp.render.skipping.kernels`; smaller ones
#: by the numpy builders of :mod:`voxwarp.render.skipping.numpy_maps` (the same arrays), so that
#: a small volume's first render does not pay numba's start-up (once per process).
COMPILED_MIN_SIZE = 1 << 23
#: Deformed-space octant maps of at least this many cells use the compiled kernels:
#: they are rebuilt for every warp state that rests (on the GUI thread, after each
#: release), where numba's start-up, once per process, is soon paid back (a 4 M-cell
#: map: 0.02 s against numpy's 0.1 s per octant).
WARPED_COMPILED_MIN_SIZE = 1 << 20


def _compiled(size: int) -> bool:
    return int(size) >= COMPILED_MIN_SIZE


def tf_key(tf: TransferFunction) -> tuple:
    """What a transfer function's visibility depends on (cache key)."""
    return tuple(tf.points)


def _texture_order(data: np.ndarray) -> np.ndarray:
    """``data.T`` as a C-contiguous (nz, ny, nx) array (no copy for a Volume's F-ordered data)."""
    return np.ascontiguousarray(np.asarray(data).T)


def block_min_max(data: np.ndarray, block: int = BLOCK) -> tuple[np.ndarray, np.ndarray]:
    """Per-block (min, max) of ``data`` (nx, ny, nz) with a one-voxel apron.

    Block ``b`` along an axis covers voxels ``[b*block - 1, (b+1)*block]`` (clamped), the
    voxels trilinear interpolation reads for any sample inside the block. Returns two
    float32 arrays of shape ``ceil(n / block)`` per axis, in data units (from
    COMPILED_MIN_SIZE voxels on, a compiled kernel in the data's own dtype,
    :func:`voxwarp.render.skipping.kernels.block_range`).
    """
    if not _compiled(np.asarray(data).size):
        return skip_numpy.block_min_max(data, block)
    from voxwarp.render.skipping import kernels as skip_kernels  # numba: on first use

    t = _texture_order(data)
    nb = tuple(-(-n // block) for n in t.shape)
    lo = np.empty(nb, dtype=t.dtype)
    hi = np.empty(nb, dtype=t.dtype)
    if t.size:
        skip_kernels.block_range(t, block, lo, hi)
    return lo.T.astype(np.float32), hi.T.astype(np.float32)


def cell_min_max(data: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per trilinear cell (min, max) of its 8 corner voxels, shape ``n + 1`` per axis.

    Cell ``c`` covers texel coordinates ``[c - 1/2, c + 1/2]`` per axis, whose samples
    interpolate voxels ``c - 1`` and ``c`` (clamped to the edge). The data's dtype
    (integer ranges keep :meth:`TransferFunction.visible_ranges` on its fast path).
    Two full-size arrays: the renderer uses :func:`cell_visibility`, which keeps none.
    """
    if not _compiled(np.asarray(data).size):
        return skip_numpy.cell_min_max(data)
    return _cell_range_slab(_texture_order(data), 0, np.asarray(data).shape[2] + 1)


def _cell_range_slab(t: np.ndarray, z0: int, z1: int) -> tuple[np.ndarray, np.ndarray]:
    """(min, max) of the cells ``z0 .. z1`` (z) of texture-order data, (x, y, z)-indexed."""
    from voxwarp.render.skipping import kernels as skip_kernels  # numba: on first use

    shape = (z1 - z0, t.shape[1] + 1, t.shape[2] + 1)
    lo = np.empty(shape, dtype=t.dtype)
    hi = np.empty(shape, dtype=t.dtype)
    skip_kernels.cell_range(t, z0, lo, hi)
    return lo.T, hi.T


#: cells per slab of the generic (float data) path of :func:`cell_visibility`
_SLAB_CELLS = 1 << 22
#: integer data whose value range spans at most this many values uses a lookup table
_TABLE_VALUES = 1 << 17


def cell_visibility(
    scene: Scene, data: np.ndarray, block_min: np.ndarray, block_max: np.ndarray
) -> np.ndarray:
    """Which trilinear cells of ``data`` (n + 1 per axis) ``scene``'s mode can see.

    The same as ``static_block_visibility(scene, *cell_min_max(data))`` without the two
    full-size range arrays (from COMPILED_MIN_SIZE cells on; smaller volumes build
    them): integer data of at most 2 bytes goes through one compiled
    pass and a table of, per lower end ``lo`` of a cell's range, the lowest upper end
    that makes it visible (visibility only grows with the upper end, in every mode);
    other data is classified slab by slab. ``block_min``/``block_max`` (from
    :func:`block_min_max`) give the data's value range. Returns a bool array, a
    transposed view of a C-contiguous (z, y, x) array.
    """
    if not _compiled(np.prod(cell_grid_shape(np.shape(data)))):
        return static_block_visibility(scene, *cell_min_max(data))
    from voxwarp.render.skipping import kernels as skip_kernels  # numba: on first use

    t = _texture_order(data)
    out = np.empty((t.shape[0] + 1, t.shape[1] + 1, t.shape[2] + 1), dtype=bool)
    if t.size == 0:
        return out.T
    vmin, vmax = int(np.min(block_min)), int(np.max(block_max))
    if t.dtype.kind in "ui" and t.dtype.itemsize <= 2 and vmax - vmin < _TABLE_VALUES:
        first_hi = _first_visible_hi(scene, t.dtype, vmin, vmax)
        skip_kernels.cell_visibility_table(t, vmin, first_hi, out)
        return out.T
    step = max(1, _SLAB_CELLS // (out.shape[1] * out.shape[2]))
    for z0 in range(0, out.shape[0], step):
        z1 = min(z0 + step, out.shape[0])
        out[z0:z1] = static_block_visibility(scene, *_cell_range_slab(t, z0, z1)).T
    return out.T


def _first_visible_hi(scene: Scene, dtype: np.dtype, vmin: int, vmax: int) -> np.ndarray:
    """Per value ``lo`` in [vmin, vmax]: the lowest ``hi`` in [lo, vmax] for which a cell
    of range [lo, hi] is visible to ``scene``'s mode, or ``vmax + 1`` (int64; a binary
    search over :func:`static_block_visibility`, which is non-decreasing in ``hi``)."""
    lo = np.arange(vmin, vmax + 1, dtype=np.int64)
    left = lo.copy()  # the answer lies in [left, right]; right = vmax + 1 means never
    right = np.full_like(lo, vmax + 1)
    while np.any(left < right):
        mid = np.minimum((left + right) // 2, vmax)
        ok = static_block_visibility(scene, lo.astype(dtype), mid.astype(dtype))
        ok = np.asarray(ok, dtype=bool) & (left < right)
        right = np.where(ok, mid, right)
        left = np.where(ok | (left >= right), left, mid + 1)
    return right


def static_block_visibility(
    scene: Scene, block_min: np.ndarray, block_max: np.ndarray
) -> np.ndarray:
    """Blocks the scene's mode may need, from their value ranges alone (bool grid).

    dvr: the transfer function is non-zero somewhere in the block's range; mip: the
    block's maximum is above the window's low end; minip: its minimum is below the
    window's high end; iso / flm: its maximum reaches the isovalue / threshold;
    xray: its maximum is above the window's low end (values at or below it add nothing
    to the line integral); average: every block. (mip and minip also skip dynamically
    in the shader.)
    """
    mode = scene.mode
    level, width = scene.window
    if mode == "dvr":
        return _in_slabs(scene.transfer_function.visible_ranges, block_min, block_max)
    if mode in ("mip", "xray"):
        return block_max > level - width / 2
    if mode == "minip":
        return block_min < level + width / 2
    if mode == "iso":
        return block_max >= scene.resolved_iso_value()
    if mode == "flm":
        return block_max >= scene.resolved_flm_threshold()
    return np.ones(block_min.shape, dtype=bool)


#: blocks classified at a time by :func:`_in_slabs` (its int64 temporaries: 2 MiB each)
_SLAB_BLOCKS = 1 << 18


def _in_slabs(classify: Any, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``classify(lo, hi)`` (elementwise, bool) over slabs of z layers, so its temporaries
    are a slab's, not the grid's (a 512³ volume's 2M blocks: 64 MiB of int64 at once).
    Arrays other than 3D grids are classified at once."""
    if lo.ndim != 3:
        return classify(lo, hi)
    nx, ny, nz = lo.shape
    step = max(1, _SLAB_BLOCKS // max(1, nx * ny))
    if step >= nz:
        return classify(lo, hi)
    out = np.empty(lo.shape, dtype=bool, order="F")
    for z0 in range(0, nz, step):
        out[:, :, z0 : z0 + step] = classify(lo[:, :, z0 : z0 + step], hi[:, :, z0 : z0 + step])
    return out


def block_skip_distances(visible: np.ndarray) -> np.ndarray:
    """Chessboard distance (in blocks, capped at 255) from each block to a visible one.

    0 marks a visible block. A ray in a block at distance d may jump out of the cube of
    (2d - 1)³ blocks centred on it in one step: none of them is visible. Returns uint8
    (the visible set grown one chessboard step at a time; the blocks of a volume of
    COMPILED_MIN_SIZE voxels or more, a compiled chamfer transform: both exact).
    """
    visible = np.asarray(visible, dtype=bool)
    if not visible.any():
        return np.full(visible.shape, 255, dtype=np.uint8)
    if visible.all():
        return np.zeros(visible.shape, dtype=np.uint8)
    if not _compiled(visible.size * BLOCK**3):  # the blocks of a volume that large
        return skip_numpy.block_skip_distances(visible)
    from voxwarp.render.skipping import kernels as skip_kernels  # numba: on first use

    v = _texture_order(visible)
    d = np.empty(v.shape, dtype=np.int32)
    skip_kernels.chessboard_distance(v, d)
    return np.minimum(d, 255).astype(np.uint8).T


def skip_map_key(scene: Scene) -> tuple:
    """What the static block visibility of ``scene`` depends on (cache key)."""
    mode = scene.mode
    if mode == "dvr":
        return (mode, tf_key(scene.transfer_function))
    if mode in ("mip", "minip", "xray"):
        return (mode, scene.window)
    if mode == "iso":
        return (mode, scene.resolved_iso_value())
    if mode == "flm":
        return (mode, scene.resolved_flm_threshold())
    return (mode,)


def octant_skip_distances(
    visible: np.ndarray,
    signs: Octant,
    cell_cap: int = CELL_CAP,
    block: int = BLOCK,
    compiled: bool | None = None,
) -> np.ndarray:
    """Edge (in cells, capped at 255) of the largest invisible cube starting at each cell
    and extending in the direction ``signs``; 0 marks a visible cell.

    The cube of edge ``r`` at cell ``c`` covers cells ``c + s * [0, r - 1]`` per axis
    (s = ``signs``). It is exact up to ``cell_cap`` cells; beyond that it is the bound
    given by the block-level map (blocks of ``block`` cells, counted from the corner the
    rays start at, exact in blocks): the cube of ``R`` invisible blocks starting at the
    cell's block contains the cell's cube of edge ``R * block - max_i(offset of the cell
    in its block)``. Both are lower bounds of the true edge, so every jump stays inside
    invisible cells. Returns uint8 of ``visible``'s shape (a transposed view of a
    C-contiguous (z, y, x) array: the texture's layout).

    Each distance is a forward chessboard distance, built as three 1D passes
    ``min over 0 <= k < cap of max(k, g[c + s k])`` (max distributes over min, so the
    passes compose exactly); compiled, in place in the output
    (:mod:`voxwarp.render.skipping.kernels`), from COMPILED_MIN_SIZE cells on or where
    ``compiled`` says so, else in numpy (the same map).
    """
    visible = np.asarray(visible, dtype=bool)
    if visible.ndim != 3:
        raise ValueError(f"visible must be a 3D bool array; got shape {visible.shape}")
    if any(s not in (-1, 1) for s in signs) or len(signs) != 3:
        raise ValueError(f"signs must be three of +1/-1; got {signs}")
    cap = int(min(max(cell_cap, 1), 255))
    if not (_compiled(visible.size) if compiled is None else compiled):
        return skip_numpy.octant_skip_distances(visible, signs, cap, block)
    from voxwarp.render.skipping import kernels as kern  # numba: on first use

    v = _texture_order(visible)
    out = np.empty(v.shape, dtype=np.uint8)
    if v.size == 0:
        return out.T
    sz, sy, sx = (int(s) for s in reversed(tuple(signs)))
    kern.scan_z(v, sz, cap, out)
    kern.pass_y(out, sy, cap)
    kern.pass_x(out, sx, cap)
    # block level, in the frame where the rays run towards +x, +y, +z; block distances
    # beyond far_cap give a cell bound over 255 anyway: far_cap * block - (block - 1)
    # >= 255, so the capped block map loses nothing
    far_cap = min(-(-(255 + block - 1) // block), 255)
    maps = [_flipped_block_index(n, s, block) for n, s in zip(v.shape, (sz, sy, sx), strict=True)]
    far = np.zeros(tuple(-(-n // block) for n in v.shape), dtype=np.uint8)
    kern.flipped_blocks(v, maps[0][0], maps[1][0], maps[2][0], far)
    dist = np.empty_like(far)
    kern.scan_z(far, 1, far_cap, dist)
    kern.pass_y(dist, 1, far_cap)
    kern.pass_x(dist, 1, far_cap)
    kern.raise_to_block_bound(out, dist, *(m[0] for m in maps), *(m[1] for m in maps), block)
    return out.T


def _flipped_block_index(n: int, sign: int, block: int) -> tuple[np.ndarray, np.ndarray]:
    """Per cell index of an axis of ``n`` cells: its block and its offset in that block,
    counting from the end the rays start at (the last cell for ``sign`` -1)."""
    c = np.arange(n, dtype=np.int64)
    if sign < 0:
        c = n - 1 - c
    return c // block, c % block


def ray_direction_coefficients(inv_view_proj: np.ndarray, to_texel: np.ndarray) -> np.ndarray:
    """(3, 3) array ``A`` with texel-space ray direction ``du ~ A @ (x, y, 1)`` at NDC (x, y).

    The shader's ray runs from the unprojected near point to the far point; for
    perspective and orthographic projections both are affine in (x, y), so the
    direction (before normalisation, which keeps its signs) is too. ``to_texel`` is
    the 4x4 (deformed world -> texel) matrix, of which only the linear part matters.
    """
    inv = np.asarray(inv_view_proj, dtype=np.float64)
    lin = np.asarray(to_texel, dtype=np.float64)[:3, :3]

    def direction(x: float, y: float) -> np.ndarray:
        a = inv @ np.array([x, y, -1.0, 1.0])
        b = inv @ np.array([x, y, 1.0, 1.0])
        return lin @ (b[:3] / b[3] - a[:3] / a[3])

    d00, d10, d01 = direction(0.0, 0.0), direction(1.0, 0.0), direction(0.0, 1.0)
    return np.stack([d10 - d00, d01 - d00, d00], axis=1)


def _clip_polygon(poly: list[tuple[float, float]], a: float, b: float, c: float) -> list:
    """Sutherland-Hodgman: the part of convex ``poly`` where a*x + b*y + c >= 0."""
    out: list[tuple[float, float]] = []
    n = len(poly)
    for i in range(n):
        p, q = poly[i], poly[(i + 1) % n]
        fp, fq = a * p[0] + b * p[1] + c, a * q[0] + b * q[1] + c
        if fp >= 0:
            out.append(p)
        if (fp >= 0) != (fq >= 0):
            s = fp / (fp - fq)
            out.append((p[0] + s * (q[0] - p[0]), p[1] + s * (q[1] - p[1])))
    return out


def octant_regions(
    coefficients: np.ndarray, size: tuple[int, int], margin_px: float = 2.0
) -> list[tuple[Octant, list[tuple[float, float]]]]:
    """Convex NDC polygons, one per octant that some pixel's ray lies in.

    ``coefficients`` come from :func:`ray_direction_coefficients`; ``size`` is the
    viewport (width, height). Each polygon is the viewport square [-1, 1]² clipped to
    where the octant's direction signs hold, widened by ``margin_px`` pixels and by
    the ``OCTANT_EPS`` band so that it covers every pixel whose ray the shader (in
    float32) puts in that octant. The
    polygons overlap along their borders; the shader discards the pixels of other
    octants, so each pixel is drawn exactly once.
    """
    w, h = size
    px = np.array([2.0 / max(w, 1), 2.0 / max(h, 1)])
    coefficients = np.asarray(coefficients, dtype=np.float64)
    corners = np.array([[x, y, 1.0] for x in (-1.0, 1.0) for y in (-1.0, 1.0)])
    # largest |component| over the image (affine: at a corner) bounds the zero band
    du_max = float(np.max(np.abs(corners @ coefficients.T)))
    regions = []
    for sx in (1, -1):
        for sy in (1, -1):
            for sz in (1, -1):
                poly = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
                for s, (a, b, c) in zip((sx, sy, sz), coefficients, strict=True):
                    slack = (
                        margin_px * (abs(a) * px[0] + abs(b) * px[1])
                        + OCTANT_EPS * du_max
                        + 1e-9 * (abs(a) + abs(b) + abs(c))
                    )
                    poly = _clip_polygon(poly, s * a, s * b, s * c + slack)
                    if len(poly) < 3:
                        break
                if len(poly) >= 3:
                    regions.append(((sx, sy, sz), poly))
    return regions


def cell_grid_shape(volume_shape: Any) -> tuple[int, int, int]:
    """Trilinear cells per axis of a volume of ``volume_shape`` voxels (one more than
    voxels: cell ``c`` interpolates voxels ``c - 1`` and ``c``; see :func:`cell_min_max`)."""
    return tuple(int(n) + 1 for n in volume_shape)  # type: ignore[return-value]


def coarsen_visibility(visible: np.ndarray, factor: int = 2) -> np.ndarray:
    """Visibility of coarse cells of ``factor``³ trilinear cells: coarse cell ``C`` is
    visible when any of the cells ``C * factor + [0, factor - 1]`` per axis is (cells past
    the grid's end count as invisible, as beyond the volume). Shape ``ceil(n / factor)``
    per axis, a transposed view of a C-contiguous (z, y, x) array like ``visible``.

    An octant skip map of the coarse visibility (:func:`octant_skip_distances`) is a
    conservative map of the fine cells: the raycaster turns a coarse edge ``D`` at fine
    cell ``c`` into the fine edge ``D * factor - (offset of c in its coarse cell, from the
    corner the ray starts at)``, a cube inside the invisible coarse one.
    """
    visible = np.asarray(visible, dtype=bool)
    f = int(factor)
    if visible.ndim != 3 or f < 1:
        raise ValueError(f"need a 3D visibility and a factor >= 1; got {visible.shape}, {f}")
    v = visible.T  # texture order (z, y, x), no copy for the maps' own views
    out = np.zeros(tuple(-(-n // f) for n in v.shape), dtype=bool)
    for i in range(f):
        for j in range(f):
            for k in range(f):
                part = v[i::f, j::f, k::f]
                out[: part.shape[0], : part.shape[1], : part.shape[2]] |= part
    return out.T


def warped_cell_grid(
    cells: Any, spacing: Any, origin: Any, ray_lo: Any, ray_hi: Any
) -> tuple[np.ndarray, np.ndarray]:
    """(shape, offset) of the deformed-space cell grid of :func:`warped_cell_visibility`:
    the volume's ``cells`` per axis padded to cover the ray box ``[ray_lo, ray_hi]`` (mm),
    and the index of its cell 0 in the original cell grid (per axis, <= 0)."""
    sp = np.asarray(spacing, dtype=float)
    org = np.asarray(origin, dtype=float)
    n = np.asarray(cells, dtype=np.int64)
    # cells covering the ray box: texel u = (p - origin) / spacing + 1/2, cell floor(u + 1/2)
    with np.errstate(over="ignore", invalid="ignore"):
        c_lo = np.floor((np.asarray(ray_lo, float) - org) / sp + 1.0)
        c_hi = np.floor((np.asarray(ray_hi, float) - org) / sp + 1.0)
    big = float(2**40)  # a ray box beyond any texture: clipped so the ints stay exact
    c_lo = np.clip(np.nan_to_num(c_lo, nan=0.0), -big, big).astype(np.int64)
    c_hi = np.clip(np.nan_to_num(c_hi, nan=0.0), -big, big).astype(np.int64)
    pad_lo = np.maximum(-c_lo, 0)
    pad_hi = np.maximum(c_hi - (n - 1), 0)
    return n + pad_lo + pad_hi, -pad_lo


def warped_cell_visibility(
    visible: np.ndarray,
    spacing: Any,
    origin: Any,
    warps: Any,
    ray_lo: Any,
    ray_hi: Any,
    block: int = BLOCK,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Cell visibility in *deformed* space for a warp chain that bounds its displacement.

    A deformed-space point p samples the original volume at ``warp(p)``, and
    ``warp(p) - p`` lies in an interval ``[a, b]`` per axis
    (:meth:`voxwarp.deform.warp.Warp.displacement_range`, per block of ``block``³ cells). So a
    deformed-space cell c can show something only if a visible original cell lies in
    the box ``c + [floor(a / spacing), ceil(b / spacing)]``: the deformed visibility is
    the original one spread by a window that follows the local displacement. A smooth
    field that moves a region by ~d reads it through a window around -d one to two
    cells wide, instead of a ball of radius d; cells where nothing moves keep their
    original visibility. Each cell of a moved block is tested exactly with a
    summed-area table. Octant skip maps built on this grid
    (:func:`octant_skip_distances`) let warped rays jump through deformed space as
    straight rays do through the original, without changing the image.

    Parameters
    ----------
    visible
        Original-space cell visibility (n + 1 per axis, cell c centred on texel c).
    spacing, origin
        The volume's voxel spacing and origin (mm).
    warps
        The warp chain (deformed -> original).
    ray_lo, ray_hi
        Deformed-space box the rays march in (mm); the grid is padded to cover it.
    block
        Cells per block edge of the displacement intervals.

    Returns
    -------
    (visible_deformed, offset) or None
        Boolean grid of deformed-space cells and the index of its cell 0 in the
        original cell grid (per axis, <= 0; a deformed point with texel coordinate u
        lies in cell ``floor(u + 1/2) - offset``); ``None`` when a warp of the chain
        gives no interval (e.g. a GPU-owned field).
    """
    visible = np.asarray(visible, dtype=bool)
    sp = np.asarray(spacing, dtype=float)
    org = np.asarray(origin, dtype=float)
    n = np.asarray(visible.shape)
    shape, offset = warped_cell_grid(visible.shape, spacing, origin, ray_lo, ray_hi)
    pad_lo = -offset
    # displacement interval per block of cells (boxes in deformed world mm)
    nb = -(-shape // block)
    idx = np.stack(np.meshgrid(*(np.arange(k) for k in nb), indexing="ij"), -1).reshape(-1, 3)
    first = idx * block + offset  # original cell index of each block's first cell
    box_lo = org + (first - 1.0) * sp  # cell c spans texels [c - 1/2, c + 1/2]
    box_hi = org + (first + block - 1.0) * sp
    rng = chain_displacement_range(warps, box_lo, box_hi)
    if rng is None:
        return None
    big = float(shape.max())
    # p in cell c: texel of warp(p) in [c - 1/2 + a, c + 1/2 + b], its cell in
    # [c + floor(a), c + ceil(b)] (a, b in texels)
    d_lo = np.clip(np.floor(np.asarray(rng[0], float) / sp), -big, big).astype(np.int64)
    d_hi = np.clip(np.ceil(np.asarray(rng[1], float) / sp), -big, big).astype(np.int64)
    d_lo, d_hi = d_lo.reshape(*nb, 3), d_hi.reshape(*nb, 3)
    out = np.zeros(tuple(shape), dtype=bool)
    inner = tuple(slice(pad_lo[a], pad_lo[a] + n[a]) for a in range(3))
    out[inner] = visible
    moved = np.argwhere(np.any((d_lo != 0) | (d_hi != 0), axis=-1))
    if len(moved) == 0 or not visible.any():
        return out, offset
    # the box [q0, q1) of cells every window of a moved block lies in (a local drag's
    # is a part of the grid), and the summed-area table of the padded visibility over
    # it: sat[i, j, k] = visible cells of [q0, q0 + (i, j, k)), summed in place
    blo = d_lo[moved[:, 0], moved[:, 1], moved[:, 2]]
    bhi = d_hi[moved[:, 0], moved[:, 1], moved[:, 2]]
    q0 = np.clip((moved * block + blo).min(axis=0), 0, shape)
    q1 = np.maximum(np.clip((moved * block + block + bhi).max(axis=0), 0, shape), q0)
    sat = np.zeros(tuple(q1 - q0 + 1), dtype=np.int32)
    core = sat[1:, 1:, 1:]
    core[...] = out[q0[0] : q1[0], q0[1] : q1[1], q0[2] : q1[2]]
    for axis in range(3):
        np.cumsum(core, axis=axis, out=core)

    def count_visible(lo_cell: np.ndarray, hi_cell: np.ndarray) -> np.ndarray:
        """Visible cells in the boxes [lo_cell, hi_cell) (clipped to the grid)."""
        a, b = np.clip(lo_cell, q0, q1) - q0, np.clip(hi_cell, q0, q1) - q0
        b = np.maximum(a, b)
        count = np.zeros(len(a), dtype=np.int64)
        for corner in range(8):
            pick = [(corner >> ax) & 1 for ax in range(3)]
            ix = [b[:, ax] if pick[ax] else a[:, ax] for ax in range(3)]
            count += (-1 if (3 - sum(pick)) % 2 else 1) * sat[ix[0], ix[1], ix[2]]
        return count

    # a moved block's window (the union of its cells' windows): where it holds no
    # visible cell, the block's cells see nothing; where every one of its cells is
    # visible and it lies within the grid, each cell's window (a non-empty part of it)
    # sees something. Only the blocks in between are counted cell by cell.
    w_lo, w_hi = moved * block + blo, moved * block + block + bhi
    seen = count_visible(w_lo, w_hi)
    inside = np.all((w_lo >= 0) & (w_hi <= shape), axis=1)
    ordered = np.all(bhi >= blo, axis=1)  # (every cell's window holds a cell)
    full = inside & ordered & (seen == np.prod(w_hi - w_lo, axis=1))
    _set_blocks(out, moved[seen == 0], block, False)
    _set_blocks(out, moved[full], block, True)
    moved = moved[(seen > 0) & ~full]
    if len(moved) and out.size >= WARPED_COMPILED_MIN_SIZE:  # numba: the same counts
        from voxwarp.render.skipping import kernels as kern

        lo_off = d_lo[moved[:, 0], moved[:, 1], moved[:, 2]]
        hi_off = d_hi[moved[:, 0], moved[:, 1], moved[:, 2]]
        kern.window_cells(out, sat, q0, q1, moved, lo_off, hi_off, block)
        return out, offset
    local = np.stack(np.meshgrid(*(np.arange(block),) * 3, indexing="ij"), -1).reshape(-1, 3)
    for chunk in np.array_split(moved, max(1, len(moved) // 4096)) if len(moved) else []:
        cells = (chunk[:, None, :] * block + local[None]).reshape(-1, 3)
        lo_off = np.repeat(d_lo[chunk[:, 0], chunk[:, 1], chunk[:, 2]], len(local), axis=0)
        hi_off = np.repeat(d_hi[chunk[:, 0], chunk[:, 1], chunk[:, 2]], len(local), axis=0)
        keep = np.all(cells < shape, axis=1)
        cells, lo_off, hi_off = cells[keep], lo_off[keep], hi_off[keep]
        count = count_visible(cells + lo_off, cells + hi_off + 1)
        out[cells[:, 0], cells[:, 1], cells[:, 2]] = count > 0
    return out, offset


def _set_blocks(out: np.ndarray, blocks: np.ndarray, block: int, value: bool) -> None:
    """Set every cell of the ``block``³ blocks (block indices, (n, 3)) of ``out``."""
    if len(blocks) == 0:
        return
    nb = -(-np.asarray(out.shape) // block)
    mask = np.zeros(tuple(nb), dtype=bool)
    mask[tuple(blocks.T)] = True
    for axis in range(3):  # blocks -> cells
        mask = np.repeat(mask, block, axis=axis)
    mask = mask[: out.shape[0], : out.shape[1], : out.shape[2]]
    out[mask] = value
