"""Smoke tests of ``python -m benchmarks lattice`` (benchmarks.lattice) on a tiny configuration.

Oracles: every FPS ratio is the quotient of the two medians it names; the report has
one row per cell count and configuration, in order; the torus has 4 n² triangles (about
the requested count) and the composition graph exactly the requested objects, each a
48-triangle sphere; the trilinear graph composes a lattice per leaf, the linear one a
matrix per leaf; the bench's own MeshInstance wrapping equals
``instances_from_scene_graph``; bad options exit with status 2 and say why.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from benchmarks import lattice as bl
from benchmarks.lattice import (
    THROUGHPUT_CONFIGS,
    CompositionRow,
    LatticeBenchReport,
    ThroughputRow,
    add_bench_lattice_parser,
    bench_lattice,
    build_scene_graph,
    torus_for,
    wrap_instances,
)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m benchmarks")
    bsub = p.add_subparsers(dest="bench", required=True)
    add_bench_lattice_parser(bsub)
    return p


def test_tiny_run(gl_ctx: Any) -> None:
    logged: list[str] = []
    cells = (3, 1)
    report = bench_lattice(
        triangles=2000,
        objects=30,
        frames=2,
        size=(48, 32),
        cells=cells,
        ctx=gl_ctx,
        log=logged.append,
    )
    assert report.gl_renderer not in ("", "?")
    # the torus: 4 n² triangles, 2 n² vertices, close to the request
    n = round((2000 / 4) ** 0.5)
    assert report.triangles == 4 * n * n
    assert report.vertices == 2 * n * n
    assert abs(report.triangles - 2000) / 2000 < 0.05
    # section 1: one row per cell count and configuration, in order
    keys = [(r.cells, r.stage, r.normal_method, r.position) for r in report.throughput]
    assert keys == [(c, *cfg) for c in cells for cfg in THROUGHPUT_CONFIGS]
    for r in report.throughput:
        assert r.frames == 2
        assert 0 < r.lattice_min_ms <= r.lattice_ms
        assert 0 < r.linear_min_ms <= r.linear_ms
        assert r.fps_ratio == pytest.approx(r.linear_ms / r.lattice_ms)
        assert r.fps_ratio == pytest.approx(r.lattice_fps / r.linear_fps)
        if r.stage == "frame":
            assert 0 < r.lattice_coverage <= 100
            assert 0 < r.linear_coverage <= 100
            assert 0 < r.changed <= 100  # the lattice bends the torus
        else:
            assert r.lattice_coverage is None
            assert r.linear_coverage is None
            assert r.changed is None
    cc = report.crosscheck
    assert cc is not None
    assert cc.cells == (3, 3, 3)  # the middle of the sorted cell counts
    assert cc.size == 48
    assert "square" in cc.note
    assert cc.triangles == report.triangles
    assert cc.fps_ratio("lattice_normal") == pytest.approx(
        cc.ms["linear"] / cc.ms["lattice_normal"]
    )
    # section 2: both graphs, exact object counts
    assert [r.variant for r in report.composition] == ["trilinear", "linear"]
    tri, lin = report.composition
    for r in report.composition:
        assert r.objects == 30
        assert r.triangles == 30 * 48
        assert r.depth == 2
        assert r.nodes == 1 + r.groups + r.objects
        assert r.frames == 2
        assert 0 < r.frame_min_ms <= r.frame_ms
        assert min(r.compose_ms, r.wrap_ms, r.draw_ms, r.static_draw_ms) > 0
        # frame = compose + wrap + draw per frame: its median is at least each part's
        # median, its minimum at least the sum of the parts' minima
        assert r.frame_ms >= max(r.compose_ms, r.wrap_ms, r.draw_ms) - 1e-9
        assert 0 < r.coverage <= 100
    assert (tri.grid_leaves, tri.composed_cells) == (30, (4, 4, 4))
    assert (lin.grid_leaves, lin.composed_cells) == (0, None)
    assert report.composition_fps_ratio == pytest.approx(lin.frame_ms / tri.frame_ms)
    assert report.static_fps_ratio == pytest.approx(lin.static_draw_ms / tri.static_draw_ms)
    assert report.compose_ratio == pytest.approx(tri.compose_ms / lin.compose_ms)
    assert report.compose_ratio > 1  # lattices compose node by node, matrices multiply

    text = report.markdown("python -m benchmarks lattice --triangles 2000")
    assert text.startswith("Command: `python -m benchmarks lattice --triangles 2000`")
    for heading in ("## Summary", "## 1. Vertex throughput", "## 2. Composition"):
        assert heading in text
    assert "| 3³ | vertex | tangent | exact |" in text
    assert "| 1³ | frame | normal | hardware |" in text
    assert f"| trilinear | 30 | {tri.groups} | 30 x 4x4x4 |" in text
    assert f"animated frame {report.composition_fps_ratio:.2f}" in text
    row = report.row(1, "frame", "tangent")
    assert f"tangent {row.fps_ratio:.0%}" in text
    assert f"{row.fps_ratio:.2f} |" in text
    assert f"Device: GL {report.gl_renderer};" in text
    assert any(s.startswith("composition frame 2/2") for s in logged)


def test_report_ratios_without_gl() -> None:
    report = LatticeBenchReport(
        triangles_requested=1000,
        triangles=1024,
        vertices=512,
        objects=10,
        cells=(2,),
        frames=3,
        size=(64, 64),
    )
    for method, ms in (("normal", 100.0), ("tangent", 80.0)):
        for stage in ("frame", "vertex"):
            report.throughput.append(
                ThroughputRow(2, stage, method, "exact", 3, ms, ms - 1, 60.0, 59.0)
            )
    common = dict(objects=10, groups=4, nodes=15, depth=2, triangles=480, frames=3)
    report.composition = [
        CompositionRow(
            "trilinear",
            **common,
            grid_leaves=10,
            composed_cells=(4, 4, 4),
            compose_ms=8.0,
            wrap_ms=1.0,
            draw_ms=3.0,
            static_draw_ms=2.0,
            frame_ms=12.0,
            frame_min_ms=11.0,
        ),
        CompositionRow(
            "linear",
            **common,
            grid_leaves=0,
            composed_cells=None,
            compose_ms=0.5,
            wrap_ms=1.5,
            draw_ms=2.0,
            static_draw_ms=2.0,
            frame_ms=4.0,
            frame_min_ms=3.5,
        ),
    ]
    assert report.row(2, "frame", "normal").fps_ratio == pytest.approx(0.6)
    assert report.row(2, "frame", "tangent").fps_ratio == pytest.approx(0.75)
    assert report.row(2, "frame", "normal", "hardware") is None
    assert report.composition_fps_ratio == pytest.approx(4.0 / 12.0)
    assert report.static_fps_ratio == pytest.approx(1.0)
    assert report.compose_ratio == pytest.approx(16.0)
    summary = report.summary_lines()
    assert "2³ cells: normal 60%, tangent 75%" in summary[1]
    assert "vertex stage only" in summary[2]
    assert "= 33% per animated frame (12.0 vs 4.0 ms" in summary[3]
    text = report.markdown("python -m benchmarks lattice")
    row = (
        "| 2³ | frame | tangent | exact | 80.0 (79.0) | 60.0 (59.0) | 12.5 | 16.7 | 0.75 | — | — |"
    )
    assert row in text
    assert "| linear | 10 | 4 | none (4x4) |" in text
    assert "Cross-check" not in text  # not run


@pytest.mark.parametrize("objects", [1, 7, 30])
def test_scene_graphs_compose_as_described(objects: int) -> None:
    from voxwarp.core.mesh import instances_from_scene_graph
    from voxwarp.deform.lattice.scene_graph import compose_scene

    composed = {}
    for lattice in (True, False):
        root, info = build_scene_graph(objects, lattice)
        nodes = list(root.walk())
        assert info.objects == objects
        assert info.nodes == len(nodes) == 1 + info.groups + objects
        assert max(d for _, d in nodes) == info.depth == 2
        assert info.groups == -(-objects // info.per_group)
        leaves = compose_scene(root)
        assert len(leaves) == objects
        assert all(c.is_linear != lattice for c in leaves)
        # the bench's wrapping is what instances_from_scene_graph does
        ours = wrap_instances(leaves)
        ref = instances_from_scene_graph(root)
        assert len(ours) == len(ref) == objects
        for a, b in zip(ours, ref, strict=True):
            assert (a.name, a.color, a.normal_method) == (b.name, b.color, b.normal_method)
            assert a.mesh is b.mesh
            np.testing.assert_allclose(a.box[0], b.box[0])
            np.testing.assert_allclose(a.box[1], b.box[1])
            if lattice:
                np.testing.assert_allclose(a.transform.nodes, b.transform.nodes)
            else:
                np.testing.assert_allclose(a.transform, b.transform)
            assert a.mesh.n_faces == 48
        composed[lattice] = ours
    # same objects, bent by the lattices: the world positions differ, but not wildly
    moved = []
    for a, b in zip(composed[True], composed[False], strict=True):
        wa, wb = a.world_vertices(), b.world_vertices()
        moved.append(float(np.abs(wa - wb).max()))
    assert max(moved) > 0.01
    assert max(moved) < 10.0


def test_torus_triangle_counts() -> None:
    for asked in (100, 2000, 50_000):
        mesh = torus_for(asked)
        assert abs(mesh.n_faces - asked) / asked < 0.11
        assert mesh.n_vertices * 2 == mesh.n_faces


def test_bad_options_are_rejected(capsys: pytest.CaptureFixture) -> None:
    parser = _parser()
    bad_cases = (
        ["--triangles", "0"],
        ["--triangles", "abc"],
        ["--triangles", "1e400"],
        ["--triangles", "1.5"],
        ["--objects", "0"],
        ["--objects", "-3"],
        ["--frames", "0"],
        ["--size", "512"],
        ["--size", "0x10"],
        ["--cells", "0"],
        ["--cells", "4,x"],
    )
    for bad in bad_cases:
        with pytest.raises(SystemExit) as exc:
            parser.parse_args(["lattice", *bad])
        assert exc.value.code == 2, bad
    err = capsys.readouterr().err
    assert "--triangles must be a whole number 100..20000000" in err
    assert "--objects must be a whole number 1..100000" in err
    assert "--frames must be a whole number" in err
    assert "size must be WxH" in err
    assert "size must be 1..16384 pixels per side" in err
    assert "cells are comma-separated whole numbers 1..64" in err
    args = parser.parse_args(["lattice"])
    assert (args.triangles, args.objects, args.frames) == (1_500_000, 2000, 5)
    assert (args.size, args.cells, args.markdown) == ((512, 512), (1, 4, 16), None)
    assert args.func is bl.cmd_bench_lattice
    args = parser.parse_args(
        ["lattice", "--triangles", "1.5e6", "--cells", "4,1,4", "--size", "64X32"]
    )
    assert (args.triangles, args.cells, args.size) == (1_500_000, (4, 1), (64, 32))
    with pytest.raises(ValueError, match="cells per axis"):
        bench_lattice(cells=(0,), log=lambda s: None)
    with pytest.raises(ValueError, match="triangles must be"):
        bench_lattice(triangles=10, log=lambda s: None)


@pytest.mark.slow
def test_cli_writes_the_markdown(
    gl_ctx: Any, tmp_path: Path, capsys: pytest.CaptureFixture, monkeypatch: Any
) -> None:
    real = bl.bench_lattice

    def on_session_ctx(**kw: Any) -> LatticeBenchReport:
        return real(**kw, ctx=gl_ctx, crosscheck=False)

    monkeypatch.setattr(bl, "bench_lattice", on_session_ctx)
    monkeypatch.setattr(sys, "argv", ["pytest"])
    out = tmp_path / "sub" / "lattice.md"
    argv = ["lattice", "--triangles", "400", "--objects", "5", "--frames", "1"]
    argv += ["--size", "32x24", "--cells", "2"]
    args = _parser().parse_args([*argv, "--markdown", str(out)])
    assert args.func(args) == 0
    printed = capsys.readouterr()
    text = out.read_text()
    assert text in printed.out
    assert text.startswith(f"Command: `python -m benchmarks {' '.join(argv)} --markdown {out}`")
    assert "Image 32x24" in text
    assert "| 2³ | frame | normal | exact |" in text
    assert "| 4³ |" not in text
    assert "| linear | 5 |" in text
    assert "composition frame 1/1" in printed.err  # progress goes to stderr
    assert "composition frame" not in printed.out


def test_cli_main_knows_bench_lattice() -> None:
    from benchmarks.__main__ import build_parser

    args = build_parser().parse_args(["lattice", "--objects", "10"])
    assert args.func is bl.cmd_bench_lattice


def test_bench_cpu_grid_times_the_forward_maps_and_the_inverse() -> None:
    """The CPU measurement that replaced the wall-clock assert of test_trilinear.py."""
    out = bl.bench_cpu_grid(points=2000, cells=4, repeats=2)
    assert out["points"] == 2000
    assert out["cells"] == 4
    for key in ("forward_s", "inverse_s"):
        assert 0.0 < out[key] < 60.0
