"""2D slice images of a deformation's internal fields (the GUI's field view; no Qt here).

About the views
---------------
The raycaster never shows what a warp computes per sample; these views do, on an
axis-aligned plane through the volume, as an RGB image:

* wires (:class:`~voxwarp.deform.wires.field.WireFieldWarp`): the attribute field
  (:meth:`~voxwarp.deform.wires.field.WireField.decode`), sampled at the nearest field voxel as the
  shader decides a sample's state (field voxel ``i`` covers
  ``[lo + i h, lo + (i + 1) h)``, ``lo`` / ``h`` the field's own box corner and
  spacing, ``field_scale`` times the volume's):

  - ``"attribute t"``: the arc-length fraction u = t / 255 of swept voxels through
    viridis (0 dark purple, 1 yellow); vacated voxels dark grey, the rest black;
  - ``"wire id"``: the wire of swept voxels in categorical colours;
  - ``"swept / vacated"``: the sweep flags (the paper's plane masks carried into the
    field): swept orange, vacated blue, identity dark.

* offset fields (:class:`~voxwarp.deform.elements.offset_field.OffsetFieldWarp`, mass-spring and
  ChainMail): ``"offset |d|"``, the length of the node displacement field ``u(X)``
  interpolated trilinearly onto the pixels (original space, 0 outside the grid box).

* displacement fields read from files
  (:class:`~voxwarp.deform.fields.displacement.DisplacementFieldWarp`, any warp with a
  ``displacement_at(points)``): ``"field |u|"``, the length of the field's vector
  ``u(p)`` at the pixels' world points (trilinear on the field's own grid, 0 beyond
  half a node outside it), in mm.

* every warp: ``"displacement"``, ``|w(p) - p|`` of the inverse map ``w`` the raycaster
  samples through (:meth:`~voxwarp.deform.warp.Warp.apply`) on a coarser grid
  (:data:`DISPLACEMENT_PIXELS` across); pixels that show nothing (a wire's vacated
  place, outside a lattice that left its box) are dark red.

Scalar views are scaled to the slice's own maximum, which the legend states. The image's
rows run from the top (largest second in-plane coordinate) down; its columns along the
first in-plane axis: (y, z) for an x slice, (x, z) for y, (x, y) for z.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from voxwarp.deform.elements.offset_field import OffsetFieldWarp, texture_field
from voxwarp.deform.warp import WarpError
from voxwarp.deform.wires.field import FAR, LUT_SIZE
from voxwarp.errors import VoxwarpError

#: views per warp kind (``warp.kind``); other warps get :data:`GENERIC_VIEWS`
VIEWS: dict[str, tuple[str, ...]] = {
    "wires": ("attribute t", "wire id", "swept / vacated", "displacement"),
    "offset_field": ("offset |d|", "displacement"),
    "lattice": ("displacement",),
    "displacement_field": ("field |u|", "displacement"),
}
#: views of any warp (through its CPU reference :meth:`~voxwarp.deform.warp.Warp.apply`)
GENERIC_VIEWS: tuple[str, ...] = ("displacement",)
#: names of the slice normals 0, 1, 2
AXES: tuple[str, ...] = ("x", "y", "z")
#: pixels across the ``"displacement"`` view (``warp.apply`` per pixel: Newton steps for
#: a lattice, fixed-point steps for an offset field)
DISPLACEMENT_PIXELS = 128
#: largest ``max_pixels`` accepted
MAX_PIXELS = 2048
#: displacements at least this long (mm) mean "shows nothing" (a point sent far away)
NOWHERE_MM = 1.0e6
#: lengths below this (mm) are float noise and shown as 0 (an identity lattice's inverse
#: is exact only to ~1e-14 mm)
TINY_MM = 1.0e-6
#: fixed-point steps of the ``"displacement"`` view of a baked offset field (the CPU bake
#: of :meth:`~voxwarp.deform.elements.offset_field.OffsetFieldWarp.baked_inverse` takes seconds on
#: big
#: grids; 8 plain steps are within ~0.1 % of a node spacing of it for unfolded fields)
OFFSET_STEPS = 8

#: viridis at 10 equally spaced values (matplotlib's ``viridis(10)``)
VIRIDIS = np.array(
    [
        (68, 1, 84),
        (72, 40, 120),
        (62, 73, 137),
        (49, 104, 142),
        (38, 130, 142),
        (31, 158, 137),
        (53, 183, 121),
        (110, 206, 88),
        (181, 222, 43),
        (253, 231, 37),
    ],
    dtype=np.float64,
)
#: categorical colours of wire ids (id modulo 10) and their names for the legend
WIRE_COLORS: tuple[tuple[str, tuple[int, int, int]], ...] = (
    ("blue", (31, 119, 180)),
    ("orange", (255, 127, 14)),
    ("green", (44, 160, 44)),
    ("red", (214, 39, 40)),
    ("purple", (148, 103, 189)),
    ("brown", (140, 86, 75)),
    ("pink", (227, 119, 194)),
    ("yellow", (229, 196, 0)),
    ("olive", (188, 189, 34)),
    ("cyan", (23, 190, 207)),
)
SWEPT_COLOR = (255, 150, 30)
VACATED_COLOR = (40, 140, 255)
IDENTITY_COLOR = (25, 25, 25)
#: vacated voxels in the attribute t / wire id views
VACATED_GREY = (70, 70, 70)
#: pixels that show nothing in the displacement view
NOWHERE_COLOR = (150, 0, 40)


class FieldViewError(VoxwarpError, ValueError):
    """A field view cannot be made (bad view, axis or position; a field not on the CPU)."""


@dataclass
class FieldSlice:
    """One slice image of a field.

    Attributes
    ----------
    image : numpy.ndarray
        ``(H, W, 3)`` uint8 RGB; row 0 is the top (largest second in-plane coordinate).
    title : str
        What is shown and where, e.g. ``"attribute t, z = 64.0 mm"``.
    legend : str
        How to read the colours, e.g. ``"|d| 0 (dark) .. 12.3 mm (yellow)"``.
    extent : tuple of float
        World mm of the image's left, right, bottom and top edges.
    """

    image: np.ndarray
    title: str
    legend: str
    extent: tuple[float, float, float, float]


def views_for(warp: Any) -> tuple[str, ...]:
    """The views :func:`field_slice` offers for ``warp``.

    Parameters
    ----------
    warp
        A warp (as in ``session.scene.warps``; for the editor
        :meth:`voxwarp.editing.session.EditSession.model_warp`), or ``None``.

    Returns
    -------
    tuple of str
        ``VIEWS[warp.kind]``, :data:`GENERIC_VIEWS` for other warps, ``()`` for None.
    """
    if warp is None:
        return ()
    return VIEWS.get(str(getattr(warp, "kind", "")), GENERIC_VIEWS)


def _in_plane(axis: int) -> tuple[int, int]:
    """The image's horizontal and vertical world axes for a slice normal to ``axis``."""
    return ((1, 2), (0, 2), (0, 1))[axis]


def _check(warp: Any, view: Any, axis: Any, fraction: Any, max_pixels: Any) -> float:
    if warp is None:
        raise FieldViewError("no deformation: there is no field to show")
    views = views_for(warp)
    if not isinstance(view, str) or view not in views:
        raise FieldViewError(
            f"view must be one of {', '.join(repr(v) for v in views)} for a"
            f" {getattr(warp, 'kind', type(warp).__name__)!s} warp; got {view!r}"
        )
    if isinstance(axis, bool) or not isinstance(axis, int | np.integer) or axis not in (0, 1, 2):
        raise FieldViewError(f"axis must be 0, 1 or 2 (slice normal x, y or z); got {axis!r}")
    try:
        f = float(fraction)
    except (TypeError, ValueError) as exc:
        raise FieldViewError(
            f"fraction must be a number in [0, 1] across the volume; got {fraction!r}"
        ) from exc
    if not (math.isfinite(f) and 0.0 <= f <= 1.0):
        raise FieldViewError(f"fraction must be in [0, 1] across the volume; got {fraction!r}")
    if (
        isinstance(max_pixels, bool)
        or not isinstance(max_pixels, int | np.integer)
        or not 2 <= max_pixels <= MAX_PIXELS
    ):
        raise FieldViewError(f"max_pixels must be an integer 2..{MAX_PIXELS}; got {max_pixels!r}")
    return f


def _extent(warp: Any, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The volume's box joined with the warp's deformed box (a bent object may leave
    the volume's box)."""
    try:
        dlo, dhi = warp.deformed_bounds(lo, hi)
        dlo, dhi = np.asarray(dlo, dtype=np.float64), np.asarray(dhi, dtype=np.float64)
    except (WarpError, VoxwarpError, AttributeError, TypeError, ValueError):
        return lo, hi
    if dlo.shape != (3,) or dhi.shape != (3,) or not np.all(np.isfinite(dlo + dhi)):
        return lo, hi
    return np.minimum(lo, dlo), np.maximum(hi, dhi)


def _pixel_grid(
    lo: np.ndarray, hi: np.ndarray, axis: int, position: float, pixels: int
) -> np.ndarray:
    """``(H, W, 3)`` world points at the pixel centres of the slice; row 0 on top."""
    a, b = _in_plane(axis)
    w, h = float(hi[a] - lo[a]), float(hi[b] - lo[b])
    size = max(w, h) / pixels
    nw = max(1, min(pixels, round(w / size)))
    nh = max(1, min(pixels, round(h / size)))
    xs = lo[a] + (np.arange(nw) + 0.5) * (w / nw)
    ys = hi[b] - (np.arange(nh) + 0.5) * (h / nh)
    pts = np.empty((nh, nw, 3))
    pts[..., axis] = position
    pts[..., a] = xs[None, :]
    pts[..., b] = ys[:, None]
    return pts


def colormap(values: np.ndarray) -> np.ndarray:
    """Viridis colours (uint8 RGB, shape ``values.shape + (3,)``) of values in [0, 1]
    (clipped; NaN as 0)."""
    v = np.nan_to_num(np.clip(np.asarray(values, dtype=np.float64), 0.0, 1.0))
    keys = np.linspace(0.0, 1.0, len(VIRIDIS))
    out = np.stack([np.interp(v, keys, VIRIDIS[:, c]) for c in range(3)], axis=-1)
    return np.rint(out).astype(np.uint8)


def _scalar_image(mag: np.ndarray) -> tuple[np.ndarray, float]:
    """Viridis image of non-negative values scaled to their maximum, and that maximum
    (values below :data:`TINY_MM` count as 0)."""
    mag = np.where(mag < TINY_MM, 0.0, mag)
    top = float(mag.max()) if mag.size else 0.0
    scaled = mag / top if top > 0 else np.zeros_like(mag)
    return colormap(scaled), top


def _mm(value: float) -> str:
    return f"{value:.3g}"


# ---------------------------------------------------------------------- offset fields
def _offset_nodes(warp: OffsetFieldWarp, ctx: Any) -> np.ndarray:
    """The ``(nx, ny, nz, 3)`` node field: the CPU field, or a GPU field read back from
    its texture on ``ctx`` (current)."""
    if not warp.gpu_owned:
        return warp.displacements
    if ctx is None:
        raise FieldViewError(
            "this offset field lives on the GPU: the field view needs the OpenGL context"
            " to read it back (pass ctx, with the context current)"
        )
    try:
        tex = warp.textures(ctx)["displacement"]
    except (WarpError, VoxwarpError, KeyError) as exc:
        raise FieldViewError(f"cannot read the GPU offset field back: {exc}") from exc
    nodes = texture_field(tex, warp.shape)
    if nodes is None:
        raise FieldViewError(
            "cannot read the GPU offset field back: its texture is not an RGBA16F array of"
            f" {warp.shape} nodes"
        )
    return nodes


def _cpu_offset_warp(warp: OffsetFieldWarp, ctx: Any) -> OffsetFieldWarp:
    """A CPU warp of the same field whose :meth:`apply` needs no CPU bake: the warp itself
    for ``"approx"`` / ``"exact"`` CPU fields, else :data:`OFFSET_STEPS` fixed-point
    steps on the (read-back) nodes."""
    if not warp.gpu_owned and warp.inverse != "baked":
        return warp
    nodes = _offset_nodes(warp, ctx)
    steps = max(OFFSET_STEPS, warp.steps)
    return OffsetFieldWarp(warp.lo, warp.hi, nodes, inverse="exact", iterations=steps)


def _offset_view(warp: Any, pts: np.ndarray, ctx: Any) -> tuple[np.ndarray, str]:
    if not isinstance(warp, OffsetFieldWarp):
        raise FieldViewError(f"'offset |d|' needs an offset-field warp; got {type(warp).__name__}")
    nodes = _offset_nodes(warp, ctx)
    cpu = warp if not warp.gpu_owned else OffsetFieldWarp(warp.lo, warp.hi, nodes)
    d = cpu.offset(pts.reshape(-1, 3))
    mag = np.sqrt(np.sum(d * d, axis=-1)).reshape(pts.shape[:2])
    image, top = _scalar_image(mag)
    whole = float(np.sqrt(np.max(np.sum(nodes * nodes, axis=-1)))) if nodes.size else 0.0
    legend = f"|d| 0 (dark) .. {_mm(top)} mm (yellow); whole field max {_mm(whole)} mm"
    return image, legend


# ---------------------------------------------------------------------- field |u|
def _field_magnitude_view(warp: Any, pts: np.ndarray) -> tuple[np.ndarray, str]:
    """``|u(p)|`` of a warp with ``displacement_at`` (sampled at the pixels' world points:
    the field has its own, maybe rotated, grid)."""
    sample = getattr(warp, "displacement_at", None)
    if not callable(sample):
        raise FieldViewError(f"'field |u|' needs a displacement field; got {type(warp).__name__}")
    try:
        u = np.asarray(sample(pts.reshape(-1, 3)), dtype=np.float64)
    except (WarpError, VoxwarpError) as exc:
        raise FieldViewError(f"cannot sample the displacement field: {exc}") from exc
    mag = np.sqrt(np.sum(u * u, axis=-1)).reshape(pts.shape[:2])
    image, top = _scalar_image(mag)
    legend = f"|u| 0 (dark) .. {_mm(top)} mm (yellow)"
    whole = getattr(warp, "max_displacement", None)
    if callable(whole):
        legend += f"; whole field max {_mm(float(whole()))} mm"
    return image, legend


# ---------------------------------------------------------------------- any warp
def _displacement_view(warp: Any, pts: np.ndarray, ctx: Any) -> tuple[np.ndarray, str]:
    flat = pts.reshape(-1, 3)
    source = _cpu_offset_warp(warp, ctx) if isinstance(warp, OffsetFieldWarp) else warp
    try:
        q = np.asarray(source.apply(flat), dtype=np.float64)
    except (WarpError, VoxwarpError) as exc:
        raise FieldViewError(f"cannot evaluate the warp on the CPU: {exc}") from exc
    d = np.sqrt(np.sum((q - flat) ** 2, axis=-1))
    nowhere = ~np.isfinite(d) | (d >= NOWHERE_MM) | np.any(np.abs(q) >= 0.5 * FAR, axis=-1)
    mag = np.where(nowhere, 0.0, d).reshape(pts.shape[:2])
    image, top = _scalar_image(mag)
    nowhere = nowhere.reshape(pts.shape[:2])
    image[nowhere] = NOWHERE_COLOR
    legend = f"|w(p) - p| 0 (dark) .. {_mm(top)} mm (yellow)"
    if nowhere.any():
        legend += "; dark red: shows nothing"
    return image, legend


# ---------------------------------------------------------------------- wires
def _wire_samples(warp: Any, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(state, wire, u) at the points from the nearest field voxel: state 0 identity (and
    outside the field), 1 vacated, 2 swept; u = t / (LUT_SIZE - 1) in [0, 1]."""
    try:
        fld = warp.field
    except (WarpError, VoxwarpError) as exc:
        raise FieldViewError(f"the wire field is not available: {exc}") from exc
    state_f, wire_f, t_f = fld.decode()
    flat = pts.reshape(-1, 3)
    g = np.floor((flat - np.asarray(fld.lo)) / np.asarray(fld.spacing)).astype(np.int64)
    shape = np.asarray(fld.shape)
    inside = np.all((g >= 0) & (g < shape), axis=1)
    gi = g[inside]
    state = np.zeros(len(flat), dtype=np.uint8)
    wire = np.zeros(len(flat), dtype=np.int64)
    u = np.zeros(len(flat))
    state[inside] = state_f[gi[:, 0], gi[:, 1], gi[:, 2]]
    wire[inside] = wire_f[gi[:, 0], gi[:, 1], gi[:, 2]]
    u[inside] = np.asarray(t_f[gi[:, 0], gi[:, 1], gi[:, 2]], dtype=np.float64) / (LUT_SIZE - 1)
    hw = pts.shape[:2]
    return state.reshape(hw), wire.reshape(hw), np.clip(u, 0.0, 1.0).reshape(hw)


def _wire_names(warp: Any) -> list[str]:
    try:
        return [w.name for w in warp.wires]
    except (WarpError, VoxwarpError, AttributeError):
        return []


def _wire_view(warp: Any, view: str, pts: np.ndarray) -> tuple[np.ndarray, str]:
    state, wire, u = _wire_samples(warp, pts)
    swept, vacated = state == 2, state == 1
    image = np.zeros((*state.shape, 3), dtype=np.uint8)
    if view == "attribute t":
        image[swept] = colormap(u[swept])
        image[vacated] = VACATED_GREY
        legend = "t: 0 (dark) .. 1 (yellow) along the wire; grey: vacated; black: no wire"
        if swept.any():
            legend += f"; here {u[swept].min():.2f} .. {u[swept].max():.2f}"
        return image, legend
    if view == "wire id":
        palette = np.array([c for _, c in WIRE_COLORS], dtype=np.uint8)
        image[swept] = palette[wire[swept] % len(palette)]
        image[vacated] = VACATED_GREY
        names = _wire_names(warp)
        shown = []
        for wi in np.unique(wire[swept])[:6]:
            label = names[wi] if wi < len(names) and names[wi] else f"wire {wi + 1}"
            shown.append(f"{WIRE_COLORS[int(wi) % len(WIRE_COLORS)][0]}: {label}")
        legend = "; ".join(shown) if shown else "no swept voxels here"
        return image, legend + "; grey: vacated"
    image[:] = IDENTITY_COLOR
    image[swept] = SWEPT_COLOR
    image[vacated] = VACATED_COLOR
    pct = 100.0 / max(state.size, 1)
    legend = (
        f"orange: swept ({swept.sum() * pct:.0f} %), blue: vacated"
        f" ({vacated.sum() * pct:.0f} %), dark: identity"
    )
    return image, legend


# ---------------------------------------------------------------------- entry point
TITLES: dict[str, str] = {
    "attribute t": "attribute t",
    "wire id": "wire id",
    "swept / vacated": "swept / vacated",
    "offset |d|": "offset |d|",
    "field |u|": "displacement field |u|",
    "displacement": "displacement |w(p) - p|",
}


def field_slice(
    warp: Any,
    volume: Any,
    view: str,
    axis: int,
    fraction: float,
    max_pixels: int = 256,
    *,
    ctx: Any = None,
) -> FieldSlice:
    """A slice image of one of ``warp``'s fields (see the module docstring).

    Parameters
    ----------
    warp
        The warp (for the editor, :meth:`voxwarp.editing.session.EditSession.model_warp`: the model
        warp in the grid frame, without a placement's affine warps).
    volume
        The volume (its ``bounds`` place the slice).
    view
        One of :func:`views_for` ``(warp)``.
    axis
        Slice normal: 0 (x), 1 (y) or 2 (z).
    fraction
        Position of the slice across the volume's box along ``axis``, in [0, 1].
    max_pixels
        Pixels across the longer side of the image (the ``"displacement"`` view uses at
        most :data:`DISPLACEMENT_PIXELS`).
    ctx
        The moderngl context (current) to read a GPU-owned offset field back from;
        unused otherwise.

    Returns
    -------
    FieldSlice
        The image over the volume's box joined with the warp's deformed box, its title,
        legend and extent.

    Raises
    ------
    FieldViewError
        For a bad view, axis, fraction or ``max_pixels`` (the message names the allowed
        values), or a field that cannot be read.
    """
    f = _check(warp, view, axis, fraction, max_pixels)
    axis = int(axis)
    try:
        lo, hi = (np.asarray(v, dtype=np.float64).reshape(3) for v in volume.bounds)
    except (AttributeError, TypeError, ValueError) as exc:
        raise FieldViewError(
            f"volume must have bounds (lo, hi) in mm; got {type(volume).__name__}"
        ) from exc
    position = float(lo[axis] + f * (hi[axis] - lo[axis]))
    elo, ehi = _extent(warp, lo, hi)
    pixels = int(max_pixels)
    if view == "displacement":
        pixels = min(pixels, DISPLACEMENT_PIXELS)
    pts = _pixel_grid(elo, ehi, axis, position, pixels)
    if view == "offset |d|":
        image, legend = _offset_view(warp, pts, ctx)
    elif view == "field |u|":
        image, legend = _field_magnitude_view(warp, pts)
    elif view == "displacement":
        image, legend = _displacement_view(warp, pts, ctx)
    else:
        image, legend = _wire_view(warp, view, pts)
    a, b = _in_plane(axis)
    extent = (float(elo[a]), float(ehi[a]), float(elo[b]), float(ehi[b]))
    title = f"{TITLES[view]}, {AXES[axis]} = {position:.1f} mm"
    return FieldSlice(np.ascontiguousarray(image), title, legend, extent)


def pixel_of(fs: FieldSlice, point: Sequence[float], axis: int) -> tuple[int, int]:
    """``(row, column)`` of the pixel of ``fs`` holding a world point (mm) of its plane.

    Parameters
    ----------
    fs
        A slice from :func:`field_slice`.
    point
        World point (x, y, z) in mm; its coordinate along ``axis`` is ignored.
    axis
        The slice normal ``fs`` was made with.
    """
    a, b = _in_plane(axis)
    h, w = fs.image.shape[:2]
    left, right, bottom, top = fs.extent
    col = int(np.clip((float(point[a]) - left) / (right - left) * w, 0, w - 1))
    row = int(np.clip((top - float(point[b])) / (top - bottom) * h, 0, h - 1))
    return row, col
