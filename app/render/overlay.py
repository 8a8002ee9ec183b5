"""Editing handles drawn over a rendered frame (moderngl, no Qt).

About this pass
---------------
An editor shows what it edits on top of the volume: elements and control points as
points, springs / links between elements, wires (polylines), lattice cell edges and the
clipping box as line segments. :class:`OverlayRenderer` draws such
:class:`OverlayLayer` batches, in world coordinates (mm), with the raycaster's
:class:`~voxwarp.core.camera.Camera`, into a framebuffer it is given; the GUI calls it right after
:meth:`voxwarp.render.raycaster.Renderer.draw` on the same framebuffer and viewport.

* Handles are drawn on top: no depth test, premultiplied "over" blending (the raycaster
  writes premultiplied colour), in the order of the layers (later layers on top).
* Points are round discs of ``size`` pixels (``gl_PointSize`` sprites, discarded outside
  the disc through ``gl_PointCoord``) with a dark ring :data:`OUTLINE_WIDTH` pixel wide
  around them, so they read on bright volumes as well as on the background.
* Lines are 1 pixel wide (core profile); consecutive pairs of positions are segments.
  Per-vertex colours are interpolated along each segment.
* Handles are not clipped by the camera's near and far planes (whose range only covers
  the scene sphere); in perspective, what lies behind the eye is clipped.
* All layers of a frame go into one vertex buffer (float32 positions, RGBA8 colours,
  16 bytes per vertex) that is kept and orphaned from frame to frame; it grows to the
  next power of two when a frame needs more.

:func:`polyline_segments`, :func:`grid_edges` and :func:`box_edges` build the segment
pairs of ``"lines"`` layers from wires, node grids (lattices, mass-spring elements)
and boxes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from voxwarp import shaders
from voxwarp.core.camera import Camera
from voxwarp.deform import gl_programs
from voxwarp.errors import RenderError

#: Layer kinds: ``"points"`` or ``"lines"`` (consecutive pairs of positions).
KINDS: tuple[str, ...] = ("points", "lines")
#: Straight RGBA of the ring around points (its alpha is scaled by the point's).
OUTLINE_COLOR = (0.05, 0.05, 0.05, 1.0)
#: Width of the ring around points, in pixels.
OUTLINE_WIDTH = 1.0
#: Smallest vertex buffer made (bytes); buffers grow by powers of two.
MIN_BUFFER_BYTES = 1 << 16

#: One vertex as uploaded: world position (float32) and straight RGBA8 colour.
_VERTEX = np.dtype([("position", "<f4", (3,)), ("color", "u1", (4,))])
_VERTEX_FORMAT = "3f 4f1"


@dataclass
class OverlayLayer:
    """One batch of handles.

    Parameters
    ----------
    kind
        ``"points"`` or ``"lines"``; for lines, consecutive pairs of positions are
        segments (see :func:`polyline_segments`, :func:`grid_edges`, :func:`box_edges`).
    positions
        (N, 3) world points in mm; N may be 0 (the layer is skipped).
    colors
        Straight RGBA in [0, 1]: one (4,) colour for the layer or (N, 4), one per point
        (drawn with 8 bits per channel).
    size
        Diameter in pixels of the coloured disc of each point (the dark outline ring
        lies outside it); ignored for lines.
    name
        A label for error messages and the GUI.

    Raises
    ------
    RenderError
        When a field is invalid (see :meth:`validated`); layers are checked again when
        drawn, so fields may be replaced between frames.
    """

    kind: Literal["points", "lines"]
    positions: np.ndarray
    colors: np.ndarray | tuple
    size: float = 6.0
    name: str = ""

    def __post_init__(self) -> None:
        self.validated()

    def validated(self, label: str | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Check the layer and return its positions and colours as arrays.

        Parameters
        ----------
        label
            How error messages name the layer; default ``overlay layer 'NAME'``.

        Returns
        -------
        positions : numpy.ndarray
            (N, 3) real array (not copied when ``positions`` already is one).
        colors : numpy.ndarray
            (4,) or (N, 4) float64 RGBA in [0, 1].

        Raises
        ------
        RenderError
            Unknown kind, positions not (N, 3) real and finite, an odd number of line
            positions, colours not (4,) or (N, 4) finite values in [0, 1], or a size
            that is not positive and finite.
        """
        what = label or (f"overlay layer {self.name!r}" if self.name else "overlay layer")
        if self.kind not in KINDS:
            raise RenderError(
                f"{what}: kind must be one of {', '.join(map(repr, KINDS))}; got {self.kind!r}"
            )
        pos = _points_array(self.positions, f"{what}: positions")
        n = len(pos)
        if self.kind == "lines" and n % 2:
            raise RenderError(
                f"{what}: a lines layer takes pairs of positions (segment ends), so an even"
                f" count; got {n}. Build the pairs with polyline_segments(), grid_edges()"
                " or box_edges()"
            )
        try:
            col = np.asarray(self.colors, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise RenderError(
                f"{what}: colors must be numbers (RGBA in [0, 1]); got {self.colors!r:.80}"
            ) from exc
        if col.shape != (4,) and not (col.ndim == 2 and col.shape[1] == 4):
            hint = " (add alpha: RGBA)" if col.shape[-1:] == (3,) else ""
            raise RenderError(
                f"{what}: colors must be one RGBA colour (4,) or one per point (N, 4);"
                f" got shape {col.shape}{hint}"
            )
        if col.ndim == 2 and len(col) != n:
            raise RenderError(
                f"{what}: colors has {len(col)} rows but positions has {n} points; pass"
                " one (4,) colour for the whole layer or exactly one row per position"
            )
        if not np.all(np.isfinite(col)) or col.min(initial=0.0) < 0 or col.max(initial=0.0) > 1:
            raise RenderError(
                f"{what}: colors must be finite RGBA values in [0, 1] (divide 8-bit colours by 255)"
            )
        try:
            size = float(self.size)
        except (TypeError, ValueError) as exc:
            raise RenderError(
                f"{what}: size must be a number of pixels; got {self.size!r}"
            ) from exc
        if not (np.isfinite(size) and size > 0):
            raise RenderError(f"{what}: size must be a positive number of pixels; got {size}")
        return pos, col


class OverlayRenderer:
    """Draws :class:`OverlayLayer` lists on a given moderngl context.

    Parameters
    ----------
    ctx
        A ``moderngl.Context`` (OpenGL 4.3+, as :class:`voxwarp.render.raycaster.Renderer`); the
        caller owns it.

    The program, vertex buffer and vertex array are made once and reused by every
    :meth:`draw`; :meth:`release` frees them (idempotent).
    """

    def __init__(self, ctx: Any) -> None:
        if ctx.version_code < 430:
            raise RenderError(
                f"voxwarp needs OpenGL 4.3 or newer; this context offers {ctx.version_code}"
            )
        self.ctx = ctx
        self._released = False
        try:  # compiled once per context, shared by its overlay renderers (gl_programs)
            self._hold = gl_programs.program(
                ctx,
                vertex_shader=shaders.source("overlay.vert.glsl"),
                fragment_shader=shaders.source("overlay.frag.glsl"),
            )
        except Exception as exc:
            raise RenderError(f"overlay shader failed to compile/link: {exc}") from exc
        self._prog = self._hold.program
        point_range = ctx.info.get("GL_POINT_SIZE_RANGE") or (1.0, 64.0)
        #: largest sprite the driver draws (gl_PointSize is clamped to it)
        self.max_sprite_size = float(point_range[1])
        self._vbo: Any = None
        self._vao: Any = None
        self._staging = np.zeros(0, dtype=_VERTEX)

    # ------------------------------------------------------------------ buffers
    def _upload(self, data: np.ndarray) -> None:
        """Write ``data`` (vertices) at the start of the kept buffer, growing it if needed."""
        nbytes = data.nbytes
        if self._vbo is None or self._vbo.size < nbytes:
            self._release_buffers()
            capacity = max(MIN_BUFFER_BYTES, 1 << (nbytes - 1).bit_length())
            self._vbo = self.ctx.buffer(reserve=capacity, dynamic=True)
            self._vao = self.ctx.vertex_array(
                self._prog, [(self._vbo, _VERTEX_FORMAT, "in_position", "in_color")]
            )
        else:
            self._vbo.orphan()  # the previous frame may still read the old storage
        self._vbo.write(data)

    def _release_buffers(self) -> None:
        if self._vao is not None:
            self._vao.release()
            self._vao = None
        if self._vbo is not None:
            self._vbo.release()
            self._vbo = None

    # ------------------------------------------------------------------ drawing
    def draw(
        self,
        layers: Sequence[OverlayLayer],
        framebuffer: Any,
        camera: Camera,
        viewport: tuple[int, int, int, int] | None = None,
        point_scale: float = 1.0,
    ) -> None:
        """Draw ``layers`` seen by ``camera`` over what ``framebuffer`` holds.

        Parameters
        ----------
        layers
            Drawn in order (later layers on top); empty layers are skipped.
        framebuffer
            A ``moderngl.Framebuffer`` (e.g. the one :meth:`voxwarp.render.raycaster.Renderer.draw`
            just drew into); left bound, with its viewport as it was.
        camera
            The camera of the frame (perspective or orthographic).
        viewport
            ``(x, y, width, height)`` in pixels, origin bottom-left, as given to the
            raycaster; default the whole framebuffer.
        point_scale
            Multiplies the points' ``size`` (device pixels per layer pixel: a frame drawn
            at a lower or higher resolution than it is shown keeps its handles' size).

        Raises
        ------
        RenderError
            When the renderer was released, a layer or the viewport is invalid.

        Notes
        -----
        Blending and program point size are enabled and depth testing / face culling
        disabled only while drawing; the previous enable flags (as moderngl tracks
        them) are restored and the blend function is reset to moderngl's default.
        """
        if self._released:
            raise RenderError("this OverlayRenderer was released")
        if not isinstance(camera, Camera):
            raise RenderError(
                f"OverlayRenderer.draw takes a voxwarp.Camera; got {type(camera).__name__}"
            )
        batches = []
        for i, layer in enumerate(layers):
            if not isinstance(layer, OverlayLayer):
                raise RenderError(
                    f"OverlayRenderer.draw takes OverlayLayer objects; layer {i} is a"
                    f" {type(layer).__name__}"
                )
            label = f"overlay layer {i}" + (f" ({layer.name!r})" if layer.name else "")
            pos, col = layer.validated(label)
            if len(pos):
                batches.append((layer, pos, col))
        if viewport is None:
            viewport = (0, 0, *framebuffer.size)
        x, y, w, h = (int(v) for v in viewport)
        if w <= 0 or h <= 0:
            raise RenderError(f"viewport must have a positive size; got {viewport}")
        if not batches:
            return

        total = sum(len(pos) for _, pos, _ in batches)
        if len(self._staging) < total:
            self._staging = np.zeros(max(total, 2 * len(self._staging)), dtype=_VERTEX)
        ranges = []
        first = 0
        for layer, pos, col in batches:
            n = len(pos)
            chunk = self._staging[first : first + n]
            chunk["position"] = pos
            chunk["color"] = np.rint(col * 255.0).astype(np.uint8)
            ranges.append((layer, first, n))
            first += n
        self._upload(self._staging[:total])

        ctx, prog = self.ctx, self._prog
        vp = camera.view_projection(w / h)
        prog["u_view_proj"].write(np.ascontiguousarray(vp.T, dtype="f4").tobytes())
        _set(prog, "u_outline", OUTLINE_COLOR)
        _set(prog, "u_outline_width", OUTLINE_WIDTH)
        previous_viewport = framebuffer.viewport
        framebuffer.use()
        framebuffer.viewport = (x, y, w, h)
        # the scope restores the enable flags moderngl tracked before it on exit
        scope = ctx.scope(framebuffer, enable_only=ctx.BLEND | ctx.PROGRAM_POINT_SIZE)
        try:
            with scope:
                ctx.blend_func = (ctx.ONE, ctx.ONE_MINUS_SRC_ALPHA)  # premultiplied over
                for layer, start, n in ranges:
                    points = layer.kind == "points"
                    disc = float(layer.size) * float(point_scale)
                    sprite = min(disc + 2 * OUTLINE_WIDTH, self.max_sprite_size)
                    _set(prog, "u_points", int(points))
                    _set(prog, "u_sprite_size", sprite)
                    mode = ctx.POINTS if points else ctx.LINES
                    self._vao.render(mode=mode, vertices=n, first=start)
        finally:
            ctx.blend_func = ctx.DEFAULT_BLENDING
            scope.release()
            framebuffer.viewport = previous_viewport

    def release(self) -> None:
        """Free the program and buffers; idempotent."""
        if self._released:
            return
        self._release_buffers()
        self._hold.release()  # the shared program stays for the context's other users
        self._staging = np.zeros(0, dtype=_VERTEX)
        self._released = True


# ---------------------------------------------------------------------- segment builders
def polyline_segments(points: np.ndarray) -> np.ndarray:
    """Segment pairs of an open polyline (a wire) for a ``"lines"`` layer.

    Parameters
    ----------
    points
        (N, 3) vertices in order.

    Returns
    -------
    numpy.ndarray
        (2 (N - 1), 3) float64: ``p0, p1, p1, p2, ...``; (0, 3) for fewer than 2 points.

    Raises
    ------
    RenderError
        When ``points`` is not an (N, 3) real array.
    """
    p = np.asarray(_points_array(points, "polyline_segments: points"), dtype=np.float64)
    if len(p) < 2:
        return np.zeros((0, 3))
    out = np.empty((2 * (len(p) - 1), 3))
    out[0::2] = p[:-1]
    out[1::2] = p[1:]
    return out


def grid_edges(positions: np.ndarray) -> np.ndarray:
    """Segment pairs joining neighbouring nodes of a node grid along its three axes.

    These are the links / springs of a grid of elements and the cell edges of a lattice
    (e.g. :attr:`voxwarp.deform.lattice.trilinear.TrilinearGrid.nodes`).

    Parameters
    ----------
    positions
        (nx, ny, nz, 3) node positions, node ``(i, j, k)`` at ``positions[i, j, k]``.

    Returns
    -------
    numpy.ndarray
        (2 E, 3) float64 with E = (nx-1) ny nz + nx (ny-1) nz + nx ny (nz-1): first the
        edges along x (``[i, j, k]`` to ``[i+1, j, k]``), then along y, then along z.

    Raises
    ------
    RenderError
        When ``positions`` is not an (nx, ny, nz, 3) real array with nx, ny, nz >= 1.
    """
    try:
        a = np.asarray(positions, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise RenderError("grid_edges: positions must be an (nx, ny, nz, 3) number array") from exc
    if a.ndim != 4 or a.shape[3] != 3 or min(a.shape[:3]) < 1:
        raise RenderError(
            "grid_edges: positions must be an (nx, ny, nz, 3) array of node positions with"
            f" at least one node per axis; got shape {a.shape}"
        )
    parts = [
        np.stack([a[:-1], a[1:]], axis=-2),
        np.stack([a[:, :-1], a[:, 1:]], axis=-2),
        np.stack([a[:, :, :-1], a[:, :, 1:]], axis=-2),
    ]
    return np.concatenate([p.reshape(-1, 3) for p in parts])


def box_edges(lo: Sequence[float], hi: Sequence[float]) -> np.ndarray:
    """Segment pairs of the 12 edges of the axis-aligned box [lo, hi] (e.g. a clip box).

    Parameters
    ----------
    lo, hi
        Opposite corners (3,) in mm.

    Returns
    -------
    numpy.ndarray
        (24, 3) float64: 4 edges along x, then 4 along y, then 4 along z.

    Raises
    ------
    RenderError
        When a corner is not 3 finite numbers.
    """
    corners = []
    for name, c in (("lo", lo), ("hi", hi)):
        try:
            v = np.asarray(c, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise RenderError(f"box_edges: {name} must be 3 numbers (mm); got {c!r}") from exc
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise RenderError(f"box_edges: {name} must be 3 finite numbers (mm); got {c!r}")
        corners.append(v)
    b = np.stack(corners)  # b[0] = lo, b[1] = hi
    out = []
    for axis in range(3):
        u, v = (a for a in range(3) if a != axis)
        for su in (0, 1):
            for sv in (0, 1):
                for end in (0, 1):
                    p = np.empty(3)
                    p[axis] = b[end, axis]
                    p[u] = b[su, u]
                    p[v] = b[sv, v]
                    out.append(p)
    return np.array(out)


# ---------------------------------------------------------------------- helpers
def _points_array(points: Any, what: str) -> np.ndarray:
    """``points`` as an (N, 3) real, finite array (an empty input gives (0, 3))."""
    try:
        p = np.asarray(points)
    except (TypeError, ValueError) as exc:
        raise RenderError(f"{what} must be an (N, 3) array of world points (mm)") from exc
    if p.size == 0 and p.ndim <= 2 and (p.ndim < 2 or p.shape[1] in (0, 3)):
        return np.zeros((0, 3))
    if p.dtype == object or not (np.issubdtype(p.dtype, np.integer) or p.dtype.kind == "f"):
        raise RenderError(
            f"{what} must be a real (N, 3) array of world points (mm); got dtype {p.dtype}"
        )
    if p.ndim != 2 or p.shape[1] != 3:
        raise RenderError(
            f"{what} must be an (N, 3) array of world points (mm); got shape {p.shape}"
            " (a grid of nodes: use grid_edges() or positions.reshape(-1, 3))"
        )
    finite = np.isfinite(p).all(axis=1)
    if not finite.all():
        bad = np.flatnonzero(~finite)
        raise RenderError(
            f"{what} has {len(bad)} non-finite point(s) (NaN or inf), the first at index"
            f" {bad[0]}; drop or fix them before drawing"
        )
    return p


def _set(prog: Any, name: str, value: Any) -> None:
    if name in prog:  # optimised out otherwise
        prog[name].value = value
