"""Tests of benchmarks.scale (``python -m benchmarks scale``) on tiny volumes."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
import pytest

from benchmarks import scale


def test_synthetic_cube_layers() -> None:
    """Air at the corners, the shell, the ball and its rod where the docstring says."""
    n = 40
    cube = scale.synthetic_cube(n)
    assert cube.shape == (n, n, n)
    assert cube.dtype == np.uint8
    c = n // 2
    assert cube[0, 0, 0] == 0
    assert cube[c, c, c] == 140  # the rod through the centre
    assert cube[c + 8, c, c] == 200  # inside the ball, off the rod
    assert cube[c + 16, c, c] == 80  # the shell (0.35 < r < 0.45 of the edge)
    assert set(np.unique(cube)) == {0, 80, 140, 200}
    assert cube.flags.f_contiguous  # the layout Volume keeps: no copy when wrapped


def test_peak_rss_sees_an_allocation() -> None:
    """A 64 MiB array touched inside the block shows in the peak beyond the start."""
    if scale._status_kib("VmHWM") < 0:
        pytest.skip("no /proc/self/status here")
    with scale.PeakRSS() as peak:
        block = np.ones(64 * 2**20, dtype=np.uint8)
        del block
    assert peak.reset
    assert 48 <= peak.mib < 1024


def test_sizes_arg() -> None:
    assert scale._sizes_arg("32,48") == (32, 48)
    for bad in ("", "4", "32,x", "2048"):
        with pytest.raises(argparse.ArgumentTypeError):
            scale._sizes_arg(bad)


@pytest.mark.slow
def test_bench_scale_tiny(gl_ctx: Any) -> None:
    """Two tiny volumes: positive timings, every phase, and growth ratios that are the
    quotients of the report's own numbers."""
    report = scale.bench_scale((48, 32), frames=1, size=(96, 96), ctx=gl_ctx, log=lambda s: None)
    assert [r.shape for r in report.rows] == [(32, 32, 32), (48, 48, 48)]  # ascending
    for r in report.rows:
        assert r.first_ms > 0
        assert r.steady_ms > 0
        assert set(r.phases) == {*scale.PHASES, scale.BLOCK_MIN_MAX}
        assert all(v >= 0 for v in r.phases.values())
        assert r.traced_mib > 0
        assert r.skip_kind == "cells, then cells"  # small volumes build cell maps at once
        assert r.second_ms > 0
    small, big = report.rows
    data = report.to_dict()
    growth = data["rows"][1]["growth"]
    assert growth["voxels"] == pytest.approx((48 / 32) ** 3)
    assert growth["first_frame"] == pytest.approx(big.first_ms / small.first_ms)
    assert growth["steady_frame"] == pytest.approx(big.steady_ms / small.steady_ms)
    assert data["rows"][0]["growth"]["first_frame"] == pytest.approx(1.0)
    text = report.markdown("python -m benchmarks scale --sizes 32,48")
    assert "| 48³ uint8 |" in text
    assert "3.4x" in text


def test_scale_scene_is_visible(offscreen: Any) -> None:
    """The benchmark scene draws something: the measured frames are not of empty space."""
    from voxwarp.bench.render import covered_fraction
    from voxwarp.core.volume import Volume

    r = offscreen(64, 64)
    bench = scale._Bench(r, 1)
    scene = bench.scene(Volume(scale.synthetic_cube(32), (1.0, 1.0, 1.0)))
    image = r.render(scene.copy(background=(0.0, 0.0, 0.0, 0.0)))
    assert 0.2 < covered_fraction(image) < 1.0


def test_samplings_arg() -> None:
    assert scale._samplings_arg("auto,slice_pairs") == ("auto", "slice_pairs")
    for bad in ("", "pairs", "auto,texture2d"):
        with pytest.raises(argparse.ArgumentTypeError):
            scale._samplings_arg(bad)


@pytest.mark.slow
def test_bench_scale_measures_each_sampling(gl_ctx: Any) -> None:
    """One row per sampling setting, in the layout asked for, with the memory kept
    after its cell maps measured."""
    report = scale.bench_scale(
        (96,),
        frames=1,
        size=(64, 64),
        ctx=gl_ctx,
        log=lambda s: None,
        samplings=("slice_pairs", "slice_layers"),
    )
    pairs, layers = report.rows
    assert (pairs.layout, layers.layout) == ("slice_pairs", "slice_layers")
    assert pairs.kept_mib >= 0
    assert layers.kept_mib >= 0
    assert "| slice_layers |" in report.markdown("python -m benchmarks scale")
