"""``python -m benchmarks wire-ends``: rigid vs smooth wire ends on the bundled MRI."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from benchmarks.wire_ends import SCALES, head_wire, markdown, measure_case
from benchmarks.wires import content_box
from voxwarp.io.samples import load_sample


def test_head_wire_ends_inside_the_head() -> None:
    vol = load_sample("colin27")
    _, hi = content_box(vol)
    w = head_wire(vol, "rigid")
    top = w.base.evaluate(np.array([1.0]))[0]
    assert top[2] == pytest.approx(hi[2] - 14.0)  # 14 mm below the top: inside the head
    assert w.modified.evaluate(np.array([1.0]))[0][0] == pytest.approx(top[0] + 40.0)


@pytest.mark.gl
@pytest.mark.slow
def test_smooth_ends_leave_fewer_seams_than_the_rigid_cut(gl_ctx: Any) -> None:
    rows = measure_case("colin27", size=(160, 160), frames=1, repeats=1)
    assert [r.ends for r in rows] == ["rigid", "smooth"]
    rigid, smooth = rows
    for r in rows:
        assert set(r.seams) == set(SCALES)
        assert r.build_s > 0
        assert r.frame_ms > 0
    # the rigid sweep cuts the skull where the wire ends; coarse fields make the cut
    # blocky, while the smooth falloff has no cut to coarsen
    assert smooth.seams[2][0] < rigid.seams[2][0]
    text = markdown(rows, "python -m benchmarks wire-ends")
    assert "| colin27 | smooth |" in text
    assert "smooth / rigid build" in text
