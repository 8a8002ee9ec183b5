"""The ``voxwarp`` command line: one module per command (``render``, ``slice``, ``info``,
``demo``, ``bench``, ``gui``, ...), each adding its parser with ``add_parser(sub)``, the
options they share (:mod:`~voxwarp.cli.options`, :mod:`~voxwarp.cli.render_options`,
:mod:`~voxwarp.cli.deform_options`), and :mod:`~voxwarp.cli.main`, which builds the
top-level parser and is the console script's entry point.
"""
