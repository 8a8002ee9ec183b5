"""Teaching demos: ``voxwarp demo NAME`` writes a figure sheet per deformation model.

Each demo measures something on this machine, draws it with matplotlib (the Agg canvas,
no pyplot, no GUI toolkit) into one multi-panel PNG sheet, and returns the numbers it
shows (:class:`DemoResult`). ``voxwarp reproduce`` (:mod:`voxwarp.teaching.reproduce`) runs them all
and puts their numbers beside the papers'.

* ``massspring`` (Knoche 2008, 3.5): explicit vs semi-implicit Euler at the same time
  step: energy over time, the largest energy growth over a range of steps (where each
  integrator becomes unstable), and renders of the fish bent by a drag.
* ``chainmail`` (Gibson 1997; Schill et al. 1998; Knoche 2008, Figure 13): the order in
  which one drag moves the elements (Gibson's sponsors as arrows; the enhanced variant's
  priority queue), then the element grid after 0, 1 and 4 relaxation steps, the
  smoothness energy per step, and the fish rendered after 0, 1 and 4 steps.
* ``compare`` (Knoche 2008, Figures 12-13): mass-spring and ChainMail on the same grid
  and the same drag, side by side, and the CPU and GPU solvers' timings at small sizes
  (:mod:`voxwarp.teaching.measure`; GPU = the moderngl backends on the EGL context,
  labelled with its GL renderer).
* ``wires`` (Journal of WSCG 2006, Figure 12 and Table 1): the fish bent by the bundled
  spine wires with the attribute field at 1:1 ... 1:4096, build times, the share of
  field voxels and of ray samples that need no mapping ("ignored")
  (:mod:`voxwarp.teaching.wire_measure`); the paper's Tables 1-3 measured its way are
  ``python -m benchmarks wire-tables`` in a checkout.
* ``lattice`` (GRAPP 2010, Figures 1 and 5): renders of a bent volume, of the
  lattice-wrapped torus of the paper's Figure 1 and of both normal methods; the frame
  rates against 4x4 matrices (the paper's table) are a full study of the lab, ``python -m
  benchmarks lattice`` in a checkout.
* ``registration`` (no paper; :mod:`voxwarp.teaching.registration_demo`): colin27 deformed
  by known Gaussian bumps, registered back with SimpleITK demons, the moving image
  rendered through the recovered field beside the fixed one (``registration`` extra).

``quick=True`` shrinks every measurement (small volumes, images and grids, one repeat) so
that a demo runs in seconds: the test suite runs every demo that way. With ``tour=True``
a demo also writes ``NAME_tour.json`` (:data:`TOUR_FORMAT`, see :func:`write_tour`): the
steps of a guided walk through the model for the desktop GUI, each with a title, a text
for a student and a scene JSON to show.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.core.extras import require
from voxwarp.core.files import atomic_write, atomic_write_text
from voxwarp.errors import VoxwarpError
from voxwarp.io.samples import bundled_dir
from voxwarp.teaching import DEMO_TITLES, DEMOS
from voxwarp.teaching.tour import TOUR_FORMAT, TOUR_VERSION

#: resolution of the figure sheets (dots per inch)
DPI = 90

# ---------------------------------------------------------------------- the fish drag
#: the element grid over the fish, its fixed head layers (i < HEAD_LAYERS) and the drag
#: of two tail elements sideways (+y), as the mass-spring example of
#: docs/howto/command-line.md (corners not fixed: the head holds the grid)
FISH_GRID: tuple[int, int, int] = (8, 8, 8)
HEAD_LAYERS = 3
FISH_DRAGGED: tuple[tuple[int, int, int], ...] = ((6, 4, 3), (6, 3, 3))
FISH_DRAG_MM: tuple[float, float, float] = (0.0, 12.0, 0.0)
#: the fish renders: seen from above (+z), soft tissue and bone
FISH_VIEW = "+z"
FISH_TF = "ct-soft"

# ---------------------------------------------------------------------- the slice grid
#: the 2D teaching grid of ``chainmail`` and ``compare``: 12 x 9 x 3 elements 10 mm
#: apart, the x = 0 layer fixed, element (9, 4, 1) dragged 15 mm along +y; the figures
#: show the middle z layer
SLICE_SHAPE: tuple[int, int, int] = (12, 9, 3)
SLICE_BOX: tuple[tuple[float, float, float], tuple[float, float, float]] = (
    (0.0, 0.0, 0.0),
    (110.0, 80.0, 20.0),
)
SLICE_DRAGGED: tuple[int, int, int] = (9, 4, 1)
SLICE_DRAG_MM: tuple[float, float, float] = (0.0, 15.0, 0.0)
#: the relaxation steps of the thesis' Figure 13
RELAX_STEPS: tuple[int, ...] = (0, 1, 4)

# ---------------------------------------------------------------------- mass-spring
#: the demo's time step, in units of the semi-implicit integrator's stable step: beyond
#: the explicit integrator's real limit on the fish grid (measured: between 1.0 and 1.5)
DT_FACTOR = 1.5
#: an energy this many times the starting energy counts as blown up
BLOWUP = 1e9


class DemoError(VoxwarpError):
    """An unknown demo name (the message lists the demos)."""


@dataclass
class DemoResult:
    """What :func:`run_demo` wrote and measured.

    Attributes
    ----------
    name
        The demo (one of :data:`DEMOS`).
    figures
        The figure sheet(s), PNG.
    numbers
        The numbers the sheet shows (JSON-ready: plain lists, dicts, floats; infinities
        and NaNs as None).
    seconds
        Wall time of the demo.
    tour
        The tour file (``NAME_tour.json``) when asked for, else None.
    """

    name: str
    figures: list[Path]
    numbers: dict[str, Any]
    seconds: float = 0.0
    tour: Path | None = None

    @property
    def figure(self) -> Path:
        """The (first) figure sheet."""
        return self.figures[0]


@dataclass(frozen=True)
class _Settings:
    """Sizes of one run: full (``voxwarp reproduce``) or quick (tests)."""

    quick: bool
    fish_shape: tuple[int, int, int]
    render_size: tuple[int, int]
    sim_seconds: float
    sweep_points: int
    sweep_steps: int
    relax_curve: int
    ms_sizes: tuple[int, ...]
    ms_steps: int
    ms_repeats: int
    cm_sizes: tuple[int, ...]
    cm_repeats: int
    wire_padded: bool
    wire_size: tuple[int, int]
    wire_subsample: int
    wire_repeats: int
    wire_frames: int


FULL = _Settings(
    quick=False,
    fish_shape=(192, 96, 80),
    render_size=(320, 176),
    sim_seconds=5.0,
    sweep_points=11,
    sweep_steps=150,
    relax_curve=8,
    ms_sizes=(16, 32, 64),
    ms_steps=20,
    ms_repeats=3,
    cm_sizes=(16, 32, 64),
    cm_repeats=3,
    wire_padded=True,
    wire_size=(512, 256),
    wire_subsample=4,
    wire_repeats=2,
    wire_frames=5,
)
QUICK = _Settings(
    quick=True,
    fish_shape=(96, 48, 40),
    render_size=(128, 72),
    sim_seconds=3.0,
    sweep_points=5,
    sweep_steps=60,
    relax_curve=4,
    ms_sizes=(8,),
    ms_steps=4,
    ms_repeats=1,
    cm_sizes=(8,),
    cm_repeats=1,
    wire_padded=False,
    wire_size=(128, 64),
    wire_subsample=8,
    wire_repeats=1,
    wire_frames=1,
)


# ====================================================================== entry point
def run_demo(
    name: str,
    out_dir: str | os.PathLike,
    *,
    quick: bool = False,
    log: Callable[[str], None] | None = None,
    tour: bool = False,
) -> DemoResult:
    """Run the teaching demo ``name`` and write its figure sheet ``out_dir/NAME.png``.

    Parameters
    ----------
    name
        One of :data:`DEMOS`.
    out_dir
        Folder of the sheet (created when missing).
    quick
        Shrink every measurement so that the demo takes seconds (tests).
    log
        Progress messages go here (default: nowhere).
    tour
        Also write ``out_dir/NAME_tour.json`` and the scenes it shows under
        ``out_dir/NAME_tour/`` (see :func:`write_tour`).

    Returns
    -------
    DemoResult
        The sheet's path and the numbers it shows.

    Raises
    ------
    DemoError
        When ``name`` is not a demo.
    """
    if name not in DEMOS:
        raise DemoError(f"unknown demo {name!r}; the demos are: {', '.join(DEMOS)}")
    require("teach", f"voxwarp demo {name}")
    say = log or (lambda _s: None)
    settings = QUICK if quick else FULL
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    run = {
        "massspring": _demo_massspring,
        "chainmail": _demo_chainmail,
        "wires": _demo_wires,
        "lattice": _demo_lattice,
        "compare": _demo_compare,
        "registration": _demo_registration,
    }[name]
    with warnings.catch_warnings():
        # numpy overflow of the blown-up explicit integrator is the point, not a bug
        warnings.simplefilter("ignore", RuntimeWarning)
        figures, numbers, steps = run(settings, out, say)
    numbers = _jsonable(numbers)
    numbers["quick"] = settings.quick
    tour_path = None
    if tour:
        tour_path = write_tour(out, name, DEMO_TITLES[name], figures[0], steps)
    seconds = time.perf_counter() - t0
    numbers["seconds"] = seconds
    say(f"demo {name}: {', '.join(str(f) for f in figures)} ({seconds:.1f} s)")
    return DemoResult(name, figures, numbers, seconds, tour_path)


def _demo_registration(
    settings: _Settings, out: Path, say: Callable[[str], None]
) -> tuple[list[Path], dict[str, Any], list[TourStep]]:
    """``registration``: see :mod:`voxwarp.teaching.registration_demo`."""
    from voxwarp.teaching.registration_demo import demo_registration

    return demo_registration(settings.quick, out, say)


# ====================================================================== shared helpers
@dataclass
class TourStep:
    """One step of a demo's tour (see :func:`write_tour`).

    Attributes
    ----------
    title
        A few words.
    text
        What the step shows and why, for a student.
    scene
        Scene JSON to show (a dict, :meth:`voxwarp.scene.Scene.to_dict` of the moment), the
        path of an existing scene JSON file, or None (the step explains the figure).
    panel
        The letter of the figure sheet's panel the step explains, or None.
    """

    title: str
    text: str
    scene: Any = None
    panel: str | None = None


def _snap(scene: Any) -> dict[str, Any]:
    """The scene JSON of ``scene`` now (a model's warp changes as it steps: tours keep
    the state of the moment)."""
    return scene.to_dict()


def write_tour(
    out_dir: Path, name: str, title: str, figure: Path, steps: Sequence[TourStep]
) -> Path:
    """Write the tour of demo ``name``: ``out_dir/NAME_tour.json`` and its scenes.

    The file is JSON::

        {"format": "voxwarp-tour", "version": 1, "demo": NAME, "title": TITLE,
         "figure": "NAME.png",
         "steps": [{"title": ..., "text": ..., "scene": "NAME_tour/01.json" | null,
                    "panel": "a" | null}, ...]}

    Paths are relative to the tour file's folder. Every scene is scene JSON
    (:meth:`voxwarp.scene.Scene.save`): ``voxwarp render`` and ``voxwarp gui`` open it and
    :meth:`voxwarp.editing.session.EditSession.load` resumes its deformation model. ``panel`` names
    the panel of the figure sheet the step explains.

    Parameters
    ----------
    out_dir
        Folder of the tour file.
    name, title
        The demo and its title.
    figure
        The demo's figure sheet.
    steps
        The steps; a step's ``scene`` is a :class:`~voxwarp.scene.Scene`, a path of an
        existing scene JSON, or None (the step only explains the figure).

    Returns
    -------
    pathlib.Path
        The tour file.
    """
    scene_dir = out_dir / f"{name}_tour"
    entries = []
    for i, st in enumerate(steps, start=1):
        rel = None
        if isinstance(st.scene, str | Path):
            rel = os.path.relpath(Path(st.scene).resolve(), out_dir.resolve())
        elif st.scene is not None:
            path = scene_dir / f"{i:02d}.json"
            atomic_write_text(path, json.dumps(st.scene, indent=1) + "\n")
            rel = path.relative_to(out_dir).as_posix()
        entries.append({"title": st.title, "text": st.text, "scene": rel, "panel": st.panel})
    doc = {
        "format": TOUR_FORMAT,
        "version": TOUR_VERSION,
        "demo": name,
        "title": title,
        "figure": os.path.relpath(figure.resolve(), out_dir.resolve()),
        "steps": entries,
    }
    path = out_dir / f"{name}_tour.json"
    atomic_write_text(path, json.dumps(doc, indent=1) + "\n")
    return path


def _jsonable(x: Any) -> Any:
    """``x`` with numpy scalars and arrays as Python numbers and lists, tuples as lists,
    non-finite floats as None and dict keys as they are (str or int)."""
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, np.bool_ | bool):
        return bool(x)
    if isinstance(x, np.integer | int):
        return int(x)
    if isinstance(x, np.floating | float):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, Path):
        return str(x)
    return x


@contextlib.contextmanager
def _offscreen(size: tuple[int, int]) -> Iterator[Any]:
    """An :class:`~voxwarp.render.offscreen.OffscreenRenderer` whose context is current for the
    block
    (the GPU solvers and benchmarks run on it too)."""
    from voxwarp.render.offscreen import OffscreenRenderer

    with OffscreenRenderer(*size) as r, r.current():
        yield r


def _gl_renderer(r: Any) -> str:
    return str(r.ctx.info.get("GL_RENDERER", "?"))


def _rgb(r: Any, scene: Any, size: tuple[int, int]) -> np.ndarray:
    """``scene`` rendered at ``size`` as (H, W, 3) uint8."""
    if tuple(r.size) != tuple(size):
        r.resize(*size)
    return r.render(scene)[..., :3].copy()


def _framing_camera(
    lo: np.ndarray,
    hi: np.ndarray,
    view: Any,
    size: tuple[int, int],
    fill: float = 0.95,
    fov: float = 30.0,
) -> Any:
    """A perspective camera from ``view`` that the box [lo, hi] fills (``fill`` of the
    image's width or height, whichever is reached first)."""
    from voxwarp.core.camera import Camera

    return Camera.framing(lo, hi, view, size, fill=fill, fov=fov)


def _fish(settings: _Settings) -> Any:
    from voxwarp.io.samples import load_sample

    return load_sample("fish", shape=settings.fish_shape)


def _fish_camera(vol: Any, size: tuple[int, int]) -> Any:
    """The top view of the fish and where the drag moves its tail."""
    lo, hi = (np.asarray(b, dtype=np.float64).copy() for b in vol.bounds)
    lo[1] -= 2.0
    hi[1] += FISH_DRAG_MM[1] + 2.0
    return _framing_camera(lo, hi, FISH_VIEW, size)


def _fish_scene(vol: Any, camera: Any, warps: Sequence[Any] = ()) -> Any:
    from voxwarp.scene import Scene

    return Scene(vol, transfer_function=FISH_TF, camera=camera, warps=list(warps), jitter=False)


def _fish_grid(vol: Any) -> Any:
    """The fish's element grid: the head layers fixed, the other corners free."""
    from voxwarp.deform.elements.grid import ElementGrid

    grid = ElementGrid(vol, shape=FISH_GRID)
    grid.free(grid.corner_mask())
    head = np.zeros(FISH_GRID, dtype=bool)
    head[:HEAD_LAYERS] = True
    grid.fix(head)
    return grid


def _slice_grid() -> Any:
    """The teaching grid (:data:`SLICE_SHAPE`): the x = 0 layer fixed, no other corner."""
    from voxwarp.deform.elements.grid import ElementGrid

    grid = ElementGrid(SLICE_BOX, shape=SLICE_SHAPE)
    grid.free(grid.corner_mask())
    left = np.zeros(SLICE_SHAPE, dtype=bool)
    left[0] = True
    grid.fix(left)
    return grid


def _figure(width: float, height: float, title: str) -> Any:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=DPI, layout="constrained")
    fig.suptitle(title, fontsize=14, fontweight="bold")
    return fig


def _save_figure(fig: Any, path: Path) -> Path:
    """Write ``fig`` as a PNG of 256 colours (renders and plots alike look the same and
    the file is about 4x smaller), atomically: temp file beside ``path``, then rename."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from PIL import Image

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    rgb = np.ascontiguousarray(np.asarray(canvas.buffer_rgba())[..., :3])
    img = Image.fromarray(rgb).quantize(
        256, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE
    )
    atomic_write(path, ".png", lambda tmp: img.save(tmp, format="PNG", optimize=True))
    return path


def _show_image(ax: Any, img: np.ndarray, title: str) -> None:
    ax.imshow(img, interpolation="lanczos")
    ax.set_title(title, fontsize=10)
    ax.set_xticks([])
    ax.set_yticks([])
    for s in ax.spines.values():
        s.set_visible(False)


def _note(ax: Any, text: str, where: str = "lower left", width: int = 60) -> None:
    """A small boxed note inside a panel (``where``: "lower left", "upper left", "lower
    right" or "upper right"), wrapped at ``width`` characters; it does not take part in
    the layout."""
    import textwrap

    vert, horiz = where.split()
    x = 0.02 if horiz == "left" else 0.98
    y = 0.03 if vert == "lower" else 0.97
    t = ax.text(
        x,
        y,
        textwrap.fill(text, width),
        transform=ax.transAxes,
        fontsize=8,
        color="0.2",
        va="bottom" if vert == "lower" else "top",
        ha=horiz,
        multialignment="left",
        bbox={"boxstyle": "round", "facecolor": "white", "edgecolor": "0.7", "alpha": 0.9},
        zorder=10,
    )
    t.set_in_layout(False)


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
    ms = _mass_spring(_fish_grid(vol), integrator, dt, clamp)
    ms.move(list(FISH_DRAGGED), FISH_DRAG_MM)
    return ms


def _demo_massspring(
    s: _Settings, out: Path, log: Callable[[str], None]
) -> tuple[list[Path], dict[str, Any], list[TourStep]]:
    vol = _fish(s)
    probe = {i: _mass_spring(_fish_grid(vol), i, 1.0, True) for i in ("explicit", "semi-implicit")}
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
    cam = _fish_camera(vol, s.render_size)
    shots: list[tuple[str, np.ndarray]] = []
    tour_states: dict[str, Any] = {}
    semi_dt = stable["semi-implicit"]
    mid_steps = max(1, round(0.3 / semi_dt))
    with _offscreen(s.render_size) as r:
        gl = _gl_renderer(r)
        shots.append(("(c) at rest", _rgb(r, _fish_scene(vol, cam), s.render_size)))
        semi = _dragged_fish_model(vol, "semi-implicit", semi_dt, True)
        tour_states["dragged"] = _snap(_fish_scene(vol, cam, [semi.warp()]))
        shots.append(
            (
                "(d) t = 0: tail elements dragged",
                _rgb(r, _fish_scene(vol, cam, [semi.warp()]), s.render_size),
            )
        )
        semi.step(mid_steps)
        t_mid = mid_steps * semi_dt
        tour_states["moving"] = _snap(_fish_scene(vol, cam, [semi.warp()]))
        shots.append(
            (
                f"(e) semi-implicit (dt {semi_dt * 1000:.1f} ms), t = {t_mid:.2f} s",
                _rgb(r, _fish_scene(vol, cam, [semi.warp()]), s.render_size),
            )
        )
        settle_steps = mid_steps + semi.settle(max_steps=20000, tol=1e-3)
        tour_states["settled"] = _snap(_fish_scene(vol, cam, [semi.warp()]))
        max_disp = float(np.linalg.norm(semi.displacements(), axis=-1).max())
        shots.append(
            (
                f"(f) semi-implicit, settled ({settle_steps} steps)",
                _rgb(r, _fish_scene(vol, cam, [semi.warp()]), s.render_size),
            )
        )
        expl = _dragged_fish_model(vol, "explicit", dt, True)
        with np.errstate(all="ignore"):
            expl.step(steps)
        tour_states["explicit"] = _snap(_fish_scene(vol, cam, [expl.warp()]))
        shots.append(
            (
                f"(g) explicit + clamp, same dt, t = {steps * dt:.1f} s",
                _rgb(r, _fish_scene(vol, cam, [expl.warp()]), s.render_size),
            )
        )
        slow = _dragged_fish_model(vol, "explicit", stable["explicit"], True)
        slow.step(steps)
        shots.append(
            (
                f"(h) explicit at its stable dt, {steps} steps"
                f" (t = {steps * stable['explicit']:.2f} s)",
                _rgb(r, _fish_scene(vol, cam, [slow.warp()]), s.render_size),
            )
        )

    numbers: dict[str, Any] = {
        "grid": FISH_GRID,
        "fixed": f"i < {HEAD_LAYERS} (the head)",
        "dragged": FISH_DRAGGED,
        "drag_mm": FISH_DRAG_MM,
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
    fig = _figure(15.0, 9.2, DEMO_TITLES["massspring"])
    grid = fig.add_gridspec(2, 6, height_ratios=[1.15, 1.0])
    _plot_energy(fig.add_subplot(grid[0, 0:3]), numbers)
    _plot_sweep(fig.add_subplot(grid[0, 3:6]), numbers)
    sub = grid[1, :].subgridspec(2, 3)
    for i, (title, img) in enumerate(shots):
        _show_image(fig.add_subplot(sub[i // 3, i % 3]), img, title)
    path = _save_figure(fig, out / "massspring.png")

    tour = [
        TourStep(
            "A grid of masses and springs",
            "The fish is covered by an 8x8x8 grid of point masses joined by springs (along"
            " the axes and the face diagonals). The head's three layers are fixed. Moving"
            " an element stretches its springs; their forces pull the neighbours along, and"
            " the elements' displacements bend the volume at render time: the voxels are"
            " never resampled.",
            _snap(_fish_scene(vol, cam)),
            "c",
        ),
        TourStep(
            "Drag the tail",
            "Two tail elements are held 12 mm to the side. At t = 0 nothing else has moved"
            " yet: only the cells around the held elements are stretched.",
            tour_states["dragged"],
            "d",
        ),
        TourStep(
            "Semi-implicit Euler",
            "Each step first updates the velocity from the spring forces, v' = v + dt a,"
            " then the position with the new velocity, x' = x + dt v'. At its default time"
            f" step ({semi_dt * 1000:.0f} ms), and even at {dt * 1000:.0f} ms (panel a), the"
            " energy only falls: the bend spreads along the body.",
            tour_states["moving"],
            "e",
        ),
        TourStep(
            "Settled",
            "Once every element is slower than 0.001 mm/s the grid is at rest: the tail"
            " bends in a smooth curve from the fixed head to the held elements.",
            tour_states["settled"],
            "f",
        ),
        TourStep(
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
        TourStep(
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
    _note(
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
    _note(
        ax,
        "Dashed: each integrator's guaranteed-stable step (MassSpring.stable_time_step);"
        " solid: the dt of (a). Above 1: the run gained energy (capped at"
        f" {BLOWUP:.0e}). Explicit Euler turns unstable at a step several times smaller"
        " than semi-implicit Euler.",
        "upper left",
        48,
    )


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
        cm = ChainMail(_slice_grid(), variant=variant)
        stats = cm.move(SLICE_DRAGGED, SLICE_DRAG_MM)
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
        sp = gibson_sponsor(e, SLICE_DRAGGED)
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


def _demo_chainmail(
    s: _Settings, out: Path, log: Callable[[str], None]
) -> tuple[list[Path], dict[str, Any], list[TourStep]]:
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

    vol = _fish(s)
    cam = _fish_camera(vol, s.render_size)
    fish_cm = ChainMail(_fish_grid(vol), variant="enhanced")
    fish_stats = fish_cm.move(list(FISH_DRAGGED), FISH_DRAG_MM)
    renders: list[tuple[str, np.ndarray]] = []
    fish_curve = [fish_cm.smoothness_energy()]
    tour_scenes: dict[int, Any] = {}
    done = 0
    with _offscreen(s.render_size) as r:
        gl = _gl_renderer(r)
        for k in RELAX_STEPS:
            if k > done:
                for _ in range(k - done):
                    fish_cm.relax(1)
                    fish_curve.append(fish_cm.smoothness_energy())
                done = k
            fish_cm.relax_steps = k  # saved with the model: a resumed one relaxes alike
            scene = _fish_scene(vol, cam, [fish_cm.warp()])
            tour_scenes[k] = _snap(scene)
            renders.append(
                (
                    f"({'ghi'[len(renders)]}) fish, tail dragged 12 mm, {k} relaxation"
                    f" step{'s' * (k != 1)}",
                    _rgb(r, scene, s.render_size),
                )
            )
    for _ in range(done, s.relax_curve):
        fish_cm.relax(1)
        fish_curve.append(fish_cm.smoothness_energy())

    numbers: dict[str, Any] = {
        "grid": SLICE_SHAPE,
        "box_mm": SLICE_BOX,
        "dragged": SLICE_DRAGGED,
        "drag_mm": SLICE_DRAG_MM,
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
            "grid": FISH_GRID,
            "dragged": FISH_DRAGGED,
            "drag_mm": FISH_DRAG_MM,
            "touched": fish_stats.touched,
            "fraction": fish_stats.fraction,
            "smoothness_energy": {k: fish_curve[k] for k in RELAX_STEPS},
            "relax_curve": fish_curve,
        },
        "gl_renderer": gl,
    }
    fig = _figure(15.0, 13.0, DEMO_TITLES["chainmail"])
    grid = fig.add_gridspec(3, 3, height_ratios=[1.15, 1.0, 0.75])
    _plot_order(fig.add_subplot(grid[0, 0]), sl["gibson"], sponsors=True)
    _plot_order(fig.add_subplot(grid[0, 1]), sl["enhanced"], sponsors=False)
    _plot_relax_curve(fig.add_subplot(grid[0, 2]), slice_curve, fish_curve)
    for i, k in enumerate(RELAX_STEPS):
        _plot_slice_state(
            fig.add_subplot(grid[1, i]),
            states[k],
            f"({'def'[i]}) {k} relaxation step{'s' * (k != 1)} after the drag:"
            f" E = {slice_energy[k]:.0f} mm²",
            colorbar=i == len(RELAX_STEPS) - 1,
        )
    for i, (title, img) in enumerate(renders):
        _show_image(fig.add_subplot(grid[2, i]), img, title)
    path = _save_figure(fig, out / "chainmail.png")

    tour = [
        TourStep(
            "Links with slack",
            "3D ChainMail links every element to its 6 neighbours like the rings of a chain"
            " mail: a link may stretch, compress or shear by up to a quarter of the element"
            " spacing (stiffness 0.5) before it pulls its neighbour along.",
            _snap(_fish_scene(vol, cam)),
            None,
        ),
        TourStep(
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
        TourStep(
            "The enhanced variant",
            "Schill et al.'s priority queue moves first the element that is asked to move"
            " farthest, against all its links at once (Dijkstra's order). For one drag it"
            " ends in the same state as Gibson's lists (panel b): only the order differs.",
            None,
            "b",
        ),
        TourStep(
            "Right after the drag",
            "Without relaxation the deformation is piecewise linear: straight, sheared blocks"
            " with sharp kinks at both ends of the taut chain of links.",
            tour_scenes[0],
            "d",
        ),
        TourStep(
            "One relaxation step",
            "Relaxation moves every free element towards the mean displacement of its"
            " neighbours, but only as far as its links allow: the kinks round off and the"
            " smoothness energy (sum of squared displacement differences) falls.",
            tour_scenes[1],
            "e",
        ),
        TourStep(
            "Four relaxation steps",
            "After four steps the bend is smooth; every link still satisfies its limits"
            " (panel c plots the energy per step).",
            tour_scenes[4],
            "f",
        ),
    ]
    return [path], numbers, tour


def _slice_xy(positions: np.ndarray) -> np.ndarray:
    """(nx, ny, 2) x, y of the middle z layer."""
    return positions[:, :, SLICE_DRAGGED[2], :2]


def _slice_frame(ax: Any) -> None:
    lo, hi = SLICE_BOX
    ax.set_xlim(lo[0] - 8, hi[0] + 8)
    ax.set_ylim(lo[1] - 8, hi[1] + 8 + SLICE_DRAG_MM[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.tick_params(labelsize=8)


def _plot_order(ax: Any, data: dict[str, Any], sponsors: bool) -> None:
    from voxwarp.deform.elements.grid import ElementGrid

    rest = ElementGrid(SLICE_BOX, shape=SLICE_SHAPE).rest_positions
    xy = _slice_xy(rest)
    k = SLICE_DRAGGED[2]
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
    seed = rest[SLICE_DRAGGED][:2]
    ax.scatter([seed[0]], [seed[1]], marker="*", s=300, c="tab:red", zorder=6, label="dragged")
    ax.annotate(
        "",
        xy=seed + np.asarray(SLICE_DRAG_MM[:2]),
        xytext=seed,
        arrowprops={"arrowstyle": "-|>", "color": "tab:red", "lw": 2.5},
        zorder=6,
    )
    _slice_frame(ax)
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


def _plot_slice_state(ax: Any, positions: np.ndarray, title: str, colorbar: bool = True) -> None:
    from voxwarp.deform.elements.grid import ElementGrid

    rest = ElementGrid(SLICE_BOX, shape=SLICE_SHAPE).rest_positions
    xy = _slice_xy(positions)
    u = np.linalg.norm(_slice_xy(positions - rest), axis=-1)
    for i in range(xy.shape[0]):
        ax.plot(xy[i, :, 0], xy[i, :, 1], color="0.55", lw=0.8, zorder=1)
    for j in range(xy.shape[1]):
        ax.plot(xy[:, j, 0], xy[:, j, 1], color="0.55", lw=0.8, zorder=1)
    sc = ax.scatter(
        xy[..., 0].ravel(),
        xy[..., 1].ravel(),
        c=u.ravel(),
        cmap="magma_r",
        vmin=0,
        vmax=float(np.linalg.norm(SLICE_DRAG_MM)),
        s=22,
        edgecolors="0.3",
        linewidths=0.4,
        zorder=2,
    )
    ax.scatter(xy[0, :, 0], xy[0, :, 1], s=40, marker="s", c="0.3", zorder=3)
    d = SLICE_DRAGGED[:2]
    ax.scatter([xy[d][0]], [xy[d][1]], marker="*", s=200, c="tab:red", zorder=4)
    _slice_frame(ax)
    ax.set_title(title, fontsize=10)
    if colorbar:
        cb = ax.figure.colorbar(sc, ax=ax, shrink=0.8, pad=0.02)
        cb.set_label("|displacement| (mm)", fontsize=8)
        cb.ax.tick_params(labelsize=7)


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


# ====================================================================== compare
def _demo_compare(
    s: _Settings, out: Path, log: Callable[[str], None]
) -> tuple[list[Path], dict[str, Any], list[TourStep]]:
    from voxwarp.deform.elements.chainmail import ChainMail
    from voxwarp.deform.elements.grid import ElementGrid
    from voxwarp.deform.elements.massspring import MassSpring
    from voxwarp.teaching.measure import chainmail_times, massspring_rates

    # the same grid and drag in both models
    t = time.perf_counter()
    ms = MassSpring(_slice_grid(), integrator="semi-implicit", shear=True)
    ms.move(SLICE_DRAGGED, SLICE_DRAG_MM)
    ms_steps = ms.settle(max_steps=20000, tol=1e-3)
    ms_s = time.perf_counter() - t
    cm = ChainMail(_slice_grid(), variant="enhanced")
    cm.move(SLICE_DRAGGED, SLICE_DRAG_MM)  # loads the numba kernels: not timed
    cm.reset()
    stats = cm.move(SLICE_DRAGGED, SLICE_DRAG_MM)
    cm0 = cm.positions()
    cm.relax(4)
    cm4 = cm.positions()
    rest = ElementGrid(SLICE_BOX, shape=SLICE_SHAPE).rest_positions
    states = {"massspring": ms.positions(), "chainmail": cm0, "chainmail+4": cm4}
    u = {k: np.linalg.norm(v - rest, axis=-1) for k, v in states.items()}
    moved = {k: int(np.count_nonzero(v > 0.01)) for k, v in u.items()}
    log(f"compare: mass-spring settled in {ms_steps} steps, ChainMail touched {stats.touched}")

    vol = _fish(s)
    cam = _fish_camera(vol, s.render_size)
    renders: list[tuple[str, np.ndarray]] = []
    tour_scenes: dict[str, Any] = {}
    with _offscreen(s.render_size) as r:
        gl = _gl_renderer(r)
        fms = MassSpring(_fish_grid(vol), integrator="semi-implicit", shear=True)
        fms.move(list(FISH_DRAGGED), FISH_DRAG_MM)
        fms.settle(max_steps=20000, tol=1e-3)
        scene = _fish_scene(vol, cam, [fms.warp()])
        tour_scenes["massspring"] = _snap(scene)
        renders.append(("(d) fish, mass-spring (settled)", _rgb(r, scene, s.render_size)))
        fcm = ChainMail(_fish_grid(vol), variant="enhanced")
        fcm.move(list(FISH_DRAGGED), FISH_DRAG_MM)
        scene = _fish_scene(vol, cam, [fcm.warp()])
        tour_scenes["chainmail"] = _snap(scene)
        renders.append(("(e) fish, ChainMail", _rgb(r, scene, s.render_size)))
        fcm.relax(4)
        fcm.relax_steps = 4
        scene = _fish_scene(vol, cam, [fcm.warp()])
        tour_scenes["chainmail+4"] = _snap(scene)
        renders.append(("(f) fish, ChainMail + 4 relaxation steps", _rgb(r, scene, s.render_size)))
        # CPU vs GPU at small sizes, on this context (voxwarp.teaching.measure)
        log("compare: timing the mass-spring solvers")
        ms_rows, ms_model = massspring_rates(
            s.ms_sizes, steps=s.ms_steps, repeats=s.ms_repeats, ctx=r.ctx, log=log
        )
        log("compare: timing the ChainMail solvers")
        cm_rows = chainmail_times(s.cm_sizes, repeats=s.cm_repeats, ctx=r.ctx, log=log)
    diff = np.linalg.norm(states["massspring"] - states["chainmail+4"], axis=-1)
    numbers: dict[str, Any] = {
        "grid": SLICE_SHAPE,
        "dragged": SLICE_DRAGGED,
        "drag_mm": SLICE_DRAG_MM,
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
    fig = _figure(16.0, 10.5, DEMO_TITLES["compare"])
    grid = fig.add_gridspec(3, 1, height_ratios=[1.2, 0.8, 1.0])
    top = grid[0].subgridspec(1, 3)
    _plot_slice_state(
        fig.add_subplot(top[0, 0]),
        states["massspring"],
        f"(a) mass-spring, settled ({ms_steps} steps)\n{moved['massspring']} elements moved",
    )
    _plot_slice_state(
        fig.add_subplot(top[0, 1]),
        states["chainmail"],
        f"(b) ChainMail, one move ({stats.seconds * 1000:.2f} ms)\n"
        f"{moved['chainmail']} elements moved",
    )
    _plot_slice_state(
        fig.add_subplot(top[0, 2]),
        states["chainmail+4"],
        f"(c) ChainMail + 4 relaxation steps\n{moved['chainmail+4']} elements moved",
    )
    mid = grid[1].subgridspec(1, 3)
    for i, (title, img) in enumerate(renders):
        _show_image(fig.add_subplot(mid[0, i]), img, title)
    bottom = grid[2].subgridspec(1, 2)
    _plot_ms_timings(fig.add_subplot(bottom[0, 0]), numbers)
    _plot_cm_timings(fig.add_subplot(bottom[0, 1]), numbers)
    path = _save_figure(fig, out / "compare.png")

    tour = [
        TourStep(
            "Mass-spring: forces over time",
            "The mass-spring model pulls the grid along through spring forces, step by step"
            f" ({ms_steps} semi-implicit steps until it settles). Every element moves a"
            " little: the bend is smooth and spreads over the whole free part.",
            tour_scenes["massspring"],
            "a",
        ),
        TourStep(
            "ChainMail: geometry at once",
            "ChainMail settles the same drag in one move, in milliseconds, by moving every"
            " other element as little as its links allow: only the elements on taut chains"
            " move, and the rest stays exactly at rest.",
            tour_scenes["chainmail"],
            "b",
        ),
        TourStep(
            "ChainMail with relaxation",
            "Four relaxation steps spread the deformation and round the kinks, coming closer"
            " to the mass-spring shape while every link stays within its limits.",
            tour_scenes["chainmail+4"],
            "c",
        ),
        TourStep(
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


# ====================================================================== wires
def _demo_wires(
    s: _Settings, out: Path, log: Callable[[str], None]
) -> tuple[list[Path], dict[str, Any], list[TourStep]]:
    from voxwarp.deform.wires.field import WireFieldWarp
    from voxwarp.deform.wires.propagation import opencl_device_name
    from voxwarp.io.samples import load_sample
    from voxwarp.scene import Scene
    from voxwarp.teaching.wire_measure import (
        DEFAULT_SCALES,
        FISH_WIRES,
        FRAMED_VIEW,
        RENDER_SCALE,
        classify_samples,
        framed_camera,
        load_wires,
        padded_fish,
        time_field_builds,
    )

    vol = padded_fish() if s.wire_padded else _fish(s)
    wires, spec = load_wires(FISH_WIRES)
    size = s.wire_size
    # the pictures from above (+z: the sideways bend in the image plane, the tail fin
    # turned edge-on by the twist); the ray statistics and the render cost from the view
    # of ``python -m benchmarks wires`` (FRAMED_VIEW), so that they compare with its report
    cam = framed_camera(vol, wires, size, view=FISH_VIEW)
    stats_cam = framed_camera(vol, wires, size)
    tf = FISH_TF
    rows: list[dict[str, Any]] = []
    renders: list[tuple[str, np.ndarray]] = []
    render_cost: dict[str, Any] = {}
    with _offscreen(size) as r:
        gl = _gl_renderer(r)
        base = Scene(vol, transfer_function=tf, camera=cam, jitter=False)
        stats_base = base.copy(camera=stats_cam)
        renders.append(("undeformed", _rgb(r, base, size)))
        first: np.ndarray | None = None
        for scale in DEFAULT_SCALES:
            row, wd = time_field_builds(vol, wires, scale, s.wire_repeats)
            warp = wd.warp()
            scene = base.copy(warps=[warp])
            stats_scene = stats_base.copy(warps=[warp])
            stats = classify_samples(stats_scene, stats_cam, size, warp, s.wire_subsample)
            img = _rgb(r, scene, size)
            renders.append((f"1:{scale**3}", img))
            if first is None:
                first = img
            differ = np.abs(img.astype(np.int16) - first.astype(np.int16)).max(axis=-1) > 24
            rows.append(
                {
                    "scale": scale,
                    "ratio": f"1:{scale**3}",
                    **row,
                    "samples": stats["samples"],
                    "samples_ignored": stats["identity"],
                    "samples_vacated": stats["vacated"],
                    "samples_swept": stats["swept"],
                    "percent_ignored_samples": 100.0 * stats["identity"] / max(stats["samples"], 1),
                    "pixels_differing_from_1to1": 100.0 * float(differ.mean()),
                }
            )
            log(
                f"wires 1:{scale**3}: built in {row['build_s']:.3f} s,"
                f" {row['percent_ignored_voxels']:.2f} % of field voxels and"
                f" {rows[-1]['percent_ignored_samples']:.2f} % of ray samples ignored"
            )
            if scale == RENDER_SCALE:
                warm = 2 if not s.quick else 1
                deformed = r.time_frames(stats_scene, frames=s.wire_frames, warmup=warm)
                plain = r.time_frames(stats_base, frames=s.wire_frames, warmup=warm)
                render_cost = {
                    "scale": scale,
                    "deformed_ms": float(np.median(deformed)),
                    "undeformed_ms": float(np.median(plain)),
                    "frames": s.wire_frames,
                }
                render_cost["ratio"] = render_cost["deformed_ms"] / render_cost["undeformed_ms"]
    numbers: dict[str, Any] = {
        "storage": _wire_storage(vol, wires),
        "volume": vol.name,
        "volume_shape": vol.shape,
        "wire_file": "sample_volumes/fish_spine_wires.json",
        "image": size,
        "transfer_function": tf,
        "ray_subsample": s.wire_subsample,
        "view": FISH_VIEW,
        "stats_view": FRAMED_VIEW,
        "rows": rows,
        "render_cost": render_cost,
        "opencl_device": opencl_device_name(),
        "gl_renderer": gl,
    }
    fig = _figure(16.0, 11.0, DEMO_TITLES["wires"])
    grid = fig.add_gridspec(3, 1, height_ratios=[1.0, 1.0, 1.15])
    for row_i in range(2):
        sub = grid[row_i].subgridspec(1, 3)
        for j in range(3):
            idx = row_i * 3 + j
            title, img = renders[idx]
            if idx == 0:
                label = "(a) undeformed fish"
            else:
                rw = rows[idx - 1]
                fs = "x".join(map(str, rw["field_shape"]))
                label = f"({'abcdef'[idx]}) field {title} ({fs}), built in {rw['build_s']:.3f} s"
                if idx > 1:
                    diff = rw["pixels_differing_from_1to1"]
                    label += f"\n{diff:.2f} % of the pixels differ from the 1:1 image"
            _show_image(fig.add_subplot(sub[0, j]), img, label)
    bottom = grid[2].subgridspec(1, 2, width_ratios=[1.0, 1.35])
    _plot_ignored(fig.add_subplot(bottom[0, 0]), numbers)
    _table_wires(fig.add_subplot(bottom[0, 1]), numbers)
    path = _save_figure(fig, out / "wires.png")

    # the tour's scenes: the bundled fish (its default shape), the wire file at each scale
    fish = load_sample("fish")
    tcam = framed_camera(fish, wires, size)
    entry = {"type": "wires", **{k: v for k, v in spec.items() if k in ("wires", "masks")}}
    tour = [
        TourStep(
            "Wires",
            "A wire is a curve laid through an object (the base wire, along the fish's spine)"
            " and a modified copy the user bends, twists and scales. Each cross-section of the"
            " object normal to the base wire is shown on the plane normal to the modified wire"
            " at the same fraction of its length.",
            _snap(Scene(fish, transfer_function=tf, camera=tcam, jitter=False)),
            "a",
        ),
    ]
    for i, scale in enumerate(DEFAULT_SCALES):
        warp = WireFieldWarp.from_dict({**entry, "field_scale": scale})
        tour.append(
            TourStep(
                f"Attribute field 1:{scale**3}",
                "Every ray sample looks up a field that says whether it is swept, by which"
                " wire and at which fraction t, or can be ignored (no mapping needed)."
                f" Here the field has one voxel per {scale}³ volume voxels"
                f" ({rows[i]['percent_ignored_voxels']:.1f} % of its voxels ignored,"
                f" built in {rows[i]['build_s']:.3f} s on this machine). Coarser fields"
                " build faster but blur the edges of the swept object.",
                _snap(Scene(fish, transfer_function=tf, camera=tcam, jitter=False, warps=[warp])),
                "abcdef"[i + 1],
            )
        )
    tour.append(
        TourStep(
            "Samples ignored",
            "Most samples of a ray never touch the bent object: they read the field once and"
            " go on unmapped (panel g, the wire paper's Table 1). The share shrinks as the"
            " field gets coarser, because a coarse voxel that touches the object counts as"
            " swept as a whole.",
            None,
            "g",
        )
    )
    return [path], numbers, tour


def _wire_storage(vol: Any, wires: Sequence[Any]) -> list[dict[str, Any]]:
    """Bytes per field voxel of each layout and the plane masks' memory (section 7.2 and
    7.1) for the fish's field at the render scale."""
    from voxwarp.deform.wires.field import LAYOUTS, WireDeformer
    from voxwarp.teaching.wire_measure import RENDER_SCALE

    rows = []
    for layout in LAYOUTS:
        wd = WireDeformer(vol, wires, field_scale=RENDER_SCALE, layout=layout)
        st = wd.build()
        rows.append(
            {
                "layout": layout,
                "field_shape": list(st.field_shape),
                "bytes_per_voxel": wd.field.nbytes / st.voxels,
                "field_bytes": wd.field.nbytes,
                "mask_bytes": st.mask_bytes_total,
            }
        )
    return rows


def _plot_ignored(ax: Any, n: dict[str, Any]) -> None:
    rows = n["rows"]
    labels = [r["ratio"] for r in rows]
    x = np.arange(len(rows))
    ax.plot(x, [r["percent_ignored_voxels"] for r in rows], "o-", lw=2, label="field voxels")
    ax.plot(x, [r["percent_ignored_samples"] for r in rows], "s-", lw=2, label="ray samples")
    ax.set_xticks(x, labels)
    ax.set_xlabel("attribute field : volume voxels")
    ax.set_ylabel("ignored (identity, no mapping) %")
    ax.set_title("(g) samples ignored per field scale, over the whole ray box", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax2 = ax.twinx()
    ax2.semilogy(x, [r["build_s"] for r in rows], "^--", color="tab:red", label="build time")
    ax2.set_ylabel("field build (s, log)", color="tab:red")
    ax2.tick_params(axis="y", colors="tab:red")
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, fontsize=8, loc="upper right")


def _table_wires(ax: Any, n: dict[str, Any]) -> None:
    ax.axis("off")
    head = [
        "field",
        "shape",
        "build s",
        "swept",
        "vacated",
        "% voxels\nignored",
        "samples",
        "% samples\nignored",
    ]
    cells = [
        [
            r["ratio"],
            "x".join(map(str, r["field_shape"])),
            f"{r['build_s']:.3f}",
            str(r["swept"]),
            str(r["vacated"]),
            f"{r['percent_ignored_voxels']:.2f}",
            str(r["samples"]),
            f"{r['percent_ignored_samples']:.2f}",
        ]
        for r in n["rows"]
    ]
    table = ax.table(cellText=cells, colLabels=head, loc="upper center", cellLoc="right")
    table.auto_set_font_size(False)
    table.set_fontsize(9)
    table.scale(1.0, 1.6)
    for (row, _col), cell in table.get_celld().items():
        if row == 0:
            cell.set_facecolor("0.9")
            cell.set_text_props(fontweight="bold")
    rc = n["render_cost"]
    text = (
        "Coarser fields build faster, but a coarse voxel that touches the bent object is"
        " swept as a whole, so fewer samples can be ignored. Pixels 'differ' by more than"
        " 24/255 in a channel. Table 1 counted the paper's way (inside the wires' regions"
        " only) and Tables 2-3 (identity wires): `voxwarp reproduce`'s report."
    )
    if rc:
        text += (
            f" Render at 1:{rc['scale'] ** 3}: {rc['deformed_ms']:.1f} ms deformed vs"
            f" {rc['undeformed_ms']:.1f} ms undeformed = {rc['ratio']:.2f}x"
            f" ({n['image'][0]}x{n['image'][1]}, {n['gl_renderer']})."
        )
    _note(ax, text, "lower left", 110)
    ax.set_title(
        f"(h) field builds (median of {n['rows'][0]['builds']}) and ray samples\n{n['volume']};"
        f" rays through every {n['ray_subsample']}th pixel of {n['image'][0]}x{n['image'][1]},"
        f" view {tuple(n['stats_view'])}",
        fontsize=10,
    )


# ====================================================================== lattice
def _demo_lattice(
    s: _Settings, out: Path, log: Callable[[str], None]
) -> tuple[list[Path], dict[str, Any], list[TourStep]]:
    from voxwarp.deform.lattice.warp import LatticeWarp
    from voxwarp.teaching.lattice_scenes import torus_tubes
    from voxwarp.teaching.papers import lattice_ratio_range

    vol = _fish(s)
    spec = json.loads((bundled_dir() / "fish_lattice_bend.json").read_text(encoding="utf-8"))
    entry = {k: v for k, v in spec.items() if k not in ("description", "sample", "type")}
    entry.setdefault("box", [list(map(float, b)) for b in vol.bounds])
    warp = LatticeWarp.from_dict(entry)
    lo, hi = (np.asarray(b, dtype=np.float64).copy() for b in vol.bounds)
    nodes = np.asarray(warp.grid.nodes).reshape(-1, 3)
    lo, hi = np.minimum(lo, nodes.min(0)), np.maximum(hi, nodes.max(0))
    size = s.render_size
    cam = _framing_camera(lo, hi, FISH_VIEW, size)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the mesh scene's empty volume's TF
        torus = torus_tubes()
    renders: list[tuple[str, np.ndarray]] = []
    with _offscreen(size) as r:
        gl = _gl_renderer(r)
        plain = _fish_scene(vol, cam)
        bent = _fish_scene(vol, cam, [warp])
        renders.append(("(a) fish, undeformed", _rgb(r, plain, size)))
        renders.append(("(b) fish bent by a 12x4x2-cell lattice", _rgb(r, bent, size)))
        renders.append(("(c) tubes wrapped round a torus (paper Fig. 1)", _rgb(r, torus, size)))
        normal_scenes = _normal_scenes(size)
        normal_renders = [(title, _rgb(r, sc, size)) for title, sc in normal_scenes]
    # the frame rates against 4x4 matrices and the normals' angles are full studies of the
    # lab (a torus of 1.5 M triangles, thousands of composed objects): not run here
    numbers: dict[str, Any] = {
        "paper_fps_ratio": lattice_ratio_range(),
        "lab_command": LATTICE_LAB_COMMAND,
        "gl_renderer": gl,
    }
    fig = _figure(16.0, 10.0, DEMO_TITLES["lattice"])
    grid = fig.add_gridspec(2, 1)
    middle = grid[0].subgridspec(1, 3)
    for i, (title, img) in enumerate(renders):
        _show_image(fig.add_subplot(middle[0, i]), img, title)
    bottom = grid[1].subgridspec(1, 2)
    for i, (title, img) in enumerate(normal_renders):
        _show_image(fig.add_subplot(bottom[0, i]), img, title)
    path = _save_figure(fig, out / "lattice.png")

    tour = [
        TourStep(
            "A lattice of trilinear cells",
            "A trilinear lattice replaces a 4x4 matrix by a grid of cells; each cell maps"
            " the unit cube by interpolating its 8 corner nodes. Moving nodes bends what the"
            " lattice holds, smoothly and continuously across cells.",
            _snap(plain),
            "a",
        ),
        TourStep(
            "Bending a volume",
            "The same lattice bends a volume at render time: each ray sample is mapped back"
            " through the lattice (a few Newton steps per sample) to read the original voxels.",
            _snap(bent),
            "b",
        ),
        TourStep(
            "Composition in a scene graph",
            "Lattices compose like matrices: a mesh under nested nodes gets one composed"
            " lattice, so a flat slab of tubes becomes a torus (the paper's Figure 1).",
            bundled_dir() / "lattice_torus_tubes.json",
            "c",
        ),
        TourStep(
            "Attachments follow an animated mesh",
            "Anchors sit on a base mesh's triangles; every frame they are evaluated on the"
            " moved mesh and rebuild the lattices of the bands and the plate attached to it,"
            " so they follow the swaying body (the paper's Figure 8); Render Movie renders it.",
            bundled_dir() / "lattice_accessories_anim.json",
            None,
        ),
        TourStep(
            "What it costs",
            "Frames per second with lattices relative to plain 4x4 matrices (the paper's"
            " table: 76.4-80.6 %), and animating many objects, where every composed lattice is"
            f" recomputed on the CPU each frame: measured by `{LATTICE_LAB_COMMAND}` in a"
            " checkout of voxwarp (docs/benchmarks.md).",
            None,
            None,
        ),
        TourStep(
            "Normals across cells",
            "GRAPP 2010 (section 4.2, Figure 5) carries normals two ways. Panel d transforms"
            " the normal itself (J n): the shading flows smoothly over cell borders but is"
            " not exactly perpendicular to the surface. Panel e transforms two tangents and"
            " crosses them: exactly perpendicular, but the shading jumps at every border of"
            " these 30-degree cells. The tangent way is voxwarp's default.",
            _snap(normal_scenes[1][1]),
            "e",
        ),
    ]
    return [path], numbers, tour


#: the lab's command that measures the lattice's costs (frame rates against 4x4 matrices,
#: composition, normals' angles): a checkout's ``benchmarks/``, not installed
LATTICE_LAB_COMMAND = "python -m benchmarks lattice"


#: The lattice demo's normal panels: cells of the coarse torus lattice (30 degrees per cell
#: around the major circle) and the view of the close-up.
NORMALS_CELLS = (12, 2, 1)
NORMALS_VIEW = (60.0, 30.0)


def _normal_scenes(size: tuple[int, int]) -> list[tuple[str, Any]]:
    """The torus of tubes on a coarse lattice, close up, with each normal method
    (GRAPP 2010, Figure 5): (title, scene) for the direct and the tangent-space normals."""
    from voxwarp.teaching.lattice_scenes import torus_tubes

    out = []
    for method, title in (
        ("normal", "(d) direct normals J n (Fig. 5 left): smooth"),
        ("tangent", "(e) tangent-space normals (Fig. 5 right): seams"),
    ):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # the mesh scene's empty volume's TF
            scene = torus_tubes()
        for inst in scene.meshes:
            inst.transform = inst.transform.resample(NORMALS_CELLS)
            inst.normal_method = method
        w = np.concatenate([inst.world_vertices() for inst in scene.meshes])
        lo, hi = w.min(axis=0), w.max(axis=0)
        quarter = np.r_[0.1 * hi[:2], lo[2]], hi  # the quadrant facing the camera
        scene.camera = _framing_camera(*quarter, NORMALS_VIEW, size)
        out.append((title, scene))
    return out
