"""Imported displacement fields (ITK, ANTs, Slicer transforms) as warps.

Modules: ``displacement`` (the field on a regular grid and its warp).
"""
