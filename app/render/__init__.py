"""The renderer: the raycaster (``raycaster``), its headless context and offscreen wrapper
(``context``, ``offscreen``), empty-space skipping (``skipping/``), the mesh pass, the
editing overlay, slices, field views.
"""
