"""The warped grid and displacement glyphs in 3D: meshes and line layers.

:func:`overlay_meshes` gives mesh instances for a scene's mesh pass, drawn depth-tested
with the volume. The grid's lines are thin tubes around rest-space polylines
(:func:`voxwarp.core.warp_grid.lattice_lines`) that the mesh pass moves by the chain's
forward map, as it moves every mesh (:mod:`voxwarp.core.mesh_warp`). Glyph arrows are
built where they are seen (on a plane of the deformed space) and stored pulled back
through the chain, so the forward map puts them back there undistorted.

:class:`WarpLines` gives the same as 1-pixel line layers drawn on top of a view
(:class:`voxwarp.render.overlay.OverlayRenderer`; the GUI's 3D view and the notebook
viewer), the plane facing the camera, cached per warp revision. The slice
counterparts are in :mod:`voxwarp.render.warp_overlays`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from voxwarp.core.mesh import Mesh, MeshInstance
from voxwarp.core.warp_grid import PLANE_AXIS, lattice_lines, nice_spacing, pull_back
from voxwarp.deform.identity import token
from voxwarp.deform.warp import Warp, chain_forward_lenient
from voxwarp.errors import InputError
from voxwarp.render.overlay import OverlayLayer
from voxwarp.render.warp_overlays import GLYPH_RGB, GRID_RGB

#: Tube radius of 3D grid lines, as a fraction of the box's largest side.
TUBE_RADIUS = 1 / 500
#: Sides of the tubes and arrow shafts.
TUBE_SIDES = 4


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
        warps = tuple((token(w), w.revision) for w in scene.warps)
        key = (warps, self.grid, self.glyphs, spacing, plane, token(scene.volume))
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
    "TUBE_RADIUS",
    "TUBE_SIDES",
    "WarpLines",
    "arrow_vertices",
    "camera_pixel_mm",
    "facing_plane",
    "glyph_mesh",
    "glyph_segments",
    "grid_segments",
    "overlay_meshes",
    "plane_points",
    "tube_mesh",
]
