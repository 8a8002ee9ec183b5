"""The renderer: the raycaster and its GL context, empty-space skipping, the mesh pass, the editing
overlay, field views.
"""
