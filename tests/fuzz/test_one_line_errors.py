"""Regression tests for what the fuzz suite found and was fixed here: error messages that
spanned several lines."""

from __future__ import annotations

import numpy as np
import pytest

from tests.fuzz._support import assert_one_line
from voxwarp.core.volume import parse_triple, short_repr
from voxwarp.errors import VolumeError, VoxwarpError


def test_short_repr_of_an_array_is_one_line() -> None:
    """An array's repr spans lines; the one in an error message must not."""
    text = short_repr(np.zeros((4, 4)))
    assert_one_line(text, "short_repr")
    assert text.startswith("array([[0., 0., 0., 0.], [0.")


def test_spacing_error_for_a_matrix_is_one_line(tmp_path) -> None:
    """The npz fuzz case: a (4, 4) 'spacing' array gave a five-line VolumeError."""
    with pytest.raises(VolumeError) as info:
        parse_triple(np.zeros((4, 4)), "'spacing'", where="v.npz")
    assert_one_line(str(info.value), "VolumeError")


def test_wrapped_library_messages_are_one_line() -> None:
    """pynrrd's 'Invalid NRRD magic line: NRRD\\n' reached the user as two lines; every
    VoxwarpError now reads as one line, its words kept."""
    exc = VolumeError("cannot read v.nrrd (NRRDError: Invalid NRRD magic line: NRRD\n). Fix it.")
    assert str(exc) == "cannot read v.nrrd (NRRDError: Invalid NRRD magic line: NRRD ). Fix it."
    assert str(VoxwarpError("a\r\n  b\tc")) == "a b c"
    assert exc.args[0].count("\n") == 1  # the original message is kept in args


@pytest.mark.parametrize("value", [1e300, -1e300])
def test_float64_values_beyond_float32_are_named_not_called_nan(value: float) -> None:
    """float64 data beyond float32's range became Inf on conversion and was then reported
    as "N NaN/Inf voxel(s)", which the file did not have; now the range is named."""
    from voxwarp.core.volume import Volume

    data = np.zeros((4, 4, 4))
    data[1, 2, 3] = value
    with pytest.raises(VolumeError, match=r"values reach 1e\+300, beyond float32's range") as info:
        Volume(data)
    assert_one_line(str(info.value), "VolumeError")
    data[1, 2, 3] = 3e38  # within float32: converted as before
    assert Volume(data).data.dtype == np.float32


@pytest.mark.parametrize("name", ["v.nrrd", "v.nii", "v.mha", "v.npy", "v.tif"])
def test_an_empty_file_and_a_link_to_nothing_are_named(tmp_path, name: str) -> None:
    """An empty .nrrd reached the user as "(StopIteration: )" and a link loop as "no
    such file"; every reader now gets the same plain line first."""
    from voxwarp.io.volumes import load_volume

    empty = tmp_path / name
    empty.write_bytes(b"")
    with pytest.raises(VolumeError, match=r"is empty \(0 bytes\)"):
        load_volume(empty)
    loop_a, loop_b = tmp_path / f"a_{name}", tmp_path / f"b_{name}"
    loop_a.symlink_to(loop_b)
    loop_b.symlink_to(loop_a)
    with pytest.raises(VolumeError, match="a link to nothing"):
        load_volume(loop_a)
