"""GRAPP 2010's own test scenes (section 6, Figure 7), built as scene graphs.

The paper times three scenes, each drawn once with 4x4 matrices (FPS/L) and once with
trilinear lattices (FPS/T) in the scene graph (its table in section 6). We rebuild them
with the same object and triangle counts (our own meshes and layout):

* :func:`spheres_scene` ("spheres", 185 objects, 1.5 M triangles; the GPU's vertex
  throughput): highly tessellated spheres attached to an animated object. Here the
  object is a tube-shaped body, bent (its pose baked into its vertices, as a
  vertex-animated mesh is), with eight chains of spheres along it; each chain's lattice is
  built from a 1D array of anchors on the bent body (section 5), so the chains follow it.
* :func:`helix_scene` ("helix", 4,617 objects / 164 k triangles and 2,566 objects /
  656 k; the CPU's composition): many small low-resolution spheres in a rope of 3 x 3
  spheres wound into a helix. The root carries a sway lattice, every rope segment a
  lattice that maps the straight segment onto its piece of the helix, every sphere a 4x4
  into its slot: two lattices composed per object.

Each builder returns a :class:`GrappScene` holding both graphs: ``trilinear`` (lattices
as above) and ``linear`` (the same leaves, meshes and slots, the lattices replaced by
4x4s: a rigid frame per chain sphere or rope segment, the identity for the sway), so
the two variants differ only in their transforms. The triangle counts are met exactly by
mixing two sphere resolutions (:func:`sphere_mix`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from voxwarp.core.mesh import PALETTE, Mesh, MeshInstance, tube_mesh, uv_sphere
from voxwarp.deform.lattice.anchors import AnchorStrip, anchor_frames, anchors_at
from voxwarp.deform.lattice.scene_graph import SceneNode, compose_scene
from voxwarp.deform.lattice.trilinear import TrilinearGrid
from voxwarp.errors import MeshError
from voxwarp.teaching.lattice_scenes import bend_map
from voxwarp.teaching.papers import LATTICE_FPS, LatticeFpsRow

#: the two variants of every scene: lattices, or 4x4 matrices in their place
VARIANTS: tuple[str, ...] = ("trilinear", "linear")

# the spheres scene: the body (mm) and its bend, the chains along it
BODY_RADIUS, BODY_LENGTH, BODY_BEND = 6.0, 60.0, 1.2
#: rings x sections of the body's tube: 16,224 triangles, which leaves the 184 spheres a
#: total that one sphere resolution divides
BODY_RINGS, BODY_SECTIONS = 170, 48
CHAINS = 8
# the helix scene: spheres across the rope, slices per segment, turns, sphere spacing
ROPE_SIDE, SEGMENT_SLICES, TURNS, SLOT = 3, 9, 4, 1.0


@dataclass
class GrappScene:
    """One scene of the paper's table in both variants (see the module docstring).

    Attributes
    ----------
    name
        The scene's key (``spheres``, ``helix_4617``, ``helix_2566``).
    row
        The paper's row (:data:`voxwarp.teaching.papers.LATTICE_FPS`).
    graphs
        ``{"trilinear": root, "linear": root}``: the two scene graphs.
    view
        Camera (azimuth, elevation) in degrees that shows the scene.
    layout
        One line: how this scene is laid out (where it differs from the paper's).
    """

    name: str
    row: LatticeFpsRow
    graphs: dict[str, SceneNode]
    view: tuple[float, float]
    layout: str = ""

    def leaves(self, variant: str = "trilinear") -> list[SceneNode]:
        """The graph's nodes with geometry (the objects)."""
        return [n for n, _ in self.graphs[variant].walk() if n.geometry is not None]

    @property
    def objects(self) -> int:
        """Number of objects (mesh leaves)."""
        return len(self.leaves())

    @property
    def triangles(self) -> int:
        """Triangles over all objects."""
        return sum(n.geometry.n_faces for n in self.leaves())

    def instances(self, variant: str = "trilinear") -> list[MeshInstance]:
        """Compose the graph (``compose_scene``) and wrap each leaf in a MeshInstance."""
        return wrap_instances(self.graphs[variant])


def wrap_instances(root: SceneNode) -> list[MeshInstance]:
    """One :class:`MeshInstance` per composed mesh leaf of ``root`` (coloured from the
    palette by leaf index): what a frame of an animated scene graph recomputes."""
    out = []
    for c in compose_scene(root):
        transform = c.grid if c.matrix is None else np.asarray(c.matrix, dtype=np.float64)
        box = None if c.box is None else (np.asarray(c.box[0]), np.asarray(c.box[1]))
        colour = PALETTE[len(out) % len(PALETTE)]
        out.append(MeshInstance(c.node.geometry, transform, box=box, color=colour))
    return out


# ---------------------------------------------------------------------- meshes
def sphere_mix(triangles: int, count: int) -> list[tuple[int, int, int]]:
    """``count`` uv spheres with exactly ``triangles`` triangles in all: ``[(rows, cols,
    how many), ...]`` (one or two resolutions, the same rows, cols c and c + 1).

    A uv sphere has 2 (rows - 1) cols triangles; rows - 1 is a divisor of triangles / 2
    (so that the total is met), cols about twice that (round spheres)."""
    if count < 1 or triangles < 8 * count or triangles % 2:
        raise MeshError(
            f"cannot split {triangles} triangles over {count} spheres; give an even count"
            " of at least 8 triangles per sphere"
        )
    half = triangles // 2
    best: tuple[float, int, int] | None = None
    for d in range(1, min(half // (3 * count), 512) + 1):
        if half % d:
            continue
        cols = half // (count * d)
        score = abs(math.log(cols / (2.0 * d)))
        if cols >= 3 and (best is None or score < best[0] - 1e-9):
            best = (score, d, cols)
    if best is None:
        raise MeshError(f"no sphere resolution splits {triangles} triangles over {count} spheres")
    _, d, cols = best
    more = (half - count * d * cols) // d  # spheres with cols + 1
    mix = [(d + 1, cols, count - more), (d + 1, cols + 1, more)]
    return [m for m in mix if m[2] > 0]


def sphere_meshes(triangles: int, count: int, radius: float) -> list[Mesh]:
    """``count`` sphere meshes (shared per resolution) with ``triangles`` in all."""
    out: list[Mesh] = []
    for rows, cols, n in sphere_mix(triangles, count):
        out += [uv_sphere(radius, rows=rows, cols=cols)] * n
    return out


def _placed(name: str, matrix: np.ndarray, mesh: Mesh) -> SceneNode:
    return SceneNode(name, matrix, box=mesh.bounds, geometry=mesh)


def _translate(t: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = t
    return m


def _rigid(frame: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """4x4 of the nearest rotation to ``frame`` (columns) and the translation ``origin``."""
    u, _, vt = np.linalg.svd(frame)
    r = u @ vt
    if np.linalg.det(r) < 0:
        r = u @ np.diag([1.0, 1.0, -1.0]) @ vt
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = r, origin
    return m


# ---------------------------------------------------------------------- spheres
def bent_body() -> Mesh:
    """The animated object of the spheres scene: a tube standing along z, bent by
    :data:`BODY_BEND` radians (the pose baked into its vertices)."""
    r, length = BODY_RADIUS, BODY_LENGTH
    tube = tube_mesh(length, r, rings=BODY_RINGS, sections=BODY_SECTIONS)
    v = tube.vertices[:, [2, 1, 0]] * np.array([-1.0, 1.0, 1.0])  # along x -> along z
    lo, hi = np.array([-r, -r, 0.0]), np.array([r, r, length])
    grid = TrilinearGrid.from_function(bend_map(length, r, BODY_BEND), (2, 2, 24))
    return Mesh.from_arrays(grid((v - lo) / (hi - lo)), tube.faces, name="body")


def _chain_strip(body: Mesh, rest: np.ndarray, angle: float, cells: int) -> AnchorStrip:
    """A 1D anchor array of ``cells + 1`` anchors up the body at ``angle`` (rad)."""
    step = 0.9 * BODY_LENGTH / cells
    z = 0.05 * BODY_LENGTH + step * np.arange(cells + 1)
    ring = BODY_RADIUS * np.array([math.cos(angle), math.sin(angle)])
    pts = np.c_[np.tile(ring, (len(z), 1)), z]
    ups = np.tile([0.0, 0.0, 1.0], (len(z), 1))
    anchors = anchors_at(rest, body.faces, pts, ups)
    return AnchorStrip(anchors, thickness=step, width=step, offset=0.05 * step)


def spheres_scene(
    objects: int = 185, triangles: int = 1_500_000, *, row: LatticeFpsRow | None = None
) -> GrappScene:
    """The paper's "spheres" row: a bent body and ``objects - 1`` spheres in
    :data:`CHAINS` chains along it, ``triangles`` in all (see the module docstring)."""
    body = bent_body()
    rest = tube_mesh(BODY_LENGTH, BODY_RADIUS, rings=BODY_RINGS, sections=BODY_SECTIONS)
    rest_v = rest.vertices[:, [2, 1, 0]] * np.array([-1.0, 1.0, 1.0])
    n = objects - 1
    per = math.ceil(n / CHAINS)
    step = 0.9 * BODY_LENGTH / per
    spheres = iter(sphere_meshes(triangles - body.n_faces, n, 0.45 * step))
    graphs = {v: SceneNode(f"spheres {v}") for v in VARIANTS}
    for g in graphs.values():
        g.add(SceneNode("body", np.eye(4), box=body.bounds, geometry=body))
    faces = np.asarray(body.faces, dtype=np.int64)
    for c in range(CHAINS):
        count = min(per, n - c * per)
        if count <= 0:
            break
        strip = _chain_strip(body, rest_v, 2 * math.pi * c / CHAINS, per)
        grid = strip.grid(body.vertices, faces)
        box = (np.zeros(3), np.array([per * step, step, step]))
        tri = graphs["trilinear"].add(SceneNode(f"chain {c}", grid, box=box))
        lin = graphs["linear"].add(SceneNode(f"chain {c}", np.eye(4)))
        _, frames = anchor_frames(strip.anchors[0], body.vertices, faces)
        for i in range(count):
            mesh = next(spheres)
            local = np.array([(i + 0.5) * step, 0.5 * step, 0.5 * step])
            tri.add(_placed(f"sphere {c}.{i}", _translate(local), mesh))
            centre = grid(local[None] / box[1])[0]
            lin.add(_placed(f"sphere {c}.{i}", _rigid(frames[i] + frames[i + 1], centre), mesh))
    layout = (
        f"a bent tube body (baked pose) and {n} spheres in {CHAINS} chains anchored to it;"
        " the paper's: spheres attached to an animated figurine"
    )
    return GrappScene("spheres", row or LATTICE_FPS[0], graphs, (-60.0, 20.0), layout)


# ---------------------------------------------------------------------- helix
def helix_frame(s: np.ndarray, length: float) -> tuple[np.ndarray, np.ndarray]:
    """The rope's centre line wound into :data:`TURNS` turns: points (N, 3) and frames
    (N, 3, 3) (columns: tangent, outward, up) at arc lengths ``s`` of ``length``."""
    pitch = 2.5 * ROPE_SIDE * SLOT
    per_turn = length / TURNS
    radius = math.sqrt(max(per_turn**2 - pitch**2, 1e-9)) / (2 * math.pi)
    theta = 2 * math.pi * np.asarray(s, dtype=np.float64) / per_turn
    c, si = np.cos(theta), np.sin(theta)
    centre = np.stack([radius * c, radius * si, pitch * theta / (2 * math.pi)], -1)
    t = np.stack([-2 * math.pi * radius * si, 2 * math.pi * radius * c, np.full_like(c, pitch)])
    t = (t / np.linalg.norm(t, axis=0)).T
    out = np.stack([c, si, np.zeros_like(c)], -1)
    up = np.cross(t, out)
    return centre, np.stack([t, out, up], axis=-1)


def _helix_map(x0: float, seg: float, width: float, length: float) -> Callable:
    """Unit cube of a rope segment (x from ``x0``, ``seg`` long; y, z across the rope's
    ``width``) -> its piece of the helix."""

    def f(u: np.ndarray) -> np.ndarray:
        centre, fr = helix_frame(x0 + u[:, 0] * seg, length)
        across = (u[:, 1:] - 0.5) * width
        return centre + fr[:, :, 1] * across[:, :1] + fr[:, :, 2] * across[:, 1:]

    return f


def _sway(lo: np.ndarray, hi: np.ndarray) -> TrilinearGrid:
    """The root's lattice over the box ``[lo, hi]``: the top sways sideways (x) by a
    fifth of the height, quadratically."""
    size = hi - lo

    def f(u: np.ndarray) -> np.ndarray:
        p = lo + u * size
        p[:, 0] += 0.2 * size[2] * u[:, 2] ** 2
        return p

    return TrilinearGrid.from_function(f, (2, 2, 4))


def helix_scene(
    objects: int = 4617, triangles: int = 164_000, *, row: LatticeFpsRow | None = None
) -> GrappScene:
    """The paper's "helix" rows: ``objects`` low-resolution spheres, ``triangles`` in all,
    in a rope of :data:`ROPE_SIDE` ² spheres across wound into a helix (see the module
    docstring)."""
    per_slice = ROPE_SIDE**2
    per_seg = per_slice * SEGMENT_SLICES
    slices = math.ceil(objects / per_slice)
    length, width, seg = slices * SLOT, ROPE_SIDE * SLOT, SEGMENT_SLICES * SLOT
    spheres = iter(sphere_meshes(triangles, objects, 0.45 * SLOT))
    centre, _ = helix_frame(np.linspace(0.0, length, 64), length)
    lo, hi = centre.min(0) - 2 * width, centre.max(0) + 2 * width
    graphs = {
        "trilinear": SceneNode("helix trilinear", _sway(lo, hi), box=(lo, hi)),
        "linear": SceneNode("helix linear", np.eye(4)),
    }
    box = (np.zeros(3), np.array([seg, width, width]))
    for g in range(math.ceil(objects / per_seg)):
        x0 = g * seg
        lattice = TrilinearGrid.from_function(_helix_map(x0, seg, width, length), (4, 1, 1))
        mid, fr = helix_frame(np.array([x0 + seg / 2]), length)
        rigid = _rigid(fr[0], mid[0]) @ _translate(-box[1] / 2)
        tri = graphs["trilinear"].add(SceneNode(f"segment {g}", lattice, box=box))
        lin = graphs["linear"].add(SceneNode(f"segment {g}", rigid))
        for k in range(min(per_seg, objects - g * per_seg)):
            i, j, m = k // per_slice, (k // ROPE_SIDE) % ROPE_SIDE, k % ROPE_SIDE
            slot = _translate((np.array([i, j, m]) + 0.5) * SLOT)
            mesh = next(spheres)
            tri.add(_placed(f"sphere {g}.{k}", slot, mesh))
            lin.add(_placed(f"sphere {g}.{k}", slot, mesh))
    layout = (
        f"a rope of {ROPE_SIDE}x{ROPE_SIDE} spheres in {len(graphs['linear'].children)}"
        f" segments, {TURNS} turns; per object a sway and a segment lattice composed"
    )
    row = row or LATTICE_FPS[1]
    return GrappScene(f"helix_{objects}", row, graphs, (30.0, 25.0), layout)


def paper_scenes() -> dict[str, Callable[[], GrappScene]]:
    """The builders of the paper's three rows (:data:`LATTICE_FPS`), each with its row's
    object and triangle counts, by scene key (``spheres``, ``helix_4617``, ``helix_2566``)."""
    out: dict[str, Callable[[], GrappScene]] = {}
    for row in LATTICE_FPS:
        build = spheres_scene if row.scene == "spheres" else helix_scene
        key = "spheres" if row.scene == "spheres" else f"helix_{row.objects}"
        out[key] = functools.partial(build, row.objects, row.triangle_count, row=row)
    return out
