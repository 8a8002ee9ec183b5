"""Animation targets of the deformation families: one handler per family, registered here.

:mod:`voxwarp.animation.tracks` asks this registry about every target that is not a scene
attribute (camera, transfer function, numbers): which family keys it, how its values are
checked, and how it binds to a scene. Adding a family's targets is one module with a
:class:`~voxwarp.animation.target_family.TargetFamily` and one entry in
:data:`TARGET_FAMILIES`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from voxwarp.animation.element_targets import ElementTargets
from voxwarp.animation.lattice_targets import LatticeTargets
from voxwarp.animation.mesh_targets import MeshTargets
from voxwarp.animation.target_family import Binding, Keys, TargetFamily
from voxwarp.animation.values import AnimationError
from voxwarp.animation.wire_targets import WireTargets

__all__ = [
    "EXTRA_KEYS",
    "FAMILY_TARGET_NAMES",
    "TARGET_FAMILIES",
    "Binding",
    "TargetFamily",
    "family_of",
    "repeatable",
    "track_elements",
    "track_extras",
]

#: one handler per deformation family, in the order :data:`FAMILY_TARGET_NAMES` lists them
TARGET_FAMILIES: tuple[TargetFamily, ...] = (
    WireTargets(),
    LatticeTargets(),
    ElementTargets(),
    MeshTargets(),
)
#: every family target (``i``: a wire's index)
FAMILY_TARGET_NAMES: tuple[str, ...] = tuple(n for f in TARGET_FAMILIES for n in f.names)
#: track entries some family takes besides target, keys, interpolation and elements
EXTRA_KEYS: tuple[str, ...] = tuple(k for f in TARGET_FAMILIES for k in f.extra_keys)


def family_of(target: str) -> TargetFamily | None:
    """The family that keys ``target`` (None: a scene attribute, or unknown)."""
    return next((f for f in TARGET_FAMILIES if f.matches(target)), None)


def repeatable(target: str) -> bool:
    """Whether several tracks may key ``target``."""
    family = family_of(target)
    return family is not None and family.repeatable


def track_elements(
    target: str, d: Mapping[str, Any], keys: Keys, where: str
) -> list[list[int]] | None:
    """The checked ``"elements"`` of track entry ``d`` (None for targets without them)."""
    family = family_of(target)
    if family is not None and family.takes_elements:
        return family.elements(d, keys, where)
    if "elements" in d:
        owners = [n for f in TARGET_FAMILIES if f.takes_elements for n in f.names]
        raise AnimationError(f"{where}: 'elements' belongs to {', '.join(owners)} tracks only")
    return None


def track_extras(target: str, d: Mapping[str, Any], where: str) -> dict[str, Any]:
    """The checked family entries (:data:`EXTRA_KEYS`) of track entry ``d``."""
    family = family_of(target)
    for key in EXTRA_KEYS:
        if key in d and (family is None or key not in family.extra_keys):
            owners = [n for f in TARGET_FAMILIES if key in f.extra_keys for n in f.names]
            raise AnimationError(f"{where}: {key!r} belongs to {', '.join(owners)} tracks only")
    return family.extras(d, where) if family is not None else {}
