"""``voxwarp demo compare`` (Knoche 2008, Figures 12-13): mass-spring beside ChainMail.

Both models on the same slice grid and the same drag, side by side, the fish bent by each,
and the CPU and GPU solvers' timings at small sizes (:mod:`voxwarp.teaching.measure`; GPU =
the moderngl backends on the EGL context, labelled with its GL renderer). Run by
:func:`voxwarp.teaching.demos.run_demo`; the helpers it shares with the other demos are in
:mod:`voxwarp.teaching.sheets`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.teaching import DEMO_TITLES, sheets
from voxwarp.teaching.measure import chainmail_times, massspring_rates


# ====================================================================== compare
def demo_compare(
    s: sheets.DemoSettings, out: Path, log: Callable[[str], None]
) -> tuple[list[Path], dict[str, Any], list[sheets.TourStep]]:
    from voxwarp.deform.elements.chainmail import ChainMail
    from voxwarp.deform.elements.grid import ElementGrid
    from voxwarp.deform.elements.massspring import MassSpring

    # the same grid and drag in both models
    t = time.perf_counter()
    ms = MassSpring(sheets.slice_grid(), integrator="semi-implicit", shear=True)
    ms.move(sheets.SLICE_DRAGGED, sheets.SLICE_DRAG_MM)
    ms_steps = ms.settle(max_steps=20000, tol=1e-3)
    ms_s = time.perf_counter() - t
    cm = ChainMail(sheets.slice_grid(), variant="enhanced")
    cm.move(sheets.SLICE_DRAGGED, sheets.SLICE_DRAG_MM)  # loads the numba kernels: not timed
    cm.reset()
    stats = cm.move(sheets.SLICE_DRAGGED, sheets.SLICE_DRAG_MM)
    cm0 = cm.positions()
    cm.relax(4)
    cm4 = cm.positions()
    rest = ElementGrid(sheets.SLICE_BOX, shape=sheets.SLICE_SHAPE, anchor="corners").rest_positions
    states = {"massspring": ms.positions(), "chainmail": cm0, "chainmail+4": cm4}
    u = {k: np.linalg.norm(v - rest, axis=-1) for k, v in states.items()}
    moved = {k: int(np.count_nonzero(v > 0.01)) for k, v in u.items()}
    log(f"compare: mass-spring settled in {ms_steps} steps, ChainMail touched {stats.touched}")

    vol = sheets.fish_volume(s)
    cam = sheets.fish_camera(vol, s.render_size)
    renders: list[tuple[str, np.ndarray]] = []
    tour_scenes: dict[str, Any] = {}
    with sheets.offscreen_renderer(s.render_size) as r:
        gl = sheets.gl_renderer(r)
        fms = MassSpring(sheets.fish_grid(vol), integrator="semi-implicit", shear=True)
        fms.move(list(sheets.FISH_DRAGGED), sheets.FISH_DRAG_MM)
        fms.settle(max_steps=20000, tol=1e-3)
        scene = sheets.fish_scene(vol, cam, [fms.warp()])
        tour_scenes["massspring"] = sheets.snap(scene)
        renders.append(
            ("(d) fish, mass-spring (settled)", sheets.render_rgb(r, scene, s.render_size))
        )
        fcm = ChainMail(sheets.fish_grid(vol), variant="enhanced")
        fcm.move(list(sheets.FISH_DRAGGED), sheets.FISH_DRAG_MM)
        scene = sheets.fish_scene(vol, cam, [fcm.warp()])
        tour_scenes["chainmail"] = sheets.snap(scene)
        renders.append(("(e) fish, ChainMail", sheets.render_rgb(r, scene, s.render_size)))
        fcm.relax(4)
        fcm.relax_steps = 4
        scene = sheets.fish_scene(vol, cam, [fcm.warp()])
        tour_scenes["chainmail+4"] = sheets.snap(scene)
        renders.append(
            ("(f) fish, ChainMail + 4 relaxation steps", sheets.render_rgb(r, scene, s.render_size))
        )
        # CPU vs GPU at small sizes, on this context (voxwarp.teaching.measure)
        log("compare: timing the mass-spring solvers")
        ms_rows, ms_model = massspring_rates(
            s.ms_sizes, steps=s.ms_steps, repeats=s.ms_repeats, ctx=r.ctx, log=log
        )
        log("compare: timing the ChainMail solvers")
        cm_rows = chainmail_times(s.cm_sizes, repeats=s.cm_repeats, ctx=r.ctx, log=log)
    diff = np.linalg.norm(states["massspring"] - states["chainmail+4"], axis=-1)
    numbers: dict[str, Any] = {
        "grid": sheets.SLICE_SHAPE,
        "dragged": sheets.SLICE_DRAGGED,
        "drag_mm": sheets.SLICE_DRAG_MM,
        "massspring": {
            "integrator": "semi-implicit",
            "settle_steps": ms_steps,
            "seconds": ms_s,
            "moved": moved["massspring"],
            "max_displacement_mm": float(u["massspring"].max()),
        },
        "chainmail": {
            "variant": "enhanced",
            "move_ms": stats.seconds * 1000,
            "touched": stats.touched,
            "moved": moved["chainmail"],
            "moved_after_relax4": moved["chainmail+4"],
        },
        "rms_difference_mm": float(np.sqrt(np.mean(diff**2))),
        "gl_renderer": gl,
        "timings": {
            "massspring": ms_rows,
            "massspring_dt_s": ms_model["dt"],
            "massspring_integrator": ms_model["integrator"],
            "chainmail": cm_rows,
            "gl_renderer": gl,
        },
    }
    fig = sheets.new_figure(16.0, 10.5, DEMO_TITLES["compare"])
    grid = fig.add_gridspec(3, 1, height_ratios=[1.2, 0.8, 1.0])
    top = grid[0].subgridspec(1, 3)
    sheets.plot_slice_state(
        fig.add_subplot(top[0, 0]),
        states["massspring"],
        f"(a) mass-spring, settled ({ms_steps} steps)\n{moved['massspring']} elements moved",
    )
    sheets.plot_slice_state(
        fig.add_subplot(top[0, 1]),
        states["chainmail"],
        f"(b) ChainMail, one move ({stats.seconds * 1000:.2f} ms)\n"
        f"{moved['chainmail']} elements moved",
    )
    sheets.plot_slice_state(
        fig.add_subplot(top[0, 2]),
        states["chainmail+4"],
        f"(c) ChainMail + 4 relaxation steps\n{moved['chainmail+4']} elements moved",
    )
    mid = grid[1].subgridspec(1, 3)
    for i, (title, img) in enumerate(renders):
        sheets.show_image(fig.add_subplot(mid[0, i]), img, title)
    bottom = grid[2].subgridspec(1, 2)
    _plot_ms_timings(fig.add_subplot(bottom[0, 0]), numbers)
    _plot_cm_timings(fig.add_subplot(bottom[0, 1]), numbers)
    path = sheets.save_figure(fig, out / "compare.png")

    tour = [
        sheets.TourStep(
            "Mass-spring: forces over time",
            "The mass-spring model pulls the grid along through spring forces, step by step"
            f" ({ms_steps} semi-implicit steps until it settles). Every element moves a"
            " little: the bend is smooth and spreads over the whole free part.",
            tour_scenes["massspring"],
            "a",
        ),
        sheets.TourStep(
            "ChainMail: geometry at once",
            "ChainMail settles the same drag in one move, in milliseconds, by moving every"
            " other element as little as its links allow: only the elements on taut chains"
            " move, and the rest stays exactly at rest.",
            tour_scenes["chainmail"],
            "b",
        ),
        sheets.TourStep(
            "ChainMail with relaxation",
            "Four relaxation steps spread the deformation and round the kinks, coming closer"
            " to the mass-spring shape while every link stays within its limits.",
            tour_scenes["chainmail+4"],
            "c",
        ),
        sheets.TourStep(
            "CPU and GPU",
            "Both models also run in fragment shaders on the renderer's OpenGL context"
            f" ({gl}). Panel g: mass-spring steps per second; panel h: milliseconds per"
            " ChainMail move. The GPU pays off for large grids; for local ChainMail drags the"
            " CPU solver, which touches only the elements that move, is faster.",
            None,
            "g",
        ),
    ]
    return [path], numbers, tour


def _bars(
    ax: Any,
    groups: Sequence[str],
    series: dict[str, Sequence[float | None]],
    colors: Sequence[str],
) -> None:
    """Grouped bars, one group per label, with the values written on them (log scale)."""
    n = len(series)
    width = 0.8 / max(n, 1)
    x = np.arange(len(groups))
    for i, ((label, vals), color) in enumerate(zip(series.items(), colors, strict=False)):
        v = np.array([np.nan if a is None else a for a in vals], dtype=np.float64)
        pos = x - 0.4 + width * (i + 0.5)
        ax.bar(pos, v, width, label=label, color=color)
        for p, val in zip(pos, v, strict=True):
            if np.isfinite(val):
                text = f"{val:.3g}" if val < 1000 else f"{val:.0f}"
                ax.text(
                    p, val, text, ha="center", va="bottom", fontsize=7, rotation=90, in_layout=False
                )
    ax.set_xticks(x, groups)
    ax.set_yscale("log")
    finite = [a for vals in series.values() for a in vals if a is not None and a > 0]
    if finite:  # room above the tallest bar for its value
        ax.set_ylim(min(finite) / 2, max(finite) * 6)
    ax.grid(True, axis="y", which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")


def _plot_ms_timings(ax: Any, n: dict[str, Any]) -> None:
    tm = n["timings"]
    sizes = sorted({r["size"] for r in tm["massspring"]})
    series: dict[str, list[float | None]] = {}
    for backend, label in (("numpy", "CPU (numpy)"), ("gpu", "GPU")):
        series[label] = []
        for size in sizes:
            rows = [r for r in tm["massspring"] if r["size"] == size and r["backend"] == backend]
            v = rows[0]["steps_per_s"] if rows and rows[0]["steps_per_s"] else None
            series[label].append(v)
    _bars(ax, [f"{n}³" for n in sizes], series, ("tab:gray", "tab:green"))
    ax.set_ylabel("steps per second (higher is faster)")
    ax.set_xlabel("grid (elements)")
    ax.set_title(
        f"(g) mass-spring steps/s, {tm['massspring_integrator']} Euler — GPU: {n['gl_renderer']}",
        fontsize=10,
    )


def _plot_cm_timings(ax: Any, n: dict[str, Any]) -> None:
    tm = n["timings"]
    sizes = sorted({r["size"] for r in tm["chainmail"]})
    groups, keys = [], []
    for size in sizes:
        for drag in ("local", "large"):
            groups.append(f"{size}³ {drag}")
            keys.append((size, drag))
    series: dict[str, list[float | None]] = {}
    for solver, label in (
        ("gibson", "CPU Gibson"),
        ("enhanced", "CPU enhanced"),
        ("gpu", "GPU"),
    ):
        vals: list[float | None] = []
        for size, drag in keys:
            rows = [
                r
                for r in tm["chainmail"]
                if (r["size"], r["drag"], r["solver"]) == (size, drag, solver)
            ]
            vals.append(rows[0]["ms"] if rows else None)
        series[label] = vals
    _bars(ax, groups, series, ("tab:gray", "tab:blue", "tab:green"))
    ax.set_ylabel("ms per move (lower is faster)")
    ax.set_xlabel("grid and drag (local: 1 spacing; large: 20 spacings)")
    ax.set_title(f"(h) ChainMail ms per move — GPU: {tm['gl_renderer']}", fontsize=10)
