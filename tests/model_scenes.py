"""Deformed scenes on a real scan shared by the slice and export tests: colin27 at 4 mm
with a margin, pushed by a mass-spring grid or bent by a wire."""

from __future__ import annotations

import numpy as np

from voxwarp.core.volume import Volume
from voxwarp.deform.elements.grid import ElementGrid
from voxwarp.deform.elements.massspring import MassSpring
from voxwarp.deform.warp import Warp
from voxwarp.deform.wires.field import Wire, WireDeformer
from voxwarp.io.samples import load_sample

#: voxels of zeros around the head: the deformations move anatomy into them
PAD = 6


def padded_colin(pad: int = PAD) -> Volume:
    """colin27 downsampled to 4 mm, with ``pad`` zero voxels on every side."""
    vol = load_sample("colin27").downsample(2)
    data = np.pad(np.asarray(vol.data), pad)
    origin = np.asarray(vol.origin) - pad * np.asarray(vol.spacing)
    return Volume(data, vol.spacing, tuple(origin), name="colin27-padded", space=vol.space)


def massspring_push(vol: Volume, shape: int, steps: int) -> list[Warp]:
    """A ``shape``³ grid fixed at its bottom layer, its inner top elements pushed 28 mm
    along +x and settled (at most ``steps`` steps)."""
    ms = MassSpring(ElementGrid(vol, shape=shape, anchor="corners"))
    ms.fix([(i, j, 0) for i in range(shape) for j in range(shape)])
    top = [(i, j, 4) for i in range(1, shape - 1) for j in range(1, shape - 1)]
    ms.move(top, np.tile([28.0, 0.0, 0.0], (len(top), 1)))
    ms.settle(max_steps=steps)
    return [ms.warp()]


def wire_bend(vol: Volume, dx: float, radius: float, pad: int = PAD) -> list[Warp]:
    """A rigid-ended wire along y through the centre of :func:`padded_colin` (``pad``),
    its middle points moved ``dx`` mm along +x, of ``radius`` mm, classifying values
    60..2000 (the head)."""
    c = vol.center
    lo, hi = (b + s * pad * 4.0 for b, s in zip(vol.bounds, (1, -1), strict=True))
    ys = np.linspace(lo[1] + 10, hi[1] - 10, 4)
    base = [[c[0], y, c[2]] for y in ys]
    bent = [[c[0] + d, y, c[2]] for y, d in zip(ys, (0.0, dx, dx, 0.0), strict=True)]
    wd = WireDeformer(vol, [Wire(base, bent, radius=radius, beta=(60.0, 2000.0), ends="rigid")])
    wd.build()
    return [wd.warp()]
