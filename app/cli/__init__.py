"""The ``voxwarp`` command line: parser and commands (the ``gui`` command is added by
:mod:`voxwarp.ui.cli`).
"""
