"""``python -m benchmarks wires --head`` (issue 19, lever 4) on a small head.

Oracles: both build paths give the same field (same swept and vacated counts); the
stages of a row never sum to more than its total; the markdown has one row per scale
and path and a target line per scale of the OpenCL path; the upsampled head keeps the
bundled MRI's millimetre box.
"""

from __future__ import annotations

import argparse

import numpy as np

from benchmarks import wires as bw
from voxwarp.io.samples import load_sample


def test_head_volume_keeps_the_mri_box() -> None:
    small = bw.head_volume(40)
    mri = load_sample("colin27")
    assert small.shape == (40, 40, 40)
    for vol in (small, mri):
        lo = np.asarray(vol.origin) - 0.5 * np.asarray(vol.spacing)
        hi = lo + np.asarray(vol.spacing) * np.asarray(vol.shape)
        if vol is small:
            box = (lo, hi)
        else:
            np.testing.assert_allclose(box[0], lo, atol=1e-9)
            np.testing.assert_allclose(box[1], hi, atol=1e-9)


def test_head_builds_compare_both_paths() -> None:
    rows = bw.bench_head_builds(bw.head_volume(40), scales=(8, 4), repeats=1, log=lambda s: None)
    assert [(r.scale, r.path) for r in rows] == [(s, p) for s in (8, 4) for p in bw.HEAD_PATHS]
    for a, b in zip(rows[::2], rows[1::2], strict=True):
        assert (a.swept, a.vacated, a.field_shape) == (b.swept, b.vacated, b.field_shape)
        assert a.swept > 0
    for r in rows:
        assert sum(r.stages.values()) <= r.median_s + 1e-6
    text = bw.head_markdown(rows, "python -m benchmarks wires --head --scales 8,4")
    assert text.startswith("Command: `python -m benchmarks wires --head --scales 8,4`")
    assert text.count("| 1:512 |") == 2
    assert text.count("| 1:64 |") == 2
    assert "Target: head field build" not in text  # targets exist for 1:8 and 1:1 only


def test_head_flag_is_parsed() -> None:
    p = argparse.ArgumentParser(prog="python -m benchmarks")
    bsub = p.add_subparsers()
    bw.add_bench_wires_parser(bsub)
    args = p.parse_args(["wires", "--head", "--repeats", "2"])
    assert args.head
    assert args.repeats == 2
    assert "--head" in bw.command_line(args)
