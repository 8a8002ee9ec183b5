"""The GUI's slice views sample the voxel grid (issue 32, item 7), without Qt.

Oracle: ``volume.world_to_index`` of every pixel centre. At 1:1 zoom
(:meth:`SliceViews.native_zoom`: a pixel is a voxel) the pixel centres of each untilted
view must be voxel centres (integer indices), for odd and even view sizes, wherever the
crosshair is (also between voxels) and after a pan; without the alignment they sit a
fraction of a voxel off. Text helpers: the window label and the two-line readout."""

from __future__ import annotations

import numpy as np
import pytest

from voxwarp.core.volume import Volume
from voxwarp.editing.reading import split_readout, window_text
from voxwarp.editing.slice_views import SliceViews, readout


def _views(shape: tuple[int, int, int]) -> SliceViews:
    data = np.arange(np.prod(shape), dtype=np.float32).reshape(shape)
    vol = Volume(data, (2.0, 2.0, 2.0), (-31.0, 17.0, 4.0), space="RAS")
    return SliceViews(vol, (0.0, 1.0))


def _indices(state: SliceViews, name: str, size: tuple[int, int]) -> np.ndarray:
    plane = state.plane(name, size[0] / size[1], size=size)
    m = plane.pixel_to_world(size)
    cols, rows = np.meshgrid(np.arange(size[0]), np.arange(size[1]))
    pix = np.stack([cols, rows, 0 * cols, 1 + 0 * cols], -1).reshape(-1, 4).astype(float)
    return state.volume.world_to_index((pix @ m.T)[:, :3])


@pytest.mark.parametrize("shape", [(21, 18, 15), (20, 17, 16)])
@pytest.mark.parametrize("size", [(301, 240), (300, 241)])
def test_one_to_one_views_sample_voxel_centres(shape: tuple, size: tuple) -> None:
    state = _views(shape)
    state.set_crosshair(state.volume.index_to_world(np.array([7.3, 5.6, 4.45])))
    for name in state.names:
        state.views[name].zoom = state.native_zoom(name, size)
        assert state.plane(name, size[0] / size[1], size=size).pixel_mm(size) == pytest.approx(2)
        for pan in ((0.0, 0.0), (3.3, -1.7)):
            state.views[name].pan = np.asarray(pan)
            idx = _indices(state, name, size)
            axis = {"axial": 2, "coronal": 1, "sagittal": 0}[name]
            in_plane = np.delete(idx, axis, axis=1)
            assert np.abs(in_plane - np.round(in_plane)).max() < 1e-6, (name, pan)


def test_without_a_size_the_plane_is_unchanged() -> None:
    """The alignment moves a view by less than half a pixel, in its plane only."""
    state = _views((20, 17, 16))
    size = (300, 241)
    for name in state.names:
        free = state.plane(name, size[0] / size[1])
        on_grid = state.plane(name, size[0] / size[1], size=size)
        shift = on_grid.center - free.center
        assert abs(shift @ free.normal) < 1e-9
        assert np.all(np.abs([shift @ free.right, shift @ free.up]) <= free.pixel_mm(size) / 2)


def test_window_label_and_readout_lines() -> None:
    assert window_text((40.0, 400.0)) == "W 400 L 40"
    assert window_text((-600, 1500), "lung") == "lung  W 1500 L -600"
    line = readout((12.25, -3.0, 0.0), "RAS", 123.456, float("nan"))
    position, values = split_readout(line)
    assert position == "R 12.2  P 3.0  S 0.0 mm"
    assert values.split() == ["deformed", "123.46", "rest", "—"]
