"""voxwarp deformation models (offset field, wire field, trilinear lattice).

Each model has a CPU reference and a GPU backend and exposes its result as a warp
(:class:`deform.warps.Warp`) that the raycaster samples without resampling the volume.
"""
