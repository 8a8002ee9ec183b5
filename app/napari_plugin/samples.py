"""voxwarp's bundled samples as napari sample data (File > Open Sample > voxwarp).

One function per sample (npe2 names a command per entry of ``napari.yaml``); each
returns the sample as an Image layer with its spacing as ``scale`` and its origin, as
:func:`voxwarp.napari_plugin.convert.volume_to_layer_data` makes them.
"""

from __future__ import annotations

from collections.abc import Callable

from voxwarp.io.samples import load_sample
from voxwarp.napari_plugin.convert import LayerData, volume_to_layer_data


def sample_layers(name: str) -> list[LayerData]:
    """The bundled sample ``name`` (see :func:`voxwarp.io.samples.sample_names`)."""
    return [volume_to_layer_data(load_sample(name), metadata={"sample": name})]


def _sample(name: str) -> Callable[[], list[LayerData]]:
    def make() -> list[LayerData]:
        return sample_layers(name)

    make.__name__ = make.__qualname__ = name
    make.__doc__ = f"The bundled sample {name!r} as an Image layer."
    return make


fish = _sample("fish")
tubes = _sample("tubes")
head = _sample("head")
stent = _sample("stent")
colin27 = _sample("colin27")
