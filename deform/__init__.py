"""voxwarp deformation models (offset field, wire field, trilinear lattice).

Each model has a CPU reference and a GPU backend and exposes its result as a warp
(:class:`voxwarp.deform.warp.Warp`) that the raycaster samples without resampling the
volume. Names load on first use (the models pull in numba, scipy and pyopencl).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from voxwarp.lazy import exports

#: public name -> module that defines it (imported on first access)
_PUBLIC: dict[str, str] = {
    "ChainMail": "voxwarp.deform.chainmail",
    "MoveStats": "voxwarp.deform.chainmail",
    "ChainMailError": "voxwarp.deform.chainmail_model",
    "DisplacementFieldWarp": "voxwarp.deform.displacement_field",
    "ElementGrid": "voxwarp.deform.elements",
    "ElementGridError": "voxwarp.deform.elements",
    "ElementModel": "voxwarp.deform.element_model",
    "LatticeWarp": "voxwarp.deform.lattice_warp",
    "CpuSpringSolver": "voxwarp.deform.massspring",
    "MassSpring": "voxwarp.deform.massspring",
    "OffsetFieldWarp": "voxwarp.deform.offset_field",
    "SceneNode": "voxwarp.deform.scene_graph",
    "compose_scene": "voxwarp.deform.scene_graph",
    "TrilinearGrid": "voxwarp.deform.trilinear",
    "TrilinearTransform": "voxwarp.deform.trilinear",
    "AffineWarp": "voxwarp.deform.warp",
    "IdentityWarp": "voxwarp.deform.warp",
    "Warp": "voxwarp.deform.warp",
    "WarpError": "voxwarp.deform.warp",
    "chain_apply": "voxwarp.deform.warp",
    "compose_glsl": "voxwarp.deform.warp",
    "known_warps": "voxwarp.deform.warp",
    "register_warp": "voxwarp.deform.warp",
    "warp_from_dict": "voxwarp.deform.warp",
    "Wire": "voxwarp.deform.wires",
    "WireDeformer": "voxwarp.deform.wires",
    "WireFieldWarp": "voxwarp.deform.wires",
}

__all__ = sorted(_PUBLIC)


__getattr__, __dir__ = exports(__name__, _PUBLIC)


if TYPE_CHECKING:  # for type checkers and IDEs; at run time __getattr__ loads these
    from voxwarp.deform.chainmail import ChainMail, MoveStats
    from voxwarp.deform.chainmail_model import ChainMailError
    from voxwarp.deform.displacement_field import DisplacementFieldWarp
    from voxwarp.deform.element_model import ElementModel
    from voxwarp.deform.elements import ElementGrid, ElementGridError
    from voxwarp.deform.lattice_warp import LatticeWarp
    from voxwarp.deform.massspring import CpuSpringSolver, MassSpring
    from voxwarp.deform.offset_field import OffsetFieldWarp
    from voxwarp.deform.scene_graph import SceneNode, compose_scene
    from voxwarp.deform.trilinear import TrilinearGrid, TrilinearTransform
    from voxwarp.deform.warp import (
        AffineWarp,
        IdentityWarp,
        Warp,
        WarpError,
        chain_apply,
        compose_glsl,
        known_warps,
        register_warp,
        warp_from_dict,
    )
    from voxwarp.deform.wires import Wire, WireDeformer, WireFieldWarp
