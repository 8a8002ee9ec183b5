"""``python -m benchmarks wire-tables``: the identity wires, the wire laid along an object's axis,
the regions of influence and Table 1 counted inside them."""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
import pytest

from benchmarks.wire_tables import TablesRow, axis_wire, identity_wires, markdown, measure
from benchmarks.wires import influence_region, ray_sample_stats
from tests.benchmarks.test_bench_wires import _Box, _HalfSwept
from voxwarp.core.camera import Camera
from voxwarp.core.volume import Volume
from voxwarp.deform.wires.field import Wire, WireDeformer


def _cylinder(axis: np.ndarray, radius: float = 6.0) -> Volume:
    """A 64³ volume (1 mm) holding a bright cylinder along ``axis`` through the centre,
    40 mm long."""
    g = np.stack(np.meshgrid(*(np.arange(64.0),) * 3, indexing="ij"), -1) - 31.5
    a = axis / np.linalg.norm(axis)
    along = g @ a
    radial = np.linalg.norm(g - along[..., None] * a, axis=-1)
    data = np.where((np.abs(along) < 20) & (radial < radius), 1000, 0).astype(np.int16)
    return Volume(data, spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0))


def test_identity_wires_map_every_point_to_itself() -> None:
    wire = Wire(
        [[10, 32, 32], [32, 32, 32], [54, 32, 32]],
        [[10, 32, 32], [32, 40, 32], [54, 50, 32]],
        twist=[(0.0, 0.0), (1.0, 1.0)],
        scale=[(0.0, 1.0), (1.0, 1.5)],
        radius=8.0,
    )
    (ident,) = identity_wires([wire])
    assert np.array_equal(ident.modified.control_points, wire.base.control_points)
    vol = _cylinder(np.array([1.0, 0.0, 0.0]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        wd = WireDeformer(vol, [ident], field_scale=1)
        wd.build()
    p = np.random.default_rng(1).uniform(10, 54, (5000, 3))
    assert np.abs(wd.warp().apply(p) - p).max() < 1e-9
    assert wd.field.decode()[0].max() >= 2  # something is swept: the map is exercised


@pytest.mark.parametrize("axis", [(1.0, 0.0, 0.0), (1.0, 1.0, 0.5)])
def test_axis_wire_runs_along_the_object_with_its_ends_outside(axis: Any) -> None:
    a = np.asarray(axis) / np.linalg.norm(axis)
    vol = _cylinder(a)
    w = axis_wire(vol, 500.0)
    pts = w.base.evaluate(np.linspace(0, 1, 101))
    centre = np.full(3, 31.5)
    # on the axis (within a voxel) and past both ends of the 40 mm cylinder
    off_axis = np.linalg.norm((pts - centre) - np.outer((pts - centre) @ a, a), axis=1)
    assert off_axis.max() < 1.0
    ends = (pts[[0, -1]] - centre) @ a
    assert min(abs(ends[0]), abs(ends[1])) > 20.0
    assert ends[0] * ends[1] < 0
    assert 6.0 <= w.radius <= 6.0 + 2.0 + 1.0  # covers the cylinder, 2 voxels margin
    assert w.beta == (500.0, 1000.0)


def test_axis_wire_needs_an_object() -> None:
    vol = Volume(np.zeros((8, 8, 8), np.int16))
    with pytest.raises(ValueError, match="no object"):
        axis_wire(vol, 10.0)


def test_influence_region_is_the_tubes_around_both_wires() -> None:
    wire = Wire([[0, 0, 0], [50, 0, 0]], [[0, 20, 0], [50, 20, 0]], radius=5.0, scale=[(0.0, 2.0)])
    inside = influence_region([wire])
    pts = np.array(
        [
            [25, 4.9, 0],  # near the base wire
            [25, 5.2, 0],  # just outside the base tube
            [25, 29.8, 0],  # within radius x scale (10) of the modified wire
            [25, 30.3, 0],  # just outside it
            [25, 0, -4.9],
        ]
    )
    assert inside(pts).tolist() == [True, False, True, False, True]


def test_table1_counts_the_samples_inside_the_region() -> None:
    cam = Camera.fit((0, 0, 0), (10, 10, 6), view="+z", projection="orthographic")
    everything = ray_sample_stats(
        _Box(), cam, (64, 64), _HalfSwept(), subsample=2, region=lambda p: np.ones(len(p), bool)
    )
    assert everything.region_samples == everything.samples
    assert everything.region_identity == everything.identity
    half = ray_sample_stats(
        _Box(), cam, (64, 64), _HalfSwept(), subsample=2, region=lambda p: p[:, 0] > 5
    )
    assert half.region_samples == half.swept  # x > 5 is exactly the swept half
    assert half.region_identity == 0
    assert half.percent_ignored_in_region == 0.0
    assert (
        ray_sample_stats(_Box(), cam, (64, 64), _HalfSwept(), 2).percent_ignored_in_region is None
    )


@pytest.mark.gl
def test_measure_the_tubes(gl_ctx: Any) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        row = measure("tubes", size=(96, 48), frames=1, repeats=1, ctx=gl_ctx, log=lambda s: None)
    assert isinstance(row, TablesRow)
    s = row.samples
    assert 0 < s.region_samples < s.samples
    assert s.percent_ignored_in_region < s.percent_ignored  # the region holds the object
    assert row.render_ratio == pytest.approx(row.identity_ms / row.standard_ms)
    assert row.total_ratio > row.render_ratio
    assert math.isfinite(row.changed_pixels)
    assert row.changed_pixels < 5.0
    text = markdown([row], "python -m benchmarks wire-tables")
    assert "| paper (Tables 2-3): Tubes | 2590 | 0.96 | 4810 | 1.86x | 2.23x | — |" in text
    assert "| paper (Table 1): CT Carp | — | — | 26,011,195 | 59.7 |" in text
