"""The trilinear-lattice demo scenes (app/teaching/lattice_scenes.py,
sample_volumes/lattice_*.json).

Oracles: neighbouring tubes wrapped around the torus still touch along their contact
line (Figure 1); neighbouring tiles share their edges exactly, C0 seams (Figure 9); the
attached bands and plate sit on the bent body at their anchors (Figures 6 and 8); the
bundled scene files are what the builders make now, and render.
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from voxwarp.scene import Scene
from voxwarp.teaching.lattice_scenes import DEMOS, accessories, torus_tiles, torus_tubes

ROOT = Path(__file__).resolve().parents[2]


def quiet(make: Callable[[], Scene]) -> Scene:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # HU presets on the empty carrier volume
        return make()


def test_wrapped_tubes_stay_in_contact() -> None:
    scene = quiet(lambda: torus_tubes(tubes=6))
    tubes = scene.meshes
    assert len(tubes) == 6
    x = np.linspace(0.0, 100.0, 41)
    r = 2.0
    for a, b in itertools.pairwise(tubes):
        top = a.local_to_world(np.stack([x, np.full_like(x, r), np.zeros_like(x)], -1))
        bottom = b.local_to_world(np.stack([x, np.full_like(x, -r), np.zeros_like(x)], -1))
        np.testing.assert_allclose(top, bottom, atol=1e-9)
    # and the arrangement really is wrapped: tube 0's ring closes on itself
    ends = tubes[0].local_to_world(np.array([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]]))
    np.testing.assert_allclose(ends[0], ends[1], atol=1e-9)


def test_tiles_meet_with_c0_seams() -> None:
    scene = quiet(lambda: torus_tiles(rows=3, cols=6))
    tiles = {inst.name: inst for inst in scene.meshes}
    assert len(tiles) == 18
    edge = np.linspace(0.0, 10.0, 25)
    for i in range(6):
        for j in range(3):
            here = tiles[f"tile {i},{j}"]
            right = tiles[f"tile {(i + 1) % 6},{j}"]
            a = here.local_to_world(np.stack([np.full_like(edge, 10.0), edge, 0 * edge], -1))
            b = right.local_to_world(np.stack([0 * edge, edge, 0 * edge], -1))
            np.testing.assert_allclose(a, b, atol=1e-9)
            up = tiles[f"tile {i},{(j + 1) % 3}"]
            a = here.local_to_world(np.stack([edge, np.full_like(edge, 10.0), 0 * edge], -1))
            b = up.local_to_world(np.stack([edge, 0 * edge, 0 * edge], -1))
            np.testing.assert_allclose(a, b, atol=1e-9)


def test_accessories_sit_on_the_bent_body() -> None:
    scene = quiet(accessories)
    body, band, _, plate = scene.meshes
    bent = body.local_to_world(np.asarray(body.mesh.vertices))
    assert np.ptp(bent[:, 0]) > 20.0  # the body really is bent
    nodes = np.asarray(band.transform.nodes)  # (n, 2, 2, 3)
    centre = nodes[:, :, 0].mean(axis=1)  # the band's bottom centre line
    # every node of that line is an anchor point on the bent body's surface
    d = np.linalg.norm(bent[None, :, :] - centre[:, None, :], axis=2).min(axis=1)
    assert d.max() < 0.6  # within a triangle of a vertex (mesh ~1 mm)
    u = np.stack(
        [np.linspace(0, 1, len(centre)), np.full(len(centre), 0.5), np.zeros(len(centre))], -1
    )
    lo, hi = band.box
    np.testing.assert_allclose(band.local_to_world(lo + u * (hi - lo)), centre, atol=1e-9)
    # the plate's bottom corners are its anchors, above the surface by its offset
    pn = np.asarray(plate.transform.nodes)
    assert pn.shape[:3] == (2, 5, 2)
    assert np.linalg.norm(pn[:, :, 1] - pn[:, :, 0], axis=-1) == pytest.approx(2.5)


@pytest.mark.parametrize("name", sorted(DEMOS))
def test_bundled_demo_files_are_current_and_render(name: str, offscreen: Any) -> None:
    path = ROOT / "sample_volumes" / f"lattice_{name}.json"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        bundled = Scene.load(path)
    fresh = quiet(DEMOS[name])
    assert len(bundled.meshes) == len(fresh.meshes)
    r = offscreen(96, 72)
    a = r.render(bundled)
    b = r.render(fresh)
    np.testing.assert_array_equal(a, b)  # regenerate: scripts/make_lattice_demos.py
    rgb = a[..., :3].astype(float)
    background = rgb[0, 0]
    assert (np.abs(rgb - background).max(axis=-1) > 30).mean() > 0.05  # something drawn
