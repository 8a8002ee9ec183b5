"""The volume at a reduced resolution for interactive frames (the thesis's setting of
the volume resolution, section 3.2: the user trades detail for interactivity).

:func:`reduced_volume` averages the voxels onto a grid ``factor`` times coarser per
axis that covers **exactly the same box** (an area-weighted box filter: where the axis
length is not a multiple of the factor, the new voxels are a little larger than
``factor`` old ones), so warps, clipping boxes and cameras in world mm apply unchanged.
:class:`InteractionVolumes` keeps one reduced copy per volume and level, and
:meth:`InteractionVolumes.scene` swaps it into a scene for an interactive frame; the
scene's look (window, threshold levels, transfer function) stays the full volume's.
Stills (screenshots, ``voxwarp render``, exports) draw the full volume.
"""

from __future__ import annotations

import weakref

import numpy as np

from voxwarp.core.volume import Volume
from voxwarp.scene import Scene, check_interactive_downsample


def _axis_weights(n: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Old-voxel indices (m, k) and weights (m, k) of ``m`` new voxels covering ``n``
    old ones: each new voxel averages the old ones it overlaps, by overlap length."""
    edges = np.arange(m + 1) * (n / m)
    k = int(np.ceil(n / m)) + 1
    idx = np.floor(edges[:-1])[:, None].astype(np.int64) + np.arange(k)
    lo = np.maximum(idx, edges[:-1, None])
    hi = np.minimum(idx + 1, edges[1:, None])
    w = np.clip(hi - lo, 0.0, None) / (n / m)
    return np.minimum(idx, n - 1), w


def _reduce_axis(data: np.ndarray, axis: int, m: int) -> np.ndarray:
    n = data.shape[axis]
    if n % m == 0:  # whole blocks: their plain mean (the same weights, faster)
        blocks = (*data.shape[:axis], m, n // m, *data.shape[axis + 1 :])
        return data.reshape(blocks).mean(axis=axis + 1, dtype=np.float32)
    idx, w = _axis_weights(n, m)
    out = np.zeros((*data.shape[:axis], m, *data.shape[axis + 1 :]), dtype=np.float32)
    shape = [1] * data.ndim
    shape[axis] = m
    for j in range(idx.shape[1]):
        out += np.take(data, idx[:, j], axis=axis) * w[:, j].reshape(shape).astype(np.float32)
    return out


def reduced_volume(volume: Volume, factor: int) -> Volume:
    """``volume`` on a grid ``factor`` times coarser per axis (at least one voxel), over
    the same box: ``ceil(n / factor)`` voxels of ``n / ceil(n / factor)`` old spacings
    each, every one the overlap-weighted mean of the old voxels it covers. Integer data
    is rounded back to its type. ``factor`` 1 returns ``volume`` itself."""
    f = check_interactive_downsample(factor)
    if f == 1:
        return volume
    n = np.asarray(volume.shape)
    m = np.maximum(np.ceil(n / f).astype(np.int64), 1)
    data: np.ndarray = volume.data
    # whole-block axes first (cheap), so the overlap-weighted ones see less data
    for axis in sorted(range(3), key=lambda a: n[a] % m[a] != 0):
        if m[axis] != n[axis]:
            data = _reduce_axis(data, axis, int(m[axis]))
    if volume.dtype.kind in "iu":
        info = np.iinfo(volume.dtype)
        data = np.clip(np.rint(data), info.min, info.max).astype(volume.dtype)
    elif data.dtype != volume.dtype:
        data = data.astype(volume.dtype)
    ratio = n / m
    origin = volume.index_to_world(0.5 * ratio - 0.5)
    spacing = tuple(float(s) for s in np.asarray(volume.spacing) * ratio)
    return volume.with_geometry(np.ascontiguousarray(data), spacing=spacing, origin=tuple(origin))


class InteractionVolumes:
    """Reduced copies of volumes for interactive frames, one per volume and factor,
    kept while the volume lives (the GUI's viewport and the notebook viewer hold one)."""

    def __init__(self) -> None:
        self._copies: dict[tuple[int, int], tuple[weakref.ref, Volume]] = {}

    def volume(self, volume: Volume, factor: int) -> Volume:
        """The reduced copy of ``volume`` (made on first use; ``volume`` at factor 1)."""
        f = check_interactive_downsample(factor)
        if f == 1:
            return volume
        for key in [k for k, (ref, _) in self._copies.items() if ref() is None]:
            del self._copies[key]
        small = self.cached(volume, f)
        if small is None:
            small = reduced_volume(volume, f)
            self.put(volume, f, small)
        return small

    def cached(self, volume: Volume, factor: int) -> Volume | None:
        """The reduced copy of ``volume`` if made already (``volume`` at factor 1), else
        None: a caller that must not wait makes it elsewhere (:func:`reduced_volume`,
        e.g. on a worker thread) and hands it to :meth:`put`."""
        f = check_interactive_downsample(factor)
        if f == 1:
            return volume
        hit = self._copies.get((id(volume), f))
        return hit[1] if hit is not None and hit[0]() is volume else None

    def put(self, volume: Volume, factor: int, small: Volume) -> None:
        """Keep ``small`` as the reduced copy of ``volume`` at ``factor``."""
        self._copies[(id(volume), check_interactive_downsample(factor))] = (
            weakref.ref(volume),
            small,
        )

    def scene(self, scene: Scene) -> Scene:
        """``scene`` with its volume reduced by ``scene.interactive_downsample`` (the
        scene itself at 1); window, threshold levels and transfer function stay the
        full volume's, so the interactive frame keeps the look of the still."""
        f = scene.interactive_downsample
        if f == 1:
            return scene
        levels = {
            "iso_value": scene.iso_value
            if scene.iso_value is not None or scene.mode != "iso"
            else scene.resolved_level("iso").value,
            "flm_threshold": scene.flm_threshold
            if scene.flm_threshold is not None or scene.mode != "flm"
            else scene.resolved_level("flm").value,
        }
        return scene.copy(
            volume=self.volume(scene.volume, f),
            window=scene.window,
            transfer_function=scene.transfer_function,
            **levels,
        )

    def clear(self) -> None:
        """Forget every copy (e.g. the GL context goes away)."""
        self._copies.clear()
