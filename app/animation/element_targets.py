"""Animation target of element models (mass-spring, ChainMail): ``elements.drag``."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from voxwarp.animation.target_family import Binding, Keys, TargetFamily, TrackLike
from voxwarp.animation.values import AnimationError, array, key_weights
from voxwarp.deform.elements.offset_field import OffsetFieldWarp

if TYPE_CHECKING:
    from voxwarp.scene import Scene

_MODELS = ("massspring", "chainmail")


class ElementTargets(TargetFamily):
    """Held elements of the scene's one element model; several tracks may hold elements."""

    names = ("elements.drag",)
    families = ("massspring", "chainmail")
    repeatable = True
    takes_elements = True

    def check_value(self, target: str, value: Any, what: str) -> None:
        if value is not None:
            array(value, f"{what} (an offset in mm)")

    def elements(self, d: Mapping[str, Any], keys: Keys, where: str) -> list[list[int]]:
        if "elements" not in d:
            raise AnimationError(
                f"{where} needs 'elements': the [i, j, k] indices of the held elements"
            )
        e = d["elements"]
        a = array(e, f"{where}: elements", None)
        if a.ndim == 1:
            a = a.reshape(1, -1)
        if a.ndim != 2 or a.shape[1] != 3 or len(a) == 0 or np.any(a != np.round(a)):
            raise AnimationError(
                f"{where}: elements must be a list of integer [i, j, k] indices; got {e!r:.60}"
            )
        elements = a.astype(int).tolist()
        for n, (_, v) in enumerate(keys):
            if v is not None and np.shape(v) not in ((3,), (len(elements), 3)):
                raise AnimationError(
                    f"{where}: key {n}'s offset must be [dx, dy, dz] or one per element"
                    f" ({len(elements)}x3), or null; got shape {np.shape(v)}"
                )
        return elements

    def bind(self, base: Scene, template: dict[str, Any], target: str) -> Binding:
        # the element models load scipy: only a scene with drag tracks needs them
        from voxwarp.deform.elements.chainmail import ChainMail
        from voxwarp.deform.elements.massspring import MassSpring

        k = _model_warp(base)
        w = base.warps[k]
        cls = MassSpring if w.model_state["type"] == "massspring" else ChainMail
        model = cls.from_warp(w)
        if isinstance(model, ChainMail):
            model.relax_steps = 0  # relax_steps per frame run in ElementBinding.step
        return ElementBinding(model, k, (w.inverse, w.iterations))


def _model_warp(base: Scene) -> int:
    """Index of the scene's one offset-field warp saved with its element model."""
    hits = [
        n
        for n, w in enumerate(base.warps)
        if isinstance(w, OffsetFieldWarp)
        and isinstance(w.model_state, Mapping)
        and w.model_state.get("type") in _MODELS
    ]
    if len(hits) != 1:
        raise AnimationError(
            "track elements.drag needs a scene with exactly one mass-spring or ChainMail"
            f" model (an offset_field warp saved with its model); this scene has"
            f" {len(hits)}: save one from the editor or with `voxwarp render"
            " --massspring/--chainmail ... --save-scene`"
        )
    return hits[0]


class ElementBinding(Binding):
    """Drag tracks bound to the scene's element ``model`` (simulated frame by frame)."""

    def __init__(self, model: Any, warp: int, inverse: tuple[str, int]) -> None:
        self.model = model
        self.warp = warp
        self.inverse = inverse
        #: this frame's drags: (element indices, offsets or None to release)
        self.drags: list[tuple[np.ndarray, Any]] = []

    def resolve(self, track: TrackLike, value: Any, what: str, first: Any) -> Any:
        self.model.grid.indices(np.asarray(track.elements))  # inside the grid?
        if value is None:
            return None
        a = np.asarray(value, dtype=np.float64)
        return np.broadcast_to(a, (len(track.elements or []), 3)).copy()

    def apply(self, d: dict[str, Any], track: TrackLike, keys: Keys, f: float) -> None:
        offsets = drag_at(keys, f, track.interpolation)
        self.drags.append((np.asarray(track.elements), offsets))

    def step(self, d: dict[str, Any], index: int, steps: int, relax: int) -> None:
        from voxwarp.deform.elements.massspring import MassSpring  # scipy, as in bind

        drags, self.drags = self.drags, []
        try:
            for elements, offsets in drags:
                if offsets is None:
                    self.model.release(elements)
                else:
                    self.model.move(elements, offsets)
            if isinstance(self.model, MassSpring):
                self.model.step(steps)
            else:
                self.model.relax(relax)
        except (ValueError, TypeError) as exc:
            raise AnimationError(f"frame {index}: elements.drag: {exc}") from exc
        inverse, iterations = self.inverse
        warp = self.model.warp(inverse=inverse, iterations=iterations)
        d["warps"][self.warp] = warp.to_dict()

    def close(self) -> None:
        if self.model is not None:
            self.model.close()
            self.model = None


def drag_at(keys: Keys, f: float, interpolation: str) -> Any:
    """Offsets of a drag track at ``f`` (None: released); steps across null keys."""
    i, j, t = key_weights([k[0] for k in keys], f, interpolation)
    a, b = keys[i][1], keys[j][1]
    if t == 0.0 or a is None or b is None:
        return None if a is None else np.array(a, dtype=np.float64)
    return a + t * (b - a)
