"""napari plugin tests: napari layers without a viewer, except the viewer check, which
runs napari in a child process on its own Xvfb (see test_viewer.py)."""

from __future__ import annotations

import warnings

import pytest

pytest.importorskip(
    "napari", reason="the napari extra is not installed (pip install -e '.[napari]')"
)


@pytest.fixture(autouse=True)
def _quiet_slicing() -> None:
    """napari warns that oblique layers slice without their out-of-slice rotation; the
    tests build such layers on purpose."""
    warnings.filterwarnings("ignore", message="Non-orthogonal slicing", category=UserWarning)
