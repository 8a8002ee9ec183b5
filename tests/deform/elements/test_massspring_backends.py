"""MassSpring end to end on both backends: the GPU backend through the public API.

* CPU and GPU agree after N steps of the same drags (structural springs and
  shear + bend, both integrators): ``max |d_gpu - d_cpu| / max |d_cpu| <= 1e-4`` with
  ``d`` the element displacements from rest (GPU float32 against the float64 CPU
  reference, so the bound is float32 round-off, not physics).
* On the GPU, fixed elements never move and held elements sit exactly at their
  targets (the float32 of ``rest + offset``) after every step.
* 10,000 random drags on the GPU with the displacement clamp on stay finite and
  bounded (the bound is derived in the test).
* An undisturbed MassSpring's warp renders the same image as no warp, on both
  backends.
* ``voxwarp bench massspring`` runs at tiny sizes and reports finite positive rates.

All but the last test need the GL context (``gl_ctx``; skipped without EGL).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from voxwarp.deform.elements.grid import ElementGrid
from voxwarp.deform.elements.massspring import MassSpring

pytest.importorskip("voxwarp.deform.elements.massspring_gpu")

BOX = ((0.0, 0.0, 0.0), (70.0, 60.0, 50.0))


def _grid(shape: tuple[int, int, int], seed: int = 5) -> ElementGrid:
    """Element grid over BOX with varied materials and one fixed interior element."""
    rng = np.random.default_rng(seed)
    g = ElementGrid(BOX, shape=shape, anchor="corners")
    g.set_material(
        stiffness=rng.uniform(0.2, 0.9, g.shape),
        damping=rng.uniform(0.5, 2.0, g.shape),
        mass=rng.uniform(0.5, 2.0, g.shape),
    )
    g.fix((1, 1, 1))
    return g


def _pair(gl_ctx: Any, shape: tuple[int, int, int], **kw: Any) -> tuple[MassSpring, MassSpring]:
    """The same model on the CPU and on the GPU (each with its own copy of the grid)."""
    return (
        MassSpring(_grid(shape), backend="cpu", **kw),
        MassSpring(_grid(shape), backend="gpu", ctx=gl_ctx, **kw),
    )


# ---------------------------------------------------------------------- CPU == GPU
@pytest.mark.parametrize(("shear", "bend"), [(False, False), (True, True)])
@pytest.mark.parametrize("integrator", ["explicit", "semi-implicit"])
def test_cpu_and_gpu_agree(gl_ctx: Any, shear: bool, bend: bool, integrator: str) -> None:
    cpu, gpu = _pair(gl_ctx, (8, 7, 6), shear=shear, bend=bend, integrator=integrator)
    try:
        # no drag puts an element onto a neighbour (spacing 10 mm): with |d| = 0 the
        # spring direction is undefined and float32 round-off would pick one at random
        for ms in (cpu, gpu):
            ms.move([(3, 3, 3), (6, 1, 4)], [(0.0, 0.0, 7.0), (-4.0, 3.0, 2.0)])
            ms.step(60)
            ms.move((2, 5, 1), (3.0, -6.0, 4.0))  # a drag in mid-motion
            ms.release((6, 1, 4))
            ms.step(90)
        d_cpu, d_gpu = cpu.displacements(), gpu.displacements()
        scale = float(np.abs(d_cpu).max())
        assert scale > 5.0  # the drags moved the grid
        free = ~(cpu.held | cpu.grid.fixed)
        assert np.abs(d_cpu[free]).max() > 0.5  # ... and the free elements followed
        # measured 2.6e-6 .. 1.9e-5 (llvmpipe; largest for explicit, whose 150 steps of
        # 0.05-0.2 ms each round positions of up to 70 mm to float32, ulp 3.8e-6 mm)
        err = float(np.abs(d_gpu - d_cpu).max()) / scale
        assert err <= 1e-4, f"max |d_gpu - d_cpu| / max |d_cpu| = {err:.2e}"
    finally:
        cpu.close()
        gpu.close()


# ---------------------------------------------------------------------- constraints
def test_gpu_fixed_never_move_and_held_stay_exactly_where_held(gl_ctx: Any) -> None:
    rng = np.random.default_rng(7)
    g = ElementGrid(((0.0, 0.0, 0.0), (50.0, 50.0, 50.0)), shape=5, anchor="corners")
    g.fix([[2, 2, 2], [0, 3, 1]])
    ms = MassSpring(g, backend="gpu", ctx=gl_ctx, shear=True)
    try:
        rest = g.rest_positions
        fixed = g.fixed.copy()
        # the GPU keeps float32 state: targets are the float32 of rest + offset, exactly
        rest32 = rest.astype(np.float32)
        held: dict[tuple[int, int, int], np.ndarray] = {}
        moved_free = 0.0
        for _ in range(150):
            idx = tuple(int(i) for i in rng.integers(0, 5, 3))
            off = rng.uniform(-15, 15, 3)
            ms.move(idx, off)  # a fixed element must ignore this
            if not fixed[idx]:
                held[idx] = off
            if rng.random() < 0.1 and held:
                key = list(held)[int(rng.integers(len(held)))]
                ms.release(key)
                del held[key]
            ms.step(int(rng.integers(1, 4)))
            x = ms.positions()
            np.testing.assert_array_equal(x[fixed], rest32[fixed])
            for k, o in held.items():
                np.testing.assert_array_equal(x[k], (rest[k] + o).astype(np.float32))
            free = ~fixed & ~ms.held
            moved_free = max(moved_free, float(np.abs(x[free] - rest[free]).max()))
        assert moved_free > 1.0  # the drags did move the free elements
        expected_held = np.zeros(g.shape, dtype=bool)
        for k in held:
            expected_held[k] = True
        np.testing.assert_array_equal(ms.held, expected_held)
    finally:
        ms.close()


# ---------------------------------------------------------------------- random drags
@pytest.mark.slow
def test_gpu_random_drags_stay_bounded(gl_ctx: Any) -> None:
    """10,000 random drags of a 6x6x6 grid on the GPU, one step each, clamp on.

    Bound (as for the CPU solver in test_massspring.py): every drag holds an element
    at most R = 3 * spacing from rest and fixed elements sit at rest. A static
    configuration of such constraints keeps its free elements within R of rest
    (discrete maximum principle of the spring network), so no spring is stretched or
    compressed by more than 2R: the potential energy of any drag configuration is at
    most U_max = N_springs * 0.5 * k_max * (2R)^2. A stable, damped integration only
    dissipates what the drags put in, so the energy must stay below U_max (measured
    max: 6.4% of it); an unstable one grows without bound or turns into NaN.
    Positions: the static configurations lie within R of rest; the motion overshoots
    them (underdamped), by less than R for a damped oscillator released from rest, so
    every element must stay within 2R of its rest position (measured max 1.27 R).
    """
    rng = np.random.default_rng(2024)
    g = ElementGrid(((0.0, 0.0, 0.0), (50.0, 50.0, 50.0)), shape=6, anchor="corners")
    h = float(g.spacing.min())
    ms = MassSpring(g, backend="gpu", ctx=gl_ctx)  # explicit, clamp on (max_step = h / 2)
    try:
        assert ms.max_step == pytest.approx(0.5 * h)
        big_r = 3.0 * h
        n_springs = 3 * 5 * 6 * 6  # structural springs of a 6^3 grid
        k_max = 50.0 * 0.5  # spring_constant * default stiffness
        u_max = n_springs * 0.5 * k_max * (2 * big_r) ** 2
        rest = g.rest_positions
        e_max = d_max = 0.0
        for it in range(10_000):
            idx = rng.integers(0, 6, 3)
            direction = rng.normal(size=3)
            ms.move(idx, direction / np.linalg.norm(direction) * rng.uniform(0, big_r))
            ms.step()
            if rng.random() < 0.1:
                ms.release(None if rng.random() < 0.2 else idx)
            if it % 20 == 0:
                e = ms.energy()
                assert math.isfinite(e), f"energy {e} after {it + 1} drags"
                e_max = max(e_max, e)
                x = ms.positions()
                assert np.all(np.isfinite(x))
                d_max = max(d_max, float(np.linalg.norm(x - rest, axis=-1).max()))
        assert np.all(np.isfinite(ms.positions()))
        assert e_max < u_max
        assert e_max > 1e-3 * u_max  # the drags did stress the grid
        assert d_max < 2 * big_r, f"an element went {d_max / big_r:.2f} R from rest"
    finally:
        ms.close()


# ---------------------------------------------------------------------- rendering
@pytest.mark.parametrize("backend", ["cpu", "gpu"])
def test_zero_displacement_renders_like_no_warp(offscreen: Any, gl_ctx: Any, backend: str) -> None:
    """An undisturbed MassSpring's warp (a zero offset field) leaves the image as it is.

    Measured on llvmpipe, both backends alike: mip and dvr images are bit-identical
    (float32 framebuffer); iso differs by at most 0.0019/255, because its surface
    refinement and shading go through the generic warp path (the inverse and the
    Jacobian of the field, evaluated in float32) instead of the folded no-warp path.
    So: exact equality for mip and dvr, 1/255 for iso (one 8-bit grey level).
    """
    from tests.render.test_render import aligned_camera, grey_scene, phantom
    from voxwarp.scene import Scene

    vol = phantom()
    grid = ElementGrid(vol, shape=(6, 5, 5), anchor="corners")
    ms = MassSpring(grid, backend=backend, ctx=gl_ctx if backend == "gpu" else None)
    try:
        # the state is float64 on the CPU, float32 on the GPU: rest there is f32(rest)
        rest = grid.rest_positions
        if backend == "gpu":
            rest = rest.astype(np.float32).astype(np.float64)
        np.testing.assert_array_equal(ms.positions(), rest)
        ms.step(5)  # undisturbed: no force at rest...
        # ... exactly on the CPU; on the GPU the float32 spring lengths differ from the
        # rest lengths by round-off, which gives speeds of ~1e-5 mm/s and, over 50
        # steps, moves an element by at most one float32 ulp (measured 1.3e-6 mm)
        tol_mm = 0.0 if backend == "cpu" else 1e-5
        assert np.abs(ms.positions() - rest).max() <= tol_mm
        warp = ms.warp()
        cam, size = aligned_camera(vol, "+z")
        mip = grey_scene(vol, "mip", "+z", cam)
        dvr, iso = (
            # unshaded ct-bone dvr, as measured above (shaded dvr goes through the
            # warp's Jacobian, as iso does)
            Scene(
                vol,
                mode=m,
                transfer_function="ct-bone",
                view=(30, 20),
                seed=0,
                window=(100.0, 2200.0),
                shading=None if m == "iso" else False,
            )
            for m in ("dvr", "iso")
        )
        for scene, sz in ((mip, size), (dvr, (64, 64)), (iso, (64, 64))):
            r = offscreen(*sz, dtype="f4")
            plain = r.render(scene)
            warped = r.render(scene.copy(warps=[warp]))
            if scene.mode == "iso":
                diff = float(np.abs(warped.astype(np.float64) - plain).max())
                assert diff <= 1 / 255, f"{backend} iso: max diff {diff * 255:.4f}/255"
            else:
                np.testing.assert_array_equal(warped, plain, err_msg=f"{backend} {scene.mode}")
        # the warp is really in the pipeline: a drag changes the picture
        ms.move((3, 2, 2), (8.0, 0.0, 0.0))
        ms.step(20)
        r = offscreen(*size, dtype="f4")
        moved = r.render(mip.copy(warps=[warp]))
        assert float(np.abs(moved - r.render(mip)).max()) > 0.02  # measured 0.07
    finally:
        ms.close()


# ---------------------------------------------------------------------- bench smoke
def test_bench_massspring_smoke(gl_ctx: Any) -> None:
    from benchmarks.massspring import BACKENDS, bench_massspring
    from benchmarks.taichi import taichi_available

    logged: list[str] = []
    report = bench_massspring(
        (3, 5), steps=3, repeats=2, ctx=gl_ctx, use_taichi=True, log=logged.append
    )
    assert report.sizes == (3, 5)
    assert report.integrator == "explicit"
    assert report.springs == 6
    assert report.dt > 0
    assert report.gl_renderer not in ("", "not used")
    for n in (3, 5):
        for b in BACKENDS:
            rows = [r for r in report.rows if r.size == n and r.backend == b]
            assert len(rows) == 1, (n, b)
            row = rows[0]
            if b in ("taichi", "taichi-min") and not taichi_available():
                assert row.median_sps == 0
                assert "not installed" in row.note
                continue
            assert 1 <= row.steps <= 3
            assert row.repeats == 2
            for v in (row.median_sps, row.min_sps, row.max_sps):
                assert math.isfinite(v)
                assert v > 0
            assert row.min_sps <= row.median_sps <= row.max_sps
        ratio = report.ratio(n, "gpu", "numpy")
        assert ratio is not None
        assert math.isfinite(ratio)
        assert ratio > 0
    text = report.markdown("voxwarp bench massspring --sizes 3,5")
    assert text.startswith("Command: `voxwarp bench massspring --sizes 3,5`")
    assert "| grid | numpy CPU steps/s | GPU steps/s | taichi CPU steps/s |" in text
    assert "| 3³ |" in text
    assert "| 5³ |" in text
    assert logged  # progress went to the log


def test_bench_massspring_cli(tmp_path: Any, capsys: pytest.CaptureFixture[str]) -> None:
    from benchmarks.__main__ import main

    out = tmp_path / "bench.md"
    argv = ["massspring", "--sizes", "3", "--steps", "2", "--repeats", "1"]
    assert main([*argv, "--no-taichi", "--no-render", "--markdown", str(out)]) == 0
    text = out.read_text(encoding="utf-8")
    assert "| 3³ |" in text
    assert "taichi CPU: skipped (--no-taichi)" in text
    assert "taichi minimal: skipped (--no-taichi)" in text
    assert main([*argv, "--no-numpy", "--no-taichi", "--no-render", "--markdown", str(out)]) == 0
    text = out.read_text(encoding="utf-8")
    assert "numpy CPU: skipped (--no-numpy)" in text
    assert "| 3³ | — |" in text  # no numpy rate, the GPU's still there
    assert text in capsys.readouterr().out
    for bad in (["--sizes", "1"], ["--sizes", "16,x"], ["--steps", "0"]):
        with pytest.raises(SystemExit):
            main(["massspring", *bad])


def test_element_dragged_onto_its_neighbour_agrees_on_cpu_and_gpu(gl_ctx: Any) -> None:
    """A zero-length spring has no direction on every backend (no float32 noise force)."""
    grid = ElementGrid(((0, 0, 0), (40, 40, 40)), shape=(5, 5, 5), anchor="corners")
    results = []
    for backend in ("cpu", "gpu"):
        ms = MassSpring(grid, backend=backend, ctx=gl_ctx if backend == "gpu" else None)
        try:
            ms.move((2, 2, 2), (10.0, 0.0, 0.0))  # exactly onto element (3, 2, 2)
            ms.step(40)
            results.append(ms.displacements())
        finally:
            ms.close()
    cpu, gpu = results
    assert np.abs(gpu - cpu).max() <= 1e-4 * np.abs(cpu).max()


def test_gpu_field_skips_through_deformed_space_once_it_holds_still(gl_ctx: Any) -> None:
    """A GPU-owned warp is bounded by reading the field back, but only when the same
    field state is drawn again: never while the simulation steps between frames."""
    from tests.render.test_render import phantom
    from voxwarp.render.offscreen import OffscreenRenderer
    from voxwarp.scene import Scene

    vol = phantom()
    grid = ElementGrid(vol, shape=(6, 5, 5), anchor="corners")
    ms = MassSpring(grid, backend="gpu", ctx=gl_ctx, integrator="semi-implicit")
    try:
        ms.move((3, 2, 2), (6.0, 0.0, 0.0))
        ms.step(30)
        warp = ms.warp()
        reads: list[int] = []
        reader = warp._field_reader
        warp._field_reader = lambda: (reads.append(1), reader())[1]
        scene = Scene(vol, mode="dvr", view=(30, 20), seed=0, warps=[warp])
        with OffscreenRenderer(48, 48, ctx=gl_ctx, dtype="f4") as r:
            kinds = []
            for _ in range(3):  # stepping between frames: no read-back, block checks
                ms.step(1)
                r.render(scene)
                kinds.append(r.renderer.last_skip_kind)
            assert kinds == ["blocks"] * 3
            assert reads == []
            first = r.render(scene)  # same state drawn again: map built from one read
            assert r.renderer.last_skip_kind == "cells"
            assert len(reads) == 1
            r.render(scene)
            assert len(reads) == 1  # cached per revision
            r.renderer.warped_skip_maps = "never"
            reference = r.render(scene)
        assert np.abs(first - reference).max() <= 1 / 255
        assert np.abs(reference - first).max(axis=-1).mean() < 1e-4
    finally:
        ms.close()
