"""``voxwarp demo chainmail`` (Gibson 1997; Schill et al. 1998; Knoche 2008, Figure 13).

The order in which one drag moves the elements of a small slice grid (Gibson's sponsors as
arrows; the enhanced variant's priority queue), then the grid after 0, 1 and 4 relaxation
steps, the smoothness energy per step, and the fish rendered after 0, 1 and 4 steps. Run
by :func:`voxwarp.teaching.demos.run_demo`; the helpers it shares with the other demos are
in :mod:`voxwarp.teaching.sheets`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.teaching import DEMO_TITLES, sheets

#: the relaxation steps of the thesis' Figure 13
RELAX_STEPS: tuple[int, ...] = (0, 1, 4)


# ====================================================================== ChainMail
def _move_order(cm: Any) -> np.ndarray:
    """(m, 3) indices of the elements the last :meth:`ChainMail.move` changed, in the
    order the CPU solver moved them (its record of the move, ``t_idx``: the seed first,
    then Gibson's sponsor lists or the priority queue)."""
    flat = np.asarray(cm._t_idx[: cm._recorded], dtype=np.int64).copy()
    return np.stack(np.unravel_index(flat, cm.grid.shape), axis=1)


def gibson_sponsor(index: Sequence[int], seed: Sequence[int]) -> tuple[int, int, int] | None:
    """The sponsor of element ``index`` in Gibson's propagation from the single ``seed``.

    Gibson's x lists queue their x, y and z neighbours, y lists their y and z
    neighbours, z lists only z: an element off the seed in z is reached along z, one off
    it in y (same z) along y, one on the seed's x row along x. Its sponsor is the
    neighbour one step back towards the seed along that axis.

    Parameters
    ----------
    index, seed
        (i, j, k) of the element and of the dragged element.

    Returns
    -------
    tuple of int or None
        The sponsor's (i, j, k); None for the seed itself.
    """
    d = np.asarray(index, dtype=np.int64) - np.asarray(seed, dtype=np.int64)
    for axis in (2, 1, 0):
        if d[axis] != 0:
            back = np.asarray(index, dtype=np.int64).copy()
            back[axis] -= int(np.sign(d[axis]))
            return (int(back[0]), int(back[1]), int(back[2]))
    return None


def _chainmail_slice() -> dict[str, Any]:
    """The slice grid's drag in both variants, then 1 and 4 relaxation steps."""
    from voxwarp.deform.elements.chainmail import ChainMail

    res: dict[str, Any] = {}
    for variant in ("gibson", "enhanced"):
        cm = ChainMail(sheets.slice_grid(), variant=variant)
        stats = cm.move(sheets.SLICE_DRAGGED, sheets.SLICE_DRAG_MM)
        res[variant] = {
            "order": _move_order(cm),
            "touched": stats.touched,
            "checks": stats.checks,
            "cleanup": stats.cleanup,
            "fraction": stats.fraction,
            "positions": cm.positions(),
        }
        res[f"_{variant}_model"] = cm
    order = res["gibson"]["order"]
    rank = {tuple(int(v) for v in e): i for i, e in enumerate(order)}
    sponsors = []
    holds = True
    for e in order[1:]:
        sp = gibson_sponsor(e, sheets.SLICE_DRAGGED)
        ok = sp in rank and rank[sp] < rank[tuple(int(v) for v in e)]
        holds &= ok
        sponsors.append((tuple(int(v) for v in e), sp if ok else None))
    res["gibson"]["sponsors"] = sponsors
    res["sponsor_rule_holds"] = bool(holds)
    res["same_state"] = float(
        np.abs(res["gibson"]["positions"] - res["enhanced"]["positions"]).max()
    )
    return res


def _relaxed_states(
    cm: Any, steps: Sequence[int], curve: int
) -> tuple[dict[int, Any], list[float]]:
    """Positions after each of ``steps`` relaxation steps (cumulative) and the smoothness
    energy after 0..``curve`` steps."""
    states: dict[int, Any] = {}
    energies = [cm.smoothness_energy()]
    done = 0
    if 0 in steps:
        states[0] = cm.positions()
    for k in range(1, max(curve, max(steps)) + 1):
        cm.relax(1)
        done = k
        if k <= curve:
            energies.append(cm.smoothness_energy())
        if k in steps:
            states[k] = cm.positions()
    assert done >= max(steps)
    return states, energies


def demo_chainmail(
    s: sheets.DemoSettings, out: Path, log: Callable[[str], None]
) -> tuple[list[Path], dict[str, Any], list[sheets.TourStep]]:
    from voxwarp.deform.elements.chainmail import ChainMail

    sl = _chainmail_slice()
    cm = sl.pop("_enhanced_model")
    sl.pop("_gibson_model")
    states, slice_curve = _relaxed_states(cm, RELAX_STEPS, s.relax_curve)
    slice_energy = {k: None for k in RELAX_STEPS}
    for k in RELAX_STEPS:
        slice_energy[k] = slice_curve[k] if k < len(slice_curve) else None
    violation = cm.violation()
    log(f"chainmail: slice drag touched {sl['gibson']['touched']} elements")

    vol = sheets.fish_volume(s)
    cam = sheets.fish_camera(vol, s.render_size)
    fish_cm = ChainMail(sheets.fish_grid(vol), variant="enhanced")
    fish_stats = fish_cm.move(list(sheets.FISH_DRAGGED), sheets.FISH_DRAG_MM)
    renders: list[tuple[str, np.ndarray]] = []
    fish_curve = [fish_cm.smoothness_energy()]
    tour_scenes: dict[int, Any] = {}
    done = 0
    with sheets.offscreen_renderer(s.render_size) as r:
        gl = sheets.gl_renderer(r)
        for k in RELAX_STEPS:
            if k > done:
                for _ in range(k - done):
                    fish_cm.relax(1)
                    fish_curve.append(fish_cm.smoothness_energy())
                done = k
            fish_cm.relax_steps = k  # saved with the model: a resumed one relaxes alike
            scene = sheets.fish_scene(vol, cam, [fish_cm.warp()])
            tour_scenes[k] = sheets.snap(scene)
            renders.append(
                (
                    f"({'ghi'[len(renders)]}) fish, tail dragged 12 mm, {k} relaxation"
                    f" step{'s' * (k != 1)}",
                    sheets.render_rgb(r, scene, s.render_size),
                )
            )
    for _ in range(done, s.relax_curve):
        fish_cm.relax(1)
        fish_curve.append(fish_cm.smoothness_energy())

    numbers: dict[str, Any] = {
        "grid": sheets.SLICE_SHAPE,
        "box_mm": sheets.SLICE_BOX,
        "dragged": sheets.SLICE_DRAGGED,
        "drag_mm": sheets.SLICE_DRAG_MM,
        "fixed": "i = 0 layer",
        "touched": {v: sl[v]["touched"] for v in ("gibson", "enhanced")},
        "checks": {v: sl[v]["checks"] for v in ("gibson", "enhanced")},
        "cleanup": {v: sl[v]["cleanup"] for v in ("gibson", "enhanced")},
        "fraction": {v: sl[v]["fraction"] for v in ("gibson", "enhanced")},
        "order": {v: sl[v]["order"] for v in ("gibson", "enhanced")},
        "sponsor_rule_holds": sl["sponsor_rule_holds"],
        "variants_max_difference_mm": sl["same_state"],
        "smoothness_energy": slice_energy,
        "relax_curve": {"steps": list(range(len(slice_curve))), "slice": slice_curve},
        "violation_after_relax_mm": violation,
        "fish": {
            "grid": sheets.FISH_GRID,
            "dragged": sheets.FISH_DRAGGED,
            "drag_mm": sheets.FISH_DRAG_MM,
            "touched": fish_stats.touched,
            "fraction": fish_stats.fraction,
            "smoothness_energy": {k: fish_curve[k] for k in RELAX_STEPS},
            "relax_curve": fish_curve,
        },
        "gl_renderer": gl,
    }
    fig = sheets.new_figure(15.0, 13.0, DEMO_TITLES["chainmail"])
    grid = fig.add_gridspec(3, 3, height_ratios=[1.15, 1.0, 0.75])
    _plot_order(fig.add_subplot(grid[0, 0]), sl["gibson"], sponsors=True)
    _plot_order(fig.add_subplot(grid[0, 1]), sl["enhanced"], sponsors=False)
    _plot_relax_curve(fig.add_subplot(grid[0, 2]), slice_curve, fish_curve)
    for i, k in enumerate(RELAX_STEPS):
        sheets.plot_slice_state(
            fig.add_subplot(grid[1, i]),
            states[k],
            f"({'def'[i]}) {k} relaxation step{'s' * (k != 1)} after the drag:"
            f" E = {slice_energy[k]:.0f} mm²",
            colorbar=i == len(RELAX_STEPS) - 1,
        )
    for i, (title, img) in enumerate(renders):
        sheets.show_image(fig.add_subplot(grid[2, i]), img, title)
    path = sheets.save_figure(fig, out / "chainmail.png")

    tour = [
        sheets.TourStep(
            "Links with slack",
            "3D ChainMail links every element to its 6 neighbours like the rings of a chain"
            " mail: a link may stretch, compress or shear by up to a quarter of the element"
            " spacing (stiffness 0.5) before it pulls its neighbour along.",
            sheets.snap(sheets.fish_scene(vol, cam)),
            None,
        ),
        sheets.TourStep(
            "Gibson's sponsors",
            "The dragged element sponsors its neighbours. Six candidate lists (+x, -x, +y,"
            " -y, +z, -z) are processed in turn: an element from an x list queues its x, y"
            " and z neighbours, one from a y list only y and z, one from a z list only z."
            " Each element is checked against its sponsor only and moves to the nearest"
            " place its link allows; the wave stops where links are slack. Panel a colours"
            " the elements by the order they moved; arrows point from sponsor to element.",
            None,
            "a",
        ),
        sheets.TourStep(
            "The enhanced variant",
            "Schill et al.'s priority queue moves first the element that is asked to move"
            " farthest, against all its links at once (Dijkstra's order). For one drag it"
            " ends in the same state as Gibson's lists (panel b): only the order differs.",
            None,
            "b",
        ),
        sheets.TourStep(
            "Right after the drag",
            "Without relaxation the deformation is piecewise linear: straight, sheared blocks"
            " with sharp kinks at both ends of the taut chain of links.",
            tour_scenes[0],
            "d",
        ),
        sheets.TourStep(
            "One relaxation step",
            "Relaxation moves every free element towards the mean displacement of its"
            " neighbours, but only as far as its links allow: the kinks round off and the"
            " smoothness energy (sum of squared displacement differences) falls.",
            tour_scenes[1],
            "e",
        ),
        sheets.TourStep(
            "Four relaxation steps",
            "After four steps the bend is smooth; every link still satisfies its limits"
            " (panel c plots the energy per step).",
            tour_scenes[4],
            "f",
        ),
    ]
    return [path], numbers, tour


def _plot_order(ax: Any, data: dict[str, Any], sponsors: bool) -> None:
    from voxwarp.deform.elements.grid import ElementGrid

    rest = ElementGrid(sheets.SLICE_BOX, shape=sheets.SLICE_SHAPE, anchor="corners").rest_positions
    xy = sheets.slice_xy(rest)
    k = sheets.SLICE_DRAGGED[2]
    order = data["order"]
    on_slice = [(i, e) for i, e in enumerate(order) if int(e[2]) == k]
    ax.scatter(xy[..., 0].ravel(), xy[..., 1].ravel(), s=12, c="0.8", zorder=1, label="at rest")
    ax.scatter(xy[0, :, 0], xy[0, :, 1], s=40, marker="s", c="0.3", zorder=2, label="fixed")
    ranks = np.array([i for i, _ in on_slice], dtype=np.float64)
    pts = np.array([rest[tuple(int(v) for v in e)][:2] for _, e in on_slice])
    sc = ax.scatter(
        pts[:, 0], pts[:, 1], c=ranks, cmap="viridis", s=70, zorder=3, vmin=0, vmax=len(order)
    )
    if sponsors:
        for e, sp in data["sponsors"]:
            if sp is None or e[2] != k or sp[2] != k:
                continue
            ax.annotate(
                "",
                xy=rest[e][:2],
                xytext=rest[sp][:2],
                arrowprops={
                    "arrowstyle": "-|>",
                    "color": "k",
                    "lw": 1.0,
                    "mutation_scale": 9,
                    "shrinkA": 4,
                    "shrinkB": 4,
                },
                zorder=4,
            )
    seed = rest[sheets.SLICE_DRAGGED][:2]
    ax.scatter([seed[0]], [seed[1]], marker="*", s=300, c="tab:red", zorder=6, label="dragged")
    ax.annotate(
        "",
        xy=seed + np.asarray(sheets.SLICE_DRAG_MM[:2]),
        xytext=seed,
        arrowprops={"arrowstyle": "-|>", "color": "tab:red", "lw": 2.5},
        zorder=6,
    )
    sheets.slice_frame(ax)
    if sponsors:
        title = (
            f"(a) Gibson's sponsor lists: move order, arrows sponsor → element\n"
            f"{data['touched']} elements moved, {data['checks']} checks, cleanup"
            f" {data['cleanup']}"
        )
    else:
        title = (
            f"(b) enhanced (priority queue): move order\n{data['touched']} elements moved,"
            f" {data['checks']} queue pops"
        )
    ax.set_title(title, fontsize=10)
    cb = ax.figure.colorbar(sc, ax=ax, shrink=0.8, pad=0.02)
    cb.set_label("order moved (0 = dragged)", fontsize=8)
    cb.ax.tick_params(labelsize=7)
    ax.legend(loc="upper left", fontsize=7, ncol=3)


def _plot_relax_curve(ax: Any, slice_curve: Sequence[float], fish_curve: Sequence[float]) -> None:
    ks = np.arange(len(slice_curve))
    ax.plot(ks, np.asarray(slice_curve) / slice_curve[0], "o-", label="12x9x3 grid (a-f)")
    kf = np.arange(len(fish_curve))
    ax.plot(kf, np.asarray(fish_curve) / fish_curve[0], "s-", label="8³ fish grid (g-i)")
    for k in RELAX_STEPS:
        ax.axvline(k, color="0.8", lw=1, zorder=0)
    ax.set_xlabel("relaxation steps")
    ax.set_ylabel("smoothness energy / after the drag")
    ax.set_title(
        "(c) smoothness energy Σ|u_b − u_a|² per relaxation step",
        fontsize=10,
    )
    ax.set_ylim(0, 1.05)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
