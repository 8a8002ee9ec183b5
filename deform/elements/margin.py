"""The ``"auto"`` grid margin: how far an element grid built before any drag is known
reaches beyond the volume's box (docs/concepts/margin.md).

Usage: ``ElementGrid(volume, shape, margin=AUTO_MARGIN)`` resolves it from the
volume's box; :func:`auto_margin` gives the mm. Light (numpy only), so settings modules
the command line's parser imports can name :data:`AUTO_MARGIN`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: the margin setting resolved from the volume's box when the grid is built
AUTO_MARGIN = "auto"
#: the ``"auto"`` margin as a fraction of the volume box's largest side
AUTO_MARGIN_FRACTION = 0.1


def auto_margin(size: Any) -> float:
    """The ``"auto"`` grid margin (mm) of a box of ``size`` (3,) mm:
    :data:`AUTO_MARGIN_FRACTION` of its largest side (about 22 mm on a 217 mm head MRI,
    so a drag of a centimetre or two across a face stays inside the grid).

    The desktop window builds models before any drag is known, so the command line's
    default (``grid.default_margin``, the largest drag) cannot be used there.
    """
    return AUTO_MARGIN_FRACTION * float(np.max(np.asarray(size, dtype=np.float64)))
