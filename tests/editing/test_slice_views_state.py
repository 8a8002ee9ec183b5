"""The linked slice views' state without Qt (voxwarp.editing.slice_views): planes through
the crosshair, scrolling by the voxel spacing, window/level drags, zoom, pan, tilt, the
planes' outlines in the 3D view, which handles a slice shows, and picking near a plane."""

from __future__ import annotations

import numpy as np
import pytest

from voxwarp.core.volume import Volume
from voxwarp.deform.warp import rotation_matrix
from voxwarp.editing.session import EditSession
from voxwarp.editing.slice_views import (
    MAX_ZOOM,
    WINDOW_DRAG_PER_PX,
    SliceViews,
    edge_labels,
    handles_near,
    layer_spacing,
    plane_box_polygon,
    readout,
    scale_bar_mm,
)
from voxwarp.errors import SceneError
from voxwarp.scene import Scene

SPACING = (1.5, 0.75, 0.625)


def volume(space: str = "RAS", direction: np.ndarray | None = None) -> Volume:
    data = np.arange(20 * 24 * 16, dtype=np.float32).reshape(20, 24, 16)
    return Volume(data, SPACING, (-10.0, 5.0, 2.0), space=space, direction=direction)


def views(space: str = "RAS") -> SliceViews:
    return SliceViews(volume(space), (100.0, 50.0))


def on_plane(state: SliceViews, name: str, point: np.ndarray) -> float:
    plane = state.plane(name, 1.3)
    return float(abs((point - plane.center) @ plane.normal))


def test_planes_are_named_by_the_volume_space_and_meet_at_the_crosshair() -> None:
    assert views("RAS").names == ("axial", "coronal", "sagittal")
    state = views("")
    assert state.names == ("z", "y", "x")
    vol = state.volume
    # the crosshair starts on a voxel centre (not between two slices)
    idx = vol.world_to_index(state.crosshair)
    np.testing.assert_allclose(idx, np.round(idx), atol=1e-9)
    point = np.array([3.3, 12.1, 7.7])
    state.set_crosshair(point)
    for name in state.names:
        assert on_plane(state, name, point) < 1e-9
    # the named planes: normals along the world axes
    np.testing.assert_allclose(np.abs(state.plane("z").normal), [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(np.abs(state.plane("x").normal), [1, 0, 0], atol=1e-12)


def test_crosshair_stays_in_the_volume_and_rejects_nan() -> None:
    state = views()
    state.set_crosshair([1e6, -1e6, 0])
    lo, hi = state.volume.bounds
    np.testing.assert_allclose(state.crosshair[:2], [hi[0], lo[1]])
    with pytest.raises(SceneError, match="finite"):
        state.set_crosshair([np.nan, 0, 0])


@pytest.mark.parametrize(("index", "axis"), [(0, 2), (1, 1), (2, 0)])
def test_one_scroll_step_is_one_voxel_spacing_along_the_axis(index: int, axis: int) -> None:
    state = views()
    name = state.names[index]
    before = state.crosshair.copy()
    state.scroll(name, 1)
    moved = state.crosshair - before
    expected = np.zeros(3)
    expected[axis] = SPACING[axis]
    np.testing.assert_allclose(moved, expected, atol=1e-9)
    state.scroll(name, -3)
    np.testing.assert_allclose(state.crosshair - before, -2 * expected, atol=1e-9)
    # scrolling far stops at the volume's edge
    state.scroll(name, 10_000)
    assert state.crosshair[axis] == pytest.approx(state.volume.bounds[1][axis])


def test_tilted_plane_scrolls_along_its_normal_by_the_spacing_that_way() -> None:
    state = views()
    point = state.crosshair.copy()
    state.rotate("axial", 90.0, about="up")  # the axial plane turned onto a sagittal one
    plane = state.plane("axial")
    assert plane.name == "oblique"
    np.testing.assert_allclose(np.abs(plane.normal), [1, 0, 0], atol=1e-9)
    assert on_plane(state, "axial", point) < 1e-9  # tilted about the crosshair
    assert state.step_mm("axial") == pytest.approx(SPACING[0])
    state.reset()
    state.rotate("axial", 30.0, about="right")
    n = state.plane("axial").normal
    expected = 1 / np.linalg.norm(n / np.asarray(SPACING))
    assert state.step_mm("axial") == pytest.approx(expected)
    with pytest.raises(SceneError, match="about"):
        state.rotate("axial", 5.0, about="normal")


def test_step_of_an_oblique_scan_follows_its_index_axes() -> None:
    rot = rotation_matrix([0, 0, 1], 90.0)  # index i along world y, j along -x
    state = SliceViews(volume(direction=rot), (0.0, 1.0))
    assert state.step_mm("sagittal") == pytest.approx(SPACING[1])  # world x: index j
    assert state.step_mm("coronal") == pytest.approx(SPACING[0])  # world y: index i


def test_window_drag_is_slicer_like_and_scaled_by_the_value_range() -> None:
    state = views()
    vmin, vmax = state.volume.value_range
    unit = (vmax - vmin) * WINDOW_DRAG_PER_PX
    state.window_drag(10, 0)
    assert state.window == pytest.approx((100.0, 50.0 + 10 * unit))
    state.window_drag(0, -20)
    assert state.window == pytest.approx((100.0 - 20 * unit, 50.0 + 10 * unit))
    state.window_drag(-1e9, 0)
    assert state.window[1] > 0  # never a zero or negative width
    state.reset()
    assert state.window == (100.0, 50.0)


def test_zoom_and_pan_change_what_a_view_frames_not_where_it_cuts() -> None:
    state = views()
    base = state.plane("coronal", 1.0)
    state.zoom("coronal", 2.0)
    state.pan("coronal", 4.0, -3.0)
    plane = state.plane("coronal", 1.0)
    assert plane.height_mm == pytest.approx(base.height_mm / 2)
    np.testing.assert_allclose(
        plane.center - base.center, 4.0 * base.right - 3.0 * base.up, atol=1e-9
    )
    assert plane.position == pytest.approx(base.position)
    state.zoom("coronal", 1e9)
    assert state.views["coronal"].zoom == MAX_ZOOM


def test_options_are_checked() -> None:
    state = views()
    state.set_option("show", "checkerboard")
    state.set_option("slab_mm", 4)
    assert (state.show, state.slab_mm) == ("checkerboard", 4.0)
    for name, bad in (("look", "hot"), ("layout", "4x4"), ("slab_mm", -1), ("zoom", 2)):
        with pytest.raises(SceneError):
            state.set_option(name, bad)


def test_outlines_are_where_the_planes_cut_the_box() -> None:
    state = views()
    layers = state.outline_layers()
    assert [layer.name for layer in layers] == ["axial plane", "coronal plane", "sagittal plane"]
    lo, hi = state.volume.bounds
    for layer, name in zip(layers, state.names, strict=True):
        pts = layer.positions
        assert len(pts) == 8  # a rectangle: four segments
        plane = state.plane(name)
        np.testing.assert_allclose((pts - plane.center) @ plane.normal, 0, atol=1e-9)
        assert np.all(pts >= lo - 1e-9)
        assert np.all(pts <= hi + 1e-9)
    # a plane normal to (1, 1, 1) through the centre of a cube cuts a regular hexagon
    lo3, hi3 = np.zeros(3), np.full(3, 2.0)
    from voxwarp.core.slice_plane import SlicePlane

    tilted = SlicePlane.oblique([1, 1, 1], [1, 1, 1], (lo3, hi3))
    ring = plane_box_polygon(tilted, lo3, hi3)
    assert len(ring) == 6
    sides = np.linalg.norm(np.roll(ring, -1, axis=0) - ring, axis=1)
    np.testing.assert_allclose(sides, np.sqrt(2), atol=1e-9)  # in order around it
    far = SlicePlane.oblique([9, 9, 9], [0, 0, 1], (lo3, hi3))
    assert len(plane_box_polygon(far.at(9.0), lo3, hi3)) == 0


def grid(shape: tuple[int, int, int], spacing: tuple[float, float, float]) -> np.ndarray:
    axes = [np.arange(n) * s for n, s in zip(shape, spacing, strict=True)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def test_a_slice_shows_the_nearest_layer_of_a_grid_also_when_deformed() -> None:
    pts = grid((6, 6, 6), (10.0, 10.0, 30.0))
    rng = np.random.default_rng(1)
    bent = pts + rng.normal(0, 1.0, pts.shape)
    assert layer_spacing(pts, [0, 0, 1]) == pytest.approx(30.0)
    assert layer_spacing(pts, [1, 0, 0]) == pytest.approx(10.0)
    assert layer_spacing(bent, [0, 0, 1]) == pytest.approx(30.0, rel=0.15)
    from voxwarp.core.slice_plane import SlicePlane

    lo, hi = pts.min(axis=0), pts.max(axis=0)
    plane = SlicePlane.named("z", (lo, hi), at=70.0)  # layers at 60 and 90: 60 is nearer
    near = handles_near(pts, plane, (200, 200))
    np.testing.assert_array_equal(np.unique(pts[near, 2]), [60.0])
    near = handles_near(pts, plane, (200, 200), slab_mm=50.0)  # a thick slab shows more
    np.testing.assert_array_equal(np.unique(pts[near, 2]), [60.0, 90.0])
    assert layer_spacing(pts[:1], [0, 0, 1]) == 0.0


def test_pick_near_plane_ignores_handles_off_the_plane() -> None:
    session = EditSession(Scene(volume("")))
    # margin 0: the handles lie on the volume's box, where the crosshair can go
    session.set_deformation("massspring", resolution=4, margin=0.0)
    pts = session.handles()
    state = SliceViews(session.volume, (0.0, 1.0))
    state.set_crosshair(pts[0])
    plane = state.plane("z", 1.0)
    size = (300, 300)
    cam = plane.camera()
    xy = cam.project(pts, size)
    # handle 0 lies on the plane; the handles above it project onto the same pixel
    above = np.flatnonzero(np.hypot(*(xy - xy[0]).T) < 1e-6)
    assert len(above) == 4
    assert session.pick_near_plane(cam, size, xy[0], max_distance=1.0) == 0
    top = int(above[np.argmax(pts[above, 2])])
    state.set_crosshair(pts[top])
    cam = state.plane("z", 1.0).camera()
    assert session.pick_near_plane(cam, size, xy[0], max_distance=1.0) == top
    assert session.pick_near_plane(cam, size, xy[0] + 50, max_distance=1.0) is None


def test_readout_edge_labels_and_scale_bar() -> None:
    text = readout([12.25, -3.0, 0.04], "RAS", 7.0, float("nan"))
    assert text.startswith("R 12.2  P 3.0  S 0.0 mm")
    assert readout([-1, 2, -3], "RAS", 81.0001, 0).startswith("L 1.0  A 2.0  I 3.0 mm")
    assert "deformed 81   rest 0" in readout([0, 0, 0], "RAS", 81.0001, 0)
    assert "deformed 7" in text
    assert "rest —" in text
    assert readout([1, 2, 3], "", 1.5, 2.5).startswith("x +1.0  y +2.0  z +3.0 mm")
    state = views("")
    labels = edge_labels(state.plane("x"), "")
    assert labels == {"right": "+y", "left": "-y", "top": "+z", "bottom": "-z"}
    ras = SliceViews(volume("RAS"), (0.0, 1.0))
    assert edge_labels(ras.plane("axial"), "RAS") == {
        "right": "L",
        "left": "R",
        "top": "A",
        "bottom": "P",
    }
    assert scale_bar_mm(0.37, 100) == 20.0  # 37 mm fit: 20 is the round length below
    assert scale_bar_mm(2.0, 100) == 200.0
    assert scale_bar_mm(0.01, 60) == pytest.approx(0.5)
