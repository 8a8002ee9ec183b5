"""The interface of a deformation family's animation targets.

A :class:`TargetFamily` names a family's targets and checks their key values without a
scene; :meth:`TargetFamily.bind` finds the family's warp in a scene and returns a
:class:`Binding`, which resolves key values against it and writes each frame's state.
The evaluator of :mod:`voxwarp.animation.tracks` only talks to these two classes.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

from voxwarp.animation.values import AnimationError

if TYPE_CHECKING:
    from voxwarp.scene import Scene

#: ``(frame, value)`` pairs of a track, resolved against the scene
Keys = Sequence[tuple[float, Any]]


class TrackLike(Protocol):
    """What a family reads of a track (:class:`voxwarp.animation.tracks.Track` is one)."""

    target: str
    interpolation: str
    elements: list[list[int]] | None
    extras: dict[str, Any]


class Binding:
    """A family's targets bound to one scene for one evaluation (keys, frames, physics)."""

    def resolve(self, track: TrackLike, value: Any, what: str, first: Any) -> Any:
        """A key value checked against the scene (``first``: the track's first, resolved)."""
        raise NotImplementedError

    def apply(self, d: dict[str, Any], track: TrackLike, keys: Keys, f: float) -> None:
        """Write ``track``'s value at animation time ``f`` into frame dict ``d``."""
        raise NotImplementedError

    def step(self, d: dict[str, Any], index: int, steps: int, relax: int) -> None:
        """Advance the family's physics by frame ``index`` (after every track applied)."""

    def check(self, d: dict[str, Any]) -> None:
        """Cheap checks of the family's warp entry in frame dict ``d``."""

    def close(self) -> None:
        """Free what the binding holds (a physics model)."""


class TargetFamily:
    """The animation targets of one deformation family (one instance, registered in
    :data:`voxwarp.animation.targets.TARGET_FAMILIES`)."""

    #: the family's targets as listed in :data:`voxwarp.animation.tracks.TARGETS`
    names: ClassVar[tuple[str, ...]] = ()
    #: the regular expression :meth:`matches` uses when :attr:`names` hold placeholders
    #: (``wires[i]...``; the animation JSON Schema takes it too)
    pattern: ClassVar[str | None] = None
    #: the deformation families (:data:`voxwarp.editing.families.FAMILIES` keys) these
    #: targets key (none for the meshes, which follow the scene's warps)
    families: ClassVar[tuple[str, ...]] = ()
    #: whether several tracks may key one target
    repeatable: ClassVar[bool] = False
    #: whether its tracks take an ``"elements"`` entry
    takes_elements: ClassVar[bool] = False
    #: further entries its tracks take (kept in :attr:`Track.extras
    #: <voxwarp.animation.tracks.Track.extras>`)
    extra_keys: ClassVar[tuple[str, ...]] = ()

    def matches(self, target: str) -> bool:
        """Whether ``target`` is one of the family's."""
        return target in self.names

    def check_value(self, target: str, value: Any, what: str) -> None:
        """Checks of a key value that need no scene (raise :class:`AnimationError`)."""
        raise NotImplementedError

    def elements(self, d: Mapping[str, Any], keys: Keys, where: str) -> list[list[int]]:
        """The checked ``"elements"`` entry of track ``d`` (families that take it)."""
        raise AnimationError(f"{where}: this target takes no 'elements'")

    def extras(self, d: Mapping[str, Any], where: str) -> dict[str, Any]:
        """The checked :attr:`extra_keys` entries of track ``d`` (JSON values), those
        present only."""
        return {}

    def bind(self, base: Scene, template: dict[str, Any], target: str) -> Binding:
        """Find the family's warp in ``base`` (``template``: its JSON form) for a track
        of ``target``; raise :class:`AnimationError` when the scene has none to key."""
        raise NotImplementedError


def find_warp(scene: Scene, cls: type, what: str, target: str) -> int:
    """Index of the scene's one warp of class ``cls`` (``what`` names it for ``target``)."""
    hits = [n for n, w in enumerate(scene.warps) if isinstance(w, cls)]
    if len(hits) != 1:
        raise AnimationError(
            f"track {target} needs a scene with exactly one {what} warp; this scene has"
            f" {len(hits)} (warps: {[w.kind for w in scene.warps]})"
        )
    return hits[0]
