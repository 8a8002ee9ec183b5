"""voxwarp deformation models (offset field, wire field, trilinear lattice).

Each model has a CPU reference and a GPU backend and exposes its result as a warp
(:class:`deform.warp.Warp`) that the raycaster samples without resampling the volume.
"""

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
