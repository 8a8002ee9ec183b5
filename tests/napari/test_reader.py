"""The napari reader: which files it takes, and the layers it makes (a NIfTI checked
against nibabel's affine, the oracle; NRRD; scene JSON with and without warps)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from napari.layers import Image

from voxwarp.io.samples import bundled_dir
from voxwarp.napari_plugin.reader import get_reader, read_scene, read_volume


def _oblique_affine() -> np.ndarray:
    """An oblique LPI-ish affine: rotated 20 degrees about z and 10 about x, x and z
    mirrored, anisotropic voxels, off-centre origin (as a tilted scan)."""
    cz, sz = np.cos(np.radians(20)), np.sin(np.radians(20))
    cx, sx = np.cos(np.radians(10)), np.sin(np.radians(10))
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    a = np.eye(4)
    a[:3, :3] = rz @ rx @ np.diag([-0.8, 1.1, -2.5])
    a[:3, 3] = (40.0, -25.0, 12.0)
    return a


def _layer(layer_data: tuple) -> Image:
    data, kwargs, kind = layer_data
    assert kind == "image"
    return Image(data, **kwargs)


def test_nifti_voxels_land_where_nibabel_puts_them(tmp_path: Path) -> None:
    nib = pytest.importorskip("nibabel")
    data = np.arange(5 * 6 * 7, dtype=np.int16).reshape(5, 6, 7)  # unique values
    affine = _oblique_affine()
    path = tmp_path / "tilted.nii.gz"
    nib.save(nib.Nifti1Image(data, affine), path)
    reader = get_reader(str(path))
    assert reader is read_volume
    (layer_data,) = reader(str(path))
    layer = _layer(layer_data)
    assert layer.data.shape == (7, 6, 5) or sorted(layer.data.shape) == [5, 6, 7]
    assert sorted(layer.scale) == pytest.approx([0.8, 1.1, 2.5])
    assert not np.allclose(layer.affine.affine_matrix, np.eye(4))  # the rotation is there
    oracle = nib.load(path).affine
    for ijk in [(0, 0, 0), (4, 5, 6), (1, 2, 3), (4, 0, 2)]:
        (n,) = np.argwhere(np.asarray(layer.data) == data[ijk])
        world_zyx = np.asarray(layer.data_to_world(tuple(n)))
        np.testing.assert_allclose(world_zyx[::-1], (oracle @ (*ijk, 1))[:3], atol=1e-4)
    assert layer.metadata["voxwarp"]["space"] == "RAS"
    assert layer.metadata["voxwarp"]["path"] == str(path)


def test_nrrd_reads_with_spacing_and_origin(tmp_path: Path) -> None:
    from voxwarp import Volume, save_volume

    vol = Volume(np.arange(60, dtype=np.uint8).reshape(3, 4, 5), (0.5, 1.5, 3.0), (1, 2, 3))
    path = save_volume(vol, tmp_path / "v.nrrd")
    layer = _layer(get_reader(str(path))(str(path))[0])
    np.testing.assert_array_equal(layer.data, vol.data.T)
    assert tuple(layer.scale) == (3.0, 1.5, 0.5)
    assert tuple(layer.translate) == (3.0, 2.0, 1.0)


def _scene_file(tmp_path: Path, warps: bool) -> Path:
    from voxwarp import Scene, load_sample
    from voxwarp.napari_plugin.deformed_view import push_warps

    vol = load_sample("head", shape=(24, 24, 24))
    scene = Scene(vol, window=(0.0, 400.0), warps=push_warps(vol) if warps else [])
    return scene.save(tmp_path / "scene.json")


def test_scene_json_gives_its_volume_with_the_scene_window(tmp_path: Path) -> None:
    path = _scene_file(tmp_path, warps=False)
    assert get_reader(str(path)) is read_scene
    (layer_data,) = read_scene(str(path))
    layer = _layer(layer_data)
    assert layer.data.shape == (24, 24, 24)
    assert tuple(layer.contrast_limits) == (-200.0, 200.0)
    assert layer.metadata["voxwarp"]["path"] == str(path)
    assert layer.metadata["voxwarp"]["mode"] == "dvr"


def test_scene_with_warps_adds_its_deformed_view(tmp_path: Path, gl_ctx: object) -> None:
    """The reader renders with its own context; ``gl_ctx`` skips the test without EGL."""
    path = _scene_file(tmp_path, warps=True)
    volume_data, render_data = read_scene(str(path))
    assert volume_data[0].shape == (24, 24, 24)
    image, kwargs, kind = render_data
    assert kind == "image"
    assert kwargs["rgb"] is True
    assert image.shape == (256, 256, 3)
    assert image.dtype == np.uint8
    assert image.std() > 5  # a picture, not a blank


def test_hand_written_scene_without_format_is_recognised(tmp_path: Path) -> None:
    path = tmp_path / "mine.json"
    path.write_text(json.dumps({"volume": {"sample": "head", "shape": [8, 8, 8]}, "mode": "mip"}))
    assert get_reader(str(path)) is read_scene


@pytest.mark.parametrize(
    "text",
    [
        '{"dims": [4, 4, 4], "dtype": "uint8"}',  # a raw volume's sidecar
        '{"volume": 1, "colour": "red"}',  # an unknown key: not a scene
        '{"format": "something-else", "volume": {}}',
        "[1, 2, 3]",
        "{not json",
        "",
    ],
)
def test_other_json_is_not_taken(tmp_path: Path, text: str) -> None:
    path = tmp_path / "other.json"
    path.write_text(text)
    assert get_reader(str(path)) is None


def test_bundled_wire_file_is_not_a_scene() -> None:
    assert get_reader(str(bundled_dir() / "fish_spine_wires.json")) is None


def test_other_paths_are_not_taken(tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("hello")
    assert get_reader(str(tmp_path / "notes.txt")) is None
    assert get_reader(str(tmp_path / "missing.json")) is None
    assert get_reader(str(tmp_path)) is None  # a folder without DICOM files
    assert get_reader([str(tmp_path / "a.nrrd"), str(tmp_path / "b.nrrd")]) is None


def test_folder_with_a_dicom_file_is_taken(tmp_path: Path) -> None:
    (tmp_path / "IM0001").write_bytes(b"\0" * 128 + b"DICM" + b"\0" * 16)
    assert get_reader(str(tmp_path)) is read_volume


def test_answers_fast_on_a_large_non_scene_json(tmp_path: Path) -> None:
    import time

    path = tmp_path / "big.json"
    path.write_text(json.dumps({"values": list(range(2_000_000))}))
    start = time.perf_counter()
    assert get_reader(str(path)) is None
    assert time.perf_counter() - start < 0.05


def test_dicom_folder_voxels_land_at_their_patient_positions(tmp_path: Path) -> None:
    pytest.importorskip("pydicom")
    from tests.orientation_layouts import write_dicom_series

    data = np.arange(6 * 5 * 4, dtype=np.int16).reshape(6, 5, 4) * 7 - 300  # unique, HU-like
    affine = np.diag([0.7, 0.9, 2.0, 1.0])  # RAS index axes
    affine[:3, 3] = (-20.0, 15.0, 40.0)
    folder = write_dicom_series(tmp_path / "series", data, affine)
    assert get_reader(str(folder)) is read_volume
    layer = _layer(read_volume(str(folder))[0])
    assert layer.metadata["voxwarp"]["modality"] == "CT"
    for ijk in [(0, 0, 0), (5, 4, 3), (2, 1, 3)]:
        (n,) = np.argwhere(np.asarray(layer.data) == data[ijk])
        world_zyx = np.asarray(layer.data_to_world(tuple(n)))
        np.testing.assert_allclose(world_zyx[::-1], (affine @ (*ijk, 1))[:3], atol=1e-4)


def test_scene_opens_without_its_render_where_rendering_fails(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from voxwarp.errors import RenderError
    from voxwarp.napari_plugin import deformed_view

    def no_gl(*_: object) -> None:
        raise RenderError("no OpenGL 4.3 context through EGL")

    monkeypatch.setattr(deformed_view, "render_rgb", no_gl)
    path = _scene_file(tmp_path, warps=True)
    with pytest.warns(UserWarning, match="deformed view was not rendered: no OpenGL"):
        layers = read_scene(str(path))
    assert len(layers) == 1
    assert layers[0][0].shape == (24, 24, 24)


def test_4d_nifti_is_one_layer_with_a_time_axis(tmp_path: Path) -> None:
    nib = pytest.importorskip("nibabel")
    data = np.arange(3 * 4 * 5 * 6, dtype=np.int16).reshape(3, 4, 5, 6)  # x, y, z, t
    nib.save(nib.Nifti1Image(data, np.diag([2.0, 3.0, 4.0, 1.0])), str(tmp_path / "t.nii.gz"))
    reader = get_reader(str(tmp_path / "t.nii.gz"))
    (layer,) = reader(str(tmp_path / "t.nii.gz"))
    np.testing.assert_array_equal(layer[0], data.transpose(3, 2, 1, 0))  # t, z, y, x
    assert tuple(layer[1]["scale"]) == (1.0, 4.0, 3.0, 2.0)
    assert _layer(layer).ndim == 4


def test_multichannel_nrrd_is_a_layer_per_channel(tmp_path: Path) -> None:
    nrrd = pytest.importorskip("nrrd")
    data = np.random.default_rng(0).normal(size=(2, 4, 5, 6)).astype(np.float32)
    header = {"kinds": ["list", "domain", "domain", "domain"], "spacings": [np.nan, 1, 1, 1]}
    nrrd.write(str(tmp_path / "c.nrrd"), data, header, index_order="F")
    layers = read_volume(str(tmp_path / "c.nrrd"))
    assert [lay[1]["name"] for lay in layers] == ["c [channel 0]", "c [channel 1]"]
    for c, layer in enumerate(layers):
        np.testing.assert_array_equal(layer[0], data[c].T)
