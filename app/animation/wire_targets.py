"""Animation targets of wires: ``wires[i].modified``, ``wires[i].twist``, ``wires[i].scale``."""

from __future__ import annotations

import copy
import re
from typing import TYPE_CHECKING, Any

import numpy as np

from voxwarp.animation.target_family import Binding, Keys, TargetFamily, TrackLike, find_warp
from voxwarp.animation.values import AnimationError, array, interpolate, number

if TYPE_CHECKING:
    from voxwarp.scene import Scene

_TARGET = re.compile(r"^wires\[(\d+)\]\.(modified|twist|scale)$")


def _parts(target: str) -> tuple[int, str]:
    """Wire index and part of a wire target."""
    m = _TARGET.match(target)
    assert m is not None
    return int(m.group(1)), m.group(2)


class WireTargets(TargetFamily):
    """Wire ``i``'s modified curve, twist or scale keys in the scene's one wires warp."""

    names = ("wires[i].modified", "wires[i].twist", "wires[i].scale")
    pattern = _TARGET.pattern
    families = ("wires",)

    def matches(self, target: str) -> bool:
        return _TARGET.match(target) is not None

    def check_value(self, target: str, value: Any, what: str) -> None:
        part = _parts(target)[1]
        if part == "modified":
            array(value, f"{what} (control points)", (None, 3))
        elif not isinstance(value, int | float) or isinstance(value, bool):
            array(value, f"{what} ({part} keys [[u, value], ...])", (None, 2))
        else:
            number(value, what)

    def bind(self, base: Scene, template: dict[str, Any], target: str) -> Binding:
        # the wire field loads scipy: only a scene with wire tracks needs it
        from voxwarp.deform.wires.field import WireFieldWarp

        return WireBinding(template, find_warp(base, WireFieldWarp, "wires", target))


class WireBinding(Binding):
    """Wire tracks bound to warp ``warp`` of a scene's JSON form ``template``."""

    def __init__(self, template: dict[str, Any], warp: int) -> None:
        self.template = template
        self.warp = warp

    def resolve(self, track: TrackLike, value: Any, what: str, first: Any) -> Any:
        from voxwarp.deform.wires.field import Wire  # scipy, as in bind

        wires = self.template["warps"][self.warp]["wires"]
        i, part = _parts(track.target)
        if i >= len(wires):
            raise AnimationError(
                f"{what}: no wire {i}; the scene's wire warp has {len(wires)} wire(s)"
                f" (indices 0..{len(wires) - 1})"
            )
        if part != "modified" and isinstance(value, int | float):
            a = np.array([[0.0, float(value)]])
        else:
            a = np.asarray(value, dtype=np.float64)
        if first is not None and first.shape != a.shape:
            raise AnimationError(
                f"{what}: every key of {track.target} needs the same shape to be interpolated;"
                f" {a.shape} here, {first.shape} in the first key"
            )
        entry = dict(wires[i])
        entry[part] = a.tolist()
        Wire.from_dict(entry)  # validates: Bézier counts, u in [0, 1], scale > 0
        return a

    def apply(self, d: dict[str, Any], track: TrackLike, keys: Keys, f: float) -> None:
        k = self.warp
        if d["warps"][k] is self.template["warps"][k]:  # first wire track of this frame
            d["warps"][k] = copy.deepcopy(d["warps"][k])
        i, part = _parts(track.target)
        value = interpolate(keys, f, track.interpolation)
        d["warps"][k]["wires"][i][part] = value.tolist()

    def check(self, d: dict[str, Any]) -> None:
        from voxwarp.deform.wires.field import Wire  # scipy, as in bind

        for w in d["warps"][self.warp]["wires"]:
            Wire.from_dict(w)
