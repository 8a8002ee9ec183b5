"""``python -m benchmarks lattice`` section 5: how well each lattice normal method shades.

GRAPP 2010 (section 4.2, Figure 5) carries vertex normals through a lattice two ways:
the *direct* method transforms the normal with the Jacobian (``J n``; the scene-file value
``"normal"``), the *tangent-space* one transforms two tangents and crosses them
(``"tangent"``). Here both are compared with the exact normals of the smooth shape the
lattice samples (the lattice's nodes lie on an exact map; its normals are the inverse
transpose of that map's Jacobian, taken by central differences), on two tubes:

* *bend*: a tube bent into a quarter circle (lengths along the axis change, the
  cross-section does not: nearly conformal in the normal's plane);
* *torus*: a tube laid in a slab that a lattice wraps round a torus, as
  ``sample_volumes/lattice_torus_tubes.json`` does (the slab stretches by different
  factors along and across the tube).

Per scene, lattice size and method: the mean and max angle to the exact normals over the
vertices, and the seam: the largest angle between the normals of two rings a hair either
side of an inner cell face (the exact normals turn by far less there). The normals are
:meth:`voxwarp.core.mesh.MeshInstance.world_normals`, the CPU reference that the vertex
shader matches (``tests/core/test_mesh_normals.py``). Nothing here is timed.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from voxwarp.core.mesh import NORMAL_METHODS, Mesh, MeshInstance, tube_mesh
from voxwarp.deform.lattice.trilinear import TrilinearGrid

#: rings this far (in units of the tube's length) either side of each inner cell face
SEAM_GAP = 1e-4
#: rings per cell besides the ones by the faces, and vertices per ring
RINGS_PER_CELL, SECTIONS = 8, 32


@dataclass
class NormalsRow:
    """One scene, lattice and normal method."""

    scene: str
    cells: tuple[int, int, int]
    method: str
    mean_deg: float  # angle to the exact normals, mean over the vertices
    max_deg: float
    seam_deg: float  # largest jump across an inner cell face


def _tube(length: float, radius: float, cells: int) -> tuple[Mesh, np.ndarray, np.ndarray]:
    """Open tube along x from 0 to ``length``; its rings by the inner faces (indices
    before, after)."""
    faces_x = length * np.arange(1, cells) / cells
    gap = SEAM_GAP * length
    xs = np.linspace(0.0, length, RINGS_PER_CELL * cells + 1)
    xs = xs[np.all(np.abs(xs[:, None] - faces_x[None, :]) > 2 * gap, axis=1)]
    xs = np.unique(np.r_[xs, faces_x - gap, faces_x + gap])
    mesh = tube_mesh(length, radius, sections=SECTIONS, ring_x=xs, phase=0.25)
    ring = np.searchsorted(xs, faces_x - gap), np.searchsorted(xs, faces_x + gap)
    before = (ring[0][:, None] * SECTIONS + np.arange(SECTIONS)).ravel()
    after = (ring[1][:, None] * SECTIONS + np.arange(SECTIONS)).ravel()
    return mesh, before, after


def _bend(length: float, radius: float) -> Callable[[np.ndarray], np.ndarray]:
    """Local (x, y, z) -> the tube (of ``radius``, unused: the map is the same for any)
    bent about the line x = 0, z = R into a quarter circle."""
    arc = length / (np.pi / 2)

    def f(p: np.ndarray) -> np.ndarray:
        t = p[:, 0] / arc
        r = arc - p[:, 2]
        return np.stack([r * np.sin(t), p[:, 1], arc - r * np.cos(t)], -1)

    return f


def _torus(length: float, radius: float) -> Callable[[np.ndarray], np.ndarray]:
    """Local (x, y, z) of a tube along x in a slab of 12 such tubes -> the slab wrapped
    round a torus (major radius 40, minor 9, the slab's thickness outwards), as
    :func:`voxwarp.teaching.lattice_scenes.torus_tubes` lays out its first tube."""
    height = 12 * 2 * radius

    def f(p: np.ndarray) -> np.ndarray:
        theta = 2 * np.pi * p[:, 0] / length
        phi = 2 * np.pi * (p[:, 1] + radius) / height
        rho = 9.0 + p[:, 2] + radius
        ring = 40.0 + rho * np.cos(phi)
        return np.stack([ring * np.cos(theta), ring * np.sin(theta), rho * np.sin(phi)], -1)

    return f


def _exact_normals(
    f: Callable[[np.ndarray], np.ndarray], p: np.ndarray, n: np.ndarray
) -> np.ndarray:
    h = 1e-5 * float(np.ptp(p, axis=0).max())
    cols = [(f(p + h * e) - f(p - h * e)) / (2 * h) for e in np.eye(3)]
    jac = np.stack(cols, -1)
    out = np.einsum("nji,nj->ni", np.linalg.inv(jac), n)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def _angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=1), -1.0, 1.0)))


#: (scene, tube length, radius, map maker, lattice cells along the tube, across it)
SCENES = (
    ("bend", 2.0, 0.25, _bend, (4, 16), 1),
    ("torus", 100.0, 2.0, _torus, (12, 48), 2),
)


def normals_study() -> list[NormalsRow]:
    """The rows of section 5 (see the module docstring)."""
    rows = []
    for scene, length, radius, make, along, across in SCENES:
        f = make(length, radius)
        lo = np.array([0.0, -radius, -radius])
        hi = np.array([length, radius, radius])
        for c in along:
            cells = (c, across, 1)
            mesh, before, after = _tube(length, radius, c)
            grid = TrilinearGrid.from_function(
                lambda u, f=f, lo=lo, hi=hi: f(lo + u * (hi - lo)), cells
            )
            p = mesh.vertices.astype(np.float64)
            exact = _exact_normals(f, p, mesh.normals.astype(np.float64))
            for method in NORMAL_METHODS:
                inst = MeshInstance(mesh, grid, box=(lo, hi), normal_method=method)
                got = inst.world_normals()
                err = _angles(got, exact)
                rows.append(
                    NormalsRow(
                        scene=scene,
                        cells=cells,
                        method=method,
                        mean_deg=float(err.mean()),
                        max_deg=float(err.max()),
                        seam_deg=float(_angles(got[before], got[after]).max()),
                    )
                )
    return rows


def markdown_lines(rows: list[NormalsRow]) -> list[str]:
    """Section 5 of the report."""
    lines = ["## 5. Lattice normals: direct (J n) vs tangent space, against the smooth shape", ""]
    if not rows:
        return [*lines, "Not run.", ""]
    lines += [
        "GRAPP 2010 section 4.2 / Figure 5. A tube crossing the cells of a lattice whose"
        " nodes lie on an exact map: *bend* bends a tube of length 2 into a quarter circle"
        " (the cross-section keeps its shape), *torus* wraps a tube of a 12-tube slab round"
        " a torus (major radius 40, minor 9; the slab stretches more along the tube than"
        " across it), as `lattice_torus_tubes.json`. Error: angle between"
        " `MeshInstance.world_normals` (what the vertex shader computes) and the exact"
        " map's normals, mean and max over the vertices; seam: the largest angle between"
        f" the normals of two rings {SEAM_GAP:g} tube lengths either side of an inner cell"
        " face. normal = direct `J n`; tangent = two tangents through J, crossed.",
        "",
        "| scene | cells | normals | mean error (deg) | max error (deg) | seam (deg) |",
        "|---|---|---|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r.scene} | {'x'.join(map(str, r.cells))} | {r.method} | {r.mean_deg:.2f} |"
            f" {r.max_deg:.2f} | {r.seam_deg:.2f} |"
        )
    return [*lines, ""]


__all__ = ["NormalsRow", "markdown_lines", "normals_study"]
