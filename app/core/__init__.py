"""Core value types shared by every layer: volume, camera, transfer function, mesh, errors, files,
argument checks.
"""
