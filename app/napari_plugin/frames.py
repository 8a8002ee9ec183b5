"""Every volume of a 4-D or multi-channel file as napari layers.

napari shows a time series with a slider over the layer's leading axis and channels as
layers of their own (its ``channel_axis`` convention), so the reader does not ask which
volume to open as voxwarp's window does: :func:`frame_layers` stacks the time points of
each channel into one ``(t, z, y, x)`` layer, one layer per channel.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from voxwarp.io.frames import CHANNEL, FrameChoiceError
from voxwarp.io.volumes import load_volume
from voxwarp.napari_plugin.convert import LayerData, volume_to_layer_data


def frame_layers(path: str | os.PathLike[str], error: FrameChoiceError) -> list[LayerData]:
    """One Image layer per channel of ``path``, its time points (if several) stacked on
    the leading axis; ``error`` is what :func:`load_volume` said the file holds."""
    frames = next((a.size for a in error.axes if a.kind != CHANNEL), 0)
    channels = next((a.size for a in error.axes if a.kind == CHANNEL), 0)
    layers = []
    for c in range(max(channels, 1)):
        picks = [_pick(t, c, frames, channels) for t in range(max(frames, 1))]
        volumes = [load_volume(path, **p) for p in picks]
        data, kwargs, kind = volume_to_layer_data(
            volumes[0], metadata={"path": str(path), **({"channel": c} if channels else {})}
        )
        if channels:
            kwargs["name"] = f"{kwargs['name']} [channel {c}]"
        if frames:
            data = np.stack([v.data.T for v in volumes])
            _lead_with_time(kwargs)
        layers.append((data, kwargs, kind))
    return layers


def _pick(t: int, c: int, frames: int, channels: int) -> dict[str, int]:
    return {
        **({"frame_index": t} if frames else {}),
        **({"channel": c} if channels else {}),
    }


def _lead_with_time(kwargs: dict[str, Any]) -> None:
    """Give the layer's geometry a leading time axis of unit step."""
    kwargs["scale"] = (1.0, *kwargs["scale"])
    if "translate" in kwargs:
        kwargs["translate"] = (0.0, *kwargs["translate"])
    if "affine" in kwargs:
        a = np.eye(5)
        a[1:, 1:] = np.asarray(kwargs["affine"])
        kwargs["affine"] = a
