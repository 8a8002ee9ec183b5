"""The paper layout's guard against a voxel code colliding with the vacated code
(issue 33): with 16 wires x 16 segments, a voxel of wire 15 at the very end of its last
segment packs to ``15 << 11 | 15 << 7 | 127`` = 0x7FFF, which is
:data:`PAPER_VACATED`; such a voxel must take t = 126 (one t step, 1/127 of the
segment, short of its end) and never read back as vacated, swept or not."""

from __future__ import annotations

import numpy as np

from voxwarp.deform.wires.constants import LUT_SIZE, PAPER_VACATED
from voxwarp.deform.wires.layouts import _paper_codes, _paper_t

WIRES = SEGMENTS = 16


def _starts() -> np.ndarray:
    """Evenly spaced segment starts (table units) of 16 wires of 16 segments each."""
    top = float(LUT_SIZE - 1)
    row = np.arange(SEGMENTS + 1) / SEGMENTS * top
    return np.tile(row, (WIRES, 1)).astype(np.float32)


def test_the_last_voxel_of_wire_15_is_not_the_vacated_code() -> None:
    starts, counts = _starts(), np.full(WIRES, SEGMENTS)
    wire = np.repeat(np.arange(WIRES), 3)
    u = np.tile([0.0, 0.5, 1.0], WIRES)  # start, middle, end of every wire
    for swept in (False, True):
        codes = _paper_codes(wire, u, np.full(wire.shape, swept), starts, counts)
        low = codes.astype(np.int64) & 0x7FFF
        assert not np.any(low == PAPER_VACATED)
        assert low[-1] == PAPER_VACATED - 1  # wire 15, segment 15, t 126
        assert bool(codes[-1] & 0x8000) == swept
        t = _paper_t(low, starts)
        np.testing.assert_allclose(t[:-1], u[:-1] * (LUT_SIZE - 1), atol=1e-3)
        step = (starts[15, 16] - starts[15, 15]) / 127  # one t step of the last segment
        np.testing.assert_allclose(t[-1], LUT_SIZE - 1 - step, rtol=1e-6)
