"""The edit session's element families with boundary conditions: the default shell,
anchored elements drawn in their own colour, and picking that frees them.

Oracles: the anchor masks of voxwarp.deform.elements.anchors, the overlay's colours
(voxwarp.editing.common.COLORS) and the model's own fixed and anchored masks.
"""

from __future__ import annotations

import numpy as np
import pytest

from voxwarp.core.volume import Volume
from voxwarp.deform.elements.anchors import anchor_mask
from voxwarp.editing.common import COLORS
from voxwarp.editing.session import EditSession
from voxwarp.io.samples import load_sample
from voxwarp.scene import Scene


@pytest.fixture(scope="module")
def volume() -> Volume:
    return load_sample("fish", shape=(48, 48, 48))


@pytest.mark.parametrize("kind", ["massspring", "chainmail"])
def test_anchored_elements_have_their_own_layer_and_free_like_fixed(
    volume: Volume, kind: str
) -> None:
    s = EditSession(Scene(volume))
    s.set_deformation(kind, resolution=9, anchor="shell", fix_outside=15)
    grid = s.model.grid
    np.testing.assert_array_equal(grid.fixed, anchor_mask(grid.shape, "shell"))
    assert "shell fixed" in s.family.boundary_text()
    s.model.move((4, 4, 4), (1.0, 0.0, 0.0))  # the drag of the adapter: hold and move
    assert grid.anchored.any()
    layers = {layer.name: layer for layer in s.overlay_layers()}
    assert tuple(layers["anchored"].colors) == COLORS["anchored"] != COLORS["fixed"]
    handles = s.handles()
    np.testing.assert_array_equal(layers["anchored"].positions, handles[grid.anchored.reshape(-1)])
    assert len(layers["elements"].positions) == grid.count - grid.constrained().sum()
    assert "anchored now" in s.family.boundary_text()
    np.testing.assert_array_equal(s.anchored_handles(), grid.anchored.reshape(-1))
    picked = int(np.flatnonzero(grid.anchored.reshape(-1))[0])
    s.set_fixed([picked], False)  # picking frees an anchored element
    assert not grid.anchored.reshape(-1)[picked]
    assert not grid.fixed.reshape(-1)[picked]
    s.model.move((4, 4, 4), (2.0, 0.0, 0.0))  # a new drag recomputes the region ...
    assert not grid.anchored.reshape(-1)[picked]  # ... and keeps the freed one free
    assert grid.anchored.any()
