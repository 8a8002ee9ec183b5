"""Jupyter support (``pip install 'voxwarp[notebook]'``).

* :class:`Viewer` (:mod:`voxwarp.notebook.viewer`): an interactive ``jupyter_rfb`` widget
  showing a scene: orbit, zoom, pick and drag handles through the desktop GUI's
  :class:`~voxwarp.editing.session.EditSession`, live mass-spring and ChainMail.
* Inline pictures (:mod:`voxwarp.notebook.display`): importing this package (or
  ``%load_ext voxwarp.notebook``) makes a cell ending in a
  :class:`~voxwarp.scene.Scene` show a small render of it; rendered images show
  themselves anyway. :func:`side_by_side` puts images in a row.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from voxwarp.lazy import exports
from voxwarp.notebook.display import register as _register

_PUBLIC: dict[str, str] = {
    "Viewer": "voxwarp.notebook.viewer",
    "session_for": "voxwarp.notebook.viewer",
    "preview": "voxwarp.notebook.display",
    "side_by_side": "voxwarp.notebook.display",
}
__all__ = ["Viewer", "load_ipython_extension", "preview", "session_for", "side_by_side"]
__getattr__, __dir__ = exports(__name__, _PUBLIC)


def load_ipython_extension(ipython: Any) -> None:
    """``%load_ext voxwarp.notebook``: show scenes inline in this shell."""
    _register(ipython)


_register()  # in a running IPython: scenes show inline from here on

if TYPE_CHECKING:
    from voxwarp.notebook.display import preview, side_by_side
    from voxwarp.notebook.viewer import Viewer, session_for
