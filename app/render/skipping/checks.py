"""How many lattice samples a straight ray takes per skip-map check.

A straight ray with cell maps (``SAMPLES_PER_CHECK`` in shaders/raycast.frag.glsl) looks
its cell up in the octant skip map, jumps if the cell is invisible, and then takes
``n`` consecutive lattice samples before it looks again. The samples it takes
unchecked keep the lattice, and one in an invisible cell adds exactly nothing (zero
opacity; below the isovalue or threshold), so ``n`` changes the work, never the image.

Which ``n`` pays depends on the rasteriser: a CPU rasteriser (llvmpipe) runs both
sides of every branch for all lanes of a SIMD group, so every loop iteration pays for
the check and its jump; checking every second sample saves half of that where rays
sample visible runs, and costs one extra sample per jump in empty space. On unshaded
dvr a sample costs about two checks and the trade pays on dense scans (docs/benchmarks.md,
"Fewer skip-map fetches per straight sample"); with shading, or iso's bisection, a
sample is dearer and it does not. A GPU skips a branch no lane takes, so it keeps one
check per sample.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from voxwarp.errors import RenderError

if TYPE_CHECKING:
    from voxwarp.scene import Scene

#: the most samples per check the raycaster's program is written for
MAX_SAMPLES_PER_CHECK = 4
#: what "auto" takes for unshaded dvr on a CPU rasteriser
SOFTWARE_DVR_SAMPLES_PER_CHECK = 2


def checked_setting(value: int | str) -> int | str:
    """``value`` if it is "auto" or an int from 1 to :data:`MAX_SAMPLES_PER_CHECK`, else a
    :class:`~voxwarp.errors.RenderError` naming the allowed values."""
    if value == "auto":
        return value
    if isinstance(value, bool) or not isinstance(value, int):
        raise RenderError(f"samples_per_check must be 'auto' or an int; got {value!r}")
    if not 1 <= value <= MAX_SAMPLES_PER_CHECK:
        raise RenderError(
            f"samples_per_check must be 1 to {MAX_SAMPLES_PER_CHECK} (or 'auto'); got {value}"
        )
    return value


def samples_per_check(setting: int | str, scene: Scene, software: bool) -> int:
    """Samples per skip-map check for straight rays drawing ``scene``: ``setting`` if it
    is a number, else (``"auto"``) :data:`SOFTWARE_DVR_SAMPLES_PER_CHECK` for unshaded
    dvr on a CPU rasteriser (``software``) and 1 otherwise (see the module docstring)."""
    if setting != "auto":
        return int(setting)
    if software and scene.mode == "dvr" and not scene.use_shading():
        return SOFTWARE_DVR_SAMPLES_PER_CHECK
    return 1
