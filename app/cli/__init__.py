"""The ``voxwarp`` command line: one module per command (``render``, ``slice``, ``info``,
``demo``, ``bench``, ``gui``, ...), each adding its parser with ``add_parser(sub)``, the
options they share (:mod:`~voxwarp.cli.options`, :mod:`~voxwarp.cli.render_options`,
:mod:`~voxwarp.cli.deform_options`), and :mod:`~voxwarp.cli.main`, which builds the
top-level parser and is the console script's entry point.

Every command's module loads whenever the parser is built (``voxwarp --help`` too), so
what a command needs to run (the scene, the renderer, the models, the readers, the teaching
demos) is imported inside its functions: ``voxwarp --help`` loads the parser, numpy and a
few small modules only (``tests/test_package.py`` checks that no heavy module loads).
What the parser loads anyway, and a few small modules (``core.files``, ``core.progress``,
``teaching.tour``: some ms together), are imported at the top.
"""
