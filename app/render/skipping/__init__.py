"""Empty-space skipping: what rays may jump over, built once per volume or warp state.

Modules: ``maps`` (the maths: block and cell visibility, octant skip distances, warped
bounds), ``numpy_maps`` and ``kernels`` (the numpy and numba builders ``maps`` picks
between), ``cache`` (when the raycaster builds, keeps and drops the maps), ``segments``
(how long a piecewise-linear warped ray segment may be), ``checks`` (how many samples a
straight ray takes per skip-map check).
"""
