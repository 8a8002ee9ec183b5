"""The warped grid and displacement glyphs drawn on slices and in 3D.

Slices (:func:`draw_slice_overlays`, numpy, no GL): over a slice's RGBA, the rest-space
grid lines carried by the chain (:func:`voxwarp.core.warp_grid.grid_coverage` of the
pull-back point of each pixel centre, the point the slice shader samples) and arrows of
the in-plane displacement ``u = chain(x) - x`` with a legend arrow and its length in mm
(top right)
(:func:`voxwarp.core.warp_grid.slice_glyphs`).

3D (:func:`overlay_meshes`): mesh instances for a scene's mesh pass, drawn depth-tested
with the volume. The grid's lines are thin tubes around rest-space polylines
(:func:`voxwarp.core.warp_grid.lattice_lines`) that the mesh pass moves by the chain's
forward map, as it moves every mesh. Glyph arrows are built where they are seen (on a
plane of the deformed space) and stored pulled back through the chain, so the forward
map puts them back there undistorted.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from voxwarp.core.mesh import Mesh, MeshInstance
from voxwarp.core.warp_grid import (
    PLANE_AXIS,
    SliceGlyphs,
    grid_coverage,
    lattice_lines,
    nice_spacing,
    pixel_points,
    pull_back,
    slice_glyphs,
)
from voxwarp.deform.warp import Warp, chain_forward_lenient
from voxwarp.errors import InputError
from voxwarp.render.overlay import OverlayLayer

#: Overlays these functions draw (the CLI's ``--overlay`` accepts them).
WARP_OVERLAYS: tuple[str, ...] = ("grid", "glyphs")
#: RGB (0..1) of grid lines and of glyph arrows.
GRID_RGB = (1.0, 0.85, 0.1)
GLYPH_RGB = (0.2, 0.9, 1.0)
#: Coverage opacity of slice grid lines (the anatomy stays readable under them).
GRID_ALPHA = 0.8
#: Tube radius of 3D grid lines, as a fraction of the box's largest side.
TUBE_RADIUS = 1 / 500
#: Fewest pixels between default glyphs on a slice.
MIN_GLYPH_PX = 20
#: Sides of the tubes and arrow shafts.
TUBE_SIDES = 4

# 5x7 bitmap digits for the glyph legend, rows top to bottom
_FONT: dict[str, tuple[str, ...]] = {
    "0": (".###.", "#...#", "#..##", "#.#.#", "##..#", "#...#", ".###."),
    "1": ("..#..", ".##..", "..#..", "..#..", "..#..", "..#..", ".###."),
    "2": (".###.", "#...#", "....#", "...#.", "..#..", ".#...", "#####"),
    "3": ("####.", "....#", "....#", ".###.", "....#", "....#", "####."),
    "4": ("...#.", "..##.", ".#.#.", "#..#.", "#####", "...#.", "...#."),
    "5": ("#####", "#....", "####.", "....#", "....#", "#...#", ".###."),
    "6": (".###.", "#....", "#....", "####.", "#...#", "#...#", ".###."),
    "7": ("#####", "....#", "...#.", "..#..", ".#...", ".#...", ".#..."),
    "8": (".###.", "#...#", "#...#", ".###.", "#...#", "#...#", ".###."),
    "9": (".###.", "#...#", "#...#", ".####", "....#", "....#", ".###."),
    ".": (".....", ".....", ".....", ".....", ".....", ".##..", ".##.."),
    "m": (".....", ".....", "##.#.", "#.#.#", "#.#.#", "#.#.#", "#.#.#"),
    " ": (".....",) * 7,
}


# ------------------------------------------------------------------------ slices
def draw_slice_overlays(
    rgba: np.ndarray,
    warps: Sequence[Warp],
    pixel_to_world: np.ndarray,
    overlays: Sequence[str],
    spacing_mm: float,
    *,
    glyph_spacing_mm: float | None = None,
) -> tuple[np.ndarray, list[str]]:
    """``rgba`` (H, W, 4 uint8) with ``overlays`` (``"grid"``, ``"glyphs"``; others are
    left to their own modules) drawn over it, and one line per overlay saying what
    was drawn. ``spacing_mm``: grid spacing; glyphs every ``glyph_spacing_mm``
    (default the grid spacing)."""
    h, w = np.asarray(rgba).shape[:2]
    layer, notes = slice_overlay_layer(
        warps, pixel_to_world, (w, h), overlays, spacing_mm, glyph_spacing_mm=glyph_spacing_mm
    )
    return composite(rgba, layer), notes


def slice_overlay_layer(
    warps: Sequence[Warp],
    pixel_to_world: np.ndarray,
    size: tuple[int, int],
    overlays: Sequence[str],
    spacing_mm: float,
    *,
    glyph_spacing_mm: float | None = None,
    rest: np.ndarray | None = None,
) -> tuple[np.ndarray, list[str]]:
    """The overlays of a ``size`` (W, H) slice as a premultiplied (H, W, 4) float layer
    (colour 0..255, alpha 0..1; :func:`composite` puts it over a slice) and the notes
    of :func:`draw_slice_overlays`. ``rest``: the pixels' pull-back points if known."""
    w, h = (int(v) for v in size)
    m = np.asarray(pixel_to_world, dtype=np.float64)
    layer = np.zeros((h, w, 4))
    notes = []
    if "grid" in overlays:
        if rest is None:
            rest = pull_back(warps, pixel_points(m, (w, h)))
        cover = grid_coverage(rest, (m[:3, 0], m[:3, 1]), spacing_mm)
        _blend(layer, cover * GRID_ALPHA, GRID_RGB)
        notes.append(f"grid: rest-space lines every {spacing_mm:g} mm")
    if "glyphs" in overlays:
        glyphs = slice_glyphs(warps, m, (w, h), glyph_spacing_mm or glyph_default(m, spacing_mm))
        draw_glyphs(layer, glyphs)
        notes.append(glyph_note(glyphs))
    return layer, notes


def glyph_default(pixel_to_world: np.ndarray, spacing_mm: float) -> float:
    """Default glyph spacing on a slice: the grid spacing, doubled while that is under
    :data:`MIN_GLYPH_PX` pixels (glyphs stay on grid nodes)."""
    px = float(np.linalg.norm(np.asarray(pixel_to_world, dtype=np.float64)[:3, 0]))
    spacing = float(spacing_mm)
    while spacing < MIN_GLYPH_PX * px:
        spacing *= 2
    return spacing


def composite(rgba: np.ndarray, layer: np.ndarray) -> np.ndarray:
    """``layer`` (:func:`slice_overlay_layer`) over ``rgba`` (H, W, 4 uint8): a new
    contiguous uint8 RGBA, alpha kept."""
    out = np.array(rgba, dtype=np.uint8, copy=True)
    a = layer[..., 3:]
    rgb = layer[..., :3] + out[..., :3] * (1.0 - a)
    out[..., :3] = (rgb + 0.5).clip(0, 255).astype(np.uint8)
    return out


def glyph_note(glyphs: SliceGlyphs) -> str:
    """One line: the glyph spacing and the arrow scale (what the legend shows)."""
    if glyphs.px_per_mm <= 0:
        return "glyphs: no in-plane displacement on this plane"
    legend_px = glyphs.legend_mm * glyphs.px_per_mm
    return (
        f"glyphs: arrows of u = chain(x) - x every {glyphs.spacing_px:.3g} px;"
        f" legend: {legend_px:.3g} px = {glyphs.legend_mm:g} mm"
    )


def draw_glyphs(out: np.ndarray, glyphs: SliceGlyphs, rgb: Sequence[float] = GLYPH_RGB) -> None:
    """Arrows (a dark halo under them) and the legend arrow drawn into ``out``
    (H, W, 3 float colour in 0..255, or a premultiplied layer with alpha), in place."""
    if glyphs.px_per_mm <= 0:
        return
    width = 1.5 if glyphs.spacing_px >= 16 else 1.0
    for tail, head in zip(glyphs.tails, glyphs.heads(), strict=True):
        _arrow(out, tail, head, width, rgb)
    _legend(out, glyphs, width, rgb)


def _arrow(out: np.ndarray, tail: np.ndarray, head: np.ndarray, width: float, rgb: Any) -> None:
    """One arrow: a shaft and two barbs (a quarter of its length, at least 3 px and at
    most 0.6 of it); none when shorter than a pixel."""
    d = head - tail
    length = float(np.hypot(*d))
    if length < 1.0:  # under a pixel: no arrow (not a dot on every still glyph)
        return
    segments = [(tail, head)]
    if length >= 2:
        barb = min(max(3.0, length / 4), 0.6 * length) * d / length
        for angle in (0.5, -0.5):
            c, s = np.cos(angle), np.sin(angle)
            back = np.array([c * barb[0] - s * barb[1], s * barb[0] + c * barb[1]])
            segments.append((head, head - back))
    for a, b in segments:
        _segment(out, a, b, width + 1.5, (0.0, 0.0, 0.0), 0.6)
    for a, b in segments:
        _segment(out, a, b, width, rgb, 1.0)


def _segment(
    out: np.ndarray, a: np.ndarray, b: np.ndarray, width: float, rgb: Any, alpha: float
) -> None:
    """Antialiased segment from ``a`` to ``b`` (pixel (col, row) centres), in place."""
    h, w = out.shape[:2]
    pad = width + 1
    c0, c1 = int(max(0, min(a[0], b[0]) - pad)), int(min(w, max(a[0], b[0]) + pad + 1))
    r0, r1 = int(max(0, min(a[1], b[1]) - pad)), int(min(h, max(a[1], b[1]) + pad + 1))
    if c1 <= c0 or r1 <= r0:
        return
    cols, rows = np.meshgrid(np.arange(c0, c1, dtype=float), np.arange(r0, r1, dtype=float))
    d = b - a
    len2 = float(d @ d)
    t = ((cols - a[0]) * d[0] + (rows - a[1]) * d[1]) / len2 if len2 > 0 else 0 * cols
    t = np.clip(t, 0.0, 1.0)
    dist = np.hypot(cols - a[0] - t * d[0], rows - a[1] - t * d[1])
    cover = np.clip(width / 2 + 0.5 - dist, 0.0, 1.0) * alpha
    _blend(out[r0:r1, c0:c1], cover, rgb)


def _legend(out: np.ndarray, glyphs: SliceGlyphs, width: float, rgb: Any) -> None:
    """The legend, top right: an arrow of ``legend_mm`` and its length as text."""
    h, w = out.shape[:2]
    length = glyphs.legend_mm * glyphs.px_per_mm
    scale = 2 if h >= 384 else 1
    text = f"{glyphs.legend_mm:g} mm"
    x0 = w - 8 - 6 * scale * len(text) - 6 - length
    y = 8
    tail = np.array([x0, y + 3.5 * scale])
    _arrow(out, tail, tail + np.array([length, 0.0]), width, rgb)
    _text(out, text, int(x0 + length + 6), y, scale, rgb)


def _text(out: np.ndarray, text: str, x: int, y: int, scale: int, rgb: Any) -> None:
    """``text`` (digits, '.', 'm', ' ') at pixel (x, y) top left, over a dark box."""
    masks = [_glyph_mask(ch, scale) for ch in text]
    gh, gw = 7 * scale, 6 * scale * len(masks)
    h, w = out.shape[:2]
    if x + gw > w or y + gh > h or x < 0 or y < 0:
        return
    box = out[max(0, y - scale) : y + gh + scale, max(0, x - scale) : x + gw]
    _blend(box, np.full(box.shape[:2], 0.6), (0.0, 0.0, 0.0))
    for i, mask in enumerate(masks):
        x0 = x + 6 * scale * i
        _blend(out[y : y + gh, x0 : x0 + 5 * scale], mask.astype(float), rgb)


def _glyph_mask(ch: str, scale: int) -> np.ndarray:
    rows = np.array([[c == "#" for c in row] for row in _FONT.get(ch, _FONT[" "])])
    return np.kron(rows, np.ones((scale, scale), dtype=bool))


def _blend(region: np.ndarray, alpha: np.ndarray, rgb: Sequence[float]) -> None:
    """``region`` (h, w, 3 or 4; colour 0..255, premultiplied alpha 0..1) <- ``rgb``
    (0..1) over it with coverage ``alpha``."""
    a = np.asarray(alpha, dtype=np.float64)[..., None]
    col = np.asarray(rgb, dtype=np.float64) * 255.0
    region[..., :3] = region[..., :3] * (1 - a) + col * a
    if region.shape[-1] == 4:
        region[..., 3:] = region[..., 3:] * (1 - a) + a


# ---------------------------------------------------------------------------- 3D
def overlay_meshes(
    scene: Any,
    overlays: Sequence[str],
    spacing_mm: float,
    plane: str = "all",
    *,
    pixel_mm: float = 0.0,
) -> list[MeshInstance]:
    """Mesh instances of ``overlays`` (``"grid"``, ``"glyphs"``) for ``scene``'s mesh
    pass: the grid's tubes (rest space, moved by the chain when drawn) over the
    volume's box, and glyph arrows on ``plane`` (the box centre's axial plane for
    ``"all"``). ``pixel_mm``: the picture's pixel size at the volume (see
    :func:`camera_pixel_mm`); tubes are at least 1.5 pixels wide."""
    lo, hi = (np.asarray(b, dtype=np.float64) for b in scene.volume.bounds)
    radius = max(float(np.max(hi - lo)) * TUBE_RADIUS, 0.75 * float(pixel_mm))
    out = []
    if "grid" in overlays:
        lines = lattice_lines(lo, hi, spacing_mm, plane)
        mesh = tube_mesh(lines, radius, name="warped grid")
        out.append(MeshInstance(mesh, color=(*GRID_RGB, 1.0), name="warped grid"))
    if "glyphs" in overlays:
        glyph_plane = "axial" if plane == "all" else plane
        lo_d, hi_d = (np.asarray(b, float) for b in scene.deformed_bounds())
        mesh = glyph_mesh(scene.warps, lo_d, hi_d, spacing_mm, glyph_plane, radius)
        if mesh is not None:
            out.append(MeshInstance(mesh, color=(*GLYPH_RGB, 1.0), name="displacement glyphs"))
    return out


def camera_pixel_mm(camera: Any, size: tuple[int, int]) -> float:
    """Size in mm of one pixel of a ``size`` picture at the camera's centre."""
    c = np.asarray(camera.center, dtype=np.float64)
    right = np.asarray(camera.rotation, dtype=np.float64)[:, 0]
    a, b = camera.project(np.stack([c, c + right]), size)
    return 1.0 / max(float(np.hypot(*(b - a))), 1e-12)


def facing_plane(camera: Any) -> str:
    """The named plane (axial, coronal, sagittal) whose normal is closest to the
    camera's viewing direction."""
    view = np.asarray(camera.rotation, dtype=np.float64)[:, 2]
    axis = int(np.argmax(np.abs(view)))
    return {k: name for name, k in PLANE_AXIS.items()}[axis]


def tube_mesh(lines: Sequence[np.ndarray], radius: float, name: str = "tubes") -> Mesh:
    """One mesh of :data:`TUBE_SIDES`-sided tubes of ``radius`` mm around polylines."""
    verts, faces, base = [], [], 0
    for p in lines:
        v, f = _tube(np.asarray(p, dtype=np.float64), radius)
        verts.append(v)
        faces.append(f + base)
        base += len(v)
    if not verts:
        raise InputError("the grid has no line inside the volume; give a smaller --grid-spacing")
    return Mesh(np.concatenate(verts), np.concatenate(faces), name=name)


def _frame(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = direction / np.linalg.norm(direction)
    helper = np.eye(3)[int(np.argmin(np.abs(d)))]
    a = np.cross(d, helper)
    a /= np.linalg.norm(a)
    return a, np.cross(d, a)


def _tube(p: np.ndarray, radius: float, sides: int = TUBE_SIDES) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (n * sides, 3) and faces of a tube around a straight-framed polyline;
    ring ``i`` (vertices ``i * sides ...``) is centred on ``p[i]``."""
    a, b = _frame(p[-1] - p[0])
    ang = 2 * np.pi * np.arange(sides) / sides
    ring = radius * (np.cos(ang)[:, None] * a + np.sin(ang)[:, None] * b)
    verts = (p[:, None, :] + ring[None]).reshape(-1, 3)
    i = np.arange(len(p) - 1)[:, None] * sides
    j = np.arange(sides)[None, :]
    v00, v01 = i + j, i + (j + 1) % sides
    v10, v11 = v00 + sides, v01 + sides
    faces = np.concatenate(
        [np.stack([v00, v01, v11], -1).reshape(-1, 3), np.stack([v00, v11, v10], -1).reshape(-1, 3)]
    )
    return verts, faces


def glyph_mesh(
    warps: Sequence[Warp],
    lo: np.ndarray,
    hi: np.ndarray,
    spacing_mm: float,
    plane: str,
    radius: float,
) -> Mesh | None:
    """Arrows of ``u = chain(x) - x`` at the points every ``spacing_mm`` of the
    deformed-space plane ``plane`` through the box centre (longest 0.9 spacing),
    stored pulled back through the chain (the mesh pass's forward map returns them
    to where they are built). None when nothing moves there."""
    x = plane_points(lo, hi, spacing_mm, plane)
    u = pull_back(warps, x) - x
    size = np.linalg.norm(u, axis=1)
    keep = np.isfinite(size) & (size > 1e-6)
    if not np.any(keep) or float(size[keep].max()) <= 1e-6:
        return None
    scale = 0.9 * spacing_mm / float(size[keep].max())
    verts, faces, base = [], [], 0
    for tail, vec in zip(x[keep], u[keep] * scale, strict=True):
        v, f = arrow_vertices(tail, vec, radius)
        verts.append(v)
        faces.append(f + base)
        base += len(v)
    deformed = np.concatenate(verts)
    rest = pull_back(warps, deformed)
    rest = np.where(np.isfinite(rest), rest, deformed)
    return Mesh(rest, np.concatenate(faces), name="displacement glyphs")


def grid_segments(scene: Any, spacing_mm: float, plane: str = "all") -> np.ndarray:
    """Line segments (2k, 3) of the rest-space grid moved by the chain's forward map
    (for 1-pixel line overlays such as the GUI's; points without a forward map keep
    their best estimate)."""
    lo, hi = scene.volume.bounds
    segments = []
    for p in lattice_lines(lo, hi, spacing_mm, plane):
        q = chain_forward_lenient(scene.warps, p)[0] if scene.warps else p
        segments.append(np.repeat(q, 2, axis=0)[1:-1])
    return np.concatenate(segments) if segments else np.zeros((0, 3))


def glyph_segments(scene: Any, spacing_mm: float, plane: str) -> np.ndarray:
    """Line segments (2k, 3) of arrows of ``u = chain(x) - x`` on the deformed-space
    ``plane`` through the box centre (shaft and two barbs each; longest 0.9 spacing)."""
    lo, hi = (np.asarray(b, float) for b in scene.deformed_bounds())
    x = plane_points(lo, hi, spacing_mm, plane)
    u = pull_back(scene.warps, x) - x
    size = np.linalg.norm(u, axis=1)
    keep = np.isfinite(size) & (size > 1e-6)
    if not np.any(keep):
        return np.zeros((0, 3))
    x, vec = x[keep], u[keep] * (0.9 * spacing_mm / float(size[keep].max()))
    tip = x + vec
    normal = np.eye(3)[PLANE_AXIS[plane]]
    side = np.cross(vec, normal) * 0.15
    back = vec * 0.3
    parts = [x, tip, tip, tip - back + side, tip, tip - back - side]
    return np.stack(parts, axis=1).reshape(-1, 3)


def plane_points(lo: np.ndarray, hi: np.ndarray, spacing_mm: float, plane: str) -> np.ndarray:
    """(n, 3) points every ``spacing_mm`` (cell centres) on the named plane through the
    centre of the box ``lo..hi``."""
    k = PLANE_AXIS[plane]
    a, b = (ax for ax in range(3) if ax != k)
    ta = np.arange(lo[a] + spacing_mm / 2, hi[a], spacing_mm)
    tb = np.arange(lo[b] + spacing_mm / 2, hi[b], spacing_mm)
    ga, gb = np.meshgrid(ta, tb, indexing="ij")
    x = np.empty((ga.size, 3))
    x[:, a], x[:, b], x[:, k] = ga.ravel(), gb.ravel(), (lo[k] + hi[k]) / 2
    return x


class WarpLines:
    """The grid and glyphs as 1-pixel line layers over a 3D view (GUI, notebook).

    Switches ``grid``, ``glyphs`` and ``spacing_mm`` (0: :func:`nice_spacing` of the
    volume); :meth:`layers` gives the :class:`~voxwarp.render.overlay.OverlayLayer`
    list for a scene and camera: the plane facing the camera, cached per warp
    revision, spacing and plane.
    """

    def __init__(self, grid: bool = False, glyphs: bool = False, spacing_mm: float = 0.0):
        self.grid, self.glyphs, self.spacing_mm = bool(grid), bool(glyphs), float(spacing_mm)
        self._cache: tuple[Any, list[OverlayLayer]] | None = None

    def spacing(self, volume: Any) -> float:
        """The grid spacing in mm for ``volume`` (``spacing_mm``, or automatic)."""
        if self.spacing_mm > 0:
            return self.spacing_mm
        return nice_spacing(*volume.bounds)

    def layers(self, scene: Any, camera: Any) -> list[OverlayLayer]:
        """Line layers of the switched-on overlays (empty when both are off)."""
        if not (self.grid or self.glyphs):
            return []
        plane = facing_plane(camera)
        spacing = self.spacing(scene.volume)
        warps = tuple((id(w), w.revision) for w in scene.warps)
        key = (warps, self.grid, self.glyphs, spacing, plane, id(scene.volume))
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1]
        layers = []
        if self.grid:
            seg = grid_segments(scene, spacing, plane)
            layers.append(OverlayLayer("lines", seg, (*GRID_RGB, 1.0), name="warped grid"))
        if self.glyphs:
            seg = glyph_segments(scene, spacing, plane)
            layers.append(OverlayLayer("lines", seg, (*GLYPH_RGB, 1.0), name="glyphs"))
        self._cache = (key, layers)
        return layers


def arrow_vertices(
    tail: np.ndarray, vec: np.ndarray, radius: float
) -> tuple[np.ndarray, np.ndarray]:
    """A shaft (tube) and a cone head from ``tail`` along ``vec``: vertices and faces."""
    length = float(np.linalg.norm(vec))
    d = vec / length
    head = min(length * 0.35, 6 * radius)
    shaft_v, shaft_f = _tube(np.stack([tail, tail + d * (length - head)]), radius)
    a, b = _frame(d)
    ang = 2 * np.pi * np.arange(6) / 6
    base = tail + d * (length - head)
    ring = base + 3 * radius * (np.cos(ang)[:, None] * a + np.sin(ang)[:, None] * b)
    cone_v = np.vstack([ring, tail + vec])
    n0 = len(shaft_v)
    cone_f = np.array([[n0 + i, n0 + (i + 1) % 6, n0 + 6] for i in range(6)])
    return np.vstack([shaft_v, cone_v]), np.vstack([shaft_f, cone_f])


__all__ = [
    "GLYPH_RGB",
    "GRID_RGB",
    "WARP_OVERLAYS",
    "WarpLines",
    "arrow_vertices",
    "camera_pixel_mm",
    "composite",
    "draw_glyphs",
    "draw_slice_overlays",
    "facing_plane",
    "glyph_mesh",
    "glyph_note",
    "glyph_segments",
    "grid_segments",
    "overlay_meshes",
    "plane_points",
    "slice_overlay_layer",
    "tube_mesh",
]
