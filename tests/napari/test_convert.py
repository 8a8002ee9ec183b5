"""convert.py: napari Image layers <-> voxwarp volumes, checked through napari's own
data -> world map (``layer.data_to_world``) against ``Volume.index_to_world``."""

from __future__ import annotations

import numpy as np
import pytest
from napari.layers import Image, Labels

from voxwarp.core.volume import Volume
from voxwarp.errors import VolumeError
from voxwarp.napari_plugin.convert import (
    TF_MAX_OPACITY,
    colormap_transfer_function,
    layer_scene_options,
    layer_to_volume,
    napari_affine,
    volume_to_layer_data,
)


def _rotation(axis: tuple[float, float, float], degrees: float) -> np.ndarray:
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    t = np.radians(degrees)
    return np.eye(3) + np.sin(t) * k + (1 - np.cos(t)) * k @ k


def _volume(direction: np.ndarray | None = None) -> Volume:
    data = np.arange(5 * 6 * 7, dtype=np.int16).reshape(5, 6, 7)  # unique values
    return Volume(data, (0.5, 1.0, 2.0), (3.0, -4.0, 5.0), name="v", direction=direction)


def _layer(volume: Volume) -> Image:
    data, kwargs, kind = volume_to_layer_data(volume, window=(100.0, 50.0))
    assert kind == "image"
    return Image(data, **kwargs)


VOXELS = [(0, 0, 0), (4, 5, 6), (1, 2, 3), (3, 0, 6)]


@pytest.mark.parametrize("oblique", [False, True])
def test_layer_maps_voxels_where_voxwarp_does(oblique: bool) -> None:
    vol = _volume(_rotation((1, 2, 3), 25) if oblique else None)
    layer = _layer(vol)
    assert layer.data.shape == (7, 6, 5)
    assert tuple(layer.scale) == (2.0, 1.0, 0.5)
    for i, j, k in VOXELS:
        assert layer.data[k, j, i] == vol.data[i, j, k]
        world_zyx = np.asarray(layer.data_to_world((k, j, i)))
        np.testing.assert_allclose(world_zyx[::-1], vol.index_to_world([i, j, k]), atol=1e-9)


@pytest.mark.parametrize("oblique", [False, True])
def test_round_trip_keeps_voxels_and_geometry(oblique: bool) -> None:
    vol = _volume(_rotation((0, 1, 1), -40) if oblique else None)
    back = layer_to_volume(_layer(vol))
    np.testing.assert_array_equal(back.data, vol.data)
    np.testing.assert_allclose(back.affine, vol.affine, atol=1e-9)
    assert back.name == "v"


def test_translate_and_scale_of_a_plain_layer() -> None:
    data = np.zeros((4, 3, 2), np.float32)  # z, y, x
    vol = layer_to_volume(Image(data, scale=(3.0, 2.0, 0.5), translate=(30.0, 20.0, 10.0)))
    assert vol.shape == (2, 3, 4)
    assert vol.spacing == (0.5, 2.0, 3.0)
    assert vol.origin == (10.0, 20.0, 30.0)
    assert not vol.is_oblique


_TURNED = np.array([[1, 0, 0, 0], [0, 0, -1, 5.0], [0, 1, 0, 0], [0, 0, 0, 1]])  # y <-> x


@pytest.mark.parametrize(
    "kwargs",
    [
        {"scale": (1.0, 1.0, -2.0), "translate": (0.0, 0.0, 7.0)},  # x mirrored
        {"scale": (3.0, 1.0, 2.0), "affine": _TURNED},  # turned 90 degrees about z
    ],
)
def test_mirrored_or_turned_layer_keeps_every_voxel_in_place(kwargs: dict) -> None:
    data = np.arange(4 * 3 * 2, dtype=np.float32).reshape(4, 3, 2)
    layer = Image(data, **kwargs)
    vol = layer_to_volume(layer)
    assert np.linalg.det(vol.direction) > 0
    assert not vol.is_oblique  # reordered to the closest RAS axes, as files are
    for n in np.ndindex(data.shape):
        ijk = np.argwhere(vol.data == data[n])[0]
        np.testing.assert_allclose(
            vol.index_to_world(ijk), np.asarray(layer.data_to_world(n))[::-1], atol=1e-9
        )


def test_napari_affine_reverses_axes_and_is_its_own_inverse() -> None:
    a = np.arange(16, dtype=float).reshape(4, 4)
    a[3] = (0, 0, 0, 1)
    b = napari_affine(a)
    assert b[0, 0] == a[2, 2]
    assert b[0, 3] == a[2, 3]
    assert b[2, 1] == a[0, 1]
    np.testing.assert_array_equal(napari_affine(b), a)


def test_contrast_limits_become_the_window() -> None:
    layer = _layer(_volume())
    assert tuple(layer.contrast_limits) == (75.0, 125.0)
    options = layer_scene_options(layer)
    assert options["window"] == (100.0, 50.0)
    assert options["mode"] == "mip"  # napari's default 3D rendering


def test_default_contrast_limits_follow_voxwarp_modality_window() -> None:
    from voxwarp.core.modality import display_defaults

    vol = _volume()
    _, kwargs, _ = volume_to_layer_data(vol)
    level, width = display_defaults(vol, "mip").window
    assert kwargs["contrast_limits"] == (level - width / 2, level + width / 2)
    assert kwargs["colormap"] == "gray"


def test_gray_colormap_is_a_grey_ramp_over_the_limits() -> None:
    tf = colormap_transfer_function("gray", (10.0, 20.0))
    pts = np.asarray(tf.points)
    assert pts[0, 0] == 10.0
    assert pts[-1, 0] == 20.0
    np.testing.assert_allclose(pts[:, 1], pts[:, 2])
    np.testing.assert_allclose(pts[:, 1], np.linspace(0, 1, len(pts)), atol=1e-6)
    assert pts[0, 4] == 0.0
    assert pts[-1, 4] == pytest.approx(TF_MAX_OPACITY)
    assert np.all(np.diff(pts[:, 4]) > 0)
    assert tf.name == "napari:gray"


def test_viridis_colours_are_napari_colours() -> None:
    from napari.utils.colormaps import ensure_colormap

    tf = colormap_transfer_function("viridis", (0.0, 1.0))
    pts = np.asarray(tf.points)
    expected = ensure_colormap("viridis").map(pts[:, 0])[:, :3]
    np.testing.assert_allclose(pts[:, 1:4], expected, atol=1e-6)
    assert tf(0.5)[:3] == pytest.approx(ensure_colormap("viridis").map([0.5])[0, :3], abs=0.02)


def test_layer_display_drives_the_scene() -> None:
    layer = _layer(_volume())
    layer.colormap = "magma"
    layer.rendering = "iso"
    layer.iso_threshold = 110.0
    layer.opacity = 0.5
    options = layer_scene_options(layer)
    assert options["mode"] == "iso"
    assert options["iso_value"] == 110.0
    tf = options["transfer_function"]
    assert tf.name == "napari:magma"
    assert tf.points[-1][4] == pytest.approx(0.5 * TF_MAX_OPACITY)
    layer.rendering = "translucent"
    assert layer_scene_options(layer)["mode"] == "dvr"


def test_unknown_colormap_name_is_one_line() -> None:
    with pytest.raises(VolumeError, match="unknown colormap 'no-such-map'"):
        colormap_transfer_function("no-such-map", (0.0, 1.0))


@pytest.mark.parametrize(
    ("layer", "message"),
    [
        (Image(np.zeros((8, 9))), "has 2 dimensions .*a single image has no depth"),
        (Image(np.zeros((4, 8, 9, 3), np.uint8), rgb=True), "is RGB; voxwarp renders scalar"),
        (Image(np.zeros((2, 4, 8, 9))), "has 4 dimensions .*one time point or channel"),
        (Labels(np.zeros((4, 8, 9), int)), "is a Labels, not an image"),
        (Image(np.zeros((4, 8, 9)), shear=(0.3, 0, 0)), "is sheared"),
        (Image([np.zeros((4, 8, 8)), np.zeros((2, 4, 4))], multiscale=True), "is multiscale"),
    ],
)
def test_unusable_layers_are_refused_in_one_line(layer: object, message: str) -> None:
    with pytest.raises(VolumeError, match=message) as info:
        layer_to_volume(layer)
    assert "\n" not in str(info.value)
