"""The render modes of the raycaster (one GLSL file each, ``shaders/mode_*.glsl``).

``dvr`` direct volume rendering through the transfer function; ``mip`` / ``minip``
maximum / minimum intensity projection; ``average`` the mean along the ray; ``xray`` a
radiograph (line integral); ``flm`` first local maximum; ``iso`` the first crossing of
an iso value, shaded.

``average`` and ``xray`` differ as follows (window ``w_lo .. w_hi``):

* ``average`` is the thesis's mean along the ray (Knoche 2008, section 2.3.2,
  "Mittelwert"): the sum of the samples inside the volume box divided by their number,
  shown through the window. It does not grow with the thickness of the object, and rays
  that cross the box near its faces average over a few samples only, so an object that
  touches those faces shows bright caps there.
* ``xray`` is a radiograph: the line integral ``I = sum max(v - w_lo, 0) * step`` (value
  x mm, ``step`` the sample distance in deformed space) of the value above the window's
  low end (the low end is zero attenuation, as air in a CT window: values below it add
  nothing, values above the window's top still add), divided by a FIXED reference length
  ``L`` = the longest edge of the volume box in mm (``max(shape * spacing)``; the same for
  every ray, view, warp and clip box), shown as ``clamp(I / L / (w_hi - w_lo), 0, 1)``:
  bright = more material. A ray crossing ``L`` mm of value ``v`` shows ``v`` as the
  window maps it; a slab twice as thick is twice as bright (until white); box faces
  leave no caps.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Literal

import numpy as np

if TYPE_CHECKING:
    from voxwarp.core.volume import Volume

Mode = Literal["dvr", "mip", "minip", "average", "xray", "flm", "iso"]
#: every render mode, in the order the GUI and ``voxwarp render --mode`` offer them
MODES: tuple[str, ...] = ("dvr", "mip", "minip", "average", "xray", "flm", "iso")


def xray_reference_length(volume: Volume) -> float:
    """The fixed length (mm) the ``xray`` mode divides its line integral by: the longest
    edge of the volume box, ``max(shape * spacing)`` (independent of the ray, the view,
    the volume's rotation, warps and the clip box)."""
    return float(np.max(np.asarray(volume.shape, float) * np.asarray(volume.spacing, float)))
