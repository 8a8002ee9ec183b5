"""The default node spacing of a field export, and its size before it is written.

**Default spacing** (:func:`default_spacing`). Each warp states the finest length on
which its map's derivative changes (:meth:`voxwarp.deform.warp.Warp.export_resolution`):
the shortest edge of an element grid's or a lattice's cells, at rest or deformed (the
inverse the volume is drawn with bends at the deformed cells' faces); infinite for an
affine map; ``None`` for maps with detail down to voxels (wires, imported fields). A
chain of smooth warps starts at :data:`NODES_PER_ELEMENT` nodes per shortest edge:
inside a cell the map is smooth, so the export's trilinear interpolation misses it
mostly near the cell faces (its kinks), by about the node spacing times the change of
slope there, which a quarter of a cell keeps small; :mod:`voxwarp.core.field_check`
then measures it and refines the spacing where it misses the tolerance. The spacing is
never finer than the volume's voxels (per axis) and keeps at least :data:`MIN_NODES`
nodes per axis over the volume. A chain with a wire or an imported field starts on the
volume's voxel grid, as before.

**Size estimate** (:func:`estimate_bytes`): nodes x 3 components x 4 bytes (float32)
plus the format's header; compressed formats (``.nii.gz``, ``.h5``) are estimated
uncompressed (an upper bound). :func:`check_room` refuses an export whose estimate is
over the free disk space at the output.
"""

from __future__ import annotations

import math
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from voxwarp.core.files import file_size_limit
from voxwarp.core.limits import format_bytes
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import Warp
from voxwarp.errors import SceneError

#: Nodes per element (along each axis) of the finest smooth warp in the chain.
NODES_PER_ELEMENT = 4
#: Fewest nodes per volume axis of a default grid (an affine chain gets this many).
MIN_NODES = 16
#: Bytes of a format's header and metadata, at most (NIfTI: 352 + extensions; NRRD,
#: MHA: a text header; HDF5: its tree).
HEADER_BYTES = 64 * 1024


@dataclass(frozen=True)
class SpacingChoice:
    """A default spacing and why (:func:`default_spacing`).

    Attributes
    ----------
    spacing : numpy.ndarray or None
        Node spacing per volume index axis (mm), or None: the volume's own voxel grid.
    reason : str
        One line saying how it was chosen.
    """

    spacing: np.ndarray | None
    reason: str


def default_spacing(volume: Volume, warps: Sequence[Warp]) -> SpacingChoice:
    """The default export spacing of ``warps`` over ``volume`` (see the module doc)."""
    res = [w.export_resolution() for w in warps]
    if not res or any(r is None for r in res):
        why = "no warps" if not res else "a warp with voxel detail (wire or imported field)"
        return SpacingChoice(None, f"the volume's voxels ({why})")
    finest = min(float(r) for r in res if r is not None)
    voxels = np.asarray(volume.spacing, float)
    extent = np.asarray(volume.shape, float) * voxels
    coarsest = extent / (MIN_NODES - 1)
    wanted = finest / NODES_PER_ELEMENT
    s = np.maximum(np.minimum(wanted, coarsest), voxels)
    if math.isinf(finest):
        why = f"an affine chain: {MIN_NODES} nodes per axis"
    else:
        why = f"a quarter of the shortest element or lattice cell edge ({finest:.3g} mm)"
    if np.any(s == voxels) and np.any(voxels > wanted):
        why += ", no finer than the voxels"
    return SpacingChoice(s, why)


def field_file_bytes(shape: Sequence[int], components: int = 3, itemsize: int = 4) -> int:
    """The data bytes of a field (or scalar map) of ``shape`` nodes."""
    return int(np.prod([int(n) for n in shape])) * components * itemsize


def estimate_bytes(shape: Sequence[int], components: int = 3, itemsize: int = 4) -> int:
    """Estimated file size: the data (:func:`field_file_bytes`) plus
    :data:`HEADER_BYTES`; an upper bound for compressed formats."""
    return field_file_bytes(shape, components, itemsize) + HEADER_BYTES


def check_room(out: Path, nbytes: int) -> None:
    """Raise :class:`SceneError` when ``nbytes`` is over the free space at ``out`` or the
    process's file-size limit (:func:`file_size_limit`): checked before a native writer
    (HDF5, MetaImage) runs into either, which some cannot survive."""
    folder = Path(out).resolve().parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    free = shutil.disk_usage(folder).free
    if nbytes > free:
        raise SceneError(
            f"{out}: the export needs about {format_bytes(nbytes)}, over the"
            f" {format_bytes(free)} free on its disk; use a coarser --spacing (or free space)"
        )
    cap = file_size_limit()
    if nbytes > cap:
        raise SceneError(
            f"{out}: the export needs about {format_bytes(nbytes)}, over this process's"
            f" file-size limit of {format_bytes(cap)} (ulimit -f); use a coarser --spacing"
            " or raise the limit"
        )
