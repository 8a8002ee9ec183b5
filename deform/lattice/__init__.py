"""Trilinear lattice (Knuth, Kohlhammer, Kuijper, GRAPP 2010): grids of trilinear cells in
a scene graph, deforming meshes forward and volumes through the inverse.

Modules: ``trilinear`` (grid and transform), ``kernel`` (its numba kernels), ``warp``
(the lattice as a warp), ``scene_graph`` (nested lattices), ``anchors`` (objects anchored
to a lattice).
"""
