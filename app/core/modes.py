"""The render modes of the raycaster (one GLSL file each, ``shaders/mode_*.glsl``).

``dvr`` direct volume rendering through the transfer function; ``mip`` / ``minip``
maximum / minimum intensity projection; ``average`` the mean along the ray; ``flm``
first local maximum; ``iso`` the first crossing of an iso value, shaded.
"""

from typing import Literal

Mode = Literal["dvr", "mip", "minip", "average", "flm", "iso"]
#: every render mode, in the order the GUI and ``voxwarp render --mode`` offer them
MODES: tuple[str, ...] = ("dvr", "mip", "minip", "average", "flm", "iso")
