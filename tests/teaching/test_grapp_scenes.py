"""GRAPP 2010's own test scenes (app/teaching/grapp_scenes.py) and their frame rates
(app/teaching/grapp_measure.py) in ``voxwarp reproduce``'s lattice section.

Oracles: the paper's object and triangle counts, exactly; the sphere mix's arithmetic;
the chains' spheres sit where their anchors' lattice puts them in both variants; the
helix's rope is continuous across its segments' lattices and winds round the centre
line; the report puts each measured row beside the paper's.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
import pytest

from voxwarp.errors import MeshError
from voxwarp.teaching import grapp_scenes as gs
from voxwarp.teaching.grapp_measure import measure_scene, measure_scenes
from voxwarp.teaching.papers import LATTICE_FPS
from voxwarp.teaching.reproduce import QUICK_SKIP, _lattice_section


def _centres(scene: gs.GrappScene, variant: str) -> np.ndarray:
    """World position of every object's local origin (a sphere's centre), through its
    composed transform."""
    return np.array([inst.local_to_world(np.zeros((1, 3)))[0] for inst in scene.instances(variant)])


def test_triangle_counts_read_as_printed() -> None:
    assert [r.triangle_count for r in LATTICE_FPS] == [1_500_000, 164_000, 656_000]


@pytest.mark.parametrize(
    ("triangles", "count"),
    [(164_000, 4617), (656_000, 2566), (1_483_776, 184), (1000, 7), (96, 2)],
)
def test_sphere_mix_meets_the_total_exactly(triangles: int, count: int) -> None:
    mix = gs.sphere_mix(triangles, count)
    assert sum(n for _, _, n in mix) == count
    assert sum(2 * (rows - 1) * cols * n for rows, cols, n in mix) == triangles
    assert len({rows for rows, _, _ in mix}) == 1  # one latitude count, cols c and c + 1
    if count > 100:  # the paper's scenes: round spheres, cols about twice rows
        for rows, cols, _ in mix:
            assert 0.4 < cols / (2 * (rows - 1)) < 2.5, (rows, cols)


@pytest.mark.parametrize(("triangles", "count"), [(1001, 7), (40, 7), (100, 0)])
def test_sphere_mix_refuses_totals_it_cannot_meet(triangles: int, count: int) -> None:
    with pytest.raises(MeshError, match="spheres"):
        gs.sphere_mix(triangles, count)


@pytest.mark.slow
def test_paper_scenes_have_the_papers_object_and_triangle_counts() -> None:
    builders = gs.paper_scenes()
    assert list(builders) == ["spheres", "helix_4617", "helix_2566"]
    for (name, build), row in zip(builders.items(), LATTICE_FPS, strict=True):
        scene = build()
        assert scene.row == row
        assert (scene.objects, scene.triangles) == (row.objects, row.triangle_count), name
        # the linear graph holds the very same meshes in the same order
        tri, lin = scene.leaves("trilinear"), scene.leaves("linear")
        assert [n.geometry for n in tri] == [n.geometry for n in lin]
        kinds = {v: [i.is_lattice for i in scene.instances(v)] for v in gs.VARIANTS}
        assert not any(kinds["linear"])
        # every sphere is under a lattice; the spheres scene's body is vertex-animated
        assert sum(kinds["trilinear"]) == row.objects - (name == "spheres")


def test_chain_spheres_sit_where_their_anchors_put_them() -> None:
    scene = gs.spheres_scene(objects=1 + 2 * gs.CHAINS, triangles=40_000)
    assert (scene.objects, scene.triangles) == (17, 40_000)
    tri, lin = _centres(scene, "trilinear")[1:], _centres(scene, "linear")[1:]
    # the linear variant places each sphere rigidly at the image of its centre: the same
    np.testing.assert_allclose(tri, lin, atol=1e-9)
    # outside the bent body, by about half a chain's thickness (anchored to its surface)
    body = scene.leaves()[0].geometry.vertices
    gap = np.array([np.linalg.norm(body - c, axis=1).min() for c in tri])
    step = 0.9 * gs.BODY_LENGTH / 2
    assert np.all(gap > 0.3 * step), gap.min()
    assert np.all(gap < 0.8 * step), gap.max()


def test_helix_rope_is_continuous_and_winds_round_its_centre_line() -> None:
    objects = 3 * 9 * gs.SEGMENT_SLICES
    scene = gs.helix_scene(objects=objects, triangles=objects * 48)
    segments = scene.graphs["trilinear"].children
    assert len(segments) == 3
    face = np.stack(np.meshgrid([0.0], np.linspace(0, 1, 5), np.linspace(0, 1, 5)), -1)
    face = face.reshape(-1, 3)
    for a, b in itertools.pairwise(segments):
        end = a.transform(face + np.array([1.0, 0.0, 0.0]))
        np.testing.assert_allclose(end, b.transform(face), atol=1e-9)  # C0: no gaps
    # the linear spheres lie within half the rope's diagonal of the centre line
    length = objects / 9 * gs.SLOT
    line, _ = gs.helix_frame(np.linspace(0, length, 4000), length)
    lin = _centres(scene, "linear")
    dist = np.array([np.linalg.norm(line - c, axis=1).min() for c in lin])
    assert dist.max() < math.sqrt(2) * 1.5 * gs.SLOT
    # and the sway bends the trilinear one: its top moves along +x, its bottom stays
    tri = _centres(scene, "trilinear")
    top = tri[:, 2] > np.percentile(tri[:, 2], 90)
    assert (tri[top, 0] - lin[top, 0]).mean() > 1.0


@pytest.mark.gl
def test_measured_rows_stand_beside_the_papers(gl_ctx: Any) -> None:
    small = [
        lambda: gs.spheres_scene(objects=9, triangles=20_000, row=LATTICE_FPS[0]),
        lambda: gs.helix_scene(objects=30, triangles=30 * 48, row=LATTICE_FPS[1]),
        lambda: gs.helix_scene(objects=20, triangles=20 * 96, row=LATTICE_FPS[2]),
    ]
    rows, shots = measure_scenes(small, gl_ctx, (48, 32), 1)
    for r, (name, images) in zip(rows, shots, strict=True):
        assert r["scene"] == name
        assert r["ratio"] == pytest.approx(r["linear_ms"] / r["trilinear_ms"])
        assert r["trilinear_fps"] == pytest.approx(1000.0 / r["trilinear_ms"])
        for v in gs.VARIANTS:
            assert images[v].shape == (32, 48, 3)
            assert images[v].max() > 50  # something was drawn
    text = "\n".join(_lattice_section({"grapp_scenes": rows}, quick=False))
    for r, p in zip(rows, LATTICE_FPS, strict=True):
        line = next(x for x in text.splitlines() if x.startswith(f"| {r['scene']} ("))
        assert f"| {p.linear_fps:g} / {p.trilinear_fps:g} | {p.ratio:.1%} |" in line
        assert f"| {r['linear_fps']:.2f} / {r['trilinear_fps']:.2f} | {r['ratio']:.1%} |" in line
        assert f"(paper {p.triangles})" in line
    quick = "\n".join(_lattice_section({"grapp_scenes": rows}, quick=True))
    assert quick.count(QUICK_SKIP) == 3 * 3


@pytest.mark.gl
def test_the_spheres_variants_draw_the_same_picture(gl_ctx: Any) -> None:
    """Sphere centres agree in both variants; only the spheres' own bend differs, so the
    two frames (each drawn by the GPU) nearly match: the lattice program places them as
    the CPU composition says."""
    scene = gs.spheres_scene(objects=1 + 10 * gs.CHAINS, triangles=60_000)
    _, images = measure_scene(scene, gl_ctx, (160, 120), 1)
    a, b = (images[v].astype(np.int16) for v in gs.VARIANTS)
    drawn = (a.max(-1) > 20) | (b.max(-1) > 20)
    assert drawn.mean() > 0.02
    assert (np.abs(a - b).max(-1) > 40)[drawn].mean() < 0.15
