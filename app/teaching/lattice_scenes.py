"""The trilinear-lattice demo scenes (GRAPP 2010, Figures 1, 6, 8 and 9), built headless.

* :func:`torus_tubes`: a 2D arrangement of straight tubes, side by side and touching,
  laid in a flat slab whose scene-graph node carries a grid of trilinear cells that wraps
  the slab around a torus (Figure 1): every tube closes into a ring, and neighbours stay
  in contact because the lattice is continuous.
* :func:`torus_tiles`: one bumpy tile repeated m x n times in the slab and mapped onto
  the torus the same way (Figure 9): the tiles meet with C0 seams.
* :func:`accessories`: a tube-shaped body bent by its own lattice, with two bands and a
  plate attached through anchors on its triangles (section 5, Figures 6 and 8, with our
  own meshes): the attachments' grids are rebuilt from the bent body, so they follow it.
* :func:`accessories_anim`: the same body swaying one way and the other over 25 frames
  (Figure 8 as an animation): a ``meshes[body].nodes`` track keys its lattice and carries
  the anchors, so each frame rebuilds the attachments' grids on the moved body
  (:mod:`voxwarp.animation.mesh_targets`); ``voxwarp animate
  sample_volumes/lattice_accessories_anim.json -o body.mp4`` renders it.

Each returns a :class:`voxwarp.scene.Scene` (meshes over a 2³ empty volume, the documented
mesh-only convention). ``scripts/make_lattice_demos.py`` writes them to
``sample_volumes/lattice_*.json``; ``voxwarp render sample_volumes/lattice_torus_tubes.json
-o tubes.png`` renders one.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from voxwarp.animation.tracks import Animation, Track
from voxwarp.core.mesh import (
    PALETTE,
    Mesh,
    MeshInstance,
    box_mesh_tessellated,
    height_tile,
    instances_from_scene_graph,
    tube_mesh,
)
from voxwarp.core.volume import Volume
from voxwarp.deform.lattice.anchors import Anchor, AnchorStrip
from voxwarp.deform.lattice.scene_graph import SceneNode
from voxwarp.deform.lattice.trilinear import TrilinearGrid
from voxwarp.scene import Scene


def empty_volume() -> Volume:
    """The 2³ empty volume that carries a mesh-only scene."""
    return Volume(np.zeros((2, 2, 2), np.uint8), name="empty")


def torus_map(major: float, minor: float, thickness: float) -> Callable[[np.ndarray], np.ndarray]:
    """Unit slab -> torus shell: u around the major circle, v around the minor one, w
    outwards from the minor radius ``minor`` to ``minor + thickness`` (mm)."""

    def f(u: np.ndarray) -> np.ndarray:
        theta = 2 * np.pi * u[:, 0]
        phi = 2 * np.pi * u[:, 1]
        rho = minor + thickness * u[:, 2]
        ring = major + rho * np.cos(phi)
        return np.stack([ring * np.cos(theta), ring * np.sin(theta), rho * np.sin(phi)], -1)

    return f


def _translate(t: tuple[float, float, float]) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = t
    return m


def _scene(instances: list[MeshInstance], view: tuple[float, float]) -> Scene:
    return Scene(empty_volume(), view=view, meshes=instances, background=(0.08, 0.09, 0.11, 1.0))


def torus_tubes(
    tubes: int = 12, tube_radius: float = 2.0, major: float = 40.0, minor: float = 9.0
) -> Scene:
    """Figure 1: ``tubes`` touching tubes wrapped around a torus by one lattice node."""
    length = 100.0  # the slab's extent around the major circle (its units are free)
    height = tubes * 2 * tube_radius
    thickness = 2 * tube_radius
    grid = TrilinearGrid.from_function(torus_map(major, minor, thickness), (48, 4 * tubes, 1))
    root = SceneNode("torus lattice", transform=grid, box=((0, 0, 0), (length, height, thickness)))
    mesh = tube_mesh(length, tube_radius)
    for i in range(tubes):
        leaf = SceneNode(
            f"tube {i}",
            transform=_translate((0.0, (2 * i + 1) * tube_radius, tube_radius)),
            box=mesh.bounds,
            geometry=MeshInstance(mesh, color=PALETTE[i % len(PALETTE)]),
        )
        root.add(leaf)
    instances = instances_from_scene_graph(root)
    # each tube spans 1/tubes of the minor circle: 2 cells across it are plenty (the
    # composition sampled it at the whole lattice's resolution)
    for inst in instances:
        inst.transform = inst.transform.resample((48, 2, 1))
    return _scene(instances, (30.0, 40.0))


def torus_tiles(
    rows: int = 8, cols: int = 24, tile: float = 10.0, major: float = 40.0, minor: float = 12.0
) -> Scene:
    """Figure 9: one tile repeated ``cols`` x ``rows`` times around a torus (C0 seams)."""
    height = 0.25 * tile
    grid = TrilinearGrid.from_function(torus_map(major, minor, height), (2 * cols, 2 * rows, 1))
    root = SceneNode(
        "torus lattice", transform=grid, box=((0, 0, 0), (cols * tile, rows * tile, height))
    )
    mesh = height_tile(tile, height)
    lo, hi = mesh.bounds
    box = (lo, np.maximum(hi, lo + np.array([0.0, 0.0, height])))
    for i in range(cols):
        for j in range(rows):
            root.add(
                SceneNode(
                    f"tile {i},{j}",
                    transform=_translate((i * tile, j * tile, 0.0)),
                    box=box,
                    geometry=MeshInstance(mesh, color=PALETTE[(i + j) % 2 + 1]),
                )
            )
    instances = instances_from_scene_graph(root)
    for inst in instances:
        inst.transform = inst.transform.resample((2, 2, 1))
    return _scene(instances, (20.0, 35.0))


def bend_map(length: float, radius: float, angle: float) -> Callable[[np.ndarray], np.ndarray]:
    """Unit box of a body along z (x, y in [-radius, radius], z in [0, length]) -> the
    body bent by ``angle`` radians about the y axis over its upper 70 %."""
    z0 = 0.3 * length
    bend_radius = (length - z0) / angle

    def f(u: np.ndarray) -> np.ndarray:
        x = (2 * u[:, 0] - 1) * radius
        y = (2 * u[:, 1] - 1) * radius
        z = u[:, 2] * length
        s = np.clip(z - z0, 0.0, None)
        a = s / bend_radius
        r = bend_radius - x
        bx = bend_radius - r * np.cos(a)
        bz = z0 + r * np.sin(a)
        return np.stack([np.where(z > z0, bx, x), y, np.where(z > z0, bz, z)], -1)

    return f


ACCESSORY_RADIUS, ACCESSORY_LENGTH = 6.0, 60.0
_RINGS, _SECTIONS = 60, 32


def accessory_body() -> tuple[Mesh, tuple[np.ndarray, np.ndarray]]:
    """The tube-shaped body standing along z, and the box its lattice acts on."""
    radius, length = ACCESSORY_RADIUS, ACCESSORY_LENGTH
    body = tube_mesh(length, radius, rings=_RINGS, sections=_SECTIONS)
    # the tube runs along x: stand it up along z
    turn = np.array([[0, 0, -1, 0], [0, 1, 0, 0], [1, 0, 0, 0], [0, 0, 0, 1.0]])
    v = np.c_[body.vertices, np.ones(len(body.vertices))] @ turn.T
    # normals from the faces, as a scene file stores the turned body inline and its
    # loader computes them
    body = Mesh.from_arrays(v[:, :3], body.faces, name="body")
    box = (np.array([-radius, -radius, 0.0]), np.array([radius, radius, length]))
    return body, box


def accessory_pose(angle: float) -> TrilinearGrid:
    """The body's lattice bent by ``angle`` radians (0: straight, the box itself)."""
    body_box = accessory_body()[1]
    if angle == 0.0:
        return TrilinearGrid.from_box(*body_box, (2, 2, 24))
    return TrilinearGrid.from_function(
        bend_map(ACCESSORY_LENGTH, ACCESSORY_RADIUS, angle), (2, 2, 24)
    )


def accessory_attachments() -> list[tuple[str, AnchorStrip, Mesh, tuple[float, ...]]]:
    """The bands and the plate: ``(name, anchor array on the body, mesh, colour)``."""
    ring_step = ACCESSORY_LENGTH / (_RINGS - 1)
    sections = _SECTIONS

    def anchors(ring: int, sects: list[int]) -> list[Anchor]:
        # the centre of quad (ring, j)'s first triangle (a, c, b); the tangent point lies
        # towards the next section, so x runs around the body and y along it
        return [
            Anchor(
                ring * sections + j % sections,
                (1 / 3, 1 / 3, 1 / 3),
                (1 / 3, 1 / 3 + 0.2, 1 / 3 - 0.2),
            )
            for j in sects
        ]

    out = []
    # bands: a ring of anchors around the body, closed by repeating the first anchor
    for k, (z, colour) in enumerate(((30.0, PALETTE[2]), (48.0, PALETTE[1]))):
        ring = round(z / ring_step)
        strip = AnchorStrip(anchors(ring, list(range(sections + 1))), thickness=1.2, width=4.0)
        band = box_mesh_tessellated((1.0, 1.0, 1.0), (64, 2, 2))
        out.append((f"band {k}", strip, band, colour))
    # a plate on a 2 x 5 patch of anchors on the body's side, near its top
    top = round(54.0 / ring_step)
    patch = AnchorStrip(
        [anchors(top - 3, [11, 12, 13, 14, 15]), anchors(top + 3, [11, 12, 13, 14, 15])],
        thickness=2.5,
        offset=0.3,
    )
    plate = box_mesh_tessellated((1.0, 1.0, 1.0), (4, 6, 2))
    out.append(("plate", patch, plate, PALETTE[3]))
    return out


def accessories(angle: float = 1.2) -> Scene:
    """Figures 6 and 8: two bands and a plate anchored to a body that a lattice bends."""
    body, box = accessory_body()
    body_inst = MeshInstance(body, accessory_pose(angle), box=box, color=PALETTE[0], name="body")
    bent = body_inst.local_to_world(body.vertices)  # the base mesh as the lattice shows it
    faces = np.asarray(body.faces, dtype=np.int64)
    instances = [body_inst]
    for name, strip, mesh, colour in accessory_attachments():
        grid = strip.grid(bent, faces)
        instances.append(MeshInstance(mesh, grid, box=mesh.bounds, color=colour, name=name))
    return _scene(instances, (-60.0, 20.0))


#: the animated body's poses: (key frame, bend angle in radians; 0 = straight)
ACCESSORY_KEYS: tuple[tuple[int, float], ...] = (
    (0, 1.2),
    (6, 0.0),
    (12, -1.2),
    (18, 0.0),
    (24, 1.2),
)


_ANIM_DESCRIPTION = (
    "GRAPP 2010 Figure 8 with our own meshes: a body bent by its lattice sways one way,"
    " then the other; two bands and a plate anchored to its triangles follow it."
)


def accessories_anim(keys: tuple[tuple[int, float], ...] = ACCESSORY_KEYS) -> dict[str, Any]:
    """Figure 8 animated: the body bends one way, then the other, and back; the bands and
    the plate follow it through their anchors (scene JSON with an ``"animation"`` entry,
    a ``meshes[body].nodes`` track with ``"attachments"``, smooth interpolation)."""
    scene = accessories(keys[0][1]).copy(zoom=0.8)  # room for every pose in the held view
    values = [(f, "rest" if a == 0.0 else accessory_pose(a).nodes.tolist()) for f, a in keys]
    attachments = [{"mesh": n, **s.to_dict()} for n, s, _, _ in accessory_attachments()]
    track = Track("meshes[body].nodes", values, "smooth", extras={"attachments": attachments})
    d = {"description": _ANIM_DESCRIPTION, **scene.to_dict()}
    d["animation"] = Animation(keys[-1][0] + 1, 12.0, [track]).to_dict()
    return d


#: name -> builder of the bundled demo scenes (``sample_volumes/lattice_<name>.json``)
DEMOS: dict[str, Callable[[], Scene]] = {
    "torus_tubes": torus_tubes,
    "torus_tiles": torus_tiles,
    "accessories": accessories,
}
#: name -> builder of the bundled animated scenes (``sample_volumes/lattice_<name>.json``)
ANIMATED: dict[str, Callable[[], dict[str, Any]]] = {"accessories_anim": accessories_anim}
