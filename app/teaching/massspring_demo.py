"""``voxwarp demo massspring`` (Knoche 2008, 3.5): explicit vs semi-implicit Euler.

Both integrators at the same time step on the fish's element grid, its tail dragged
sideways: the energy over time, the largest energy growth over a range of steps (where
each integrator becomes unstable), and renders of the fish bent by the drag. Run by
:func:`voxwarp.teaching.demos.run_demo`; the helpers it shares with the other demos are in
:mod:`voxwarp.teaching.sheets`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.teaching import DEMO_TITLES, sheets

# ---------------------------------------------------------------------- mass-spring
#: the demo's time step, in units of the semi-implicit integrator's stable step: beyond
#: the explicit integrator's real limit on the fish grid (measured: between 1.0 and 1.5)
DT_FACTOR = 1.5
#: an energy this many times the starting energy counts as blown up
BLOWUP = 1e9


# ====================================================================== mass-spring
def _mass_spring(grid: Any, integrator: str, dt: float, clamp: bool) -> Any:
    """The fish drag's model with ``integrator`` at time step ``dt`` (s).

    ``MassSpring`` clamps a ``dt`` above :meth:`~voxwarp.deform.elements.massspring.MassSpring.
    stable_time_step` to it; the CPU solver reads ``model.dt`` at every step, so the
    demo sets it there, beyond the limit, on purpose.
    """
    from voxwarp.deform.elements.massspring import MassSpring

    ms = MassSpring(grid, integrator=integrator, shear=True, max_step=None if clamp else 0.0)
    ms.model.dt = float(dt)
    return ms


def _energy_run(ms: Any, steps: int, e0: float) -> list[float]:
    """Energy after each of ``steps`` steps; stops once it is not finite or above
    :data:`BLOWUP` times ``e0``."""
    out: list[float] = []
    with np.errstate(all="ignore"):
        for _ in range(int(steps)):
            ms.step(1)
            e = ms.energy()
            out.append(e if math.isfinite(e) else math.inf)
            if not math.isfinite(e) or e > BLOWUP * e0:
                break
    return out


def _dragged_fish_model(vol: Any, integrator: str, dt: float, clamp: bool) -> Any:
    ms = _mass_spring(sheets.fish_grid(vol), integrator, dt, clamp)
    ms.move(list(sheets.FISH_DRAGGED), sheets.FISH_DRAG_MM)
    return ms


def demo_massspring(
    s: sheets.DemoSettings, out: Path, log: Callable[[str], None]
) -> tuple[list[Path], dict[str, Any], list[sheets.TourStep]]:
    vol = sheets.fish_volume(s)
    probe = {
        i: _mass_spring(sheets.fish_grid(vol), i, 1.0, True) for i in ("explicit", "semi-implicit")
    }
    stable = {i: m.stable_time_step() for i, m in probe.items()}
    dt = DT_FACTOR * stable["semi-implicit"]
    steps = max(2, math.ceil(s.sim_seconds / dt))
    log(
        f"massspring: dt {dt * 1000:.1f} ms ({dt / stable['explicit']:.0f}x explicit's stable"
        f" step), {steps} steps"
    )
    runs = {
        "explicit": ("explicit", False),
        "semi-implicit": ("semi-implicit", False),
        "explicit + clamp": ("explicit", True),
    }
    e0 = _dragged_fish_model(vol, "semi-implicit", dt, False).energy()
    energy: dict[str, list[float]] = {}
    for label, (integ, clamp) in runs.items():
        energy[label] = _energy_run(_dragged_fish_model(vol, integ, dt, clamp), steps, e0)
    blew = energy["explicit"]
    blew_up_at = dt * len(blew) if len(blew) < steps else None

    # the stability sweep: largest energy over a fixed number of steps, per dt
    dts = np.geomspace(stable["explicit"], 4.0 * stable["semi-implicit"], s.sweep_points)
    growth: dict[str, list[float]] = {"explicit": [], "semi-implicit": []}
    for d in dts:
        for integ in growth:
            es = _energy_run(_dragged_fish_model(vol, integ, d, False), s.sweep_steps, e0)
            growth[integ].append(min(max(es) / e0, BLOWUP) if es else 1.0)
    log("massspring: stability sweep done")

    # renders: the semi-implicit model at its own (default) step over time, as the GUI
    # runs it (its scenes resume there), then the explicit ones at the demo's dt and at
    # their own stable step
    cam = sheets.fish_camera(vol, s.render_size)
    shots: list[tuple[str, np.ndarray]] = []
    tour_states: dict[str, Any] = {}
    semi_dt = stable["semi-implicit"]
    mid_steps = max(1, round(0.3 / semi_dt))
    with sheets.offscreen_renderer(s.render_size) as r:
        gl = sheets.gl_renderer(r)
        shots.append(
            ("(c) at rest", sheets.render_rgb(r, sheets.fish_scene(vol, cam), s.render_size))
        )
        semi = _dragged_fish_model(vol, "semi-implicit", semi_dt, True)
        tour_states["dragged"] = sheets.snap(sheets.fish_scene(vol, cam, [semi.warp()]))
        shots.append(
            (
                "(d) t = 0: tail elements dragged",
                sheets.render_rgb(r, sheets.fish_scene(vol, cam, [semi.warp()]), s.render_size),
            )
        )
        semi.step(mid_steps)
        t_mid = mid_steps * semi_dt
        tour_states["moving"] = sheets.snap(sheets.fish_scene(vol, cam, [semi.warp()]))
        shots.append(
            (
                f"(e) semi-implicit (dt {semi_dt * 1000:.1f} ms), t = {t_mid:.2f} s",
                sheets.render_rgb(r, sheets.fish_scene(vol, cam, [semi.warp()]), s.render_size),
            )
        )
        settle_steps = mid_steps + semi.settle(max_steps=20000, tol=1e-3)
        tour_states["settled"] = sheets.snap(sheets.fish_scene(vol, cam, [semi.warp()]))
        max_disp = float(np.linalg.norm(semi.displacements(), axis=-1).max())
        shots.append(
            (
                f"(f) semi-implicit, settled ({settle_steps} steps)",
                sheets.render_rgb(r, sheets.fish_scene(vol, cam, [semi.warp()]), s.render_size),
            )
        )
        expl = _dragged_fish_model(vol, "explicit", dt, True)
        with np.errstate(all="ignore"):
            expl.step(steps)
        tour_states["explicit"] = sheets.snap(sheets.fish_scene(vol, cam, [expl.warp()]))
        shots.append(
            (
                f"(g) explicit + clamp, same dt, t = {steps * dt:.1f} s",
                sheets.render_rgb(r, sheets.fish_scene(vol, cam, [expl.warp()]), s.render_size),
            )
        )
        slow = _dragged_fish_model(vol, "explicit", stable["explicit"], True)
        slow.step(steps)
        shots.append(
            (
                f"(h) explicit at its stable dt, {steps} steps"
                f" (t = {steps * stable['explicit']:.2f} s)",
                sheets.render_rgb(r, sheets.fish_scene(vol, cam, [slow.warp()]), s.render_size),
            )
        )

    numbers: dict[str, Any] = {
        "grid": sheets.FISH_GRID,
        "fixed": f"i < {sheets.HEAD_LAYERS} (the head)",
        "dragged": sheets.FISH_DRAGGED,
        "drag_mm": sheets.FISH_DRAG_MM,
        "volume": f"fish {'x'.join(map(str, vol.shape))}",
        "dt_s": dt,
        "stable_dt_s": stable,
        "dt_over_explicit_stable": dt / stable["explicit"],
        "steps": steps,
        "initial_energy": e0,
        "time_s": [dt * (i + 1) for i in range(steps)],
        "energy": energy,
        "final_energy": {k: v[-1] for k, v in energy.items()},
        "max_energy": {k: max(v) for k, v in energy.items()},
        "explicit_blew_up_at_s": blew_up_at,
        "sweep": {"dt_s": dts, "steps": s.sweep_steps, "growth": growth},
        "settle_steps": settle_steps,
        "max_displacement_mm": max_disp,
        "gl_renderer": gl,
    }
    fig = sheets.new_figure(15.0, 9.2, DEMO_TITLES["massspring"])
    grid = fig.add_gridspec(2, 6, height_ratios=[1.15, 1.0])
    _plot_energy(fig.add_subplot(grid[0, 0:3]), numbers)
    _plot_sweep(fig.add_subplot(grid[0, 3:6]), numbers)
    sub = grid[1, :].subgridspec(2, 3)
    for i, (title, img) in enumerate(shots):
        sheets.show_image(fig.add_subplot(sub[i // 3, i % 3]), img, title)
    path = sheets.save_figure(fig, out / "massspring.png")

    tour = [
        sheets.TourStep(
            "A grid of masses and springs",
            "The fish is covered by an 8x8x8 grid of point masses joined by springs (along"
            " the axes and the face diagonals). The head's three layers are fixed. Moving"
            " an element stretches its springs; their forces pull the neighbours along, and"
            " the elements' displacements bend the volume at render time: the voxels are"
            " never resampled.",
            sheets.snap(sheets.fish_scene(vol, cam)),
            "c",
        ),
        sheets.TourStep(
            "Drag the tail",
            "Two tail elements are held 12 mm to the side. At t = 0 nothing else has moved"
            " yet: only the cells around the held elements are stretched.",
            tour_states["dragged"],
            "d",
        ),
        sheets.TourStep(
            "Semi-implicit Euler",
            "Each step first updates the velocity from the spring forces, v' = v + dt a,"
            " then the position with the new velocity, x' = x + dt v'. At its default time"
            f" step ({semi_dt * 1000:.0f} ms), and even at {dt * 1000:.0f} ms (panel a), the"
            " energy only falls: the bend spreads along the body.",
            tour_states["moving"],
            "e",
        ),
        sheets.TourStep(
            "Settled",
            "Once every element is slower than 0.001 mm/s the grid is at rest: the tail"
            " bends in a smooth curve from the fixed head to the held elements.",
            tour_states["settled"],
            "f",
        ),
        sheets.TourStep(
            "Explicit Euler at the same step",
            "Explicit Euler moves with the old velocity, x' = x + dt v. Beyond its stability"
            f" limit (here dt is {dt / stable['explicit']:.0f}x its guaranteed-stable step)"
            " every step adds energy to the fastest vibrations: the energy grows"
            " exponentially (panel a). The thesis' displacement clamp keeps it bounded, but"
            " the grid never settles and the fish is torn apart. (The GUI resumes this state"
            " at explicit Euler's stable step, and warns that it had to reduce dt.)",
            tour_states["explicit"],
            "g",
        ),
        sheets.TourStep(
            "Where each integrator becomes unstable",
            "Panel b runs both integrators at a range of time steps: explicit Euler blows up"
            " at a step several times smaller than semi-implicit Euler, which is why the"
            " semi-implicit one is the default.",
            None,
            "b",
        ),
    ]
    return [path], numbers, tour


def _plot_energy(ax: Any, n: dict[str, Any]) -> None:
    t = np.asarray(n["time_s"])
    styles = {
        "explicit": ("tab:red", "-"),
        "semi-implicit": ("tab:blue", "-"),
        "explicit + clamp": ("tab:orange", "--"),
    }
    for label, es in n["energy"].items():
        y = np.array([np.nan if v is None else v for v in es], dtype=np.float64)
        color, ls = styles[label]
        ax.semilogy(t[: len(y)], y, ls, color=color, lw=2, label=label)
        if label == "explicit":
            end = t[len(y) - 1]
            if n["explicit_blew_up_at_s"] is not None:
                ax.plot(end, y[-1], "x", color=color, ms=12, mew=3)
                text = f"blew up (> {BLOWUP:.0e}x) at t = {end:.2f} s"
            else:
                text = f"{y[-1] / n['initial_energy']:.3g}x the energy at t = 0"
            ax.annotate(
                text,
                (end, y[-1]),
                textcoords="offset points",
                xytext=(-12, -4),
                ha="right",
                va="top",
                color=color,
                fontsize=9,
            )
    ax.axhline(n["initial_energy"], color="0.5", lw=1, ls=":", label="energy at t = 0")
    ax.set_xlabel("simulated time t (s)")
    ax.set_ylabel("kinetic + spring energy (mass·mm²/s²)")
    st = n["stable_dt_s"]
    ax.set_title(
        f"(a) energy at the same time step dt = {n['dt_s'] * 1000:.1f} ms"
        f" ({n['dt_over_explicit_stable']:.0f}x explicit's stable step"
        f" {st['explicit'] * 1000:.1f} ms, {DT_FACTOR:g}x semi-implicit's"
        f" {st['semi-implicit'] * 1000:.1f} ms)",
        fontsize=10,
    )
    ax.legend(loc="upper left", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    sheets.add_note(
        ax,
        "Same model, drag and dt: explicit Euler (x' = x + dt v) gains energy every step and"
        " blows up; the thesis' displacement clamp keeps it bounded, but it never settles."
        " Semi-implicit Euler (x' = x + dt v') loses energy to damping and settles.",
        "lower right",
        58,
    )


def _plot_sweep(ax: Any, n: dict[str, Any]) -> None:
    sw = n["sweep"]
    dts = np.asarray(sw["dt_s"]) * 1000
    for integ, color in (("explicit", "tab:red"), ("semi-implicit", "tab:blue")):
        g = np.array([np.nan if v is None else v for v in sw["growth"][integ]])
        ax.loglog(dts, g, "o-", color=color, lw=2, label=integ)
    ax.axhline(1.0, color="0.5", lw=1, ls=":")
    for integ, color in (("explicit", "tab:red"), ("semi-implicit", "tab:blue")):
        ax.axvline(n["stable_dt_s"][integ] * 1000, color=color, lw=1, ls="--", alpha=0.7)
    ax.axvline(n["dt_s"] * 1000, color="k", lw=1.5, alpha=0.6)
    ax.annotate(
        "dt of (a)",
        (n["dt_s"] * 1000, 1.0),
        textcoords="offset points",
        xytext=(4, 8),
        fontsize=9,
    )
    ax.set_xlabel("time step dt (ms)")
    ax.set_ylabel("largest energy / energy at t = 0")
    ax.set_title(f"(b) stability: largest energy over {sw['steps']} steps, no clamp", fontsize=10)
    ax.legend(loc="center left", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    sheets.add_note(
        ax,
        "Dashed: each integrator's guaranteed-stable step (MassSpring.stable_time_step);"
        " solid: the dt of (a). Above 1: the run gained energy (capped at"
        f" {BLOWUP:.0e}). Explicit Euler turns unstable at a step several times smaller"
        " than semi-implicit Euler.",
        "upper left",
        48,
    )
