"""View › Warped Grid / Displacement Glyphs in the real window (Xvfb, see conftest).

Scene: a volume moved by a known translation ``t`` (forward map ``p + t``, pull-back
``x - t``). Oracles: with the grid on, the axial slice view's yellow pixels are the ones
whose pull-back point ``x - t`` lies within half a pixel of a multiple of the spacing
(none elsewhere); the 3D view's grid layer holds the rest lattice lines moved by ``t``;
the glyph layer's arrows all point along ``-t``; with the rest state shown the grid is
straight (multiples of the spacing in world x, y); switching off restores the slice.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from PySide6.QtWidgets import QApplication

from tests.ui.windows import shown_window
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import AffineWarp
from voxwarp.editing.session import EditSession
from voxwarp.scene import Scene
from voxwarp.ui.viewport import qimage_to_array

SIZE = (1100, 760)
SHIFT = np.array([4.0, -3.0, 1.5])
N = 10.0


@pytest.fixture
def window(qtbot: Any, monkeypatch: pytest.MonkeyPatch) -> Any:
    data = np.full((40, 36, 30), 80.0, np.float32)
    vol = Volume(data, (1.5, 1.5, 1.5), (-30.0, -27.0, -22.0), name="flat", space="RAS")
    session = EditSession(Scene(vol, mode="mip", jitter=False))
    session.add_warps_front([AffineWarp.translation(SHIFT)])  # as an imported transform
    w = shown_window(qtbot, monkeypatch, session, SIZE, layout="2x2")
    qtbot.waitUntil(lambda: all(v.image is not None for v in w.mpr.views), timeout=30000)
    yield w
    w.close()


def _slice(view: Any) -> np.ndarray:
    for _ in range(3):
        QApplication.processEvents()
    return qimage_to_array(view._qimage)[..., :3].astype(int)


def test_grid_and_glyphs_follow_the_warp(window: Any) -> None:
    w = window
    axial = w.mpr.views[0]
    before = _slice(axial)
    w.warp_overlay_actions["spacing"].setValue(N)
    w.warp_overlay_actions["grid"].setChecked(True)
    img = _slice(axial)
    m = axial.image.pixel_to_world
    h, wd = img.shape[:2]
    cols, rows = np.meshgrid(np.arange(wd), np.arange(h))
    world = cols[..., None] * m[:3, 0] + rows[..., None] * m[:3, 1] + m[:3, 3]
    rest = world - SHIFT
    px = float(np.linalg.norm(m[:3, 0]))
    d = (np.abs(rest[..., :2] / N - np.round(rest[..., :2] / N)) * N / px).min(axis=-1)
    inside = np.isfinite(axial.image.values)
    yellow = (img[..., 0] - img[..., 2] > 60) & inside
    assert (yellow & (d <= 0.5)).sum() > 50
    assert not np.any(yellow & (d > 1.3))
    # 3D: rest lattice lines moved by the forward map (p + t)
    layers = w.warp_overlays.layers_3d()
    (grid,) = layers
    pos = grid.positions
    lo, hi = w.session.scene.volume.bounds
    rest3 = pos - SHIFT
    on_plane_axes = np.isclose(np.mod(rest3 + 1e-6, N), 0, atol=1e-4)
    assert np.all(on_plane_axes.sum(axis=1) >= 1)
    assert np.all((rest3 >= lo - 1e-6) & (rest3 <= hi + 1e-6))
    # glyphs: every arrow shaft along -t (u = chain(x) - x = -t)
    w.warp_overlay_actions["glyphs"].setChecked(True)
    glyph_layer = w.warp_overlays.layers_3d()[1]
    seg = glyph_layer.positions.reshape(-1, 6, 3)
    shafts = seg[:, 1] - seg[:, 0]
    np.testing.assert_allclose(
        shafts / np.linalg.norm(shafts, axis=1, keepdims=True),
        np.broadcast_to(-SHIFT / np.linalg.norm(SHIFT), shafts.shape),
        atol=1e-9,
    )
    # the rest state shown: the grid is straight, at multiples of N in world x, y
    w.warp_overlay_actions["glyphs"].setChecked(False)
    w.mpr.set_option("show", "rest")
    img = _slice(axial)
    d0 = (np.abs(world[..., :2] / N - np.round(world[..., :2] / N)) * N / px).min(axis=-1)
    yellow = (img[..., 0] - img[..., 2] > 60) & np.isfinite(axial.image.rest)
    assert (yellow & (d0 <= 0.5)).sum() > 50
    assert not np.any(yellow & (d0 > 1.3))
    w.mpr.set_option("show", "deformed")
    w.warp_overlay_actions["grid"].setChecked(False)
    np.testing.assert_array_equal(_slice(axial), before)
