"""Piecewise-linear warped rays: how long a segment may be, per region of space.

About this technique
--------------------
Every warp is smooth at the scale of a few voxels, so a warped ray is almost straight
over a short stretch. With segments of ``K`` samples the raycaster evaluates the warp
chain only at segment ends and interpolates the original-space position (and the
Jacobian, for shading) linearly in between (``PIECEWISE`` in
``shaders/raycast.frag.glsl``): one chain evaluation per ``K`` samples instead of one
per sample, every lane of a SIMD group evaluating at the same loop iteration.

The error of a segment is the distance between the chain and its chord. For a
segment of length ``L`` from ``x`` along ``d`` this module measures it at the midpoint,

    e = | w(x + L/2 d) - (w(x) + w(x + L d)) / 2 |     (texels of the volume)

from the chain evaluated once on a node grid over the deformed-space ray box
(:func:`segment_lengths`; ``GRID`` cells on the longest axis), for the 13 grid
directions (axes, face and body diagonals) and ``L`` = twice the node step along
them. It then allows a segment length ``h`` that keeps the error within the
tolerance, assuming the error grows linearly with ``h`` below ``L`` (a kink, as at the
faces of trilinear cells) and quadratically above (a smooth bend):
``h = L * tol / e`` if ``e > tol``, else ``L * sqrt(tol / e)``, after multiplying ``e``
by ``SAFETY``. Each grid cell keeps the smallest ``h`` of its corners; it then
allows the longest of ``MAX_SAMPLES`` voxels halved up to four times that every cell
within that distance allows (a segment may run into its neighbours), else 0. A tear
(a vacated region, where a warp shows nothing) gives 0 around it: those rays
evaluate every sample.

This is a measurement on a grid, not a proof: a kink narrower than the node step can
be under-estimated (its midpoint error depends on where it falls between nodes), so
the tolerance is a target rather than a guarantee; ``tests/render/test_ray_segments.py``
states the image differences measured against the per-sample path, and
``Renderer.ray_segment = 1`` turns interpolation off.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from voxwarp.deform.warp import Warp, chain_apply
from voxwarp.errors import RenderError

#: grid cells on the longest axis of the ray box
GRID = 48
#: measured errors are multiplied by this before they are compared with the tolerance
SAFETY = 2.0
#: the most samples one segment spans
MAX_SAMPLES = 16
#: texel positions beyond this are a warp's "nothing here" (vacated space)
_FAR = 1.0e6


@dataclass
class SegmentMap:
    """Longest allowed segment (mm) per cell of a grid over the deformed-space ray box.

    ``lengths`` is (nx, ny, nz) float32; cell (i, j, k) spans
    ``lo + (i, j, k) * cell`` to ``lo + (i + 1, j + 1, k + 1) * cell``.
    """

    lengths: np.ndarray
    lo: np.ndarray
    cell: np.ndarray
    #: the chord error (texels) it was measured for
    tolerance: float = 0.0

    def world_to_map(self) -> np.ndarray:
        """4x4 map from deformed world (mm) to this grid's cell coordinates."""
        m = np.eye(4)
        m[:3, :3] = np.diag(1.0 / self.cell)
        m[:3, 3] = -self.lo / self.cell
        return m


def _grid_directions() -> np.ndarray:
    """The 13 integer grid directions: 3 axes, 6 face diagonals, 4 body diagonals."""
    out = []
    for d in np.ndindex(3, 3, 3):
        v = np.array(d) - 1
        if v.any() and v[np.flatnonzero(v)[0]] > 0:
            out.append(v)
    return np.array(out)


DIRECTIONS = _grid_directions()


def _node_texels(
    warps: Sequence[Warp], lo: np.ndarray, step: np.ndarray, nodes: tuple, to_texel: np.ndarray
) -> np.ndarray:
    """The chain at every node of the grid, in texels (nan where a warp shows nothing)."""
    axes = [lo[a] + step[a] * np.arange(nodes[a]) for a in range(3)]
    p = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    q = chain_apply(warps, p)
    u = q @ to_texel[:3, :3].T + to_texel[:3, 3]
    u[~(np.abs(u) < _FAR).all(axis=1)] = np.nan
    return u.reshape(*nodes, 3)


def _allowed_at_nodes(u: np.ndarray, step: np.ndarray, tolerance: float) -> np.ndarray:
    """Per node: the longest segment (mm) its measured chord errors allow."""
    allowed = np.full(u.shape[:3], np.inf)
    n = np.array(u.shape[:3])
    for d in DIRECTIONS:
        span = 2 * np.abs(d)
        if (span >= n).any():
            continue
        sl = [slice(0, n[a] - span[a]) if d[a] >= 0 else slice(span[a], n[a]) for a in range(3)]
        mid = [slice(s.start + d[a], s.stop + d[a]) for a, s in enumerate(sl)]
        end = [slice(s.start + 2 * d[a], s.stop + 2 * d[a]) for a, s in enumerate(sl)]
        a, m, b = u[tuple(sl)], u[tuple(mid)], u[tuple(end)]
        e = SAFETY * np.linalg.norm(m - 0.5 * (a + b), axis=-1)
        e = np.where(np.isnan(e), np.inf, e)
        length = float(np.linalg.norm(2 * d * step))
        with np.errstate(divide="ignore", invalid="ignore"):
            h = np.where(e > tolerance, length * tolerance / e, length * np.sqrt(tolerance / e))
        region = allowed[tuple(sl)]
        np.minimum(region, h, out=region)
    return allowed


def _min_filter(a: np.ndarray, radius: int) -> np.ndarray:
    """Minimum over the (2 radius + 1)³ neighbourhood (separable, edges clamped)."""
    out = a
    for axis in range(3):
        padded = np.concatenate(
            [
                np.repeat(out.take([0], axis), radius, axis),
                out,
                np.repeat(out.take([-1], axis), radius, axis),
            ],
            axis=axis,
        )
        n = out.shape[axis]
        acc = padded.take(range(0, n), axis)
        for k in range(1, 2 * radius + 1):
            acc = np.minimum(acc, padded.take(range(k, k + n), axis))
        out = acc
    return out


def segment_lengths(
    warps: Sequence[Warp],
    lo: Sequence[float],
    hi: Sequence[float],
    world_to_texel: np.ndarray,
    tolerance: float,
    max_length: float,
    grid: int = GRID,
) -> SegmentMap:
    """The :class:`SegmentMap` of ``warps`` over the box ``lo..hi`` (deformed world, mm).

    ``world_to_texel``: 4x4 from original world (mm) to the volume's texels;
    ``tolerance``: chord error allowed, in texels; ``max_length`` (mm): the longest
    segment the raycaster will use (it sets how far a cell looks around itself).
    """
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    extent = np.maximum(hi - lo, 1e-9)
    cells = np.maximum(1, np.ceil(grid * extent / extent.max())).astype(int)
    step = extent / cells
    u = _node_texels(warps, lo, step, tuple(cells + 1), np.asarray(world_to_texel, float))
    at_nodes = _allowed_at_nodes(u, step, tolerance)
    # a cell: the smallest of its 8 corners
    c = at_nodes[:-1, :-1, :-1]
    for off in np.ndindex(2, 2, 2):
        c = np.minimum(
            c, at_nodes[off[0] :, off[1] :, off[2] :][: cells[0], : cells[1], : cells[2]]
        )
    return SegmentMap(_reachable(c, step, max_length), lo, step, float(tolerance))


def _reachable(allowed: np.ndarray, step: np.ndarray, max_length: float) -> np.ndarray:
    """Per cell the longest of the lengths max_length / 2**i (down to one sixteenth)
    that every cell within that length allows (a segment may run into its neighbours)."""
    out = np.zeros(allowed.shape, np.float32)
    length = max_length
    for _ in range(5):
        reach = int(np.ceil(length / step.min()))
        ok = (_min_filter(allowed, reach) >= length) & (out == 0)
        out[ok] = length
        length /= 2
    return out


class RaySegments:
    """The renderer's settings for piecewise-linear warped rays.

    ``setting``: ``"auto"`` uses each warp state's :class:`SegmentMap` (built with its
    deformed-space skip maps); an int fixes the samples per segment everywhere (1, the
    default: the chain at every sample, the exact path; > 1 ignores the tolerance, for
    measuring). The default stays 1 because on the CPU rasteriser measured so far
    (llvmpipe) "auto" did not pay (docs/benchmarks.md, issue 19 lever 1).
    ``tolerance``: chord error allowed per segment, in texels of the volume.
    """

    def __init__(self, setting: int | str = 1, tolerance: float = 0.1) -> None:
        self.setting = setting
        self.tolerance = tolerance

    @property
    def setting(self) -> int | str:
        """``"auto"`` or a fixed number of samples per segment (>= 1)."""
        return self._setting

    @setting.setter
    def setting(self, value: int | str) -> None:
        fixed = isinstance(value, int) and not isinstance(value, bool) and value >= 1
        if value != "auto" and not fixed:
            raise RenderError(f"ray_segment must be 'auto' or an int >= 1; got {value!r}")
        self._setting = value

    @property
    def tolerance(self) -> float:
        """Largest chord error of a segment, in texels of the volume."""
        return self._tolerance

    @tolerance.setter
    def tolerance(self, value: float) -> None:
        value = float(value)
        if not np.isfinite(value) or value < 0:
            raise RenderError(f"ray_tolerance must be a number >= 0 texels; got {value!r}")
        self._tolerance = value

    def fixed(self) -> int:
        """Samples per segment forced everywhere, or 0 (the segment map decides)."""
        return 0 if self.setting == "auto" else int(self.setting)

    def max_length(self, volume: Any) -> float:
        """The longest segment a map allows (mm): ``MAX_SAMPLES`` of the finest voxel."""
        return float(MAX_SAMPLES * np.min(volume.spacing))

    def texture(self, ctx: Any, segments: SegmentMap) -> Any:
        """An R32F 3D texture of ``segments.lengths`` (nearest filtering)."""
        data = np.ascontiguousarray(segments.lengths.transpose(2, 1, 0), dtype=np.float32)
        tex = ctx.texture3d(segments.lengths.shape, 1, data.tobytes(), dtype="f4")
        tex.filter = (ctx.NEAREST, ctx.NEAREST)
        return tex
