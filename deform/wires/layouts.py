"""The attribute field's storage layouts (``float``, ``packed``, ``paper``;
wire paper section 7.2): the built field, its build statistics, packing the codes and
reading t back as the shader does."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from voxwarp.deform.wires.constants import (
    LUT_SIZE,
    PACKED_VACATED,
    PAPER_MAX_SEGMENTS,
    PAPER_T_MAX,
    PAPER_VACATED,
)
from voxwarp.deform.wires.geometry import _CORNERS, _box_slices
from voxwarp.deform.wires.tables import WireTables
from voxwarp.deform.wires.wire import Wire


# ---------------------------------------------------------------------- statistics
@dataclass
class WireFieldStats:
    """What :meth:`WireDeformer.build` did (the paper's Tables 1-3 for preprocessing)."""

    field_shape: tuple[int, int, int]
    field_scale: int
    layout: str
    backend: str
    planes: int
    planes_dropped: int
    seeds: int
    region_voxels: int
    swept: int
    vacated: int
    #: field voxels that render as the identity (not swept, not vacated)
    ignored: int
    #: seconds per stage: tables, masks, box (the field's box), seeds, propagate, flags,
    #: store, total (seeds, propagation and flags of both sides: the swept voxels and
    #: the vacated place)
    timings: dict[str, float] = field(default_factory=dict)
    #: plane-mask memory per wire, bytes: kept planes x K^2 / 8 (section 7.1's
    #: sum_p a(p) s / 8, see :mod:`voxwarp.deform.wires`)
    mask_bytes: tuple[int, ...] = ()
    #: the propagation domain (``WireDeformer(propagate=...)``)
    propagate: str = "region"
    #: field voxels of smooth-sides wires whose weight was faded towards a seam (where
    #: the closest point on the wires jumps; :mod:`voxwarp.deform.wires.seams`)
    seam_faded: int = 0

    @property
    def voxels(self) -> int:
        """Voxels of the attribute field."""
        return int(np.prod(self.field_shape))

    @property
    def mask_bytes_total(self) -> int:
        """Plane-mask memory of all wires, bytes."""
        return int(sum(self.mask_bytes))

    @property
    def percent_ignored(self) -> float:
        """Share of field voxels a sample ignores (identity), in %."""
        return 100.0 * self.ignored / max(self.voxels, 1)

    def as_dict(self) -> dict[str, Any]:
        """Plain dict (JSON-ready)."""
        return {
            "field_shape": list(self.field_shape),
            "field_scale": self.field_scale,
            "layout": self.layout,
            "backend": self.backend,
            "planes": self.planes,
            "planes_dropped": self.planes_dropped,
            "seeds": self.seeds,
            "region_voxels": self.region_voxels,
            "swept": self.swept,
            "vacated": self.vacated,
            "ignored": self.ignored,
            "voxels": self.voxels,
            "percent_ignored": self.percent_ignored,
            "timings": dict(self.timings),
            "mask_bytes": list(self.mask_bytes),
            "mask_bytes_total": self.mask_bytes_total,
            "propagate": self.propagate,
            "seam_faded": self.seam_faded,
        }


@dataclass
class WireField:
    """A built attribute field (see :mod:`voxwarp.deform.wires` for the layouts)."""

    lo: np.ndarray
    spacing: np.ndarray
    shape: tuple[int, int, int]
    layout: str
    #: float layout: state (0 identity, 1 vacated, 2 + wire) and t (u * (LUT_SIZE - 1))
    state: np.ndarray | None
    t: np.ndarray | None
    #: packed and paper layouts: the uint16 codes
    code: np.ndarray | None
    tables: list[WireTables]
    #: the propagated region (first voxel, shape): swept voxels lie inside it
    region_lo: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=np.int64))
    region_shape: tuple[int, int, int] = (0, 0, 0)
    #: paper layout: where each segment of each modified wire starts, in table units
    #: (wires, PAPER_MAX_SEGMENTS + 1) float32; entries past a wire's last segment
    #: repeat its end
    segments: np.ndarray | None = None
    #: with any smooth (``sides`` or ``ends``) wire: float32 weight in [0, 1] per voxel
    #: (trilinearly interpolated) by which a swept sample's displacement is scaled;
    #: None: all rigid
    weight: np.ndarray | None = None

    @property
    def hi(self) -> np.ndarray:
        """Upper corner of the field box (mm)."""
        return self.lo + self.spacing * np.asarray(self.shape)

    @property
    def nbytes(self) -> int:
        """Bytes of the per-voxel data."""
        arrays = (self.state, self.t, self.code, self.weight)
        return sum(a.nbytes for a in arrays if a is not None)

    def decode(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(state, wire, t) per voxel for either layout: state 0 identity, 1 vacated,
        2 swept; wire id; t in table units (integer for the packed layout)."""
        if self.layout == "float":
            assert self.state is not None
            assert self.t is not None
            s = self.state
            state = np.where(s >= 2, 2, s).astype(np.uint8)
            wire = np.where(s >= 2, s.astype(np.int32) - 2, 0)
            return state, wire, self.t
        assert self.code is not None
        c = self.code.astype(np.int32)
        swept = (c & 0x8000) != 0
        state = np.where(swept, 2, np.where(c == PACKED_VACATED, 1, 0)).astype(np.uint8)
        if self.layout == "paper":
            assert self.segments is not None
            return state, (c >> 11) & 0xF, _paper_t(c, self.segments).astype(np.float32)
        return state, (c >> 8) & 0x7F, (c & 0xFF).astype(np.float32)


def _segment_starts(wires: Sequence[Wire], tables: Sequence[WireTables]) -> np.ndarray:
    """Where each segment of each modified wire starts, in table units (the paper
    layout's segments): (wires, PAPER_MAX_SEGMENTS + 1) float32, the last real entry
    the wire's end (LUT_SIZE - 1), repeated to the right. A segment s starts at curve
    parameter s / n_segments, turned into a table coordinate through the wire's table
    of curve parameters (the same piecewise-linear map the tables interpolate)."""
    top = float(LUT_SIZE - 1)
    out = np.full((len(wires), PAPER_MAX_SEGMENTS + 1), top, dtype=np.float64)
    for wi, (w, tab) in enumerate(zip(wires, tables, strict=True)):
        n = w.modified.n_segments
        knots = np.arange(n + 1) / n
        out[wi, : n + 1] = np.interp(knots, tab.t_modified, tab.u) * top
        out[wi, 0], out[wi, n] = 0.0, top
    return out.astype(np.float32)


def _paper_codes(
    wire: np.ndarray, u: np.ndarray, swept: np.ndarray, starts: np.ndarray, counts: np.ndarray
) -> np.ndarray:
    """The paper layout's uint16 codes of voxels with wire ids, fractions u and swept
    flags (``starts`` from :func:`_segment_starts`, ``counts`` the wires' segment
    counts): ``flag << 15 | wire << 11 | segment << 7 | t``, t = round(127 x the
    position of u within its segment); an unswept code equal to :data:`PAPER_VACATED`
    takes t = 126."""
    w = wire.astype(np.int64)
    tu = np.asarray(u, dtype=np.float64) * (LUT_SIZE - 1)
    st = starts.astype(np.float64)
    seg = np.zeros(w.shape, dtype=np.int64)
    for k in range(1, PAPER_MAX_SEGMENTS):  # segment = inner starts at or below tu
        seg += st[w, k] <= tu
    seg = np.minimum(seg, np.asarray(counts, dtype=np.int64)[w] - 1)
    a, b = st[w, seg], st[w, seg + 1]
    frac = np.where(b > a, (tu - a) / np.where(b > a, b - a, 1.0), 0.0)
    t = np.clip(np.rint(frac * PAPER_T_MAX), 0, PAPER_T_MAX).astype(np.int64)
    c = (w << 11) | (seg << 7) | t
    c = np.where(c == PAPER_VACATED, PAPER_VACATED - 1, c)
    return np.where(swept, c | 0x8000, c).astype(np.uint16)


def _paper_t(code: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Table coordinate of paper codes: ``u_s + (t / 127) (u_{s+1} - u_s)``."""
    c = np.asarray(code, dtype=np.int64)
    w, seg, t = (c >> 11) & 0xF, (c >> 7) & 0xF, c & 0x7F
    st = starts.astype(np.float64)
    w = np.minimum(w, len(st) - 1)  # the vacated code names wire 15
    a, b = st[w, seg], st[w, seg + 1]
    return a + (b - a) * (t / PAPER_T_MAX)


# ---------------------------------------------------------------------- the warp
def _sample_t_float(t_field: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Trilinear t at continuous voxel coordinates g (voxel i centred at i + 1/2), with
    clamp-to-edge: what GL_LINEAR filtering of the t texture returns."""
    shape = np.asarray(t_field.shape)
    gc = np.clip(g - 0.5, 0.0, shape - 1.0)
    i0 = np.minimum(np.floor(gc).astype(np.int64), np.maximum(shape - 2, 0))
    f = gc - i0
    # per axis, the two neighbours' flat offsets and weights; corners in _CORNERS' order
    # (the same sums as indexing each corner: one flat gather a corner)
    step = np.array([shape[1] * shape[2], shape[2], 1])
    ends = (i0, np.minimum(i0 + 1, shape - 1))
    offs = [[ends[c][:, a] * step[a] for c in (0, 1)] for a in range(3)]
    wts = [[1.0 - f[:, a], f[:, a]] for a in range(3)]
    flat = t_field.reshape(-1)
    out = np.zeros(len(g))
    for a, b, c in _CORNERS:
        w = wts[0][a] * wts[1][b] * wts[2][c]
        out += w * flat[offs[0][a] + offs[1][b] + offs[2][c]]
    return out


def _trilinear_gradient(t_field: np.ndarray, g: np.ndarray) -> np.ndarray:
    """d/dg of :func:`_sample_t_float` at continuous voxel coordinates g (N, 3): the
    exact gradient of the trilinear interpolant (0 along an axis where g is clamped);
    divide by the voxel size for mm."""
    shape = np.asarray(t_field.shape)
    raw = g - 0.5
    gc = np.clip(raw, 0.0, shape - 1.0)
    i0 = np.minimum(np.floor(gc).astype(np.int64), np.maximum(shape - 2, 0))
    f = gc - i0
    out = np.zeros((len(g), 3))
    for c in _CORNERS:
        idx = np.minimum(i0 + c, shape - 1)
        v = t_field[idx[:, 0], idx[:, 1], idx[:, 2]]
        lin = np.where(c == 1, f, 1.0 - f)
        for a in range(3):
            others = np.prod(np.delete(lin, a, axis=1), axis=1)
            out[:, a] += (1.0 if c[a] == 1 else -1.0) * others * v
    inside = (raw > 0.0) & (raw < shape - 1.0)
    return np.where(inside, out, 0.0)


def _sample_t_packed(code: np.ndarray, g: np.ndarray, wire: np.ndarray) -> np.ndarray:
    """t at g from the 8 packed neighbours of the same wire (vacated ones excluded),
    renormalised; the nearest voxel's integer t where none qualifies (as the shader)."""
    return _sample_t_same_wire(
        code, g, wire, lambda v: (v >> 8) & 0x7F, lambda v: v & 0xFF, PACKED_VACATED
    )


def _sample_t_paper(
    code: np.ndarray, g: np.ndarray, wire: np.ndarray, starts: np.ndarray
) -> np.ndarray:
    """t at g (table units) from the 8 paper-layout neighbours of the same wire (vacated
    ones excluded), each turned into its table coordinate before the weighted mean (so
    neighbours in different segments mix their u, not their per-segment t); the
    nearest voxel's own value where none qualifies (as the shader)."""
    return _sample_t_same_wire(
        code, g, wire, lambda v: (v >> 11) & 0xF, lambda v: _paper_t(v, starts), PAPER_VACATED
    )


def _sample_t_same_wire(
    code: np.ndarray,
    g: np.ndarray,
    wire: np.ndarray,
    wire_of: Callable[[np.ndarray], np.ndarray],
    t_of: Callable[[np.ndarray], np.ndarray],
    vacated: int,
) -> np.ndarray:
    """The trilinear mean of ``t_of(code)`` at field points ``g`` over the neighbours
    whose ``wire_of(code)`` is ``wire`` and which are not ``vacated``, renormalised by
    their weights; the nearest voxel's own t where none qualifies."""
    shape = np.asarray(code.shape)
    gc = np.clip(g - 0.5, 0.0, shape - 1.0)
    i0 = np.floor(gc).astype(np.int64)
    f = gc - i0
    ts = np.zeros(len(g))
    ws = np.zeros(len(g))
    for c in _CORNERS:
        idx = np.minimum(i0 + c, shape - 1)
        v = code[idx[:, 0], idx[:, 1], idx[:, 2]].astype(np.int64)
        ok = (wire_of(v) == wire) & (v != vacated)
        w = np.prod(np.where(c == 1, f, 1.0 - f), axis=1) * ok
        ts += w * t_of(v)
        ws += w
    near = np.floor(g).astype(np.int64)
    own = t_of(code[near[:, 0], near[:, 1], near[:, 2]].astype(np.int64))
    return np.where(ws > 0, ts / np.where(ws > 0, ws, 1.0), own)


def store_field(
    layout: str,
    wires: Sequence[Wire],
    tables: list[WireTables],
    box: tuple[np.ndarray, np.ndarray, tuple[int, int, int]],
    swept_side: tuple[np.ndarray, tuple[int, int, int], np.ndarray, np.ndarray, np.ndarray, int],
    vacated_side: tuple[np.ndarray, tuple[int, int, int], np.ndarray],
) -> WireField:
    """The attribute field in ``layout`` (build step 6): ``box`` the field's corner, voxel
    size and shape; ``swept_side`` the modified side's region (first voxel, shape, wire
    id and u per voxel, swept bits, seed count); ``vacated_side`` the base side's region
    and its vacated bits."""
    lo, h, shape = box
    region_lo, rshape, r_wire, r_u, swept, _ = swept_side
    b_lo, b_shape, vacated = vacated_side
    region = _box_slices(region_lo, rshape)
    b_region = _box_slices(b_lo, b_shape)
    tscale = LUT_SIZE - 1
    if layout == "float":
        state = np.zeros(shape, dtype=np.uint8, order="F")
        state[b_region] = vacated
        # into the field's (Fortran) boxes without full-size temporaries of the region
        ids = np.add(r_wire, 2, out=np.empty(rshape, dtype=np.uint8), casting="unsafe")
        np.copyto(state[region], ids, where=swept)
        tf = np.zeros(shape, dtype=np.float32, order="F")
        np.multiply(r_u, tscale, out=tf[region])
        return WireField(lo, h, shape, "float", state, tf, None, tables, region_lo, rshape)
    code = np.zeros(shape, dtype=np.uint16, order="F")
    if layout == "packed":
        ti = np.clip(np.rint(r_u * tscale), 0, tscale).astype(np.int32)
        c = (r_wire.astype(np.int32) << 8) | ti
        c = np.where(c == PACKED_VACATED, PACKED_VACATED - 1, c)
        c = np.where(swept, c | 0x8000, c)
        code[region] = c.astype(np.uint16)
        np.copyto(code[b_region], PACKED_VACATED, where=vacated)
        return WireField(lo, h, shape, "packed", None, None, code, tables, region_lo, rshape)
    starts = _segment_starts(wires, tables)
    counts = np.array([w.modified.n_segments for w in wires])
    code[region] = _paper_codes(r_wire, r_u, swept, starts, counts)
    np.copyto(code[b_region], PAPER_VACATED, where=vacated)
    return WireField(
        lo, h, shape, "paper", None, None, code, tables, region_lo, rshape, segments=starts
    )
