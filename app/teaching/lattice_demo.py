"""``voxwarp demo lattice`` (GRAPP 2010, Figures 1 and 5, section 6).

Renders of a bent volume, of the lattice-wrapped torus of the paper's Figure 1 and of both
normal methods (``lattice.png``); the frame rates of the paper's own scenes, linear
against trilinear (its section 6 table; :mod:`voxwarp.teaching.grapp_measure`), with
their frames on a second sheet (``lattice_grapp.png``). The fuller study against 4x4
matrices is the lab's, ``python -m benchmarks lattice`` in a checkout. Run by
:func:`voxwarp.teaching.demos.run_demo`; the helpers it shares with the other demos are in
:mod:`voxwarp.teaching.sheets`.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.core.json_input import read_json
from voxwarp.io.samples import bundled_dir
from voxwarp.teaching import DEMO_TITLES, grapp_measure, sheets
from voxwarp.teaching.grapp_scenes import VARIANTS, paper_scenes
from voxwarp.teaching.lattice_scenes import torus_tubes
from voxwarp.teaching.papers import lattice_ratio_range


# ====================================================================== lattice
def demo_lattice(
    s: sheets.DemoSettings, out: Path, log: Callable[[str], None]
) -> tuple[list[Path], dict[str, Any], list[sheets.TourStep]]:
    from voxwarp.deform.lattice.warp import LatticeWarp

    vol = sheets.fish_volume(s)
    spec = read_json(bundled_dir() / "fish_lattice_bend.json")
    entry = {k: v for k, v in spec.items() if k not in ("description", "sample", "type")}
    entry.setdefault("box", [list(map(float, b)) for b in vol.bounds])
    warp = LatticeWarp.from_dict(entry)
    lo, hi = (np.asarray(b, dtype=np.float64).copy() for b in vol.bounds)
    nodes = np.asarray(warp.grid.nodes).reshape(-1, 3)
    lo, hi = np.minimum(lo, nodes.min(0)), np.maximum(hi, nodes.max(0))
    size = s.render_size
    cam = sheets.framing_camera(lo, hi, sheets.FISH_VIEW, size)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the mesh scene's empty volume's TF
        torus = torus_tubes()
    renders: list[tuple[str, np.ndarray]] = []
    with sheets.offscreen_renderer(size) as r:
        gl = sheets.gl_renderer(r)
        plain = sheets.fish_scene(vol, cam)
        bent = sheets.fish_scene(vol, cam, [warp])
        renders.append(("(a) fish, undeformed", sheets.render_rgb(r, plain, size)))
        renders.append(("(b) fish bent by a 12x4x2-cell lattice", sheets.render_rgb(r, bent, size)))
        renders.append(
            ("(c) tubes wrapped round a torus (paper Fig. 1)", sheets.render_rgb(r, torus, size))
        )
        normal_scenes = _normal_scenes(size)
        normal_renders = [(title, sheets.render_rgb(r, sc, size)) for title, sc in normal_scenes]
        # the paper's own scenes (section 6 table), linear and trilinear frames alternated
        grapp_rows, grapp_shots = _grapp_frames(s, r, log)
    # the vertex stage alone, the static redraw and the normals' angles are full studies
    # of the lab: not run here
    numbers: dict[str, Any] = {
        "paper_fps_ratio": lattice_ratio_range(),
        "lab_command": LATTICE_LAB_COMMAND,
        "gl_renderer": gl,
        "grapp_scenes": grapp_rows,
        "extra_figures": [{"file": GRAPP_SHEET, "title": GRAPP_SHEET_TITLE}],
    }
    fig = sheets.new_figure(16.0, 10.0, DEMO_TITLES["lattice"])
    grid = fig.add_gridspec(2, 1)
    middle = grid[0].subgridspec(1, 3)
    for i, (title, img) in enumerate(renders):
        sheets.show_image(fig.add_subplot(middle[0, i]), img, title)
    bottom = grid[1].subgridspec(1, 2)
    for i, (title, img) in enumerate(normal_renders):
        sheets.show_image(fig.add_subplot(bottom[0, i]), img, title)
    path = sheets.save_figure(fig, out / "lattice.png")
    grapp_path = _grapp_sheet(grapp_rows, grapp_shots, out / GRAPP_SHEET, s.quick)

    tour = [
        sheets.TourStep(
            "A lattice of trilinear cells",
            "A trilinear lattice replaces a 4x4 matrix by a grid of cells; each cell maps"
            " the unit cube by interpolating its 8 corner nodes. Moving nodes bends what the"
            " lattice holds, smoothly and continuously across cells.",
            sheets.snap(plain),
            "a",
        ),
        sheets.TourStep(
            "Bending a volume",
            "The same lattice bends a volume at render time: each ray sample is mapped back"
            " through the lattice (a few Newton steps per sample) to read the original voxels.",
            sheets.snap(bent),
            "b",
        ),
        sheets.TourStep(
            "Composition in a scene graph",
            "Lattices compose like matrices: a mesh under nested nodes gets one composed"
            " lattice, so a flat slab of tubes becomes a torus (the paper's Figure 1).",
            bundled_dir() / "lattice_torus_tubes.json",
            "c",
        ),
        sheets.TourStep(
            "Attachments follow an animated mesh",
            "Anchors sit on a base mesh's triangles; every frame they are evaluated on the"
            " moved mesh and rebuild the lattices of the bands and the plate attached to it,"
            " so they follow the swaying body (the paper's Figure 8); Render Movie renders it.",
            bundled_dir() / "lattice_accessories_anim.json",
            None,
        ),
        sheets.TourStep(
            "What it costs",
            "Frames per second with lattices relative to plain 4x4 matrices (the paper's"
            " table: 76.4-80.6 %) on the paper's own scenes: 1.5 M triangles of spheres"
            " anchored to a bent body, and helices of thousands of small spheres, where every"
            " composed lattice is recomputed on the CPU each frame. This demo times them"
            " (its second sheet, `voxwarp reproduce`'s table); the fuller study is"
            f" `{LATTICE_LAB_COMMAND}` in a checkout of voxwarp (docs/benchmarks.md).",
            None,
            None,
        ),
        sheets.TourStep(
            "Normals across cells",
            "GRAPP 2010 (section 4.2, Figure 5) carries normals two ways. Panel d transforms"
            " the normal itself (J n): the shading flows smoothly over cell borders but is"
            " not exactly perpendicular to the surface. Panel e transforms two tangents and"
            " crosses them: exactly perpendicular, but the shading jumps at every border of"
            " these 30-degree cells. The tangent way is voxwarp's default.",
            sheets.snap(normal_scenes[1][1]),
            "e",
        ),
    ]
    return [path, grapp_path], numbers, tour


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
        scene.camera = sheets.framing_camera(*quarter, NORMALS_VIEW, size)
        out.append((title, scene))
    return out


#: the sheet of the paper's own scenes (section 6), beside ``lattice.png``
GRAPP_SHEET = "lattice_grapp.png"
GRAPP_SHEET_TITLE = "GRAPP 2010 section 6: the paper's scenes, trilinear (top) and linear (bottom)"


def _grapp_frames(
    s: sheets.DemoSettings, r: Any, log: Callable[[str], None]
) -> tuple[list[dict[str, Any]], list[tuple[str, dict[str, np.ndarray]]]]:
    """The paper's three scenes timed on ``r``'s context (:mod:`voxwarp.teaching.
    grapp_measure`; ``--quick``: its quick size and frame count)."""
    if s.quick:
        size, frames = grapp_measure.QUICK_SIZE, grapp_measure.QUICK_FRAMES
    else:
        size, frames = grapp_measure.FULL_SIZE, grapp_measure.FULL_FRAMES
    return grapp_measure.measure_scenes(paper_scenes().values(), r.ctx, size, frames, log)


def _grapp_sheet(
    rows: list[dict[str, Any]],
    shots: list[tuple[str, dict[str, np.ndarray]]],
    path: Path,
    quick: bool,
) -> Path:
    """The warm-up frame of each scene, trilinear over linear, titled with its counts
    (and its frame rate, except in a quick run)."""
    fig = sheets.new_figure(15.0, 8.0, GRAPP_SHEET_TITLE)
    axes = fig.subplots(len(VARIANTS), len(shots), squeeze=False)
    for col, (row, (name, images)) in enumerate(zip(rows, shots, strict=True)):
        for k, v in enumerate(VARIANTS):
            title = f"{name}: {row['objects']:,} objects, {row['triangles']:,} triangles, {v}"
            if not quick:
                title += f" {row[f'{v}_fps']:.2f} FPS"
            sheets.show_image(axes[k, col], images[v], title)
    return sheets.save_figure(fig, path)
