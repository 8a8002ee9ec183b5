"""Per-box bounds of one wire field: the displacement intervals of the raycaster's
skipping through deformed space, and where the object left its place.

:class:`FieldBounds` answers for index boxes of the field's propagated region from mip
pyramids built once per field (:class:`~voxwarp.deform.wires.bounds._ReducePyramid`):

* the *info* pyramid: per voxel the range of t over its 3³ neighbourhood (what the
  GPU's filtered lookups can return there), the wire id of swept voxels, and whether it
  is the identity. A box whose swept voxels belong to one wire gets that wire's mapping
  bounded over the box itself and that t range (:func:`_box_mapping_range`); a box
  without swept voxels moves nothing.
* the per-voxel *displacement* pyramid (every swept voxel's own interval: the costly
  one), only for boxes holding swept voxels of several wires; built the first time such
  a box is asked about, so a single-wire field never pays for it.
* the *vacated* pyramid: whether a box holds a voxel the swept object left.
"""

from __future__ import annotations

import threading

import numpy as np
from scipy import ndimage

from voxwarp.deform.wires.bounds import (
    _AnyPyramid,
    _box_mapping_range,
    _grow,
    _MinMaxPyramid,
    _ReducePyramid,
)
from voxwarp.deform.wires.constants import LUT_SIZE
from voxwarp.deform.wires.geometry import _box_slices
from voxwarp.deform.wires.layouts import WireField


class FieldBounds:
    """Bounds of one built :class:`~voxwarp.deform.wires.layouts.WireField` over
    world boxes (make a new one when the field changes)."""

    def __init__(self, fld: WireField) -> None:
        self.field = fld
        self._info: _ReducePyramid | None = None
        self._vacated: _AnyPyramid | None = None
        self._displacement: _MinMaxPyramid | None = None
        # the GUI asks from two threads at once (the skip maps' worker, the support on
        # the GUI thread): one builds each pyramid, the other waits for it
        self._lock = threading.Lock()

    def voxel_boxes(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The field voxel indices (first, last; (n, 3) each, unclipped) holding the
        corners of the world boxes [lo, hi] (the voxel a sample looks up)."""
        fld = self.field
        lo = np.atleast_2d(np.asarray(lo, dtype=np.float64))
        hi = np.atleast_2d(np.asarray(hi, dtype=np.float64))
        a = np.floor((lo - fld.lo) / fld.spacing).astype(np.int64)
        b = np.floor((hi - fld.lo) / fld.spacing).astype(np.int64)
        return a, b

    def displacement_range(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per world box, an interval holding ``apply(p) - p`` over the samples that
        can show something (see :meth:`WireFieldWarp.displacement_range`)."""
        lo = np.atleast_2d(np.asarray(lo, dtype=np.float64))
        hi = np.atleast_2d(np.asarray(hi, dtype=np.float64))
        fld = self.field
        a, b = (v - fld.region_lo for v in self.voxel_boxes(lo, hi))
        rs = np.asarray(fld.region_shape)
        empty = np.any((b < 0) | (a > rs - 1), axis=1)  # no voxel of the region
        outside = np.any((a < 0) | (b > rs - 1), axis=1)  # some place outside it
        a, b = np.clip(a, 0, rs - 1), np.clip(b, 0, rs - 1)
        rlo = np.zeros((len(lo), 3))
        rhi = np.zeros((len(lo), 3))
        t_lo, t_hi, ident, w_lo, w_hi = self._info_query(a, b)
        swept = (~empty) & np.isfinite(w_lo)
        one = swept & (w_lo == w_hi)
        mixed = np.nonzero(swept & ~one)[0]
        if len(mixed):  # several wires' swept voxels: their own intervals' union
            m_lo, m_hi = self._displacement_pyramid()(a[mixed], b[mixed])
            out = outside[mixed, None]
            rlo[mixed] = np.where(out, np.minimum(m_lo, 0.0), m_lo)
            rhi[mixed] = np.where(out, np.maximum(m_hi, 0.0), m_hi)
        sel = np.nonzero(one)[0]
        if len(sel):  # one wire: its mapping over the box itself (tighter)
            tight_lo, tight_hi = _box_mapping_range(
                fld.tables,
                w_lo[sel].astype(np.int64),
                np.maximum(t_lo[sel], 0.0),
                np.minimum(t_hi[sel], LUT_SIZE - 1.0),
                lo[sel],
                hi[sel],
            )
            # (a smooth wire's weight scales the displacement towards 0)
            keep0 = (outside[sel] | ident[sel] | (fld.weight is not None))[:, None]
            rlo[sel] = _grow(np.where(keep0, np.minimum(tight_lo, 0.0), tight_lo), -1.0)
            rhi[sel] = _grow(np.where(keep0, np.maximum(tight_hi, 0.0), tight_hi), 1.0)
        none = rlo > rhi  # only vacated voxels: nothing shows; any interval is sound
        rlo[none] = 0.0
        rhi[none] = 0.0
        return rlo, rhi

    def any_vacated(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray | None:
        """Per world box, whether it holds a vacated voxel; None where the field has
        none."""
        self._info_pyramid()
        if self._vacated is None:
            return None
        a, b = self.voxel_boxes(lo, hi)
        top = np.asarray(self.field.shape) - 1
        meets = np.all((b >= 0) & (a <= top), axis=1)
        out = np.zeros(len(a), dtype=bool)
        out[meets] = self._vacated(np.clip(a[meets], 0, top), np.clip(b[meets], 0, top))
        return out

    def _info_pyramid(self) -> _ReducePyramid:
        """The info pyramid over the propagated region (t min, t max, any identity, and
        the swept voxels' wire ids: their min and max, or with one wire whether there
        are any), and the vacated pyramid over the field, from one decode."""
        with self._lock:
            if self._info is None:
                self._info = self._build_info()
            return self._info

    def _build_info(self) -> _ReducePyramid:
        """:meth:`_info_pyramid`'s build (sets the vacated pyramid too)."""
        fld = self.field
        state, wire, t_all = fld.decode()
        vacated = state == 1
        self._vacated = _AnyPyramid(vacated) if vacated.any() else None
        del vacated
        st, wr, t_lo, t_hi = _region_t_ranges(fld, state, wire, t_all)
        swept = st == 2
        if len(fld.tables) == 1:  # one wire: whether a box holds swept voxels says it all
            wires = [(swept, np.logical_or, False)]
        else:  # wire ids (< 128) are exact in float32
            w_lo, w_hi = wr.astype(np.float32), wr.astype(np.float32)
            w_lo[~swept], w_hi[~swept] = np.inf, -np.inf
            wires = [(w_lo, np.minimum, np.inf), (w_hi, np.maximum, -np.inf)]
        return _ReducePyramid(
            (t_lo, np.minimum, np.inf),
            (t_hi, np.maximum, -np.inf),
            (st == 0, np.logical_or, False),
            *wires,
        )

    def _info_query(self, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, ...]:
        """Per index box of the region: t min, t max, any identity voxel, and the least
        and greatest wire id of its swept voxels (inf and -inf: none)."""
        t_lo, t_hi, ident, *wires = self._info_pyramid()(a, b)
        if len(wires) == 2:
            return t_lo, t_hi, ident, wires[0], wires[1]
        zero = np.where(wires[0], 0.0, np.inf)
        return t_lo, t_hi, ident, zero, np.where(wires[0], 0.0, -np.inf)

    def _displacement_pyramid(self) -> _MinMaxPyramid:
        """Per-voxel displacement intervals over the propagated region: a swept voxel's
        is that of its box for every t its samples can interpolate (from its 3³
        neighbourhood); identity voxels give [0, 0], vacated ones nothing."""
        with self._lock:
            if self._displacement is None:
                self._displacement = _voxel_intervals(self.field)
            return self._displacement


def _region_t_ranges(
    fld: WireField, state: np.ndarray, wire: np.ndarray, t_all: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """State and wire id over the propagated region of the decoded field, and per
    voxel the range of t over its 3³ neighbourhood (what the GPU's filtered lookups of
    t can return there), in the field's float type (min and max are exact in it)."""
    region = _box_slices(fld.region_lo, fld.region_shape)
    tt = np.asarray(t_all[region])
    if tt.dtype != np.float32:
        tt = tt.astype(np.float64)
    t_lo = ndimage.minimum_filter(tt, size=3, mode="nearest")
    t_hi = ndimage.maximum_filter(tt, size=3, mode="nearest")
    return state[region], wire[region], t_lo, t_hi


def _voxel_intervals(fld: WireField) -> _MinMaxPyramid:
    """:meth:`FieldBounds._displacement_pyramid`'s pyramid (float32, rounded outwards)."""
    rs = fld.region_shape
    st, wr, t_lo, t_hi = _region_t_ranges(fld, *fld.decode())
    idx = np.nonzero(st.ravel() == 2)[0]
    ii = np.stack(np.unravel_index(idx, rs), -1)
    centres = fld.lo + (ii + fld.region_lo + 0.5) * fld.spacing
    half = 0.5 * fld.spacing
    d_lo, d_hi = _box_mapping_range(
        fld.tables,
        wr.ravel()[idx],
        t_lo.ravel()[idx],
        t_hi.ravel()[idx],
        centres - half,
        centres + half,
    )
    dlo = np.empty((*rs, 3), dtype=np.float32)
    dhi = np.empty((*rs, 3), dtype=np.float32)
    dlo[...] = np.where(st == 0, 0.0, np.inf)[..., None]
    dhi[...] = np.where(st == 0, 0.0, -np.inf)[..., None]
    if fld.weight is not None:  # weights in [0, 1] scale each displacement towards 0
        d_lo, d_hi = np.minimum(d_lo, 0.0), np.maximum(d_hi, 0.0)
    dlo.reshape(-1, 3)[idx] = _outward32(_grow(d_lo, -1.0), -1.0)
    dhi.reshape(-1, 3)[idx] = _outward32(_grow(d_hi, 1.0), 1.0)
    return _MinMaxPyramid(dlo, dhi)


def _outward32(x: np.ndarray, sign: float) -> np.ndarray:
    """``x`` as float32, each value rounded away from it towards ``sign`` (-1: down,
    +1: up) where float32 cannot hold it: a bound stays a bound."""
    y = x.astype(np.float32)
    off = y < x if sign > 0 else y > x
    y[off] = np.nextafter(y[off], np.float32(np.inf * sign))
    return y
