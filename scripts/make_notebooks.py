"""Write the teaching notebooks in notebooks/ (one per deformation model, plus viewing a
registration) from the cells below, without outputs.

Usage: ``python scripts/make_notebooks.py`` (then review ``git diff notebooks/``). The
notebooks are small enough to execute headless in CI (tests/notebook/test_notebooks.py):
reduced volumes, images of about 200 pixels. ``--pictures DIR`` also executes them
(nbclient, kernel ``python3``) and writes every picture they show to
``DIR/NAME_CELL_OUTPUT.png`` (docs/notebooks.md shows two of them, copied to
docs/images/notebooks/).
"""

from __future__ import annotations

import argparse
import base64
import sys
from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "notebooks"

SETUP = """\
import numpy as np

from voxwarp import OffscreenRenderer, Scene, load_sample

# in Jupyter, a Scene at the end of a cell shows a picture of itself (import voxwarp does it)
from voxwarp.notebook import Viewer, side_by_side"""

FISH = """\
# the bundled fish phantom (CT values in HU), generated at a small size for speed
vol = load_sample("fish", shape=(96, 48, 40))
scene = Scene(vol, view="+z", transfer_function="ct-soft", zoom=1.5, jitter=False)
scene"""

VIEWER_HELP = """\
## Try it yourself

The viewer below is live when the notebook runs in Jupyter (it needs a kernel; a static
copy of the notebook shows its first picture only). **Drag a handle** (a dot) with the
left button to move it, **drag elsewhere** to orbit, drag with the right button (or
Shift + left) to pan, turn the **wheel** to zoom. Keys: arrows orbit, `+`/`-` zoom,
`r` refits the view, space pauses the simulation, Ctrl+Z / Ctrl+Shift+Z undo and redo.
Red dots are fixed elements; the selected handle is yellow."""


def _nb(cells: list) -> nbformat.NotebookNode:
    nb = new_notebook(cells=cells)
    nb.metadata["kernelspec"] = {
        "name": "python3",
        "display_name": "Python 3",
        "language": "python",
    }
    nb.metadata["language_info"] = {"name": "python"}
    return nb


def mass_spring() -> nbformat.NotebookNode:
    return _nb(
        [
            new_markdown_cell(
                """\
# Mass-spring deformation of a volume

*Model: T. Knoche, GPU-based Volume Deformation using Mass-Spring-Systems, diploma thesis,
Universität Siegen, 2008.*

A coarse grid of **elements** is laid over the volume. Each element is a point mass; springs
join it to its neighbours along the axes (they resist stretching) and across the cell
diagonals (they resist shearing). Dragging an element holds it at a new place; every time
step adds up the spring forces on the free elements, damps them and moves them (Newton's
second law, integrated semi-implicitly), until the grid comes to rest.

The grid's displacement `u` becomes a small 3D texture. The volume itself is never
resampled: for every sample along a viewing ray, the renderer looks up the point of the
*original* volume that moved there, solving `X = p - u(X)` by a few fixed-point steps
(the thesis takes the first step only)."""
            ),
            new_code_cell(SETUP),
            new_markdown_cell("The volume and a scene that draws it (a `Scene` shows itself):"),
            new_code_cell(FISH),
            new_markdown_cell(
                """\
An 8 x 8 x 8 element grid over the fish's box. Its eight corners are fixed; we also fix
the elements over the head (x below 20 mm) and hold a block of eight elements near the
tail 14 mm along +y, then let the springs settle."""
            ),
            new_code_cell(
                """\
from voxwarp.deform import ElementGrid, MassSpring

grid = ElementGrid(vol, shape=(8, 8, 8))
ms = MassSpring(grid, integrator="semi-implicit")
ms.fix(grid.rest_positions[..., 0] < 20.0)  # the head stays put
tail = [(6, j, k) for j in (3, 4) for k in (2, 3, 4, 5)]  # elements (i, j, k)
ms.move(tail, [(0.0, 14.0, 0.0)] * len(tail))  # held 14 mm along +y
steps = ms.settle(max_steps=1500)
moved = np.linalg.norm(ms.positions() - grid.rest_positions, axis=-1)
print(f"{steps} steps; elements moved up to {moved.max():.1f} mm, {np.sum(moved > 1)} over 1 mm")"""
            ),
            new_markdown_cell(
                "Before and after: the same camera, the warp appended to the scene's chain."
            ),
            new_code_cell(
                """\
bent = scene.copy(warps=[ms.warp()])
with OffscreenRenderer(224, 128) as r:
    before, after = r.render(scene), r.render(bent)
side_by_side([before, after])"""
            ),
            new_markdown_cell(VIEWER_HELP),
            new_code_cell(
                """\
viewer = Viewer(scene, "massspring", resolution=6, size=(384, 256))
viewer"""
            ),
            new_markdown_cell(
                """\
The viewer is scriptable too: the same actions as with the mouse, from code. Here a
column of elements over the tail is selected (with the mouse: Shift+click each), the top
one is dragged 30 pixels up the screen (the whole selection follows it), the model runs 40
frames, and `snapshot()` returns the picture (an array that shows itself). The springs'
lines are switched off to see the fish better."""
            ),
            new_code_cell(
                """\
g = viewer.session.model.grid
column = [int(np.ravel_multi_index((4, 2, k), g.shape)) for k in range(g.shape[2])]
viewer.session.select(column)  # the last one (the top) is the reference
x, y = viewer.handle_pixels()[column[-1]]
viewer.drag((x, y), (x, y - 30))
viewer.step(40)
viewer.display_options.links = False
viewer.snapshot()"""
            ),
        ]
    )


def chainmail() -> nbformat.NotebookNode:
    return _nb(
        [
            new_markdown_cell(
                """\
# 3D ChainMail: deformation by slack links

*Model: S. F. Gibson, 3D ChainMail (1997), as implemented and extended on the GPU in
T. Knoche, GPU-based Volume Deformation using Mass-Spring-Systems, diploma thesis,
Universität Siegen, 2008.*

The same element grid as the mass-spring model, but no forces and no time steps. Each
link between neighbours has **slack**: it may stretch, compress and shear within limits.
When an element is dragged, a neighbour moves only if its link now breaks a limit, and
then only as far as needed to satisfy it; the disturbance spreads outwards element by
element and stops where the slack absorbs it. One drag is settled at once.

The result is piecewise linear: straight, sheared blocks with sharp kinks where the
moved part meets the still part. A few steps of **relaxation** (constrained smoothing
towards the average of the neighbours) round the kinks."""
            ),
            new_code_cell(SETUP),
            new_code_cell(FISH),
            new_markdown_cell(
                """\
Hold a block of eight elements near the tail 14 mm along +y, once without relaxation and
once with four relaxation steps after the drag. `stats.touched` counts the elements the drag
moved."""
            ),
            new_code_cell(
                """\
from voxwarp.deform import ChainMail, ElementGrid


def poke(relax_steps):
    grid = ElementGrid(vol, shape=(8, 8, 8))
    cm = ChainMail(grid, relax_steps=relax_steps)
    cm.fix(grid.rest_positions[..., 0] < 20.0)  # the head stays put
    tail = [(6, j, k) for j in (3, 4) for k in (2, 3, 4, 5)]
    stats = cm.move(tail, [(0.0, 14.0, 0.0)] * len(tail))
    return cm, stats


sharp, stats = poke(0)
smooth, _ = poke(4)
print(f"one drag moved {stats.touched} elements")"""
            ),
            new_markdown_cell("Rest state, no relaxation (kinks), four relaxation steps:"),
            new_code_cell(
                """\
with OffscreenRenderer(224, 128) as r:
    images = [r.render(scene.copy(warps=w)) for w in ([], [sharp.warp()], [smooth.warp()])]
side_by_side(images)"""
            ),
            new_markdown_cell(VIEWER_HELP),
            new_code_cell(
                """\
viewer = Viewer(scene, "chainmail", resolution=6, size=(384, 256))
viewer"""
            ),
            new_markdown_cell(
                "From code: select a column of elements and drag it 30 pixels down the screen."
            ),
            new_code_cell(
                """\
g = viewer.session.model.grid
column = [int(np.ravel_multi_index((4, 3, k), g.shape)) for k in range(g.shape[2])]
viewer.session.select(column)
x, y = viewer.handle_pixels()[column[-1]]
viewer.drag((x, y), (x, y + 30))
viewer.display_options.links = False
viewer.snapshot()"""
            ),
        ]
    )


def wires() -> nbformat.NotebookNode:
    return _nb(
        [
            new_markdown_cell(
                """\
# Wires: bending a volume along a curve

*Model: S. J. Walton and M. W. Jones, Volume Wires: A Framework for Empirical Non-linear
Deformation of Volumetric Datasets, Journal of WSCG 14 (2006).*

A **wire** is a curve laid through an object (the *base* wire) and a changed copy of it
(the *modified* wire), optionally twisted and scaled along its length. Every voxel near
the modified wire learns which wire it belongs to and where along it lies (a parameter
`t`); this *attribute field* is computed once per edit with a distance transform (OpenCL,
or scipy without it). While rendering, a sample at `p` near the modified wire at `t` is
carried into the base wire's frame at the same `t` (rotation-minimising frames, twist
and scale included), and the volume is read there. The object's old place is marked
*vacated*, so the bent object leaves no copy behind."""
            ),
            new_code_cell(SETUP),
            new_code_cell(FISH),
            new_markdown_cell(
                """\
A wire along the fish's spine (world mm; the fish phantom has the same size whatever its
voxel count). The modified wire swings the back half sideways by up to 12 mm, and the
tail turns by 90 degrees about the wire."""
            ),
            new_code_cell(
                """\
from voxwarp.deform import Wire, WireDeformer

x = np.linspace(10.0, 92.0, 9)
base = np.c_[x, np.full_like(x, 23.75), np.full_like(x, 20.0)]
modified = base.copy()
modified[:, 1] += 12.0 * np.clip((x - 40.0) / 52.0, 0.0, 1.0) ** 2  # bend sideways
wire = Wire(
    base=base,
    modified=modified,
    kind="catmull-rom",
    twist=[(0.0, 0.0), (0.6, 0.0), (1.0, np.pi / 2)],  # (t, radians)
    radius=14.0,  # mm around the wire that it moves
    beta=(-200, 3000),  # the fish's value range (HU): what the sweep carries
    sides="rigid",  # the paper's sweep of the masked fish (its old place is vacated)
)
deformer = WireDeformer(vol, [wire], field_scale=2)
stats = deformer.build()
stats"""
            ),
            new_code_cell(
                """\
bent = scene.copy(warps=[deformer.warp()])
with OffscreenRenderer(224, 128) as r:
    before, after = r.render(scene), r.render(bent)
side_by_side([before, after])"""
            ),
            new_markdown_cell(
                VIEWER_HELP
                + """

With the wires model, the handles are the modified wire's control points (green); the
grey curve is the base wire. The field is rebuilt when you let go of a point."""
            ),
            new_code_cell(
                """\
viewer = Viewer(scene, "wires", size=(384, 256))
viewer"""
            ),
            new_markdown_cell("From code: pull the wire's last control point 20 pixels down."),
            new_code_cell(
                """\
x, y = viewer.handle_pixels()[-1]
viewer.drag((x, y), (x, y + 20), steps=2)
viewer.snapshot()"""
            ),
        ]
    )


def lattice() -> nbformat.NotebookNode:
    return _nb(
        [
            new_markdown_cell(
                """\
# Trilinear lattices

*Model: M. Knuth, J. Kohlhammer, A. Kuijper, Embedding Hierarchical Deformation within a
Realtime Scene Graph, GRAPP 2010.*

A scene graph places objects with 4x4 matrices: straight lines stay straight. The paper
replaces a matrix by a **trilinear transformation**: a cuboid cell whose eight corners
may go anywhere; a point inside moves by trilinear interpolation of the corners. A grid
of such cells (a lattice) bends an object smoothly, and lattices nest like matrices do.
Meshes move forward through the lattice in the vertex shader; a volume is drawn through
its *inverse* (for each ray sample: which rest point maps here?), found by Newton steps."""
            ),
            new_code_cell(SETUP),
            new_markdown_cell(
                "One cell: the map `T(u)` of the unit cube, its inverse and its Jacobian."
            ),
            new_code_cell(
                """\
from voxwarp.deform import LatticeWarp, TrilinearGrid, TrilinearTransform

corners = np.array(
    [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1], [1.5, 1.5, 1]],
    float,
)  # the unit cube with one corner pulled out
T = TrilinearTransform(corners)
u = np.array([0.5, 0.5, 0.5])
x = T(u)
print("T(centre) =", x, " inverse:", T.inverse(x), " linear:", T.is_linear)"""
            ),
            new_code_cell(FISH),
            new_markdown_cell(
                """\
A lattice of 8 x 2 x 1 cells over the fish's box (`from_function` samples any map of the
unit cube at the nodes): the back 60 % bends sideways, quadratically along the length."""
            ),
            new_code_cell(
                """\
lo, hi = (np.asarray(b) for b in vol.bounds)


def bend(u):
    x = lo + u * (hi - lo)
    x[:, 1] += 14.0 * np.clip((u[:, 0] - 0.4) / 0.6, 0.0, 1.0) ** 2
    return x


grid = TrilinearGrid.from_function(bend, cells=(8, 2, 1))
bent = scene.copy(warps=[LatticeWarp(grid, vol.bounds)])
with OffscreenRenderer(224, 128) as r:
    before, after = r.render(scene), r.render(bent)
side_by_side([before, after])"""
            ),
            new_markdown_cell(
                VIEWER_HELP
                + """

With the lattice model, the handles are the lattice's nodes (orange cell edges)."""
            ),
            new_code_cell(
                """\
viewer = Viewer(scene, "lattice", resolution=4, size=(384, 256))
viewer"""
            ),
            new_markdown_cell(
                """\
From code: select the nodes of the lattice's end face (x at its maximum) and drag them
25 pixels up the screen together; the last column of cells shears and the tail follows."""
            ),
            new_code_cell(
                """\
nodes = viewer.session.handles()  # world mm
end = [int(i) for i in np.flatnonzero(nodes[:, 0] > nodes[:, 0].max() - 1e-6)]
viewer.session.select(end)  # the last one is the reference the drag grabs
x, y = viewer.handle_pixels()[end[-1]]
viewer.drag((x, y), (x, y - 25), steps=2)
viewer.snapshot()"""
            ),
        ]
    )


def registration() -> nbformat.NotebookNode:
    return _nb(
        [
            new_markdown_cell(
                """\
# Viewing a registration without resampling

Registration tools (ITK, SimpleITK, ANTs, 3D Slicer) store a non-linear registration as a
**displacement field** on the fixed image's grid: the fixed point `p` takes its value from
the moving image at `p + u(p)`. The usual way to look at the result is to resample the
moving image through the field into a new volume. voxwarp instead reads the field at
every ray sample, like its own deformations, so the moving image is *seen* registered
while the data stays as scanned.

Here the bundled Colin27 MRI is the fixed image. A known smooth field (a few Gaussian
bumps) plays the registration's answer; the moving image is made from it (SimpleITK,
`pip install 'voxwarp[registration]'`). `voxwarp demo registration` runs a real demons
registration instead; the viewing is the same."""
            ),
            new_code_cell(SETUP),
            new_code_cell(
                """\
from voxwarp.teaching.registration_demo import deform_volume, known_field

fixed = load_sample("colin27")
field = known_field(fixed)  # a DisplacementFieldWarp on the fixed grid
moving = deform_volume(fixed, field)  # resampled once, to make the example
u_max = np.linalg.norm(field.displacements, axis=-1).max()
print(fixed.shape, f"voxels; the field moves points by up to {u_max:.1f} mm")"""
            ),
            new_markdown_cell(
                """\
A tool would hand us the field as a file: write it the way ITK does (NIfTI, LPS vectors)
and read it back as any field from ANTs or Slicer would be read."""
            ),
            new_code_cell(
                """\
import tempfile
from pathlib import Path

from voxwarp import load_transform, save_displacement_field

path = save_displacement_field(field, Path(tempfile.mkdtemp()) / "field.nii.gz")
warps = load_transform(path)
warps"""
            ),
            new_markdown_cell(
                """\
Axial slices: the fixed image, the moving image, and the moving image seen *through* the
field. The last should look like the first; the numbers say how close they are."""
            ),
            new_code_cell(
                """\
window = (80.0, 160.0)  # (level, width) of the MRI
with OffscreenRenderer(160, 192) as r:
    views = {
        "fixed": r.render_slice(Scene(fixed, window=window), "axial"),
        "moving": r.render_slice(Scene(moving, window=window), "axial"),
        "through": r.render_slice(Scene(moving, window=window, warps=warps), "axial"),
    }
for name in ("moving", "through"):
    d = np.nanmean(np.abs(views[name].values - views["fixed"].values))
    print(f"mean |{name} - fixed| on the slice: {d:.2f}")
side_by_side([v.rgba for v in views.values()])"""
            ),
            new_markdown_cell(
                "The same in 3D, and live: the viewer draws the moving image through the field."
            ),
            new_code_cell(
                """\
viewer = Viewer(Scene(moving, warps=warps, transfer_function="mri"), size=(320, 320))
print("warps drawn:", viewer.session.scene.warps)
viewer"""
            ),
        ]
    )


NOTEBOOKS = {
    "mass_spring": mass_spring,
    "chainmail": chainmail,
    "wires": wires,
    "lattice": lattice,
    "registration": registration,
}


def write_pictures(nb: nbformat.NotebookNode, name: str, folder: Path) -> None:
    """Execute ``nb`` (a copy) and write each image/png output it shows to ``folder``."""
    from nbclient import NotebookClient

    nb = nbformat.from_dict(nb)
    NotebookClient(nb, timeout=300, resources={"metadata": {"path": str(OUT)}}).execute()
    folder.mkdir(parents=True, exist_ok=True)
    for i, cell in enumerate(nb.cells):
        for j, out in enumerate(cell.get("outputs", [])):
            png = out.get("data", {}).get("image/png")
            if png:
                path = folder / f"{name}_{i}_{j}.png"
                path.write_bytes(base64.b64decode(png))
                print(f"  {path}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pictures", type=Path, help="also execute them; pictures go here")
    args = parser.parse_args(argv)
    OUT.mkdir(exist_ok=True)
    for name, make in NOTEBOOKS.items():
        nb = make()
        for i, cell in enumerate(nb.cells):
            cell.id = f"{name}-{i}"  # stable ids: regenerating changes nothing
        nbformat.validate(nb)
        path = OUT / f"{name}.ipynb"
        nbformat.write(nb, str(path))
        print(path.relative_to(ROOT))
        if args.pictures is not None:
            write_pictures(nb, name, args.pictures)
    return 0


if __name__ == "__main__":
    sys.exit(main())
