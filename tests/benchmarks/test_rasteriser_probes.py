"""The lab's rasteriser probes (benchmarks.rasteriser_probes) compile and draw: a probe
whose shader no longer compiles would leave docs/benchmarks.md quoting a dead command."""

from __future__ import annotations

from typing import Any

import pytest

from benchmarks.rasteriser_probes import PROBES, run_probe


@pytest.mark.gl
@pytest.mark.parametrize("name", sorted(PROBES))
def test_every_probe_variant_draws(gl_ctx: Any, name: str) -> None:
    times = run_probe(gl_ctx, name, rounds=1, size=8)
    assert list(times) == list(PROBES[name])
    assert all(ms > 0.0 for ms in times.values())
