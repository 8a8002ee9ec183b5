"""Multi-page TIFF files whatever their series layout: every page is a slice.

A stack written page by page with tifffile (each ``write`` call its own series) used to
load as its first slice only, silently. Oracles: the array that was written (page k is
slice z = k, voxwarp's ``(x, y, z)`` order is the transpose of tifffile's ``(z, y, x)``),
ImageJ calibration as written, and one-line errors naming the first odd page.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import tifffile

from voxwarp.errors import VolumeError
from voxwarp.io.volumes import load_volume


def _stack(dtype: type, shape: tuple[int, int, int] = (5, 6, 7)) -> np.ndarray:
    """A (z, y, x) stack whose every voxel differs from its neighbours in each axis."""
    rng = np.random.default_rng(7)
    if np.issubdtype(dtype, np.floating):
        return rng.normal(0, 1000, shape).astype(dtype)
    info = np.iinfo(dtype)
    return rng.integers(info.min, info.max, shape, endpoint=True).astype(dtype)


def _write_page_by_page(path: Path, stack: np.ndarray, **kwargs: object) -> None:
    with tifffile.TiffWriter(path) as w:
        for page in stack:
            w.write(page, **kwargs)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
@pytest.mark.parametrize("metadata", ["shaped", "none"])
def test_stack_written_page_by_page_loads_every_page(
    tmp_path: Path, dtype: type, metadata: str
) -> None:
    stack = _stack(dtype)
    path = tmp_path / "pages.tif"
    _write_page_by_page(path, stack, **({"metadata": None} if metadata == "none" else {}))
    if metadata == "shaped":
        with tifffile.TiffFile(path) as tif:  # the layout this test is about
            assert len(tif.series) == len(stack)
    vol = load_volume(path)
    assert vol.dtype == np.dtype(dtype)
    assert vol.shape == (7, 6, 5)
    np.testing.assert_array_equal(vol.data, stack.transpose(2, 1, 0))


def test_pages_of_one_size_and_another_type_keep_file_order(tmp_path: Path) -> None:
    # without metadata tifffile groups pages by kind, not by position: the stack must
    # still come out in file order
    stack = _stack(np.uint8, (4, 6, 7))
    path = tmp_path / "order.tif"
    with tifffile.TiffWriter(path) as w:
        for k, page in enumerate(stack):
            w.write(page, metadata=None, compression="zlib" if k % 2 else None)
    vol = load_volume(path)
    np.testing.assert_array_equal(vol.data, stack.transpose(2, 1, 0))


def test_imagej_stack_keeps_its_calibration(tmp_path: Path) -> None:
    stack = _stack(np.uint16)
    path = tmp_path / "ij.tif"
    tifffile.imwrite(
        path,
        stack,
        imagej=True,
        resolution=(1 / 0.5, 1 / 0.25),  # pixels per micron
        metadata={"axes": "ZYX", "spacing": 2.0, "unit": "um"},
    )
    vol = load_volume(path)
    np.testing.assert_array_equal(vol.data, stack.transpose(2, 1, 0))
    np.testing.assert_allclose(vol.spacing, (0.0005, 0.00025, 0.002))


def test_imagej_hyperstack_with_a_time_point_of_one(tmp_path: Path) -> None:
    stack = _stack(np.uint8)
    path = tmp_path / "hyper.tif"
    tifffile.imwrite(
        path, stack[None, :, None], imagej=True, metadata={"axes": "TZCYX", "spacing": 3.0}
    )
    vol = load_volume(path)
    np.testing.assert_array_equal(vol.data, stack.transpose(2, 1, 0))
    assert vol.spacing[2] == pytest.approx(3.0)


@pytest.mark.parametrize("metadata", ["shaped", "none"])
def test_pages_of_different_sizes_name_the_first_odd_page(tmp_path: Path, metadata: str) -> None:
    path = tmp_path / "mixed.tif"
    kw = {"metadata": None} if metadata == "none" else {}
    with tifffile.TiffWriter(path) as w:
        w.write(np.zeros((6, 7), np.uint8), **kw)
        w.write(np.zeros((6, 7), np.uint8), **kw)
        w.write(np.zeros((8, 9), np.uint8), **kw)
        w.write(np.zeros((5, 4), np.uint8), **kw)
    with pytest.raises(VolumeError) as info:
        load_volume(path)
    msg = str(info.value)
    assert "\n" not in msg
    assert "page 3 of mixed.tif is 9x8 pixels" in msg
    assert "page 1 is 7x6" in msg


def test_pages_of_different_types_are_an_error(tmp_path: Path) -> None:
    path = tmp_path / "types.tif"
    with tifffile.TiffWriter(path) as w:
        w.write(np.zeros((6, 7), np.uint8))
        w.write(np.zeros((6, 7), np.uint16))
    with pytest.raises(VolumeError, match=r"page 2 of types\.tif .* uint16 but page 1 .* uint8"):
        load_volume(path)


def test_single_page_file_is_one_slice(tmp_path: Path) -> None:
    page = _stack(np.uint16, (1, 6, 7))[0]
    path = tmp_path / "one.tif"
    tifffile.imwrite(path, page)
    vol = load_volume(path)
    assert vol.shape == (7, 6, 1)
    np.testing.assert_array_equal(vol.data[:, :, 0], page.T)


def test_rgb_pages_written_page_by_page_keep_the_clear_error(tmp_path: Path) -> None:
    path = tmp_path / "rgb.tif"
    _write_page_by_page(path, np.zeros((3, 6, 7, 3), np.uint8), photometric="rgb")
    with pytest.raises(VolumeError, match="grayscale z-stack") as info:
        load_volume(path)
    assert "\n" not in str(info.value)


def test_folder_slice_holding_pages_written_one_by_one_is_refused(tmp_path: Path) -> None:
    folder = tmp_path / "slices"
    folder.mkdir()
    tifffile.imwrite(folder / "s1.tif", np.zeros((6, 7), np.uint8))
    _write_page_by_page(folder / "s2.tif", np.zeros((3, 6, 7), np.uint8))
    with pytest.raises(VolumeError, match=r"s2\.tif holds 3 pages"):
        load_volume(folder)
