"""Animation target of the lattice: ``lattice.nodes``."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from voxwarp.animation.target_family import Binding, Keys, TargetFamily, TrackLike, find_warp
from voxwarp.animation.values import AnimationError, array, interpolate

if TYPE_CHECKING:
    from voxwarp.scene import Scene


class LatticeTargets(TargetFamily):
    """The nodes of the scene's one lattice warp (or ``"rest"``)."""

    names = ("lattice.nodes",)
    families = ("lattice",)

    def check_value(self, target: str, value: Any, what: str) -> None:
        if not (isinstance(value, str) and value == "rest"):
            array(value, f"{what} (lattice nodes)", (None, None, None, 3))

    def bind(self, base: Scene, template: dict[str, Any], target: str) -> Binding:
        # the lattice warp loads scipy: only a scene with lattice tracks needs it
        from voxwarp.deform.lattice.warp import LatticeWarp

        k = find_warp(base, LatticeWarp, "lattice", target)
        return LatticeBinding(base.warps[k], k)


class LatticeBinding(Binding):
    """The lattice track bound to the scene's lattice warp ``lattice`` (index ``warp``)."""

    def __init__(self, lattice: Any, warp: int) -> None:
        self.lattice = lattice
        self.warp = warp

    def resolve(self, track: TrackLike, value: Any, what: str, first: Any) -> Any:
        w = self.lattice
        shape = np.asarray(w.grid.nodes).shape
        if isinstance(value, str) and value == "rest":
            cells = [n - 1 for n in shape[:3]]
            u = np.stack(
                np.meshgrid(*(np.linspace(0.0, 1.0, c + 1) for c in cells), indexing="ij"), -1
            )
            return w.lo + u * (w.hi - w.lo)
        a = np.asarray(value, dtype=np.float64)
        if a.shape != shape:
            raise AnimationError(
                f"{what}: lattice nodes must have the scene lattice's shape {shape}; got {a.shape}"
            )
        return a

    def apply(self, d: dict[str, Any], track: TrackLike, keys: Keys, f: float) -> None:
        entry = dict(d["warps"][self.warp])
        entry["grid"] = {"nodes": interpolate(keys, f, track.interpolation).tolist()}
        d["warps"][self.warp] = entry

    def check(self, d: dict[str, Any]) -> None:
        from voxwarp.deform.lattice.warp import LatticeWarp  # scipy, as in bind

        LatticeWarp.from_dict(d["warps"][self.warp])
