"""voxwarp deformation models (offset field, wire field, trilinear lattice).

Each model has a CPU reference and a GPU backend and exposes its result as a warp
(:class:`deform.warp.Warp`) that the raycaster samples without resampling the volume.
"""

from deform.chainmail import ChainMail as ChainMail
from deform.chainmail import MoveStats as MoveStats
from deform.chainmail_model import ChainMailError as ChainMailError
from deform.elements import ElementGrid as ElementGrid
from deform.elements import ElementGridError as ElementGridError
from deform.lattice_warp import LatticeWarp as LatticeWarp
from deform.massspring import CpuSpringSolver as CpuSpringSolver
from deform.massspring import MassSpring as MassSpring
from deform.offset_field import OffsetFieldWarp as OffsetFieldWarp
from deform.scene_graph import SceneNode as SceneNode
from deform.scene_graph import compose_scene as compose_scene
from deform.trilinear import TrilinearGrid as TrilinearGrid
from deform.trilinear import TrilinearTransform as TrilinearTransform
from deform.warp import (
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
from deform.wires import Wire as Wire
from deform.wires import WireDeformer as WireDeformer
from deform.wires import WireFieldWarp as WireFieldWarp

__all__ = [
    "AffineWarp",
    "IdentityWarp",
    "Warp",
    "WarpError",
    "chain_apply",
    "compose_glsl",
    "known_warps",
    "register_warp",
    "warp_from_dict",
]
