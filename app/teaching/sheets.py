"""What the teaching demos share: run sizes, the fish and slice-grid set-ups, renders,
figure sheets and tours.

Every demo of :mod:`voxwarp.teaching.demos` (one module each: ``massspring_demo``,
``chainmail_demo``, ``compare_demo``, ``wires_demo``, ``lattice_demo``,
``registration_demo``) builds its sheet from these: :class:`DemoSettings` (:data:`FULL` or
:data:`QUICK`), the fish drag (:data:`FISH_GRID`, :func:`fish_grid`, :func:`fish_scene`,
...), the 2D slice grid of ``chainmail`` and ``compare`` (:data:`SLICE_SHAPE`,
:func:`slice_grid`, :func:`plot_slice_state`), an offscreen renderer
(:func:`offscreen_renderer`, :func:`render_rgb`), the matplotlib sheet (Agg canvas, no
pyplot: :func:`new_figure`, :func:`show_image`, :func:`add_note`, :func:`save_figure`) and
the tour (:class:`TourStep`, :func:`write_tour`).

matplotlib and Pillow load when a sheet is drawn, and the deformation models (which load
scipy) when a demo builds one, not on import: the demo modules import them inside their
functions too, so that the registry (:mod:`voxwarp.teaching.demos`) imports every demo
cheaply.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import textwrap
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.core.camera import Camera
from voxwarp.core.files import atomic_write, atomic_write_text
from voxwarp.io.samples import load_sample
from voxwarp.render import offscreen
from voxwarp.scene import Scene
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


@dataclass(frozen=True)
class DemoSettings:
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


FULL = DemoSettings(
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
QUICK = DemoSettings(
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


def snap(scene: Any) -> dict[str, Any]:
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


def jsonable(x: Any) -> Any:
    """``x`` with numpy scalars and arrays as Python numbers and lists, tuples as lists,
    non-finite floats as None and dict keys as they are (str or int)."""
    if isinstance(x, dict):
        return {k: jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
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
def offscreen_renderer(size: tuple[int, int]) -> Iterator[Any]:
    """An :class:`~voxwarp.render.offscreen.OffscreenRenderer` of ``size`` whose context is
    current for the block (the GPU solvers and benchmarks run on it too)."""
    with offscreen.OffscreenRenderer(*size) as r, r.current():
        yield r


def gl_renderer(r: Any) -> str:
    """The GL renderer string of ``r``'s context (the sheets name the GPU they timed)."""
    return str(r.ctx.info.get("GL_RENDERER", "?"))


def render_rgb(r: Any, scene: Any, size: tuple[int, int]) -> np.ndarray:
    """``scene`` rendered at ``size`` as (H, W, 3) uint8."""
    if tuple(r.size) != tuple(size):
        r.resize(*size)
    return r.render(scene)[..., :3].copy()


def framing_camera(
    lo: np.ndarray,
    hi: np.ndarray,
    view: Any,
    size: tuple[int, int],
    fill: float = 0.95,
    fov: float = 30.0,
) -> Any:
    """A perspective camera from ``view`` that the box [lo, hi] fills (``fill`` of the
    image's width or height, whichever is reached first)."""
    return Camera.framing(lo, hi, view, size, fill=fill, fov=fov)


def fish_volume(settings: DemoSettings) -> Any:
    """The sample fish at the run's size (``settings.fish_shape``)."""
    return load_sample("fish", shape=settings.fish_shape)


def fish_camera(vol: Any, size: tuple[int, int]) -> Any:
    """The top view of the fish and where the drag moves its tail."""
    lo, hi = (np.asarray(b, dtype=np.float64).copy() for b in vol.bounds)
    lo[1] -= 2.0
    hi[1] += FISH_DRAG_MM[1] + 2.0
    return framing_camera(lo, hi, FISH_VIEW, size)


def fish_scene(vol: Any, camera: Any, warps: Sequence[Any] = ()) -> Any:
    """The fish (``vol``) seen by ``camera`` through ``warps``, its transfer function
    :data:`FISH_TF`, no jitter."""
    return Scene(vol, transfer_function=FISH_TF, camera=camera, warps=list(warps), jitter=False)


def fish_grid(vol: Any) -> Any:
    """The fish's element grid: the head layers fixed, the other corners free."""
    from voxwarp.deform.elements.grid import ElementGrid

    grid = ElementGrid(vol, shape=FISH_GRID, anchor="corners")
    grid.free(grid.corner_mask())
    head = np.zeros(FISH_GRID, dtype=bool)
    head[:HEAD_LAYERS] = True
    grid.fix(head)
    return grid


def slice_grid() -> Any:
    """The teaching grid (:data:`SLICE_SHAPE`): the x = 0 layer fixed, no other corner."""
    from voxwarp.deform.elements.grid import ElementGrid

    grid = ElementGrid(SLICE_BOX, shape=SLICE_SHAPE, anchor="corners")
    grid.free(grid.corner_mask())
    left = np.zeros(SLICE_SHAPE, dtype=bool)
    left[0] = True
    grid.fix(left)
    return grid


def new_figure(width: float, height: float, title: str) -> Any:
    """An empty sheet (matplotlib ``Figure``, constrained layout, :data:`DPI`) of
    ``width`` x ``height`` inches with ``title`` on top."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=DPI, layout="constrained")
    fig.suptitle(title, fontsize=14, fontweight="bold")
    return fig


def save_figure(fig: Any, path: Path) -> Path:
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


def show_image(ax: Any, img: np.ndarray, title: str) -> None:
    """``img`` in panel ``ax`` under ``title``, without ticks or frame."""
    ax.imshow(img, interpolation="lanczos")
    ax.set_title(title, fontsize=10)
    ax.set_xticks([])
    ax.set_yticks([])
    for s in ax.spines.values():
        s.set_visible(False)


def add_note(ax: Any, text: str, where: str = "lower left", width: int = 60) -> None:
    """A small boxed note inside a panel (``where``: "lower left", "upper left", "lower
    right" or "upper right"), wrapped at ``width`` characters; it does not take part in
    the layout."""
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


def slice_xy(positions: np.ndarray) -> np.ndarray:
    """(nx, ny, 2) x, y of the middle z layer."""
    return positions[:, :, SLICE_DRAGGED[2], :2]


def slice_frame(ax: Any) -> None:
    """Limits, aspect and labels of a panel that shows the slice grid."""
    lo, hi = SLICE_BOX
    ax.set_xlim(lo[0] - 8, hi[0] + 8)
    ax.set_ylim(lo[1] - 8, hi[1] + 8 + SLICE_DRAG_MM[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.tick_params(labelsize=8)


def plot_slice_state(ax: Any, positions: np.ndarray, title: str, colorbar: bool = True) -> None:
    """The slice grid's middle z layer at ``positions`` in panel ``ax``, elements coloured by
    their displacement (with a colour bar when ``colorbar``)."""
    from voxwarp.deform.elements.grid import ElementGrid

    rest = ElementGrid(SLICE_BOX, shape=SLICE_SHAPE, anchor="corners").rest_positions
    xy = slice_xy(positions)
    u = np.linalg.norm(slice_xy(positions - rest), axis=-1)
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
    slice_frame(ax)
    ax.set_title(title, fontsize=10)
    if colorbar:
        cb = ax.figure.colorbar(sc, ax=ax, shrink=0.8, pad=0.02)
        cb.set_label("|displacement| (mm)", fontsize=8)
        cb.ax.tick_params(labelsize=7)
