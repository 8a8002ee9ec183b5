"""The notebook Viewer's warped grid and glyph switches (:meth:`Viewer.show_overlays`).

Oracle: the grid's line layer holds the rest lattice lines of the plane facing the
camera moved by the chain's forward map (here the mass-spring model at rest: its
forward map, solved independently by ``chain_forward``); switched on, the frame
changes along the lines' projections (``Camera.project``) and nowhere far from them;
switched off, the frame is the plain one again.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from tests.notebook.test_viewer import NO_OVERLAY, SIZE, _scene
from voxwarp.deform.warp import chain_apply, chain_forward


@pytest.fixture
def viewer(gl_ctx: Any) -> Iterator[Any]:
    from voxwarp.notebook import Viewer

    v = Viewer(_scene(), "massspring", size=SIZE, ctx=gl_ctx, resolution=6, anchor="corners")
    v.handle_event({"type": "resize", "width": SIZE[0], "height": SIZE[1], "ratio": 1.0})
    v.display_options = NO_OVERLAY
    v.running = False
    yield v
    v.release()


def test_grid_switch_draws_the_forward_mapped_lines(viewer: Any) -> None:
    plain = np.asarray(viewer.snapshot()).astype(int)
    viewer.show_overlays(grid=True, spacing_mm=10.0)
    scene = viewer.session.scene
    (layer,) = viewer.warp_lines.layers(scene, viewer.camera)
    seg = layer.positions
    # every segment end is the forward map of a rest point on a line at multiples of 10
    assert scene.warps  # the model's warp
    back = chain_apply(scene.warps, seg)
    np.testing.assert_allclose(chain_forward(scene.warps, back), seg, atol=1e-3)
    near_multiple = np.isclose(np.mod(back + 1e-6, 10.0), 0.0, atol=1e-3)
    assert np.all(near_multiple.sum(axis=1) >= 1)
    shown = np.asarray(viewer.snapshot()).astype(int)
    changed = np.abs(shown - plain)[..., :3].max(axis=-1) > 20
    px = viewer.camera.project(seg, SIZE).astype(int)
    inside = (px[:, 0] >= 0) & (px[:, 0] < SIZE[0]) & (px[:, 1] >= 0) & (px[:, 1] < SIZE[1])
    assert inside.sum() > 10
    near = np.zeros(changed.shape, bool)
    for a, b in zip(px[0::2], px[1::2], strict=True):
        for t in np.linspace(0, 1, 64):
            c, r = np.round(a + t * (b - a)).astype(int)
            near[max(r - 2, 0) : r + 3, max(c - 2, 0) : c + 3] = True
    assert changed.sum() > 50
    assert not np.any(changed & ~near)
    viewer.show_overlays(grid=False)
    np.testing.assert_array_equal(np.asarray(viewer.snapshot()).astype(int), plain)
