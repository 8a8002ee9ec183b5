"""The OpenCL classification kernel cache (deform/wires/classify.py) never hands out a
kernel of another context: a context made after one was freed can reuse its id()
(tests reset the OpenCL state), and the stale kernel failed with INVALID_CONTEXT."""

from __future__ import annotations

import pytest

from voxwarp.deform.wires import classify as wc
from voxwarp.deform.wires import propagation as prop


def test_a_reused_context_id_gets_its_own_kernel(monkeypatch: pytest.MonkeyPatch) -> None:
    if not prop.opencl_available():
        pytest.skip("no OpenCL platform")
    st = prop._opencl_state()
    if not wc.classify_available(st):
        pytest.skip("no double-precision OpenCL device")
    stale = object()
    # what the cache held when a freed context had this id
    monkeypatch.setitem(wc._programs, id(st["ctx"]), (object(), stale))
    kernel = wc._program(st)
    assert kernel is not None
    assert kernel is not stale
    assert wc._programs[id(st["ctx"])][0] is st["ctx"]
    assert wc._program(st) is kernel  # then cached
