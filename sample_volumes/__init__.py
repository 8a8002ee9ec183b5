"""Sample volumes for voxwarp: seeded synthetic phantoms in HU and two small real scans.

>>> from sample_volumes import get, names
>>> names()
['fish', 'tubes', 'head', 'stent', 'colin27']
>>> get("fish", shape=(48, 24, 20)).data.shape
(48, 24, 20)

Arrays are indexed ``data[i, j, k]`` with ``i`` along x (the voxwarp convention). See
``README.md`` in this package for what each sample is, how it is made and its licence.
This package imports only numpy, scipy and the standard library (nibabel is not needed).
"""

from voxwarp.sample_volumes.generators import (
    FISH_FOV_MM,
    HEAD_FOV_MM,
    NOISE_STD,
    TUBES_FOV_MM,
    SampleData,
    colin27,
    fish,
    fish_spine,
    get,
    head,
    names,
    stent,
    tubes,
)

__all__ = [
    "FISH_FOV_MM",
    "HEAD_FOV_MM",
    "NOISE_STD",
    "TUBES_FOV_MM",
    "SampleData",
    "colin27",
    "fish",
    "fish_spine",
    "get",
    "head",
    "names",
    "stent",
    "tubes",
]
