"""One adapter per deformation family, registered by name (as napari's
``layer_to_visual``): the edit session, keyframes and panels look a family up here and
never switch on it. A new family: its warp and shader in ``deform/``, an adapter class
(:class:`~voxwarp.editing.families.base.Family`) in a file here, its entry below, and a
panel in ``ui/``."""

from __future__ import annotations

from voxwarp.editing.families.base import Family
from voxwarp.editing.families.elements import ChainMailFamily, MassSpringFamily
from voxwarp.editing.families.lattice import LatticeFamily
from voxwarp.editing.families.wires import WireBuild, WiresFamily

#: family name -> adapter class, in the order the GUI offers them
FAMILIES: dict[str, type[Family]] = {
    cls.kind: cls for cls in (Family, MassSpringFamily, ChainMailFamily, WiresFamily, LatticeFamily)
}

__all__ = ["FAMILIES", "Family", "WireBuild"]
