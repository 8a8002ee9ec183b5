"""How many lattice samples a straight ray takes per skip-map check.

A straight ray with cell maps (``SAMPLES_PER_CHECK`` in shaders/raycast.frag.glsl) looks
its cell up in the octant skip map, jumps if the cell is invisible, and then takes
``n`` consecutive lattice samples before it looks again. A warped ray on the support's
map path does the same in its straight phases (before and after the moved region). The
samples it takes unchecked keep the lattice, and one in an invisible cell adds exactly nothing (zero
opacity; below the isovalue or threshold), so ``n`` changes the work, never the image.

Which ``n`` pays depends on the rasteriser and on how much of the volume the mode
can see. A CPU rasteriser (llvmpipe) runs both sides of every branch for all lanes of a
SIMD group, so every loop iteration pays for the check and its jump; checking every
``n``-th sample saves that where rays sample visible runs, and costs up to ``n - 1``
extra samples per jump in empty space. On unshaded dvr a sample costs about two checks:
the fewer checks, the faster a dense view (most cells visible: rays sample long runs),
and the slower a sparse one (rays mostly jump). ``"auto"`` therefore takes the share of
visible cells: below :data:`SPARSE_VISIBLE` one check per sample, from
:data:`DENSE_VISIBLE` on one per :data:`DENSE_SAMPLES_PER_CHECK`, two in between
(docs/benchmarks.md, "Fewer skip-map fetches per straight sample" and "Samples per
check by the share of visible cells"). With shading a sample is dearer: shaded dvr
takes :data:`SHADED_SAMPLES_PER_CHECK` from :data:`DENSE_VISIBLE` of the cells visible
(colin27's MRI: 0.93x the frame of one check per sample), 1 below (a chest CT's bones:
1.14x with 2); iso's bisection and the other modes keep 1. A GPU skips a branch no lane
takes, so it keeps one check per sample.

Samples through the warp chain (warped rays, a support's chained phase) pay the chain
even in an invisible cell, so an unchecked one is dearer than a straight ray's:
:func:`chained_samples_per_check` takes two only from :data:`CHAINED_DENSE_VISIBLE` of
the deformed-space cells visible (shaded: :data:`DENSE_VISIBLE`; docs/benchmarks.md,
"Chained samples per check").
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from voxwarp.errors import RenderError

if TYPE_CHECKING:
    from voxwarp.scene import Scene

#: the most samples per check the raycaster's program is written for
MAX_SAMPLES_PER_CHECK = 4
#: what "auto" takes for unshaded dvr on a CPU rasteriser (between the shares below, or
#: before the share of visible cells is known)
SOFTWARE_DVR_SAMPLES_PER_CHECK = 2
#: below this share of visible cells, "auto" checks every sample (sparse views)
SPARSE_VISIBLE = 0.06
#: from this share of visible cells on, "auto" takes DENSE_SAMPLES_PER_CHECK (dense views)
DENSE_VISIBLE = 0.3
DENSE_SAMPLES_PER_CHECK = 4
#: what "auto" takes for shaded dvr on a CPU rasteriser from DENSE_VISIBLE on (a shaded
#: sample is dearer: sparse views lost 10-14 % with 2, dense ones gained 5-11 %)
SHADED_SAMPLES_PER_CHECK = 2
#: from this share of visible deformed-space cells on, chained samples take two per
#: check on a CPU rasteriser (measured: 14 % visible lost 4-9 %, 26 % and 60 % gained
#: 3-9 %; unshaded dvr, llvmpipe)
CHAINED_DENSE_VISIBLE = 0.2
#: the most chained samples per check the raycaster's program is written for
MAX_CHAINED_PER_CHECK = 2


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


def samples_per_check(
    setting: int | str, scene: Scene, software: bool, visible: float | None = None
) -> int:
    """Samples per skip-map check for straight rays drawing ``scene``: ``setting`` if it
    is a number, else (``"auto"``) 1 except for dvr on a CPU rasteriser (``software``),
    where it follows ``visible``, the share of cells the mode can see (None: not known
    yet): unshaded, see the module docstring; shaded, :data:`SHADED_SAMPLES_PER_CHECK`
    from :data:`DENSE_VISIBLE` on, else 1."""
    if setting != "auto":
        return int(setting)
    if not (software and scene.mode == "dvr"):
        return 1
    if scene.use_shading():
        dense = visible is not None and visible >= DENSE_VISIBLE
        return SHADED_SAMPLES_PER_CHECK if dense else 1
    if visible is None:
        return SOFTWARE_DVR_SAMPLES_PER_CHECK
    if visible < SPARSE_VISIBLE:
        return 1
    if visible >= DENSE_VISIBLE:
        return DENSE_SAMPLES_PER_CHECK
    return SOFTWARE_DVR_SAMPLES_PER_CHECK


def chained_samples_per_check(
    setting: int | str, scene: Scene, software: bool, visible: float | None
) -> int:
    """Samples through the warp chain per skip-map check: ``setting`` if it is a number
    (at most :data:`MAX_CHAINED_PER_CHECK`), else (``"auto"``) 2 for dvr on a CPU
    rasteriser where ``visible`` (the share of deformed-space cells the mode can see)
    is at least :data:`CHAINED_DENSE_VISIBLE` (shaded: :data:`DENSE_VISIBLE`), 1
    otherwise (see the module docstring)."""
    if setting != "auto":
        return min(int(setting), MAX_CHAINED_PER_CHECK)
    if not (software and scene.mode == "dvr") or visible is None:
        return 1
    least = DENSE_VISIBLE if scene.use_shading() else CHAINED_DENSE_VISIBLE
    return MAX_CHAINED_PER_CHECK if visible >= least else 1
