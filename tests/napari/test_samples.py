"""Sample data: each bundled sample as an Image layer with its spacing and origin."""

from __future__ import annotations

import numpy as np
import pytest

from voxwarp.io.samples import load_sample, sample_names
from voxwarp.napari_plugin import samples


@pytest.mark.parametrize("name", sample_names())
def test_sample_layer_has_the_sample_geometry(name: str) -> None:
    (layer_data,) = getattr(samples, name)()
    data, kwargs, kind = layer_data
    vol = load_sample(name)
    assert kind == "image"
    assert data.shape == vol.shape[::-1]
    np.testing.assert_array_equal(data[1, 2, 3], vol.data[3, 2, 1])
    assert kwargs["scale"] == vol.spacing[::-1]
    assert kwargs["translate"] == vol.origin[::-1]
    assert kwargs["metadata"]["voxwarp"]["sample"] == name
    lo, hi = kwargs["contrast_limits"]
    assert vol.value_range[0] <= lo < hi <= vol.value_range[1]
