"""A wire's lookup tables: the mapping ``q = A p + b`` tabulated along the wire
(wire paper, section 7.2: wire points and frames at integer t)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from voxwarp.deform.wires.constants import LUT_SIZE
from voxwarp.deform.wires.curves import minimal_rotation

if TYPE_CHECKING:
    from voxwarp.deform.wires.wire import Wire


@dataclass
class WireTables:
    """A wire's mapping tabulated at ``n`` equally spaced arc-length fractions u_i.

    ``q = C(u) + A(u) (p - M(u))`` maps deformed points near the modified wire to the
    original volume (see :mod:`voxwarp.deform.wires`); M, C, A are interpolated linearly in u.
    """

    #: fractions u_i = i / (n - 1)
    u: np.ndarray
    #: modified wire points M(u_i) (n, 3)
    modified_points: np.ndarray
    #: modified wire frames (n, 3, 3), columns (N, B, T)
    modified_frames: np.ndarray
    #: base wire points C(u_i) (n, 3)
    base_points: np.ndarray
    #: base wire frames (n, 3, 3), columns (N, B, T)
    base_frames: np.ndarray
    #: the linear part A(u_i) (n, 3, 3)
    matrices: np.ndarray
    #: curve parameters of u_i on each curve, and their segment indices
    t_base: np.ndarray
    t_modified: np.ndarray
    segment_base: np.ndarray
    segment_modified: np.ndarray
    #: arc lengths (mm)
    length_base: float
    length_modified: float
    #: b(u_i) = C - A M (n, 3): the mapping is ``q = A p + b``
    offsets: np.ndarray

    @classmethod
    def build(cls, wire: Wire, n: int = LUT_SIZE, precision: float = 1e-4) -> WireTables:
        """Tabulate ``wire`` (see the class docstring)."""
        u = np.linspace(0.0, 1.0, n)
        tb, sb = wire.base.arc_length_table(n, precision)
        tm, sm = wire.modified.arc_length_table(n, precision)
        lb, lm = float(sb[-1]), float(sm[-1])
        tb_, nb_, bb_ = wire.base.frames(tb, initial_normal=wire.initial_normal)
        rot = minimal_rotation(tb_[0], wire.modified.frames(np.array([0.0]))[0][0])
        tm_, nm_, bm_ = wire.modified.frames(tm, initial_normal=rot @ nb_[0])
        fb = np.stack([nb_, bb_, tb_], axis=-1)
        fm = np.stack([nm_, bm_, tm_], axis=-1)
        theta = wire.twist_at(u)
        s = wire.scale_at(u)
        c, si = np.cos(-theta), np.sin(-theta)
        rz = np.zeros((n, 3, 3))
        rz[:, 0, 0], rz[:, 0, 1], rz[:, 1, 0], rz[:, 1, 1] = c, -si, si, c
        rz[:, 2, 2] = 1.0
        d = np.zeros((n, 3, 3))
        d[:, 0, 0] = d[:, 1, 1] = 1.0 / s
        d[:, 2, 2] = lb / lm
        a = fb @ d @ rz @ np.transpose(fm, (0, 2, 1))
        m_pts, b_pts = wire.modified.evaluate(tm), wire.base.evaluate(tb)
        return cls(
            u=u,
            modified_points=m_pts,
            modified_frames=fm,
            base_points=b_pts,
            base_frames=fb,
            matrices=a,
            t_base=tb,
            t_modified=tm,
            segment_base=wire.base.segment_of(tb)[0],
            segment_modified=wire.modified.segment_of(tm)[0],
            length_base=lb,
            length_modified=lm,
            offsets=b_pts - np.einsum("nij,nj->ni", a, m_pts),
        )

    @property
    def size(self) -> int:
        """Number of entries."""
        return len(self.u)

    def lookup(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(A, b) at continuous table coordinates t in [0, n - 1], each linear in t (as
        the shader's filtered lookup table)."""
        return _lerp_table(self.matrices, t), _lerp_table(self.offsets, t)

    def gpu_rows(self) -> np.ndarray:
        """The 3 RGBA32F rows of the shader's lookup table, (3, n, 4) float32: row r holds
        (A[r, 0], A[r, 1], A[r, 2], b[r])."""
        out = np.empty((3, self.size, 4), dtype=np.float32)
        out[:, :, :3] = np.transpose(self.matrices, (1, 0, 2))
        out[:, :, 3] = self.offsets.T
        return out


def map_points(tables: WireTables, t: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The wire mapping ``q = A p + b`` at table coordinates t (deformed -> original)."""
    a, b = tables.lookup(t)
    return np.einsum("nij,nj->ni", a, p) + b


def _lerp_table(table: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Entries of a table (n, ...) linearly interpolated at table coordinates t (clamped
    to [0, n - 1]); frames come out not re-orthonormalised (neighbouring entries differ
    by well under a degree)."""
    n = table.shape[0]
    t = np.clip(np.asarray(t, dtype=np.float64), 0.0, n - 1)
    i0 = np.minimum(np.floor(t).astype(np.int64), n - 2)
    f = (t - i0).reshape(-1, *([1] * (table.ndim - 1)))
    return table[i0] * (1 - f) + table[i0 + 1] * f
