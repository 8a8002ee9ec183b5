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
    "ChainMail": "voxwarp.deform.elements.chainmail",
    "MoveStats": "voxwarp.deform.elements.chainmail",
    "ChainMailError": "voxwarp.deform.elements.chainmail_model",
    "DisplacementFieldWarp": "voxwarp.deform.fields.displacement",
    "ElementGrid": "voxwarp.deform.elements.grid",
    "ElementGridError": "voxwarp.deform.elements.grid",
    "ElementModel": "voxwarp.deform.elements.model",
    "LatticeWarp": "voxwarp.deform.lattice.warp",
    "CpuSpringSolver": "voxwarp.deform.elements.massspring",
    "MassSpring": "voxwarp.deform.elements.massspring",
    "OffsetFieldWarp": "voxwarp.deform.elements.offset_field",
    "SceneNode": "voxwarp.deform.lattice.scene_graph",
    "compose_scene": "voxwarp.deform.lattice.scene_graph",
    "TrilinearGrid": "voxwarp.deform.lattice.trilinear",
    "TrilinearTransform": "voxwarp.deform.lattice.trilinear",
    "AffineWarp": "voxwarp.deform.warp",
    "IdentityWarp": "voxwarp.deform.warp",
    "Warp": "voxwarp.deform.warp",
    "WarpError": "voxwarp.deform.warp",
    "chain_apply": "voxwarp.deform.warp",
    "compose_glsl": "voxwarp.deform.warp",
    "known_warps": "voxwarp.deform.warp",
    "register_warp": "voxwarp.deform.warp",
    "warp_from_dict": "voxwarp.deform.warp",
    "Wire": "voxwarp.deform.wires.wire",
    "WireDeformer": "voxwarp.deform.wires.build",
    "WireFieldWarp": "voxwarp.deform.wires.warp",
}

__all__ = sorted(_PUBLIC)


__getattr__, __dir__ = exports(__name__, _PUBLIC)


if TYPE_CHECKING:  # for type checkers and IDEs; at run time __getattr__ loads these
    from voxwarp.deform.elements.chainmail import ChainMail, MoveStats
    from voxwarp.deform.elements.chainmail_model import ChainMailError
    from voxwarp.deform.elements.grid import ElementGrid, ElementGridError
    from voxwarp.deform.elements.massspring import CpuSpringSolver, MassSpring
    from voxwarp.deform.elements.model import ElementModel
    from voxwarp.deform.elements.offset_field import OffsetFieldWarp
    from voxwarp.deform.fields.displacement import DisplacementFieldWarp
    from voxwarp.deform.lattice.scene_graph import SceneNode, compose_scene
    from voxwarp.deform.lattice.trilinear import TrilinearGrid, TrilinearTransform
    from voxwarp.deform.lattice.warp import LatticeWarp
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
    from voxwarp.deform.wires.build import WireDeformer
    from voxwarp.deform.wires.warp import WireFieldWarp
    from voxwarp.deform.wires.wire import Wire
