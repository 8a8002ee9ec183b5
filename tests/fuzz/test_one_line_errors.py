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
