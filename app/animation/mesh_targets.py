"""Animation target of the mesh scene graph: ``meshes[NAME].nodes``, with attachments.

The GRAPP 2010 paper animates a base mesh and lets attached geometry follow it (section
5, Figure 8): anchors sit on the base mesh's triangles (barycentric), and each frame the
attachments' lattices are rebuilt from the anchors on the moved base mesh. Here the base
mesh moves by its own lattice: a ``meshes[NAME].nodes`` track keys the node grid of the
mesh instance named ``NAME`` (or ``"rest"``: the undeformed lattice over its box), and
its optional ``"attachments"`` entry lists the meshes that follow it::

    {"target": "meshes[body].nodes", "interpolation": "smooth",
     "keys": [[0, [[[[x, y, z], ...]]]], [12, "rest"]],
     "attachments": [{"mesh": "band 0", "anchors": [{"triangle": 5, "position": [...],
                      "tangent": [...]}, ...], "thickness": 1.2, "width": 4.0}]}

An attachment is :meth:`voxwarp.deform.lattice.anchors.AnchorStrip.to_dict` plus the attached
instance's ``"mesh"`` name. For every frame the base's nodes are interpolated, its
vertices mapped through them, the anchors evaluated on those vertices and each
attachment's grid set to :meth:`AnchorStrip.nodes
<voxwarp.deform.lattice.anchors.AnchorStrip.nodes>`
there: the attached geometry follows the base exactly as the static scene built at that
pose would place it.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from voxwarp.animation.target_family import Binding, Keys, TargetFamily, TrackLike
from voxwarp.animation.values import AnimationError, array, interpolate
from voxwarp.core.mesh import MeshInstance
from voxwarp.deform.lattice.anchors import AnchorStrip
from voxwarp.deform.lattice.trilinear import TrilinearGrid
from voxwarp.deform.warp import WarpError

if TYPE_CHECKING:
    from voxwarp.scene import Scene

_TARGET = re.compile(r"^meshes\[([^\]]+)\]\.nodes$")


def mesh_name(target: str) -> str:
    """The mesh instance name of a ``meshes[NAME].nodes`` target."""
    m = _TARGET.match(target)
    assert m is not None
    return m.group(1)


def _attachment(a: Any, where: str) -> dict[str, Any]:
    """One checked attachment entry (its anchor array parsed, then kept as JSON)."""
    if not isinstance(a, Mapping) or not isinstance(a.get("mesh"), str):
        raise AnimationError(f"{where}: an attachment needs 'mesh' (the attached mesh's name)")
    strip = {k: v for k, v in a.items() if k != "mesh"}
    try:
        AnchorStrip.from_dict(strip)
    except WarpError as exc:
        raise AnimationError(f"{where}: attachment {a['mesh']!r}: {exc}") from exc
    return dict(a)


class MeshTargets(TargetFamily):
    """The lattice nodes of a named mesh instance, and the meshes anchored to it."""

    names = ("meshes[NAME].nodes",)
    pattern = _TARGET.pattern
    extra_keys = ("attachments",)

    def matches(self, target: str) -> bool:
        return _TARGET.match(target) is not None

    def check_value(self, target: str, value: Any, what: str) -> None:
        if not (isinstance(value, str) and value == "rest"):
            array(value, f"{what} (mesh lattice nodes)", (None, None, None, 3))

    def extras(self, d: Mapping[str, Any], where: str) -> dict[str, Any]:
        if "attachments" not in d:
            return {}
        raw = d["attachments"]
        if not isinstance(raw, list):
            raise AnimationError(f"{where}: 'attachments' must be a list of attachment objects")
        return {"attachments": [_attachment(a, where) for a in raw]}

    def bind(self, base: Scene, template: dict[str, Any], target: str) -> Binding:
        return MeshBinding(base, template)


class MeshBinding(Binding):
    """Mesh tracks bound to the meshes of ``base`` (``template``: its JSON form)."""

    def __init__(self, base: Scene, template: dict[str, Any]) -> None:
        self.meshes = base.meshes
        self.template = template
        #: mesh name -> the target that moves it (a base or an attachment: one each)
        self.claimed: dict[str, str] = {}
        #: target -> [(mesh index, anchor array)] of its attachments
        self.attached: dict[str, list[tuple[int, AnchorStrip]]] = {}

    def _index(self, name: str, what: str) -> int:
        hits = [i for i, m in enumerate(self.meshes) if m.name == name]
        if len(hits) != 1:
            names = ", ".join(repr(m.name) for m in self.meshes) or "none"
            fix = "use one of the scene's meshes" if not hits else "give each mesh its own name"
            raise AnimationError(
                f"{what}: {len(hits) or 'no'} mesh(es) named {name!r}; {fix} (meshes: {names})"
            )
        return hits[0]

    def _claim(self, name: str, target: str, what: str) -> int:
        i = self._index(name, what)
        if name in self.claimed:
            raise AnimationError(
                f"{what}: mesh {name!r} is already moved by track {self.claimed[name]};"
                " key or attach each mesh once"
            )
        self.claimed[name] = target
        return i

    def _bind_track(self, track: TrackLike, what: str) -> None:
        """Claim the track's base mesh and attachments; check the anchors fit the base."""
        target = track.target
        base = self.meshes[self._claim(mesh_name(target), target, what)]
        if not base.is_lattice:
            raise AnimationError(
                f"{what}: mesh {base.name!r} is placed by a matrix; give it a lattice"
                " transform ({'grid': ...}) to key its nodes"
            )
        strips = []
        saved = base.world_vertices()  # the base as the scene saves it
        for a in track.extras.get("attachments", []):
            j = self._claim(a["mesh"], target, what)
            strip = AnchorStrip.from_dict({k: v for k, v in a.items() if k != "mesh"})
            try:
                strip.nodes(saved, base.mesh.faces)
            except WarpError as exc:
                raise AnimationError(f"{what}: attachment {a['mesh']!r}: {exc}") from exc
            strips.append((j, strip))
        self.attached[target] = strips

    def resolve(self, track: TrackLike, value: Any, what: str, first: Any) -> Any:
        if track.target not in self.attached:
            self._bind_track(track, what)
        inst = self.meshes[self._index(mesh_name(track.target), what)]
        shape = np.asarray(inst.transform.nodes).shape
        if isinstance(value, str) and value == "rest":
            lo, hi = inst.box
            return np.array(TrilinearGrid.from_box(lo, hi, [n - 1 for n in shape[:3]]).nodes)
        a = np.asarray(value, dtype=np.float64)
        if a.shape != shape:
            raise AnimationError(
                f"{what}: mesh {inst.name!r}'s lattice nodes must have its lattice's shape"
                f" {shape}; got {a.shape}"
            )
        return a

    def apply(self, d: dict[str, Any], track: TrackLike, keys: Keys, f: float) -> None:
        if d.get("meshes") is self.template.get("meshes"):  # first mesh track of this frame
            d["meshes"] = list(self.template["meshes"])
        i = self._index(mesh_name(track.target), track.target)
        nodes = interpolate(keys, f, track.interpolation)
        _set_grid(d, i, nodes)
        inst = self.meshes[i]
        moved = _with_grid(inst, TrilinearGrid(nodes))
        vertices, faces = moved.world_vertices(), inst.mesh.faces
        for j, strip in self.attached[track.target]:
            try:
                _set_grid(d, j, strip.nodes(vertices, faces))
            except WarpError as exc:
                raise AnimationError(
                    f"track {track.target} at frame {f:g}: attachment"
                    f" {self.meshes[j].name!r}: {exc}"
                ) from exc


def _with_grid(inst: MeshInstance, grid: Any) -> MeshInstance:
    """A copy of ``inst`` placed by ``grid`` (its box kept)."""
    return MeshInstance(inst.mesh, grid, box=inst.box, name=inst.name)


def _set_grid(d: dict[str, Any], i: int, nodes: np.ndarray) -> None:
    """Set mesh ``i``'s lattice in frame dict ``d`` (a copy of its entry)."""
    d["meshes"][i] = {**d["meshes"][i], "transform": {"grid": {"nodes": nodes.tolist()}}}
